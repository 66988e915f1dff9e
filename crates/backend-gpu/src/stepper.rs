//! The GPU as a [`Stepper`]: the explicit scheme in `f32`, with a host-side copy of the state
//! refreshed after every batch so that reads cost no round trip of their own.

use cosserat_model::energy::{Energies, ForceModel, energies};
use cosserat_model::{RodParams, RodState, Vec3};
use cosserat_problem::divergence::first_too_fast;
use cosserat_problem::stepper::{
    check_capabilities, check_condition, check_end, check_rod, check_write, condition_needs,
    read_state_field, read_state_frames, unit_frames,
};
use cosserat_problem::{
    Capabilities, Capability, Clock, CollisionStats, ContactSample, ControlError, CouplingStats,
    Divergence, EndCondition, EndReaction, PointLoad, Snapshot, SolverSettings, StateField,
    StepError, Stepper, StepperInfo, StiffSummary,
};

use crate::{GpuError, GpuField, GpuOptions, GpuRodInput, GpuSimulation, GpuSnapshot};

const NAME: &str = "gpu explicit";

/// Rods stepped on the GPU through the [`Stepper`] interface.
pub struct GpuStepper {
    sim: GpuSimulation,
    /// The state after the last batch, as read back.
    states: Vec<RodState<f32>>,
    params: Vec<RodParams<f32>>,
    ends: Vec<[EndCondition<f32>; 2]>,
    settings: SolverSettings<f32>,
    clock: Clock,
}

/// A [`GpuStepper`]'s snapshot.
struct Saved {
    device: GpuSnapshot,
    states: Vec<RodState<f32>>,
    ends: Vec<[EndCondition<f32>; 2]>,
    clock: Clock,
}

fn to_step(e: GpuError) -> StepError {
    match e {
        GpuError::Diverged(d) => StepError::Diverged(d),
        other => StepError::Backend(other.to_string()),
    }
}

fn to_control(e: GpuError) -> ControlError {
    ControlError::Unsupported {
        stepper: NAME,
        what: format!("complete the call: {e}"),
    }
}

impl GpuStepper {
    /// Uploads `rods` (see [`GpuSimulation::new`]).
    pub fn new(
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: GpuOptions,
    ) -> Result<Self, GpuError> {
        Self::around(rods, settings, |rods| {
            GpuSimulation::new(rods, settings, options)
        })
    }

    /// Uploads `rods` to a device the caller already has (see [`GpuSimulation::on_device`]).
    pub fn on_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: GpuOptions,
    ) -> Result<Self, GpuError> {
        Self::around(rods, settings, |rods| {
            GpuSimulation::on_device(device, queue, rods, settings, options)
        })
    }

    /// The stepper around the simulation `make` builds from `rods`, with the host-side copy of
    /// their state.
    fn around(
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        make: impl FnOnce(Vec<GpuRodInput>) -> Result<GpuSimulation, GpuError>,
    ) -> Result<Self, GpuError> {
        let states = rods.iter().map(|r| r.state.clone()).collect();
        let params = rods.iter().map(|r| r.params.clone()).collect();
        let ends = rods.iter().map(|r| r.ends.clone()).collect();
        let sim = make(rods)?;
        Ok(Self {
            sim,
            states,
            params,
            ends,
            settings: *settings,
            clock: Clock::start(f64::from(settings.dt)),
        })
    }

    /// What the GPU stepper runs besides free rods: contact with one static mesh and the
    /// introducer guide (on the single-workgroup path).
    pub fn supported() -> Capabilities {
        Capabilities::of(&[Capability::MeshContact, Capability::Guide])
    }

    /// The simulation underneath, for what the trait does not cover (adapter, kernel path).
    pub fn simulation(&self) -> &GpuSimulation {
        &self.sim
    }

    fn elements_of(&self, rod: usize) -> Result<usize, ControlError> {
        check_rod(rod, self.states.len())?;
        Ok(self.states[rod].elements())
    }
}

impl Stepper for GpuStepper {
    fn info(&self) -> StepperInfo {
        StepperInfo {
            name: NAME,
            double_precision: false,
        }
    }

    fn capabilities(&self) -> Capabilities {
        Self::supported()
    }

    fn clock(&self) -> Clock {
        self.clock
    }

