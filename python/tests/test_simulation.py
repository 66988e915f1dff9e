"""Tests of the `cosserat` Python package against independent references: beam theory for a
clamped cantilever, the momentum balance of its clamp, bit-for-bit replay from a snapshot, and
the library's own error messages surfacing as exceptions."""

import pathlib
import threading

import numpy as np
import pytest

import cosserat

ROOT = pathlib.Path(__file__).resolve().parents[2]
PENDULUM = ROOT / "scenes" / "pendulum.toml"

# A nitinol cantilever, 0.1 m, clamped at the origin along x, under gravity, with drag at about
# twice its first bending frequency so that it settles in a few periods; the stiff scheme at
# 1 ms. Small deflection: w L⁴ / (8 E I) is 0.4 % of the length.
CANTILEVER = """
name = "cantilever"

[solver]
scheme = "stiff"
dt = 1e-3
duration = 3.0
gravity = [0.0, 0.0, -9.81]

[[rod]]
name = "wire"
elements = 40
shape = { kind = "straight", start = [0.0, 0.0, 0.0], direction = [1.0, 0.0, 0.0], length = 0.1 }
material = { young_modulus = 6.0e10, poisson_ratio = 0.33, density = 6450.0, radius = 2.0e-4 }
damping = { drag = 30.0 }
start = { kind = "clamped" }
"""

E, NU, RHO, R, L = 6.0e10, 0.33, 6450.0, 2.0e-4, 0.1
AREA = np.pi * R**2
I = np.pi * R**4 / 4.0
G = E / (2.0 * (1.0 + NU))


def cantilever():
    return cosserat.Simulation.from_toml(CANTILEVER, name="cantilever.toml")


def test_scene_from_file_has_the_shapes_it_says():
    sim = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 50})
    assert sim.name == "pendulum"
    assert sim.rod_names == ["rope"]
    assert sim.elements() == 50
    assert sim.positions().shape == (51, 3)
    assert sim.velocities().shape == (51, 3)
    assert sim.angular_velocities().shape == (50, 3)
    assert sim.frames().shape == (50, 4)
    assert sim.directors().shape == (50, 3, 3)
    assert sim.scene_steps == round(1.0 / sim.dt)
    sim.run(100)
    assert sim.steps == 100
    assert sim.time == pytest.approx(100 * sim.dt)
    # The pinned end stays; the rest falls.
    p = sim.positions()
    assert np.allclose(p[0], 0.0, atol=1e-6)
    assert p[-1, 2] < 0.0


def test_directors_are_the_frames_rotation_matrices():
    sim = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 20})
    sim.run(500)
    q = sim.frames()
    d = sim.directors()
    w, x, y, z = q.T
    # Column k of the rotation matrix of q is director d_{k+1}.
    rot = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)], -1),
            np.stack([2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)], -1),
            np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        1,
    )
    assert np.allclose(d, rot, atol=1e-6)
    # d3 follows the segments.
    p = sim.positions()
    t = np.diff(p, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    assert np.all(np.einsum("ij,ij->i", t, d[:, 2]) > 0.999)


def test_cantilever_sags_as_beam_theory_says_and_the_clamp_holds_its_weight():
    sim = cantilever()
    sim.run()
    w = RHO * AREA * 9.81
    # Euler-Bernoulli plus the shear term of the parallel penalty (K_p = G A).
    expected = w * L**4 / (8 * E * I) + w * L**2 / (2 * G * AREA)
    tip = -sim.positions()[-1, 2]
    assert tip == pytest.approx(expected, rel=2e-3)
    force, torque = sim.end_reaction(0)
    weight = w * L
    assert force == pytest.approx([0.0, 0.0, weight], abs=1e-3 * weight)
    # The clamp's moment about the held point balances the weight's, w L² / 2 about -y.
    assert torque == pytest.approx([0.0, -w * L**2 / 2, 0.0], abs=2e-3 * w * L**2 / 2)
    assert sim.end_reaction(1) is None


def test_a_restored_snapshot_repeats_the_steps_that_followed_it():
    sim = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 30})
    sim.run(200)
    snap = sim.snapshot()
    assert snap.time == pytest.approx(sim.time)
    sim.set_loads([(30, (0.0, 0.0, -0.1))])
    sim.run(300)
    first = sim.positions()
    sim.restore(snap)
    assert sim.time == pytest.approx(snap.time)
    sim.set_loads([(30, (0.0, 0.0, -0.1))])
    sim.run(300)
    assert np.array_equal(first, sim.positions())


