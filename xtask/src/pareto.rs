//! `cargo xtask bench --pareto`: run time against error (work-precision diagrams).
//!
//! Two problems: the paper's free-space pendulum (tip position after 0.2 s against a fine f64
//! run with the exact constraint solver) and a large-deflection cantilever (static tip
//! deflection at α = F L²/EI = 2 against the shearable elastica, reached by damped relaxation).
//! Each is run over time steps, constraint sweeps, element counts, the constraint solver
//! (iterative Gauss–Seidel / direct Newton), extensible mode and precision, serially; the wall
//! time of each run is measured. Writes `docs/benchmarks/pareto.json`, a PNG and an SVG diagram
//! per problem, and `docs/benchmarks/pareto.md` (which setting to choose for which accuracy).
//!
//! The direct solver is not wired into the facade yet; it runs through the stand-alone loop of
//! the explicit scheme with `solver.constraint_solver = "direct"`, the same Fig. 5 step with the constraint solve replaced.
//!
//! The stiff scheme (`solver.scheme = "stiff"`, `docs/stiff-solver.md`: XPBD compliant
//! constraints, direct banded solve, implicit Euler) joins both diagrams with its default
//! settings. It has no stability limit on `dt`, so its points sweep `dt` up to 1e-3 s on the
//! pendulum and up to a tenth of the first bending period's `1/ω₁` on the cantilever; a run that
//! fails is reported and left out.
//!
//! PyElastica 1.0 (`pip install pyelastica==1.0.0`) runs the same two problems in the same run,
//! when `python3` (or `$PARETO_PYTHON`) imports `elastica` of version 1.0.x: after the sweeps
//! above, `benches/pyelastica/pareto.py` gets the physical parameters, element counts, time step
//! ladders and both references in a JSON file (nothing is defined twice; its docstring tells
//! how the parameters are matched) and returns its points, which join the JSON, the diagrams
//! (family `PyElastica 1.0`, red triangles, its own Pareto front) and the markdown (its own
//! table and front, and a computed comparison of the fronts at equal wall time). Without it the
//! markdown says so and the rest is unchanged. `PARETO_PYELASTICA_ONLY=1 cargo xtask bench
//! --pareto` runs only the references and PyElastica on two element counts per problem
//! (`PARETO_PYELASTICA_ONLY=full`: all of them), prints the points and writes nothing: a check
//! of the PyElastica set-up.

use crate::support::cases::{pendulum, pendulum_spec, workspace_file};
use crate::support::reference::elastica_tip;
use cosserat::cosserat_backend_cpu::StiffSettings;
use cosserat::cosserat_model::Material;
use cosserat::cosserat_model::stability::{StabilityInput, stable_step};
use cosserat::{Ordering, RodBuilder, RodHandle, SimulationBuilder};
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;
use std::process::Command;
use std::time::Instant;

/// One measured point.
#[derive(Clone, Debug, Serialize)]
struct Point {
    problem: &'static str,
    family: String,
    solver: String,
    sweeps: usize,
    extensible: bool,
    precision: &'static str,
    elements: usize,
    dt: f64,
    wall_s: f64,
    error: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Solver {
    Iterative(usize),
    Direct,
    Extensible,
    /// The stiff scheme (XPBD, direct banded solve), default settings.
    Stiff,
    /// The same with BDF2 time integration (`solver.stiff.integrator = "bdf2"`).
    StiffBdf2,
}

impl Solver {
    fn name(self) -> String {
        match self {
            Solver::Iterative(k) => format!("iterative GS {k}"),
            Solver::Direct => "direct".into(),
            Solver::Extensible => "extensible".into(),
            Solver::Stiff => "stiff (XPBD direct)".into(),
            Solver::StiffBdf2 => "stiff BDF2 (XPBD direct)".into(),
        }
    }

