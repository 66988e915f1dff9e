//! The `cosserat` Python package's native module (`cosserat._cosserat`).
//!
//! One class, [`PySimulation`] (`cosserat.Simulation`), wraps the library's `Simulation`: scenes
//! from a TOML file or string with overrides, stepping with the GIL released, the whole control
//! API (end motions and holds, loads, snapshots, reactions, writing state) and the state read
//! straight into new NumPy arrays (one copy, from the stepper's layout into the array). Errors
//! become Python exceptions carrying the library's messages: `SceneError` for a scene that
//! cannot be built, `StepError` for a run that diverged or was refused, `ControlError` for a
//! control call that was refused.
//!
//! The simulation lives behind a mutex (a `Stepper` is `Send` but not `Sync`, and Python may
//! call from any thread). A call that steps releases the GIL first and takes the mutex inside,
//! so it never waits for the GIL while holding the mutex.

use cosserat::scene::parse_scene;
use cosserat::{
    Backend, ControlError as LibControlError, EndCondition, EndKind, EndPath, PointLoad, RodHandle,
    Simulation, SimulationSnapshot, StateField, StepError as LibStepError,
};
use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyString};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

pyo3::create_exception!(
    cosserat,
    SceneError,
    PyValueError,
    "A scene that cannot be read or built; the message names the file, field and value."
);
pyo3::create_exception!(
    cosserat,
    StepError,
    PyRuntimeError,
    "A run that diverged (the message names the rod, element and step) or was refused."
);
pyo3::create_exception!(
    cosserat,
    ControlError,
    PyValueError,
    "A control call that was refused (no such rod, end or point, a wrong length, a value out of range); nothing was changed."
);

/// `(force, torque)` arrays of an end reaction.
type Wrench<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);
/// `(forces, torques)` of a batch's end reactions, `(copies, 3)` each.
type Wrenches<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>);
/// `(forces, escaped points)` per copy of a batch.
type WallContact<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<u64>>);
/// `(points, normals, forces)` arrays of a rod's contacts.
type Contacts<'py> = (
    Bound<'py, PyArray1<u64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
);

fn control_err(e: LibControlError) -> PyErr {
    ControlError::new_err(e.to_string())
}

/// A scene override value as the scene reader takes it (a TOML literal).
fn override_text(value: &Bound<'_, PyAny>) -> PyResult<String> {
    if value.is_instance_of::<PyBool>() {
        Ok(if value.extract::<bool>()? {
            "true"
        } else {
            "false"
        }
        .into())
    } else if value.is_instance_of::<PyInt>() {
        Ok(value.extract::<i64>()?.to_string())
    } else if value.is_instance_of::<PyFloat>() {
        let x: f64 = value.extract()?;
        // `{:?}` keeps a decimal point or exponent, so TOML reads a float.
        Ok(format!("{x:?}"))
    } else if value.is_instance_of::<PyString>() {
        value.extract()
    } else {
        Ok(value.str()?.to_string())
    }
}