def test_a_driven_end_moves_at_its_velocity():
    sim = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 30})
    sim.set_end_velocity(0, [0.0, 0.1, 0.0])
    sim.run(1000)
    assert sim.positions()[0] == pytest.approx([0.0, 0.1 * sim.time, 0.0], abs=1e-6)
    sim.move_end_to(0, [0.0, 0.0, 0.0], 0.01)
    sim.run(1000)
    assert sim.positions()[0] == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)


def test_an_end_follows_its_path_and_slides_along_its_axis():
    sim = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 30})
    # The pinned start follows a path 2 cm along y over 0.01 s and holds there.
    sim.set_end_path(0, [0.0, 0.01], displacement=[[0.0, 0.0, 0.0], [0.0, 0.02, 0.0]])
    sim.run(250)
    assert sim.positions()[0] == pytest.approx([0.0, 0.01, 0.0], abs=1e-6)
    sim.run(1000)
    assert sim.positions()[0] == pytest.approx([0.0, 0.02, 0.0], abs=1e-6)
    # Free along z, the pinned start falls with the rope; it stays on its line.
    sim.slide_end(0, [0.0, 0.0, 1.0])
    sim.run(1000)
    start = sim.positions()[0]
    assert start[2] < -1e-3
    assert start[:2] == pytest.approx([0.0, 0.02], abs=1e-6)
    with pytest.raises(cosserat.ControlError, match="free end"):
        sim.hold_end(1, "free")
        sim.slide_end(1, [1.0, 0.0, 0.0])


def test_a_hinged_clamp_swings_like_a_pin():
    # Hinged about y, the axis the rope's weight turns it about, a clamp leaves that turn
    # free, as a pin does.
    pinned = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 20})
    hinged = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 20})
    hinged.hold_end(0, "clamped")
    hinged.hinge_end(0, [0.0, 1.0, 0.0])
    pinned.run(2000)
    hinged.run(2000)
    assert hinged.positions() == pytest.approx(pinned.positions(), abs=1e-4)
    hinged.hinge_end(0, None)
    hinged.run(10)
    with pytest.raises(cosserat.ControlError, match="only a clamped end"):
        pinned.hinge_end(0, [0.0, 1.0, 0.0])


FLOOR = """
[solver]
dt = 5e-5
iterations = 10
precision = "f64"
gravity = [0.0, 0.0, -9.81]

[[rod]]
name = "rope"
elements = 20
shape = { kind = "straight", start = [0.0, 0.0, 0.001], direction = [1.0, 0.0, 0.0], length = 0.1 }
material = { young_modulus = 3e5, poisson_ratio = 0.5, density = 1000.0, radius = 1e-3 }
damping = { drag = 2.0 }

[[obstacles]]
shape = { kind = "half-space", point = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 1.0] }
"""


def test_an_obstacle_set_moving_carries_the_rope():
    sim = cosserat.Simulation.from_toml(FLOOR, name="floor.toml")
    sim.run(2000)
    resting = sim.positions()[:, 2].mean()
    assert resting == pytest.approx(1e-3, abs=2e-4)
    # The floor rises 1 cm over 0.1 s and stops; the rope rides on it.
    sim.set_obstacle_path(0, [0.0, 0.1], displacement=[[0, 0, 0], [0, 0, 0.01]])
    sim.run(4000)
    assert sim.positions()[:, 2].mean() == pytest.approx(resting + 0.01, abs=5e-4)
    sim.set_obstacle_path(0, None)
    with pytest.raises(cosserat.ControlError):
        sim.set_obstacle_path(3, [0.0, 0.1])


