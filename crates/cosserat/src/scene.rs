//! Scene files: TOML descriptions of rods, materials, end conditions, loads and solver settings.
//!
//! A scene is parsed into plain serde structs (unknown fields are rejected, so a typo is an
//! error rather than a silently ignored setting), then every value is checked and the scene is
//! turned into a [`SimulationBuilder`]. Every error names the file, the field (as a dotted
//! path such as `rod[0].material.radius`) and the offending value.
//!
//! Values can be overridden from the command line before checking (`--set rod.0.elements=1000`),
//! which is how one scene file serves several resolutions.

use crate::environment::{Entry, Environment};
use crate::obstacles::{Obstacle, Side};
use crate::sim::{
    BindingSpec, BindingVariant, Gpus, RodBuilder, RodContactSpec, SimulationBuilder,
};
use cosserat_backend_cpu::{
    EndCondition, EndKind, EndPath, LoadProfile, Ordering, PointLoad, PrescribedMotion,
};
use cosserat_model::Material;
use cosserat_model::rod::RestShape;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A scene that could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{path}: cannot read the scene: {source}")]
    Io {
        /// The scene file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TOML is malformed or a field has the wrong type or name.
    #[error("{path}: {message}")]
    Parse {
        /// The scene file.
        path: PathBuf,
        /// The parser's description, with the line and the field.
        message: String,
    },
    /// A field has a value outside its valid range.
    #[error("{path}: field `{field}` = {value} is invalid: {expected}")]
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// Dotted path of the field.
        field: String,
        /// The value as written.
        value: String,
        /// What a valid value looks like.
        expected: String,
    },
    /// A `--set KEY=VALUE` override could not be applied.
    #[error("{path}: override `{key}`: {reason}")]
    Override {
        /// The scene file.
        path: PathBuf,
        /// The override key.
        key: String,
        /// Why it failed.
        reason: String,
    },
}

/// The top level of a scene file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Scene name, for reports.
    pub name: Option<String>,
    /// Solver settings.
    #[serde(default)]
    pub solver: SolverSection,
    /// The rods.
    #[serde(default, rename = "rod")]
    pub rods: Vec<RodSection>,
    /// The static mesh the rods collide with, if any.
    pub environment: Option<EnvironmentSection>,
    /// More obstacles, each with its own friction and side: `[[obstacles]]`.
    #[serde(default)]
    pub obstacles: Vec<ObstacleSection>,
    /// Instruments bound inside each other (paper section 3.4): `[[binding]]`.
    #[serde(default, rename = "binding")]
    pub bindings: Vec<BindingSection>,
    /// Rod–rod and self-contact (paper section "Collisions and self-collisions").
    pub rod_contact: Option<RodContactSection>,
    /// Filtering of the reaction force reported at held ends.
    pub haptics: Option<HapticsSection>,
    /// Independent copies of the scene's rods stepped together.
    pub batch: Option<BatchSection>,
    /// How `cosserat render` (and `cosserat run --render`) draws the run; the simulation
    /// ignores it.
    pub render: Option<RenderSection>,
}

/// `[render]`: the pictures' defaults for this scene; the command line overrides each. The
/// values are checked when the run is rendered, and errors name `render.<field>`.
#[derive(Clone, Debug, Default, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RenderSection {
    /// `"ortho"` or `"perspective"`.
    pub camera: Option<String>,
    /// `"auto"`, `"front"`, `"top"`, `"iso"`, … or `"AZIMUTH,ELEVATION"` in degrees.
    pub view: Option<String>,
    /// Vertical field of view of the perspective camera [degrees].
    pub fov: Option<f64>,
    /// Picture width [pixels].
    pub width: Option<u32>,
    /// Picture height [pixels].
    pub height: Option<u32>,
    /// Frames per second of the animation.
    pub fps: Option<u32>,
    /// Normal contact force drawn fully red [N].
    pub force_scale: Option<f64>,
}

/// `[[binding]]`: rod `inner` slides inside rod `outer`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BindingSection {
    /// Index of the inner rod (the guidewire).
    pub inner: usize,
    /// Index of the outer rod (the catheter).
    pub outer: usize,
    /// `"none"` (v0), `"one-way"` (v1) or `"two-way"` (v2, default).
    pub variant: Option<String>,
    /// Inner points farther than this from the outer centreline are free [m] (default: the
    /// outer rod's radius).
    pub capture: Option<f64>,
}

/// `[rod_contact]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RodContactSection {
    /// Whether each rod collides with itself (default true).
    pub self_collisions: Option<bool>,
    /// Coulomb friction between rods (default static 0.3, kinetic 0.2).
    pub friction: Option<FrictionSection>,
    /// Speculative contact margin [m] (default 1e-4).
    pub margin: Option<f64>,
    /// Segments per broad-phase bounding sphere (default 4).
    pub segments_per_sphere: Option<usize>,
}

/// `[batch]`: independent copies of the scene's rods (with their ends, loads, guides and
/// bindings), sharing the environment, stepped together (one GPU dispatch; in parallel on the
/// CPU with rayon). Copy `c` holds rods `c · k .. (c + 1) · k`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BatchSection {
    /// Number of copies (at least 1; default 1, e.g. a scene of several rods that only asks
    /// for several GPUs).
    pub copies: Option<usize>,
    /// GPUs to spread the copies over with the GPU backend: a number, or `"all"` (default 1).
    pub gpus: Option<GpuCount>,
}

/// `batch.gpus`: a number of GPUs, or `"all"`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub enum GpuCount {
    /// This many.
    Count(i64),
    /// Every one there is (the string `"all"`).
    Named(String),
}

/// `[haptics]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HapticsSection {
    /// Cut-off of the first-order low-pass filter on end reactions [Hz] (default 50).
    pub cutoff_hz: f64,
}

/// `[environment]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentSection {
    /// The mesh.
    pub mesh: MeshSection,
    /// Coulomb friction with the mesh.
    pub friction: Option<FrictionSection>,
    /// Speculative contact margin [m] (default 1e-4).
    pub margin: Option<f64>,
    /// Stop the run as diverged when a point of a rod is found outside the lumen (default
    /// true); false reports it and goes on.
    pub stop_outside: Option<bool>,
    /// Which side of a closed mesh the rods stay on: `"lumen"` (inside; the default for a file)
    /// or `"solid"` (outside; the default, and the only choice, for a cylinder).
    pub side: Option<String>,
}

/// `[[obstacles]]`: one obstacle besides the environment (`crate::obstacles`): a `mesh` of any
/// kind `environment.mesh` takes, or an analytic `shape`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleSection {
    /// A mesh, as `environment.mesh`.
    pub mesh: Option<MeshSection>,
    /// An analytic shape.
    pub shape: Option<ObstacleShapeSection>,
    /// Coulomb friction with it (default static 0.1, kinetic 0.08).
    pub friction: Option<FrictionSection>,
    /// Which side the rods stay on, as `environment.side`; for a cylinder shape `"solid"`
    /// (outside, the default) or `"lumen"` (inside).
    pub side: Option<String>,
    /// A keyframed rigid motion of a shape (as `rod.end.path`: displacement of the shape's
    /// point, rotation about it).
    pub path: Option<PathSection>,
}

/// `obstacles.shape`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, tag = "kind", rename_all = "kebab-case")]
pub enum ObstacleShapeSection {
    /// The half-space behind an infinite plane.
    HalfSpace {
        /// A point on the plane [m].
        point: [f64; 3],
        /// The side the rods are on.
        normal: [f64; 3],
    },
    /// An infinite cylinder.
    Cylinder {
        /// A point on the axis [m].
        point: [f64; 3],
        /// Direction of the axis.
        axis: [f64; 3],
        /// Radius [m].
        radius: f64,
    },
}

/// `environment.mesh`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, tag = "kind", rename_all = "kebab-case")]
pub enum MeshSection {
    /// The procedural vessel tree (an aorta-like trunk with branches).
    Vessel {
        /// Approximate number of triangles (default 26 000, like the paper's phantom).
        triangles: Option<usize>,
        /// A random anatomy of the same kind (trunk, bow, two to four branches) drawn from this
        /// seed; none gives the default tree.
        seed: Option<u64>,
    },
    /// An OBJ or STL file, relative to the scene file.
    File {
        /// Path of the mesh.
        path: PathBuf,
        /// Factor from file units to metres (0.001 for millimetres).
        scale: f64,
        /// Where a wire enters the lumen, in file units: `{ point = [..], direction = [..] }`.
        entry: Option<EntrySection>,
    },
    /// A closed cylinder the rods stay outside of (a post, a capstan drum); `length` along the
    /// axis, 256 faces around by default.
    Cylinder(RoundSection),
    /// A capsule (a cylinder with hemispherical ends) the rods stay outside of; `length`
    /// between the centres of its ends, 128 faces around by default.
    Capsule(RoundSection),
    /// A sphere the rods stay outside of.
    Sphere {
        /// Centre [m].
        center: [f64; 3],
        /// Radius [m].
        radius: f64,
        /// Flat faces around (default 128).
        segments: Option<usize>,
    },
    /// A box the rods stay outside of.
    Box {
        /// Centre [m].
        center: [f64; 3],
        /// Edge lengths along its own axes [m].
        size: [f64; 3],
        /// Rotation vector (axis times angle) [rad] from the world axes (default none).
        rotation: Option<[f64; 3]>,
    },
    /// A square floor.
    Plane {
        /// A point on the plane [m].
        point: [f64; 3],
        /// The side the rods are on.
        normal: [f64; 3],
        /// Side length [m].
        size: f64,
    },
}