fn overrides_of(overrides: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<(String, String)>> {
    let mut out = Vec::new();
    if let Some(d) = overrides {
        for (k, v) in d.iter() {
            out.push((k.extract::<String>()?, override_text(&v)?));
        }
    }
    Ok(out)
}

fn backend_of(name: &str) -> PyResult<Backend> {
    match name {
        "cpu" => Ok(Backend::Cpu),
        "cpu-rayon" => Ok(Backend::CpuRayon),
        "gpu" => Ok(Backend::Gpu),
        other => Err(SceneError::new_err(format!(
            "backend = {other:?}: expected \"cpu\", \"cpu-rayon\" or \"gpu\""
        ))),
    }
}

fn end_kind_of(kind: &str) -> PyResult<EndKind> {
    match kind {
        "free" => Ok(EndKind::Free),
        "pinned" => Ok(EndKind::Pinned),
        "clamped" => Ok(EndKind::Clamped),
        other => Err(ControlError::new_err(format!(
            "kind = {other:?}: expected \"free\", \"pinned\" or \"clamped\""
        ))),
    }
}

/// `[[f64; N]]` over the memory of a C-contiguous `(k, N)` float64 array.
fn rows<const N: usize>(slice: &mut [f64]) -> &mut [[f64; N]] {
    let len = slice.len() / N;
    // SAFETY: `[f64; N]` has the size of `N` `f64` and their alignment, no padding.
    unsafe { std::slice::from_raw_parts_mut(slice.as_mut_ptr().cast::<[f64; N]>(), len) }
}

/// A path's displacement and rotation at each keyframe.
type Keyframes = (Vec<[f64; 3]>, Vec<[f64; 3]>);

/// The displacement and rotation keyframes of a path of `n` keyframes (zero where not given).
fn keyframes(
    n: usize,
    displacement: Option<Vec<Vec<f64>>>,
    rotation: Option<Vec<Vec<f64>>>,
) -> PyResult<Keyframes> {
    let rows = |name: &str, v: Option<Vec<Vec<f64>>>| -> PyResult<Vec<[f64; 3]>> {
        match v {
            None => Ok(vec![[0.0; 3]; n]),
            Some(rows) => rows.iter().map(|r| vec3(name, r)).collect(),
        }
    };
    Ok((
        rows("displacement", displacement)?,
        rows("rotation", rotation)?,
    ))
}

fn vec3(name: &str, v: &[f64]) -> PyResult<[f64; 3]> {
    <[f64; 3]>::try_from(v)
        .map_err(|_| ControlError::new_err(format!("{name}: expected 3 numbers, got {}", v.len())))
}

/// A state snapshot of a `Simulation` (`Simulation.snapshot()`), to return to with
/// `Simulation.restore()`.
#[pyclass(name = "Snapshot", module = "cosserat")]
struct PySnapshot {
    inner: Mutex<Saved>,
    time: f64,
}

/// What a snapshot holds.
enum Saved {
    /// A whole simulation: restoring and stepping repeats the steps bit for bit.
    Whole(SimulationSnapshot),
    /// The rods of one copy of a batch stepped as one simulation.
    Rods(Vec<RodState>),
}

/// A rod's state and end conditions (a copy's share of a batch stepped as one simulation).
struct RodState {
    positions: Vec<[f64; 3]>,
    velocities: Vec<[f64; 3]>,
    angular_velocities: Vec<[f64; 3]>,
    frames: Vec<[f64; 4]>,
    ends: [EndCondition<f64>; 2],
}

impl RodState {
    fn of(sim: &Simulation, h: RodHandle) -> Result<Self, LibControlError> {
        let n = sim.stepper().elements(h.0)?;
        let field = |f: StateField| -> Result<Vec<[f64; 3]>, LibControlError> {
            let mut v = vec![[0.0; 3]; f.len(n)];
            sim.read(h, f, &mut v)?;
            Ok(v)
        };
        let mut frames = vec![[0.0; 4]; n];
        sim.read_frames(h, &mut frames)?;
        Ok(Self {
            positions: field(StateField::Positions)?,
            velocities: field(StateField::Velocities)?,
            angular_velocities: field(StateField::AngularVelocities)?,
            frames,
            ends: [sim.end_condition(h, 0)?, sim.end_condition(h, 1)?],
        })
    }

    /// Writes this state into rod `h`; motions of the ends are shifted by `shift` seconds (the
    /// clock moved on since the state was taken).
    fn write(&self, sim: &mut Simulation, h: RodHandle, shift: f64) -> Result<(), LibControlError> {
        sim.write(h, StateField::Positions, &self.positions)?;
        sim.write(h, StateField::Velocities, &self.velocities)?;
        sim.write(h, StateField::AngularVelocities, &self.angular_velocities)?;
        sim.write_frames(h, &self.frames)?;
        for (end, condition) in self.ends.iter().enumerate() {
            let mut condition = condition.clone();
            if let Some(m) = condition.motion.as_mut() {
                m.start_time += shift;
                m.end_time += shift;
            }
            sim.set_end_condition(h, end, condition)?;
        }
        Ok(())
    }
}

impl PySnapshot {
    /// The state of `sim` now.
    fn of(sim: &mut Simulation) -> PyResult<Self> {
        let time = sim.time();
        let inner = sim
            .snapshot()
            .map_err(|e| StepError::new_err(e.to_string()))?;
        Ok(Self {
            inner: Mutex::new(Saved::Whole(inner)),
            time,
        })
    }

    /// The state of rods `rods` of `sim` now.
    fn of_rods(sim: &Simulation, rods: Range<usize>) -> PyResult<Self> {
        let states = rods
            .map(|r| RodState::of(sim, RodHandle(r)))
            .collect::<Result<_, _>>()
            .map_err(control_err)?;
        Ok(Self {
            inner: Mutex::new(Saved::Rods(states)),
            time: sim.time(),
        })
    }

    /// Returns rods `rods` of `sim` to this state: all of them from a whole snapshot (bit for
    /// bit), or those of a copy.
    fn restore_into(&self, sim: &mut Simulation, rods: Range<usize>) -> PyResult<()> {
        let saved = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        match &*saved {
            Saved::Whole(snap) if rods == (0..sim.rods().count()) => {
                sim.restore(snap).map_err(control_err)
            }
            Saved::Whole(_) => Err(ControlError::new_err(
                "this snapshot holds a whole simulation; one copy of a batch stepped as one \
                 simulation (layout=\"copies\") takes a snapshot of a copy of such a batch",
            )),
            Saved::Rods(states) if states.len() != rods.len() => {
                Err(ControlError::new_err(format!(
                    "the snapshot holds {} rod(s), this has {}",
                    states.len(),
                    rods.len()
                )))
            }
            Saved::Rods(states) => {
                let shift = sim.time() - self.time;
                for (s, r) in states.iter().zip(rods) {
                    s.write(sim, RodHandle(r), shift).map_err(control_err)?;
                }
                Ok(())
            }
        }
    }
}

#[pymethods]
impl PySnapshot {
    /// Simulated time of the snapshot [s].
    #[getter]
    fn time(&self) -> f64 {
        self.time
    }

    fn __repr__(&self) -> String {
        format!("<cosserat.Snapshot at t = {} s>", self.time)
    }
}

/// A simulation of one or more Cosserat rods (see the package docstring).
#[pyclass(name = "Simulation", module = "cosserat")]
struct PySimulation {
    sim: Mutex<Simulation>,
    name: String,
    scene_steps: u64,
}

impl PySimulation {
    fn lock(&self) -> MutexGuard<'_, Simulation> {
        // A panic while stepping poisons the mutex; the state is then whatever the step left,
        // as after a divergence.
        self.sim.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn from_text(
        path: &Path,
        text: &str,
        overrides: Vec<(String, String)>,
        backend: &str,
    ) -> PyResult<Self> {
        let backend = backend_of(backend)?;
        let (builder, length, name) =
            parse_scene(path, text, &overrides).map_err(|e| SceneError::new_err(e.to_string()))?;
        let sim = builder
            .backend(backend)
            .build()
            .map_err(|e| SceneError::new_err(format!("{}: {e}", path.display())))?;
        Ok(Self {
            sim: Mutex::new(sim),
            name,
            scene_steps: length.steps,
        })
    }

    fn handle(sim: &Simulation, rod: usize) -> PyResult<RodHandle> {
        let count = sim.rods().count();
        if rod < count {
            Ok(RodHandle(rod))
        } else {
            Err(ControlError::new_err(format!(
                "no rod {rod}: the simulation has rods 0..{count}"
            )))
        }
    }

    fn read3<'py>(
        &self,
        py: Python<'py>,
        rod: usize,
        field: StateField,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        let n = sim.stepper().elements(h.0).map_err(control_err)?;
        let len = field.len(n);
        let out = PyArray2::<f64>::zeros(py, [len, 3], false);
        {
            let mut rw = out.readwrite();
            let slice = rw
                .as_slice_mut()
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            sim.read(h, field, rows::<3>(slice)).map_err(control_err)?;
        }
        Ok(out)
    }

    fn write3(
        &self,
        rod: usize,
        field: StateField,
        values: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<()> {
        let shape = values.shape();
        if shape.len() != 2 || shape[1] != 3 {
            return Err(ControlError::new_err(format!(
                "{}: expected an array of shape (k, 3), got {shape:?}",
                field_name(field)
            )));
        }
        let rows: Vec<[f64; 3]> = values
            .as_array()
            .rows()
            .into_iter()
            .map(|r| [r[0], r[1], r[2]])
            .collect();
        let mut sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        sim.write(h, field, &rows).map_err(control_err)
    }
}

fn field_name(field: StateField) -> &'static str {
    match field {
        StateField::Positions => "positions",
        StateField::Velocities => "velocities",
        StateField::AngularVelocities => "angular_velocities",
        StateField::Director(_) => "directors",
    }
}

