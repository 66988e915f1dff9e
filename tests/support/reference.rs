//! Independent references: closed-form beam theory and f64 ODE solutions (shooting methods).
//!
//! Nothing here uses the simulator. The rods of the simulator are shearable (the parallel
//! penalty `K_p = G A` is a Timoshenko shear energy with shear coefficient 1) and carry rotary
//! inertia, so each reference is given for a shearable rod with a parameter `K_p`; as
//! `K_p → ∞` (and `ρI → 0`) they reduce to the Euler–Bernoulli formulas quoted in the brief
//! (`w L⁴/(8EI)`, `F L³/(3EI)`, the elastica `θ'' = −α cos θ`, `π² EI/(4L²)`,
//! `(β_n L)² √(EI/(ρ A L⁴))`), which are also provided.

#![allow(dead_code)]

/// Tip deflection of a clamped–free beam under a uniform load `w` [N/m]:
/// Euler–Bernoulli `w L⁴/(8 EI)` plus the shear term `w L²/(2 K_p)`.
pub fn cantilever_uniform_tip(w: f64, l: f64, ei: f64, kp: f64) -> f64 {
    w * l.powi(4) / (8.0 * ei) + w * l * l / (2.0 * kp)
}

/// Deflection at `x` of a clamped–free beam under a tip load `f` [N]:
/// `F x² (3L − x)/(6 EI) + F x / K_p`.
pub fn cantilever_point_load(f: f64, l: f64, ei: f64, kp: f64, x: f64) -> f64 {
    f * x * x * (3.0 * l - x) / (6.0 * ei) + f * x / kp
}

/// Critical load of a clamped–free column: Euler's `P_E = π² EI/(4L²)` reduced by shear
/// (Engesser): `P_E / (1 + P_E/K_p)`.
pub fn column_critical_load(l: f64, ei: f64, kp: f64) -> f64 {
    let pe = std::f64::consts::PI.powi(2) * ei / (4.0 * l * l);
    pe / (1.0 + pe / kp)
}

/// Euler–Bernoulli bending frequencies of a clamped–free beam [rad/s].
pub fn euler_bernoulli_frequencies(l: f64, ei: f64, rho_a: f64) -> [f64; 3] {
    [1.875_104_07, 4.694_091_13, 7.854_757_44]
        .map(|bl: f64| bl * bl * (ei / (rho_a * l.powi(4))).sqrt())
}

