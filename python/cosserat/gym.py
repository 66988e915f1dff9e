"""Gymnasium environments: guidewire navigation in a vessel tree.

``cosserat/GuidewireNavigation-v0`` (registered on import of this module:
``import cosserat.gym`` then ``gymnasium.make("cosserat/GuidewireNavigation-v0")``, or
``gymnasium.make("cosserat.gym:cosserat/GuidewireNavigation-v0")`` in one call) pushes a soft guidewire through an
introducer into a vessel tree, procedural (a random anatomy per seed) or fixed, towards the end of
one of its branches. The agent is the hand:

- **action** ``[push, twist]`` in ``[-1, 1]²``: the held end's speed along the introducer
  (``max_push_speed``, pulling back when negative) and its spin about it (``max_twist_rate``),
  applied for one environment step of ``substeps × dt`` (10 ms by default: ten 1 ms steps of the
  stiff scheme, as a 100 Hz controller over a 1 kHz simulation).
- **observation** (float32): the tip's position relative to the target and to the entry, the tip's
  direction, and ``samples`` points of the distal wire relative to the tip (scaled by 0.1 m), and,
  with ``observe_force``, the force at the hand [N].
- **reward**: progress of the tip along the path from the inlet to the target (the trunk's
  centreline to the branch's junction, then the branch's) in centimetres, minus
  ``wall_force_penalty`` times the summed contact forces [N], plus ``success_reward`` on reaching
  the target and minus ``failure_penalty`` when the run fails (a point outside the lumen, a
  divergence).
- **termination** when the tip is within one lumen radius of the target point, or on failure;
  truncation after ``max_episode_steps`` (the registered ``TimeLimit``).

Seeded resets are reproducible: the seed draws the anatomy (unless ``vessel_seed`` fixes it) and
the target branch (unless ``target_branch`` fixes it); the simulation itself is deterministic.
"""

from __future__ import annotations

import math
from typing import Any, Optional

import numpy as np

import cosserat

try:
    import gymnasium as gym
    from gymnasium import spaces
except ImportError as e:  # pragma: no cover - exercised only without gymnasium
    raise ImportError("cosserat.gym needs gymnasium: pip install gymnasium") from e

ENV_ID = "cosserat/GuidewireNavigation-v0"

_SCENE = """
name = "guidewire-navigation"

[solver]
scheme = "stiff"
dt = {dt!r}
steps = 1
mode = "inextensible"
precision = "f64"
gravity = [0.0, 0.0, 0.0]

[environment]
mesh = {{ kind = "vessel", triangles = {triangles}, seed = {seed} }}
friction = {{ static = {mu_s!r}, kinetic = {mu_k!r} }}
margin = 1e-4
stop_outside = false

[[rod]]
name = "guidewire"
elements = {elements}
shape = {{ kind = "insertion", length = {length!r}, inserted = 0.01 }}
material = {{ young_modulus = {young!r}, poisson_ratio = 0.5, density = 1100.0, radius = {radius!r} }}
damping = {{ drag = 5.0 }}
start = {{ kind = "clamped", guide = {guide!r} }}
"""


