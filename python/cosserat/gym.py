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


class _Route:
    """The path from the inlet along the trunk to a branch's junction, then along the branch,
    and the tip's progress on it."""

    def __init__(self, vessel: dict, branch: int):
        branches = vessel["branches"]
        if not 0 <= branch < len(branches):
            raise ValueError(f"target_branch = {branch}: the vessel has branches 0..{len(branches)}")
        trunk, trunk_radii = vessel["trunk"]
        points, radii = branches[branch]
        # The trunk point nearest the junction (the branch starts on the trunk's axis).
        k = int(np.argmin(np.linalg.norm(trunk - points[0], axis=1)))
        self.path = np.vstack([trunk[: k + 1], points[1:]])
        self.radii = np.concatenate([trunk_radii[: k + 1], radii[1:]])
        self.s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(self.path, axis=0), axis=1))])
        self.junction = float(self.s[k])
        self.branch = branch
        self.target = points[-1]
        self.target_radius = float(radii[-1])
        self.length = float(self.s[-1])

    def progress(self, tip: np.ndarray) -> float:
        """Arc length along the path of the tip's nearest path point; a tip outside the path's
        lumen (in another branch, or up the trunk past the junction) counts as far as the
        junction at most."""
        s, d, radius = _polyline_projection(self.path, self.s, self.radii, tip)
        if d > 1.5 * radius:
            s = min(s, self.junction)
        return s

    def reached(self, tip: np.ndarray) -> bool:
        return bool(np.linalg.norm(tip - self.target) <= self.target_radius)


def _observation(route: _Route, entry: np.ndarray, p: np.ndarray, samples: int, force=None) -> np.ndarray:
    """The observation of one wire with points `p` (see the module docstring)."""
    tip = p[-1]
    direction = p[-1] - p[-2]
    direction = direction / np.linalg.norm(direction)
    idx = np.linspace(len(p) - 1 - samples, len(p) - 2, samples).round().astype(int)
    parts = [(route.target - tip) / 0.1, (tip - entry) / 0.1, direction, ((p[idx] - tip) / 0.1).ravel()]
    if force is not None:
        parts.append(force)
    return np.concatenate(parts).astype(np.float32)


