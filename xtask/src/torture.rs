//! `cargo xtask torture`: every instrument preset pushed and twisted through vessels that make
//! contact hard, each frame checked by the inside test (an oracle independent of the contact
//! queries), into `docs/benchmarks/torture.md`.
//!
//! Vessels: the generated tree; a generated tree with a strong bow and a trunk narrowing to a
//! third of its inlet (a stenosis-like taper); a generated tree with a stenosis to 40 % of the
//! radius, a fusiform aneurysm of 1.8× and a branch leaving at 80°; the vascular phantom of
//! `data/meshes/`; the phantom with injected defects the mesh intake must repair (a tenth of
//! its triangles flipped in patches and a loose fragment; a seam, zero-area triangles, faces
//! of two vertices and 32 fragments); the phantom with its ends closed, entered through a
//! port; and the carotid bifurcation of `data/meshes/`. Instruments: the soft wire of the
//! insertion scenes and the `nitinol`, `steel` and `catheter-polymer` presets, with the stiff
//! scheme at the steps the README recommends in a vessel (1 ms, 0.1 ms, 0.05 ms, 0.1 ms). The
//! hand pushes at 0.2 m/s and twists back and forth (5 rad/s, 1.5 Hz) through the control API
//! every millisecond, for one second (0.35 s in the carotid, whose branches are shorter); after
//! every millisecond the inside test counts the points outside the lumen at any depth. A run
//! that diverges is reported with where it stopped. The exit status is non-zero when any point
//! was ever outside, a run diverged, or a run's `max_penetration` disagreed with the inside
//! test's deepest sphere by more than 5 %. A second table gives each step's time by the number
//! of points in contact at its end, against the generated tree's at as many contacts.

use crate::bench::{conditions, machine, root};
use cosserat::cosserat_collide::{Bulge, VesselParams};
use cosserat::scene::load_scene;
use cosserat::{Environment, RodHandle, StateField};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One vessel of the suite.
struct Vessel {
    label: &'static str,
    scene: &'static str,
    /// Overrides of the scene.
    set: Vec<(String, String)>,
    /// A generated tree that replaces the scene's environment.
    tree: Option<VesselParams>,
    /// How long the hand pushes [s]: up to the vessel's length at 0.2 m/s.
    seconds: f64,
}

/// One instrument: a material at its recommended step.
struct Instrument {
    label: &'static str,
    /// The scene's `rod.0.material` value.
    material: &'static str,
    dt: f64,
}

const INSTRUMENTS: [Instrument; 4] = [
    Instrument {
        label: "soft",
        material: "{ young_modulus = 5.0e6, poisson_ratio = 0.5, density = 1100.0, radius = 4.0e-4 }",
        dt: 1e-3,
    },
    Instrument {
        label: "nitinol",
        material: "{ preset = \"nitinol\" }",
        dt: 1e-4,
    },
    Instrument {
        label: "steel",
        material: "{ preset = \"steel\" }",
        dt: 5e-5,
    },
    Instrument {
        label: "catheter-polymer",
        material: "{ preset = \"catheter-polymer\" }",
        dt: 1e-4,
    },
];

/// What a maintainer may change about the whole suite (`cargo xtask torture --contact-rows
/// VALUE --dt SECONDS`); the default run leaves both as the scenes and [`INSTRUMENTS`] have them.
#[derive(Default)]
pub(crate) struct Variant {
    /// The TOML value given to `solver.stiff.contact_rows` in every run.
    pub(crate) contact_rows: Option<String>,
    /// One step for every instrument instead of its recommended one [s].
    pub(crate) dt: Option<f64>,
}

impl Variant {
    /// The page a run of the whole suite writes: `torture.md` for the default, else a page of
    /// its own named by what it changed, so that the default table is never overwritten by a
    /// variant.
    fn page(&self) -> String {
        let mut name = String::from("torture");
        if let Some(dt) = self.dt {
            name.push_str(&format!("-dt{dt:e}"));
        }
        if let Some(rows) = &self.contact_rows {
            let value: String = rows.chars().filter(char::is_ascii_alphanumeric).collect();
            name.push_str(&format!("-contact-rows-{value}"));
        }
        name + ".md"
    }

