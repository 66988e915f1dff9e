"""Environment steps per second of `cosserat/GuidewireNavigation-v0` on one core.

One environment with its defaults (the stiff scheme at 1 ms, ten steps per environment step,
96 elements, an 8000-triangle random vessel), a random policy, episodes reset when they end;
the median of five runs of `STEPS` steps after one warm-up episode. Prints a Markdown line.

    python python/bench/navigation.py
"""

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


def main():
    rates = [run(seed) for seed in range(5)]
    print(
        f"| GuidewireNavigation-v0, defaults, random policy | {statistics.median(rates):.0f} env steps/s "
        f"(runs: {', '.join(f'{r:.0f}' for r in rates)}) | {platform.machine()}, Python {platform.python_version()} |"
    )


if __name__ == "__main__":
    main()
