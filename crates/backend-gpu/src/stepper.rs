//! The GPU as a [`Stepper`]: the explicit scheme in `f32`, with a host-side copy of the state
//! refreshed after every batch so that reads cost no round trip of their own.
//!
//! The rods can be split across several devices ([`GpuStepper::on_gpus`]): each device steps a
//! contiguous share of them as a [`GpuSimulation`] of its own. Rods that bindings or rod
//! contact couple are stepped in one workgroup and never split between shares, so a share
//! needs nothing from another during a batch: every device is given its steps before any is waited for, and the one round trip per
//! batch reads them one after the other while the others are still running.

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

use crate::device::Gpu;
use crate::{GpuError, GpuField, GpuOptions, GpuRodInput, GpuSimulation, GpuSnapshot, Gpus};
use rayon::prelude::*;

const NAME: &str = "gpu explicit";

/// Rods stepped on the GPU through the [`Stepper`] interface.
pub struct GpuStepper {
    /// One simulation per device, each stepping the rods `starts[k]..starts[k + 1]`.
    parts: Vec<GpuSimulation>,
    starts: Vec<usize>,
    /// The state after the last batch, as read back.
    states: Vec<RodState<f32>>,
    params: Vec<RodParams<f32>>,
    ends: Vec<[EndCondition<f32>; 2]>,
    settings: SolverSettings<f32>,
    clock: Clock,
}