    /// The command line that makes the page.
    fn command(&self) -> String {
        let mut c = String::from("cargo xtask torture");
        if let Some(rows) = &self.contact_rows {
            c.push_str(&format!(" --contact-rows {rows}"));
        }
        if let Some(dt) = self.dt {
            c.push_str(&format!(" --dt {dt:e}"));
        }
        c
    }
}

/// Bins of the number of points in contact at the end of a step, `(from, to)` inclusive: the
/// step's cost is compared between vessels at the same number of contacts.
const CONTACT_BINS: [(usize, usize); 6] =
    [(0, 0), (1, 2), (3, 5), (6, 10), (11, 20), (21, usize::MAX)];

/// Per run: the vessel's index, the instrument and [`Outcome::by_contacts`].
type RunCost = (usize, &'static str, [(f64, usize); CONTACT_BINS.len()]);

/// Fewer steps than this in a bin give no figure for it: too few to time.
const BIN_MIN_STEPS: usize = 100;

/// What one run found.
struct Outcome {
    frames: usize,
    /// The most points the inside test found outside at once, and the deepest of any check.
    most_outside: usize,
    deepest: f64,
    /// What the run's contact statistics report: the most points outside the lumen at the end
    /// of a step (`escaped_points`) and the deepest penetration (`max_penetration`).
    contact_escaped: usize,
    contact_depth: f64,
    /// The stiff solver's iterations and factorisations per step, and the points in contact at
    /// the end: where the step's time goes.
    iterations: f64,
    factorisations: f64,
    /// Steps kept above the solver's tolerance, and the largest residual of any step.
    unconverged: u64,
    max_residual: f64,
    contacts: usize,
    us_per_step: f64,
    /// Of which in the contact queries.
    detection_us_per_step: f64,
    /// The fastest any point moved over a tick [m/s]: a whip, or a solve gone wrong.
    fastest: f64,
    /// The deepest any inside point's sphere reached into the wall after any step, by the
    /// oracle: the radius less the point's distance from the mesh [m].
    sphere_depth: f64,
    stopped: Option<String>,
    /// Wall time [s] and number of the steps that ended with a number of points in contact in
    /// each of [`CONTACT_BINS`].
    by_contacts: [(f64, usize); CONTACT_BINS.len()],
    /// When a point was first found outside: time [s], point and depth [m].
    first_outside: Option<(f64, usize, f64)>,
}

/// The phantom with a tenth of its triangles flipped (in patches around every tenth vertex) and
/// a loose tetrahedron beside it, written as an OBJ file.
fn defective_phantom(dir: &Path) -> Result<PathBuf, String> {
    let (mesh, _) =
        cosserat::cosserat_collide::load_mesh(root().join("data/meshes/phantom.obj"), 1.0)
            .map_err(|e| e.to_string())?;
    let mut text = String::new();
    for v in mesh.vertices() {
        let _ = writeln!(text, "v {} {} {}", v.x, v.y, v.z);
    }
    let seeds: Vec<usize> = (0..mesh.vertices().len()).step_by(97).collect();
    let near_seed = |t: [u32; 3]| {
        seeds.iter().any(|&s| {
            t.iter()
                .any(|&v| (mesh.vertices()[v as usize] - mesh.vertices()[s]).norm() < 4.0)
        })
    };
    let mut flipped = 0;
    for &t in mesh.triangles() {
        let t = if near_seed(t) {
            flipped += 1;
            [t[0], t[2], t[1]]
        } else {
            t
        };
        let _ = writeln!(text, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    let base = mesh.vertices().len() + 1;
    for v in [
        [50.0, 50.0, 50.0],
        [52.0, 50.0, 50.0],
        [50.0, 52.0, 50.0],
        [50.0, 50.0, 52.0],
    ] {
        let _ = writeln!(text, "v {} {} {}", v[0], v[1], v[2]);
    }
    for f in [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
        let _ = writeln!(text, "f {} {} {}", base + f[0], base + f[1], base + f[2]);
    }
    eprintln!(
        "defective phantom: {flipped} of {} triangles flipped, one loose fragment",
        mesh.triangles().len()
    );
    let path = dir.join("phantom-defective.obj");
    std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(path)
}

/// Writes `vertices` and 0-based `faces` (any number of corners) as an OBJ file.
fn write_obj(path: &Path, vertices: &[[f64; 3]], faces: &[Vec<u32>]) -> Result<(), String> {
    let mut text = String::new();
    for v in vertices {
        let _ = writeln!(text, "v {} {} {}", v[0], v[1], v[2]);
    }
    for f in faces {
        let corners: Vec<String> = f.iter().map(|i| (i + 1).to_string()).collect();
        let _ = writeln!(text, "f {}", corners.join(" "));
    }
    std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
}

fn phantom() -> Result<cosserat::cosserat_collide::TriMesh, String> {
    cosserat::cosserat_collide::load_mesh(root().join("data/meshes/phantom.obj"), 1.0)
        .map(|(mesh, _)| mesh)
        .map_err(|e| e.to_string())
}

/// The phantom with every open end closed by a fan of triangles from its centre (a vessel
/// whose ends are rounded shut, as exported anatomy often is), written as an OBJ file; and the
/// radius of the port the wire enters through: the mean radius of the end at the entry.
fn closed_phantom(dir: &Path, entry: [f64; 3]) -> Result<(PathBuf, f64), String> {
    let mesh = phantom()?;
    let mut vertices: Vec<[f64; 3]> = mesh.vertices().iter().map(|v| [v.x, v.y, v.z]).collect();
    let mut faces: Vec<Vec<u32>> = mesh.triangles().iter().map(|t| t.to_vec()).collect();
    let mut port = f64::INFINITY;
    let mut nearest = f64::INFINITY;
    for cap in cosserat::cosserat_collide::opening_caps(&mesh) {
        // Each fan triangle is (centre, rim, rim).
        let centre = cap[0][0];
        let radius = cap.iter().map(|t| (t[1] - centre).norm()).sum::<f64>() / cap.len() as f64;
        let d = (centre - nalgebra::Vector3::from(entry)).norm();
        if d < nearest {
            (nearest, port) = (d, radius);
        }
        for t in cap {
            let base = vertices.len() as u32;
            vertices.extend(t.iter().map(|v| [v.x, v.y, v.z]));
            faces.push(vec![base, base + 1, base + 2]);
        }
    }
    let path = dir.join("phantom-closed.obj");
    write_obj(&path, &vertices, &faces)?;
    eprintln!("closed phantom: port radius {port:.2} mm at the entry's end");
    Ok((path, port))
}

/// The phantom cut in two by a seam (the triangles beyond x = −150 mm use copies of their
/// vertices, so that the two halves share no vertex, as separately exported parts do), with 36
/// zero-area triangles, two faces of two vertices and 32 loose fragments (small tetrahedra
/// outside the vessel), written as an OBJ file.
fn seamed_phantom(dir: &Path) -> Result<PathBuf, String> {
    let mesh = phantom()?;
    let mut vertices: Vec<[f64; 3]> = mesh.vertices().iter().map(|v| [v.x, v.y, v.z]).collect();
    let copy = vertices.len() as u32;
    vertices.extend_from_within(..);
    let mut faces: Vec<Vec<u32>> = Vec::new();
    for t in mesh.triangles() {
        let centroid_x: f64 = t
            .iter()
            .map(|&v| mesh.vertices()[v as usize].x)
            .sum::<f64>()
            / 3.0;
        let shift = if centroid_x < -150.0 { copy } else { 0 };
        faces.push(t.iter().map(|&v| v + shift).collect());
    }
    for t in mesh
        .triangles()
        .iter()
        .step_by(mesh.triangles().len() / 36)
        .take(36)
    {
        faces.push(vec![t[0], t[1], t[1]]);
    }
    faces.push(vec![0, 1]);
    faces.push(vec![2, 3]);
    for k in 0..32 {
        let base = vertices.len() as u32;
        let at = [40.0 + 3.0 * k as f64, 80.0, 40.0];
        for d in [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ] {
            vertices.push([at[0] + d[0], at[1] + d[1], at[2] + d[2]]);
        }
        for f in [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
            faces.push(f.iter().map(|&i| base + i).collect());
        }
    }
    let path = dir.join("phantom-seamed.obj");
    write_obj(&path, &vertices, &faces)?;
    Ok(path)
}

fn run_one(vessel: &Vessel, instrument: &Instrument, variant: &Variant) -> Result<Outcome, String> {
    let mut set = vessel.set.clone();
    let dt = variant.dt.unwrap_or(instrument.dt);
    if let Some(rows) = &variant.contact_rows {
        set.push(("solver.stiff.contact_rows".to_string(), rows.clone()));
    }
    set.extend([
        ("solver.scheme".to_string(), "\"stiff\"".to_string()),
        ("solver.precision".to_string(), "\"f64\"".to_string()),
        ("solver.dt".to_string(), format!("{dt:e}")),
        ("rod.0.elements".to_string(), "256".to_string()),
        (
            "rod.0.material".to_string(),
            instrument.material.to_string(),
        ),
        ("environment.stop_outside".to_string(), "false".to_string()),
    ]);
    let (mut builder, _, _) =
        load_scene(&root().join(vessel.scene), &set).map_err(|e| e.to_string())?;
    if let Some(params) = &vessel.tree {
        let mut env = Environment::vessel_with(params).map_err(|e| e.to_string())?;
        env.stop_outside = false;
        if let Some(old) = builder.environment_ref() {
            env.friction = old.friction;
            env.margin = old.margin;
        }
        builder = builder.environment(env);
    }
    let mut sim = builder.build().map_err(|e| e.to_string())?;
    let wire = RodHandle(0);
    let n = sim.stepper().elements(0).map_err(|e| e.to_string())?;
    let mut points = vec![[0.0; 3]; n + 1];
    sim.read(wire, StateField::Positions, &mut points)
        .map_err(|e| e.to_string())?;
    let axis = {
        let d: [f64; 3] = std::array::from_fn(|k| points[1][k] - points[0][k]);
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|x| x / l)
    };
    let per_tick = (1e-3 / dt).round().max(1.0) as u64;
    let radius = sim.rod_radius(wire);
    let mut out = Outcome {
        frames: 0,
        most_outside: 0,
        deepest: 0.0,
        contact_escaped: 0,
        contact_depth: 0.0,
        iterations: 0.0,
        factorisations: 0.0,
        unconverged: 0,
        max_residual: 0.0,
        contacts: 0,
        us_per_step: 0.0,
        detection_us_per_step: 0.0,
        fastest: 0.0,
        sphere_depth: 0.0,
        stopped: None,
        by_contacts: [(0.0, 0); CONTACT_BINS.len()],
        first_outside: None,
    };
    let mut wall = 0.0;
    let ticks = (vessel.seconds / 1e-3).round() as usize;
    for tick in 0..ticks {
        let t = tick as f64 * 1e-3;
        let twist = 5.0 * (2.0 * std::f64::consts::PI * 1.5 * t).sin();
        sim.set_end_velocity(wire, 0, axis.map(|a| a * 0.2), axis.map(|a| a * twist))
            .map_err(|e| e.to_string())?;
        let before = points.clone();
        let mut stopped = None;
        for _ in 0..per_tick {
            let started = Instant::now();
            let stepped = sim.run(1);
            let took = started.elapsed().as_secs_f64();
            wall += took;
            let touching = sim.stepper().collision_stats(0).map_or(0, |st| st.contacts);
            if let Some(bin) = CONTACT_BINS
                .iter()
                .position(|&(from, to)| (from..=to).contains(&touching))
            {
                out.by_contacts[bin].0 += took;
                out.by_contacts[bin].1 += 1;
            }
            if let Err(e) = stepped {
                stopped = Some(format!("t = {:.3} s: {e}", sim.time()));
                break;
            }
            // The spheres' depth in the wall after every step, by the oracle: points within a
            // radius of the mesh (a bounded tree query) and inside the lumen (the inside test).
            sim.read(wire, StateField::Positions, &mut points)
                .map_err(|e| e.to_string())?;
            if let Some(env) = sim.environment() {
                let c = &env.collider;
                for p in &points {
                    if let Some(near) = c.nearest(p, radius)
                        && c.lumen_winding(p) >= 0.5
                    {
                        out.sphere_depth = out.sphere_depth.max(radius - near.distance);
                    }
                }
            }
        }
        if stopped.is_some() {
            out.stopped = stopped;
            break;
        }
        for (a, b) in before.iter().zip(&points) {
            let d: f64 = (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
            out.fastest = out.fastest.max(d / 1e-3);
        }
        // With stop_outside off it reports and never stops the run.
        let now = sim.check_lumen().map_err(|e| e.to_string())?;
        out.most_outside = out.most_outside.max(now.count);
        out.deepest = out.deepest.max(now.deepest);
        out.frames += 1;
        if let (None, Some(point)) = (out.first_outside, now.deepest_point) {
            out.first_outside = Some((sim.time(), point, now.deepest));
        }
    }
    for rod in 0..sim.stepper().rod_count() {
        if let Some(st) = sim.stepper().collision_stats(rod) {
            out.contact_escaped = out.contact_escaped.max(st.escaped_points);
            out.contact_depth = out.contact_depth.max(st.max_penetration);
            out.contacts += st.contacts;
            out.detection_us_per_step += st.detection_seconds * 1e6 / sim.steps().max(1) as f64;
        }
    }
    if let Some(st) = sim.stiff_summary() {
        out.iterations = st.iterations_per_step();
        out.factorisations = st.factorisations_per_step();
        out.unconverged = st.unconverged_steps;
        out.max_residual = st.max_residual;
    }
    out.us_per_step = wall * 1e6 / sim.steps().max(1) as f64;
    Ok(out)
}

/// The second table of the page: each run's step time by the number of points in contact at
/// the end of the step, and its ratio to the step in the generated tree (the first vessel) with
/// the same instrument and as many contacts.
fn cost_by_contacts(vessels: &[Vessel], costs: &[RunCost]) -> String {
    let bin_label = |&(from, to): &(usize, usize)| match (from, to) {
        (f, t) if f == t => format!("{f}"),
        (f, usize::MAX) => format!("{f}+"),
        (f, t) => format!("{f}–{t}"),
    };
    let mean = |(seconds, steps): (f64, usize)| {
        (steps >= BIN_MIN_STEPS).then(|| seconds * 1e6 / steps as f64)
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        "## Step time by points in contact\n\nEach step's wall time, binned by the points in contact \
         at its end: µs/step (steps in the bin), and in brackets its ratio to the step of the same \
         instrument in the generated tree (26k triangles) with as many contacts. A bin with fewer \
         than {BIN_MIN_STEPS} steps in either run gives no figure.\n"
    );
    let header: Vec<String> = CONTACT_BINS.iter().map(bin_label).collect();
    let _ = writeln!(
        out,
        "| vessel | instrument | {} contacts |\n|---|---|{}",
        header.join(" contacts | "),
        "---|".repeat(CONTACT_BINS.len())
    );
    for (v, instrument, bins) in costs {
        let reference = costs
            .iter()
            .find(|(rv, ri, _)| *rv == 0 && ri == instrument)
            .map(|c| c.2);
        let cells: Vec<String> = (0..CONTACT_BINS.len())
            .map(|b| match mean(bins[b]) {
                None => format!("— ({})", bins[b].1),
                Some(us) => match reference.and_then(|r| mean(r[b])) {
                    Some(base) if *v != 0 => {
                        format!("{us:.0} ({}) [{:.1}×]", bins[b].1, us / base)
                    }
                    _ => format!("{us:.0} ({})", bins[b].1),
                },
            })
            .collect();
        let _ = writeln!(
            out,
            "| {} | {instrument} | {} |",
            vessels[*v].label,
            cells.join(" | ")
        );
    }
    out
}

/// Runs the suite, writes `docs/benchmarks/torture.md`; `Err` when a point was outside or a run
/// diverged.
pub(crate) fn run(only: Option<&str>, variant: &Variant) -> Result<(), String> {
    let dir = std::env::temp_dir().join(format!("cosserat-torture-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let defective = defective_phantom(&dir)?;
    let phantom_entry = [1.0, 0.42, -0.32];
    let (closed, port) = closed_phantom(&dir, phantom_entry)?;
    let seamed = seamed_phantom(&dir)?;
    let mesh_path = |p: &Path| {
        (
            "environment.mesh.path".to_string(),
            format!("\"{}\"", p.display()),
        )
    };
    let deg = std::f64::consts::PI / 180.0;
    let mut sharp = VesselParams::default();
    sharp.branches[0].angle = 80.0 * deg;
    let vessels = [
        Vessel {
            label: "generated tree (26k triangles)",
            scene: "scenes/nitinol-guidewire-insertion.toml",
            set: Vec::new(),
            tree: None,
            seconds: 1.0,
        },
        Vessel {
            label: "generated tree, bowed and narrowing to a third",
            scene: "scenes/nitinol-guidewire-insertion.toml",
            set: Vec::new(),
            tree: Some(VesselParams {
                bow: 0.08,
                trunk_radius_end: 0.0033,
                ..VesselParams::default()
            }),
            seconds: 1.0,
        },
        Vessel {
            label: "generated tree, a stenosis to 40 %, an aneurysm of 1.8× and an 80° bifurcation",
            scene: "scenes/nitinol-guidewire-insertion.toml",
            set: Vec::new(),
            tree: Some(VesselParams {
                bulges: vec![
                    Bulge {
                        at: 0.12,
                        length: 0.03,
                        factor: 0.4,
                    },
                    Bulge {
                        at: 0.35,
                        length: 0.04,
                        factor: 1.8,
                    },
                ],
                ..sharp
            }),
            seconds: 1.0,
        },
        Vessel {
            label: "vascular phantom (data/meshes)",
            scene: "scenes/phantom-insertion.toml",
            set: Vec::new(),
            tree: None,
            seconds: 1.0,
        },
        Vessel {
            label: "phantom with flipped patches and a fragment",
            scene: "scenes/phantom-insertion.toml",
            set: vec![mesh_path(&defective)],
            tree: None,
            seconds: 1.0,
        },
        Vessel {
            label: "phantom with a seam, 36 zero-area triangles, 2 two-vertex faces and 32 fragments",
            scene: "scenes/phantom-insertion.toml",
            set: vec![mesh_path(&seamed)],
            tree: None,
            seconds: 1.0,
        },
        Vessel {
            label: "phantom with its ends closed, entered through a port",
            scene: "scenes/phantom-insertion.toml",
            set: vec![
                mesh_path(&closed),
                (
                    "environment.mesh.entry".to_string(),
                    format!(
                        "{{ point = [{}, {}, {}], direction = [-1.0, 0.0, 0.0], radius = {port} }}",
                        phantom_entry[0], phantom_entry[1], phantom_entry[2]
                    ),
                ),
            ],
            tree: None,
            seconds: 1.0,
        },
        Vessel {
            label: "carotid bifurcation (data/meshes/carotids.stl)",
            scene: "scenes/phantom-insertion.toml",
            set: vec![
                mesh_path(&root().join("data/meshes/carotids.stl")),
                (
                    "environment.mesh.entry".to_string(),
                    "{ point = [0.55, 0.77, 0.22], direction = [0.0, -1.0, 0.0] }".to_string(),
                ),
            ],
            tree: None,
            // The common carotid and the internal one are about 85 mm long together.
            seconds: 0.35,
        },
    ];
    let mut table = String::new();
    let _ = writeln!(
        table,
        "| vessel | instrument | step | frames checked | points outside (inside test) | deepest [mm] | outside (statistics) | deepest (statistics) [µm] | deepest sphere (inside test) [µm] | first outside | contacts at the end | iterations / factorisations per step | steps above the tolerance (largest residual) | µs/step | of which contact queries | fastest point [m/s] | stopped |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    let mut clean = true;
    // Per run: vessel, instrument and the step's cost by contacts.
    let mut costs: Vec<RunCost> = Vec::new();
    for (v, vessel) in vessels.iter().enumerate() {
        for instrument in &INSTRUMENTS {
            let name = format!("{} × {}", vessel.label, instrument.label);
            if only.is_some_and(|o| !name.contains(o)) {
                continue;
            }
            eprintln!("{} × {} …", vessel.label, instrument.label);
            let dt = variant.dt.unwrap_or(instrument.dt);
            let row = match run_one(vessel, instrument, variant) {
                Ok(o) => {
                    // The statistics agree with the oracle's depth within 5 % (and rounding).
                    let agree = (o.contact_depth - o.sphere_depth).abs()
                        <= 0.05 * o.sphere_depth.max(o.contact_depth) + 1e-9;
                    clean &= o.most_outside == 0
                        && o.contact_escaped == 0
                        && o.stopped.is_none()
                        && agree;
                    costs.push((v, instrument.label, o.by_contacts));
                    format!(
                        "| {} | {} | {:e} s | {} | {} | {:.2} | {} | {:.2} | {:.2} | {} | {} | {:.2} / {:.2} | {} ({:.1e}) | {:.1} | {:.1} | {:.2} | {} |",
                        vessel.label,
                        instrument.label,
                        dt,
                        o.frames,
                        o.most_outside,
                        o.deepest * 1e3,
                        o.contact_escaped,
                        o.contact_depth * 1e6,
                        o.sphere_depth * 1e6,
                        o.first_outside.map_or("—".to_string(), |(t, p, d)| format!(
                            "t = {t:.3} s, point {p}, {:.2} mm",
                            d * 1e3
                        )),
                        o.contacts,
                        o.iterations,
                        o.factorisations,
                        o.unconverged,
                        o.max_residual,
                        o.us_per_step,
                        o.detection_us_per_step,
                        o.fastest,
                        o.stopped.as_deref().unwrap_or("no")
                    )
                }
                Err(e) => {
                    clean = false;
                    format!(
                        "| {} | {} | {:e} s | — | — | — | — | — | — | — | — | — | — | — | — | — | could not run: {e} |",
                        vessel.label, instrument.label, dt
                    )
                }
            };
            println!("{row}");
            let _ = writeln!(table, "{row}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
    let by_contacts = cost_by_contacts(&vessels, &costs);
    print!("{by_contacts}");
    let doc = format!(
        "# Torture suite: instruments through hard vessels, checked by the inside test\n\n\
         Machine: {}; {}. Command: `{}` (`xtask/src/torture.rs`, whose module \
         docs say what each run does). Each run: 256 elements, the stiff scheme in f64 at {}, \
         contacts {}, the hand pushing at 0.2 m/s and \
         twisting at up to 5 rad/s for 1 s through the control API, one tick a millisecond. \
         `frames checked`: inside tests made (after every millisecond tick); `points outside \
         (inside test)`: the most points the inside test found outside the lumen at once, and \
         `deepest` the deepest of them (distance behind the wall plus the radius); `outside \
         (statistics)` and `deepest (statistics)`: what the run's contact statistics report \
         (`escaped_points`, `max_penetration`), which must agree with the inside test's depth \
         within 5 %; `deepest sphere`: \
         the deepest any point's sphere reached into the wall after any step, by the inside \
         test and the distance from the mesh (radius less distance, points inside the lumen), \
         its independent measure; \
         `first outside`: when, which point and how deep the inside test first found a \
         point outside; `steps above the tolerance`: steps the stiff solver kept with a \
         residual above its tolerance (1e-5), and the largest residual of any step; `µs/step`: wall time of the steps alone, and of that the time in the contact queries \
         (points, swept points and elements, all iterations); `fastest point`: the largest \
         distance any point moved over one millisecond tick, over the tick (the hand moves \
         at 0.2 m/s; a whipping wire is faster).\n\n{table}\n{by_contacts}",
        machine(),
        conditions(),
        variant.command(),
        match variant.dt {
            Some(dt) => format!("a step of {dt:e} s"),
            None => "the step the README recommends for the preset in a vessel".to_string(),
        },
        match &variant.contact_rows {
            Some(rows) => format!("with `solver.stiff.contact_rows = {rows}`"),
            None => "as the scene's default solver settings resolve them".to_string(),
        },
    );
    // A part of the suite does not replace the whole table.
    if only.is_none() {
        let path = root().join("docs/benchmarks").join(variant.page());
        std::fs::write(&path, doc).map_err(|e| format!("{}: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    if clean {
        Ok(())
    } else {
        Err("points left the lumen or runs stopped (see the table)".into())
    }
}