class _Settings:
    """What both environments take (see :class:`GuidewireNavigationEnv`)."""

    def __init__(
        self,
        elements=96,
        triangles=8000,
        dt=1e-3,
        substeps=10,
        wire_length=0.6,
        young_modulus=5.0e6,
        radius=4.0e-4,
        friction=(0.08, 0.05),
        max_push_speed=0.1,
        max_twist_rate=2.0 * math.pi,
        samples=8,
        observe_force=False,
        wall_force_penalty=0.1,
        success_reward=10.0,
        failure_penalty=10.0,
        backend="cpu",
    ):
        if elements < samples + 1:
            raise ValueError(f"elements = {elements}: expected at least samples + 1 = {samples + 1}")
        self.__dict__.update(locals())
        del self.__dict__["self"]

    def scene(self, seed: int) -> str:
        return _SCENE.format(
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

    def observation_space(self) -> spaces.Box:
        size = 9 + 3 * self.samples + (3 if self.observe_force else 0)
        return spaces.Box(-np.inf, np.inf, shape=(size,), dtype=np.float32)

    def action_space(self) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

    def reward(self, before: float, after: float, wall: float, reached: bool, failed: bool) -> float:
        r = 100.0 * (after - before) - self.wall_force_penalty * wall
        if reached:
            r += self.success_reward
        if failed:
            r -= self.failure_penalty
        return float(r)


class GuidewireNavigationEnv(gym.Env):
    """Guidewire navigation to a target branch (see the module docstring)."""

    metadata = {"render_modes": []}

    def __init__(
        self,
        vessel_seed: Optional[int] = None,
        target_branch: Optional[int] = None,
        **settings: Any,
    ):
        """``vessel_seed`` fixes the anatomy (drawn per reset from the reset's seed when
        ``None``), ``target_branch`` the target (likewise). ``settings``: ``elements`` (96),
        ``triangles`` of the vessel (8000), ``dt`` (1e-3 s), ``substeps`` per environment step
        (10), ``wire_length`` (0.6 m), ``young_modulus`` (5e6 Pa), ``radius`` (0.4 mm),
        ``friction`` ((0.08, 0.05)), ``max_push_speed`` (0.1 m/s), ``max_twist_rate``
        (2π rad/s), ``samples`` of the distal wire (8), ``observe_force`` (False),
        ``wall_force_penalty`` (0.1 per N), ``success_reward`` (10), ``failure_penalty`` (10),
        ``backend`` ("cpu")."""
        super().__init__()
        self.vessel_seed = vessel_seed
        self.target_branch = target_branch
        self.settings = _Settings(**settings)
        self.observation_space = self.settings.observation_space()
        self.action_space = self.settings.action_space()
        self.sim: Optional[cosserat.Simulation] = None

    # -- episode set-up ----------------------------------------------------------------------

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict[str, Any]] = None):
        super().reset(seed=seed)
        vessel_seed = (
            self.vessel_seed
            if self.vessel_seed is not None
            else int(self.np_random.integers(0, 2**31 - 1))
        )
        st = self.settings
        self.sim = cosserat.Simulation.from_toml(st.scene(vessel_seed), backend=st.backend, name="navigation.toml")
        vessel = self.sim.vessel()
        self.entry = np.asarray(vessel["entry_point"])
        self.axis = np.asarray(vessel["entry_direction"])
        branch = (
            self.target_branch
            if self.target_branch is not None
            else int(self.np_random.integers(0, len(vessel["branches"])))
        )
        self.route = _Route(vessel, branch)
        self.progress = self.route.progress(self.sim.positions()[-1])
        info = {"vessel_seed": vessel_seed, "target_branch": branch, "path_length": self.route.length}
        return self._observation(), info

    def _observation(self) -> np.ndarray:
        force = None
        if self.settings.observe_force:
            reaction = self.sim.end_reaction(0)
            force = reaction[0] if reaction is not None else np.zeros(3)
        return _observation(self.route, self.entry, self.sim.positions(), self.settings.samples, force)

    def step(self, action):
        st = self.settings
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        self.sim.set_end_velocity(0, a[0] * st.max_push_speed * self.axis, a[1] * st.max_twist_rate * self.axis)
        failed = None
        try:
            self.sim.run(st.substeps)
        except cosserat.StepError as e:
            failed = str(e)
        tip = self.sim.positions()[-1]
        progress = self.route.progress(tip)
        forces = self.sim.contacts()[2]
        wall = float(np.linalg.norm(forces, axis=1).sum()) if len(forces) else 0.0
        stats = self.sim.collision_stats()
        if failed is None and stats is not None and stats["escaped_points"] > 0:
            failed = f"{stats['escaped_points']} points of the wire left the lumen"
        reached = self.route.reached(tip)
        reward = st.reward(self.progress, progress, wall, reached, failed is not None)
        self.progress = progress
        info = {"progress": progress, "path_length": self.route.length, "wall_force": wall, "reached": reached}
        if failed is not None:
            info["failure"] = failed
        return self._observation(), reward, reached or failed is not None, False, info