/// `environment.mesh` of kind `cylinder` or `capsule`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoundSection {
    /// Centre of the axis [m].
    pub center: [f64; 3],
    /// Direction of the axis.
    pub axis: [f64; 3],
    /// Radius [m].
    pub radius: f64,
    /// Length [m] (see the kind).
    pub length: f64,
    /// Flat faces around.
    pub segments: Option<usize>,
}

/// A [`RoundSection`], checked, with its default number of faces filled in.
struct Round {
    center: [f64; 3],
    axis: [f64; 3],
    radius: f64,
    length: f64,
    segments: usize,
}

/// `environment.mesh.entry`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EntrySection {
    /// The entry point (file units).
    pub point: [f64; 3],
    /// The direction into the lumen.
    pub direction: [f64; 3],
    /// The entry port's radius (file units): the channel in which a wire on its way in is not
    /// outside the lumen, and the hole opened in a closed wall. Default: the opening's radius
    /// where the axis enters through an open end, half the lumen's where it passes a wall.
    pub radius: Option<f64>,
}

/// `environment.friction`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrictionSection {
    /// Static coefficient `μ_s`.
    #[serde(rename = "static")]
    pub static_coefficient: f64,
    /// Kinetic coefficient `μ_k ≤ μ_s`.
    pub kinetic: f64,
}

/// `[solver]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolverSection {
    /// Time step [s].
    pub dt: f64,
    /// Default run length in steps (the command line can override it).
    pub steps: Option<u64>,
    /// Default run length in seconds of simulated time (alternative to `steps`).
    pub duration: Option<f64>,
    /// Distance-constraint iterations per step.
    pub iterations: usize,
    /// `"inextensible"` (distance constraints) or `"extensible"` (stretch energy).
    pub mode: String,
    /// `"gauss-seidel"` or `"red-black"`.
    pub ordering: String,
    /// `"f32"` or `"f64"`.
    pub precision: String,
    /// Gravity [m/s²].
    pub gravity: [f64; 3],
    /// Strain beyond which the run is declared diverged.
    pub divergence_strain: f64,
    /// Speed [m/s] beyond which the run is declared diverged.
    pub divergence_speed: f64,
    /// `"iterative"` (the paper's impulses, default) or `"direct"` (exact: Newton iterations
    /// on the tridiagonal constraint system).
    pub constraint_solver: String,
    /// Refuse a time step beyond the estimated stable step of the explicit scheme (default
    /// true).
    pub check_stability: bool,
    /// The fraction of the estimated critical step of the explicit scheme below which a step is
    /// accepted without a warning (default 0.9, `SimulationBuilder::stability_safety`).
    pub stability_safety: f64,
    /// Stop a run whose total energy grows beyond the work its loads and driven ends could
    /// have done (default true; `cosserat::energy_watch`).
    pub energy_check: bool,
    /// `"explicit"` (the paper's scheme, default) or `"stiff"` (implicit bending and twisting:
    /// stable at haptic time steps for real instruments; `docs/stiff-solver.md`).
    pub scheme: String,
    /// Settings of the stiff scheme.
    pub stiff: Option<StiffSection>,
}

/// `[solver.stiff]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StiffSection {
    /// Largest number of Newton iterations per step (default 8).
    pub iterations: Option<usize>,
    /// Residual (a strain) at which iterations stop (default 1e-5; 0: always run
    /// `iterations`).
    pub tolerance: Option<f64>,
    /// Floor on frame inertia as a multiple of `m l² / 12` (default 0: the model's inertia).
    pub inertia_floor: Option<f64>,
    /// Retake a step of an inextensible rod that does not converge with the material's axial
    /// compliance (default true; `cosserat_backend_cpu::StiffSettings::axial_fallback`).
    pub axial_fallback: Option<bool>,
    /// Answer the mesh query of a touching point that has barely moved between two iterations
    /// of a step from its last query (default true; `false` queries every point every time;
    /// `cosserat_backend_cpu::StiffSettings::reuse_contact_queries`).
    pub reuse_contact_queries: Option<bool>,
    /// Contacts with meshes and rod contacts' planes as unilateral rows of the Newton system
    /// (default true); `false` holds them as pins whose walls may pull within a round, as before
    /// 2026-11-27 (`cosserat_backend_cpu::StiffSettings::contact_rows`).
    pub contact_rows: Option<bool>,
    /// Residual above which a step still unconverged after `iterations` is retaken in halves
    /// (default: never; `cosserat_backend_cpu::StiffSettings::halve_above`).
    pub halve_above: Option<f64>,
    /// When the banded matrix is refactorised: `"every-step"` (default: once per step, reused
    /// by the step's later iterations), `"every-iteration"` (Newton) or `"lagged"` (kept
    /// across steps); `cosserat_backend_cpu::Refactor`.
    pub refactor: Option<String>,
    /// Time integration: `"implicit-euler"` (default, first order) or `"bdf2"` (second
    /// order); `cosserat_backend_cpu::Integrator`.
    pub integrator: Option<String>,
}

impl Default for SolverSection {
    fn default() -> Self {
        Self {
            dt: 1e-4,
            steps: None,
            duration: None,
            iterations: 10,
            mode: "inextensible".into(),
            ordering: "red-black".into(),
            precision: "f32".into(),
            gravity: [0.0, 0.0, -9.81],
            divergence_strain: 0.5,
            divergence_speed: 1e3,
            constraint_solver: "iterative".into(),
            check_stability: true,
            stability_safety: cosserat_model::stability::SAFETY,
            energy_check: true,
            scheme: "explicit".into(),
            stiff: None,
        }
    }
}

/// `[[rod]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RodSection {
    /// Name for reports and output.
    pub name: Option<String>,
    /// Number of elements; a polyline is resampled to this many equal elements.
    pub elements: Option<usize>,
    /// Initial centreline.
    pub shape: ShapeSection,
    /// Material.
    pub material: MaterialSection,
    /// Rest shape: `"initial"` (default), `"straight"`, or `{ curvature = [κ1, κ2, τ] }`.
    #[serde(default)]
    pub rest_shape: Option<toml::Value>,
    /// Override of the parallel-constraint penalty `K_p` [N] (default `G A`).
    pub parallel_stiffness: Option<f64>,
    /// The rod's strain as built (`0.01`: stretched by 1 % over its rest length); or give
    /// `rest_length`.
    pub pre_strain: Option<f64>,
    /// The rod's total rest length [m] (the built length over `1 + pre_strain`).
    pub rest_length: Option<f64>,
    /// The rest length of every element [m], one per element (a rod strained unevenly, as a rope
    /// hung under its own weight); `pre_strain` or `rest_length` then cannot be given.
    pub rest_lengths: Option<Vec<f64>>,
    /// Damping coefficients.
    #[serde(default)]
    pub damping: DampingSection,
    /// Condition at the first point.
    #[serde(default)]
    pub start: EndSection,
    /// Condition at the last point.
    #[serde(default)]
    pub end: EndSection,
    /// Point loads.
    #[serde(default, rename = "load")]
    pub loads: Vec<LoadSection>,
    /// Loads spread along the whole rod, per unit length: `force` [N/m], `moment` [N m/m],
    /// `profile` as a point load's (`point` and `at` are not taken).
    #[serde(default, rename = "distributed_load")]
    pub distributed_loads: Vec<LoadSection>,
    /// Direction the first frame's `d1` should point to.
    pub first_director: Option<[f64; 3]>,
    /// Whether the rod collides with the environment (default true).
    pub collides: Option<bool>,
}

/// `rod.shape`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, tag = "kind", rename_all = "kebab-case")]
pub enum ShapeSection {
    /// A straight rod.
    Straight {
        /// First point [m].
        start: [f64; 3],
        /// Direction (normalised on load).
        direction: [f64; 3],
        /// Length [m].
        length: f64,
    },
    /// A polyline through the given points [m].
    Polyline {
        /// The points.
        points: Vec<[f64; 3]>,
    },
    /// Along the centreline of the environment's vessel trunk, between two fractions of it.
    VesselTrunk {
        /// Start, as a fraction of the trunk (0 = entry).
        from: f64,
        /// End, as a fraction of the trunk.
        to: f64,
    },
    /// A straight wire ready to be pushed into the environment's vessel: it ends `inserted`
    /// metres inside the entry point, along the entry direction, and is `length` long.
    Insertion {
        /// Total length [m].
        length: f64,
        /// Length already inside the vessel [m].
        inserted: f64,
    },
    /// One strand (0 or 1) of a loosely formed double fisherman's knot (paper section 3.5),
    /// sized by the rod's radius: each strand's standing part is fixed at its first point,
    /// `standing` metres from the knot's centre, and its tail is its last point.
    FishermansKnot {
        /// Which strand: 0 (fixed on the −x side) or 1 (the same turned half a turn about z).
        strand: u8,
        /// Distance of the first point from the knot's centre [m] (default 80 radii).
        standing: Option<f64>,
    },
}

