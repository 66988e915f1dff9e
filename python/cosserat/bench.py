"""A `cosseratbench <https://pypi.org/project/cosseratbench/>`_ solver for this simulator
(issue 23).

cosseratbench finds it through the ``cosseratbench.solvers`` entry point ``cosserat``
(``python/pyproject.toml``) and runs it in this process::

    pip install "cosserat[bench]"
    cosseratbench run cantilever catenary --solver cosserat --solver pyelastica

:class:`CosseratSolver` turns a :class:`cosseratbench.Scenario` into a scene (TOML text for
:meth:`cosserat.Simulation.from_toml`, the same format as ``scenes/*.toml``), steps it with the
GIL released and samples the frames cosseratbench asks for: every rod's points and the ``d1``
director of each of its frames.

What a scene cannot say is declared, not imitated: the run raises ``NotImplementedError``
naming it, which cosseratbench reports as *unsupported* (issue 28 lists these gaps):

- more than one obstacle, and friction coefficients that differ between rods or between rods
  and an obstacle in a way one scene-wide coefficient cannot express.

cosseratbench 0.3.0 has no torques, moments or time-varying loads in its scenarios; its
constant end forces are scene loads.

cosseratbench is an optional dependency (``pip install "cosserat[bench]"``): ``import
cosserat`` does not import it; only this module does, when cosseratbench loads it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np

from . import _cosserat

try:
    from cosseratbench.scenario import (
        Cylinder,
        End,
        EndCondition,
        Plane,
        Rod,
        Scenario,
    )
    from cosseratbench.solver import Capability, Diverged
    from cosseratbench.trajectory import Trajectory
except ImportError as error:  # pragma: no cover - exercised only without the extra
    raise ImportError(
        'cosserat.bench needs cosseratbench: pip install "cosserat[bench]"',
        name="cosseratbench",
    ) from error

__all__ = ["CosseratSolver"]

# The explicit scheme's accepted fraction of its estimated critical step
# (`cosserat_model::stability::SAFETY`, measured in docs/stability.md).
_SAFETY = 0.9
# Time step of the stiff scheme: the haptic step it is validated at (docs/stiff-solver.md). Its
# statics do not depend on the step, so a quasi-static run needs only enough steps per slowest
# period to follow the rod settling (the bound below), and a driven end enough per frame.
_STIFF_DT = 1e-3
_STIFF_STEPS_PER_RADIAN = 20.0  # steps per radian of the slowest mode: h ω ≤ 1/20
# A floor is a square plane mesh; this many times the rods' extent, so that nothing reaches
# its edges.
_FLOOR_SIZE = 100.0
# Faces around a cylinder obstacle: the faces lie within radius (1 - cos(pi/512)) = 1.9e-5 radius
# of the round surface.
_CYLINDER_SEGMENTS = 512


def _stable_step(rod: Rod, n_elements: int, drag: float, extensible: bool) -> float:
    """The explicit scheme's estimated critical step for ``rod`` (seconds).

    The same estimate as the library's ``cosserat_model::stability::stable_step``, which the
    scene builder applies to refuse a step (it is not in the Python API, and this adapter needs
    it before it writes the scene): the fastest of the bending/shear, torsion and stretching
    blocks, with the default parallel penalty ``K_p = G A`` and drag as the only damping.
    """
    m = rod.material
    rho, r = m.density, rod.radius
    # The shortest element: the rod is resampled to equal chords, never longer than its arc.
    nodes = rod.nodes(n_elements)
    seg = float(np.linalg.norm(np.diff(nodes, axis=0), axis=1).min())
    area = math.pi * r * r
    i2 = math.pi * r**4 / 4.0
    kp = m.shear_modulus * area
    bending = 4.0 * m.youngs_modulus / (rho * seg**2)
    blocks = [
        (bending + kp / rho * (4.0 / (area * seg**2) + 1.0 / i2), drag),
        (4.0 * m.shear_modulus / (rho * seg**2), 0.0),
        (4.0 * m.youngs_modulus / (rho * seg**2) if extensible else 0.0, drag),
    ]

    def critical(w2: float, gamma: float) -> float:
        if w2 == 0.0:
            return 2.0 / gamma if gamma > 0.0 else math.inf
        return 4.0 / (math.sqrt(gamma * gamma + 4.0 * w2) + gamma)

    return min(critical(w2, g) for w2, g in blocks)


def _toml(value: Any) -> str:
    """A TOML literal."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    return "[" + ", ".join(_toml(v) for v in value) + "]"