    fn stiff(self) -> bool {
        matches!(self, Solver::Stiff | Solver::StiffBdf2)
    }
}

const PENDULUM_T: f64 = 0.2;

fn pendulum_run(
    solver: Solver,
    double: bool,
    n: usize,
    dt: f64,
) -> Result<([f64; 3], f64), String> {
    let steps = (PENDULUM_T / dt).round() as u64;
    let (mode, sweeps) = match solver {
        Solver::Iterative(k) => ("inextensible", k),
        Solver::Direct => ("inextensible", 1),
        Solver::Stiff | Solver::StiffBdf2 => ("inextensible", 10),
        _ => ("extensible", 0),
    };
    let mut overrides = vec![
        ("rod.0.elements", n.to_string()),
        ("solver.dt", format!("{dt:e}")),
        (
            "solver.precision",
            if double { "f64" } else { "f32" }.into(),
        ),
        ("solver.iterations", sweeps.to_string()),
        ("solver.mode", mode.into()),
        ("solver.ordering", "gauss-seidel".into()),
    ];
    if solver.stiff() {
        overrides.push(("solver.scheme", "stiff".into()));
    }
    if solver == Solver::Direct {
        overrides.push(("solver.constraint_solver", "direct".into()));
        overrides.push(("solver.check_stability", "false".into()));
    }
    if solver == Solver::StiffBdf2 {
        overrides.push(("solver.stiff.integrator", "bdf2".into()));
    }
    let b = pendulum(&overrides)?;
    let mut sim = b.build().map_err(|e| e.to_string())?;
    let t = Instant::now();
    sim.run(steps).map_err(|e| e.to_string())?;
    let wall = t.elapsed().as_secs_f64();
    Ok((*sim.positions(RodHandle(0)).last().expect("points"), wall))
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The pendulum's reference tip after [`PENDULUM_T`]: the direct solver in f64, N = 400,
/// dt = 2.5e-6 s.
fn pendulum_reference() -> Result<[f64; 3], String> {
    eprintln!("pendulum reference: direct, f64, N = 400, dt = 2.5e-6 ...");
    Ok(pendulum_run(Solver::Direct, true, 400, 2.5e-6)?.0)
}

fn pendulum_sweep(reference: [f64; 3]) -> Result<Vec<Point>, String> {
    let spec = pendulum_spec(1);
    let length = dist(&spec.points[0], &spec.points[1]);
    let mut out = Vec::new();
    let mut push =
        |family: &str, solver: Solver, double: bool, n: usize, dt: f64| -> Result<(), String> {
            let mat = spec.spec.material;
            let limit = stable_step(&StabilityInput::new(
                &mat,
                length / n as f64,
                solver == Solver::Extensible,
            ))
            .max_dt;
            if dt > limit && !solver.stiff() {
                return Ok(());
            }
            let (tip, wall) = match pendulum_run(solver, double, n, dt) {
                Ok(r) => r,
                Err(e) if solver.stiff() => {
                    eprintln!("  {family}, N {n}, dt {dt:e}: {e} (left out)");
                    return Ok(());
                }
                Err(e) => return Err(e),
            };
            out.push(Point {
                problem: "pendulum",
                family: family.into(),
                solver: solver.name(),
                sweeps: if let Solver::Iterative(k) = solver {
                    k
                } else {
                    0
                },
                extensible: solver == Solver::Extensible,
                precision: if double { "f64" } else { "f32" },
                elements: n,
                dt,
                wall_s: wall,
                error: dist(&tip, &reference) / length,
            });
            Ok(())
        };
    for double in [false, true] {
        let p = if double { "f64" } else { "f32" };
        for (name, solver) in [
            ("iterative GS 10", Solver::Iterative(10)),
            ("direct", Solver::Direct),
            ("extensible", Solver::Extensible),
        ] {
            for n in [25, 50, 100, 200] {
                for dt in [4e-5, 2e-5, 1e-5] {
                    push(&format!("{name}, {p}"), solver, double, n, dt)?;
                }
            }
        }
        for n in [25, 50, 100, 200] {
            for dt in [1e-3, 2e-4, 4e-5, 1e-5] {
                push(&format!("stiff, {p}"), Solver::Stiff, double, n, dt)?;
                push(
                    &format!("stiff BDF2, {p}"),
                    Solver::StiffBdf2,
                    double,
                    n,
                    dt,
                )?;
            }
        }
        for k in [1, 3, 30, 100] {
            push(
                &format!("GS sweeps 1–100 (N 100, dt 2e-5), {p}"),
                Solver::Iterative(k),
                double,
                100,
                2e-5,
            )?;
        }
    }
    Ok(out)
}

/// The cantilever: the test rod, α = F L²/EI.
const CANTILEVER_ALPHA: f64 = 2.0;
/// A relaxation stops when the tip deflection y/L moves less than this in `1/ω₁`.
const CANTILEVER_TOLERANCE: f64 = 1e-8;
/// ... or after this many chunks of `1/ω₁`.
const CANTILEVER_CHUNKS: usize = 80;

/// The cantilever's length, material, tip force, first bending frequency ω₁ and drag rate.
struct Cantilever {
    length: f64,
    material: Material,
    force: f64,
    w1: f64,
    drag: f64,
}

fn cantilever() -> Cantilever {
    let (length, material) = (1.0f64, Material::new(1e6, 1e6 / 3.0, 1000.0, 0.02));
    let ei = material.bend_twist_stiffness()[0];
    // First bending frequency (Euler–Bernoulli is enough to set the damping and run length).
    let w1 = 1.875_104_07f64.powi(2) * (ei / (material.linear_density() * length.powi(4))).sqrt();
    Cantilever {
        length,
        material,
        force: CANTILEVER_ALPHA * ei / (length * length),
        w1,
        drag: 2.0 * w1,
    }
}

/// The static tip deflection y/L of the shearable elastica at [`CANTILEVER_ALPHA`].
fn cantilever_reference() -> f64 {
    let material = cantilever().material;
    let sigma = material.bend_twist_stiffness()[0] / material.shear_stiffness();
    elastica_tip(CANTILEVER_ALPHA, sigma, 4000).1
}

/// Static tip deflection y/L at α = 2: runs until the tip moves less than 1e-8 L per 1/ω₁.
/// `stiff_dt` is the stiff scheme's step as a multiple of `1/ω₁` (the others run at half their
/// stable step).
fn cantilever_run(
    solver: Solver,
    double: bool,
    n: usize,
    stiff_dt: f64,
) -> Result<(f64, f64, f64), String> {
    let Cantilever {
        length,
        material,
        force,
        w1,
        drag,
    } = cantilever();
    let mut input = StabilityInput::new(&material, length / n as f64, solver == Solver::Extensible);
    input.drag = drag;
    let dt = if solver == Solver::Stiff {
        stiff_dt / w1
    } else {
        0.5 * stable_step(&input).critical_dt
    };
    let chunk = (1.0 / (w1 * dt)).ceil() as u64;
    let max_chunks = CANTILEVER_CHUNKS;
    let sweeps = if let Solver::Iterative(k) = solver {
        k
    } else {
        0
    };
    let rod = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], length, n, material)
        .clamp_start()
        .damping(0.0, 0.0, drag)
        .load(n, [0.0, 0.0, -force]);
    let mut sim = SimulationBuilder::new()
        .check_stability(false)
        .stiff_solver((solver == Solver::Stiff).then(StiffSettings::default))
        .direct_constraints(solver == Solver::Direct)
        .dt(dt)
        .iterations(sweeps)
        .ordering(Ordering::GaussSeidel)
        .extensible(solver == Solver::Extensible)
        .gravity([0.0; 3])
        .double_precision(double)
        .with_rod(rod)
        .build()
        .map_err(|e| e.to_string())?;
    let t = Instant::now();
    let mut prev = 0.0;
    for _ in 0..max_chunks {
        sim.run(chunk).map_err(|e| e.to_string())?;
        let y = -sim.positions(RodHandle(0))[n][2] / length;
        if (y - prev).abs() < CANTILEVER_TOLERANCE {
            prev = y;
            break;
        }
        prev = y;
    }
    Ok((prev, t.elapsed().as_secs_f64(), dt))
}

