"""Parameter sweeps on a local Ray cluster (`cosserat.distributed`): complete rows equal to a
direct run, a worker killed mid-sweep, and a resumed sweep that runs only the missing chunk
(skipped without Ray)."""

import json
import os
import pathlib
import sys

import numpy as np
import pytest

ray = pytest.importorskip("ray")

import cosserat  # noqa: E402
from cosserat.distributed import design_points, sweep  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
PENDULUM = ROOT / "scenes" / "pendulum.toml"
DURATION = 0.01
# 2 × 3 points; 4 per task: chunk 0 has points 0-3, chunk 1 points 4 and 5.
PARAMETERS = {
    "rod.0.elements": [8, 10],
    "rod.0.material.young_modulus": [1.0e5, 1.0e6, 1.0e7],
}


@pytest.fixture(scope="module", autouse=True)
def local_cluster():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def counting(directory):
    """A summary that leaves one file per call, named by the design point."""

    def summary(sim, point):
        (directory / f"ran-{point['index']}-{os.getpid()}-{os.urandom(4).hex()}").touch()
        return {"energy": sum(sim.energies().values())}

    return summary


def runs(directory):
    counts = {}
    for f in directory.glob("ran-*"):
        i = int(f.name.split("-")[1])
        counts[i] = counts.get(i, 0) + 1
    return counts


def test_a_grid_sweep_gives_one_complete_row_per_point_equal_to_a_direct_run(tmp_path):
    table = sweep(
        PENDULUM, PARAMETERS, out=tmp_path / "out", per_task=4, duration=DURATION, trajectories=3, progress=False
    )
    points = design_points(PARAMETERS)
    assert len(points) == 6
    assert list(table["index"]) == list(range(6))
    assert list(table["rod.0.elements"]) == [p["rod.0.elements"] for p in points]
    assert list(table["error"]) == [""] * 6
    assert np.all(table["steps"] == round(DURATION / 2e-5))
    for column in ("rod0_tip_x", "rod0_tip_z", "rod0_hand_force", "wall_seconds"):
        assert np.all(np.isfinite(table[column])), column
    # No mesh in the scene: nothing measured.
    assert np.all(np.isnan(table["max_penetration"])) and np.all(table["escaped_points"] == 0)
    assert table["trajectory"].shape == (6, 3, 1, 3)
    # Stiffer cords sag less.
    assert table["rod0_tip_z"][2] > table["rod0_tip_z"][0]
    # Design point 4 again, directly: the very same numbers.
    sim = cosserat.Simulation.from_file(PENDULUM, {**points[4], "solver.duration": DURATION})
    sim.run()
    tip = sim.positions()[-1]
    assert [table[f"rod0_tip_{a}"][4] for a in "xyz"] == list(tip)
    assert np.array_equal(table["trajectory"][4, -1, 0], tip)
    assert table["rod0_hand_force"][4] == np.linalg.norm(sim.end_reaction(0)[0])
    # The table on disk is the returned one.
    pq = pytest.importorskip("pyarrow.parquet")
    disk = pq.read_table(tmp_path / "out" / "results.parquet").to_pydict()
    assert disk["rod0_tip_x"] == list(table["rod0_tip_x"])
    assert sorted(p.name for p in (tmp_path / "out").glob("part-*")) == ["part-000000.json", "part-000001.json"]


def test_diverged_runs_and_refused_points_are_rows_with_their_errors(tmp_path):
    # A step 100 times the stable one: refused by the stability check, or run until it diverges.
    table = sweep(
        PENDULUM,
        {"solver.check_stability": [True, False], "solver.dt": [2e-5, 2e-3]},
        out=tmp_path,
        per_task=1,
        duration=0.05,
        progress=False,
    )
    assert list(table["error"][[0, 2]]) == ["", ""]
    assert table["error"][1].startswith("SceneError: ") and "stability limit" in table["error"][1]
    assert table["steps"][1] == 0 and np.isnan(table["rod0_tip_x"][1])
    assert table["error"][3].startswith("StepError: ") and "diverged" in table["error"][3]
    assert 0 < table["steps"][3] < 25


