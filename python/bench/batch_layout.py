"""A `cosserat.Batch` on the CPU with rayon held both ways: one simulation per copy
(`layout="simulations"`) against one simulation of all copies (`layout="copies"`).

Three batches: 64 pendulums of 20 elements and 16 of 100 (`scenes/pendulum.toml`, explicit,
f32, 2 000 steps), and 32 short insertions (`scenes/stiff-guidewire-insertion.toml` at 64
elements in a 2 000-triangle vessel, stiff scheme, 100 steps). Both layouts are built, warmed
with 10 steps and timed in turn five times; the median gives copy-steps per second. Prints a
Markdown table.

    python python/bench/batch_layout.py [--backend gpu]

With `--backend gpu`, 16, 64 and 256 pendulums of 20 elements on the GPU backend instead (one
simulation per copy acquires a device per copy, which bounds the counts).
"""

import argparse
import os
import pathlib
import statistics
import time

import cosserat

ROOT = pathlib.Path(__file__).resolve().parents[2]
CASES = [
    ("64 pendulums, 20 elements", "pendulum.toml", 64, {"rod.0.elements": 20}, 2000),
    ("16 pendulums, 100 elements", "pendulum.toml", 16, {"rod.0.elements": 100}, 2000),
    (
        "32 insertions, 64 elements, stiff, vessel",
        "stiff-guidewire-insertion.toml",
        32,
        {"rod.0.elements": 64, "environment.mesh.triangles": 2000},
        100,
    ),
]
LAYOUTS = ("simulations", "copies")


# `--backend gpu`: pendulums of 20 elements (f32, explicit), from a few copies to many.
GPU_CASES = [(f"{n} pendulums, 20 elements", "pendulum.toml", n, {"rod.0.elements": 20}, 2000) for n in (16, 64, 256)]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--backend", default="cpu-rayon", choices=["cpu-rayon", "gpu"])
    args = ap.parse_args()
    print(f"load average before: {os.getloadavg()}")
    print("| batch | `simulations` [copy-steps/s] | `copies` [copy-steps/s] |")
    print("|---|---|---|")
    for label, scene, copies, overrides, steps in CASES if args.backend == "cpu-rayon" else GPU_CASES:
        batches = {
            layout: cosserat.Batch.from_file(ROOT / "scenes" / scene, copies, overrides, args.backend, layout=layout)
            for layout in LAYOUTS
        }
        times = {layout: [] for layout in LAYOUTS}
        for b in batches.values():
            b.run(10)
        for _ in range(5):
            for layout, b in batches.items():
                start = time.perf_counter()
                errors = b.run(steps)
                times[layout].append(time.perf_counter() - start)
                assert errors == [None] * copies, f"{label}, {layout}: {next(e for e in errors if e)}"
        rates = [copies * steps / statistics.median(times[layout]) for layout in LAYOUTS]
        print(f"| {label} | {rates[0]:,.0f} | {rates[1]:,.0f} |", flush=True)
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