@dataclass
class _Plan:
    """The numerical choices for one scenario at one resolution, and the scene they make."""

    scheme: str
    extensible: bool
    time_step: float
    steps_per_frame: int
    drag: float
    scene: str
    notes: list[str] = field(default_factory=list)


def _unsupported(scenario: Scenario) -> list[str]:
    """What in ``scenario`` the scene format cannot express (issue 28), one line each."""
    reasons = []
    if len(scenario.obstacles) > 1:
        reasons.append(f"{len(scenario.obstacles)} obstacles: a scene has one environment mesh")
    elif scenario.obstacles:
        obstacle = scenario.obstacles[0]
        coefficients = {max(obstacle.friction, rod.friction) for rod in scenario.rods}
        if len(coefficients) > 1:
            reasons.append(
                f"rod-obstacle friction differs between rods ({sorted(coefficients)}): a scene "
                "has one coefficient for its environment"
            )
    if _touching(scenario) and len({rod.friction for rod in scenario.rods}) > 1:
        reasons.append(
            "rods with different friction coefficients touch each other: a scene has one "
            "coefficient for rod-rod contact"
        )
    return reasons


def _rest_lengths(rod: Rod, n_elements: int) -> list[float]:
    """The rest length of each of the ``n_elements`` elements the rod is built with: its rest
    arc length (given at its centreline's nodes) interpolated at the built nodes' arc length."""
    points = np.asarray(rod.centerline, dtype=float)
    arc = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))))
    rest = np.asarray(rod.rest_arc_length, dtype=float)
    nodes = np.asarray(rod.nodes(n_elements), dtype=float)
    built = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(nodes, axis=0), axis=1))))
    at = built * (arc[-1] / built[-1])
    return [float(x) for x in np.diff(np.interp(at, arc, rest))]


def _clear_of_cylinder(nodes: np.ndarray, cylinder: Cylinder, radius: float) -> np.ndarray:
    """``nodes`` with those wrapped on ``cylinder`` moved out from its axis so that the chords
    between them rest on it instead of cutting into it.

    cosseratbench places a wrapped rope's material points a hair outside the wrap radius for
    its own fine sampling; a rod of fewer, longer elements through the same points has chords
    that cut into the cylinder by their sagitta (0.12 mm, an eighth of the rope's radius, for
    the capstan at 100 elements), which the first step's contacts throw out: a jolt that starts
    the rope sliding. Points within a chord's sagitta of the wrap radius are put at
    ``wrap / cos(Δ/2)``, ``Δ`` the angle a chord spans there.
    """
    axis = cylinder.unit_axis
    center = np.asarray(cylinder.center, dtype=float)
    wrap = cylinder.radius + radius
    chord = float(np.linalg.norm(np.diff(nodes, axis=0), axis=1).mean())
    outside = wrap / math.cos(min(chord / wrap, 1.0) / 2.0)
    rel = nodes - center
    along = rel @ axis
    across = rel - along[:, None] * axis
    distance = np.linalg.norm(across, axis=1)
    wrapped = (distance < outside) & (np.abs(along) <= cylinder.length / 2.0) & (distance > 0.0)
    out = nodes.copy()
    out[wrapped] = (
        center + along[wrapped, None] * axis + across[wrapped] * (outside / distance[wrapped])[:, None]
    )
    return out