#[pymethods]
impl PySimulation {
    /// Builds the scene in the TOML file `path`.
    ///
    /// `overrides` maps dotted scene keys to values (`{"rod.elements": 100, "solver.dt":
    /// 1e-5}`), as the command line's `--set key=value`; a string value is read as a TOML
    /// literal. `backend` is `"cpu"`, `"cpu-rayon"` or `"gpu"`.
    #[staticmethod]
    #[pyo3(signature = (path, overrides=None, backend="cpu"))]
    fn from_file(
        path: PathBuf,
        overrides: Option<&Bound<'_, PyDict>>,
        backend: &str,
    ) -> PyResult<Self> {
        let text = std::fs::read_to_string(&path)
            .map_err(|e| SceneError::new_err(format!("{}: {e}", path.display())))?;
        Self::from_text(&path, &text, overrides_of(overrides)?, backend)
    }

    /// Builds a scene from TOML text; `name` names it in messages (relative mesh paths are
    /// resolved against the working directory).
    #[staticmethod]
    #[pyo3(signature = (text, overrides=None, backend="cpu", name="scene.toml"))]
    fn from_toml(
        text: &str,
        overrides: Option<&Bound<'_, PyDict>>,
        backend: &str,
        name: &str,
    ) -> PyResult<Self> {
        Self::from_text(Path::new(name), text, overrides_of(overrides)?, backend)
    }

    /// Takes one step.
    fn step(&self, py: Python<'_>) -> PyResult<()> {
        py.detach(|| self.lock().step())
            .map_err(|e| StepError::new_err(e.to_string()))
    }

    /// Takes `steps` steps (the scene's own run length when `None`), with the GIL released.
    #[pyo3(signature = (steps=None))]
    fn run(&self, py: Python<'_>, steps: Option<u64>) -> PyResult<()> {
        let steps = steps.unwrap_or(self.scene_steps);
        py.detach(|| self.lock().run(steps))
            .map_err(|e| StepError::new_err(e.to_string()))
    }

    /// The scene's name.
    #[getter]
    fn name(&self) -> String {
        self.name.clone()
    }

    /// Simulated time [s].
    #[getter]
    fn time(&self) -> f64 {
        self.lock().time()
    }

    /// The time step [s].
    #[getter]
    fn dt(&self) -> f64 {
        self.lock().dt()
    }

    /// Steps taken so far.
    #[getter]
    fn steps(&self) -> u64 {
        self.lock().steps()
    }

    /// The scene's run length in steps (what `run()` takes).
    #[getter]
    fn scene_steps(&self) -> u64 {
        self.scene_steps
    }