class GuidewireNavigationVectorEnv(gym.vector.VectorEnv):
    """``num_envs`` copies of the navigation task in one anatomy, stepped together in one call
    (``cosserat.Batch``: in parallel, the GIL released): the vector environment of
    ``GuidewireNavigationEnv``, with next-step autoreset (a copy that ended is reset by the next
    ``step``, which ignores its action and returns its first observation with reward 0).

    Every copy has its own target branch, drawn per episode from the vector environment's seed
    unless ``target_branch`` fixes it; ``max_episode_steps`` truncates episodes. The other
    settings are those of ``GuidewireNavigationEnv``.
    """

    metadata = {"render_modes": [], "autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int,
        vessel_seed: int = 0,
        target_branch: Optional[int] = None,
        max_episode_steps: int = 1000,
        **settings: Any,
    ):
        self.num_envs = num_envs
        self.settings = st = _Settings(**settings)
        self.single_observation_space = st.observation_space()
        self.single_action_space = st.action_space()
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)
        self.vessel_seed = vessel_seed
        self.target_branch = target_branch
        self.max_episode_steps = max_episode_steps
        self.batch = cosserat.Batch.from_toml(st.scene(vessel_seed), num_envs, backend=st.backend, name="navigation.toml")
        self.initial = self.batch.snapshot(0)
        self.vessel = self.batch.vessel()
        self.entry = np.asarray(self.vessel["entry_point"])
        self.axis = np.asarray(self.vessel["entry_direction"])
        self.routes: list[_Route] = [None] * num_envs  # type: ignore[list-item]
        self.progress = np.zeros(num_envs)
        self.elapsed = np.zeros(num_envs, dtype=np.int64)
        self.escaped = np.zeros(num_envs, dtype=np.int64)
        self.needs_reset = np.zeros(num_envs, dtype=bool)
        self._np_random = np.random.default_rng()

    def vessel_info(self) -> dict:
        """The shared anatomy (``Batch.vessel``)."""
        return self.vessel

    def _start(self, c: int, p: np.ndarray) -> None:
        """Copy `c` at its first state (points `p`), with a new target."""
        self.batch.restore(c, self.initial)
        branch = (
            self.target_branch
            if self.target_branch is not None
            else int(self._np_random.integers(0, len(self.vessel["branches"])))
        )
        self.routes[c] = _Route(self.vessel, branch)
        self.progress[c] = self.routes[c].progress(p[-1])
        self.elapsed[c] = 0
        self.needs_reset[c] = False

    def _observations(self, positions: np.ndarray) -> np.ndarray:
        forces = self.batch.end_reactions(0)[0] if self.settings.observe_force else None
        return np.stack(
            [
                _observation(self.routes[c], self.entry, positions[c], self.settings.samples,
                             None if forces is None else np.nan_to_num(forces[c]))
                for c in range(self.num_envs)
            ]
        )

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict[str, Any]] = None):
        if seed is not None:
            self._np_random = np.random.default_rng(seed)
        initial = self.batch.positions()[0]
        for c in range(self.num_envs):
            self._start(c, initial)
        _, self.escaped[:] = self.batch.wall_contact()
        positions = self.batch.positions()
        return self._observations(positions), {"target_branch": np.array([r.branch for r in self.routes])}

    def step(self, actions):
        st = self.settings
        a = np.clip(np.asarray(actions, dtype=np.float64).reshape(self.num_envs, 2), -1.0, 1.0)
        restarted = self.needs_reset.copy()
        if restarted.any():
            for c in np.flatnonzero(restarted):
                self.batch.restore(int(c), self.initial)
            start = self.batch.positions()
            for c in np.flatnonzero(restarted):
                self._start(int(c), start[c])
            a[restarted] = 0.0
        self.batch.set_end_velocity(
            0, (a[:, 0] * st.max_push_speed)[:, None] * self.axis, (a[:, 1] * st.max_twist_rate)[:, None] * self.axis
        )
        errors = self.batch.run(st.substeps)
        positions = self.batch.positions()
        wall, escaped = self.batch.wall_contact()
        rewards = np.zeros(self.num_envs)
        terminated = np.zeros(self.num_envs, dtype=bool)
        truncated = np.zeros(self.num_envs, dtype=bool)
        reached = np.zeros(self.num_envs, dtype=bool)
        for c in range(self.num_envs):
            if restarted[c]:
                continue
            tip = positions[c][-1]
            route = self.routes[c]
            progress = route.progress(tip)
            failed = errors[c] is not None or escaped[c] > self.escaped[c]
            reached[c] = route.reached(tip)
            rewards[c] = st.reward(self.progress[c], progress, float(wall[c]), bool(reached[c]), failed)
            self.progress[c] = progress
            self.elapsed[c] += 1
            terminated[c] = reached[c] or failed
            truncated[c] = not terminated[c] and self.elapsed[c] >= self.max_episode_steps
        self.escaped[:] = escaped
        self.needs_reset = terminated | truncated
        infos = {"progress": self.progress.copy(), "reached": reached, "wall_force": np.asarray(wall)}
        return self._observations(positions), rewards, terminated, truncated, infos


def register_envs() -> None:
    """Registers ``cosserat/GuidewireNavigation-v0`` (1000 steps: 10 s of simulated time)."""
    if ENV_ID not in gym.registry:
        gym.register(
            id=ENV_ID,
            entry_point="cosserat.gym:GuidewireNavigationEnv",
            max_episode_steps=1000,
            vector_entry_point="cosserat.gym:GuidewireNavigationVectorEnv",
        )


register_envs()
