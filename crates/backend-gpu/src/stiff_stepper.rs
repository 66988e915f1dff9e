//! The GPU's stiff scheme as a [`Stepper`]: [`GpuStiffSimulation`] with a host copy of the
//! state, read back after every batch of steps so that reads cost no round trip of their own.

use cosserat_model::energy::{Energies, ForceModel, energies};
use cosserat_model::{Quat, RodParams, RodState, Vec3};
use cosserat_problem::divergence::first_too_fast;
use cosserat_problem::stepper::{
    check_capabilities, check_condition, check_end, check_loads, check_rod, check_write,
    condition_needs, read_state_field, read_state_frames, unit_frames,
};
use cosserat_problem::{
    Capabilities, Capability, Clock, CollisionStats, ContactSample, ControlError, CouplingStats,
    Divergence, EndCondition, EndReaction, PointLoad, Snapshot, SolverSettings, StateField,
    StepError, Stepper, StepperInfo, StiffSettings, StiffSummary,
};

use crate::stiff::GpuStiffSnapshot;
use crate::{GpuError, GpuOptions, GpuStiffRod, GpuStiffSimulation, GpuStiffWall};

const NAME: &str = "gpu stiff";

/// A rod as the stepper takes it: state, parameters, end conditions, and the introducer it is
/// fed through, if any.
pub type StiffRodParts = (
    RodState<f64>,
    RodParams<f64>,
    [EndCondition<f64>; 2],
    Option<crate::GpuGuide>,
);

/// Rods stepped by the stiff scheme on the GPU, through the [`Stepper`] interface.
pub struct GpuStiffStepper {
    sim: GpuStiffSimulation,
    /// The state after the last batch, as read back.
    states: Vec<RodState<f64>>,
    params: Vec<RodParams<f64>>,
    ends: Vec<[EndCondition<f64>; 2]>,
    loads: Vec<Vec<PointLoad<f64>>>,
    guides: Vec<Option<crate::GpuGuide>>,
    settings: SolverSettings<f64>,
    stiff: StiffSettings,
    clock: Clock,
}

/// A [`GpuStiffStepper`]'s snapshot: the device's (state, multipliers, factorisation, report)
/// and the host copies.
struct Saved {
    device: GpuStiffSnapshot,
    states: Vec<RodState<f64>>,
    params: Vec<RodParams<f64>>,
    ends: Vec<[EndCondition<f64>; 2]>,
    loads: Vec<Vec<PointLoad<f64>>>,
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

/// Constant forces as `(point, force)`; varying loads and moments are refused by the
/// capabilities before they get here.
fn forces(loads: &[PointLoad<f64>]) -> Vec<(usize, [f64; 3])> {
    loads
        .iter()
        .map(|l| (l.point, [l.force.x, l.force.y, l.force.z]))
        .collect()
}

impl GpuStiffStepper {
    /// Uploads `rods` (state, parameters, ends, constant loads) to a device of its own, in
    /// contact with `wall` if given; the held ends' reactions are low-pass filtered at
    /// `reaction_cutoff_hz`.
    pub fn new(
        rods: Vec<StiffRodParts>,
        loads: Vec<Vec<PointLoad<f64>>>,
        settings: &SolverSettings<f64>,
        stiff: &StiffSettings,
        reaction_cutoff_hz: f64,
        options: &GpuOptions,
        wall: Option<GpuStiffWall>,
    ) -> Result<Self, GpuError> {
        let inputs: Vec<GpuStiffRod> = rods
            .iter()
            .zip(&loads)
            .map(|((state, params, ends, guide), l)| GpuStiffRod {
                state: state.clone(),
                params: params.clone(),
                ends: ends.clone(),
                loads: forces(l),
                guide: *guide,
            })
            .collect();
        let mut sim = GpuStiffSimulation::with_wall(inputs, settings, stiff, options, wall)?;
        sim.set_reaction_cutoff(reaction_cutoff_hz);
        Ok(Self {
            states: rods.iter().map(|r| r.0.clone()).collect(),
            params: (0..sim.rods()).map(|r| sim.rod(r).params.clone()).collect(),
            guides: rods.iter().map(|r| r.3).collect(),
            ends: rods.into_iter().map(|r| r.2).collect(),
            loads,
            sim,
            settings: *settings,
            stiff: *stiff,
            clock: Clock::start(settings.dt),
        })
    }

    /// What the GPU's stiff stepper runs besides free rods: contact with one static mesh, guides,
    /// keyframed end paths, the held ends' reactions, double precision (its state is `f64`
    /// whatever the scene's precision).
    pub fn supported() -> Capabilities {
        Capabilities::of(&[
            Capability::MeshContact,
            Capability::Guide,
            Capability::StiffScheme,
            Capability::DoublePrecision,
            Capability::EndPaths,
            Capability::Reactions,
        ])
    }

    /// The simulation underneath (adapter, partition, per-rod reports).
    pub fn simulation(&self) -> &GpuStiffSimulation {
        &self.sim
    }

    fn elements_of(&self, rod: usize) -> Result<usize, ControlError> {
        check_rod(rod, self.states.len())?;
        Ok(self.states[rod].elements())
    }