    fn advance(&mut self, steps: u64) -> Result<f64, StepError> {
        if steps == 0 {
            return Ok(0.0);
        }
        let mut left = steps;
        let run = (|| {
            while left > 0 {
                let k = left.min(u64::from(u32::MAX)) as u32;
                self.sim.step(k)?;
                left -= u64::from(k);
            }
            // One round trip: the state and the divergence status come back together.
            self.sim.read_state()
        })();
        match run {
            Ok(states) => {
                let mut worst = 0.0f64;
                for (p, state) in self.params.iter().zip(&states) {
                    let (lo, hi) =
                        cosserat_constraints::strain_extremes(&state.positions, &p.rest_lengths);
                    worst = worst.max(f64::from(hi) - 1.0).max(1.0 - f64::from(lo));
                }
                self.states = states;
                self.clock = self.clock.advanced(steps);
                Ok(worst)
            }
            Err(e) => {
                if let GpuError::Diverged(d) = &e {
                    self.clock.step = d.step;
                }
                Err(to_step(e))
            }
        }
    }

    fn rod_count(&self) -> usize {
        self.states.len()
    }

    fn elements(&self, rod: usize) -> Result<usize, ControlError> {
        self.elements_of(rod)
    }

    fn read(
        &self,
        rod: usize,
        field: StateField,
        out: &mut [[f64; 3]],
    ) -> Result<(), ControlError> {
        check_rod(rod, self.states.len())?;
        read_state_field(&self.states[rod], field, out)
    }

    fn read_frames(&self, rod: usize, out: &mut [[f64; 4]]) -> Result<(), ControlError> {
        check_rod(rod, self.states.len())?;
        read_state_frames(&self.states[rod], out)
    }

    fn write(
        &mut self,
        rod: usize,
        field: StateField,
        values: &[[f64; 3]],
    ) -> Result<(), ControlError> {
        let n = self.elements_of(rod)?;
        check_write(field, n, values)?;
        let gpu = match field {
            StateField::Positions => GpuField::Positions,
            StateField::Velocities => GpuField::Velocities,
            _ => GpuField::AngularVelocities,
        };
        let words: Vec<[f32; 4]> = values
            .iter()
            .map(|v| [v[0] as f32, v[1] as f32, v[2] as f32, 0.0])
            .collect();
        self.sim
            .write_rod_field(rod, gpu, &words)
            .map_err(to_control)?;
        let s = &mut self.states[rod];
        let target = match field {
            StateField::Positions => &mut s.positions,
            StateField::Velocities => &mut s.velocities,
            _ => &mut s.angular_velocities,
        };
        for (t, w) in target.iter_mut().zip(&words) {
            *t = Vec3::new(w[0], w[1], w[2]);
        }
        Ok(())
    }

    fn write_frames(&mut self, rod: usize, values: &[[f64; 4]]) -> Result<(), ControlError> {
        let n = self.elements_of(rod)?;
        let words: Vec<[f32; 4]> = unit_frames(n, values)?
            .map(|q| [q[1] as f32, q[2] as f32, q[3] as f32, q[0] as f32])
            .collect();
        self.sim
            .write_rod_field(rod, GpuField::Frames, &words)
            .map_err(to_control)?;
        for (t, w) in self.states[rod].frames.iter_mut().zip(&words) {
            *t = cosserat_model::Quat::new(w[3], w[0], w[1], w[2]);
        }
        // A clamp closes on the written end frame, as on the CPU: seated on the host copy and
        // written to the device.
        for end in 0..2 {
            if self.ends[rod][end].holds_frame() {
                self.states[rod].seat_clamp(&self.params[rod], end);
                let q = self.states[rod].clamp_frames[end];
                self.sim
                    .write_clamp_frame(rod, end, [q.i, q.j, q.k, q.w])
                    .map_err(to_control)?;
            }
        }
        Ok(())
    }

    fn end_condition(&self, rod: usize, end: usize) -> Result<EndCondition<f64>, ControlError> {
        check_end(end)?;
        check_rod(rod, self.ends.len())?;
        Ok(self.ends[rod][end].cast())
    }