/// Classic RK4 step for a system of dimension `D`.
fn rk4<const D: usize>(
    f: &impl Fn(f64, &[f64; D]) -> [f64; D],
    t: f64,
    y: &[f64; D],
    h: f64,
) -> [f64; D] {
    let add =
        |a: &[f64; D], b: &[f64; D], s: f64| std::array::from_fn::<f64, D, _>(|i| a[i] + s * b[i]);
    let k1 = f(t, y);
    let k2 = f(t + 0.5 * h, &add(y, &k1, 0.5 * h));
    let k3 = f(t + 0.5 * h, &add(y, &k2, 0.5 * h));
    let k4 = f(t + h, &add(y, &k3, h));
    std::array::from_fn(|i| y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

fn integrate<const D: usize>(
    f: &impl Fn(f64, &[f64; D]) -> [f64; D],
    y0: [f64; D],
    length: f64,
    steps: usize,
) -> [f64; D] {
    let h = length / steps as f64;
    let mut y = y0;
    for k in 0..steps {
        y = rk4(f, k as f64 * h, &y, h);
    }
    y
}

/// Bisection for a sign change of `g` in `[a, b]` down to `|b − a| <= tol`.
fn bisect(g: impl Fn(f64) -> f64, mut a: f64, mut b: f64, tol: f64) -> f64 {
    let mut ga = g(a);
    while (b - a).abs() > tol {
        let m = 0.5 * (a + b);
        let gm = g(m);
        if gm == 0.0 {
            return m;
        }
        if (gm > 0.0) == (ga > 0.0) {
            a = m;
            ga = gm;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

/// Tip position `(x/L, y/L)` (`y` along the load) of a cantilever under a dead tip load with
/// `α = F L²/EI`, clamped horizontally.
///
/// Shearable elastica (Reissner): with the frame angle `φ` and the tangent angle `ψ`, moment
/// balance is `φ'' = −α cos ψ` and the shear force balance `sin(ψ − φ) = α σ cos ψ`, where
/// `σ = EI/(K_p L²)`; `σ = 0` is the classical elastica `θ'' = −α cos θ`. Boundary conditions
/// `φ(0) = 0`, `φ'(1) = 0`; solved by shooting on `φ'(0)` (bisection) with RK4 on `steps` steps.
pub fn elastica_tip(alpha: f64, sigma: f64, steps: usize) -> (f64, f64) {
    let (x, y, _) = elastica_end(alpha, sigma, steps);
    (x, y)
}

/// [`elastica_tip`] and the tip's tangent angle `ψ(1)` [rad] below the horizontal.
pub fn elastica_end(alpha: f64, sigma: f64, steps: usize) -> (f64, f64, f64) {
    let tangent = |phi: f64| {
        // Newton on g(ψ) = sin(ψ − φ) − ασ cos ψ from ψ = φ (σ small: 2–3 iterations).
        let mut psi = phi;
        for _ in 0..50 {
            let g = (psi - phi).sin() - alpha * sigma * psi.cos();
            let dg = (psi - phi).cos() + alpha * sigma * psi.sin();
            let d = g / dg;
            psi -= d;
            if d.abs() < 1e-16 {
                break;
            }
        }
        psi
    };
    let rhs = |_: f64, y: &[f64; 4]| {
        let psi = tangent(y[0]);
        [y[1], -alpha * psi.cos(), psi.cos(), psi.sin()]
    };
    let end = |k: f64| integrate(&rhs, [0.0, k, 0.0, 0.0], 1.0, steps);
    // φ'(1) is −α∫cos ψ < 0 at k = 0 and grows with k; bracket, then bisect to round-off.
    let mut hi = alpha.max(1.0);
    while end(hi)[1] < 0.0 {
        hi *= 2.0;
    }
    let k = bisect(|k| end(k)[1], 0.0, hi, 1e-15 * hi);
    let y = end(k);
    (y[2], y[3], tangent(y[0]))
}

/// The first three bending frequencies [rad/s] of a clamped–free Timoshenko beam (shear
/// stiffness `K_p`, rotary inertia `ρ I`), from the roots of the shooting determinant.
///
/// `EI ψ'' + K_p (w' − ψ) + ρI ω² ψ = 0`, `K_p (w'' − ψ') + ρA ω² w = 0`; clamped at 0
/// (`w = ψ = 0`), free at `L` (`ψ' = 0`, `w' − ψ = 0`).
pub fn timoshenko_frequencies(l: f64, ei: f64, kp: f64, rho_a: f64, rho_i: f64) -> [f64; 3] {
    timoshenko_frequencies_with(l, ei, kp, rho_a, rho_i, 4000)
}

/// [`timoshenko_frequencies`] with `steps` RK4 steps over the length.
///
/// The shear terms add a boundary-layer solution growing like `exp(√(K_p/EI) s)`; both
/// shooting solutions are re-orthonormalised every twentieth of the length (Gram–Schmidt with
/// positive diagonal), which rescales the boundary determinant by a positive factor and so keeps
/// its roots while avoiding the cancellation of the growing mode.
pub fn timoshenko_frequencies_with(
    l: f64,
    ei: f64,
    kp: f64,
    rho_a: f64,
    rho_i: f64,
    steps: usize,
) -> [f64; 3] {
    let det = |omega: f64| {
        let w2 = omega * omega;
        let rhs = |_: f64, y: &[f64; 4]| {
            // y = (w, w', ψ, ψ')
            let (w, dw, psi, dpsi) = (y[0], y[1], y[2], y[3]);
            [
                dw,
                dpsi - rho_a * w2 * w / kp,
                dpsi,
                (-kp * (dw - psi) - rho_i * w2 * psi) / ei,
            ]
        };
        let (mut a, mut b) = ([0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0 / l]);
        let segments = 20;
        for _ in 0..segments {
            a = integrate(&rhs, a, l / segments as f64, steps / segments);
            b = integrate(&rhs, b, l / segments as f64, steps / segments);
            let na = a.iter().map(|x| x * x).sum::<f64>().sqrt();
            a = a.map(|x| x / na);
            let d: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            b = std::array::from_fn(|i| b[i] - d * a[i]);
            let nb = b.iter().map(|x| x * x).sum::<f64>().sqrt();
            b = b.map(|x| x / nb);
        }
        a[3] * (b[1] - b[2]) - b[3] * (a[1] - a[2])
    };
    let eb = euler_bernoulli_frequencies(l, ei, rho_a);
    let mut roots = Vec::new();
    let (lo, hi) = (0.3 * eb[0], 1.2 * eb[2]);
    let scan = 400;
    let mut prev = (lo, det(lo));
    for k in 1..=scan {
        let w = lo + (hi - lo) * k as f64 / scan as f64;
        let d = det(w);
        if (d > 0.0) != (prev.1 > 0.0) {
            roots.push(bisect(det, prev.0, w, 1e-13 * w));
            if roots.len() == 3 {
                break;
            }
        }
        prev = (w, d);
    }
    assert_eq!(
        roots.len(),
        3,
        "expected three roots below 1.2 ω₃(EB), found {roots:?}"
    );
    [roots[0], roots[1], roots[2]]
}

/// Checks of the reference solvers themselves (run by `tests/validation.rs` and by
/// `cargo xtask validate`): limits with known closed forms, and convergence of the ODE solves.
pub fn self_check() {
    checks::elastica_reaches_small_deflection_limit_and_converges();
    checks::timoshenko_reduces_to_euler_bernoulli();
}

mod checks {
    use super::*;

    pub(super) fn elastica_reaches_small_deflection_limit_and_converges() {
        // Small α: y_tip = α/3 (linear theory).
        let (_, y) = elastica_tip(1e-4, 0.0, 2000);
        assert!((y / (1e-4 / 3.0) - 1.0).abs() < 1e-7);
        // Small α: the end shortens by ½∫θ² with θ = α(s − s²/2), i.e. 1 − x_tip = α²/15.
        let (x, _) = elastica_tip(1e-2, 0.0, 2000);
        assert!(
            ((1.0 - x) / (1e-4 / 15.0) - 1.0).abs() < 1e-3,
            "1 - x = {}",
            1.0 - x
        );
        // RK4 on 2000 steps is converged to 1e-10 even at α = 10.
        let (a, b) = (
            elastica_tip(10.0, 1e-3, 2000),
            elastica_tip(10.0, 1e-3, 4000),
        );
        assert!((a.0 - b.0).abs() < 1e-10 && (a.1 - b.1).abs() < 1e-10);
    }

    pub(super) fn timoshenko_reduces_to_euler_bernoulli() {
        // Shear stiffness 1e6 EI/L², no rotary inertia: the shear correction is
        // ~ (β L)² EI/(K_p L²) / 2 ≤ 3.1e-5 for the third mode.
        let (l, ei, rho_a) = (1.0, 2.0, 3.0);
        let t = timoshenko_frequencies_with(l, ei, 1e6 * ei, rho_a, 0.0, 4000);
        let e = euler_bernoulli_frequencies(l, ei, rho_a);
        for k in 0..3 {
            let bl2 = e[k] / (ei / (rho_a * l.powi(4))).sqrt();
            assert!((t[k] / e[k] - 1.0).abs() < bl2 * 1e-6, "{t:?} vs {e:?}");
        }
        // The solution is converged in the number of RK4 steps for the thick test rod
        // (√(K_p/EI) L = 58).
        let (ei, kp, rho_i) = (
            1e6 * std::f64::consts::PI * 0.02f64.powi(4) / 4.0,
            1e6 / 3.0 * std::f64::consts::PI * 4e-4,
            1000.0 * std::f64::consts::PI * 0.02f64.powi(4) / 4.0,
        );
        let (a, b) = (
            timoshenko_frequencies_with(
                1.0,
                ei,
                kp,
                1000.0 * std::f64::consts::PI * 4e-4,
                rho_i,
                4000,
            ),
            timoshenko_frequencies_with(
                1.0,
                ei,
                kp,
                1000.0 * std::f64::consts::PI * 4e-4,
                rho_i,
                8000,
            ),
        );
        for k in 0..3 {
            assert!((a[k] / b[k] - 1.0).abs() < 1e-10, "{a:?} vs {b:?}");
        }
    }
}
