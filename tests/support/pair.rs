//! One scene built for the CPU and for the GPU, for the tests that take the CPU as the GPU's
//! oracle (`tests/gpu_contact.rs`, `tests/stiff_gpu.rs`). Without a GPU adapter they are skipped,
//! unless `COSSERAT_REQUIRE_GPU=1` (CI, on lavapipe) makes that a failure.

use cosserat::scene::parse_scene;
use cosserat::sim::{Backend, Simulation};
use std::path::Path;

fn gpu_required() -> bool {
    std::env::var("COSSERAT_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

fn build(text: &str, overrides: &[(&str, &str)], backend: Backend) -> Result<Simulation, String> {
    let overrides: Vec<(String, String)> = overrides
        .iter()
        .map(|(k, v)| ((*k).into(), (*v).into()))
        .collect();
    let (b, _, _) =
        parse_scene(Path::new("scene.toml"), text, &overrides).unwrap_or_else(|e| panic!("{e}"));
    b.backend(backend).build().map_err(|e| e.to_string())
}

/// The scene `text` (with `overrides`) built for the GPU, or the build's error; `None` when no
/// GPU adapter is available and none is required.
pub(crate) fn gpu_build(
    text: &str,
    overrides: &[(&str, &str)],
) -> Option<Result<Simulation, String>> {
    match build(text, overrides, Backend::Gpu) {
        Err(e) if !cfg!(feature = "gpu") || e.contains("adapter") => {
            assert!(!gpu_required(), "COSSERAT_REQUIRE_GPU=1 but {e}");
            eprintln!("note: skipping a GPU test: {e}");
            None
        }
        built => Some(built),
    }
}

/// The scene `text` (with `overrides`) built for the CPU and for the GPU; `None` when no GPU
/// adapter is available and none is required.
pub(crate) fn pair(text: &str, overrides: &[(&str, &str)]) -> Option<(Simulation, Simulation)> {
    let cpu = build(text, overrides, Backend::Cpu).unwrap_or_else(|e| panic!("cpu: {e}"));
    let gpu = gpu_build(text, overrides)?.unwrap_or_else(|e| panic!("gpu: {e}"));
    Some((cpu, gpu))
}

/// The largest distance between corresponding points of `a` and `b`.
pub(crate) fn largest_gap(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}
