//! A stepping loop with the exact (direct) inextensibility solver, for measurements until the
//! facade offers `solver.constraint_solver = "direct"`.
//!
//! It is the CPU stepper's Fig. 5 loop written out (forces → velocities → held ends →
//! constraints → positions), built only from the model's public kernels, with
//! [`solve_distance_direct`] in place of the Gauss–Seidel sweeps.

#![allow(dead_code)]

use cosserat::EndCondition;
use cosserat::cosserat_constraints::direct::{
    DirectReport, DirectScratch, DirectSettings, solve_distance_direct,
};
use cosserat::cosserat_model::energy::{Energies, ForceModel, accumulate_forces, energies};
use cosserat::cosserat_model::quat::rotate_inv;
use cosserat::cosserat_model::rod::{RodSpec, build_rod};
use cosserat::cosserat_model::{Quat, Real, RodParams, RodState, Vec3};

/// One rod stepped with the direct solver.
pub struct DirectRod<T: Real> {
    /// State.
    pub state: RodState<T>,
    /// Parameters (held points have zero inverse mass).
    pub params: RodParams<T>,
    ends: [EndCondition<f64>; 2],
    loads: Vec<(usize, Vec3<T>)>,
    forces: Vec<Vec3<T>>,
    torques: Vec<Vec3<T>>,
    scratch: DirectScratch,
    /// Newton settings.
    pub settings: DirectSettings,
    /// Largest |l/l0 − 1| after any step.
    pub max_strain: f64,
    /// Report of the last constraint solve.
    pub last: DirectReport,
}

impl<T: Real> DirectRod<T> {
    /// Builds the rod from a polyline and spec, with end conditions and point loads.
    pub fn new(
        points: &[[f64; 3]],
        spec: &RodSpec,
        ends: [EndCondition<f64>; 2],
        loads: &[(usize, [f64; 3])],
    ) -> Self {
        let (state, mut params) = build_rod::<T>(points, spec).expect("valid rod");
        let n = state.elements();
        if ends[0].holds_point() {
            params.inv_masses[0] = T::zero();
        }
        if ends[1].holds_point() {
            params.inv_masses[n] = T::zero();
        }
        let v = |a: [f64; 3]| Vec3::new(T::lit(a[0]), T::lit(a[1]), T::lit(a[2]));
        Self {
            state,
            params,
            ends,
            loads: loads.iter().map(|&(i, f)| (i, v(f))).collect(),
            forces: vec![Vec3::zeros(); n + 1],
            torques: vec![Vec3::zeros(); n],
            scratch: DirectScratch::new(n),
            settings: DirectSettings::default(),
            max_strain: 0.0,
            last: DirectReport::default(),
        }
    }

    /// Advances one step of `h` at time `time` (semi-implicit Euler, as the CPU backend).
    /// Returns `false` if the state stopped being finite.
    pub fn step(&mut self, h: T, gravity: Vec3<T>, time: f64) -> bool {
        let n = self.state.elements();
        let model = ForceModel {
            extensible: false,
            gravity,
        };
        accumulate_forces(
            &self.state,
            &self.params,
            &model,
            &mut self.forces,
            &mut self.torques,
        );
        for (i, f) in &self.loads {
            self.forces[*i] += *f;
        }
        let s = &mut self.state;
        for ((v, f), &w) in s
            .velocities
            .iter_mut()
            .zip(&self.forces)
            .zip(&self.params.inv_masses)
        {
            *v += f * (h * w);
        }
        for ((om, tq), inertia) in s
            .angular_velocities
            .iter_mut()
            .zip(&self.torques)
            .zip(&self.params.inertias)
        {
            let gyro = om.cross(&inertia.component_mul(om));
            *om += (tq - gyro).component_div(inertia) * h;
        }
        for (end, (point, frame)) in self.ends.iter().zip([(0, 0), (n, n - 1)]) {
            if end.holds_point() {
                let (v, w) = end.velocities_at(time);
                s.velocities[point] = Vec3::new(T::lit(v.x), T::lit(v.y), T::lit(v.z));
                if end.holds_frame() {
                    s.angular_velocities[frame] = rotate_inv(
                        &s.frames[frame],
                        &Vec3::new(T::lit(w.x), T::lit(w.y), T::lit(w.z)),
                    );
                }
            }
        }
        self.last = solve_distance_direct(
            &s.positions,
            &mut s.velocities,
            &self.params.inv_masses,
            &self.params.rest_lengths,
            h,
            &self.settings,
            &mut self.scratch,
        );
        let half_h = h * T::lit(0.5);
        for (q, w) in s.frames.iter_mut().zip(&s.angular_velocities) {
            let next = *q + *q * Quat::from_parts(T::zero(), w * half_h);
            *q = next / next.norm();
        }
        for (p, v) in s.positions.iter_mut().zip(&s.velocities) {
            *p += v * h;
        }
        let mut worst = 0.0_f64;
        for j in 0..n {
            let r = ((s.positions[j + 1] - s.positions[j]).norm() / self.params.rest_lengths[j])
                .to_f64();
            if !r.is_finite() {
                return false;
            }
            worst = worst.max((r - 1.0).abs());
        }
        self.max_strain = self.max_strain.max(worst);
        true
    }

    /// Energies of the rod.
    pub fn energies(&self, gravity: Vec3<T>) -> Energies {
        energies(
            &self.state,
            &self.params,
            &ForceModel {
                extensible: false,
                gravity,
            },
        )
    }

    /// Positions in f64.
    pub fn positions(&self) -> Vec<[f64; 3]> {
        self.state
            .positions
            .iter()
            .map(|p| [p.x.to_f64(), p.y.to_f64(), p.z.to_f64()])
            .collect()
    }
}