def _polyline_projection(
    path: np.ndarray, cumulative: np.ndarray, radii: np.ndarray, p: np.ndarray
) -> tuple[float, float, float]:
    """Arc length of the point of the polyline ``path`` nearest to ``p``, the distance to it and
    the lumen radius there."""
    a, b = path[:-1], path[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    nearest = a + ab * t[:, None]
    d = np.linalg.norm(nearest - p, axis=1)
    i = int(np.argmin(d))
    radius = radii[i] + t[i] * (radii[i + 1] - radii[i])
    return float(cumulative[i] + t[i] * np.linalg.norm(ab[i])), float(d[i]), float(radius)


class GuidewireNavigationEnv(gym.Env):
    """Guidewire navigation to a target branch (see the module docstring)."""

    metadata = {"render_modes": []}

    def __init__(
        self,
        vessel_seed: Optional[int] = None,
        target_branch: Optional[int] = None,
        elements: int = 96,
        triangles: int = 8000,
        dt: float = 1e-3,
        substeps: int = 10,
        wire_length: float = 0.6,
        young_modulus: float = 5.0e6,
        radius: float = 4.0e-4,
        friction: tuple[float, float] = (0.08, 0.05),
        max_push_speed: float = 0.1,
        max_twist_rate: float = 2.0 * math.pi,
        samples: int = 8,
        observe_force: bool = False,
        wall_force_penalty: float = 0.1,
        success_reward: float = 10.0,
        failure_penalty: float = 10.0,
        backend: str = "cpu",
    ):
        super().__init__()
        if elements < samples + 1:
            raise ValueError(f"elements = {elements}: expected at least samples + 1 = {samples + 1}")
        self.vessel_seed = vessel_seed
        self.target_branch = target_branch
        self.elements = elements
        self.triangles = triangles
        self.dt = dt
        self.substeps = substeps
        self.wire_length = wire_length
        self.young_modulus = young_modulus
        self.radius = radius
        self.friction = friction
        self.max_push_speed = max_push_speed
        self.max_twist_rate = max_twist_rate
        self.samples = samples
        self.observe_force = observe_force
        self.wall_force_penalty = wall_force_penalty
        self.success_reward = success_reward
        self.failure_penalty = failure_penalty
        self.backend = backend
        size = 9 + 3 * samples + (3 if observe_force else 0)
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(size,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.sim: Optional[cosserat.Simulation] = None

    # -- episode set-up ----------------------------------------------------------------------

    def _build(self, seed: int) -> None:
        text = _SCENE.format(
            dt=self.dt,
            triangles=self.triangles,
            seed=seed,
            mu_s=float(self.friction[0]),
            mu_k=float(self.friction[1]),
            elements=self.elements,
            length=self.wire_length,
            young=self.young_modulus,
            radius=self.radius,
            guide=self.wire_length - 0.01,
        )
        self.sim = cosserat.Simulation.from_toml(text, backend=self.backend, name="navigation.toml")
        vessel = self.sim.vessel()
        self.entry = np.asarray(vessel["entry_point"])
        self.axis = np.asarray(vessel["entry_direction"])
        self.branches = vessel["branches"]
        self.trunk_points, self.trunk_radii = vessel["trunk"]

    def _path_to(self, branch: int) -> None:
        """The path from the inlet along the trunk to the branch's junction, then along it."""
        points, radii = self.branches[branch]
        junction = points[0]
        trunk = self.trunk_points
        # The trunk point nearest the junction (the branch starts on the trunk's axis).
        k = int(np.argmin(np.linalg.norm(trunk - junction, axis=1)))
        path = np.vstack([trunk[: k + 1], points[1:]])
        self.path_radii = np.concatenate([self.trunk_radii[: k + 1], radii[1:]])
        self.junction = k
        self.path = path
        self.path_s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
        self.target = points[-1]
        self.target_radius = float(radii[-1])

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict[str, Any]] = None):
        super().reset(seed=seed)
        vessel_seed = (
            self.vessel_seed
            if self.vessel_seed is not None
            else int(self.np_random.integers(0, 2**31 - 1))
        )
        self._build(vessel_seed)
        branch = (
            self.target_branch
            if self.target_branch is not None
            else int(self.np_random.integers(0, len(self.branches)))
        )
        if not 0 <= branch < len(self.branches):
            raise ValueError(f"target_branch = {branch}: the vessel has branches 0..{len(self.branches)}")
        self.branch = branch
        self._path_to(branch)
        self.progress = self._progress(self._tip())
        info = {"vessel_seed": vessel_seed, "target_branch": branch, "path_length": float(self.path_s[-1])}
        return self._observation(), info

    # -- stepping -------------------------------------------------------------------------

    def _tip(self) -> np.ndarray:
        return self.sim.positions()[-1]

    def _progress(self, tip: np.ndarray) -> float:
        """Arc length along the path of the tip's nearest path point; a tip outside the path's
        lumen (in another branch, or up the trunk past the junction) counts as far as the
        junction at most."""
        s, d, radius = _polyline_projection(self.path, self.path_s, self.path_radii, tip)
        if d > 1.5 * radius:
            s = min(s, float(self.path_s[self.junction]))
        return s

    def _observation(self) -> np.ndarray:
        p = self.sim.positions()
        tip = p[-1]
        direction = p[-1] - p[-2]
        direction /= np.linalg.norm(direction)
        idx = np.linspace(len(p) - 1 - self.samples, len(p) - 2, self.samples).round().astype(int)
        parts = [
            (self.target - tip) / 0.1,
            (tip - self.entry) / 0.1,
            direction,
            ((p[idx] - tip) / 0.1).ravel(),
        ]
        if self.observe_force:
            reaction = self.sim.end_reaction(0)
            parts.append(reaction[0] if reaction is not None else np.zeros(3))
        return np.concatenate(parts).astype(np.float32)

    def step(self, action):
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        speed, twist = a[0] * self.max_push_speed, a[1] * self.max_twist_rate
        self.sim.set_end_velocity(0, speed * self.axis, twist * self.axis)
        failed = None
        try:
            self.sim.run(self.substeps)
        except cosserat.StepError as e:
            failed = str(e)
        tip = self._tip()
        progress = self._progress(tip)
        _, forces = self.sim.contacts()[1:]
        wall = float(np.linalg.norm(forces, axis=1).sum()) if len(forces) else 0.0
        stats = self.sim.collision_stats()
        if failed is None and stats is not None and stats["escaped_points"] > 0:
            failed = f"{stats['escaped_points']} points of the wire left the lumen"
        reward = 100.0 * (progress - self.progress) - self.wall_force_penalty * wall
        self.progress = progress
        reached = bool(np.linalg.norm(tip - self.target) <= self.target_radius)
        terminated = reached or failed is not None
        if reached:
            reward += self.success_reward
        if failed is not None:
            reward -= self.failure_penalty
        info = {
            "progress": progress,
            "path_length": float(self.path_s[-1]),
            "wall_force": wall,
            "reached": reached,
        }
        if failed is not None:
            info["failure"] = failed
        return self._observation(), float(reward), terminated, False, info


def register_envs() -> None:
    """Registers ``cosserat/GuidewireNavigation-v0`` (1000 steps: 10 s of simulated time)."""
    if ENV_ID not in gym.registry:
        gym.register(
            id=ENV_ID,
            entry_point="cosserat.gym:GuidewireNavigationEnv",
            max_episode_steps=1000,
        )


register_envs()