def _sliding(scenario: Scenario) -> bool:
    """Whether a clamp of the scenario slides along an axis (the explicit scheme runs those)."""
    return any(
        motion is not None and motion.slides_along is not None
        for rod in scenario.rods
        for motion in (rod.motion(end) for end in End)
    )


def _touching(scenario: Scenario) -> bool:
    """Whether the scenario needs rod-rod or self-contact."""
    return len(scenario.rods) > 1 or scenario.self_contact


class CosseratSolver:
    """The ``cosserat`` solver of cosseratbench: this package's CPU backend, in process.

    The scheme is chosen per scenario as a user of the simulator would:

    - **stiff** (implicit bending, twisting, stretch and shear; ``docs/stiff-solver.md``) for a
      quasi-static scenario, where only the state the rod settles to counts: its statics do not
      depend on the step, so it runs at the haptic step of 1 ms (a smaller one where the slowest
      mode or the frame interval needs it) instead of the explicit scheme's, which for a stiff
      thin wire is hundreds to thousands of times smaller (2 to 30 times for cosseratbench's soft
      rods). Implicit Euler damps what it cannot resolve, which a settling rod does not mind.
    - **explicit** (the paper's semi-implicit Euler) for a dynamic scenario, where the motion
      is the result: it adds no numerical damping, as cosseratbench asks, at 0.9 of the
      estimated critical step (the library's default safety). Also for rods that touch each other or
      themselves, and for clamps that slide along an axis, which the stiff scheme does not
      handle yet.

    Rods are extensible (stretch energy ``E A``) and shear through the parallel penalty
    ``K_p = G A`` (a Timoshenko rod with shear coefficient 1), in double precision, with a
    straight rest shape (cosseratbench rods are straight when stress-free). A quasi-static
    scenario gets drag at twice the slowest mode's angular frequency (critical damping of that
    mode, as cosseratbench's PyElastica adapter does); a dynamic one gets no damping at all.
    """

    name = "cosserat"
    backend_version = _cosserat.__version__
    capabilities = frozenset(
        {
            Capability.STRETCH,
            Capability.SHEAR,
            Capability.ROD_CONTACT,  # explicit scheme, [rod_contact]
            Capability.ROD_FRICTION,  # Coulomb, static and kinetic alike here
            Capability.PLANE_CONTACT,  # a square floor mesh, with Coulomb friction
            Capability.CYLINDER_CONTACT,  # a closed cylinder mesh as a solid, likewise
        }
    )

    def __init__(self, time_step_scale: float = 1.0, scheme: Optional[str] = None) -> None:
        """``time_step_scale`` multiplies the step this adapter would choose (cosseratbench's
        solver option); ``scheme`` (``"explicit"`` or ``"stiff"``) overrides the choice of
        scheme, for comparing the two (the stiff scheme has no rod-rod contact)."""
        if not time_step_scale > 0.0:
            raise ValueError(f"time_step_scale = {time_step_scale}: expected a number > 0")
        if scheme not in (None, "explicit", "stiff"):
            raise ValueError(f'scheme = {scheme!r}: expected None, "explicit" or "stiff"')
        self.time_step_scale = float(time_step_scale)
        self.scheme = scheme

    # -- planning ---------------------------------------------------------------------------

    def _plan(self, scenario: Scenario, n_elements: int, n_frames: int) -> _Plan:
        reasons = _unsupported(scenario)
        if reasons:
            raise NotImplementedError("; ".join(reasons))
        if n_frames < 2:
            raise ValueError(f"n_frames = {n_frames}: expected at least 2")
        frame_interval = scenario.duration / (n_frames - 1)
        touching = _touching(scenario)
        # The stiff scheme's friction lets a rope creep over a cylinder well below the capstan
        # ratio (it slid at 0.6 of it where the explicit scheme held 1.0, tests/solid_obstacles.rs).
        cylinder = any(isinstance(o, Cylinder) for o in scenario.obstacles)
        stiff = scenario.quasi_static and not (touching or _sliding(scenario) or cylinder)
        if self.scheme is not None:
            stiff = self.scheme == "stiff"
        drag = 2.0 * scenario.slowest_frequency() if scenario.quasi_static else 0.0
        extensible = True
        if stiff:
            limit = min(_STIFF_DT, 1.0 / (_STIFF_STEPS_PER_RADIAN * scenario.slowest_frequency()))
        else:
            limit = _SAFETY * min(
                _stable_step(rod, n_elements, drag, extensible) for rod in scenario.rods
            )
        limit *= self.time_step_scale
        steps_per_frame = max(1, math.ceil(frame_interval / limit * (1.0 - 1e-12)))
        dt = frame_interval / steps_per_frame

        notes = []
        lines = [
            f"name = {_toml('cosseratbench')}",
            "",
            "[solver]",
            f"scheme = {_toml('stiff' if stiff else 'explicit')}",
            f"dt = {_toml(dt)}",
            f"mode = {_toml('extensible' if extensible else 'inextensible')}",
            f"precision = {_toml('f64')}",
            f"gravity = {_toml([float(g) for g in scenario.gravity])}",
            # At scale 1 the step is the library's accepted fraction of its estimate; a larger
            # scale asks what happens beyond it, so the builder must not refuse it.
            f"check_stability = {_toml(self.time_step_scale <= 1.0)}",
        ]
        obstacle = scenario.obstacles[0] if scenario.obstacles else None
        if obstacle is not None:
            friction = max(obstacle.friction, scenario.rods[0].friction)
            if isinstance(obstacle, Plane):
                points = np.concatenate(
                    [np.asarray(rod.centerline, float) for rod in scenario.rods]
                )
                extent = float(np.ptp(points, axis=0).max()) + max(
                    rod.length for rod in scenario.rods
                )
                mesh = {
                    "kind": "plane",
                    "point": [float(x) for x in obstacle.point],
                    "normal": [float(x) for x in obstacle.unit_normal],
                    "size": _FLOOR_SIZE * extent,
                }
                # A floor has no lumen to leave.
                extra = ["stop_outside = false"]
                notes.append("floor: Coulomb friction, static = kinetic")
            else:
                mesh = {
                    "kind": "cylinder",
                    "center": [float(x) for x in obstacle.center],
                    "axis": [float(x) for x in obstacle.unit_axis],
                    "radius": float(obstacle.radius),
                    "length": float(obstacle.length),
                    "segments": _CYLINDER_SEGMENTS,
                }
                extra = []
                notes.append(
                    f"cylinder: a closed mesh of {_CYLINDER_SEGMENTS} faces around, as a solid; "
                    "Coulomb friction, static = kinetic"
                )
            lines += [
                "",
                "[environment]",
                "mesh = " + _toml(mesh),
                "friction = " + _toml({"static": friction, "kinetic": friction}),
                *extra,
            ]
        if touching:
            friction = scenario.rods[0].friction
            lines += [
                "",
                "[rod_contact]",
                f"self_collisions = {_toml(bool(scenario.self_contact))}",
                "friction = " + _toml({"static": friction, "kinetic": friction}),
            ]
        for k, rod in enumerate(scenario.rods):
            lines += self._rod_lines(k, rod, n_elements, drag, obstacle)
        return _Plan(
            scheme="stiff" if stiff else "explicit",
            extensible=extensible,
            time_step=dt,
            steps_per_frame=steps_per_frame,
            drag=drag,
            scene="\n".join(lines) + "\n",
            notes=notes,
        )

    @staticmethod
    def _rod_lines(
        k: int, rod: Rod, n_elements: int, drag: float, obstacle: Optional[Any] = None
    ) -> list[str]:
        m = rod.material
        nodes = np.asarray(rod.nodes(n_elements), dtype=float)
        if isinstance(obstacle, Cylinder):
            nodes = _clear_of_cylinder(nodes, obstacle, rod.radius)
        lines = [
            "",
            "[[rod]]",
            f"name = {_toml(f'rod{k}')}",
            f"elements = {n_elements}",
            # Material points evenly spaced along the rod, as cosseratbench's Rod.nodes; the
            # scene resamples them to equal chords, which moves them by less than the chord's
            # sagitta.
            "shape = "
            + _toml(
                {"kind": "polyline", "points": [list(map(float, p)) for p in nodes]}
            ),
            "material = "
            + _toml(
                {
                    "young_modulus": m.youngs_modulus,
                    "shear_modulus": m.shear_modulus,
                    "density": m.density,
                    "radius": rod.radius,
                }
            ),
            f"rest_shape = {_toml('straight')}",
            *(
                [f"rest_lengths = {_toml(_rest_lengths(rod, n_elements))}"]
                if rod.rest_arc_length is not None
                else []
            ),
            f"first_director = {_toml([float(x) for x in rod.normal])}",
            "damping = " + _toml({"drag": drag}),
        ]
        for end, key in ((End.START, "start"), (End.END, "end")):
            held: dict = {"kind": rod.condition(end).value}
            motion = rod.motion(end)
            if motion is not None:
                # cosseratbench's Motion is an end path: keyframes from 0, linear between,
                # held after the last, followed exactly at every step.
                held["path"] = {
                    "times": [float(t) for t in motion.times],
                    "displacement": [list(map(float, d)) for d in motion.displacement],
                    "rotation": [list(map(float, r)) for r in motion.rotation],
                }
                if motion.slides_along is not None:
                    # Free along the axis, where the rod and the end's loads move it; the path
                    # moves it only across the axis (cosseratbench's Motion checks that).
                    held["slide"] = [float(x) for x in motion.axis]
            lines.append(f"{key} = " + _toml(held))
        for load in rod.loads:
            lines += [
                "[[rod.load]]",
                f"point = {0 if load.at is End.START else -1}",
                f"force = {_toml([float(f) for f in load.force])}",
            ]
        return lines

    # -- the solver interface ---------------------------------------------------------------

    def settings(self, scenario: Scenario, *, n_elements: int, n_frames: int) -> dict:
        """The numerical choices this adapter makes for ``scenario``, as JSON values."""
        try:
            plan = self._plan(scenario, n_elements, n_frames)
        except NotImplementedError as error:
            return {"unsupported": str(error)}
        return {
            "scheme": plan.scheme,
            "integrator": (
                "implicit Euler (stiff scheme, direct Newton solve)"
                if plan.scheme == "stiff"
                else "semi-implicit Euler (explicit scheme)"
            ),
            "time_step": plan.time_step,
            "mode": "extensible" if plan.extensible else "inextensible",
            "precision": "f64",
            "shear_stiffness": "G A (parallel penalty)",
            "drag_rate": plan.drag,
            **({"notes": plan.notes} if plan.notes else {}),
        }

    def scene(self, scenario: Scenario, *, n_elements: int, n_frames: int) -> str:
        """The scene (TOML) this adapter runs for ``scenario``; it raises
        ``NotImplementedError`` for what a scene cannot express."""
        return self._plan(scenario, n_elements, n_frames).scene

    def run(self, scenario: Scenario, *, n_elements: int, n_frames: int) -> Trajectory:
        plan = self._plan(scenario, n_elements, n_frames)
        sim = _cosserat.Simulation.from_toml(plan.scene, name="cosseratbench.toml")
        n_rods = len(scenario.rods)
        positions = [[sim.positions(k)] for k in range(n_rods)]
        directors = [[sim.directors(k)[:, 0, :]] for k in range(n_rods)]
        try:
            for _ in range(n_frames - 1):
                sim.run(plan.steps_per_frame)
                for k in range(n_rods):
                    positions[k].append(sim.positions(k))
                    directors[k].append(sim.directors(k)[:, 0, :])
        except _cosserat.StepError as error:
            raise Diverged(f"cosserat: {error}", time=float(sim.time)) from error
        return Trajectory(
            np.linspace(0.0, scenario.duration, n_frames),
            tuple(np.stack(p) for p in positions),
            tuple(np.stack(d) for d in directors),
        )