/// `rod.material`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSection {
    /// A named material (`nitinol`, `steel`, `catheter-polymer`, `suture`;
    /// `cosserat_model::presets`); the fields below override it.
    pub preset: Option<String>,
    /// Young's modulus [Pa].
    pub young_modulus: Option<f64>,
    /// Shear modulus [Pa]; default `E / (2 (1 + ν))` with `poisson_ratio`.
    pub shear_modulus: Option<f64>,
    /// Poisson's ratio, used only when `shear_modulus` is absent (default 0.5: incompressible).
    pub poisson_ratio: Option<f64>,
    /// Density [kg/m³].
    pub density: Option<f64>,
    /// Radius [m].
    pub radius: Option<f64>,
}

/// `rod.damping`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DampingSection {
    /// Rotational internal damping [N m² s].
    pub bend: f64,
    /// Translational internal damping along the rod [N s].
    pub stretch: f64,
    /// Drag rate of the surrounding medium [1/s].
    pub drag: f64,
}

/// `rod.start` / `rod.end`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EndSection {
    /// `"free"`, `"pinned"` or `"clamped"`.
    pub kind: Option<String>,
    /// Prescribed velocity of the end [m/s].
    pub velocity: Option<[f64; 3]>,
    /// Prescribed angular velocity of the end frame [rad/s] (clamped ends).
    pub angular_velocity: Option<[f64; 3]>,
    /// Prescribed speed along the rod's own tangent at this end [m/s], positive in the
    /// direction from the first point to the last (a push, for the first end).
    pub axial_speed: Option<f64>,
    /// Prescribed spin about the rod's own tangent at this end [rad/s] (clamped ends).
    pub axial_angular_velocity: Option<f64>,
    /// When the prescribed motion starts [s].
    pub start_time: Option<f64>,
    /// When it stops [s].
    pub end_time: Option<f64>,
    /// Length [m] of a straight introducer from the start point along the first element, in
    /// which points move only along its axis (`rod.start` only).
    pub guide: Option<f64>,
    /// A keyframed path instead of a constant velocity (`cosserat_problem::EndPath`).
    pub path: Option<PathSection>,
    /// An axis (world frame) along which the held end point is free: the rod and loads on the
    /// end point move it along the axis, the motion or path only across it.
    pub slide: Option<[f64; 3]>,
    /// An axis (world frame) about which a clamped end's clamp turns freely (a hinge); it
    /// holds the end frame in every other direction.
    pub hinge: Option<[f64; 3]>,
}

/// `rod.start.path` / `rod.end.path`: keyframes of a held end's displacement and rotation
/// from where it is when the path starts, interpolated linearly, held after the last.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PathSection {
    /// When the path starts [s] (default 0).
    pub start_time: f64,
    /// Keyframe times [s after the start], from 0, increasing.
    pub times: Vec<f64>,
    /// Displacement at each keyframe [m], world frame (default: none).
    pub displacement: Option<Vec<[f64; 3]>>,
    /// Rotation at each keyframe, as a rotation vector (axis times angle) [rad], world frame
    /// (default: none; needs a clamped end).
    pub rotation: Option<Vec<[f64; 3]>>,
}

/// `[[rod.load]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSection {
    /// Point index; negative counts from the end (`-1` is the last point).
    pub point: Option<i64>,
    /// Or where along the rod, as a fraction `0..=1` of its elements (of its length when the
    /// elements are equal): the nearest point, so the load stays in place when `--elements`
    /// changes.
    pub at: Option<f64>,
    /// Force [N], world frame (default none).
    #[serde(default)]
    pub force: [f64; 3],
    /// Moment [N m], world frame (default none): half on each frame beside an interior point,
    /// all on an end point's frame.
    #[serde(default)]
    pub moment: [f64; 3],
    /// How force and moment vary in time (default: constant).
    pub profile: Option<ProfileSection>,
}

/// `[[rod.load]] profile`: the factor force and moment are multiplied by over time.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, tag = "kind", rename_all = "kebab-case")]
pub enum ProfileSection {
    /// 0 before `start`, rising linearly to 1 over `duration` [s].
    Ramp {
        /// When it starts [s] (default 0).
        #[serde(default)]
        start: f64,
        /// How long it takes [s].
        duration: f64,
    },
    /// `offset + amplitude sin(2π frequency t + phase)`.
    Sine {
        /// Mean factor (default 0).
        #[serde(default)]
        offset: f64,
        /// Amplitude (default 1).
        amplitude: Option<f64>,
        /// Frequency [Hz].
        frequency: f64,
        /// Phase [rad] (default 0).
        #[serde(default)]
        phase: f64,
    },
    /// Linear between `(time [s], factor)` points, held outside them.
    Table {
        /// The points.
        points: Vec<[f64; 2]>,
    },
}

/// Run-time settings a scene asks for besides the physics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunLength {
    /// Steps to run when the command line does not say.
    pub steps: u64,
}

/// Applies `key=value` overrides (dotted keys, `rod.0.elements`) to a parsed TOML document.
fn apply_overrides(
    path: &Path,
    doc: &mut toml::Value,
    overrides: &[(String, String)],
) -> Result<(), SceneError> {
    for (key, raw) in overrides {
        let err = |reason: String| SceneError::Override {
            path: path.into(),
            key: key.clone(),
            reason,
        };
        let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(raw.clone()));
        let parts: Vec<&str> = key.split('.').collect();
        let mut cur = &mut *doc;
        for (i, part) in parts.iter().enumerate() {
            let last = i + 1 == parts.len();
            cur = match cur {
                toml::Value::Table(t) => {
                    if last {
                        t.insert(part.to_string(), value.clone());
                        break;
                    }
                    t.entry(part.to_string())
                        .or_insert_with(|| toml::Value::Table(Default::default()))
                }
                toml::Value::Array(a) => {
                    let idx: usize = part
                        .parse()
                        .map_err(|_| err(format!("`{part}` is not an index into an array")))?;
                    let len = a.len();
                    let slot = a.get_mut(idx).ok_or_else(|| {
                        err(format!("index {idx} is out of range (length {len})"))
                    })?;
                    if last {
                        *slot = value.clone();
                        break;
                    }
                    slot
                }
                _ => {
                    return Err(err(format!(
                        "`{part}` is inside a value that is not a table or array"
                    )));
                }
            };
        }
    }
    Ok(())
}

/// Reads, overrides, checks and builds a scene.
pub fn load_scene(
    path: &Path,
    overrides: &[(String, String)],
) -> Result<(SimulationBuilder, RunLength, String), SceneError> {
    let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
        path: path.into(),
        source,
    })?;
    parse_scene(path, &text, overrides)
}

/// Parses a scene from text; `path` is used in messages and for the default name.
pub fn parse_scene(
    path: &Path,
    text: &str,
    overrides: &[(String, String)],
) -> Result<(SimulationBuilder, RunLength, String), SceneError> {
    let parse_err = |e: toml::de::Error| SceneError::Parse {
        path: path.into(),
        message: e.to_string().trim_end().to_string(),
    };
    let mut doc: toml::Value = toml::from_str(text).map_err(parse_err)?;
    apply_overrides(path, &mut doc, overrides)?;
    let scene: SceneFile = doc.try_into().map_err(parse_err)?;
    let name = scene.name.clone().unwrap_or_else(|| {
        path.file_stem()
            .map_or("scene".into(), |s| s.to_string_lossy().into_owned())
    });
    let checker = Checker { path };
    let (builder, run) = checker.build(&scene)?;
    Ok((builder, run, name))
}

/// The `[render]` table of the scene at `path` (after `overrides`), if it has one.
///
/// # Errors
/// [`SceneError`] naming the file when it cannot be read or its `[render]` table holds an
/// unknown field or a value of the wrong type.
pub fn load_render_section(
    path: &Path,
    overrides: &[(String, String)],
) -> Result<Option<RenderSection>, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
        path: path.into(),
        source,
    })?;
    let parse_err = |e: toml::de::Error| SceneError::Parse {
        path: path.into(),
        message: e.to_string().trim_end().to_string(),
    };
    let mut doc: toml::Value = toml::from_str(&text).map_err(parse_err)?;
    apply_overrides(path, &mut doc, overrides)?;
    let scene: SceneFile = doc.try_into().map_err(parse_err)?;
    Ok(scene.render)
}

struct Checker<'a> {
    path: &'a Path,
}