    /// Re-uploads rod `rod` from the host copy (state, parameters, ends, loads).
    fn replace(&mut self, rod: usize) -> Result<(), ControlError> {
        let new = GpuStiffRod {
            state: self.states[rod].clone(),
            params: self.params[rod].clone(),
            ends: self.ends[rod].clone(),
            loads: forces(&self.loads[rod]),
            guide: self.guides[rod],
        };
        self.sim.replace_rod(rod, new).map_err(to_control)
    }
}

impl Stepper for GpuStiffStepper {
    fn info(&self) -> StepperInfo {
        StepperInfo {
            name: NAME,
            double_precision: true,
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
        let run = self.sim.step(steps);
        // The state is read also after a divergence (the diverged state, as on the CPU).
        self.states = self.sim.read_state().map_err(to_step)?;
        match run {
            Ok(()) => {
                let worst = self
                    .params
                    .iter()
                    .zip(&self.states)
                    .map(|(p, s)| {
                        let (lo, hi) =
                            cosserat_constraints::strain_extremes(&s.positions, &p.rest_lengths);
                        (hi - 1.0).max(1.0 - lo)
                    })
                    .fold(0.0, f64::max);
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
        let s = &mut self.states[rod];
        let target = match field {
            StateField::Positions => &mut s.positions,
            StateField::Velocities => &mut s.velocities,
            _ => &mut s.angular_velocities,
        };
        for (t, v) in target.iter_mut().zip(values) {
            *t = Vec3::new(v[0], v[1], v[2]);
        }
        self.sim
            .write_state(rod, self.states[rod].clone())
            .map_err(to_control)
    }

    fn write_frames(&mut self, rod: usize, values: &[[f64; 4]]) -> Result<(), ControlError> {
        let n = self.elements_of(rod)?;
        let frames: Vec<Quat<f64>> = unit_frames(n, values)?
            .map(|q| Quat::new(q[0], q[1], q[2], q[3]))
            .collect();
        self.states[rod].frames = frames;
        // A clamp closes on the written end frame, as on the CPU.
        for end in 0..2 {
            if self.ends[rod][end].holds_frame() {
                self.states[rod].seat_clamp(&self.params[rod], end);
            }
        }
        self.sim
            .write_state(rod, self.states[rod].clone())
            .map_err(to_control)
    }

    fn end_condition(&self, rod: usize, end: usize) -> Result<EndCondition<f64>, ControlError> {
        check_end(end)?;
        check_rod(rod, self.ends.len())?;
        Ok(self.ends[rod][end].clone())
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
        let old = std::mem::replace(&mut self.ends[rod][end], condition);
        let new = &self.ends[rod][end];
        if old.kind == new.kind {
            // A new motion: the kernel takes each step's velocities from the host.
            return self
                .sim
                .set_end_motion(rod, end, new.clone())
                .map_err(to_control);
        }
        // How the end is held changed: its point's mass, the clamp (closing on the end frame
        // where it is), the constants.
        let n = self.states[rod].elements();
        let point = if end == 0 { 0 } else { n };
        self.params[rod].inv_masses[point] = if new.holds_point() {
            0.0
        } else {
            1.0 / self.params[rod].masses[point]
        };
        if new.holds_frame() && !old.holds_frame() {
            self.states[rod].seat_clamp(&self.params[rod], end);
        }
        self.replace(rod)
    }

    fn set_loads(&mut self, rod: usize, loads: &[PointLoad<f64>]) -> Result<(), ControlError> {
        let last = self.elements_of(rod)?;
        check_loads(NAME, self.capabilities(), rod, last, loads)?;
        self.loads[rod] = loads.to_vec();
        self.replace(rod)
    }

    fn end_reaction(&self, rod: usize, end: usize) -> Option<EndReaction> {
        self.sim.end_reaction(rod, end)
    }

    fn max_reaction_force(&self) -> Option<f64> {
        self.sim.max_reaction_force()
    }

    fn contacts(&self, rod: usize, out: &mut Vec<ContactSample>) -> Result<(), ControlError> {
        check_rod(rod, self.states.len())?;
        out.clear();
        let found = self.sim.wall_contacts(rod).map_err(to_control)?;
        out.extend(
            found
                .into_iter()
                .map(|(point, normal, force)| ContactSample {
                    point,
                    normal,
                    force,
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
        let reports = self.sim.report();
        Some(StiffSummary::of_reports(
            reports,
            self.clock.step,
            self.stiff.tolerance,
        ))
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
        let step = self.clock.step;
        for (rod, (s, p)) in self.states.iter().zip(&self.params).enumerate() {
            first_too_fast(std::iter::once((s, p.radius)), limit, step)
                .map_err(|d| Divergence { rod, ..d })?;
        }
        Ok(())
    }

    fn snapshot(&mut self) -> Result<Snapshot, StepError> {
        Ok(Snapshot::new(
            NAME,
            self.clock,
            Box::new(Saved {
                device: self.sim.snapshot(),
                states: self.states.clone(),
                params: self.params.clone(),
                ends: self.ends.clone(),
                loads: self.loads.clone(),
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
        self.params.clone_from(&saved.params);
        self.ends.clone_from(&saved.ends);
        self.loads.clone_from(&saved.loads);
        self.clock = saved.clock;
        Ok(())
    }
}
