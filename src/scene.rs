//! Scene files: TOML descriptions of rods, materials, end conditions, loads and solver settings.
//!
//! A scene is parsed into plain serde structs (unknown fields are rejected, so a typo is an
//! error rather than a silently ignored setting), then every value is checked and the scene is
//! turned into a [`SimulationBuilder`]. Every error names the file, the field (as a dotted
//! path such as `rod[0].material.radius`) and the offending value.
//!
//! Values can be overridden from the command line before checking (`--set rod.0.elements=1000`),
//! which is how one scene file serves several resolutions.

use crate::environment::Environment;
use crate::sim::{RodBuilder, SimulationBuilder};
use backend_cpu::{EndCondition, EndKind, Ordering, PrescribedMotion};
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
}

/// `environment.mesh`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, tag = "kind", rename_all = "kebab-case")]
pub enum MeshSection {
    /// The procedural vessel tree (an aorta-like trunk with branches).
    Vessel {
        /// Approximate number of triangles (default 26 000, like the paper's phantom).
        triangles: Option<usize>,
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

/// `environment.mesh.entry`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EntrySection {
    /// The entry point (file units).
    pub point: [f64; 3],
    /// The direction into the lumen.
    pub direction: [f64; 3],
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
    /// Damping coefficients.
    #[serde(default)]
    pub damping: DampingSection,
    /// Condition at the first point.
    #[serde(default)]
    pub start: EndSection,
    /// Condition at the last point.
    #[serde(default)]
    pub end: EndSection,
    /// Constant point forces.
    #[serde(default, rename = "load")]
    pub loads: Vec<LoadSection>,
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
}

/// `rod.material`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSection {
    /// Young's modulus [Pa].
    pub young_modulus: f64,
    /// Shear modulus [Pa]; default `E / (2 (1 + ν))` with `poisson_ratio`.
    pub shear_modulus: Option<f64>,
    /// Poisson's ratio, used only when `shear_modulus` is absent (default 0.5: incompressible).
    pub poisson_ratio: Option<f64>,
    /// Density [kg/m³].
    pub density: f64,
    /// Radius [m].
    pub radius: f64,
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
}

/// `[[rod.load]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSection {
    /// Point index; negative counts from the end (`-1` is the last point).
    pub point: i64,
    /// Force [N].
    pub force: [f64; 3],
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

    fn non_negative(&self, field: &str, v: f64) -> Result<f64, SceneError> {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(self.invalid(field, v, "expected a finite number >= 0"))
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
            .divergence_strain(divergence_strain);
        for (i, rod) in scene.rods.iter().enumerate() {
            b.add_rod(self.rod(i, rod, environment.as_ref())?);
        }
        if let Some(env) = environment {
            b = b.environment(env);
        }
        Ok((b, RunLength { steps }))
    }

    fn environment(&self, e: &EnvironmentSection) -> Result<Environment, SceneError> {
        let mesh_err = |field: &str, err: collide::MeshError| {
            self.invalid(field, err.to_string(), "a readable, valid triangle mesh")
        };
        let mut env = match &e.mesh {
            MeshSection::Vessel { triangles } => {
                let t = triangles.unwrap_or(26_000);
                if !(100..=5_000_000).contains(&t) {
                    return Err(self.invalid(
                        "environment.mesh.triangles",
                        t,
                        "expected 100 ..= 5 000 000",
                    ));
                }
                Environment::vessel(t).map_err(|err| mesh_err("environment.mesh", err))?
            }
            MeshSection::File { path, scale, entry } => {
                let scale = self.positive("environment.mesh.scale", *scale)?;
                let entry = match entry {
                    None => None,
                    Some(e) => {
                        let p = self.finite3("environment.mesh.entry.point", e.point)?;
                        let d = self.finite3("environment.mesh.entry.direction", e.direction)?;
                        if !(d.iter().map(|x| x * x).sum::<f64>() > 0.0) {
                            return Err(self.invalid(
                                "environment.mesh.entry.direction",
                                d,
                                "expected a non-zero vector",
                            ));
                        }
                        Some(([p[0] * scale, p[1] * scale, p[2] * scale], d))
                    }
                };
                let full = self
                    .path
                    .parent()
                    .map_or_else(|| path.clone(), |dir| dir.join(path));
                Environment::from_file(&full, scale, entry)
                    .map_err(|err| mesh_err("environment.mesh.path", err))?
            }
            MeshSection::Plane {
                point,
                normal,
                size,
            } => {
                let point = self.finite3("environment.mesh.point", *point)?;
                let normal = self.finite3("environment.mesh.normal", *normal)?;
                if !(normal.iter().map(|x| x * x).sum::<f64>() > 0.0) {
                    return Err(self.invalid(
                        "environment.mesh.normal",
                        normal,
                        "expected a non-zero vector",
                    ));
                }
                let size = self.positive("environment.mesh.size", *size)?;
                Environment::plane(point, normal, size)
                    .map_err(|err| mesh_err("environment.mesh", err))?
            }
        };
        if let Some(f) = &e.friction {
            let mu_s = self.non_negative("environment.friction.static", f.static_coefficient)?;
            let mu_k = self.non_negative("environment.friction.kinetic", f.kinetic)?;
            if mu_k > mu_s {
                return Err(self.invalid(
                    "environment.friction.kinetic",
                    mu_k,
                    "expected kinetic <= static",
                ));
            }
            env.friction = constraints::Friction {
                static_coefficient: mu_s,
                kinetic_coefficient: mu_k,
            };
        }
        if let Some(m) = e.margin {
            env.margin = self.non_negative("environment.margin", m)?;
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
        let young = self.positive(&f("material.young_modulus"), m.young_modulus)?;
        let shear = match (m.shear_modulus, m.poisson_ratio) {
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
            self.positive(&f("material.density"), m.density)?,
            self.positive(&f("material.radius"), m.radius)?,
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
        let n = rb.element_count() as i64;
        for (k, load) in r.loads.iter().enumerate() {
            let idx = if load.point < 0 {
                n + 1 + load.point
            } else {
                load.point
            };
            if !(0..=n).contains(&idx) {
                return Err(self.invalid(
                    f(&format!("load[{k}].point")),
                    load.point,
                    &format!("expected a point index in -{} ..= {n}", n + 1),
                ));
            }
            rb = rb.load(
                idx as usize,
                self.finite3(&f(&format!("load[{k}].force")), load.force)?,
            );
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
        let mut cond = EndCondition { kind, motion: None };
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
