"""PyElastica 1.0 on the problems of `cargo xtask bench --pareto` (xtask/src/pareto.rs).

`cargo xtask bench --pareto` runs this script after its own sweeps, in the same run on the same
machine, and merges its points into `docs/benchmarks/pareto.{json,md}` and the diagrams. It can
also be run by hand:

    NUMBA_NUM_THREADS=1 python3 benches/pyelastica/pareto.py --input in.json --output out.json

The input (written by pareto.rs) carries every physical parameter, the element counts, the time
step ladders and the references, so that nothing is defined twice: the pendulum's reference tip
(pareto.rs's fine f64 direct-solver run) and the cantilever's reference deflection (the
shearable elastica, `tests/support/reference.rs::elastica_tip`) are read, never recomputed here.
The output is one JSON array of points with the fields of pareto.rs's `Point`.

Set-up (PyElastica 1.0.0, `pip install pyelastica==1.0.0`):

* Rod: `CosseratRod.straight_rod` with the same length, radius, density, Young's modulus E and
  shear modulus G. PyElastica's rod is shearable and extensible (stretch stiffness E A, bending
  E I, twist G J, like ours). Its shear stiffness is `alpha_c G A` with a Timoshenko shear
  coefficient `alpha_c` (27/28 in 1.0, Kaneko 1975); our rods use `K_p = G A` (coefficient 1).
  After construction the two shear entries of `shear_matrix` are divided by the coefficient the
  rod was built with (read from the matrix, not hard-coded), so the shear stiffness is `G A`
  while the twist stiffness stays `G J`.
* Pendulum (rod from `start` along `direction`, gravity from the input, undamped, `t_end`
  seconds): the first node is pinned with `GeneralConstraint` on position index 0 only (all three
  translations held, no director constrained, so the end frame rotates freely: our `pinned`
  end). `GravityForces`. Error: distance of the last node from the reference tip divided by the
  length. PyElastica's rod stretches (E A = 79 N against a weight of 0.85 N), the reference is
  inextensible: its error levels off at about 5.5e-3 whatever N and dt, as our own `extensible`
  family's does (5.4e-3 to 5.7e-3; PyElastica 5.75e-3 at N = 25, 5.46e-3 at N = 200).
* Cantilever (α = F L²/EI from the input): `OneEndFixedBC` on node 0 and element 0 (the first
  element's frame is held), `EndpointForces` with the tip force (ramp-up time 1e-12 s, i.e. a
  dead load as in pareto.rs), and `AnalyticalLinearDamper` with the physical protocol:
  translational constant `drag · m_node` on every node (velocity × exp(−drag dt): the same drag
  rate `drag = 2 ω₁` as pareto.rs's `−drag m v`) and rotational constant 0 (pareto.rs has no
  rotational damping). Same stopping rule as pareto.rs: `integrate` over chunks of
  `ceil(1/(ω₁ dt))` steps until the tip deflection y/L moves less than `tolerance` in a chunk,
  at most `max_chunks` chunks. Error: |y − y_ref| / y_ref. Measured with PyElastica 1.0.0:
  13.7 %, 6.8 %, 3.4 %, 1.66 %, 0.81 % at N = 8, 16, 32, 64, 128 (first order); the Richardson
  extrapolation of N = 64 and 128 is within 0.03 % of the elastica.
* Time stepping: `PositionVerlet` with `integrate`. PyElastica has no stability estimate, so for
  each N the time step ladder of the input is tried from the largest step down; a run that ends
  with non-finite values, a tip further than 1.5 L from the start, or an element stretched or
  compressed by more than 20 % counts as unstable and is left out. The pendulum records the
  largest stable step of the ladder and that step times each of `extra_factors` (time-step
  convergence; the ladder's steps divide `t_end`); the cantilever, whose static answer does not
  depend on dt, records the largest stable step only.
* Timing: `time.perf_counter()` around the `integrate` calls (and, for the cantilever, the
  convergence check between chunks, as pareto.rs times it), not imports or set-up; serial,
  `NUMBA_NUM_THREADS=1`; one untimed warm-up run per problem first so numba's JIT compilation
  is not timed.
"""

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import importlib.metadata  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import elastica as ea  # noqa: E402