    /// The backend: `"cpu"`, `"cpu-rayon"` or `"gpu"`.
    #[getter]
    fn backend(&self) -> &'static str {
        self.lock().backend().name()
    }

    /// The rods' names, in order (a rod is addressed by its index).
    #[getter]
    fn rod_names(&self) -> Vec<String> {
        let sim = self.lock();
        sim.rods().map(|h| sim.rod_name(h).to_string()).collect()
    }

    /// Warnings the builder gave (e.g. a step near the stability limit).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.lock().warnings().to_vec()
    }

    /// Elements of rod `rod` (it has one more point).
    #[pyo3(signature = (rod=0))]
    fn elements(&self, rod: usize) -> PyResult<usize> {
        let sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        sim.stepper().elements(h.0).map_err(control_err)
    }

    /// Centreline points of rod `rod`, shape `(n + 1, 3)` [m].
    #[pyo3(signature = (rod=0))]
    fn positions<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.read3(py, rod, StateField::Positions)
    }

    /// Point velocities of rod `rod`, shape `(n + 1, 3)` [m/s].
    #[pyo3(signature = (rod=0))]
    fn velocities<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.read3(py, rod, StateField::Velocities)
    }

    /// Frame angular velocities of rod `rod` in body axes, shape `(n, 3)` [rad/s].
    #[pyo3(signature = (rod=0))]
    fn angular_velocities<'py>(
        &self,
        py: Python<'py>,
        rod: usize,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.read3(py, rod, StateField::AngularVelocities)
    }

    /// Material frames of rod `rod` as unit quaternions `[w, x, y, z]` (body to world), shape
    /// `(n, 4)`.
    #[pyo3(signature = (rod=0))]
    fn frames<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        let n = sim.stepper().elements(h.0).map_err(control_err)?;
        let out = PyArray2::<f64>::zeros(py, [n, 4], false);
        {
            let mut rw = out.readwrite();
            let slice = rw
                .as_slice_mut()
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            sim.read_frames(h, rows::<4>(slice)).map_err(control_err)?;
        }
        Ok(out)
    }

    /// All directors of rod `rod` in world axes, shape `(n, 3, 3)`: `[j, k]` is director
    /// `d_{k+1}` of frame `j` (`d3` follows the tangent).
    #[pyo3(signature = (rod=0))]
    fn directors<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        let n = sim.stepper().elements(h.0).map_err(control_err)?;
        let mut d = vec![[0.0; 3]; n];
        let out = PyArray3::<f64>::zeros(py, [n, 3, 3], false);
        {
            let mut rw = out.readwrite();
            let slice = rw
                .as_slice_mut()
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            for k in 0..3 {
                sim.read(h, StateField::Director(k), &mut d)
                    .map_err(control_err)?;
                for (j, v) in d.iter().enumerate() {
                    slice[9 * j + 3 * k..9 * j + 3 * k + 3].copy_from_slice(v);
                }
            }
        }
        Ok(out)
    }

    /// Overwrites the points of rod `rod` (shape `(n + 1, 3)`); a held end point moves its
    /// holder with it.
    #[pyo3(signature = (values, rod=0))]
    fn set_positions(&self, values: PyReadonlyArray2<'_, f64>, rod: usize) -> PyResult<()> {
        self.write3(rod, StateField::Positions, values)
    }

    /// Overwrites the point velocities of rod `rod` (shape `(n + 1, 3)`).
    #[pyo3(signature = (values, rod=0))]
    fn set_velocities(&self, values: PyReadonlyArray2<'_, f64>, rod: usize) -> PyResult<()> {
        self.write3(rod, StateField::Velocities, values)
    }

    /// Overwrites the frames' body angular velocities of rod `rod` (shape `(n, 3)`).
    #[pyo3(signature = (values, rod=0))]
    fn set_angular_velocities(
        &self,
        values: PyReadonlyArray2<'_, f64>,
        rod: usize,
    ) -> PyResult<()> {
        self.write3(rod, StateField::AngularVelocities, values)
    }

    /// Overwrites the frames of rod `rod` (shape `(n, 4)`, `[w, x, y, z]`, normalised here); a
    /// clamp closes on the written end frame.
    #[pyo3(signature = (values, rod=0))]
    fn set_frames(&self, values: PyReadonlyArray2<'_, f64>, rod: usize) -> PyResult<()> {
        let shape = values.shape();
        if shape.len() != 2 || shape[1] != 4 {
            return Err(ControlError::new_err(format!(
                "frames: expected an array of shape (n, 4), got {shape:?}"
            )));
        }
        let rows: Vec<[f64; 4]> = values
            .as_array()
            .rows()
            .into_iter()
            .map(|r| [r[0], r[1], r[2], r[3]])
            .collect();
        let mut sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        sim.write_frames(h, &rows).map_err(control_err)
    }

    /// Drives end `end` (0: first point, 1: last) of rod `rod` at a constant `velocity` [m/s]
    /// and `angular_velocity` [rad/s] (world axes) from now until changed: a hand pushing,
    /// pulling and twisting. The end must be held (pinned or clamped).
    #[pyo3(signature = (end, velocity, angular_velocity=vec![0.0; 3], rod=0))]
    fn set_end_velocity(
        &self,
        end: usize,
        velocity: Vec<f64>,
        angular_velocity: Vec<f64>,
        rod: usize,
    ) -> PyResult<()> {
        let (v, w) = (
            vec3("velocity", &velocity)?,
            vec3("angular_velocity", &angular_velocity)?,
        );
        let mut sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        sim.set_end_velocity(h, end, v, w).map_err(control_err)
    }

    /// Moves held end `end` of rod `rod` to `position` (and, for a clamp, its frame to `frame`,
    /// `[w, x, y, z]`) in `duration` seconds at constant speed, then holds it there.
    #[pyo3(signature = (end, position, duration, frame=None, rod=0))]
    fn move_end_to(
        &self,
        end: usize,
        position: Vec<f64>,
        duration: f64,
        frame: Option<Vec<f64>>,
        rod: usize,
    ) -> PyResult<()> {
        let p = vec3("position", &position)?;
        let q = frame
            .map(|f| {
                <[f64; 4]>::try_from(f.as_slice()).map_err(|_| {
                    ControlError::new_err(format!("frame: expected 4 numbers, got {}", f.len()))
                })
            })
            .transpose()?;
        let mut sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        sim.move_end_to(h, end, p, q, duration).map_err(control_err)
    }

    /// Holds end `end` of rod `rod` as `kind` (`"free"`, `"pinned"` or `"clamped"`), at rest,
    /// from the next step on.
    #[pyo3(signature = (end, kind, rod=0))]
    fn hold_end(&self, end: usize, kind: &str, rod: usize) -> PyResult<()> {
        let kind = end_kind_of(kind)?;
        let mut sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        sim.hold_end(h, end, kind).map_err(control_err)
    }

    /// Replaces the point loads of rod `rod`: a list of `(point, (fx, fy, fz))` [N], or of
    /// `(point, (fx, fy, fz), (mx, my, mz))` with a moment [N m] (world axes; half on each
    /// frame beside an interior point, all on an end point's; explicit scheme); an empty list
    /// removes them.
    #[pyo3(signature = (loads, rod=0))]
    fn set_loads(&self, loads: Vec<Bound<'_, PyAny>>, rod: usize) -> PyResult<()> {
        let loads: Vec<PointLoad<f64>> = loads
            .iter()
            .map(|l| {
                let (point, force, moment) = match l.extract::<(usize, Vec<f64>)>() {
                    Ok((p, f)) => (p, f, vec![0.0; 3]),
                    Err(_) => l.extract::<(usize, Vec<f64>, Vec<f64>)>().map_err(|_| {
                        PyValueError::new_err("a load is (point, force) or (point, force, moment)")
                    })?,
                };
                Ok(PointLoad::new(point, vec3("load force", &force)?.into())
                    .with_moment(vec3("load moment", &moment)?.into()))
            })
            .collect::<PyResult<_>>()?;
        let mut sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        sim.set_point_loads(h, &loads).map_err(control_err)
    }

    /// Drives held end `end` of rod `rod` along a keyframed path from now on: at each of
    /// `times` [s from now] the end has moved by `displacement` [m] and turned by `rotation`
    /// (rotation vectors, axis times angle [rad]; clamped ends) from where it is now, both world
    /// axes and zero at the first time (0); linear in between, held after the last. Followed
    /// exactly at every step (CPU backends).
    #[pyo3(signature = (end, times, displacement=None, rotation=None, rod=0))]
    fn set_end_path(
        &self,
        end: usize,
        times: Vec<f64>,
        displacement: Option<Vec<Vec<f64>>>,
        rotation: Option<Vec<Vec<f64>>>,
        rod: usize,
    ) -> PyResult<()> {
        let (d, r) = keyframes(times.len(), displacement, rotation)?;
        let mut sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        let path = EndPath::new(sim.time(), times, d, r)
            .map_err(|why| ControlError::new_err(format!("end path: {why}")))?;
        let condition = sim.end_condition(h, end).map_err(control_err)?;
        sim.set_end_condition(h, end, condition.following(path))
            .map_err(control_err)
    }

    /// Moves obstacle `obstacle` (its index among the scene's obstacles, the `[environment]`
    /// first when there is one) along a keyframed path from now on, as `set_end_path` moves an
    /// end: at each of `times` [s from now] it has moved by `displacement` [m] and turned by
    /// `rotation` (rotation vectors about its own point) from where it is now; `times=None`
    /// stops it where it is. Half-spaces and cylinders only (meshes do not move), CPU backends.
    #[pyo3(signature = (obstacle, times=None, displacement=None, rotation=None))]
    fn set_obstacle_path(
        &self,
        obstacle: usize,
        times: Option<Vec<f64>>,
        displacement: Option<Vec<Vec<f64>>>,
        rotation: Option<Vec<Vec<f64>>>,
    ) -> PyResult<()> {
        let mut sim = self.lock();
        let path = match times {
            None => None,
            Some(times) => {
                let (d, r) = keyframes(times.len(), displacement, rotation)?;
                Some(
                    EndPath::new(sim.time(), times, d, r)
                        .map_err(|why| ControlError::new_err(format!("obstacle path: {why}")))?,
                )
            }
        };
        sim.set_obstacle_path(obstacle, path).map_err(control_err)
    }

    /// Lets held end `end` of rod `rod` slide freely along `axis` (world axes; the rod and the
    /// loads on the end point move it along it, its motion only across it), or holds it in
    /// every direction again with `axis=None` (explicit CPU scheme).
    #[pyo3(signature = (end, axis, rod=0))]
    fn slide_end(&self, end: usize, axis: Option<Vec<f64>>, rod: usize) -> PyResult<()> {
        let axis = axis.map(|a| vec3("axis", &a)).transpose()?;
        let mut sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        let mut condition = sim.end_condition(h, end).map_err(control_err)?;
        condition = match axis {
            Some(a) => condition.sliding_along(a.into()),
            None => EndCondition {
                slide: None,
                ..condition
            },
        };
        sim.set_end_condition(h, end, condition)
            .map_err(control_err)
    }

    /// Lets the clamp of end `end` of rod `rod` turn freely about `axis` (world axes now; it
    /// turns with the clamp's prescribed rotation): a hinge. `axis=None` holds the frame in every
    /// direction again (explicit CPU scheme).
    #[pyo3(signature = (end, axis, rod=0))]
    fn hinge_end(&self, end: usize, axis: Option<Vec<f64>>, rod: usize) -> PyResult<()> {
        let axis = axis.map(|a| vec3("axis", &a)).transpose()?;
        let mut sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        let mut condition = sim.end_condition(h, end).map_err(control_err)?;
        condition = match axis {
            Some(a) => condition.hinged_about(a.into()),
            None => EndCondition {
                hinge: None,
                ..condition
            },
        };
        sim.set_end_condition(h, end, condition)
            .map_err(control_err)
    }

    /// The filtered reaction at held end `end` of rod `rod` after the last step, the wrench the
    /// holder applies to the rod: `(force [N], torque about the held point [N m])` as arrays in
    /// world axes (a haptic device renders their negative); `None` for a free end or a backend
    /// without reactions.
    #[pyo3(signature = (end, rod=0))]
    fn end_reaction<'py>(
        &self,
        py: Python<'py>,
        end: usize,
        rod: usize,
    ) -> PyResult<Option<Wrench<'py>>> {
        let sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        if end > 1 {
            return Err(ControlError::new_err(format!(
                "no end {end}: ends are 0 (first point) and 1 (last point)"
            )));
        }
        Ok(sim.end_reaction(h, end).map(|r| {
            (
                PyArray1::from_slice(py, &r.force),
                PyArray1::from_slice(py, &r.torque),
            )
        }))
    }

    /// The contacts of rod `rod` at the last step: `(points, normals, forces)`, an index array
    /// of shape `(k,)` and two arrays of shape `(k, 3)` (unit normals, forces on the rod [N]).
    #[pyo3(signature = (rod=0))]
    fn contacts<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Contacts<'py>> {
        let sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        let mut samples = Vec::new();
        sim.contacts(h, &mut samples).map_err(control_err)?;
        let points: Vec<u64> = samples.iter().map(|c| c.point as u64).collect();
        let normals: Vec<Vec<f64>> = samples.iter().map(|c| c.normal.to_vec()).collect();
        let forces: Vec<Vec<f64>> = samples.iter().map(|c| c.force.to_vec()).collect();
        let k = samples.len();
        let as2 = |rows: Vec<Vec<f64>>| -> PyResult<Bound<'py, PyArray2<f64>>> {
            if k == 0 {
                Ok(PyArray2::zeros(py, [0, 3], false))
            } else {
                PyArray2::from_vec2(py, &rows).map_err(|e| PyValueError::new_err(e.to_string()))
            }
        };
        Ok((PyArray1::from_vec(py, points), as2(normals)?, as2(forces)?))
    }

    /// Energies of the current state [J], all rods together: `bend_twist`, `parallel`,
    /// `stretch`, `gravity`, `kinetic_translation`, `kinetic_rotation`.
    fn energies<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let e = self.lock().energies();
        let d = PyDict::new(py);
        d.set_item("bend_twist", e.bend_twist)?;
        d.set_item("parallel", e.parallel)?;
        d.set_item("stretch", e.stretch)?;
        d.set_item("gravity", e.gravity)?;
        d.set_item("kinetic_translation", e.kinetic_translation)?;
        d.set_item("kinetic_rotation", e.kinetic_rotation)?;
        Ok(d)
    }

    /// The whole state, to come back to with `restore`.
    fn snapshot(&self) -> PyResult<PySnapshot> {
        PySnapshot::of(&mut self.lock())
    }

    /// Returns to a snapshot of this simulation: the steps that follow are, bit for bit, those
    /// that followed it. (A snapshot of a copy of a `layout="copies"` batch writes its rods'
    /// state instead; see `Batch.snapshot`.)
    fn restore(&self, snapshot: &PySnapshot) -> PyResult<()> {
        let mut sim = self.lock();
        let rods = 0..sim.rods().count();
        snapshot.restore_into(&mut sim, rods)
    }

    /// Contact measurements of rod `rod` since the start, `None` without mesh contact:
    /// `max_penetration` [m], `escaped_points` (points found beyond a wall), `contacts` (at the
    /// last step), `max_contacts`, `steps`, `detection_seconds`.
    #[pyo3(signature = (rod=0))]
    fn collision_stats<'py>(
        &self,
        py: Python<'py>,
        rod: usize,
    ) -> PyResult<Option<Bound<'py, PyDict>>> {
        let sim = self.lock();
        let h = Self::handle(&sim, rod)?;
        let Some(c) = sim.stepper().collision_stats(h.0) else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("max_penetration", c.max_penetration)?;
        d.set_item("escaped_points", c.escaped_points)?;
        d.set_item("contacts", c.contacts)?;
        d.set_item("max_contacts", c.max_contacts)?;
        d.set_item("steps", c.steps)?;
        d.set_item("detection_seconds", c.detection_seconds)?;
        Ok(Some(d))
    }

    /// The generated vessel of the scene's environment, `None` for other meshes or none:
    /// `entry_point`, `entry_direction` (arrays), `trunk` (`(points (k, 3), radii (k,))` from
    /// the inlet) and `branches` (a list of such pairs, each from the trunk's axis outward) [m].
    fn vessel<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        vessel_dict(py, &self.lock())
    }

    fn __repr__(&self) -> String {
        let sim = self.lock();
        format!(
            "<cosserat.Simulation {:?}: {} rod(s), {} elements, t = {} s, dt = {} s, {}>",
            self.name,
            sim.rods().count(),
            sim.element_count(),
            sim.time(),
            sim.dt(),
            sim.backend().name()
        )
    }
}