def test_a_moment_turns_the_end_it_acts_on():
    sim = cosserat.Simulation.from_toml(
        CANTILEVER.replace('scheme = "stiff"', 'scheme = "explicit"').replace(
            "dt = 1e-3", "dt = 9e-8"
        ),
        name="cantilever.toml",
    )
    sim.set_loads([(40, (0.0, 0.0, 0.0), (0.0, 0.0, 1e-4))])
    sim.run(2000)
    # A moment about z turns the free end towards +y.
    assert sim.positions()[-1, 1] > 0.0
    # The stiff scheme takes it too, as a term of the end frame's implicit equation.
    stiff = cantilever()
    stiff.set_loads([(40, (0.0, 0.0, 0.0), (0.0, 0.0, 1e-4))])
    stiff.run(200)
    assert stiff.positions()[-1, 1] > 0.0


def test_written_state_is_read_back():
    sim = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 10})
    p = sim.positions()
    p[:, 1] += 0.01
    sim.set_positions(p)
    assert np.allclose(sim.positions(), p, atol=1e-6)
    v = np.zeros((11, 3))
    v[:, 2] = 1.0
    sim.set_velocities(v)
    assert np.allclose(sim.velocities(), v)
    with pytest.raises(cosserat.ControlError, match="expected 11 entries, got 3"):
        sim.set_velocities(np.zeros((3, 3)))


def test_errors_carry_the_library_messages():
    with pytest.raises(cosserat.SceneError, match="young_modulus"):
        cosserat.Simulation.from_toml(CANTILEVER.replace("6.0e10", "-1.0"))
    with pytest.raises(cosserat.SceneError, match="no-such-file"):
        cosserat.Simulation.from_file(ROOT / "no-such-file.toml")
    with pytest.raises(cosserat.SceneError, match="backend"):
        cosserat.Simulation.from_file(PENDULUM, backend="abacus")
    sim = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 10})
    with pytest.raises(cosserat.ControlError, match="no rod 3"):
        sim.positions(rod=3)
    with pytest.raises(cosserat.ControlError, match="no end 2"):
        sim.end_reaction(2)
    with pytest.raises(cosserat.ControlError, match="kind"):
        sim.hold_end(0, "glued")
    # A step far past the stable limit diverges and says where.
    fast = cosserat.Simulation.from_file(
        PENDULUM,
        {"rod.0.elements": 10, "solver.dt": 2e-2, "solver.check_stability": False},
    )
    with pytest.raises(cosserat.StepError, match="rod 0"):
        fast.run(1000)


def test_stepping_releases_the_gil():
    sim = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 200})
    ticks = 0
    done = threading.Event()

    def count():
        nonlocal ticks
        while not done.is_set():
            ticks += 1

    t = threading.Thread(target=count)
    t.start()
    try:
        sim.run(20000)
    finally:
        done.set()
        t.join()
    # A thread that held the GIL for the whole run would leave the counter near zero.
    assert ticks > 1000


def test_a_batch_steps_its_copies_as_separate_simulations_would():
    copies = 4
    batch = cosserat.Batch.from_file(PENDULUM, copies, {"rod.0.elements": 20})
    assert len(batch) == copies
    pushes = np.array([[0.0, 0.02 * c, 0.0] for c in range(copies)])
    batch.set_end_velocity(0, pushes)
    assert batch.run(500) == [None] * copies
    p = batch.positions()
    assert p.shape == (copies, 21, 3)
    for c in range(copies):
        one = cosserat.Simulation.from_file(PENDULUM, {"rod.0.elements": 20})
        one.set_end_velocity(0, pushes[c])
        one.run(500)
        assert np.array_equal(one.positions(), p[c])
    forces, torques = batch.end_reactions(0)
    assert forces.shape == (copies, 3) and np.all(np.isfinite(forces))
    # A snapshot of one copy restores another: copy 3 becomes copy 0.
    batch.restore(3, batch.snapshot(0))
    assert np.array_equal(batch.positions()[3], batch.positions()[0])
    with pytest.raises(cosserat.ControlError, match="expected shape"):
        batch.set_end_velocity(0, np.zeros((3, 3)))