VERSION = importlib.metadata.version("pyelastica")
FAMILY = "PyElastica 1.0"
SOLVER = f"PyElastica {VERSION} PositionVerlet"


class Simulator(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
    """A simulator with constraints, forcing and damping."""


def make_rod(n, p):
    """The straight rod of `p` with the shear stiffness G A (see the docstring)."""
    d = np.array(p["direction"], dtype=float)
    d /= np.linalg.norm(d)
    # Any normal: the cross-section is a circle.
    helper = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    normal = np.cross(helper, d)
    normal /= np.linalg.norm(normal)
    rod = ea.CosseratRod.straight_rod(
        n,
        np.array(p["start"], dtype=float),
        d,
        normal,
        p["length"],
        p["radius"],
        p["density"],
        youngs_modulus=p["young_modulus"],
        shear_modulus=p["shear_modulus"],
    )
    area = math.pi * p["radius"] ** 2
    alpha_c = rod.shear_matrix[0, 0, 0] / (p["shear_modulus"] * area)
    rod.shear_matrix[0, 0, :] /= alpha_c
    rod.shear_matrix[1, 1, :] /= alpha_c
    return rod


def integrate(stepper, sim, dt, steps, t0):
    """`ea.integrate` over `steps` steps of `dt` from `t0`; its final print goes to stderr."""
    with contextlib.redirect_stdout(sys.stderr):
        return ea.integrate(stepper, sim, steps * dt, steps, restart_time=t0, progress_bar=False)


def sane(rod, p):
    """Whether the run stayed finite and bounded (see the docstring)."""
    x = rod.position_collection
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(rod.dilatation))):
        return False
    if np.linalg.norm(x[:, -1] - np.array(p["start"])) > 1.5 * p["length"]:
        return False
    return bool(np.max(np.abs(rod.dilatation - 1.0)) < 0.2)


def pendulum_run(p, n, dt, steps=None):
    """Tip after `t_end` (or after `steps` steps), wall time, sanity."""
    sim = Simulator()
    rod = make_rod(n, p)
    sim.append(rod)
    sim.constrain(rod).using(
        ea.GeneralConstraint,
        constrained_position_idx=(0,),
        translational_constraint_selector=np.array([True, True, True]),
        rotational_constraint_selector=np.array([False, False, False]),
    )
    sim.add_forcing_to(rod).using(ea.GravityForces, acc_gravity=np.array(p["gravity"]))
    sim.finalize()
    stepper = ea.PositionVerlet()
    if steps is None:
        steps = round(p["t_end"] / dt)
    t = time.perf_counter()
    integrate(stepper, sim, dt, steps, 0.0)
    wall = time.perf_counter() - t
    return rod.position_collection[:, -1].copy(), wall, sane(rod, p)


def cantilever_run(p, n, dt, max_chunks=None):
    """Static tip deflection y/L, wall time, sanity."""
    sim = Simulator()
    rod = make_rod(n, p)
    sim.append(rod)
    sim.constrain(rod).using(
        ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,)
    )
    sim.add_forcing_to(rod).using(
        ea.EndpointForces,
        start_force=np.zeros(3),
        end_force=np.array([0.0, 0.0, -p["tip_force"]]),
        ramp_up_time=1e-12,
    )
    sim.dampen(rod).using(
        ea.AnalyticalLinearDamper,
        translational_damping_constant=p["drag"] * rod.mass.copy(),
        rotational_damping_constant=0.0,
        time_step=dt,
    )
    sim.finalize()
    stepper = ea.PositionVerlet()
    chunk = math.ceil(1.0 / (p["omega1"] * dt))
    length = p["length"]
    t_sim, prev, ok = 0.0, 0.0, True
    t = time.perf_counter()
    for _ in range(max_chunks or p["max_chunks"]):
        t_sim = integrate(stepper, sim, dt, chunk, t_sim)
        # Deflection along the load, which is along −z.
        y = -(rod.position_collection[2, -1] - p["start"][2]) / length
        if not (math.isfinite(y) and abs(y) < 1.5):
            ok = False
            break
        if abs(y - prev) < p["tolerance"]:
            prev = y
            break
        prev = y
    wall = time.perf_counter() - t
    return prev, wall, ok and sane(rod, p)