/// The generated vessel of `sim`'s environment as a dict (`Simulation.vessel`).
fn vessel_dict<'py>(py: Python<'py>, sim: &Simulation) -> PyResult<Option<Bound<'py, PyDict>>> {
    let Some(v) = sim.environment().and_then(|e| e.vessel.as_ref()) else {
        return Ok(None);
    };
    let line = |c: &cosserat::cosserat_collide::vessel::Centreline| -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
            let rows: Vec<Vec<f64>> = c.points.iter().map(|p| p.to_vec()).collect();
            let points = PyArray2::from_vec2(py, &rows).map_err(|e| PyValueError::new_err(e.to_string()))?;
            let radii = PyArray1::from_slice(py, &c.radii);
            pyo3::types::PyTuple::new(py, [points.into_any(), radii.into_any()])
        };
    let d = PyDict::new(py);
    d.set_item("entry_point", PyArray1::from_slice(py, &v.entry_point))?;
    d.set_item(
        "entry_direction",
        PyArray1::from_slice(py, &v.entry_direction),
    )?;
    d.set_item("trunk", v.trunk.as_ref().map(&line).transpose()?)?;
    let branches = v.branches.iter().map(&line).collect::<PyResult<Vec<_>>>()?;
    d.set_item("branches", branches)?;
    Ok(Some(d))
}