fn cantilever_sweep() -> Result<Vec<Point>, String> {
    let y_ref = cantilever_reference();
    let mut out = Vec::new();
    for double in [false, true] {
        let p = if double { "f64" } else { "f32" };
        for (name, solver) in [
            ("iterative GS 10", Solver::Iterative(10)),
            ("direct", Solver::Direct),
            ("extensible", Solver::Extensible),
        ] {
            for n in [8, 16, 32, 64] {
                let (y, wall, dt) = cantilever_run(solver, double, n, 0.0)?;
                out.push(Point {
                    problem: "cantilever",
                    family: format!("{name}, {p}"),
                    solver: solver.name(),
                    sweeps: if let Solver::Iterative(k) = solver {
                        k
                    } else {
                        0
                    },
                    extensible: solver == Solver::Extensible,
                    precision: p,
                    elements: n,
                    dt,
                    wall_s: wall,
                    error: ((y - y_ref) / y_ref).abs(),
                });
            }
        }
        for stiff_dt in [0.1, 0.01] {
            for n in [8, 16, 32, 64] {
                let family = format!("stiff (dt {stiff_dt}/ω₁), {p}");
                match cantilever_run(Solver::Stiff, double, n, stiff_dt) {
                    Ok((y, wall, dt)) => out.push(Point {
                        problem: "cantilever",
                        family,
                        solver: Solver::Stiff.name(),
                        sweeps: 0,
                        extensible: false,
                        precision: p,
                        elements: n,
                        dt,
                        wall_s: wall,
                        error: ((y - y_ref) / y_ref).abs(),
                    }),
                    Err(e) => eprintln!("  {family}, N {n}: {e} (left out)"),
                }
            }
        }
    }
    Ok(out)
}