def point(problem, n, dt, wall, error):
    return {
        "problem": problem,
        "family": FAMILY,
        "solver": SOLVER,
        "sweeps": 0,
        "extensible": True,
        "precision": "f64",
        "elements": n,
        "dt": dt,
        "wall_s": wall,
        "error": error,
    }


def pendulum_sweep(p, log):
    ref = np.array(p["reference_tip"])
    length = p["length"]
    out = []
    pendulum_run(p, p["elements"][0], p["dt_ladder"][-1], steps=50)  # warm-up (JIT), untimed
    for n in p["elements"]:
        ladder = sorted(p["dt_ladder"], reverse=True)
        for dt in ladder:
            tip, wall, ok = pendulum_run(p, n, dt)
            if not ok:
                log(f"  pendulum N {n}, dt {dt:.2e}: unstable (left out)")
                continue
            for dt2 in [dt] + [dt * f for f in p["extra_factors"]]:
                if dt2 != dt:
                    tip, wall, ok = pendulum_run(p, n, dt2)
                    if not ok:
                        log(f"  pendulum N {n}, dt {dt2:.2e}: unstable (left out)")
                        continue
                err = float(np.linalg.norm(tip - ref) / length)
                log(f"  pendulum N {n}, dt {dt2:.2e}: error {err:.3e} in {wall:.4f} s")
                out.append(point("pendulum", n, dt2, wall, err))
            break
        else:
            log(f"  pendulum N {n}: no stable step in the ladder")
    return out


def cantilever_sweep(p, log):
    y_ref = p["reference_deflection"]
    out = []
    cantilever_run(p, p["elements"][0], p["dt_ladder"][-1], max_chunks=1)  # warm-up (JIT), untimed
    for n in p["elements"]:
        for dt in sorted(p["dt_ladder"], reverse=True):
            y, wall, ok = cantilever_run(p, n, dt)
            if not ok:
                log(f"  cantilever N {n}, dt {dt:.2e}: unstable (left out)")
                continue
            err = abs(y - y_ref) / y_ref
            log(f"  cantilever N {n}, dt {dt:.2e}: y/L {y:.6f}, error {err:.3e} in {wall:.3f} s")
            out.append(point("cantilever", n, dt, wall, err))
            break
        else:
            log(f"  cantilever N {n}: no stable step in the ladder")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--input", required=True, help="JSON written by pareto.rs")
    ap.add_argument("--output", required=True, help="JSON array of points")
    ap.add_argument("--quick", action="store_true", help="two element counts per problem")
    ap.add_argument("--only", choices=["pendulum", "cantilever"], help="one problem only")
    args = ap.parse_args()
    with open(args.input) as f:
        cfg = json.load(f)

    def log(s):
        print(s, file=sys.stderr, flush=True)

    log(f"PyElastica {VERSION}, NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS')}")
    out = []
    for name, sweep in [("pendulum", pendulum_sweep), ("cantilever", cantilever_sweep)]:
        if args.only and args.only != name:
            continue
        p = dict(cfg[name])
        if args.quick:
            p["elements"] = p["elements"][:2]
        log(f"PyElastica {name} sweep ...")
        out.extend(sweep(p, log))
    with open(args.output, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