/// Copies of one scene stepped together (`cosserat.Batch`), for learning and Monte-Carlo loops:
/// built once, read and steered as arrays with a leading copy axis, stepped with the GIL
/// released. Two layouts (`Layout`): one simulation per copy on rayon's pool, or one simulation
/// holding every copy's rods (`SimulationBuilder::copies`: one dispatch on the GPU).
#[pyclass(name = "Batch", module = "cosserat")]
struct PyBatch {
    layout: Layout,
    copies: usize,
    name: String,
    scene_steps: u64,
}

/// How a batch holds its copies.
enum Layout {
    /// One simulation per copy (cloned from one builder: a mesh is shared, not rebuilt); a copy
    /// that fails stops alone.
    Simulations(Vec<Mutex<Simulation>>),
    /// One simulation of all copies: rod `r` of copy `c` is its rod `c * rods + r`.
    Copies {
        sim: Box<Mutex<Simulation>>,
        rods: usize,
    },
}

impl Layout {
    fn name(&self) -> &'static str {
        match self {
            Layout::Simulations(_) => "simulations",
            Layout::Copies { .. } => "copies",
        }
    }
}

fn lock(m: &Mutex<Simulation>) -> MutexGuard<'_, Simulation> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl PyBatch {
    fn from_text(
        path: &Path,
        text: &str,
        copies: usize,
        overrides: Vec<(String, String)>,
        backend: &str,
        layout: Option<&str>,
    ) -> PyResult<Self> {
        if copies == 0 {
            return Err(SceneError::new_err(
                "copies = 0: expected at least one copy",
            ));
        }
        let backend = backend_of(backend)?;
        // On the CPU one simulation per copy: as fast as one for all (docs/benchmarks/python.md),
        // and a copy then fails alone and restores bit for bit. On the GPU one for all: one
        // dispatch for the batch, not one per copy.
        let layout = layout.unwrap_or(match backend {
            Backend::Gpu => "copies",
            _ => "simulations",
        });
        let (builder, length, name) =
            parse_scene(path, text, &overrides).map_err(|e| SceneError::new_err(e.to_string()))?;
        let builder = builder.backend(backend);
        let built = |b: cosserat::SimulationBuilder| {
            b.build()
                .map_err(|e| SceneError::new_err(format!("{}: {e}", path.display())))
        };
        let layout = match layout {
            "simulations" => Layout::Simulations(
                (0..copies)
                    .map(|_| built(builder.clone()).map(Mutex::new))
                    .collect::<PyResult<_>>()?,
            ),
            "copies" => {
                let sim = built(builder.copies(copies))?;
                let rods = sim.rods().count() / copies;
                Layout::Copies {
                    sim: Box::new(Mutex::new(sim)),
                    rods,
                }
            }
            other => {
                return Err(SceneError::new_err(format!(
                    "layout = {other:?}: expected \"simulations\" or \"copies\""
                )));
            }
        };
        Ok(Self {
            layout,
            copies,
            name,
            scene_steps: length.steps,
        })
    }

    /// The simulation that holds copy `copy` (unchecked) and its rods' range in it.
    fn sim(&self, copy: usize) -> (MutexGuard<'_, Simulation>, Range<usize>) {
        match &self.layout {
            Layout::Simulations(sims) => {
                let sim = lock(&sims[copy]);
                let rods = 0..sim.rods().count();
                (sim, rods)
            }
            Layout::Copies { sim, rods } => (lock(sim), copy * rods..(copy + 1) * rods),
        }
    }

    /// Copy `copy`, or an error naming the copies there are.
    fn copy(&self, copy: usize) -> PyResult<(MutexGuard<'_, Simulation>, Range<usize>)> {
        if copy < self.copies {
            Ok(self.sim(copy))
        } else {
            Err(ControlError::new_err(format!(
                "no copy {copy}: the batch has copies 0..{}",
                self.copies
            )))
        }
    }

    /// Rod `rod` of copy `copy` (unchecked) in its simulation, or an error naming the rods.
    fn rod(&self, copy: usize, rod: usize) -> PyResult<(MutexGuard<'_, Simulation>, RodHandle)> {
        let (sim, rods) = self.sim(copy);
        if rod < rods.len() {
            Ok((sim, RodHandle(rods.start + rod)))
        } else {
            Err(ControlError::new_err(format!(
                "no rod {rod}: each copy has rods 0..{}",
                rods.len()
            )))
        }
    }

    /// `(copies, k, 3)` of a field of rod `rod` of every copy.
    fn read3<'py>(
        &self,
        py: Python<'py>,
        rod: usize,
        field: StateField,
    ) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let n = {
            let (sim, h) = self.rod(0, rod)?;
            sim.stepper().elements(h.0).map_err(control_err)?
        };
        let len = field.len(n);
        let out = PyArray3::<f64>::zeros(py, [self.copies, len, 3], false);
        {
            let mut rw = out.readwrite();
            let slice = rw
                .as_slice_mut()
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            for (c, chunk) in slice.chunks_exact_mut(3 * len).enumerate() {
                let (sim, h) = self.rod(c, rod)?;
                sim.read(h, field, rows::<3>(chunk)).map_err(control_err)?;
            }
        }
        Ok(out)
    }

    /// Rows of a `(copies, 3)` array, or one row for every copy.
    fn per_copy(&self, name: &str, values: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<[f64; 3]>> {
        let a = values.as_array();
        let copies = self.copies;
        if a.ncols() != 3 || !(a.nrows() == copies || a.nrows() == 1) {
            return Err(ControlError::new_err(format!(
                "{name}: expected shape ({copies}, 3) or (1, 3), got {:?}",
                a.shape()
            )));
        }
        Ok((0..copies)
            .map(|c| {
                let r = a.row(if a.nrows() == 1 { 0 } else { c });
                [r[0], r[1], r[2]]
            })
            .collect())
    }

    /// One entry per copy after `steps` steps of the one simulation of all copies: the error
    /// stops every copy at the same step; the copy that diverged carries the message, the
    /// others say where they stopped.
    fn run_copies(&self, sim: &mut Simulation, rods: usize, steps: u64) -> Vec<Option<String>> {
        let Err(e) = sim.run(steps) else {
            return vec![None; self.copies];
        };
        let failed = match &e {
            LibStepError::Diverged(d) => Some(d.rod / rods),
            LibStepError::Backend(_) => None,
        };
        let step = sim.steps();
        (0..self.copies)
            .map(|c| {
                Some(match failed {
                    Some(f) if f == c => format!("copy {c}: {e}"),
                    Some(f) => format!(
                        "stopped at step {step} with copy {f}, which diverged (the copies are one simulation)"
                    ),
                    None => e.to_string(),
                })
            })
            .collect()
    }
}

