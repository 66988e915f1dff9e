"""Parameter sweeps of a scene on a Ray cluster (``pip install "cosserat[distributed]"``).

:func:`sweep` runs one simulation per design point (a grid of override values, or seeded random
samples) in Ray tasks of ``per_task`` points each, and collects one summary row per point::

    from cosserat.distributed import sweep
    table = sweep("scenes/pendulum.toml",
                  {"rod.0.material.young_modulus": [1e5, 1e6, 1e7], "solver.gravity": ["[0, 0, -9.81]"]},
                  out="runs/pendulum-sweep", duration=0.1)
    table["rod0_tip_z"]       # one NumPy column per field, one entry per design point

It runs the same on a laptop (``ray.init()`` or nothing: Ray starts a local cluster) and on a
cluster: the scene goes to the tasks as text, and only the driver touches ``out``.

Fault tolerance. A task returns its rows instead of writing them; the driver waits for tasks
as they finish (``ray.wait``) and writes each chunk's rows as its own part file,
``out/part-NNNNNN.json`` named by the chunk's index, atomically (a temporary file, then
``os.replace``). So:

- a worker that dies takes nothing with it but its running task, which Ray runs again
  (``max_retries``); the retried chunk's rows are written under the same name, once;
- a sweep run again with the same ``out`` loads the parts that exist and runs only the missing
  chunks (resume after an interrupted driver, or after deleting a part to recompute it);
  ``out/sweep.json`` records what the sweep was, and a different sweep in the same ``out`` is
  refused rather than mixed;
- a run that diverges, or a design point the scene refuses, is a row whose ``error`` holds the
  message (empty otherwise), not a failed sweep. A chunk that fails otherwise (an exception in
  ``summary``, a task out of retries) leaves no part; the others are written, and the sweep
  raises at the end naming the failed chunks, so running it again finishes only those.

At the end the parts are combined into ``out/results.parquet`` (with pyarrow) or
``out/results.npz`` (without), and :func:`sweep` returns the same table as a dict of NumPy
columns in design-point order.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence, Union

import numpy as np

import cosserat

__all__ = ["design_points", "read_parts", "run_point", "sweep"]

#: A value of ``parameters``: the values of a grid axis, or for ``design="random"`` a
#: ``(low, high)`` range, a list to choose from, or a function of a ``numpy.random.Generator``.
ParameterValues = Union[Sequence[Any], Callable[[np.random.Generator], Any]]
#: ``summary(sim, point)``: extra columns of a design point's row from its finished simulation.
Summary = Callable[["cosserat.Simulation", Mapping[str, Any]], Mapping[str, Any]]

#: Tip samples per run for ``trajectories=True``.
DEFAULT_TRAJECTORY_SAMPLES = 16


def design_points(
    parameters: Mapping[str, ParameterValues],
    design: str = "grid",
    samples: Optional[int] = None,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """The design points of a sweep, as override dicts in order (the index is the position).

    ``"grid"``: every combination of the listed values, the last key varying fastest.
    ``"random"``: ``samples`` points drawn with ``numpy.random.default_rng(seed)``; per key a
    ``(low, high)`` tuple draws uniformly (integers from ``low`` to ``high`` inclusive when both
    are ints), a list draws one of its values, a callable is called with the generator.
    """
    if not parameters:
        raise ValueError("parameters: expected at least one scene key to vary")
    for key in parameters:
        if not isinstance(key, str) or not key:
            raise ValueError(f"parameters: key {key!r} is not a scene key such as 'rod.0.elements'")
    if design == "grid":
        if samples is not None:
            raise ValueError(
                f"samples = {samples}: a grid has one point per combination; samples is for design='random'"
            )
        axes = []
        for key, values in parameters.items():
            if callable(values) or isinstance(values, (str, bytes)) or not isinstance(values, (Sequence, np.ndarray)):
                raise ValueError(f"parameters[{key!r}] = {values!r}: a grid takes a list of values")
            if len(values) == 0:
                raise ValueError(f"parameters[{key!r}]: the list of values is empty")
            axes.append([_plain(v) for v in values])
        return [dict(zip(parameters, combo)) for combo in itertools.product(*axes)]
    if design == "random":
        if samples is None or int(samples) < 1:
            raise ValueError(f"samples = {samples!r}: design='random' needs samples >= 1")
        rng = np.random.default_rng(seed)
        draws = {key: _sampler(key, values) for key, values in parameters.items()}
        return [{key: _plain(draw(rng)) for key, draw in draws.items()} for _ in range(int(samples))]
    raise ValueError(f"design = {design!r}: expected 'grid' or 'random'")


def _sampler(key: str, values: ParameterValues) -> Callable[[np.random.Generator], Any]:
    if callable(values):
        return values
    if isinstance(values, tuple) and len(values) == 2 and all(_is_number(v) for v in values):
        low, high = values
        if not low <= high:
            raise ValueError(f"parameters[{key!r}] = {values!r}: expected low <= high")
        if all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in values):
            return lambda rng: int(rng.integers(low, high, endpoint=True))
        return lambda rng: float(rng.uniform(low, high))
    if isinstance(values, (list, np.ndarray)) and len(values) > 0:
        choices = list(values)
        return lambda rng: choices[int(rng.integers(len(choices)))]
    raise ValueError(
        f"parameters[{key!r}] = {values!r}: design='random' takes a (low, high) range, "
        "a non-empty list to choose from, or a function of a numpy Generator"
    )


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _plain(v: Any) -> Any:
    """A NumPy scalar as the Python scalar it holds (JSON and the scene reader take those)."""
    return v.item() if isinstance(v, np.generic) else v


def run_point(
    scene_text: str,
    name: str,
    index: int,
    point: Mapping[str, Any],
    *,
    backend: str = "cpu",
    duration: Optional[float] = None,
    summary: Optional[Summary] = None,
    trajectory_samples: int = 0,
) -> dict[str, Any]:
    """One design point's row: builds the scene with ``point`` as overrides, runs it for its
    run length (``duration`` seconds when given) and measures it. A scene that refuses the
    point, or a run that diverges, gives a row whose ``error`` names why."""
    row: dict[str, Any] = {"index": index, **point}
    overrides = dict(point)
    if duration is not None:
        overrides["solver.duration"] = float(duration)
    start = time.perf_counter()
    error = ""
    samples: list[list[list[float]]] = []
    sim = None
    try:
        sim = cosserat.Simulation.from_toml(scene_text, overrides, backend=backend, name=name)
        total = sim.scene_steps
        if trajectory_samples > 0:
            done = 0
            for j in range(trajectory_samples):
                target = round((j + 1) * total / trajectory_samples)
                sim.run(target - done)
                done = target
                samples.append(_tips(sim))
        else:
            sim.run(total)
    except (cosserat.SceneError, cosserat.StepError, cosserat.ControlError) as e:
        error = f"{type(e).__name__}: {e}"
    row["wall_seconds"] = time.perf_counter() - start
    row["steps"] = sim.steps if sim is not None else 0
    row["error"] = error
    if sim is not None:
        row.update(_measure(sim))
        if summary is not None:
            row.update({k: _plain(v) for k, v in summary(sim, {"index": index, **point}).items()})
        if trajectory_samples > 0:
            nan = [[math.nan] * 3] * len(sim.rod_names)
            row["trajectory"] = samples + [nan] * (trajectory_samples - len(samples))
    return row


def _tips(sim: "cosserat.Simulation") -> list[list[float]]:
    return [[float(x) for x in sim.positions(r)[-1]] for r in range(len(sim.rod_names))]


def _measure(sim: "cosserat.Simulation") -> dict[str, Any]:
    """Each rod's tip and hand force, the deepest penetration and the escaped points."""
    out: dict[str, Any] = {}
    penetration, escaped = math.nan, 0
    for r in range(len(sim.rod_names)):
        for axis, x in zip("xyz", sim.positions(r)[-1]):
            out[f"rod{r}_tip_{axis}"] = float(x)
        force = math.nan
        for end in (0, 1):
            reaction = sim.end_reaction(end, rod=r)
            if reaction is not None:
                force = float(np.linalg.norm(reaction[0]))
                break
        out[f"rod{r}_hand_force"] = force
        stats = sim.collision_stats(r)
        if stats is not None:
            penetration = max(stats["max_penetration"], 0.0 if math.isnan(penetration) else penetration)
            escaped += int(stats["escaped_points"])
    out["max_penetration"] = penetration
    out["escaped_points"] = escaped
    return out


