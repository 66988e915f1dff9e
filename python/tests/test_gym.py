"""The Gymnasium environment: it passes gymnasium's own checker, seeded episodes repeat, and
pushing the wire in makes progress along the path (skipped without gymnasium)."""

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
from gymnasium.utils.env_checker import check_env  # noqa: E402

import cosserat.gym  # noqa: E402,F401  (registers the environment)


def make(**kw):
    kw.setdefault("elements", 48)
    kw.setdefault("triangles", 4000)
    return gym.make(cosserat.gym.ENV_ID, **kw)


def test_the_environment_passes_gymnasiums_checker():
    env = make()
    check_env(env.unwrapped, skip_render_check=True)


def test_seeded_episodes_repeat_and_seeds_differ():
    def episode(seed):
        env = make()
        obs, info = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        out = [obs]
        for _ in range(20):
            obs, *_ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            out.append(obs)
        return info, np.array(out)

    info_a, a = episode(7)
    info_b, b = episode(7)
    assert info_a == info_b
    assert np.array_equal(a, b)
    info_c, _ = episode(8)
    assert info_c["vessel_seed"] != info_a["vessel_seed"]


def test_pushing_makes_progress_along_the_path():
    env = make(vessel_seed=5, target_branch=0)
    env.reset(seed=0)
    total, info = 0.0, {}
    for _ in range(60):
        _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0], np.float32))
        total += reward
        assert not truncated
        if terminated:
            break
    # 60 steps of 10 ms at 0.1 m/s push 6 cm of wire in; most of it shows as progress.
    assert info["progress"] > 0.04, info
    assert total > 2.0
    assert "failure" not in info, info


def test_the_vector_environment_steps_its_copies_as_single_environments_would():
    kw = dict(elements=48, triangles=4000)
    vec = gym.make_vec(cosserat.gym.ENV_ID, num_envs=3, vectorization_mode="vector_entry_point",
                       vessel_seed=5, target_branch=0, **kw)
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (3,) + vec.single_observation_space.shape
    single = cosserat.gym.GuidewireNavigationEnv(vessel_seed=5, target_branch=0, **kw)
    first, _ = single.reset(seed=0)
    assert np.array_equal(obs[0], first)
    actions = np.array([[1.0, 0.0], [0.5, 1.0], [1.0, -1.0]], np.float32)
    for _ in range(10):
        obs, rewards, terminated, truncated, _ = vec.step(actions)
        one, reward, *_ = single.step(actions[0])
    assert np.array_equal(obs[0], one)
    assert rewards[0] == pytest.approx(reward)
    # Different hands, different wires.
    assert not np.array_equal(obs[0], obs[1])
    assert not terminated.any() and not truncated.any()


def test_the_vector_environment_on_the_gpu_steps_as_on_the_cpu(on_gpu):
    """The GPU's stiff scheme (mesh contacts and the introducer in the kernel) as the vector
    environment's batch: the same observations and rewards as the CPU's batch."""
    kw = dict(num_envs=2, vectorization_mode="vector_entry_point", vessel_seed=5, target_branch=0,
              elements=24, triangles=4000)
    on_gpu_env = on_gpu(lambda: gym.make_vec(cosserat.gym.ENV_ID, backend="gpu", **kw))
    on_cpu = gym.make_vec(cosserat.gym.ENV_ID, backend="cpu", **kw)
    g, _ = on_gpu_env.reset(seed=0)
    c, _ = on_cpu.reset(seed=0)
    np.testing.assert_array_equal(g, c)
    actions = np.array([[1.0, 0.0], [0.6, 1.0]], np.float32)
    for _ in range(8):
        g, rg, tg, ug, _ = on_gpu_env.step(actions)
        c, rc, tc, uc, _ = on_cpu.step(actions)
    # Both in f64; the CPU resolves wall contacts as rows, the GPU as pins (equal to rounding).
    np.testing.assert_allclose(g, c, rtol=0, atol=1e-6)
    np.testing.assert_allclose(rg, rc, rtol=0, atol=1e-6)
    assert not np.array_equal(g[0], g[1])
    assert not (tg.any() or ug.any() or tc.any() or uc.any())