impl Checker<'_> {
    fn invalid(
        &self,
        field: impl Into<String>,
        value: impl std::fmt::Debug,
        expected: &str,
    ) -> SceneError {
        SceneError::Invalid {
            path: self.path.into(),
            field: field.into(),
            value: format!("{value:?}"),
            expected: expected.into(),
        }
    }

    fn positive(&self, field: &str, v: f64) -> Result<f64, SceneError> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.invalid(field, v, "expected a finite number > 0"))
        }
    }

    fn fraction(&self, field: &str, v: f64) -> Result<f64, SceneError> {
        if v > 0.0 && v <= 1.0 {
            Ok(v)
        } else {
            Err(self.invalid(field, v, "expected a number in (0, 1]"))
        }
    }

    fn non_negative(&self, field: &str, v: f64) -> Result<f64, SceneError> {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(self.invalid(field, v, "expected a finite number >= 0"))
        }
    }

    /// A load's force, moment and profile, checked; `field` names it (`rod[0].load[1]`).
    fn load_values(
        &self,
        field: &str,
        load: &LoadSection,
    ) -> Result<([f64; 3], [f64; 3], LoadProfile), SceneError> {
        let force = self.finite3(&format!("{field}.force"), load.force)?;
        let moment = self.finite3(&format!("{field}.moment"), load.moment)?;
        let field = format!("{field}.profile");
        let profile = match &load.profile {
            None => LoadProfile::Constant,
            Some(ProfileSection::Ramp { start, duration }) => LoadProfile::Ramp {
                start: self.finite(&format!("{field}.start"), *start)?,
                duration: self.non_negative(&format!("{field}.duration"), *duration)?,
            },
            Some(ProfileSection::Sine {
                offset,
                amplitude,
                frequency,
                phase,
            }) => LoadProfile::Sine {
                offset: self.finite(&format!("{field}.offset"), *offset)?,
                amplitude: self.finite(&format!("{field}.amplitude"), amplitude.unwrap_or(1.0))?,
                frequency: self.non_negative(&format!("{field}.frequency"), *frequency)?,
                phase: self.finite(&format!("{field}.phase"), *phase)?,
            },
            Some(ProfileSection::Table { points }) => LoadProfile::table(points.clone())
                .map_err(|why| self.invalid(format!("{field}.points"), "the points", &why))?,
        };
        Ok((force, moment, profile))
    }

    /// A cylinder's or a capsule's centre, axis, radius, length and faces around (`default`
    /// when not given), checked.
    fn round_solid(
        &self,
        prefix: &str,
        r: &RoundSection,
        default: usize,
    ) -> Result<Round, SceneError> {
        let center = self.finite3(&format!("{prefix}.mesh.center"), r.center)?;
        let axis = self.finite3(&format!("{prefix}.mesh.axis"), r.axis)?;
        if !(axis.iter().map(|x| x * x).sum::<f64>() > 0.0) {
            return Err(self.invalid(
                format!("{prefix}.mesh.axis"),
                axis,
                "expected a non-zero vector",
            ));
        }
        let radius = self.positive(&format!("{prefix}.mesh.radius"), r.radius)?;
        let length = self.positive(&format!("{prefix}.mesh.length"), r.length)?;
        let segments = r.segments.unwrap_or(default);
        if !(8..=100_000).contains(&segments) {
            return Err(self.invalid(
                format!("{prefix}.mesh.segments"),
                segments,
                "expected 8 ..= 100 000",
            ));
        }
        Ok(Round {
            center,
            axis,
            radius,
            length,
            segments,
        })
    }

    fn finite(&self, field: &str, v: f64) -> Result<f64, SceneError> {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.invalid(field, v, "expected a finite number"))
        }
    }

    fn finite3(&self, field: &str, v: [f64; 3]) -> Result<[f64; 3], SceneError> {
        if v.iter().all(|x| x.is_finite()) {
            Ok(v)
        } else {
            Err(self.invalid(field, v, "expected three finite numbers"))
        }
    }

    fn build(&self, scene: &SceneFile) -> Result<(SimulationBuilder, RunLength), SceneError> {
        let s = &scene.solver;
        let dt = self.positive("solver.dt", s.dt)?;
        if s.iterations > 10_000 {
            return Err(self.invalid("solver.iterations", s.iterations, "expected at most 10000"));
        }
        let extensible = match s.mode.as_str() {
            "inextensible" => false,
            "extensible" => true,
            other => {
                return Err(self.invalid(
                    "solver.mode",
                    other,
                    "expected \"inextensible\" or \"extensible\"",
                ));
            }
        };
        let ordering = match s.ordering.as_str() {
            "gauss-seidel" => Ordering::GaussSeidel,
            "red-black" => Ordering::RedBlack,
            other => {
                return Err(self.invalid(
                    "solver.ordering",
                    other,
                    "expected \"gauss-seidel\" or \"red-black\"",
                ));
            }
        };
        let f64_precision = match s.precision.as_str() {
            "f32" => false,
            "f64" => true,
            other => {
                return Err(self.invalid("solver.precision", other, "expected \"f32\" or \"f64\""));
            }
        };
        let gravity = self.finite3("solver.gravity", s.gravity)?;
        let divergence_strain = self.positive("solver.divergence_strain", s.divergence_strain)?;
        if divergence_strain >= 1.0 {
            return Err(self.invalid(
                "solver.divergence_strain",
                divergence_strain,
                "expected a fraction below 1",
            ));
        }
        let steps = match (s.steps, s.duration) {
            (Some(_), Some(_)) => {
                return Err(self.invalid(
                    "solver.steps",
                    s.steps,
                    "give either `steps` or `duration`, not both",
                ));
            }
            (Some(n), None) => n,
            (None, Some(d)) => (self.positive("solver.duration", d)? / dt).round() as u64,
            (None, None) => 1000,
        };
        if scene.rods.is_empty() {
            return Err(self.invalid("rod", "[]", "a scene needs at least one [[rod]]"));
        }
        let environment = scene
            .environment
            .as_ref()
            .map(|e| self.environment(e))
            .transpose()?;
        let mut b = SimulationBuilder::new()
            .dt(dt)
            .iterations(s.iterations)
            .extensible(extensible)
            .ordering(ordering)
            .gravity(gravity)
            .double_precision(f64_precision)
            .divergence_strain(divergence_strain)
            .divergence_speed(self.positive("solver.divergence_speed", s.divergence_speed)?)
            .check_stability(s.check_stability)
            .stability_safety(self.fraction("solver.stability_safety", s.stability_safety)?)
            .energy_check(s.energy_check)
            .direct_constraints(match s.constraint_solver.as_str() {
                "iterative" => false,
                "direct" => true,
                other => {
                    return Err(self.invalid(
                        "solver.constraint_solver",
                        other,
                        "expected \"iterative\" or \"direct\"",
                    ));
                }
            })
            .stiff_solver(self.stiff(s)?);
        for (i, rod) in scene.rods.iter().enumerate() {
            b.add_rod(self.rod(i, rod, environment.as_ref())?);
        }
        b = self.interactions(scene, b)?;
        if let Some(env) = environment {
            b = b.environment(env);
        }
        for (i, o) in scene.obstacles.iter().enumerate() {
            b = b.obstacle(self.obstacle(i, o)?);
        }
        Ok((b, RunLength { steps }))
    }

    /// `[[binding]]`, `[rod_contact]` and `[haptics]`.
    fn interactions(
        &self,
        scene: &SceneFile,
        mut b: SimulationBuilder,
    ) -> Result<SimulationBuilder, SceneError> {
        let n = scene.rods.len();
        for (k, bs) in scene.bindings.iter().enumerate() {
            let f = |name: &str| format!("binding[{k}].{name}");
            for (name, v) in [("inner", bs.inner), ("outer", bs.outer)] {
                if v >= n {
                    return Err(self.invalid(
                        f(name),
                        v,
                        &format!("expected a rod index in 0 ..= {}", n - 1),
                    ));
                }
            }
            if bs.inner == bs.outer {
                return Err(self.invalid(f("outer"), bs.outer, "expected a rod other than inner"));
            }
            let variant = match bs.variant.as_deref() {
                Some("none" | "v0") => BindingVariant::None,
                Some("one-way" | "v1") => BindingVariant::OneWay,
                None | Some("two-way" | "v2") => BindingVariant::TwoWay,
                Some(other) => {
                    return Err(self.invalid(
                        f("variant"),
                        other,
                        "expected \"none\", \"one-way\" or \"two-way\"",
                    ));
                }
            };
            let capture = bs
                .capture
                .map(|c| self.positive(&f("capture"), c))
                .transpose()?;
            b = b.bind_with(BindingSpec {
                inner: bs.inner,
                outer: bs.outer,
                variant,
                capture,
            });
        }
        if let Some(rc) = &scene.rod_contact {
            let mut spec = RodContactSpec::default();
            if let Some(x) = rc.self_collisions {
                spec.self_collisions = x;
            }
            if let Some(fr) = &rc.friction {
                let mu_s =
                    self.non_negative("rod_contact.friction.static", fr.static_coefficient)?;
                let mu_k = self.non_negative("rod_contact.friction.kinetic", fr.kinetic)?;
                if mu_k > mu_s {
                    return Err(self.invalid(
                        "rod_contact.friction.kinetic",
                        mu_k,
                        "expected kinetic <= static",
                    ));
                }
                spec.friction = cosserat_constraints::Friction {
                    static_coefficient: mu_s,
                    kinetic_coefficient: mu_k,
                };
            }
            if let Some(m) = rc.margin {
                spec.margin = self.non_negative("rod_contact.margin", m)?;
            }
            if let Some(k) = rc.segments_per_sphere {
                if k == 0 {
                    return Err(self.invalid(
                        "rod_contact.segments_per_sphere",
                        k,
                        "expected at least 1",
                    ));
                }
                spec.segments_per_sphere = k;
            }
            b = b.rod_contacts(spec);
        }
        if let Some(h) = &scene.haptics {
            b = b.reaction_cutoff_hz(self.positive("haptics.cutoff_hz", h.cutoff_hz)?);
        }
        if let Some(batch) = &scene.batch {
            let copies = batch.copies.unwrap_or(1);
            if copies == 0 {
                return Err(self.invalid("batch.copies", 0, "expected at least 1"));
            }
            if copies > 1 && scene.rod_contact.is_some() {
                return Err(self.invalid(
                    "batch.copies",
                    copies,
                    "copies share one space, so with [rod_contact] their rods would touch each other",
                ));
            }
            b = b.copies(copies);
            match &batch.gpus {
                None => {}
                Some(GpuCount::Count(n)) if *n >= 1 => b = b.gpus(Gpus::Count(*n as usize)),
                Some(GpuCount::Count(n)) => {
                    return Err(self.invalid("batch.gpus", n, "expected at least 1, or \"all\""));
                }
                Some(GpuCount::Named(name)) if name == "all" => b = b.gpus(Gpus::All),
                Some(GpuCount::Named(name)) => {
                    return Err(self.invalid(
                        "batch.gpus",
                        name,
                        "expected a number of GPUs, or \"all\"",
                    ));
                }
            }
        }
        Ok(b)
    }

    fn stiff(
        &self,
        s: &SolverSection,
    ) -> Result<Option<cosserat_backend_cpu::StiffSettings>, SceneError> {
        match s.scheme.as_str() {
            "explicit" => {
                if s.stiff.is_some() {
                    return Err(self.invalid(
                        "solver.stiff",
                        "[solver.stiff]",
                        "only used with solver.scheme = \"stiff\"",
                    ));
                }
                Ok(None)
            }
            "stiff" => {
                let mut st = cosserat_backend_cpu::StiffSettings::default();
                if let Some(x) = &s.stiff {
                    if let Some(n) = x.iterations {
                        if !(1..=100).contains(&n) {
                            return Err(self.invalid(
                                "solver.stiff.iterations",
                                n,
                                "expected 1 ..= 100",
                            ));
                        }
                        st.iterations = n;
                    }
                    if let Some(t) = x.tolerance {
                        st.tolerance = self.non_negative("solver.stiff.tolerance", t)?;
                    }
                    if let Some(f) = x.inertia_floor {
                        st.inertia_floor = self.non_negative("solver.stiff.inertia_floor", f)?;
                    }
                    if let Some(a) = x.axial_fallback {
                        st.axial_fallback = a;
                    }
                    if let Some(r) = x.reuse_contact_queries {
                        st.reuse_contact_queries = r;
                    }
                    if let Some(r) = x.contact_rows {
                        st.contact_rows = r;
                    }
                    if let Some(h) = x.halve_above {
                        st.halve_above = self.positive("solver.stiff.halve_above", h)?;
                    }
                    if let Some(r) = &x.refactor {
                        st.refactor = match r.as_str() {
                            "every-step" => cosserat_backend_cpu::Refactor::EveryStep,
                            "every-iteration" => cosserat_backend_cpu::Refactor::EveryIteration,
                            "lagged" => cosserat_backend_cpu::Refactor::Lagged,
                            other => {
                                return Err(self.invalid(
                                    "solver.stiff.refactor",
                                    other,
                                    "expected \"every-step\", \"every-iteration\" or \"lagged\"",
                                ));
                            }
                        };
                    }
                    if let Some(i) = &x.integrator {
                        st.integrator = match i.as_str() {
                            "implicit-euler" => cosserat_backend_cpu::Integrator::ImplicitEuler,
                            "bdf2" => cosserat_backend_cpu::Integrator::Bdf2,
                            other => {
                                return Err(self.invalid(
                                    "solver.stiff.integrator",
                                    other,
                                    "expected \"implicit-euler\" or \"bdf2\"",
                                ));
                            }
                        };
                    }
                }
                Ok(Some(st))
            }
            other => {
                Err(self.invalid("solver.scheme", other, "expected \"explicit\" or \"stiff\""))
            }
        }
    }

    fn environment(&self, e: &EnvironmentSection) -> Result<Environment, SceneError> {
        let mut env = self.mesh_obstacle(
            "environment",
            &e.mesh,
            e.friction.as_ref(),
            e.side.as_deref(),
        )?;
        if let Some(m) = e.margin {
            env.margin = self.non_negative("environment.margin", m)?;
        }
        if let Some(stop) = e.stop_outside {
            env.stop_outside = stop;
        }
        Ok(env)
    }

    /// `{prefix}.friction`, checked.
    fn friction(
        &self,
        prefix: &str,
        f: &FrictionSection,
    ) -> Result<cosserat_constraints::Friction<f64>, SceneError> {
        let mu_s = self.non_negative(&format!("{prefix}.friction.static"), f.static_coefficient)?;
        let mu_k = self.non_negative(&format!("{prefix}.friction.kinetic"), f.kinetic)?;
        if mu_k > mu_s {
            return Err(self.invalid(
                format!("{prefix}.friction.kinetic"),
                mu_k,
                "expected kinetic <= static",
            ));
        }
        Ok(cosserat_constraints::Friction {
            static_coefficient: mu_s,
            kinetic_coefficient: mu_k,
        })
    }

    /// `[[obstacles]]` entry `i`: a mesh or a shape, its friction, side and path, checked.
    fn obstacle(&self, i: usize, o: &ObstacleSection) -> Result<Obstacle, SceneError> {
        let prefix = format!("obstacles[{i}]");
        let obstacle = match (&o.mesh, &o.shape) {
            (Some(mesh), None) => Obstacle::mesh(self.mesh_obstacle(
                &prefix,
                mesh,
                o.friction.as_ref(),
                o.side.as_deref(),
            )?),
            (None, Some(shape)) => {
                let mut obstacle = self.shape(&prefix, shape, o.side.as_deref())?;
                if let Some(f) = &o.friction {
                    let f = self.friction(&prefix, f)?;
                    obstacle = obstacle.friction(f.static_coefficient, f.kinetic_coefficient);
                }
                obstacle
            }
            (Some(_), Some(_)) => {
                return Err(self.invalid(
                    prefix,
                    "a mesh and a shape",
                    "give either `mesh` or `shape`, not both",
                ));
            }
            (None, None) => {
                return Err(self.invalid(
                    prefix,
                    "neither a mesh nor a shape",
                    "give `mesh = { kind = ... }` or `shape = { kind = \"half-space\" | \"cylinder\", ... }`",
                ));
            }
        };
        let Some(p) = &o.path else {
            return Ok(obstacle);
        };
        let field = format!("{prefix}.path");
        let n = p.times.len();
        let path = EndPath::new(
            p.start_time,
            p.times.clone(),
            p.displacement.clone().unwrap_or_else(|| vec![[0.0; 3]; n]),
            p.rotation.clone().unwrap_or_else(|| vec![[0.0; 3]; n]),
        )
        .map_err(|why| self.invalid(&field, "the keyframes", &why))?;
        obstacle
            .following(path)
            .map_err(|why| self.invalid(&field, "a path", &why))
    }

    /// `{prefix}.shape` on `side`, checked.
    fn shape(
        &self,
        prefix: &str,
        shape: &ObstacleShapeSection,
        side: Option<&str>,
    ) -> Result<Obstacle, SceneError> {
        let field = |name: &str| format!("{prefix}.shape.{name}");
        match shape {
            ObstacleShapeSection::HalfSpace { point, normal } => {
                if let Some(side) = side {
                    return Err(self.invalid(
                        format!("{prefix}.side"),
                        side,
                        "a half-space has one side, the one its normal points to",
                    ));
                }
                let point = self.finite3(&field("point"), *point)?;
                let normal = self.finite3(&field("normal"), *normal)?;
                Obstacle::half_space(point, normal)
                    .map_err(|why| self.invalid(field("normal"), normal, &why))
            }
            ObstacleShapeSection::Cylinder {
                point,
                axis,
                radius,
            } => {
                let side = match side {
                    None | Some("solid") => Side::Solid,
                    Some("lumen") => Side::Lumen,
                    Some(other) => {
                        return Err(self.invalid(
                            format!("{prefix}.side"),
                            other,
                            "expected \"lumen\" or \"solid\"",
                        ));
                    }
                };
                let point = self.finite3(&field("point"), *point)?;
                let axis = self.finite3(&field("axis"), *axis)?;
                let radius = self.positive(&field("radius"), *radius)?;
                Obstacle::cylinder(point, axis, radius, side)
                    .map_err(|why| self.invalid(field("axis"), axis, &why))
            }
        }
    }

    /// A mesh (`{prefix}.mesh`) with its friction and side, checked; errors name the fields
    /// under `prefix` (`environment`, `obstacles[2]`).
    fn mesh_obstacle(
        &self,
        prefix: &str,
        mesh: &MeshSection,
        friction: Option<&FrictionSection>,
        side: Option<&str>,
    ) -> Result<Environment, SceneError> {
        let mesh_err = |field: &str, err: cosserat_collide::MeshError| {
            self.invalid(field, err.to_string(), "a readable, valid triangle mesh")
        };
        let mut env = match mesh {
            MeshSection::Vessel { triangles, seed } => {
                let t = triangles.unwrap_or(26_000);
                if !(100..=5_000_000).contains(&t) {
                    return Err(self.invalid(
                        format!("{prefix}.mesh.triangles"),
                        t,
                        "expected 100 ..= 5 000 000",
                    ));
                }
                match seed {
                    None => Environment::vessel(t),
                    Some(seed) => Environment::random_vessel(*seed, t),
                }
                .map_err(|err| mesh_err(&format!("{prefix}.mesh"), err))?
            }
            MeshSection::File { path, scale, entry } => {
                let scale = self.positive(&format!("{prefix}.mesh.scale"), *scale)?;
                let entry = match entry {
                    None => None,
                    Some(e) => {
                        let p = self.finite3(&format!("{prefix}.mesh.entry.point"), e.point)?;
                        let d =
                            self.finite3(&format!("{prefix}.mesh.entry.direction"), e.direction)?;
                        if !(d.iter().map(|x| x * x).sum::<f64>() > 0.0) {
                            return Err(self.invalid(
                                format!("{prefix}.mesh.entry.direction"),
                                d,
                                "expected a non-zero vector",
                            ));
                        }
                        let radius = match e.radius {
                            None => None,
                            Some(r) => Some(
                                self.positive(&format!("{prefix}.mesh.entry.radius"), r)? * scale,
                            ),
                        };
                        Some(Entry {
                            point: [p[0] * scale, p[1] * scale, p[2] * scale],
                            direction: d,
                            radius,
                        })
                    }
                };
                let full = self
                    .path
                    .parent()
                    .map_or_else(|| path.clone(), |dir| dir.join(path));
                Environment::from_file(&full, scale, entry)
                    .map_err(|err| mesh_err(&format!("{prefix}.mesh.path"), err))?
            }
            MeshSection::Cylinder(r) => {
                let r = self.round_solid(prefix, r, 256)?;
                Environment::cylinder(r.center, r.axis, r.radius, r.length, r.segments)
                    .map_err(|err| mesh_err(&format!("{prefix}.mesh"), err))?
            }
            MeshSection::Capsule(r) => {
                let r = self.round_solid(prefix, r, 128)?;
                Environment::capsule(r.center, r.axis, r.radius, r.length, r.segments)
                    .map_err(|err| mesh_err(&format!("{prefix}.mesh"), err))?
            }
            MeshSection::Sphere {
                center,
                radius,
                segments,
            } => {
                let center = self.finite3(&format!("{prefix}.mesh.center"), *center)?;
                let radius = self.positive(&format!("{prefix}.mesh.radius"), *radius)?;
                let segments = segments.unwrap_or(128);
                if !(8..=4096).contains(&segments) {
                    return Err(self.invalid(
                        format!("{prefix}.mesh.segments"),
                        segments,
                        "expected 8 ..= 4096",
                    ));
                }
                Environment::sphere(center, radius, segments)
                    .map_err(|err| mesh_err(&format!("{prefix}.mesh"), err))?
            }
            MeshSection::Box {
                center,
                size,
                rotation,
            } => {
                let center = self.finite3(&format!("{prefix}.mesh.center"), *center)?;
                let size = self.finite3(&format!("{prefix}.mesh.size"), *size)?;
                if !size.iter().all(|x| *x > 0.0) {
                    return Err(self.invalid(
                        format!("{prefix}.mesh.size"),
                        size,
                        "expected three lengths > 0",
                    ));
                }
                let rotation = self.finite3(
                    &format!("{prefix}.mesh.rotation"),
                    rotation.unwrap_or([0.0; 3]),
                )?;
                Environment::cuboid(center, size, rotation)
                    .map_err(|err| mesh_err(&format!("{prefix}.mesh"), err))?
            }
            MeshSection::Plane {
                point,
                normal,
                size,
            } => {
                let point = self.finite3(&format!("{prefix}.mesh.point"), *point)?;
                let normal = self.finite3(&format!("{prefix}.mesh.normal"), *normal)?;
                if !(normal.iter().map(|x| x * x).sum::<f64>() > 0.0) {
                    return Err(self.invalid(
                        format!("{prefix}.mesh.normal"),
                        normal,
                        "expected a non-zero vector",
                    ));
                }
                let size = self.positive(&format!("{prefix}.mesh.size"), *size)?;
                Environment::plane(point, normal, size)
                    .map_err(|err| mesh_err(&format!("{prefix}.mesh"), err))?
            }
        };
        if let Some(f) = friction {
            env.friction = self.friction(prefix, f)?;
        }
        match (side, mesh) {
            (None, _)
            | (
                Some("solid"),
                MeshSection::Cylinder(_)
                | MeshSection::Capsule(_)
                | MeshSection::Sphere { .. }
                | MeshSection::Box { .. },
            ) => {}
            (Some("lumen"), MeshSection::Vessel { .. } | MeshSection::File { .. }) => {}
            (Some("solid"), MeshSection::File { entry: None, .. }) => {
                env = env
                    .into_solid()
                    .map_err(|why| self.invalid(format!("{prefix}.side"), "solid", &why))?;
            }
            (Some(side @ ("lumen" | "solid")), mesh) => {
                let kind = match mesh {
                    MeshSection::Vessel { .. } => "a generated vessel is a lumen",
                    MeshSection::File { .. } => "a mesh with an entry is a lumen",
                    MeshSection::Cylinder(_) => "a cylinder is a solid",
                    MeshSection::Capsule(_) => "a capsule is a solid",
                    MeshSection::Sphere { .. } => "a sphere is a solid",
                    MeshSection::Box { .. } => "a box is a solid",
                    MeshSection::Plane { .. } => {
                        "a floor has one side, the one its normal points to"
                    }
                };
                return Err(self.invalid(format!("{prefix}.side"), side, kind));
            }
            (Some(other), _) => {
                return Err(self.invalid(
                    format!("{prefix}.side"),
                    other,
                    "expected \"lumen\" or \"solid\"",
                ));
            }
        }
        Ok(env)
    }

    fn rod(
        &self,
        i: usize,
        r: &RodSection,
        env: Option<&Environment>,
    ) -> Result<RodBuilder, SceneError> {
        let f = |name: &str| format!("rod[{i}].{name}");
        let elements = match r.elements {
            Some(0) => return Err(self.invalid(f("elements"), 0, "expected at least 1 element")),
            Some(n) if n > 10_000_000 => {
                return Err(self.invalid(f("elements"), n, "expected at most 10 000 000 elements"));
            }
            other => other,
        };
        let m = &r.material;
        let preset = match &m.preset {
            None => None,
            Some(name) => Some(cosserat_model::presets::preset(name).ok_or_else(|| {
                let names: Vec<_> = cosserat_model::presets::PRESETS
                    .iter()
                    .map(|p| p.name)
                    .collect();
                self.invalid(
                    f("material.preset"),
                    name,
                    &format!("expected one of {}", names.join(", ")),
                )
            })?),
        };
        let required = |field: &str, value: Option<f64>, from_preset: Option<f64>| {
            value.or(from_preset).ok_or_else(|| {
                self.invalid(f(field), "missing", "required unless a preset gives it")
            })
        };
        let young = self.positive(
            &f("material.young_modulus"),
            required(
                "material.young_modulus",
                m.young_modulus,
                preset.map(|p| p.young_modulus),
            )?,
        )?;
        let density = required("material.density", m.density, preset.map(|p| p.density))?;
        let radius = required("material.radius", m.radius, preset.map(|p| p.radius))?;
        let poisson = m.poisson_ratio.or(if m.shear_modulus.is_none() {
            preset.map(|p| p.poisson_ratio)
        } else {
            None
        });
        let shear = match (m.shear_modulus, poisson) {
            (Some(g), None) => self.positive(&f("material.shear_modulus"), g)?,
            (Some(_), Some(_)) => {
                return Err(self.invalid(
                    f("material.poisson_ratio"),
                    m.poisson_ratio,
                    "give either shear_modulus or poisson_ratio, not both",
                ));
            }
            (None, nu) => {
                let nu = nu.unwrap_or(0.5);
                if !(nu.is_finite() && nu > -1.0 && nu <= 0.5) {
                    return Err(self.invalid(
                        f("material.poisson_ratio"),
                        nu,
                        "expected -1 < ν <= 0.5",
                    ));
                }
                young / (2.0 * (1.0 + nu))
            }
        };
        let material = Material::new(
            young,
            shear,
            self.positive(&f("material.density"), density)?,
            self.positive(&f("material.radius"), radius)?,
        );
        let mut rb = match &r.shape {
            ShapeSection::Straight {
                start,
                direction,
                length,
            } => {
                let start = self.finite3(&f("shape.start"), *start)?;
                let direction = self.finite3(&f("shape.direction"), *direction)?;
                if !(direction.iter().map(|x| x * x).sum::<f64>() > 0.0) {
                    return Err(self.invalid(
                        f("shape.direction"),
                        direction,
                        "expected a non-zero vector",
                    ));
                }
                let length = self.positive(&f("shape.length"), *length)?;
                RodBuilder::straight(start, direction, length, elements.unwrap_or(100), material)
            }
            ShapeSection::Polyline { points } => {
                if points.len() < 2 {
                    return Err(self.invalid(
                        f("shape.points"),
                        points.len(),
                        "expected at least 2 points",
                    ));
                }
                for (k, p) in points.iter().enumerate() {
                    self.finite3(&f(&format!("shape.points[{k}]")), *p)?;
                }
                let rb = RodBuilder::polyline(points.clone(), material);
                match elements {
                    Some(n) => rb.resampled(n).map_err(|k| {
                        self.invalid(
                            f(&format!("shape.points[{k}]")),
                            points[k],
                            "expected distinct consecutive points",
                        )
                    })?,
                    None => rb,
                }
            }
            ShapeSection::VesselTrunk { from, to } => {
                let vessel = env.and_then(|e| e.vessel.as_ref()).ok_or_else(|| {
                    self.invalid(
                        f("shape.kind"),
                        "vessel-trunk",
                        "needs [environment] mesh = { kind = \"vessel\" }",
                    )
                })?;
                for (name, v) in [("shape.from", *from), ("shape.to", *to)] {
                    if !(0.0..=1.0).contains(&v) {
                        return Err(self.invalid(f(name), v, "expected a fraction in 0 ..= 1"));
                    }
                }
                if !(to > from) {
                    return Err(self.invalid(f("shape.to"), *to, "expected to > from"));
                }
                let trunk = vessel.trunk.as_ref().ok_or_else(|| {
                    self.invalid(
                        f("shape.kind"),
                        "vessel-trunk",
                        "needs a generated vessel (mesh files have no known centreline)",
                    )
                })?;
                let samples = 400;
                let pts = (0..=samples)
                    .map(|k| {
                        trunk
                            .sample(from + (to - from) * k as f64 / samples as f64)
                            .0
                    })
                    .collect();
                RodBuilder::polyline(pts, material)
                    .resampled(elements.unwrap_or(100))
                    .map_err(|k| {
                        self.invalid(f("shape"), k, "the trunk centreline has coincident points")
                    })?
            }
            ShapeSection::Insertion { length, inserted } => {
                let vessel = env.and_then(|e| e.vessel.as_ref()).ok_or_else(|| {
                    self.invalid(
                        f("shape.kind"),
                        "insertion",
                        "needs [environment] mesh = { kind = \"vessel\" }",
                    )
                })?;
                let length = self.positive(&f("shape.length"), *length)?;
                let inserted = self.non_negative(&f("shape.inserted"), *inserted)?;
                if inserted > length {
                    return Err(self.invalid(
                        f("shape.inserted"),
                        inserted,
                        "expected at most the rod's length",
                    ));
                }
                let (p, d) = (vessel.entry_point, vessel.entry_direction);
                let back = length - inserted;
                let start = [p[0] - d[0] * back, p[1] - d[1] * back, p[2] - d[2] * back];
                RodBuilder::straight(start, d, length, elements.unwrap_or(100), material)
            }
            ShapeSection::FishermansKnot { strand, standing } => {
                if *strand > 1 {
                    return Err(self.invalid(f("shape.strand"), strand, "expected 0 or 1"));
                }
                let r = material.radius;
                let standing = match standing {
                    Some(l) => self.positive(&f("shape.standing"), *l)?,
                    None => 80.0 * r,
                };
                if standing < 20.0 * r {
                    return Err(self.invalid(
                        f("shape.standing"),
                        standing,
                        "expected at least 20 rod radii (the knot's own extent)",
                    ));
                }
                let pts = fishermans_knot_strand(*strand, r, standing);
                RodBuilder::polyline(pts, material)
                    .resampled(elements.unwrap_or(256))
                    .map_err(|k| self.invalid(f("shape"), k, "a degenerate knot polyline"))?
            }
        };
        rb = match &r.rest_shape {
            None => rb,
            Some(toml::Value::String(s)) if s == "initial" => rb.rest_shape(RestShape::Initial),
            Some(toml::Value::String(s)) if s == "straight" => {
                rb.rest_shape(RestShape::Uniform([0.0; 3]))
            }
            Some(toml::Value::Table(t)) if t.len() == 1 && t.contains_key("curvature") => {
                let c: [f64; 3] = t["curvature"].clone().try_into().map_err(|_| {
                    self.invalid(
                        f("rest_shape.curvature"),
                        &t["curvature"],
                        "expected [κ1, κ2, τ] in 1/m",
                    )
                })?;
                rb.rest_shape(RestShape::Uniform(
                    self.finite3(&f("rest_shape.curvature"), c)?,
                ))
            }
            Some(v) => {
                return Err(self.invalid(
                    f("rest_shape"),
                    v,
                    "expected \"initial\", \"straight\" or { curvature = [κ1, κ2, τ] }",
                ));
            }
        };
        if let Some(kp) = r.parallel_stiffness {
            rb = rb.parallel_stiffness(self.positive(&f("parallel_stiffness"), kp)?);
        }
        if let Some(rest) = &r.rest_lengths {
            if r.pre_strain.is_some() || r.rest_length.is_some() {
                return Err(self.invalid(
                    f("rest_lengths"),
                    "rest_lengths with pre_strain or rest_length",
                    "one way of giving the rest state",
                ));
            }
            let n = rb.element_count();
            if rest.len() != n {
                return Err(self.invalid(
                    f("rest_lengths"),
                    format!("{} entries", rest.len()),
                    &format!("one per element: {n} (the rod's elements)"),
                ));
            }
            if let Some(j) = rest.iter().position(|l| !(l.is_finite() && *l > 0.0)) {
                return Err(self.invalid(
                    f(&format!("rest_lengths[{j}]")),
                    rest[j],
                    "a finite length above 0",
                ));
            }
            rb = rb.rest_lengths(rest.clone());
        }
        match (r.pre_strain, r.rest_length) {
            (None, None) => {}
            (Some(e), None) => {
                if !(e.is_finite() && e > -1.0) {
                    return Err(self.invalid(f("pre_strain"), e, "a finite number above -1"));
                }
                rb = rb.pre_strain(e);
            }
            (None, Some(l)) => {
                let l = self.positive(&f("rest_length"), l)?;
                let strain = rb.built_length() / l - 1.0;
                rb = rb.pre_strain(strain);
            }
            (Some(_), Some(_)) => {
                return Err(self.invalid(
                    f("pre_strain"),
                    "both pre_strain and rest_length",
                    "one of them",
                ));
            }
        }
        rb = rb.damping(
            self.non_negative(&f("damping.bend"), r.damping.bend)?,
            self.non_negative(&f("damping.stretch"), r.damping.stretch)?,
            self.non_negative(&f("damping.drag"), r.damping.drag)?,
        );
        if let Some(d) = r.first_director {
            rb = rb.first_director(self.finite3(&f("first_director"), d)?);
        }
        let (t_start, t_end) = rb.end_tangents();
        rb = rb
            .collides(r.collides.unwrap_or(true))
            .start(self.end(&f("start"), &r.start, t_start)?)
            .end(self.end(&f("end"), &r.end, t_end)?);
        if let Some(g) = r.end.guide {
            return Err(self.invalid(
                f("end.guide"),
                g,
                "a guide (introducer) is fed from the start end only: set rod.start.guide",
            ));
        }
        if let Some(g) = r.start.guide {
            rb = rb.guide(self.positive(&f("start.guide"), g)?);
        }
        let n = rb.element_count() as i64;
        for (k, load) in r.loads.iter().enumerate() {
            let idx = match (load.point, load.at) {
                (Some(point), None) => {
                    let idx = if point < 0 { n + 1 + point } else { point };
                    if !(0..=n).contains(&idx) {
                        return Err(self.invalid(
                            f(&format!("load[{k}].point")),
                            point,
                            &format!("expected a point index in -{} ..= {n}", n + 1),
                        ));
                    }
                    idx
                }
                (None, Some(at)) => {
                    if !(0.0..=1.0).contains(&at) {
                        return Err(self.invalid(
                            f(&format!("load[{k}].at")),
                            at,
                            "expected a fraction of the rod in 0 ..= 1",
                        ));
                    }
                    (at * n as f64).round() as i64
                }
                (p, a) => {
                    return Err(self.invalid(
                        f(&format!("load[{k}]")),
                        format!("point = {p:?}, at = {a:?}"),
                        "expected exactly one of `point` (an index) and `at` (a fraction)",
                    ));
                }
            };
            let (force, moment, profile) = self.load_values(&f(&format!("load[{k}]")), load)?;
            rb = rb.load_with(
                PointLoad::new(idx as usize, force.into())
                    .with_moment(moment.into())
                    .with_profile(profile),
            );
        }
        for (k, load) in r.distributed_loads.iter().enumerate() {
            let field = f(&format!("distributed_load[{k}]"));
            if load.point.is_some() || load.at.is_some() {
                return Err(self.invalid(
                    field,
                    format!("point = {:?}, at = {:?}", load.point, load.at),
                    "a distributed load acts along the whole rod: no `point` or `at`",
                ));
            }
            let (force, moment, profile) = self.load_values(&field, load)?;
            rb = rb.distributed_load(
                PointLoad::new(0, force.into())
                    .with_moment(moment.into())
                    .with_profile(profile),
            );
        }
        if let Some(name) = &r.name {
            rb = rb.name(name.clone());
        }
        Ok(rb)
    }

    fn end(
        &self,
        field: &str,
        e: &EndSection,
        tangent: [f64; 3],
    ) -> Result<EndCondition<f64>, SceneError> {
        let axial = |name: &str,
                     value: Option<f64>,
                     vector: Option<[f64; 3]>|
         -> Result<Option<[f64; 3]>, SceneError> {
            match (value, vector) {
                (Some(_), Some(_)) => Err(self.invalid(
                    format!("{field}.{name}"),
                    value,
                    "give either the vector or the axial value, not both",
                )),
                (Some(a), None) if a.is_finite() => {
                    Ok(Some([tangent[0] * a, tangent[1] * a, tangent[2] * a]))
                }
                (Some(a), None) => {
                    Err(self.invalid(format!("{field}.{name}"), a, "expected a finite number"))
                }
                (None, v) => Ok(v),
            }
        };
        let velocity = axial("axial_speed", e.axial_speed, e.velocity)?;
        let angular_velocity = axial(
            "axial_angular_velocity",
            e.axial_angular_velocity,
            e.angular_velocity,
        )?;
        let e = &EndSection {
            velocity,
            angular_velocity,
            axial_speed: None,
            axial_angular_velocity: None,
            kind: e.kind.clone(),
            start_time: e.start_time,
            end_time: e.end_time,
            guide: e.guide,
            path: e.path.clone(),
            slide: e.slide,
            hinge: e.hinge,
        };
        let kind = match e.kind.as_deref() {
            None | Some("free") => EndKind::Free,
            Some("pinned") => EndKind::Pinned,
            Some("clamped") => EndKind::Clamped,
            Some(other) => {
                return Err(self.invalid(
                    format!("{field}.kind"),
                    other,
                    "expected \"free\", \"pinned\" or \"clamped\"",
                ));
            }
        };
        let driven = e.velocity.is_some() || e.angular_velocity.is_some();
        if driven && kind == EndKind::Free {
            return Err(self.invalid(
                format!("{field}.kind"),
                "free",
                "a driven end (velocity / angular_velocity) must be \"pinned\" or \"clamped\"",
            ));
        }
        if e.angular_velocity.is_some() && kind != EndKind::Clamped {
            return Err(self.invalid(
                format!("{field}.kind"),
                e.kind.as_deref().unwrap_or("free"),
                "an angular_velocity needs a \"clamped\" end",
            ));
        }
        let mut cond = EndCondition {
            kind,
            ..EndCondition::default()
        };
        if let Some(axis) = e.slide {
            let axis = self.finite3(&format!("{field}.slide"), axis)?;
            if kind == EndKind::Free {
                return Err(self.invalid(
                    format!("{field}.kind"),
                    "free",
                    "a sliding end (slide) must be \"pinned\" or \"clamped\"",
                ));
            }
            if axis == [0.0; 3] {
                return Err(self.invalid(
                    format!("{field}.slide"),
                    axis,
                    "expected an axis of non-zero length",
                ));
            }
            cond = cond.sliding_along(axis.into());
        }
        if let Some(axis) = e.hinge {
            let axis = self.finite3(&format!("{field}.hinge"), axis)?;
            if kind != EndKind::Clamped {
                return Err(self.invalid(
                    format!("{field}.kind"),
                    e.kind.as_deref().unwrap_or("free"),
                    "a hinged end (hinge) must be \"clamped\": only a clamp has a frame to turn",
                ));
            }
            if axis == [0.0; 3] {
                return Err(self.invalid(
                    format!("{field}.hinge"),
                    axis,
                    "expected an axis of non-zero length",
                ));
            }
            cond = cond.hinged_about(axis.into());
        }
        if let Some(p) = &e.path {
            if driven {
                return Err(self.invalid(
                    format!("{field}.path"),
                    "a path",
                    "give either a path or a velocity / angular_velocity, not both",
                ));
            }
            if kind == EndKind::Free {
                return Err(self.invalid(
                    format!("{field}.kind"),
                    "free",
                    "an end with a path must be \"pinned\" or \"clamped\"",
                ));
            }
            if p.rotation.is_some() && kind != EndKind::Clamped {
                return Err(self.invalid(
                    format!("{field}.kind"),
                    e.kind.as_deref().unwrap_or("free"),
                    "a path with a rotation needs a \"clamped\" end",
                ));
            }
            let n = p.times.len();
            let displacement = p.displacement.clone().unwrap_or_else(|| vec![[0.0; 3]; n]);
            let rotation = p.rotation.clone().unwrap_or_else(|| vec![[0.0; 3]; n]);
            if let Some(a) = cond.slide {
                let along = displacement
                    .iter()
                    .map(|d| (d[0] * a.x + d[1] * a.y + d[2] * a.z).abs())
                    .fold(0.0, f64::max);
                if along > 0.0 {
                    return Err(self.invalid(
                        format!("{field}.path.displacement"),
                        along,
                        "a sliding end moves only across its slide axis: the displacement along it must be zero",
                    ));
                }
            }
            let path = EndPath::new(p.start_time, p.times.clone(), displacement, rotation)
                .map_err(|why| self.invalid(format!("{field}.path"), "the keyframes", &why))?;
            cond = cond.following(path);
        }
        if driven {
            let v = self.finite3(&format!("{field}.velocity"), e.velocity.unwrap_or([0.0; 3]))?;
            let w = self.finite3(
                &format!("{field}.angular_velocity"),
                e.angular_velocity.unwrap_or([0.0; 3]),
            )?;
            let start_time =
                self.non_negative(&format!("{field}.start_time"), e.start_time.unwrap_or(0.0))?;
            let end_time = e.end_time.unwrap_or(f64::INFINITY);
            if !(end_time > start_time) {
                return Err(self.invalid(
                    format!("{field}.end_time"),
                    end_time,
                    "expected a time after start_time",
                ));
            }
            cond.motion = Some(PrescribedMotion {
                velocity: v.into(),
                angular_velocity: w.into(),
                start_time,
                end_time,
            });
        }
        Ok(cond)
    }
}

