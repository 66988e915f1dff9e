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

fn pendulum_sweep() -> Result<Vec<Point>, String> {
    let spec = pendulum_spec(1);
    let length = dist(&spec.points[0], &spec.points[1]);
    eprintln!("pendulum reference: direct, f64, N = 400, dt = 2.5e-6 ...");
    let (reference, _) = pendulum_run(Solver::Direct, true, 400, 2.5e-6)?;
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

/// Static tip deflection y/L at α = 2: runs until the tip moves less than 1e-8 L per 1/ω₁.
/// `stiff_dt` is the stiff scheme's step as a multiple of `1/ω₁` (the others run at half their
/// stable step).
fn cantilever_run(
    solver: Solver,
    double: bool,
    n: usize,
    stiff_dt: f64,
) -> Result<(f64, f64, f64), String> {
    let (length, material) = (1.0, Material::new(1e6, 1e6 / 3.0, 1000.0, 0.02));
    let ei = material.bend_twist_stiffness()[0];
    let alpha = 2.0;
    let force = alpha * ei / (length * length);
    // First bending frequency (Euler–Bernoulli is enough to set the damping and run length).
    let w1 = 1.875_104_07f64.powi(2) * (ei / (material.linear_density() * length.powi(4))).sqrt();
    let drag = 2.0 * w1;
    let mut input = StabilityInput::new(&material, length / n as f64, solver == Solver::Extensible);
    input.drag = drag;
    let dt = if solver == Solver::Stiff {
        stiff_dt / w1
    } else {
        0.5 * stable_step(&input).critical_dt
    };
    let chunk = (1.0 / (w1 * dt)).ceil() as u64;
    let max_chunks = 80;
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
        if (y - prev).abs() < 1e-8 {
            prev = y;
            break;
        }
        prev = y;
    }
    Ok((prev, t.elapsed().as_secs_f64(), dt))
}

fn cantilever_sweep() -> Result<Vec<Point>, String> {
    let material = Material::new(1e6, 1e6 / 3.0, 1000.0, 0.02);
    let sigma = material.bend_twist_stiffness()[0] / material.shear_stiffness();
    let (_, y_ref) = elastica_tip(2.0, sigma, 4000);
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
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    let (t0, t1) = points.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
        (a.min(p.wall_s), b.max(p.wall_s))
    });
    let (e0, e1) = points
        .iter()
        .filter(|p| p.error > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(a, b), p| {
            (a.min(p.error), b.max(p.error))
        });
    let mut chart = ChartBuilder::on(&root)
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
    let mut families: Vec<&str> = points.iter().map(|p| p.family.as_str()).collect();
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
            .map_err(e)?
            .label(*fam)
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
    }
    let fr: Vec<(f64, f64)> = front(points).iter().map(|p| (p.wall_s, p.error)).collect();
    chart
        .draw_series(LineSeries::new(fr, BLACK.stroke_width(1)))
        .map_err(e)?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .label_font(("sans-serif", 13))
        .draw()
        .map_err(e)?;
    root.present().map_err(e)?;
    Ok(())
}

fn guidance(problem: &str, points: &[&Point]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\n### {problem}: fastest setting reaching each accuracy\n"
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

/// The 1-, 5- and 15-minute load averages (`/proc/loadavg`), where the system has them: the
/// machine may be shared, and the wall times are only comparable within one run.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "unknown".into())
}

pub(crate) fn run() -> Result<bool, String> {
    let load_before = load_average();
    let dir = workspace_file("docs/benchmarks");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    eprintln!("pendulum sweep ...");
    let mut all = pendulum_sweep()?;
    eprintln!("cantilever sweep ...");
    all.extend(cantilever_sweep()?);
    std::fs::write(
        dir.join("pareto.json"),
        serde_json::to_string_pretty(&all).map_err(|e| e.to_string())?,
    )
    .map_err(|e| e.to_string())?;
    let mut md = String::from(
        "Work-precision measurements (`cargo xtask bench --pareto`, release build, serial, one core of this machine). Errors: pendulum — tip distance after 0.2 s from a direct-solver f64 run with N = 400, dt = 2.5e-6, divided by the length; cantilever — relative error of the static tip deflection at α = FL²/EI = 2 against the shearable elastica. Settings of the explicit scheme outside its estimated stable region are skipped. The stiff scheme (`solver.scheme = \"stiff\"`, default settings, `docs/stiff-solver.md`) has no such limit: its pendulum points sweep dt = 1e-3 … 1e-5 s, with implicit Euler (`stiff`, the default) and with BDF2 (`stiff BDF2`, `solver.stiff.integrator = \"bdf2\"`), its cantilever points run at dt = 0.1/ω₁ and 0.01/ω₁ (ω₁ the first bending frequency). Data: `docs/benchmarks/pareto.json`; diagrams: `pareto-pendulum.{png,svg}`, `pareto-cantilever.{png,svg}`.\n",
    );
    let _ = writeln!(
        md,
        "\nLoad average (1, 5, 15 min) of the machine before the sweeps: {load_before}; after: {}. Wall times are comparable within one run only.",
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
            BitMapBackend::new(&png, (1000, 700)).into_drawing_area(),
            title,
            &pts,
        )?;
        draw(
            SVGBackend::new(&svg, (1000, 700)).into_drawing_area(),
            title,
            &pts,
        )?;
        md.push_str(&guidance(problem, &pts));
        println!("{}", guidance(problem, &pts));
    }
    std::fs::write(dir.join("pareto.md"), md).map_err(|e| e.to_string())?;
    println!("wrote {}", dir.display());
    Ok(true)
}