/// The family of PyElastica's points.
const PYELASTICA: &str = "PyElastica 1.0";

/// The Python interpreter that runs PyElastica: `$PARETO_PYTHON`, else `python3`.
fn python() -> String {
    std::env::var("PARETO_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// The installed PyElastica's version, or why it cannot be used.
fn pyelastica_version() -> Result<String, String> {
    let py = python();
    let out = Command::new(&py)
        .args([
            "-c",
            "import elastica, importlib.metadata as m; print(m.version('pyelastica'))",
        ])
        .output()
        .map_err(|e| format!("`{py}` could not be started ({e})"))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(format!(
            "`{py} -c \"import elastica\"` failed ({})",
            err.lines().last().unwrap_or("no message").trim()
        ));
    }
    let version = String::from_utf8_lossy(&out.stdout).trim().to_string();
    if version.starts_with("1.0.") {
        Ok(version)
    } else {
        Err(format!(
            "`{py}` has PyElastica {version}, the comparison needs 1.0.x"
        ))
    }
}

/// The input of `benches/pyelastica/pareto.py`: the problems' parameters, as this file uses
/// them, the element counts swept here, the time step ladders and the references.
fn pyelastica_input(pendulum_tip: [f64; 3], cantilever_y: f64) -> serde_json::Value {
    let spec = pendulum_spec(1);
    let pm = spec.spec.material;
    let length = dist(&spec.points[0], &spec.points[1]);
    let direction = [0, 1, 2].map(|k| (spec.points[1][k] - spec.points[0][k]) / length);
    // Steps that divide PENDULUM_T (0.2 s into 200 … 20 000 steps), largest first.
    let pendulum_ladder: Vec<f64> = [
        200, 250, 320, 400, 500, 640, 800, 1000, 1250, 1600, 2000, 2500, 3200, 4000, 5000, 8000,
        10_000, 20_000,
    ]
    .iter()
    .map(|&k| PENDULUM_T / k as f64)
    .collect();
    let c = cantilever();
    // Ratio 1.25 from 2e-3 s down (the static answer does not depend on dt).
    let cantilever_ladder: Vec<f64> = (0..20).map(|k| 2e-3 / 1.25f64.powi(k)).collect();
    serde_json::json!({
        "pendulum": {
            "length": length,
            "start": spec.points[0],
            "direction": direction,
            "radius": pm.radius,
            "density": pm.density,
            "young_modulus": pm.young_modulus,
            "shear_modulus": pm.shear_modulus,
            "gravity": spec.gravity,
            "t_end": PENDULUM_T,
            "reference_tip": pendulum_tip,
            "elements": [25, 50, 100, 200],
            "dt_ladder": pendulum_ladder,
            "extra_factors": [0.5, 0.25],
        },
        "cantilever": {
            "length": c.length,
            "start": [0.0, 0.0, 0.0],
            "direction": [1.0, 0.0, 0.0],
            "radius": c.material.radius,
            "density": c.material.density,
            "young_modulus": c.material.young_modulus,
            "shear_modulus": c.material.shear_modulus,
            "tip_force": c.force,
            "omega1": c.w1,
            "drag": c.drag,
            "tolerance": CANTILEVER_TOLERANCE,
            "max_chunks": CANTILEVER_CHUNKS,
            "reference_deflection": cantilever_y,
            "elements": [8, 16, 32, 64],
            "dt_ladder": cantilever_ladder,
        },
    })
}

/// A point as `benches/pyelastica/pareto.py` writes it.
#[derive(serde::Deserialize)]
struct PyPoint {
    problem: String,
    solver: String,
    elements: usize,
    dt: f64,
    wall_s: f64,
    error: f64,
}

/// Runs `benches/pyelastica/pareto.py` serially with `NUMBA_NUM_THREADS=1` (its progress goes to
/// stderr) and returns its points (all element counts, or two per problem with `quick`).
fn pyelastica_sweep(
    pendulum_tip: [f64; 3],
    cantilever_y: f64,
    quick: bool,
) -> Result<Vec<Point>, String> {
    let tmp = std::env::temp_dir();
    let id = std::process::id();
    let input = tmp.join(format!("pareto-pyelastica-{id}-in.json"));
    let output = tmp.join(format!("pareto-pyelastica-{id}-out.json"));
    std::fs::write(
        &input,
        serde_json::to_string_pretty(&pyelastica_input(pendulum_tip, cantilever_y))
            .map_err(|e| e.to_string())?,
    )
    .map_err(|e| e.to_string())?;
    let mut cmd = Command::new(python());
    cmd.arg(workspace_file("benches/pyelastica/pareto.py"))
        .arg("--input")
        .arg(&input)
        .arg("--output")
        .arg(&output)
        .env("NUMBA_NUM_THREADS", "1")
        .env("OMP_NUM_THREADS", "1")
        .env("OPENBLAS_NUM_THREADS", "1")
        .env("MKL_NUM_THREADS", "1");
    if quick {
        cmd.arg("--quick");
    }
    let status = cmd
        .status()
        .map_err(|e| format!("{} could not be started: {e}", python()))?;
    let _ = std::fs::remove_file(&input);
    if !status.success() {
        return Err(format!("benches/pyelastica/pareto.py failed ({status})"));
    }
    let text = std::fs::read_to_string(&output).map_err(|e| e.to_string())?;
    let _ = std::fs::remove_file(&output);
    let points: Vec<PyPoint> = serde_json::from_str(&text).map_err(|e| e.to_string())?;
    points
        .into_iter()
        .map(|p| {
            Ok(Point {
                problem: match p.problem.as_str() {
                    "pendulum" => "pendulum",
                    "cantilever" => "cantilever",
                    other => return Err(format!("PyElastica point of unknown problem `{other}`")),
                },
                family: PYELASTICA.into(),
                solver: p.solver,
                sweeps: 0,
                extensible: true,
                precision: "f64",
                elements: p.elements,
                dt: p.dt,
                wall_s: p.wall_s,
                error: p.error,
            })
        })
        .collect()
}

/// Points not dominated by another (less or equal time and error, one strictly).
fn front(points: &[&Point]) -> Vec<Point> {
    let mut f: Vec<Point> = points
        .iter()
        .filter(|p| {
            !points.iter().any(|q| {
                q.wall_s <= p.wall_s
                    && q.error <= p.error
                    && (q.wall_s < p.wall_s || q.error < p.error)
            })
        })
        .map(|p| (*p).clone())
        .collect();
    f.sort_by(|a, b| a.wall_s.total_cmp(&b.wall_s));
    f
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    points: &[&Point],
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    /// How a legend entry is drawn.
    enum Key {
        Dot(RGBAColor),
        Triangle(RGBColor),
        Line(RGBColor),
        Dashed(RGBColor),
    }
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    // The legend goes to the right of the plot, where it hides no point.
    let legend_width = 300;
    let (plot, side) = root.split_horizontally(root.dim_in_pixel().0 as i32 - legend_width);
    let (t0, t1) = points.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
        (a.min(p.wall_s), b.max(p.wall_s))
    });
    let (e0, e1) = points
        .iter()
        .filter(|p| p.error > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(a, b), p| {
            (a.min(p.error), b.max(p.error))
        });
    let mut chart = ChartBuilder::on(&plot)
        .caption(title, ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (t0 / 1.5..t1 * 1.5).log_scale(),
            (e0 / 2.0..e1 * 2.0).log_scale(),
        )
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("wall time per run [s] (serial, this machine)")
        .y_desc("relative error")
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .x_label_formatter(&|x| format!("{x:.0e}"))
        .draw()
        .map_err(e)?;
    let mut keys: Vec<(String, Key)> = Vec::new();
    let mut families: Vec<&str> = points
        .iter()
        .map(|p| p.family.as_str())
        .filter(|f| *f != PYELASTICA)
        .collect();
    families.dedup();
    families.sort();
    families.dedup();
    for (k, fam) in families.iter().enumerate() {
        let color = Palette99::pick(k).to_rgba();
        let mut pts: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.family == *fam && p.error > 0.0)
            .map(|p| (p.wall_s, p.error))
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(
                pts.iter()
                    .map(|&(x, y)| Circle::new((x, y), 4, color.filled())),
            )
            .map_err(e)?;
        keys.push((fam.to_string(), Key::Dot(color)));
    }
    let (ours, theirs) = split(points);
    let fr: Vec<(f64, f64)> = front(&ours).iter().map(|p| (p.wall_s, p.error)).collect();
    chart
        .draw_series(LineSeries::new(fr, BLACK.stroke_width(1)))
        .map_err(e)?;
    keys.push(("Pareto front".into(), Key::Line(BLACK)));
    if !theirs.is_empty() {
        let red = RGBColor(220, 0, 0);
        let pts: Vec<(f64, f64)> = theirs
            .iter()
            .filter(|p| p.error > 0.0)
            .map(|p| (p.wall_s, p.error))
            .collect();
        chart
            .draw_series(
                pts.iter()
                    .map(|&(x, y)| TriangleMarker::new((x, y), 6, red.filled())),
            )
            .map_err(e)?;
        keys.push((PYELASTICA.into(), Key::Triangle(red)));
        let fr: Vec<(f64, f64)> = front(&theirs).iter().map(|p| (p.wall_s, p.error)).collect();
        chart
            .draw_series(DashedLineSeries::new(fr, 6, 4, red.stroke_width(1)))
            .map_err(e)?;
        keys.push((format!("{PYELASTICA} Pareto front"), Key::Dashed(red)));
    }
    for (k, (label, key)) in keys.iter().enumerate() {
        let y = 60 + 20 * k as i32;
        match key {
            Key::Dot(c) => side.draw(&Circle::new((15, y), 4, c.filled())),
            Key::Triangle(c) => side.draw(&TriangleMarker::new((15, y), 6, c.filled())),
            Key::Line(c) => side.draw(&PathElement::new(vec![(3, y), (27, y)], *c)),
            Key::Dashed(c) => side
                .draw(&PathElement::new(vec![(3, y), (11, y)], *c))
                .and_then(|()| side.draw(&PathElement::new(vec![(19, y), (27, y)], *c))),
        }
        .map_err(e)?;
        side.draw(&Text::new(
            label.clone(),
            (35, y - 7),
            ("sans-serif", 13).into_font(),
        ))
        .map_err(e)?;
    }
    root.present().map_err(e)?;
    Ok(())
}