def test_a_worker_killed_mid_sweep_loses_no_row_and_duplicates_none(tmp_path):
    marker = tmp_path / "killed"

    def dies_once(sim, point):
        # The worker running design point 2 dies on the first attempt; Ray runs the chunk again.
        if point["index"] == 2 and not marker.exists():
            marker.touch()
            os._exit(1)
        return {}

    out = tmp_path / "out"
    table = sweep(PENDULUM, PARAMETERS, out=out, per_task=2, duration=DURATION, summary=dies_once, progress=False)
    assert marker.exists()
    assert list(table["index"]) == list(range(6))
    rows = [row for part in sorted(out.glob("part-*.json")) for row in json.loads(part.read_text())]
    assert sorted(r["index"] for r in rows) == list(range(6))


def test_a_resumed_sweep_runs_only_the_missing_chunk(tmp_path):
    out = tmp_path / "out"
    summary = counting(tmp_path)
    first = sweep(PENDULUM, PARAMETERS, out=out, per_task=4, duration=DURATION, summary=summary, progress=False)
    assert runs(tmp_path) == {i: 1 for i in range(6)}
    (out / "part-000001.json").unlink()
    again = sweep(PENDULUM, PARAMETERS, out=out, per_task=4, duration=DURATION, summary=summary, progress=False)
    # Points 4 and 5 (chunk 1) ran again, the others were read back.
    assert runs(tmp_path) == {0: 1, 1: 1, 2: 1, 3: 1, 4: 2, 5: 2}
    assert again.keys() == first.keys()
    for name in first:
        if name != "wall_seconds":
            assert np.array_equal(first[name], again[name], equal_nan=first[name].dtype.kind == "f"), name
    # Another sweep in the same directory is refused, not mixed in.
    with pytest.raises(ValueError, match="holds the parts of a different sweep"):
        sweep(PENDULUM, PARAMETERS, out=out, per_task=3, duration=DURATION, progress=False)


def test_random_designs_are_seeded_and_bad_parameters_are_named():
    ranges = {
        "rod.0.elements": (8, 12),
        "rod.0.material.young_modulus": (1e5, 1e6),
        "solver.iterations": [5, 10],
        "rod.0.damping.drag": lambda rng: rng.choice([0.0, 1.0]),
    }
    a = design_points(ranges, "random", samples=20, seed=3)
    assert a == design_points(ranges, "random", samples=20, seed=3)
    assert a != design_points(ranges, "random", samples=20, seed=4)
    assert all(8 <= p["rod.0.elements"] <= 12 and isinstance(p["rod.0.elements"], int) for p in a)
    assert all(1e5 <= p["rod.0.material.young_modulus"] <= 1e6 for p in a)
    with pytest.raises(ValueError, match=r"parameters\['rod.0.elements'\] = 8: a grid takes a list"):
        design_points({"rod.0.elements": 8})
    with pytest.raises(ValueError, match="samples = None: design='random' needs samples"):
        design_points({"rod.0.elements": (8, 12)}, "random")
    with pytest.raises(ValueError, match="design = 'sobol'"):
        design_points({"rod.0.elements": [8]}, "sobol")


def test_without_pyarrow_the_table_is_written_as_npz_and_progress_goes_to_stderr(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # `import pyarrow` now raises ImportError
    table = sweep(PENDULUM, PARAMETERS, out=tmp_path, per_task=3, duration=DURATION)
    assert not (tmp_path / "results.parquet").exists()
    with np.load(tmp_path / "results.npz") as disk:
        assert sorted(disk.files) == sorted(table)
        assert np.array_equal(disk["rod0_tip_z"], table["rod0_tip_z"])
        assert list(disk["error"]) == [""] * 6
    assert "sweep: 6/6 design points, 0 with errors" in capsys.readouterr().err
