//! Everything that travels from the device back to the host, and the state writes that must
//! agree with it.
//!
//! Positions come back without stalling the step loop: [`GpuSimulation::request_positions`]
//! (or [`GpuSimulation::step_and_request`]) copies them with the status words into one of two
//! staging buffers and maps it asynchronously, and [`GpuSimulation::read_positions`] waits for
//! the oldest request, first by polling the device for [`GpuOptions::spin_wait_us`], then by
//! blocking. The blocking reads ([`GpuSimulation::read_state`], [`GpuSimulation::check`],
//! snapshots, field writes) gather all the buffers they need into one staging buffer in one
//! submission: one round trip each. The kernel reports divergence and grid timeouts in per-item
//! status words, decoded here into [`GpuError`]s.
//!
//! [`GpuOptions::spin_wait_us`]: crate::GpuOptions::spin_wait_us

use crate::layout::{ClampG, DriveG};
use crate::sim::{EndTrack, RODC_STATS, WALL_STATS, WallRead};
use crate::{DivergedQuantity, Divergence, GpuError, GpuSimulation};
use cosserat_model::{Quat, Vec3};
use rayon::prelude::*;
use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering as AtomicOrdering};
use std::time::{Duration, Instant};

/// A device buffer a blocking read copies from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Part {
    Positions,
    Velocities,
    Frames,
    AngularVelocities,
    Status,
    /// Every rod's clamps ([`ClampG`], two per rod).
    Clamps,
    /// Wall contact: per-rod statistics and per-slot contacts.
    WallStats,
    Contacts,
    /// Bindings: each inner point's last outer segment.
    BoundSegments,
    /// Rod contact: per-group statistics.
    RodContactStats,
}

/// A position read in flight.
struct Pending {
    staging: usize,
    submission: wgpu::SubmissionIndex,
    /// Set by the map callback.
    mapped: Arc<AtomicBool>,
}

/// The staging buffers and the reads in flight of one simulation.
pub(crate) struct Readback {
    /// The two buffers position reads alternate between.
    staging: [wgpu::Buffer; 2],
    /// Staging buffer of blocking reads ([`GpuSimulation::check`],
    /// [`GpuSimulation::read_state`]), made on first use and kept.
    read_staging: Option<wgpu::Buffer>,
    pending: VecDeque<Pending>,
    /// How long a read polls before it blocks.
    spin_wait: Duration,
}

impl Readback {
    /// Staging buffers for `slots` state slots and `items` status words.
    pub(crate) fn new(device: &wgpu::Device, slots: u64, items: u64, spin_wait: Duration) -> Self {
        let staging_size = 16 * slots + 16 * items;
        let mk_staging = |label| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: staging_size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        Self {
            staging: [mk_staging("readback 0"), mk_staging("readback 1")],
            read_staging: None,
            pending: VecDeque::new(),
            spin_wait,
        }
    }
}

/// A field of a rod's state on the device, for [`GpuSimulation::write_rod_field`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GpuField {
    /// Centreline points.
    Positions,
    /// Point velocities.
    Velocities,
    /// Frames as `[x, y, z, w]`.
    Frames,
    /// Frame angular velocities (body coordinates).
    AngularVelocities,
}

/// The state of a [`GpuSimulation`] at one step ([`GpuSimulation::snapshot`]).
#[derive(Clone, Debug)]
pub struct GpuSnapshot {
    state: Vec<u8>,
    steps: u64,
    drives: Vec<DriveG>,
    tracks: Vec<EndTrack>,
}

impl GpuSimulation {
    /// Starts copying the current positions (and the divergence status) into a staging buffer
    /// without waiting. At most two requests may be outstanding; [`Self::read_positions`]
    /// returns the oldest.
    pub fn request_positions(&mut self) -> Result<(), GpuError> {
        let slot = self.readback_slot()?;
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        self.encode_readback(&mut enc, slot);
        let submission = self.gpu.queue.submit([enc.finish()]);
        self.map_readback(slot, submission);
        Ok(())
    }

    /// The staging buffer the next position request uses.
    pub(crate) fn readback_slot(&self) -> Result<usize, GpuError> {
        if self.readback.pending.len() >= 2 {
            return Err(GpuError::InvalidInput(
                "two position reads are already pending; read one first".into(),
            ));
        }
        Ok(match self.readback.pending.front() {
            Some(p) => 1 - p.staging,
            None => 0,
        })
    }