/// A [`GpuStepper`]'s snapshot.
struct Saved {
    devices: Vec<GpuSnapshot>,
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
        let starts = vec![0, rods.len()];
        Self::around(rods, settings, starts, |rods| {
            GpuSimulation::new(rods, settings, options.clone())
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
        let starts = vec![0, rods.len()];
        let mut device = Some((device, queue));
        Self::around(rods, settings, starts, |rods| {
            let (device, queue) = device.take().expect("one share");
            GpuSimulation::on_device(device, queue, rods, settings, options.clone())
        })
    }

    /// Splits `rods` across devices (see [`Gpus`]): each device that is used steps a
    /// contiguous share of the rods, balanced by their points, on the kernel its share plans.
    /// With [`Gpus::All`] a scene with fewer rods than devices uses one device per rod.
    pub fn on_gpus(
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        options: GpuOptions,
        gpus: Gpus,
    ) -> Result<Self, GpuError> {
        if let Gpus::Count(n) = gpus
            && n > rods.len()
        {
            return Err(GpuError::InvalidInput(format!(
                "gpus = {n}: the scene has {} rod{} to share among them; ask for at most that many",
                rods.len(),
                if rods.len() == 1 { "" } else { "s" }
            )));
        }
        let count = match gpus {
            Gpus::Count(1) => return Self::new(rods, settings, options),
            Gpus::Count(n) => Some(n),
            Gpus::All => None,
        };
        let mut devices = Gpu::acquire_each(&options, count)?.into_iter();
        let parts = devices.len().min(rods.len());
        Self::split(rods, settings, parts, |share| {
            let gpu = devices.next().expect("one device per share");
            GpuSimulation::on_gpu(gpu, share, settings, options.clone())
        })
    }

    /// Splits `rods` into at most `parts` contiguous shares balanced by their points, never
    /// between rods a binding couples, and builds each share's simulation with `make` (in
    /// order). [`Self::on_gpus`] gives each share a device of its own; a test can give two
    /// shares two devices on one adapter.
    pub fn split(
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        parts: usize,
        make: impl FnMut(Vec<GpuRodInput>) -> Result<GpuSimulation, GpuError>,
    ) -> Result<Self, GpuError> {
        let points: Vec<usize> = rods.iter().map(|r| r.state.positions.len()).collect();
        // A share may start at rod i when no group of bound rods has members on both sides.
        let mut cuttable = vec![true; rods.len()];
        for g in crate::plan::coupled_groups(&rods)? {
            let (lo, hi) = (g[0], g[g.len() - 1]);
            for c in &mut cuttable[lo + 1..=hi] {
                *c = false;
            }
        }
        let starts = shares(&points, parts, &cuttable);
        // Each share names its outer rods by their index in the share.
        let mut rods = rods;
        for w in starts.windows(2) {
            for rod in &mut rods[w[0]..w[1]] {
                if let Some(b) = &mut rod.binding {
                    b.outer -= w[0];
                }
            }
        }
        Self::around(rods, settings, starts, make)
    }

    /// The stepper around the simulations `make` builds from the shares of `rods` that begin at
    /// `starts`, with the host-side copy of their state.
    fn around(
        rods: Vec<GpuRodInput>,
        settings: &SolverSettings<f32>,
        starts: Vec<usize>,
        mut make: impl FnMut(Vec<GpuRodInput>) -> Result<GpuSimulation, GpuError>,
    ) -> Result<Self, GpuError> {
        let states = rods.iter().map(|r| r.state.clone()).collect();
        let params = rods.iter().map(|r| r.params.clone()).collect();
        let ends = rods.iter().map(|r| r.ends.clone()).collect();
        let mut rods = rods.into_iter();
        let parts = starts
            .windows(2)
            .map(|w| make(rods.by_ref().take(w[1] - w[0]).collect()))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            parts,
            starts,
            states,
            params,
            ends,
            settings: *settings,
            clock: Clock::start(f64::from(settings.dt)),
        })
    }

    /// What the GPU stepper runs besides free rods: contact with one static mesh, the
    /// introducer guide, bindings, and rod–rod and self-contact (on the single-workgroup path).
    pub fn supported() -> Capabilities {
        Capabilities::of(&[
            Capability::MeshContact,
            Capability::Guide,
            Capability::Bindings,
            Capability::RodContact,
        ])
    }

    /// The (first device's) simulation underneath, for what the trait does not cover (adapter,
    /// kernel path).
    pub fn simulation(&self) -> &GpuSimulation {
        &self.parts[0]
    }

    /// The simulation of each device, in the order of the rods they step.
    pub fn simulations(&self) -> &[GpuSimulation] {
        &self.parts
    }

    /// `steps` steps on every device, and the state read back: the rods' states in order, or
    /// the gravest error of any device.
    fn step_every_device(&mut self, steps: u64) -> Result<Vec<RodState<f32>>, GpuError> {
        // Every device steps and reads back on a thread of its own: one round trip per
        // device, the state and the divergence status together, the transfers and the
        // host's share of the devices overlapping.
        let batch = |sim: &mut GpuSimulation| {
            let mut left = steps;
            while left > 0 {
                let k = left.min(u64::from(u32::MAX)) as u32;
                sim.step(k)?;
                left -= u64::from(k);
            }
            sim.read_state()
        };
        let read: Vec<Result<Vec<RodState<f32>>, GpuError>> = match &mut self.parts[..] {
            [one] => vec![batch(one)],
            parts => std::thread::scope(|s| {
                let running: Vec<_> = parts.iter_mut().map(|sim| s.spawn(|| batch(sim))).collect();
                running
                    .into_iter()
                    .map(|t| t.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                    .collect()
            }),
        };
        // Every device is read before an error is returned, so the earliest divergence of
        // all is the one reported.
        let mut states = Vec::with_capacity(self.states.len());
        let mut first: Option<GpuError> = None;
        for (result, &start) in read.into_iter().zip(&self.starts) {
            match result {
                Ok(s) => states.extend(s),
                Err(mut e) => {
                    if let GpuError::Diverged(d) = &mut e {
                        d.rod += start;
                    }
                    first = Some(match first.take() {
                        None => e,
                        Some(f) => graver(f, e),
                    });
                }
            }
        }
        first.map_or(Ok(states), Err)
    }

    /// The device simulation that steps `rod`, and the rod's index in it.
    fn part_of(&self, rod: usize) -> (usize, usize) {
        let k = self.starts.partition_point(|&s| s <= rod) - 1;
        (k, rod - self.starts[k])
    }

    /// The device simulation that steps `rod` (mutably), and the rod's index in it.
    fn part_mut(&mut self, rod: usize) -> (&mut GpuSimulation, usize) {
        let (k, local) = self.part_of(rod);
        (&mut self.parts[k], local)
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
        let run = self.step_every_device(steps);
        match run {
            Ok(states) => {
                let worst = self
                    .params
                    .par_iter()
                    .zip(&states)
                    .map(|(p, state)| {
                        let (lo, hi) = cosserat_constraints::strain_extremes(
                            &state.positions,
                            &p.rest_lengths,
                        );
                        (f64::from(hi) - 1.0).max(1.0 - f64::from(lo))
                    })
                    .reduce(|| 0.0, f64::max);
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
        let (sim, local) = self.part_mut(rod);
        sim.write_rod_field(local, gpu, &words)
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
        let (sim, local) = self.part_mut(rod);
        sim.write_rod_field(local, GpuField::Frames, &words)
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
                let (sim, local) = self.part_mut(rod);
                sim.write_clamp_frame(local, end, [q.i, q.j, q.k, q.w])
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
        let (sim, local) = self.part_mut(rod);
        sim.set_end_motion(local, end, condition.motion)
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
        let (sim, local) = self.part_mut(rod);
        sim.set_loads(local, &loads)
            .map_err(|e| ControlError::Unsupported {
                stepper: NAME,
                what: format!("change these loads: {e}"),
            })
    }

    fn end_reaction(&self, rod: usize, end: usize) -> Option<EndReaction> {
        if rod >= self.states.len() || end > 1 {
            return None;
        }
        let (k, local) = self.part_of(rod);
        self.parts[k].end_reaction(local, end)
    }

    fn max_reaction_force(&self) -> Option<f64> {
        self.parts
            .iter()
            .filter_map(GpuSimulation::max_reaction_force)
            .reduce(f64::max)
    }

    fn contacts(&self, rod: usize, out: &mut Vec<ContactSample>) -> Result<(), ControlError> {
        check_rod(rod, self.states.len())?;
        out.clear();
        let dt = f64::from(self.settings.dt);
        let masses = &self.params[rod].masses;
        let (k, local) = self.part_of(rod);
        out.extend(
            self.parts[k]
                .wall_contacts(local)
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
        if rod >= self.states.len() {
            return None;
        }
        let (k, local) = self.part_of(rod);
        self.parts[k].collision_stats(local)
    }

    fn coupling_stats(&self) -> Option<CouplingStats> {
        // Every device's groups together (rods in contact are never split between devices).
        self.parts
            .iter()
            .filter_map(GpuSimulation::rod_contact_stats)
            .reduce(|a, b| CouplingStats {
                contacts: a.contacts + b.contacts,
                max_contacts: a.max_contacts + b.max_contacts,
                min_separation: a.min_separation.min(b.min_separation),
                min_separation_radii: if b.min_separation < a.min_separation {
                    b.min_separation_radii
                } else {
                    a.min_separation_radii
                },
                min_separation_ratio: a.min_separation_ratio.min(b.min_separation_ratio),
                steps: a.steps.max(b.steps),
                ..a
            })
    }

    fn stiff_summary(&self) -> Option<StiffSummary> {
        None
    }

    fn energies(&self) -> Energies {
        // Each rod's on every core, summed in rod order (the same sum on any machine).
        let each: Vec<Energies> = self
            .states
            .par_iter()
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
            .collect();
        each.into_iter().fold(Energies::default(), Energies::sum)
    }

    fn check_speed(&self, limit: f64) -> Result<(), Divergence> {
        // The first rod (in order) with a point too fast, each rod checked on every core.
        let step = self.clock.step;
        match self
            .states
            .par_iter()
            .zip(&self.params)
            .enumerate()
            .find_map_first(|(rod, (s, p))| {
                first_too_fast(std::iter::once((s, p.radius)), limit, step)
                    .err()
                    .map(|d| Divergence { rod, ..d })
            }) {
            Some(d) => Err(d),
            None => Ok(()),
        }
    }

    fn snapshot(&mut self) -> Result<Snapshot, StepError> {
        let devices = self
            .parts
            .iter_mut()
            .map(GpuSimulation::snapshot)
            .collect::<Result<Vec<_>, _>>()
            .map_err(to_step)?;
        Ok(Snapshot::new(
            NAME,
            self.clock,
            Box::new(Saved {
                devices,
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
        for (sim, device) in self.parts.iter_mut().zip(&saved.devices) {
            sim.restore(device)
                .map_err(|e| ControlError::Snapshot(e.to_string()))?;
        }
        self.states.clone_from(&saved.states);
        self.ends.clone_from(&saved.ends);
        self.clock = saved.clock;
        Ok(())
    }
}

/// Of two devices' errors, the one to report: a device's failure before a divergence, and of
/// two divergences the earlier.
fn graver(a: GpuError, b: GpuError) -> GpuError {
    match (&a, &b) {
        (GpuError::Diverged(x), GpuError::Diverged(y)) if y.step < x.step => b,
        (GpuError::Diverged(_), GpuError::Diverged(_)) => a,
        (GpuError::Diverged(_), _) => b,
        _ => a,
    }
}

/// The first rod of each of at most `parts` contiguous shares of rods with `points` points
/// each, and the end: shares as equal in points as whole rods allow, none empty, each starting
/// at a rod that is `cuttable` (fewer shares where too few are).
fn shares(points: &[usize], parts: usize, cuttable: &[bool]) -> Vec<usize> {
    let parts = parts.clamp(1, points.len().max(1));
    let total: usize = points.iter().sum();
    let mut starts = vec![0];
    let mut sum = 0;
    for (i, &p) in points.iter().enumerate() {
        let k = starts.len();
        // Cut before rod i once the shares so far hold their part of the points, leaving a rod
        // for each share still to come.
        let rods_left = points.len() - i;
        let shares_left = parts - (k - 1);
        if k < parts
            && i > starts[k - 1]
            && cuttable[i]
            && (sum * parts >= total * k || rods_left < shares_left)
        {
            starts.push(i);
        }
        sum += p;
    }
    starts.push(points.len());
    starts
}

#[cfg(test)]
mod tests {
    use super::shares;

    #[test]
    fn shares_are_contiguous_balanced_and_never_empty() {
        assert_eq!(shares(&[10; 8], 2, &[true; 8]), vec![0, 4, 8]);
        assert_eq!(shares(&[10; 8], 4, &[true; 8]), vec![0, 2, 4, 6, 8]);
        assert_eq!(shares(&[10; 7], 2, &[true; 7]), vec![0, 4, 7]);
        assert_eq!(shares(&[10; 3], 3, &[true; 3]), vec![0, 1, 2, 3]);
        // A long rod first: the short ones share the second device.
        assert_eq!(shares(&[100, 10, 10, 10], 2, &[true; 4]), vec![0, 1, 4]);
        // More shares than rods cannot leave one empty.
        assert_eq!(shares(&[5, 5], 4, &[true; 2]), vec![0, 1, 2]);
        assert_eq!(shares(&[5], 1, &[true]), vec![0, 1]);
        for parts in 1..6 {
            let s = shares(&[3, 1, 4, 1, 5, 9, 2, 6], parts, &[true; 8]);
            assert_eq!(s.len(), parts + 1);
            assert!(s.windows(2).all(|w| w[0] < w[1]), "{s:?}");
        }
        // Pairs of bound rods stay together: cuts only between pairs.
        let pairs = [true, false, true, false, true, false, true, false];
        assert_eq!(shares(&[10; 8], 4, &pairs), vec![0, 2, 4, 6, 8]);
        assert_eq!(shares(&[10; 8], 3, &pairs), vec![0, 4, 6, 8]);
        // One group of everything: one share.
        assert_eq!(
            shares(&[10; 4], 2, &[true, false, false, false]),
            vec![0, 4]
        );
    }
}
