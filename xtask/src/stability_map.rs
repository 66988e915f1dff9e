//! The measured stable-dt map: the largest stable step found by bisection on short runs, over
//! Young's modulus, radius and element length, next to the estimate of
//! `cosserat_model::stability`; plus random rods (intrinsic shapes, damping, driven ends,
//! extensible mode, f32) that measure the safety factor. Writes `docs/stability.md`.

use crate::support::cases::{Check, Row, workspace_file};
use crate::support::stability::TrialRod;
use cosserat::cosserat_model::Material;
use cosserat::cosserat_model::stability::SAFETY;
use std::fmt::Write as _;

/// Steps per trial run and bisection resolution (relative bracket width 2^-BITS).
const STEPS: u64 = 1000;
const BITS: u32 = 6;

struct Sample {
    label: String,
    estimate: f64,
    mode: String,
    measured: f64,
}

impl Sample {
    fn ratio(&self) -> f64 {
        self.measured / self.estimate
    }
}

fn measure(label: String, rod: &TrialRod) -> Result<Sample, String> {
    let est = rod.estimate();
    let measured = rod
        .bisect_stable_dt(STEPS, BITS)
        .map_err(|e| format!("{label}: {e}"))?;
    Ok(Sample {
        label,
        estimate: est.critical_dt,
        mode: format!("{:?}", est.mode),
        measured,
    })
}

/// A small deterministic generator (SplitMix64) for the random rods.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next()
    }
    fn log_range(&mut self, a: f64, b: f64) -> f64 {
        (a.ln() + (b.ln() - a.ln()) * self.next()).exp()
    }
}

fn grid() -> Result<Vec<Sample>, String> {
    let mut out = Vec::new();
    for &e in &[1e3, 1e6, 1e9, 2e11] {
        for &r in &[5e-5, 5e-4, 5e-3, 1e-2] {
            for &l in &[1e-4, 1e-3, 1e-2, 1e-1] {
                let m = Material::new(e, e / 2.6, 1000.0, r);
                let rod = TrialRod::straight(m, 10, l);
                out.push(measure(
                    format!("E {e:.0e} | r {:.2} mm | l {:.1} mm", r * 1e3, l * 1e3),
                    &rod,
                )?);
            }
        }
    }
    Ok(out)
}

fn random_rods(count: usize) -> Result<Vec<Sample>, String> {
    let mut rng = Rng(2024);
    let mut out = Vec::new();
    for k in 0..count {
        let e = rng.log_range(1e3, 2e11);
        let rho = rng.range(500.0, 8000.0);
        let nu = rng.range(0.0, 0.5);
        let r = rng.log_range(5e-5, 1e-2);
        let n = 2 + (rng.next() * 30.0) as usize;
        let l = rng.log_range(1e-4, 1e-1);
        let length = n as f64 * l;
        let mut rod = TrialRod::straight(Material::new(e, e / (2.0 * (1.0 + nu)), rho, r), n, l);
        let turns = 2.0 * std::f64::consts::PI / length;
        rod.set_buildable_darboux([
            rng.range(-2.0, 2.0) * turns,
            rng.range(-2.0, 2.0) * turns,
            rng.range(-2.0, 2.0) * turns,
        ]);
        rod.extensible = rng.next() < 0.3;
        rod.double = rng.next() < 0.7;
        rod.seed = k as u64 + 7;
        let i = std::f64::consts::PI * r.powi(4) / 4.0;
        // Damping up to a few times what critically damps the first bending mode.
        let w1 = 3.5 * (e * i / (rho * std::f64::consts::PI * r * r)).sqrt() / (length * length);
        rod.damping = [
            rng.range(0.0, 1.0) * rho * i * length * w1,
            0.0,
            rng.range(0.0, 4.0) * w1,
        ];
        if rng.next() < 0.5 {
            let c = (e / rho).sqrt();
            rod.driven_start = Some((
                [rng.range(-1e-3, 1e-3) * c, rng.range(-1e-3, 1e-3) * c, 0.0],
                [rng.range(-1.0, 1.0) * w1, 0.0, rng.range(-1.0, 1.0) * w1],
            ));
        }
        let label = format!(
            "#{k}: E {e:.1e}, ρ {rho:.0}, ν {nu:.2}, r {:.3} mm, l {:.2} mm, N {n}, κ ({:.0}, {:.0}, {:.0}) 1/m, {}{}{}",
            r * 1e3,
            l * 1e3,
            rod.darboux[0],
            rod.darboux[1],
            rod.darboux[2],
            if rod.extensible {
                "extensible"
            } else {
                "inextensible"
            },
            if rod.double { ", f64" } else { ", f32" },
            if rod.driven_start.is_some() {
                ", driven clamp"
            } else {
                ""
            }
        );
        out.push(measure(label, &rod)?);
    }
    Ok(out)
}

/// Rods whose frames spin about their axes at `Ω = s / h_c` (straight, undamped, free): the
/// gyroscopic coupling of the frames' bending rotations that the linearisation about a resting
/// rod leaves out.
fn spinning_rods() -> Result<Vec<Sample>, String> {
    let mut out = Vec::new();
    for &(e, r, l) in &[
        (2.4e4, 7.2e-3, 3.1e-2),
        (1e9, 5e-4, 1e-2),
        (2e11, 2e-4, 1e-3),
    ] {
        for &s in &[0.01, 0.05, 0.2, 0.5] {
            let mut rod = TrialRod::straight(Material::new(e, e / 2.6, 7000.0, r), 12, l);
            rod.spin = s / rod.estimate().critical_dt;
            out.push(measure(
                format!(
                    "E {e:.1e} | r {:.2} mm | l {:.1} mm | Ω h_c = {s}",
                    r * 1e3,
                    l * 1e3
                ),
                &rod,
            )?);
        }
    }
    Ok(out)
}