    pub(crate) fn encode_readback(&self, enc: &mut wgpu::CommandEncoder, slot: usize) {
        let staging = &self.readback.staging[slot];
        let pos_bytes = 16 * self.slots;
        enc.copy_buffer_to_buffer(&self.states[self.current].pos, 0, staging, 0, pos_bytes);
        enc.copy_buffer_to_buffer(
            &self.status_buf,
            0,
            staging,
            pos_bytes,
            16 * self.plan.items.len() as u64,
        );
    }

    pub(crate) fn map_readback(&mut self, slot: usize, submission: wgpu::SubmissionIndex) {
        let mapped = Arc::new(AtomicBool::new(false));
        let flag = mapped.clone();
        self.readback.staging[slot].map_async(wgpu::MapMode::Read, .., move |_| {
            flag.store(true, AtomicOrdering::Release);
        });
        self.readback.pending.push_back(Pending {
            staging: slot,
            submission,
            mapped,
        });
    }

    /// Waits until `mapped` is set by its map callback: first by polling the device in a busy
    /// loop for up to [`GpuOptions::spin_wait_us`], then blocking on `submission`.
    fn wait_mapped(
        &self,
        submission: wgpu::SubmissionIndex,
        mapped: &AtomicBool,
    ) -> Result<(), GpuError> {
        if !self.readback.spin_wait.is_zero() {
            let start = Instant::now();
            loop {
                self.gpu
                    .device
                    .poll(wgpu::PollType::Poll)
                    .map_err(|e| GpuError::Wgpu(format!("polling the GPU: {e}")))?;
                if mapped.load(AtomicOrdering::Acquire) {
                    return self.gpu.errors.take();
                }
                if start.elapsed() >= self.readback.spin_wait {
                    break;
                }
                std::hint::spin_loop();
            }
        }
        self.wait(submission)
    }