#[pymethods]
impl PyBatch {
    /// `copies` copies of the scene in the TOML file `path` (overrides and backend as for
    /// `Simulation.from_file`). `layout` is `"simulations"` (one simulation per copy, stepped
    /// on rayon's pool) or `"copies"` (one simulation holding all copies' rods, one dispatch on
    /// the GPU); by default `"copies"` on the GPU and `"simulations"` on the CPU. With
    /// `"copies"`, `copies` replaces a scene's own `[batch] copies`.
    #[staticmethod]
    #[pyo3(signature = (path, copies, overrides=None, backend="cpu", *, layout=None))]
    fn from_file(
        path: PathBuf,
        copies: usize,
        overrides: Option<&Bound<'_, PyDict>>,
        backend: &str,
        layout: Option<&str>,
    ) -> PyResult<Self> {
        let text = std::fs::read_to_string(&path)
            .map_err(|e| SceneError::new_err(format!("{}: {e}", path.display())))?;
        Self::from_text(
            &path,
            &text,
            copies,
            overrides_of(overrides)?,
            backend,
            layout,
        )
    }

    /// `copies` copies of a scene given as TOML text.
    #[staticmethod]
    #[pyo3(signature = (text, copies, overrides=None, backend="cpu", name="scene.toml", *, layout=None))]
    fn from_toml(
        text: &str,
        copies: usize,
        overrides: Option<&Bound<'_, PyDict>>,
        backend: &str,
        name: &str,
        layout: Option<&str>,
    ) -> PyResult<Self> {
        Self::from_text(
            Path::new(name),
            text,
            copies,
            overrides_of(overrides)?,
            backend,
            layout,
        )
    }

    /// Number of copies.
    fn __len__(&self) -> usize {
        self.copies
    }

    /// The scene's name.
    #[getter]
    fn name(&self) -> String {
        self.name.clone()
    }

    /// The scene's run length in steps.
    #[getter]
    fn scene_steps(&self) -> u64 {
        self.scene_steps
    }

