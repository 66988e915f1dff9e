"""What calling the simulator from Python costs over the Rust library.

The pendulum scene (`scenes/pendulum.toml`) at 100 elements is stepped three ways in one
process: one `run(N)` call (the library's own cost: one call for all N steps), `run(100)` calls
(stepping in chunks, as a controller or learning loop does), and `step()` calls. The overhead of
chunks is their extra time over the single call; that of `step()` is its extra time per call.
Each way is timed `REPEATS` times and the median is kept. Prints a Markdown table.

    python python/bench/overhead.py
"""

import pathlib
import platform
import statistics
import time

import cosserat

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "pendulum.toml"
STEPS = 20_000
CHUNK = 100
REPEATS = 7


def fresh():
    return cosserat.Simulation.from_file(SCENE, {"rod.0.elements": 100})


def timed(body):
    times = []
    for _ in range(REPEATS):
        sim = fresh()
        sim.run(100)  # warm caches and the stepper's scratch
        start = time.perf_counter()
        body(sim)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main():
    single = timed(lambda s: s.run(STEPS))

    def chunks(s):
        for _ in range(STEPS // CHUNK):
            s.run(CHUNK)

    def steps(s):
        for _ in range(STEPS):
            s.step()

    chunked = timed(chunks)
    stepped = timed(steps)
    per_step = single / STEPS
    print(f"pendulum, 100 elements, {STEPS} steps, median of {REPEATS}; {platform.processor() or platform.machine()}, Python {platform.python_version()}")
    print()
    print("| way | wall [s] | per step [µs] | overhead |")
    print("|---|---|---|---|")
    print(f"| one `run({STEPS})` (the library) | {single:.4f} | {per_step * 1e6:.2f} | — |")
    print(f"| `run({CHUNK})` × {STEPS // CHUNK} | {chunked:.4f} | {chunked / STEPS * 1e6:.2f} | {100 * (chunked / single - 1):+.2f} % |")
    print(f"| `step()` × {STEPS} | {stepped:.4f} | {stepped / STEPS * 1e6:.2f} | {(stepped - single) / STEPS * 1e6:+.2f} µs per call |")


if __name__ == "__main__":
    main()
