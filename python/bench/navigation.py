"""Environment steps per second of `cosserat/GuidewireNavigation-v0`.

One environment with its defaults (the stiff scheme at 1 ms, ten steps per environment step,
96 elements, an 8000-triangle random vessel) on one core, a random policy, episodes reset when
they end: the median of five runs of `STEPS` steps after a warm-up. Then the vector environment
(`GuidewireNavigationVectorEnv`, all copies in one call, in parallel on every core) with 2, 8 and
32 copies: environment steps of all copies per second. Prints Markdown lines.

    python python/bench/navigation.py
"""

import os
import platform
import statistics
import time

import numpy as np

import cosserat.gym as cg

STEPS = 2000


def run(seed):
    env = cg.GuidewireNavigationEnv()
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    for _ in range(100):
        env.step(rng.uniform(-1, 1, 2))
    start = time.perf_counter()
    for _ in range(STEPS):
        _, _, terminated, truncated, _ = env.step(np.array([rng.uniform(-0.2, 1.0), rng.uniform(-1, 1)]))
        if terminated or truncated:
            env.reset()
    return STEPS / (time.perf_counter() - start)


def run_vector(copies, seed=0):
    env = cg.GuidewireNavigationVectorEnv(copies, vessel_seed=seed)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    for _ in range(20):
        env.step(rng.uniform(-1, 1, (copies, 2)))
    steps = max(STEPS // copies, 50)
    start = time.perf_counter()
    for _ in range(steps):
        actions = np.stack([rng.uniform(-0.2, 1.0, copies), rng.uniform(-1, 1, copies)], 1)
        env.step(actions)
    return steps * copies / (time.perf_counter() - start)


def main():
    where = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    rates = [run(seed) for seed in range(5)]
    print(
        f"| one environment, defaults, random policy | {statistics.median(rates):.0f} env steps/s "
        f"(runs: {', '.join(f'{r:.0f}' for r in rates)}) | {where} |"
    )
    for copies in (2, 8, 32):
        rates = [run_vector(copies, seed) for seed in range(3)]
        print(
            f"| vector environment, {copies} copies | {statistics.median(rates):.0f} env steps/s in total "
            f"(runs: {', '.join(f'{r:.0f}' for r in rates)}) | {where} |"
        )


if __name__ == "__main__":
    main()
