"""Train a PPO policy on ``cosserat/GuidewireNavigation-v0`` with RLlib, the environments
living in Ray EnvRunner actors, and log its return curve.

What it shows. The Gymnasium environment of :mod:`cosserat.gym` is registered with Ray under a
name (:func:`ray.tune.registry.register_env`); RLlib's new API stack starts ``--env-runners``
EnvRunner actors (2 by default), and each builds its own copies of the environment in its own
process from that name and ``env_config``. Nothing but the configuration crosses the process
boundary: the simulator is constructed where it is stepped, so the same script runs on a laptop
(``ray.init()`` starts a local cluster) and on a cluster (``ray.init(address=...)``). PPO's
learner runs in the driver and sends the new weights to the EnvRunners after each iteration.

Run it (needs ``pip install "ray[rllib]" torch``; matplotlib is optional, for the plot)::

    python python/examples/rllib_navigation.py --minutes 5 --out rllib-navigation.csv

or ``--iterations N`` for a fixed number of training iterations. It writes one CSV row per
iteration (``iteration, env_steps, episode_return_mean, wall_s``), a PNG of the curve beside
the CSV when matplotlib is importable, and prints a summary.

Settings, chosen so that learning shows within minutes on two CPU cores:

- one fixed anatomy and target (``vessel_seed=5``, ``target_branch=1``): the branch that a wire
  pushed straight in enters, so the task is learnable by a policy without memory and the
  return is comparable across episodes (a random anatomy per episode is the harder task);
- short episodes, ``max_episode_steps=200`` (2 s of simulated time): pushing at full speed for
  2 s advances the tip about 21 cm along the path, a return of about 21, while the initial
  random policy, pushing and pulling at random, returns about 2; the distance between the two
  is what the curve shows;
- a coarse wire and vessel (``elements=48``, ``triangles=4000``): about 4000 environment steps
  per second in one process, so RLlib's sampling, not the simulation, sets the pace;
- a small network (two hidden layers of 64) and a small batch (2000 steps per iteration), so
  that an iteration takes seconds and a few minutes give tens of iterations.
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

#: The name under which the environment is registered with Ray.
ENV_NAME = "cosserat-navigation"

#: Environment settings of the example (see the module docstring for why).
ENV_CONFIG = {
    "vessel_seed": 5,
    "target_branch": 1,
    "max_episode_steps": 200,
    "elements": 48,
    "triangles": 4000,
}


def make_env(env_config: dict):
    """Builds one navigation environment; RLlib calls this inside each EnvRunner process."""
    import gymnasium as gym

    import cosserat.gym  # registers cosserat/GuidewireNavigation-v0 in this process

    # RLlib passes an EnvContext (a dict with worker_index and friends as attributes).
    return gym.make(cosserat.gym.ENV_ID, **dict(env_config))


def build_config(args: argparse.Namespace):
    """The PPO configuration: new API stack, remote EnvRunners, a small MLP."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    return (
        PPOConfig()
        .environment(ENV_NAME, env_config=ENV_CONFIG)
        .env_runners(
            num_env_runners=args.env_runners,
            num_envs_per_env_runner=1,
            num_cpus_per_env_runner=1,
            rollout_fragment_length="auto",
        )
        .learners(num_learners=0)  # the learner runs in the driver
        .training(
            train_batch_size_per_learner=args.batch,
            minibatch_size=250,
            num_epochs=6,
            lr=3e-4,
            gamma=0.99,
            lambda_=0.95,
            entropy_coeff=0.0,
        )
        .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=[64, 64], vf_share_layers=False))
        # The mean return over each EnvRunner's last 10 episodes (about two iterations), not
        # RLlib's default 100, so that the curve follows the policy rather than its history.
        .reporting(metrics_num_episodes_for_smoothing=10)
        .debugging(seed=args.seed)
    )


def write_plot(rows: list[dict], png: Path) -> bool:
    """Plots the mean episode return against environment steps; False without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    rows = [r for r in rows if r["episode_return_mean"] == r["episode_return_mean"]]  # drop NaN
    fig, ax = plt.subplots(figsize=(6, 3.6))
    ax.plot([r["env_steps"] for r in rows], [r["episode_return_mean"] for r in rows], marker=".")
    ax.set_xlabel("environment steps sampled")
    ax.set_ylabel("mean episode return")
    ax.set_title("PPO on cosserat/GuidewireNavigation-v0")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return True


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, default=5.0, help="wall-clock training budget (default 5)")
    p.add_argument("--iterations", type=int, default=None, help="stop after this many iterations instead")
    p.add_argument("--env-runners", type=int, default=2, help="EnvRunner actors (default 2)")
    p.add_argument("--batch", type=int, default=2000, help="environment steps per iteration (default 2000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("rllib-navigation.csv"), help="CSV of the return curve")
    args = p.parse_args(argv)

    import ray
    from ray.rllib.utils.metrics import (
        ENV_RUNNER_RESULTS,
        EPISODE_RETURN_MEAN,
        NUM_ENV_STEPS_SAMPLED_LIFETIME,
    )
    from ray.tune.registry import register_env

    ray.init(num_cpus=args.env_runners + 1, include_dashboard=False)
    register_env(ENV_NAME, make_env)
    algo = build_config(args).build_algo()

    rows: list[dict] = []
    budget = args.minutes * 60.0
    start = time.perf_counter()
    try:
        while True:
            result = algo.train()
            runners = result.get(ENV_RUNNER_RESULTS, {})
            row = {
                "iteration": len(rows) + 1,
                "env_steps": int(runners.get(NUM_ENV_STEPS_SAMPLED_LIFETIME, 0)),
                "episode_return_mean": float(runners.get(EPISODE_RETURN_MEAN, float("nan"))),
                "wall_s": round(time.perf_counter() - start, 2),
            }
            rows.append(row)
            print(
                f"iter {row['iteration']:3d}  steps {row['env_steps']:7d}  "
                f"return {row['episode_return_mean']:7.2f}  {row['wall_s']:7.1f} s",
                flush=True,
            )
            if args.iterations is not None:
                if len(rows) >= args.iterations:
                    break
            elif row["wall_s"] >= budget:
                break
    finally:
        algo.stop()
        ray.shutdown()

    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["iteration", "env_steps", "episode_return_mean", "wall_s"])
        w.writeheader()
        w.writerows(rows)
    png = args.out.with_suffix(".png")
    plotted = write_plot(rows, png)

    first, last = rows[0], rows[-1]
    print(f"\n{len(rows)} iterations, {last['env_steps']} environment steps in {last['wall_s']:.0f} s "
          f"({last['env_steps'] / last['wall_s']:.0f} steps/s, sampling and learning together)")
    print(f"mean episode return: {first['episode_return_mean']:.2f} (iteration 1) -> "
          f"{last['episode_return_mean']:.2f} (iteration {last['iteration']}), "
          f"best {max(r['episode_return_mean'] for r in rows):.2f}")
    print(f"curve: {args.out}" + (f", plot: {png}" if plotted else " (no matplotlib: no plot)"))


if __name__ == "__main__":
    main()