/// This crate's points and PyElastica's.
fn split<'a>(points: &[&'a Point]) -> (Vec<&'a Point>, Vec<&'a Point>) {
    points.iter().partition(|p| p.family != PYELASTICA)
}

/// `heading`'s table of the fastest setting per accuracy and its Pareto front.
fn guidance(heading: &str, points: &[&Point]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\n### {heading}: fastest setting reaching each accuracy\n"
    );
    s.push_str("| target error | fastest setting | N | dt [s] | error | wall [s] |\n|---|---|---|---|---|---|\n");
    for target in [1e-1, 1e-2, 1e-3, 1e-4, 1e-5] {
        match points
            .iter()
            .filter(|p| p.error <= target)
            .min_by(|a, b| a.wall_s.total_cmp(&b.wall_s))
        {
            Some(p) => {
                let _ = writeln!(
                    s,
                    "| {target:.0e} | {} | {} | {:.1e} | {:.2e} | {:.3} |",
                    p.family, p.elements, p.dt, p.error, p.wall_s
                );
            }
            None => {
                let _ = writeln!(s, "| {target:.0e} | none of the settings swept | | | | |");
            }
        }
    }
    let _ = writeln!(
        s,
        "\nPareto front (no other setting is both faster and more accurate):\n"
    );
    for p in front(points) {
        let _ = writeln!(
            s,
            "- {} — N {}, dt {:.1e}: error {:.2e} in {:.3} s",
            p.family, p.elements, p.dt, p.error, p.wall_s
        );
    }
    s
}

