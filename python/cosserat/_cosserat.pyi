"""Type stubs of the native module (``python/src/lib.rs``)."""

from os import PathLike
from typing import Any, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

class SceneError(ValueError):
    """A scene that cannot be read or built; the message names the file, field and value."""

class StepError(RuntimeError):
    """A run that diverged (naming the rod, element and step) or was refused."""

class ControlError(ValueError):
    """A control call that was refused; nothing was changed."""

class Snapshot:
    """A state of a :class:`Simulation`, to return to with :meth:`Simulation.restore`."""

    @property
    def time(self) -> float: ...

class Simulation:
    """A simulation of one or more Cosserat rods."""

    @staticmethod
    def from_file(
        path: str | PathLike[str],
        overrides: Optional[Mapping[str, Any]] = None,
        backend: str = "cpu",
    ) -> Simulation:
        """Builds the scene in a TOML file; ``overrides`` maps dotted keys to values
        (``{"rod.elements": 100}``), ``backend`` is ``"cpu"``, ``"cpu-rayon"`` or ``"gpu"``."""
    @staticmethod
    def from_toml(
        text: str,
        overrides: Optional[Mapping[str, Any]] = None,
        backend: str = "cpu",
        name: str = "scene.toml",
    ) -> Simulation:
        """Builds a scene from TOML text."""
    def step(self) -> None:
        """Takes one step."""
    def run(self, steps: Optional[int] = None) -> None:
        """Takes ``steps`` steps (the scene's run length when ``None``), GIL released."""
    @property
    def name(self) -> str: ...
    @property
    def time(self) -> float: ...
    @property
    def dt(self) -> float: ...
    @property
    def steps(self) -> int: ...
    @property
    def scene_steps(self) -> int: ...
    @property
    def backend(self) -> str: ...
    @property
    def rod_names(self) -> list[str]: ...
    @property
    def warnings(self) -> list[str]: ...
    def elements(self, rod: int = 0) -> int: ...
    def positions(self, rod: int = 0) -> npt.NDArray[np.float64]:
        """Centreline points, shape ``(n + 1, 3)`` [m]."""
    def velocities(self, rod: int = 0) -> npt.NDArray[np.float64]:
        """Point velocities, shape ``(n + 1, 3)`` [m/s]."""
    def angular_velocities(self, rod: int = 0) -> npt.NDArray[np.float64]:
        """Frame angular velocities in body axes, shape ``(n, 3)`` [rad/s]."""
    def frames(self, rod: int = 0) -> npt.NDArray[np.float64]:
        """Frames as unit quaternions ``[w, x, y, z]`` (body to world), shape ``(n, 4)``."""
    def directors(self, rod: int = 0) -> npt.NDArray[np.float64]:
        """Directors in world axes, shape ``(n, 3, 3)``: ``[j, k]`` is ``d_{k+1}`` of frame ``j``."""
    def set_positions(self, values: npt.ArrayLike, rod: int = 0) -> None: ...
    def set_velocities(self, values: npt.ArrayLike, rod: int = 0) -> None: ...
    def set_angular_velocities(self, values: npt.ArrayLike, rod: int = 0) -> None: ...
    def set_frames(self, values: npt.ArrayLike, rod: int = 0) -> None: ...
    def set_end_velocity(
        self,
        end: int,
        velocity: Sequence[float],
        angular_velocity: Sequence[float] = (0.0, 0.0, 0.0),
        rod: int = 0,
    ) -> None:
        """Drives a held end at a constant velocity and angular velocity (world axes)."""
    def move_end_to(
        self,
        end: int,
        position: Sequence[float],
        duration: float,
        frame: Optional[Sequence[float]] = None,
        rod: int = 0,
    ) -> None:
        """Moves a held end to ``position`` (and frame) in ``duration`` seconds."""
    def hold_end(self, end: int, kind: str, rod: int = 0) -> None:
        """Holds an end as ``"free"``, ``"pinned"`` or ``"clamped"``."""
    def set_loads(
        self,
        loads: Sequence[
            Union[
                Tuple[int, Sequence[float]],
                Tuple[int, Sequence[float], Sequence[float]],
            ]
        ],
        rod: int = 0,
    ) -> None:
        """Replaces the point loads: ``[(point, (fx, fy, fz)), ...]`` [N], or
        ``(point, force, (mx, my, mz))`` with a moment [N m] (explicit scheme)."""
    def set_end_path(
        self,
        end: int,
        times: Sequence[float],
        displacement: Optional[Sequence[Sequence[float]]] = None,
        rotation: Optional[Sequence[Sequence[float]]] = None,
        rod: int = 0,
    ) -> None:
        """Drives a held end along keyframes from now: displacement [m] and rotation vector
        [rad] at each time [s from now], zero at the first (0), linear between, held after."""
    def slide_end(self, end: int, axis: Optional[Sequence[float]], rod: int = 0) -> None:
        """Lets a held end slide freely along ``axis`` (world), or holds it again with ``None``."""
    def set_obstacle_path(
        self,
        obstacle: int,
        times: Optional[Sequence[float]] = None,
        displacement: Optional[Sequence[Sequence[float]]] = None,
        rotation: Optional[Sequence[Sequence[float]]] = None,
    ) -> None:
        """Moves a half-space or cylinder obstacle along keyframes from now on, or stops it with ``None``."""
    def hinge_end(self, end: int, axis: Optional[Sequence[float]], rod: int = 0) -> None:
        """Lets a clamp turn freely about ``axis`` (world), or holds its frame again with ``None``."""
    def end_reaction(
        self, end: int, rod: int = 0
    ) -> Optional[Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]:
        """``(force, torque)`` the holder applies to the rod, world axes; ``None`` if free."""
    def contacts(
        self, rod: int = 0
    ) -> Tuple[npt.NDArray[np.uint64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``(points, normals, forces)`` of the last step's contacts."""
    def energies(self) -> dict[str, float]: ...
    def snapshot(self) -> Snapshot: ...
    def restore(self, snapshot: Snapshot) -> None: ...
    def collision_stats(self, rod: int = 0) -> Optional[dict[str, float]]:
        """Contact measurements since the start; ``None`` without mesh contact."""
    def vessel(self) -> Optional[dict[str, Any]]:
        """The generated vessel: ``entry_point``, ``entry_direction``, ``trunk`` and
        ``branches`` as ``(points, radii)``; ``None`` for other environments."""

class Batch:
    """Copies of one scene stepped together (GIL released), as arrays with a leading copy axis.

    ``layout="simulations"`` holds one simulation per copy (stepped on rayon's pool; a copy that
    diverges stops alone), ``layout="copies"`` one simulation of all copies' rods (one dispatch
    on the GPU; a divergence stops every copy, and a copy's snapshot holds its rods' state and
    end conditions). The default is ``"copies"`` on the GPU, ``"simulations"`` on the CPU."""

    @staticmethod
    def from_file(
        path: str | PathLike[str],
        copies: int,
        overrides: Optional[Mapping[str, Any]] = None,
        backend: str = "cpu",
        *,
        layout: Optional[str] = None,
    ) -> Batch: ...
    @staticmethod
    def from_toml(
        text: str,
        copies: int,
        overrides: Optional[Mapping[str, Any]] = None,
        backend: str = "cpu",
        name: str = "scene.toml",
        *,
        layout: Optional[str] = None,
    ) -> Batch: ...
    def __len__(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def scene_steps(self) -> int: ...
    @property
    def layout(self) -> str:
        """``"simulations"`` or ``"copies"``."""
    @property
    def backend(self) -> str: ...
    @property
    def times(self) -> list[float]: ...
    def run(self, steps: Optional[int] = None) -> list[Optional[str]]:
        """Steps every copy; one entry per copy: ``None`` or the error that stopped it."""
    def positions(self, rod: int = 0) -> npt.NDArray[np.float64]:
        """Shape ``(copies, n + 1, 3)`` [m]."""
    def velocities(self, rod: int = 0) -> npt.NDArray[np.float64]:
        """Shape ``(copies, n + 1, 3)`` [m/s]."""
    def set_end_velocity(
        self,
        end: int,
        velocity: npt.ArrayLike,
        angular_velocity: Optional[npt.ArrayLike] = None,
        rod: int = 0,
    ) -> None:
        """Rows per copy, shape ``(copies, 3)`` or ``(1, 3)``."""
    def end_reactions(
        self, end: int, rod: int = 0
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``(forces, torques)``, each ``(copies, 3)``; NaN where there is none."""
    def wall_contact(
        self, rod: int = 0
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.uint64]]:
        """Per copy: summed contact force magnitude [N], points found beyond a wall."""
    def snapshot(self, copy: int) -> Snapshot: ...
    def restore(self, copy: int, snapshot: Snapshot) -> None: ...
    def vessel(self) -> Optional[dict[str, Any]]:
        """The generated vessel all copies share (as ``Simulation.vessel``)."""