    fn set_end_condition(
        &mut self,
        rod: usize,
        end: usize,
        condition: EndCondition<f64>,
    ) -> Result<(), ControlError> {
        check_end(end)?;
        check_rod(rod, self.ends.len())?;
        check_condition(&condition)?;
        check_capabilities(
            NAME,
            self.capabilities(),
            condition_needs(&condition),
            "drive an end with",
        )?;
        let old = &self.ends[rod][end];
        if old.kind != condition.kind {
            return Err(ControlError::Unsupported {
                stepper: NAME,
                what: format!(
                    "change how an end is held ({:?} to {:?}): its kernels are built for the ends they were given; change its motion instead",
                    old.kind, condition.kind
                ),
            });
        }
        let condition: EndCondition<f32> = condition.cast();
        self.sim
            .set_end_motion(rod, end, condition.motion)
            .map_err(to_control)?;
        self.ends[rod][end] = condition;
        Ok(())
    }

    fn set_loads(&mut self, rod: usize, loads: &[PointLoad<f64>]) -> Result<(), ControlError> {
        check_rod(rod, self.states.len())?;
        if loads.iter().any(|l| !l.force.iter().all(|x| x.is_finite())) {
            return Err(ControlError::Value {
                field: "load",
                why: "forces must be finite".into(),
            });
        }
        check_capabilities(NAME, self.capabilities(), PointLoad::needs(loads), "set")?;
        let loads: Vec<PointLoad<f32>> = loads.iter().map(PointLoad::cast).collect();
        self.sim
            .set_loads(rod, &loads)
            .map_err(|e| ControlError::Unsupported {
                stepper: NAME,
                what: format!("change these loads: {e}"),
            })
    }

    fn end_reaction(&self, _rod: usize, _end: usize) -> Option<EndReaction> {
        None
    }

    fn max_reaction_force(&self) -> Option<f64> {
        None
    }

    fn contacts(&self, rod: usize, out: &mut Vec<ContactSample>) -> Result<(), ControlError> {
        check_rod(rod, self.states.len())?;
        out.clear();
        let dt = f64::from(self.settings.dt);
        let masses = &self.params[rod].masses;
        out.extend(
            self.sim
                .wall_contacts(rod)
                .into_iter()
                .map(|(point, n, impulse)| {
                    let m = f64::from(masses[point]);
                    ContactSample {
                        point,
                        normal: n.map(f64::from),
                        force: impulse.map(|i| f64::from(i) * m / dt),
                    }
                }),
        );
        Ok(())
    }

    fn collision_stats(&self, rod: usize) -> Option<CollisionStats> {
        self.sim.collision_stats(rod)
    }

    fn coupling_stats(&self) -> Option<CouplingStats> {
        None
    }

    fn stiff_summary(&self) -> Option<StiffSummary> {
        None
    }

    fn energies(&self) -> Energies {
        self.states
            .iter()
            .zip(&self.params)
            .zip(&self.ends)
            .map(|((s, p), ends)| {
                let model = ForceModel {
                    extensible: self.settings.extensible,
                    gravity: self.settings.gravity,
                    clamped: ends.each_ref().map(|e| e.holds_frame()),
                };
                energies(s, p, &model)
            })
            .fold(Energies::default(), Energies::sum)
    }

    fn check_speed(&self, limit: f64) -> Result<(), Divergence> {
        first_too_fast(
            self.states
                .iter()
                .zip(&self.params)
                .map(|(s, p)| (s, p.radius)),
            limit,
            self.clock.step,
        )
    }

    fn snapshot(&mut self) -> Result<Snapshot, StepError> {
        let device = self.sim.snapshot().map_err(to_step)?;
        Ok(Snapshot::new(
            NAME,
            self.clock,
            Box::new(Saved {
                device,
                states: self.states.clone(),
                ends: self.ends.clone(),
                clock: self.clock,
            }),
        ))
    }

    fn restore(&mut self, snapshot: &Snapshot) -> Result<(), ControlError> {
        let Some(saved) = snapshot.data::<Saved>() else {
            return Err(ControlError::Snapshot(format!(
                "it was taken by the {} stepper, this is the {NAME} stepper",
                snapshot.stepper()
            )));
        };
        self.sim
            .restore(&saved.device)
            .map_err(|e| ControlError::Snapshot(e.to_string()))?;
        self.states.clone_from(&saved.states);
        self.ends.clone_from(&saved.ends);
        self.clock = saved.clock;
        Ok(())
    }
}