/// Compares the fronts at equal wall time. At each point of PyElastica's Pareto front (wall time
/// `t`, error `e`; PyElastica reaches nothing better up to the next such point), the lowest error
/// of this crate's settings that take at most `t`; and the fastest of this crate's settings
/// reaching `e`. Ours is below everywhere when it is below at every one of those points.
fn comparison(problem: &str, ours: &[&Point], theirs: &[&Point]) -> String {
    let fr = front(theirs);
    if fr.is_empty() {
        return format!("\n{PYELASTICA} has no point on the {problem}.\n");
    }
    let mut below = 0;
    let mut not_below = Vec::new();
    let mut speedups = Vec::new();
    for q in &fr {
        let best = ours
            .iter()
            .filter(|p| p.wall_s <= q.wall_s)
            .min_by(|a, b| a.error.total_cmp(&b.error));
        match best {
            Some(p) if p.error < q.error => below += 1,
            Some(p) => not_below.push(format!(
                "at {:.3} s ({PYELASTICA} N {}, dt {:.1e}: error {:.2e}) the best of ours no slower is {} N {}, dt {:.1e}: {:.2e}",
                q.wall_s, q.elements, q.dt, q.error, p.family, p.elements, p.dt, p.error
            )),
            None => not_below.push(format!(
                "at {:.3} s ({PYELASTICA} N {}, dt {:.1e}: error {:.2e}) none of our settings is that fast",
                q.wall_s, q.elements, q.dt, q.error
            )),
        }
        if let Some(p) = ours
            .iter()
            .filter(|p| p.error <= q.error)
            .min_by(|a, b| a.wall_s.total_cmp(&b.wall_s))
        {
            speedups.push(q.wall_s / p.wall_s);
        }
    }
    let mut s = format!("\n**{problem}, this crate against {PYELASTICA} at equal wall time:** ");
    if not_below.is_empty() {
        let _ = write!(
            s,
            "our error is lower everywhere: at each of the {} points of {PYELASTICA}'s Pareto front (from {:.3} s on, where its first run ends), one of our settings that takes no longer reaches a lower error.",
            fr.len(),
            fr[0].wall_s
        );
    } else {
        let _ = write!(
            s,
            "our error is lower at {below} of the {} points of {PYELASTICA}'s Pareto front, not everywhere: {}.",
            fr.len(),
            not_below.join("; ")
        );
    }
    if !speedups.is_empty() {
        let (lo, hi) = speedups
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
        let times = |x: f64| {
            if x >= 10.0 {
                format!("{x:.0}")
            } else {
                format!("{x:.2}")
            }
        };
        let (lo, hi) = (times(lo), times(hi));
        let _ = write!(
            s,
            " At equal error: each point of {PYELASTICA}'s front took {lo}–{hi} times the wall time of the fastest of our settings reaching its error ({} of its {} points reached by one of ours).",
            speedups.len(),
            fr.len()
        );
    }
    s.push('\n');
    s
}

