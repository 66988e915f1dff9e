"""Throughput of a parameter sweep on a local Ray cluster with 1 and with 2 workers.

A random design of short insertions (`scenes/stiff-guidewire-insertion.toml` shortened: 64
elements, a 2 000-triangle vessel, 0.3 s of pushing, i.e. 300 stiff steps of 1 ms) over the
wire's Young's modulus and drag, run by `cosserat.distributed.sweep` with `ray.init(num_cpus=1)`
and then `ray.init(num_cpus=2)`, each into a fresh output directory; design points per second
are the points over the sweep's wall time (Ray already started; the driver's combining of the
parts into `results.parquet` included). A plain loop over `run_point` in this process, without
Ray, gives the cost of one point for comparison. Prints a Markdown table of the sweeps (1 and 2
workers in turn, `--repeat` times) with the CPU share that processes other than the
benchmark's (driver, Ray's daemons and workers) took during each: the scaling figure is the
ratio of the medians over the sweeps where that share stayed under `--clean` percent, since a
sweep that shared the cores with something else measures that, not Ray.

    python python/bench/sweep.py [--points 10000] [--per-task 50] [--serial 500] [--repeat 1] [--clean 5]
"""

import argparse
import os
import pathlib
import platform
import statistics
import tempfile
import time

import ray

from cosserat.distributed import design_points, run_point, sweep

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "stiff-guidewire-insertion.toml"
DURATION = 0.3
# Ranges are drawn from; one-element lists are the shortening, the same at every point.
PARAMETERS = {
    "rod.0.elements": [64],
    "environment.mesh.triangles": [2000],
    "rod.0.material.young_modulus": (2.0e6, 1.0e7),
    "rod.0.damping.drag": (2.0, 10.0),
}


TICK = os.sysconf("SC_CLK_TCK")


def cpu_seconds():
    """Busy CPU seconds of the whole machine (`/proc/stat`), and of each of this benchmark's
    processes: the driver, Ray's daemons and its workers (Linux)."""
    with open("/proc/stat") as f:
        fields = [int(x) for x in f.readline().split()[1:]]
    busy = (sum(fields) - fields[3] - fields[4]) / TICK  # all but idle and iowait
    mine = {}
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmdline = f.read()
            with open(f"/proc/{pid}/stat") as f:
                stat = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(pid) == os.getpid() or b"ray" in cmdline:
            mine[pid] = (int(stat[11]) + int(stat[12])) / TICK  # utime, stime
    return busy, mine


def timed_sweep(workers, points, per_task, out):
    """Wall seconds of the sweep, and the CPU seconds other processes took meanwhile."""
    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    try:
        busy0, mine0 = cpu_seconds()
        start = time.perf_counter()
        table = sweep(
            SCENE,
            PARAMETERS,
            out=out,
            design="random",
            samples=points,
            seed=1,
            per_task=per_task,
            duration=DURATION,
            progress=False,
        )
        wall = time.perf_counter() - start
        busy1, mine1 = cpu_seconds()
    finally:
        ray.shutdown()
    assert len(table["index"]) == points and not any(table["error"]), "a run failed"
    others = (busy1 - busy0) - sum(t - mine0.get(pid, 0.0) for pid, t in mine1.items())
    return wall, others


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--per-task", type=int, default=50)
    ap.add_argument("--serial", type=int, default=500, help="points of the loop without Ray")
    ap.add_argument("--repeat", type=int, default=1, help="sweeps with 1 and with 2 workers, in turn")
    ap.add_argument("--clean", type=float, default=5.0, help="most CPU share [%%] of other processes in a kept sweep")
    args = ap.parse_args()
    cores = os.cpu_count()
    print(f"machine: {platform.processor() or platform.machine()}, {cores} cores, Python {platform.python_version()}")
    print(f"load average before: {os.getloadavg()}")

    points = design_points(PARAMETERS, "random", samples=args.serial, seed=1)
    text = SCENE.read_text()
    start = time.perf_counter()
    for i, p in enumerate(points):
        run_point(text, str(SCENE), i, p, duration=DURATION)
    serial = args.serial / (time.perf_counter() - start)
    print(f"\nloop over `run_point` without Ray: {serial:.1f} design points per second ({args.serial} points)\n")

    print("| sweep | workers | wall [s] | design points per second | other processes' CPU share |")
    print("|---|---|---|---|---|")
    kept = {1: [], 2: []}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeat):
            for workers in (1, 2):
                wall, others = timed_sweep(workers, args.points, args.per_task, pathlib.Path(tmp) / f"{r}-{workers}")
                share = 100 * others / (cores * wall)
                rate = args.points / wall
                if share <= args.clean:
                    kept[workers].append(rate)
                print(f"| {r + 1} | {workers} | {wall:.1f} | {rate:.1f} | {share:.1f} % |", flush=True)
    print(f"\nload average after: {os.getloadavg()}")
    if kept[1] and kept[2]:
        one, two = statistics.median(kept[1]), statistics.median(kept[2])
        print(
            f"sweeps with other processes under {args.clean} %: 1 worker {one:.1f}, 2 workers {two:.1f} "
            f"design points/s; scaling {two / one:.3f} (linear: 2; goal >= 1.8)"
        )
    else:
        print(f"no sweep of each kind ran with other processes under {args.clean} %: no scaling figure")


if __name__ == "__main__":
    main()