def _run_chunk(
    scene_text: str,
    name: str,
    first: int,
    points: list[dict[str, Any]],
    options: dict[str, Any],
) -> list[dict[str, Any]]:
    """A Ray task: the rows of design points ``first, first + 1, ...``."""
    return [run_point(scene_text, name, first + i, p, **options) for i, p in enumerate(points)]


def _scene(scene: Union[str, os.PathLike]) -> tuple[str, str]:
    """``(text, name)`` of a scene given as a path or as TOML text."""
    if isinstance(scene, os.PathLike) or ("\n" not in scene and (scene.endswith(".toml") or Path(scene).is_file())):
        path = Path(scene)
        try:
            return path.read_text(), str(path.resolve())
        except OSError as e:
            raise cosserat.SceneError(f"{path}: {e}") from e
    return scene, "scene.toml"


def _part(out: Path, chunk: int) -> Path:
    return out / f"part-{chunk:06d}.json"


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def read_parts(out: Union[str, os.PathLike]) -> list[dict[str, Any]]:
    """The rows of every part file in ``out``, in design-point order."""
    rows = [row for part in sorted(Path(out).glob("part-*.json")) for row in json.loads(part.read_text())]
    return sorted(rows, key=lambda r: r["index"])


def _columns(rows: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    """Rows as NumPy columns: a field missing from a row (a point the scene refused has no
    measurements) is NaN, or an empty string in a text column."""
    names: dict[str, None] = {}
    for row in rows:
        names.update(dict.fromkeys(row))
    columns = {}
    for name in names:
        values = [row.get(name) for row in rows]
        present = [v for v in values if v is not None]
        if name == "trajectory" and present:
            shape = np.shape(present[0])
            columns[name] = np.array([v if v is not None else np.full(shape, np.nan) for v in values], dtype=float)
        elif all(isinstance(v, str) for v in present):
            columns[name] = np.array(["" if v is None else v for v in values], dtype=str)
        elif all(isinstance(v, (int, bool)) for v in present) and len(present) == len(values):
            columns[name] = np.array(values)
        else:
            columns[name] = np.array([math.nan if v is None else v for v in values], dtype=float)
    return columns


def _save(out: Path, columns: dict[str, np.ndarray]) -> Path:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        path = out / "results.npz"
        tmp = out / ".results.tmp.npz"
        np.savez(tmp, **columns)
        os.replace(tmp, path)
        return path
    arrays = {k: (pa.array(v.tolist()) if v.ndim > 1 else pa.array(v)) for k, v in columns.items()}
    path = out / "results.parquet"
    tmp = out / ".results.tmp.parquet"
    pq.write_table(pa.table(arrays), tmp)
    os.replace(tmp, path)
    return path


class _Progress:
    """One line on stderr per finished chunk (at most one a second, and the last)."""

    def __init__(self, enabled: bool, total: int, done: int):
        self.enabled, self.total, self.done = enabled, total, done
        self.errors, self.start, self.shown, self.fresh = 0, time.perf_counter(), 0.0, 0

    def add(self, rows: list[dict[str, Any]]) -> None:
        self.done += len(rows)
        self.fresh += len(rows)
        self.errors += sum(1 for r in rows if r["error"])
        now = time.perf_counter()
        if self.enabled and (now - self.shown >= 1.0 or self.done == self.total):
            self.shown = now
            rate = self.fresh / max(now - self.start, 1e-9)
            print(
                f"sweep: {self.done}/{self.total} design points, {self.errors} with errors, {rate:.1f} points/s",
                file=sys.stderr,
                flush=True,
            )


def sweep(
    scene: Union[str, os.PathLike],
    parameters: Mapping[str, ParameterValues],
    *,
    out: Union[str, os.PathLike],
    design: str = "grid",
    samples: Optional[int] = None,
    seed: int = 0,
    per_task: int = 8,
    backend: str = "cpu",
    duration: Optional[float] = None,
    summary: Optional[Summary] = None,
    trajectories: Union[bool, int] = False,
    progress: bool = True,
    max_retries: int = 3,
) -> dict[str, np.ndarray]:
    """Runs ``scene`` (a TOML file's path, or TOML text) at every design point of
    ``parameters`` on Ray and returns one row per point as a dict of NumPy columns, in
    design-point order (also written to ``out/results.parquet``, or ``results.npz`` without
    pyarrow). See the module docstring for how a sweep survives failures and resumes.

    ``parameters`` maps scene override keys (those of ``Simulation.from_file``, e.g.
    ``"rod.0.material.young_modulus"`` or ``"solver.dt"``) to values (:func:`design_points`).
    ``per_task`` design points run in one task, one simulation each, on ``backend``, for the
    scene's run length or ``duration`` seconds. ``summary(sim, point)`` adds columns from each
    finished simulation; ``trajectories`` (``True`` or a number of samples) adds
    ``trajectory``, every rod's tip at evenly spaced times, shape ``(points, samples, rods, 3)``
    (the last sample at the end of the run; NaN after a failure).

    Columns: ``index``; one per parameter; ``rod{r}_tip_x|y|z`` (the last point of rod ``r``
    at the end); ``rod{r}_hand_force`` (the reaction at its first held end [N], NaN where the
    backend has none or no end is held); ``max_penetration`` [m] (NaN without mesh contact)
    and ``escaped_points`` over all rods; ``steps`` completed; ``wall_seconds`` (building and
    running); ``error`` (``"StepError: ..."`` and the like, empty for a run that completed);
    then those of ``summary``.
    """
    try:
        import ray
    except ImportError as e:
        raise ImportError('cosserat.distributed needs Ray: pip install "cosserat[distributed]"') from e
    if int(per_task) < 1:
        raise ValueError(f"per_task = {per_task}: expected at least 1 design point per task")
    if int(max_retries) < 0:
        raise ValueError(f"max_retries = {max_retries}: expected 0 or more")
    if duration is not None and not (isinstance(duration, (int, float)) and duration > 0):
        raise ValueError(f"duration = {duration!r}: expected a number of seconds > 0")
    samples_per_run = DEFAULT_TRAJECTORY_SAMPLES if trajectories is True else int(trajectories)
    if samples_per_run < 0:
        raise ValueError(f"trajectories = {trajectories!r}: expected True, False or a number of samples > 0")
    text, name = _scene(scene)
    points = design_points(parameters, design, samples, seed)
    per_task = int(per_task)
    chunks = [points[i : i + per_task] for i in range(0, len(points), per_task)]
    options = {"backend": backend, "duration": duration, "summary": summary, "trajectory_samples": samples_per_run}

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    manifest = {
        "scene_sha256": hashlib.sha256(text.encode()).hexdigest(),
        "scene": name,
        "design_sha256": hashlib.sha256(json.dumps(points, sort_keys=True).encode()).hexdigest(),
        "points": len(points),
        "per_task": per_task,
        "backend": backend,
        "duration": duration,
        "trajectory_samples": samples_per_run,
        "summary": None if summary is None else getattr(summary, "__qualname__", repr(summary)),
    }
    manifest_path = out / "sweep.json"
    if manifest_path.exists():
        previous = json.loads(manifest_path.read_text())
        if previous != manifest:
            changed = sorted(k for k in manifest if previous.get(k) != manifest[k])
            raise ValueError(
                f"out = {str(out)!r} holds the parts of a different sweep (it differs in {', '.join(changed)}); "
                "use another directory, or delete this one to start again"
            )
    else:
        _write_atomic(manifest_path, json.dumps(manifest, indent=1))

    todo = [c for c in range(len(chunks)) if not _part(out, c).exists()]
    shown = _Progress(progress, len(points), len(points) - sum(len(chunks[c]) for c in todo))
    failed: dict[int, BaseException] = {}
    if todo:
        if not ray.is_initialized():
            ray.init()
        task = ray.remote(_run_chunk).options(max_retries=int(max_retries), retry_exceptions=False)
        scene_ref = ray.put(text)
        pending = {task.remote(scene_ref, name, c * per_task, chunks[c], options): c for c in todo}
        while pending:
            # Whatever finished within a moment, so that a sweep of many small chunks does not
            # pass its whole list of tasks to Ray once per chunk.
            ready, _ = ray.wait(list(pending), num_returns=len(pending), timeout=0.2)
            for ref in ready:
                chunk = pending.pop(ref)
                try:
                    rows = ray.get(ref)
                except Exception as e:  # a chunk out of retries, or a summary that raised
                    failed[chunk] = e
                    continue
                _write_atomic(_part(out, chunk), json.dumps(rows))
                shown.add(rows)
    if failed:
        first = min(failed)
        raise RuntimeError(
            f"{len(failed)} of {len(chunks)} chunks failed (chunks {sorted(failed)}; the parts of the others are in "
            f"{out}, so running the sweep again runs only these). Chunk {first}: {failed[first]}"
        )
    rows = read_parts(out)
    if [r["index"] for r in rows] != list(range(len(points))):
        raise RuntimeError(f"{out}: the part files do not hold design points 0..{len(points)} once each")
    columns = _columns(rows)
    _save(out, columns)
    return columns