/// One strand of a loosely formed double fisherman's knot (paper section 3.5), for a rod of
/// radius `r`, as a dense polyline.
///
/// The knot's axis is x. Strand 0 is fixed at `(−standing, δ, 0)` and runs along `y = δ` to
/// beyond its knot at `x ∈ [c, c + w]`, turns back outwards (a hairpin in the plane `z = 0`),
/// wraps twice around the axis at radius `R` towards −x (a double overhand around both
/// standing parts), and is tucked back through its own turns at `(y, z) = (0, ρ)` towards +x,
/// ending in its tail. Strand 1 is strand 0 turned half a turn about z, so its knot grips
/// strand 0's standing part and the two tucks never meet. All distances are multiples of `r`,
/// chosen so that no two parts are closer than `2r` at the start (δ = ρ = 3r, R = 7r, two
/// turns over w = 8r).
fn fishermans_knot_strand(strand: u8, r: f64, standing: f64) -> Vec<[f64; 3]> {
    use std::f64::consts::PI;
    let (delta, rho, big_r, w, g, c, tail) = (
        3.0 * r,
        3.0 * r,
        7.0 * r,
        8.0 * r,
        4.0 * r,
        10.0 * r,
        25.0 * r,
    );
    let step = 0.25 * r;
    let mut pts: Vec<[f64; 3]> = Vec::new();
    let line = |pts: &mut Vec<[f64; 3]>, a: [f64; 3], b: [f64; 3]| {
        let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt();
        let k = (len / step).ceil().max(1.0) as usize;
        for i in 1..=k {
            let t = i as f64 / k as f64;
            pts.push([
                a[0] + (b[0] - a[0]) * t,
                a[1] + (b[1] - a[1]) * t,
                a[2] + (b[2] - a[2]) * t,
            ]);
        }
    };
    pts.push([-standing, delta, 0.0]);
    // Standing part, through the other strand's knot and its own.
    line(&mut pts, [-standing, delta, 0.0], [c + w + g, delta, 0.0]);
    // Hairpin outwards to the radius of the turns.
    let (hc, hr) = ((delta + big_r) / 2.0, (big_r - delta) / 2.0);
    let k = 24;
    for i in 1..=k {
        let a = -PI / 2.0 + PI * i as f64 / k as f64;
        pts.push([c + w + g + hr * a.cos(), hc + hr * a.sin(), 0.0]);
    }
    line(&mut pts, [c + w + g, big_r, 0.0], [c + w, big_r, 0.0]);
    // Two turns towards −x.
    let k = 160;
    for i in 1..=k {
        let phi = 4.0 * PI * i as f64 / k as f64;
        pts.push([
            c + w - w * phi / (4.0 * PI),
            big_r * phi.cos(),
            big_r * phi.sin(),
        ]);
    }
    // Inwards, a quarter turn further, out of the turns and back (a smooth U in x), to the tuck.
    let k = 24;
    for i in 1..=k {
        let t = i as f64 / k as f64;
        let phi = 4.0 * PI + 0.5 * PI * t;
        let rad = big_r + (rho - big_r) * t;
        pts.push([c - g * (PI * t).sin(), rad * phi.cos(), rad * phi.sin()]);
    }
    // Back through the turns, and the tail.
    line(&mut pts, [c, 0.0, rho], [c + w + g + tail, 0.0, rho]);
    if strand == 1 {
        for p in &mut pts {
            *p = [-p[0], -p[1], p[2]];
        }
    }
    pts
}