    fn wait(&self, submission: wgpu::SubmissionIndex) -> Result<(), GpuError> {
        self.gpu
            .device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: Some(Duration::from_secs(120)),
            })
            .map_err(|e| GpuError::Wgpu(format!("waiting for the GPU: {e}")))?;
        self.gpu.errors.take()
    }

    /// Positions of every rod (`n + 1` points each) as of the oldest pending
    /// [`Self::request_positions`], or as of now when none is pending (blocking).
    ///
    /// Fails with [`GpuError::Diverged`] naming rod, element and step if a rod diverged, and with
    /// [`GpuError::GridTimeout`] if a grid barrier timed out.
    pub fn read_positions(&mut self) -> Result<Vec<Vec<[f32; 3]>>, GpuError> {
        if self.readback.pending.is_empty() {
            self.request_positions()?;
        }
        let Some(p) = self.readback.pending.pop_front() else {
            unreachable!("a request was just made")
        };
        self.wait_mapped(p.submission, &p.mapped)?;
        let staging = &self.readback.staging[p.staging];
        let (positions, status) = {
            let view = staging
                .get_mapped_range(..)
                .map_err(|e| GpuError::Wgpu(format!("mapping the readback: {e}")))?;
            let floats: &[f32] = bytemuck::cast_slice(&view[..(16 * self.slots) as usize]);
            let status: Vec<u32> =
                bytemuck::cast_slice(&view[(16 * self.slots) as usize..]).to_vec();
            let positions = self
                .rods
                .iter()
                .map(|&(base, n)| {
                    (0..=n as usize)
                        .map(|i| {
                            let o = 4 * (base as usize + i);
                            [floats[o], floats[o + 1], floats[o + 2]]
                        })
                        .collect()
                })
                .collect();
            (positions, status)
        };
        staging.unmap();
        self.status_error(&status)?;
        Ok(positions)
    }

    fn status_error(&self, status: &[u32]) -> Result<(), GpuError> {
        let mut first: Option<Divergence> = None;
        for (i, w) in status.chunks_exact(4).enumerate() {
            if w[0] & 0x100 != 0 {
                return Err(GpuError::GridTimeout);
            }
            let code = w[0] & 0xff;
            if code == 0 {
                continue;
            }
            let value = f32::from_bits(w[3]) as f64;
            let quantity = match code {
                1 => DivergedQuantity::NonFiniteFrame,
                2 => DivergedQuantity::NonFinitePosition,
                _ => DivergedQuantity::Strain((value.sqrt() - 1.0).abs()),
            };
            let d = Divergence {
                rod: self.plan.items[i].rod as usize,
                element: w[1] as usize,
                step: w[2] as u64,
                quantity,
            };
            if first.is_none_or(|f| (d.step, d.rod, d.element) < (f.step, f.rod, f.element)) {
                first = Some(d);
            }
        }
        match first {
            Some(d) => Err(GpuError::Diverged(d)),
            None => Ok(()),
        }
    }

    /// Waits for all submitted work and reports divergence or a grid timeout, if any.
    pub fn check(&mut self) -> Result<(), GpuError> {
        let size = 16 * self.plan.items.len() as u64;
        let status = self.read_buffers(&[(Part::Status, size)])?;
        self.status_error(bytemuck::cast_slice(&status))
    }

    /// Copies `parts` (each from offset 0) one after another into the read staging buffer in one
    /// submission, waits for it, and returns the bytes: one round trip whatever the number of
    /// parts.
    fn read_buffers(&mut self, parts: &[(Part, u64)]) -> Result<Vec<u8>, GpuError> {
        let total: u64 = parts.iter().map(|p| p.1).sum();
        if self
            .readback
            .read_staging
            .as_ref()
            .is_none_or(|b| b.size() < total)
        {
            self.readback.read_staging =
                Some(self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("read"),
                    size: total,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }));
        }
        let Some(staging) = self.readback.read_staging.as_ref() else {
            unreachable!("made above")
        };
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("read"),
            });
        let st = &self.states[self.current];
        let mut offset = 0;
        for &(part, size) in parts {
            let source = match part {
                Part::Positions => &st.pos,
                Part::Velocities => &st.vel,
                Part::Frames => &st.frm,
                Part::AngularVelocities => &st.omg,
                Part::Status => &self.status_buf,
                Part::Clamps => &self.clamps_buf,
                Part::BoundSegments => {
                    let Some(b) = self.bind.as_ref() else {
                        unreachable!("bound segments are read only with binding buffers")
                    };
                    &b.segments
                }
                Part::RodContactStats => {
                    let Some(b) = self.rodc.as_ref() else {
                        unreachable!("rod contact statistics are read only with their buffers")
                    };
                    &b.stats
                }
                Part::WallStats | Part::Contacts => {
                    let Some(w) = self.wall.as_ref() else {
                        unreachable!("wall parts are read only with wall buffers")
                    };
                    if part == Part::WallStats {
                        &w.stats
                    } else {
                        &w.contacts
                    }
                }
            };
            enc.copy_buffer_to_buffer(source, 0, staging, offset, size);
            offset += size;
        }
        let submission = self.gpu.queue.submit([enc.finish()]);
        let mapped = Arc::new(AtomicBool::new(false));
        let flag = mapped.clone();
        staging.map_async(wgpu::MapMode::Read, ..total, move |_| {
            flag.store(true, AtomicOrdering::Release);
        });
        self.wait_mapped(submission, &mapped)?;
        let bytes = staging
            .get_mapped_range(..total)
            .map_err(|e| GpuError::Wgpu(format!("mapping a readback: {e}")))?
            .to_vec();
        staging.unmap();
        Ok(bytes)
    }

    /// Makes every point and element walk the tree at its next step: clearances and near lists
    /// made before the state was replaced say nothing about the new state.
    fn forget_clearances(&self) {
        if let Some(w) = &self.wall {
            for b in &w.near {
                let zeros = vec![0u8; b.size() as usize];
                self.gpu.queue.write_buffer(b, 0, &zeros);
            }
        }
    }

    /// Bytes of the status words.
    fn status_bytes(&self) -> usize {
        16 * self.plan.items.len()
    }

    /// Bytes of the clamps.
    fn clamp_bytes(&self) -> usize {
        std::mem::size_of_val(self.clamps.as_slice())
    }

    /// Positions, velocities, frames, angular velocities (each `16 · slots` bytes), the status
    /// words and the clamps, one after another, in one round trip.
    fn read_whole_state(&mut self) -> Result<Vec<u8>, GpuError> {
        let parts = self.whole_state_parts();
        self.read_buffers(&parts)
    }

    /// The parts of [`Self::read_whole_state`] and their sizes.
    fn whole_state_parts(&self) -> Vec<(Part, u64)> {
        let bytes = 16 * self.slots;
        let mut parts = vec![
            (Part::Positions, bytes),
            (Part::Velocities, bytes),
            (Part::Frames, bytes),
            (Part::AngularVelocities, bytes),
            (Part::Status, self.status_bytes() as u64),
            (Part::Clamps, self.clamp_bytes() as u64),
        ];
        if self.bind.is_some() {
            parts.push((Part::BoundSegments, 4 * self.slots));
        }
        parts
    }

    /// The full state of every rod (blocking, one round trip). Fails like
    /// [`Self::read_positions`].
    pub fn read_state(&mut self) -> Result<Vec<cosserat_model::RodState<f32>>, GpuError> {
        use cosserat_model::RodState;
        // The wall's statistics and contacts, and rod contact's statistics, come in the same
        // round trip, after the state.
        let mut parts = self.whole_state_parts();
        let extra_at: usize = parts.iter().map(|p| p.1 as usize).sum();
        let wall_bytes = 4 * WALL_STATS * self.rods.len();
        if self.wall.is_some() {
            parts.extend([
                (Part::WallStats, wall_bytes as u64),
                (Part::Contacts, 32 * self.slots),
            ]);
        }
        let rodc_bytes = 4 * RODC_STATS * self.plan.groups.len();
        if self.rodc.is_some() {
            parts.push((Part::RodContactStats, rodc_bytes as u64));
        }
        let mut all = self.read_buffers(&parts)?;
        let mut extra = all.split_off(extra_at);
        if self.rodc.is_some() {
            let words = extra.split_off(extra.len() - rodc_bytes);
            self.rodc_read = Some(bytemuck::pod_collect_to_vec(&words));
        }
        if self.wall.is_some() {
            let (stats, contacts) = extra.split_at(wall_bytes);
            self.wall_read = Some(WallRead {
                stats: bytemuck::pod_collect_to_vec(stats),
                contacts: bytemuck::pod_collect_to_vec(contacts),
            });
        }
        let dropped = self.rod_contact_dropped();
        if dropped > 0 {
            return Err(GpuError::InvalidInput(format!(
                "rod contact: {dropped} contacts or sphere pairs did not fit the kernel's arrays (at most {} contacts per thread and {} sphere pairs); the GPU cannot step this scene, use --backend cpu",
                self.plan.cfg.rodc.per_thread, self.plan.cfg.rodc.pairs
            )));
        }
        let b = (16 * self.slots) as usize;
        let clamps_at = 4 * b + self.status_bytes();
        self.status_error(bytemuck::cast_slice(&all[4 * b..clamps_at]))?;
        let clamps: Vec<ClampG> = all[clamps_at..clamps_at + self.clamp_bytes()]
            .chunks_exact(std::mem::size_of::<ClampG>())
            .map(bytemuck::pod_read_unaligned)
            .collect();
        let floats: &[f32] = bytemuck::cast_slice(&all[..4 * b]);
        let quarter = b / 4;
        let (p, v, q, w) = (
            &floats[..quarter],
            &floats[quarter..2 * quarter],
            &floats[2 * quarter..3 * quarter],
            &floats[3 * quarter..],
        );
        let v3 = |a: &[f32], i: usize| Vec3::new(a[4 * i], a[4 * i + 1], a[4 * i + 2]);
        // Every rod's state on every core (a batch of thousands of rods is megabytes).
        let states = self
            .rods
            .par_iter()
            .enumerate()
            .map(|(r, &(base, n))| {
                let (b, n) = (base as usize, n as usize);
                let clamp = |end: usize| {
                    let [x, y, z, w] = clamps[2 * r + end].q;
                    Quat::new(w, x, y, z)
                };
                RodState {
                    positions: (0..=n).map(|i| v3(p, b + i)).collect(),
                    velocities: (0..=n).map(|i| v3(v, b + i)).collect(),
                    frames: (0..n)
                        .map(|i| {
                            let o = 4 * (b + i);
                            Quat::new(q[o + 3], q[o], q[o + 1], q[o + 2])
                        })
                        .collect(),
                    angular_velocities: (0..n).map(|i| v3(w, b + i)).collect(),
                    clamp_frames: [clamp(0), clamp(1)],
                }
            })
            .collect();
        self.ends_read = clamps;
        Ok(states)
    }

    /// The filtered reaction at end `end` of rod `rod` as of the last [`Self::read_state`]
    /// (`None` for an end that holds nothing): the force and (clamped ends) the torque the
    /// holder applies to the rod, low-pass filtered at [`crate::GpuOptions::reaction_cutoff_hz`]
    /// as on the CPU.
    pub fn end_reaction(&self, rod: usize, end: usize) -> Option<cosserat_problem::EndReaction> {
        let held = self.ends_held.get(rod)?[end];
        let c = self.ends_read.get(2 * rod + end)?;
        let v = |a: [f32; 4]| [a[0], a[1], a[2]].map(f64::from);
        held.then(|| cosserat_problem::EndReaction {
            force: v(c.rf),
            torque: v(c.rt),
        })
    }

    /// The largest filtered reaction force at any held end so far [N], as of the last
    /// [`Self::read_state`]; `None` when no end is held.
    pub fn max_reaction_force(&self) -> Option<f64> {
        let held = self.ends_held.iter().flatten().zip(&self.ends_read);
        held.filter(|(h, _)| **h)
            .map(|(_, c)| f64::from(c.rf[3]))
            .reduce(f64::max)
    }

    /// The whole device state (points, frames, their velocities, the status words, the clamps)
    /// and the host's bookkeeping of held ends, for [`Self::restore`] (blocking, one round
    /// trip).
    pub fn snapshot(&mut self) -> Result<GpuSnapshot, GpuError> {
        self.ensure_idle()?;
        let state = self.read_whole_state()?;
        Ok(GpuSnapshot {
            state,
            steps: self.steps,
            drives: self.drives.clone(),
            tracks: self.tracks.clone(),
        })
    }

    /// Returns to a snapshot of this simulation: the next steps are, bit for bit, those that
    /// followed it.
    pub fn restore(&mut self, snapshot: &GpuSnapshot) -> Result<(), GpuError> {
        self.ensure_idle()?;
        self.forget_clearances();
        let bytes = (16 * self.slots) as usize;
        let clamps_at = 4 * bytes + self.status_bytes();
        let bound_at = clamps_at + self.clamp_bytes();
        let bound_bytes = if self.bind.is_some() {
            4 * self.slots as usize
        } else {
            0
        };
        if snapshot.state.len() != bound_at + bound_bytes
            || snapshot.drives.len() != self.drives.len()
        {
            return Err(GpuError::InvalidInput(
                "the snapshot was taken of other rods".into(),
            ));
        }
        let st = &self.states[self.current];
        for (k, buf) in [&st.pos, &st.vel, &st.frm, &st.omg].into_iter().enumerate() {
            self.gpu
                .queue
                .write_buffer(buf, 0, &snapshot.state[k * bytes..(k + 1) * bytes]);
        }
        self.gpu
            .queue
            .write_buffer(&self.status_buf, 0, &snapshot.state[4 * bytes..clamps_at]);
        self.gpu
            .queue
            .write_buffer(&self.clamps_buf, 0, &snapshot.state[clamps_at..bound_at]);
        if let Some(b) = &self.bind {
            self.gpu
                .queue
                .write_buffer(&b.segments, 0, &snapshot.state[bound_at..]);
        }
        // The held ends' reactions read back are those of the snapshot again.
        self.ends_read = snapshot.state[clamps_at..bound_at]
            .chunks_exact(std::mem::size_of::<ClampG>())
            .map(bytemuck::pod_read_unaligned)
            .collect();
        self.steps = snapshot.steps;
        self.drives.clone_from(&snapshot.drives);
        self.tracks.clone_from(&snapshot.tracks);
        self.drives_dirty = true;
        self.gpu.queue.submit([]);
        self.gpu.errors.take()
    }

    /// Overwrites one field of rod `rod` (`xyz` of each of its points or frames; frames as
    /// `[x, y, z, w]`), keeping whatever else the device stores beside them. A held end point
    /// starts its path again from where it is put. Clamp frames are not touched: a caller that
    /// writes end frames seats the clamps on them (`RodState::seat_clamp`) and writes them with
    /// [`write_clamp_frame`](Self::write_clamp_frame).
    pub fn write_rod_field(
        &mut self,
        rod: usize,
        field: GpuField,
        values: &[[f32; 4]],
    ) -> Result<(), GpuError> {
        self.ensure_idle()?;
        self.forget_clearances();
        let Some(&(base, n)) = self.rods.get(rod) else {
            return Err(GpuError::InvalidInput(format!("no rod {rod}")));
        };
        let (base, n) = (base as usize, n as usize);
        let (part, count, width) = match field {
            GpuField::Positions => (Part::Positions, n + 1, 3),
            GpuField::Velocities => (Part::Velocities, n + 1, 3),
            GpuField::Frames => (Part::Frames, n, 4),
            GpuField::AngularVelocities => (Part::AngularVelocities, n, 3),
        };
        if values.len() != count {
            return Err(GpuError::InvalidInput(format!(
                "rod {rod}: expected {count} entries, got {}",
                values.len()
            )));
        }
        let bytes = self.read_buffers(&[(part, 16 * self.slots)])?;
        let mut words: Vec<[f32; 4]> = bytemuck::cast_slice(&bytes).to_vec();
        for (w, v) in words[base..base + count].iter_mut().zip(values) {
            w[..width].copy_from_slice(&v[..width]);
        }
        let st = &self.states[self.current];
        let buf = match part {
            Part::Positions => &st.pos,
            Part::Velocities => &st.vel,
            Part::Frames => &st.frm,
            _ => &st.omg,
        };
        self.gpu.queue.write_buffer(
            buf,
            16 * base as u64,
            bytemuck::cast_slice(&words[base..base + count]),
        );
        if field == GpuField::Positions {
            // A held end starts its path again from where it was put.
            for end in 0..2 {
                let p = words[base + if end == 0 { 0 } else { n }];
                self.restart_end_path(2 * rod + end, [p[0], p[1], p[2]]);
            }
        }
        self.gpu.queue.submit([]);
        self.gpu.errors.take()
    }

    /// Overwrites the frame (`[x, y, z, w]`) of the clamp at end `end` of rod `rod`, a rod built
    /// with that end clamped (`CLAMP`).
    pub fn write_clamp_frame(
        &mut self,
        rod: usize,
        end: usize,
        q: [f32; 4],
    ) -> Result<(), GpuError> {
        self.ensure_idle()?;
        if !self.clamped.get(rod).is_some_and(|c| end < 2 && c[end]) {
            return Err(GpuError::InvalidInput(format!(
                "rod {rod} has no clamp at end {end}"
            )));
        }
        let at = std::mem::size_of::<ClampG>() * (2 * rod + end);
        self.gpu
            .queue
            .write_buffer(&self.clamps_buf, at as u64, bytemuck::cast_slice(&q));
        self.gpu.queue.submit([]);
        self.gpu.errors.take()
    }

    /// Refuses to change the state while a position readback is in flight.
    fn ensure_idle(&self) -> Result<(), GpuError> {
        if self.readback.pending.is_empty() {
            Ok(())
        } else {
            Err(GpuError::InvalidInput(
                "read the requested positions before changing or saving the state".into(),
            ))
        }
    }

    /// GPU time in seconds of all batches submitted since the last call, from timestamp queries
    /// (blocking); `None` when timestamps were not requested or the adapter lacks them.
    pub fn take_gpu_time(&mut self) -> Result<Option<f64>, GpuError> {
        if self.query.is_none() {
            return Ok(None);
        }
        let pending = std::mem::take(&mut self.gpu_time_pending);
        for b in &pending {
            b.map_async(wgpu::MapMode::Read, .., |_| {});
        }
        self.gpu.wait_idle()?;
        let mut total = 0.0;
        for b in &pending {
            {
                let view = b
                    .get_mapped_range(..)
                    .map_err(|e| GpuError::Wgpu(format!("mapping timestamps: {e}")))?;
                let t: &[u64] = bytemuck::cast_slice(&view);
                total += t[1].saturating_sub(t[0]) as f64 * self.timestamp_period_ns * 1e-9;
            }
            b.unmap();
        }
        self.gpu.errors.take()?;
        Ok(Some(total))
    }
}