/// The 1-, 5- and 15-minute load averages (`/proc/loadavg`), where the system has them: the
/// machine may be shared, and the wall times are only comparable within one run.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "unknown".into())
}

/// `PARETO_PYELASTICA_ONLY`: the references and PyElastica's sweep only, printed, nothing
/// written (two element counts per problem, all of them with the value `full`).
fn pyelastica_only(mode: &str) -> Result<bool, String> {
    let version = pyelastica_version()?;
    eprintln!("PyElastica {version} ({})", python());
    let pendulum_tip = pendulum_reference()?;
    let cantilever_y = cantilever_reference();
    eprintln!("references: pendulum tip {pendulum_tip:?}, cantilever y/L {cantilever_y:.9}");
    let points = pyelastica_sweep(pendulum_tip, cantilever_y, mode != "full")?;
    for p in &points {
        println!(
            "{:10} N {:4} dt {:.3e}: error {:.3e} in {:.4} s",
            p.problem, p.elements, p.dt, p.error, p.wall_s
        );
    }
    println!("(PARETO_PYELASTICA_ONLY: nothing written)");
    Ok(true)
}

pub(crate) fn run() -> Result<bool, String> {
    if let Ok(mode) = std::env::var("PARETO_PYELASTICA_ONLY") {
        return pyelastica_only(&mode);
    }
    let load_before = load_average();
    let dir = workspace_file("docs/benchmarks");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let pendulum_tip = pendulum_reference()?;
    eprintln!("pendulum sweep ...");
    let mut all = pendulum_sweep(pendulum_tip)?;
    eprintln!("cantilever sweep ...");
    all.extend(cantilever_sweep()?);
    let load_ours = load_average();
    // PyElastica 1.0 on the same problems, in the same run, when it is installed.
    let pyelastica = match pyelastica_version() {
        Ok(version) => {
            eprintln!("PyElastica {version} sweep ({}) ...", python());
            pyelastica_sweep(pendulum_tip, cantilever_reference(), false).map(|p| (version, p))
        }
        Err(e) => Err(e),
    };
    let pyelastica_note = match &pyelastica {
        Ok((version, points)) => format!(
            "PyElastica {version} ({} points, family `{PYELASTICA}`, red triangles and dashed front in the diagrams) ran the same two problems in this run after the sweeps above, serially with `NUMBA_NUM_THREADS=1` and one untimed warm-up run per problem (numba's compilation is not timed), through `benches/pyelastica/pareto.py`, whose docstring describes the set-up: the same E, G, density, radius, gravity, load, drag rate `2ω₁` (translational only, `AnalyticalLinearDamper`) and stopping rule, shear stiffness set to `G A` (PyElastica's shear coefficient 27/28 divided out), the pendulum's end pinned with `GeneralConstraint` on the position only, the cantilever clamped with `OneEndFixedBC`, `PositionVerlet`; the same references and error definitions. Its rods are extensible, so its pendulum error cannot fall below the rod's stretch under its own weight, which the inextensible reference does not have (our `extensible` family levels off the same way). For each N its time step is the largest stable one of a ladder (pendulum: also half and a quarter of it); its wall time is that of `integrate` only.",
            points.len()
        ),
        Err(e) => {
            eprintln!("PyElastica left out: {e}");
            format!(
                "PyElastica 1.0 is not in this run: {e}. Install it with `pip install pyelastica==1.0.0` for the comparison (`benches/pyelastica/pareto.py`)."
            )
        }
    };
    if let Ok((_, points)) = &pyelastica {
        all.extend(points.iter().cloned());
    }
    std::fs::write(
        dir.join("pareto.json"),
        serde_json::to_string_pretty(&all).map_err(|e| e.to_string())?,
    )
    .map_err(|e| e.to_string())?;
    let mut md = String::from(
        "Work-precision measurements (`cargo xtask bench --pareto`, release build, serial, one core of this machine). Errors: pendulum — tip distance after 0.2 s from a direct-solver f64 run with N = 400, dt = 2.5e-6, divided by the length; cantilever — relative error of the static tip deflection at α = FL²/EI = 2 against the shearable elastica. Settings of the explicit scheme outside its estimated stable region are skipped. The stiff scheme (`solver.scheme = \"stiff\"`, default settings, `docs/stiff-solver.md`) has no such limit: its pendulum points sweep dt = 1e-3 … 1e-5 s, with implicit Euler (`stiff`, the default) and with BDF2 (`stiff BDF2`, `solver.stiff.integrator = \"bdf2\"`), its cantilever points run at dt = 0.1/ω₁ and 0.01/ω₁ (ω₁ the first bending frequency). Data: `docs/benchmarks/pareto.json`; diagrams: `pareto-pendulum.{png,svg}`, `pareto-cantilever.{png,svg}`.\n",
    );
    let _ = writeln!(md, "\n{pyelastica_note}");
    let _ = writeln!(
        md,
        "\nLoad average (1, 5, 15 min) of the machine before the sweeps: {load_before}; after this crate's sweeps: {load_ours}; at the end: {}. Wall times are comparable within one run only.",
        load_average()
    );
    for (problem, title) in [
        ("pendulum", "Pendulum (free-space test), tip after 0.2 s"),
        ("cantilever", "Cantilever α = 2, static tip deflection"),
    ] {
        let pts: Vec<&Point> = all.iter().filter(|p| p.problem == problem).collect();
        let png = dir.join(format!("pareto-{problem}.png"));
        let svg = dir.join(format!("pareto-{problem}.svg"));
        draw(
            BitMapBackend::new(&png, (1300, 700)).into_drawing_area(),
            title,
            &pts,
        )?;
        draw(
            SVGBackend::new(&svg, (1300, 700)).into_drawing_area(),
            title,
            &pts,
        )?;
        let (ours, theirs) = split(&pts);
        let mut text = guidance(problem, &ours);
        if !theirs.is_empty() {
            text.push_str(&guidance(&format!("{problem}, {PYELASTICA}"), &theirs));
            text.push_str(&comparison(problem, &ours, &theirs));
        }
        md.push_str(&text);
        println!("{text}");
    }
    std::fs::write(dir.join("pareto.md"), md).map_err(|e| e.to_string())?;
    println!("wrote {}", dir.display());
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pt(family: &str, wall_s: f64, error: f64) -> Point {
        Point {
            problem: "pendulum",
            family: family.into(),
            solver: family.into(),
            sweeps: 0,
            extensible: true,
            precision: "f64",
            elements: 10,
            dt: 1e-4,
            wall_s,
            error,
        }
    }

    fn r(v: &[Point]) -> Vec<&Point> {
        v.iter().collect()
    }

    #[test]
    fn fronts_are_compared_at_equal_wall_time() {
        let ours = [pt("a", 0.01, 1e-2), pt("a", 0.1, 1e-4), pt("b", 1.0, 1e-3)];
        let below = [pt(PYELASTICA, 0.02, 5e-2), pt(PYELASTICA, 0.2, 1e-3)];
        let not_below = [pt(PYELASTICA, 0.005, 5e-2), pt(PYELASTICA, 0.05, 1e-3)];
        let s = comparison("pendulum", &r(&ours), &r(&below));
        assert!(s.contains("lower everywhere"), "{s}");
        let s = comparison("pendulum", &r(&ours), &r(&not_below));
        assert!(s.contains("lower at 0 of the 2 points"), "{s}");
        assert!(s.contains("none of our settings is that fast"), "{s}");
        // Both families in one diagram.
        let all: Vec<Point> = ours.iter().chain(&not_below).cloned().collect();
        let mut svg = String::new();
        draw(
            SVGBackend::with_string(&mut svg, (800, 600)).into_drawing_area(),
            "test",
            &r(&all),
        )
        .unwrap();
        assert!(svg.contains(PYELASTICA));
    }
}