    /// How the copies are held: `"simulations"` or `"copies"`.
    #[getter]
    fn layout(&self) -> &'static str {
        self.layout.name()
    }

    /// The backend: `"cpu"`, `"cpu-rayon"` or `"gpu"`.
    #[getter]
    fn backend(&self) -> &'static str {
        self.sim(0).0.backend().name()
    }

    /// Simulated time of each copy [s] (they differ only after a copy failed).
    #[getter]
    fn times(&self) -> Vec<f64> {
        (0..self.copies).map(|c| self.sim(c).0.time()).collect()
    }

    /// Takes `steps` steps (the scene's run length when `None`) in every copy, with the GIL
    /// released. Returns one entry per copy: `None`, or the message of the error that stopped
    /// that copy. A copy that failed stays where it failed; with one simulation per copy the
    /// others go on, with one for all (`layout="copies"`) they stop at the same step, each
    /// saying so.
    #[pyo3(signature = (steps=None))]
    fn run(&self, py: Python<'_>, steps: Option<u64>) -> Vec<Option<String>> {
        use rayon::prelude::*;
        let steps = steps.unwrap_or(self.scene_steps);
        py.detach(|| match &self.layout {
            Layout::Simulations(sims) => sims
                .par_iter()
                .map(|m| lock(m).run(steps).err().map(|e| e.to_string()))
                .collect(),
            Layout::Copies { sim, rods } => self.run_copies(&mut lock(sim), *rods, steps),
        })
    }

    /// Points of rod `rod` of every copy, shape `(copies, n + 1, 3)` [m].
    #[pyo3(signature = (rod=0))]
    fn positions<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray3<f64>>> {
        self.read3(py, rod, StateField::Positions)
    }

    /// Point velocities of rod `rod` of every copy, shape `(copies, n + 1, 3)` [m/s].
    #[pyo3(signature = (rod=0))]
    fn velocities<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<Bound<'py, PyArray3<f64>>> {
        self.read3(py, rod, StateField::Velocities)
    }

    /// Drives end `end` of rod `rod` of every copy: `velocity` and `angular_velocity` of shape
    /// `(copies, 3)` (one row per copy) or `(1, 3)` (the same for all) [m/s, rad/s, world
    /// axes]: one call per tick for the whole batch.
    #[pyo3(signature = (end, velocity, angular_velocity=None, rod=0))]
    fn set_end_velocity(
        &self,
        end: usize,
        velocity: PyReadonlyArray2<'_, f64>,
        angular_velocity: Option<PyReadonlyArray2<'_, f64>>,
        rod: usize,
    ) -> PyResult<()> {
        let v = self.per_copy("velocity", &velocity)?;
        let w = match angular_velocity {
            Some(a) => self.per_copy("angular_velocity", &a)?,
            None => vec![[0.0; 3]; self.copies],
        };
        for (c, (v, w)) in v.into_iter().zip(w).enumerate() {
            let (mut sim, h) = self.rod(c, rod)?;
            sim.set_end_velocity(h, end, v, w).map_err(control_err)?;
        }
        Ok(())
    }

    /// The filtered reaction at end `end` of rod `rod` of every copy: `(forces, torques)`, each
    /// of shape `(copies, 3)` (NaN rows where the end is free or the backend has none).
    #[pyo3(signature = (end, rod=0))]
    fn end_reactions<'py>(
        &self,
        py: Python<'py>,
        end: usize,
        rod: usize,
    ) -> PyResult<Wrenches<'py>> {
        if end > 1 {
            return Err(ControlError::new_err(format!(
                "no end {end}: ends are 0 (first point) and 1 (last point)"
            )));
        }
        let (mut f, mut t) = (Vec::new(), Vec::new());
        for c in 0..self.copies {
            let (sim, h) = self.rod(c, rod)?;
            let r = sim.end_reaction(h, end);
            f.push(r.map_or(vec![f64::NAN; 3], |r| r.force.to_vec()));
            t.push(r.map_or(vec![f64::NAN; 3], |r| r.torque.to_vec()));
        }
        let as2 = |rows: Vec<Vec<f64>>| {
            PyArray2::from_vec2(py, &rows).map_err(|e| PyValueError::new_err(e.to_string()))
        };
        Ok((as2(f)?, as2(t)?))
    }

    /// Per copy, the summed magnitude of the contact forces on rod `rod` at the last step [N]
    /// and the points of it found beyond a wall since the start: `(forces (copies,), escaped
    /// (copies,))` (zeros without mesh contact).
    #[pyo3(signature = (rod=0))]
    fn wall_contact<'py>(&self, py: Python<'py>, rod: usize) -> PyResult<WallContact<'py>> {
        let (mut forces, mut escaped) = (Vec::new(), Vec::new());
        let mut samples = Vec::new();
        for c in 0..self.copies {
            let (sim, h) = self.rod(c, rod)?;
            sim.contacts(h, &mut samples).map_err(control_err)?;
            forces.push(
                samples
                    .iter()
                    .map(|s| s.force.iter().map(|x| x * x).sum::<f64>().sqrt())
                    .sum(),
            );
            escaped.push(
                sim.stepper()
                    .collision_stats(h.0)
                    .map_or(0, |st| st.escaped_points as u64),
            );
        }
        Ok((
            PyArray1::from_vec(py, forces),
            PyArray1::from_vec(py, escaped),
        ))
    }

    /// The generated vessel all copies share (as `Simulation.vessel`).
    fn vessel<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        vessel_dict(py, &self.sim(0).0)
    }

    /// Copy `copy` as its own state snapshot (to inspect or restore one copy). With one
    /// simulation per copy it is the copy's whole simulation (restoring repeats the steps bit
    /// for bit); with one for all (`layout="copies"`) it holds the copy's rods' points,
    /// velocities, frames and end conditions, and restoring writes them back while the shared
    /// clock and the contact and reaction histories go on: the steps that follow are close to
    /// the original ones, not equal bit for bit.
    fn snapshot(&self, copy: usize) -> PyResult<PySnapshot> {
        let (mut sim, rods) = self.copy(copy)?;
        match self.layout {
            Layout::Simulations(_) => PySnapshot::of(&mut sim),
            Layout::Copies { .. } => PySnapshot::of_rods(&sim, rods),
        }
    }

    /// Returns copy `copy` to a snapshot taken of any copy of this batch.
    fn restore(&self, copy: usize, snapshot: &PySnapshot) -> PyResult<()> {
        let (mut sim, rods) = self.copy(copy)?;
        snapshot.restore_into(&mut sim, rods)
    }
}

/// The native module; the package `cosserat` re-exports it.
#[pymodule]
fn _cosserat(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySimulation>()?;
    m.add_class::<PySnapshot>()?;
    m.add_class::<PyBatch>()?;
    m.add("SceneError", m.py().get_type::<SceneError>())?;
    m.add("StepError", m.py().get_type::<StepError>())?;
    m.add("ControlError", m.py().get_type::<ControlError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