def pushed_batch(layout, backend="cpu", copies=4):
    """A batch of pendulums whose held ends are pushed at a different speed in every copy, run
    for 500 steps."""
    batch = cosserat.Batch.from_file(PENDULUM, copies, {"rod.0.elements": 20}, backend=backend, layout=layout)
    pushes = np.array([[0.0, 0.02 * c, 0.01 * c] for c in range(copies)])
    batch.set_end_velocity(0, pushes)
    assert batch.run(500) == [None] * copies
    return batch


def test_a_batch_of_one_simulation_steps_its_copies_as_separate_simulations_would():
    copies = pushed_batch("copies")
    separate = pushed_batch("simulations")
    assert (copies.layout, separate.layout) == ("copies", "simulations")
    # Not a trivial equality: the copies went different ways.
    p = copies.positions()
    assert np.abs(p[3] - p[0]).max() > 1e-4
    assert np.array_equal(p, separate.positions())
    assert np.array_equal(copies.velocities(), separate.velocities())
    assert np.array_equal(copies.end_reactions(0)[0], separate.end_reactions(0)[0])
    assert copies.times == separate.times
    # A copy's snapshot restores another copy; the other copies keep their state.
    before = copies.positions()
    copies.restore(3, copies.snapshot(0))
    after = copies.positions()
    assert np.array_equal(after[3], before[0])
    assert np.array_equal(after[:3], before[:3])
    # The restored copy then moves as copy 0 does: the same push, from the same points,
    # velocities and frames (not bit for bit: the solver's own memory of the rod is not in a
    # copy's snapshot).
    copies.run(100)
    p = copies.positions()
    np.testing.assert_allclose(p[3], p[0], rtol=0, atol=1e-8)
    with pytest.raises(cosserat.ControlError, match="no copy 4: the batch has copies 0..4"):
        copies.snapshot(4)
    with pytest.raises(cosserat.ControlError, match="no rod 1: each copy has rods 0..1"):
        copies.positions(1)
    with pytest.raises(cosserat.ControlError, match="holds a whole simulation"):
        copies.restore(0, separate.snapshot(0))
    with pytest.raises(cosserat.SceneError, match="layout = \"rows\""):
        cosserat.Batch.from_file(PENDULUM, 2, layout="rows")


def test_a_copy_that_diverges_stops_a_batch_of_one_simulation_and_says_which():
    batch = cosserat.Batch.from_file(PENDULUM, 3, {"rod.0.elements": 20}, layout="copies")
    batch.set_end_velocity(0, np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0e4, 0.0, 0.0]]))
    errors = batch.run(2000)
    assert errors[2] is not None and errors[2].startswith("copy 2: ")
    assert all(e is not None and "with copy 2, which diverged" in e for e in errors[:2])


def test_a_gpu_batch_is_one_simulation_whose_copies_match_separate_ones(on_gpu):
    copies = on_gpu(lambda: pushed_batch(None, backend="gpu"))
    assert copies.layout == "copies" and copies.backend == "gpu"
    separate = on_gpu(lambda: pushed_batch("simulations", backend="gpu"))
    p, q = copies.positions(), separate.positions()
    assert np.abs(p[3] - p[0]).max() > 1e-4
    # f32 kernels: the same arithmetic per copy, dispatched together or apart.
    np.testing.assert_allclose(p, q, rtol=0, atol=1e-5)
    copies.restore(1, copies.snapshot(2))
    assert np.allclose(copies.positions()[1], copies.positions()[2], rtol=0, atol=1e-6)
