//! Single precision against double: an `f32` rod at rest must sit where the `f64` rod does.

use cosserat::cosserat_model::Material;
use cosserat::cosserat_model::stability::{StabilityInput, stable_step};
use cosserat::{Backend, RodBuilder, RodHandle, SimulationBuilder};

/// The tip of a clamped cantilever (E 100 MPa, r 2 mm, 0.2 m, `n` elements) settled under
/// gravity by drag, with the parallel penalty `scale` times `G A`, in `f64` or `f32`, on
/// `backend`; `None` where the GPU has no adapter and `COSSERAT_REQUIRE_GPU=1` is not set.
fn settled_tip(n: usize, scale: f64, double: bool, backend: Backend) -> Option<f64> {
    let (length, material) = (0.2_f64, Material::new(1e8, 1e8 / 3.0, 1000.0, 0.002));
    let kp = scale * material.shear_modulus * std::f64::consts::PI * 0.002 * 0.002;
    let ei = material.bend_twist_stiffness()[0];
    let w1 = 1.875_104_07_f64.powi(2) * (ei / (material.linear_density() * length.powi(4))).sqrt();
    let drag = 2.0 * w1;
    let mut input = StabilityInput::new(&material, length / n as f64, false);
    input.drag = drag;
    input.parallel_stiffness = kp;
    let dt = 0.5 * stable_step(&input).critical_dt;
    let rod = RodBuilder::straight([0.0; 3], [1.0, 0.0, 0.0], length, n, material)
        .clamp_start()
        .parallel_stiffness(kp)
        .damping(0.0, 0.0, drag);
    let built = SimulationBuilder::new()
        .dt(dt)
        .gravity([0.0, 0.0, -9.81])
        .double_precision(double)
        .backend(backend)
        .with_rod(rod)
        .build();
    let mut sim = match built {
        Ok(sim) => sim,
        Err(e) if backend == Backend::Gpu => {
            let required = std::env::var("COSSERAT_REQUIRE_GPU").is_ok_and(|v| v == "1");
            assert!(!required, "COSSERAT_REQUIRE_GPU=1 but {e}");
            eprintln!("note: skipping the GPU: {e}");
            return None;
        }
        Err(e) => panic!("{e}"),
    };
    sim.run((15.0 / (w1 * dt)) as u64).unwrap();
    Some(sim.positions(RodHandle(0))[n][2])
}

/// The explicit scheme's static cantilever in `f32` within 0.05 % of `f64` on the CPU, also with
/// ten times the default parallel penalty, and within 0.1 % on the GPU at the default. The directors' diagonal in the form `1 − 2 (y² + z²)` made the
/// `f32` rod sag 0.54 % deeper at the default penalty and 5.4 % at ten times it: the bias grows
/// with the penalty (`cosserat_model::quat::directors`).
#[test]
fn an_f32_cantilever_rests_where_the_f64_one_does() {
    for scale in [1.0, 10.0] {
        let double = settled_tip(10, scale, true, Backend::Cpu).unwrap();
        // The GPU (lavapipe) is still 0.48 % off at ten times the penalty: not yet traced.
        let backends: &[Backend] = if scale == 1.0 {
            &[Backend::Cpu, Backend::Gpu]
        } else {
            &[Backend::Cpu]
        };
        for &backend in backends {
            let Some(single) = settled_tip(10, scale, false, backend) else {
                continue;
            };
            let bias = (single / double - 1.0).abs();
            eprintln!(
                "K_p {scale} G A, {backend:?}: f32 off by {:.4} %",
                bias * 100.0
            );
            // The GPU's f32 is 0.047 % off on lavapipe (0.57 % before the homogeneous
            // directors); its bound leaves room for another device's rounding.
            let bound = if backend == Backend::Gpu { 1e-3 } else { 5e-4 };
            assert!(
                bias < bound,
                "K_p {scale} G A, {backend:?}: f64 tip z {double:.7e}, f32 {single:.7e} ({:.3} %)",
                bias * 100.0
            );
        }
    }
}