/// Runs the map, writes `docs/stability.md`, returns the validation rows.
pub(crate) fn rows() -> Result<Vec<Row>, String> {
    let grid = grid()?;
    let random = random_rods(40)?;
    let spinning = spinning_rods()?;
    let min_of = |s: &[Sample]| s.iter().map(Sample::ratio).fold(f64::INFINITY, f64::min);
    let max_of = |s: &[Sample]| s.iter().map(Sample::ratio).fold(0.0, f64::max);
    let (gmin, gmax, rmin, rmax) = (
        min_of(&grid),
        max_of(&grid),
        min_of(&random),
        max_of(&random),
    );
    let (smin, smax) = (min_of(&spinning), max_of(&spinning));
    write_doc(&grid, &random, &spinning)?;
    Ok(vec![
        Row {
            case: "stable-dt map (64 straight rods)".into(),
            quantity: format!("SAFETY / min(h_measured / h_c); ratios {gmin:.3}…{gmax:.3}"),
            measured: SAFETY / gmin,
            reference: 0.0,
            tolerance: 1.0,
            check: Check::Bound,
            note: format!("E 1e3…2e11 Pa, r 0.05…10 mm, l 0.1…100 mm, N 10; bisection to 2^-{BITS}, {STEPS} steps per trial; SAFETY = {SAFETY}"),
        },
        Row {
            case: "stable-dt, 40 random rods".into(),
            quantity: format!("SAFETY / min(h_measured / h_c); ratios {rmin:.3}…{rmax:.3}"),
            measured: SAFETY / rmin,
            reference: 0.0,
            tolerance: 1.0,
            check: Check::Bound,
            note: "random intrinsic curvature/twist (up to 2 turns per length, capped at a radius of curvature of 2 r), damping, driven clamps, extensible, f32".into(),
        },
        Row {
            case: format!("stable-dt, {} spinning rods", spinning.len()),
            quantity: format!("SAFETY / min(h_measured / h_c); ratios {smin:.3}…{smax:.3}"),
            measured: SAFETY / smin,
            reference: 0.0,
            tolerance: 1.0,
            check: Check::Bound,
            note: "frames spinning about their axes at Ω h_c = 0.01…0.5 (gyroscopic coupling)".into(),
        },
    ])
}

fn write_doc(grid: &[Sample], random: &[Sample], spinning: &[Sample]) -> Result<(), String> {
    let mut s = String::new();
    s.push_str(include_str!("../data/stability-intro.md"));
    let _ = writeln!(
        s,
        "\n## Measured map (straight rods, f64, inextensible, undamped, N = 10, ρ = 1000 kg/m³, ν = 0.3)\n"
    );
    let _ = writeln!(
        s,
        "`h_c` is the estimate's critical step (`stable_step(..).critical_dt`), `h_meas` the largest step that stayed bounded for {STEPS} steps (bisection to a relative bracket of 2^-{BITS}).\n"
    );
    s.push_str("| E [Pa] | r [mm] | l [mm] | limiting block | h_c estimate [s] | h_meas [s] | h_meas / h_c |\n|---|---|---|---|---|---|---|\n");
    for g in grid {
        let parts: Vec<&str> = g.label.split(" | ").collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.3e} | {:.3e} | {:.3} |",
            parts[0].trim_start_matches("E "),
            parts[1].trim_start_matches("r ").trim_end_matches(" mm"),
            parts[2].trim_start_matches("l ").trim_end_matches(" mm"),
            g.mode,
            g.estimate,
            g.measured,
            g.ratio()
        );
    }
    for (title, rods) in [
        (
            "Random rods (intrinsic shapes, damping, driven ends, extensible, f32)",
            random,
        ),
        (
            "Spinning rods (straight, undamped, free, N = 12, ρ = 7000 kg/m³; every frame spinning about its axis at Ω)",
            spinning,
        ),
    ] {
        let _ = writeln!(
            s,
            "\n## {title}\n\n| rod | h_c [s] | h_meas [s] | h_meas / h_c |\n|---|---|---|---|"
        );
        for r in rods {
            let _ = writeln!(
                s,
                "| {} | {:.3e} | {:.3e} | {:.3} |",
                r.label,
                r.estimate,
                r.measured,
                r.ratio()
            );
        }
    }
    let every: Vec<&Sample> = grid.iter().chain(random).chain(spinning).collect();
    let all = every
        .iter()
        .map(|r| r.ratio())
        .fold(f64::INFINITY, f64::min);
    // The estimate is tight when it is 0.8–1.0 of the measured limit, up to the bisection's
    // resolution.
    let resolution = 1.0 + 0.5f64.powi(BITS as i32);
    let tight = every
        .iter()
        .filter(|r| (1.0 / resolution..=1.25).contains(&r.ratio()))
        .count();
    let loose: Vec<String> = every
        .iter()
        .filter(|r| r.ratio() > 1.25)
        .map(|r| {
            format!(
                "{} ({:.3})",
                r.label.split(':').next().unwrap_or(&r.label),
                r.ratio()
            )
        })
        .collect();
    let _ = writeln!(
        s,
        "\nSmallest measured ratio over all {} rods: **{all:.3}**; `SAFETY` = {SAFETY}. The estimate is within 0.8–1.0 of the measured limit (to the bisection's resolution) for {tight} of the {} rods; it is more cautious than that for {}.",
        every.len(),
        every.len(),
        if loose.is_empty() {
            "none".to_string()
        } else {
            loose.join(", ")
        }
    );
    let path = workspace_file("docs/stability.md");
    std::fs::write(&path, s).map_err(|e| format!("{}: {e}", path.display()))
}
