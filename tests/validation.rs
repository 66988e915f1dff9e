//! Accuracy as a tested property: every validation case at CI size (two resolutions, short
//! runs). `cargo xtask validate` runs the same cases at full size and writes
//! `docs/validation.md`.
//!
//! Each test fails if its measured quantity is further from the independent reference than the
//! tolerance derived from the discretisation (see `support/cases.rs` for how).

#[allow(unreachable_pub)]
mod support;

use support::cases::{self, Row, Size};

fn check(name: &str, rows: Result<Vec<Row>, String>) {
    let rows = rows.unwrap_or_else(|e| panic!("{name}: {e}"));
    assert!(!rows.is_empty(), "{name}: no rows");
    let mut failed = Vec::new();
    for r in &rows {
        eprintln!(
            "{:<32} {:<52} measured {:>14.6e} reference {:>14.6e} error {:>9.2e} tol {:>9.2e} {}",
            r.case,
            r.quantity,
            r.measured,
            r.reference,
            r.error(),
            r.tolerance,
            if r.passed() { "ok" } else { "FAIL" }
        );
        if !r.passed() {
            failed.push(format!(
                "{} / {}: error {:.3e} > tolerance {:.3e} ({})",
                r.case,
                r.quantity,
                r.error(),
                r.tolerance,
                r.note
            ));
        }
    }
    assert!(failed.is_empty(), "{name}:\n{}", failed.join("\n"));
}

#[test]
fn cantilever_small_deflection() {
    check("cantilever small", cases::cantilever_small(Size::Ci));
}

#[test]
fn cantilever_large_deflection_elastica() {
    check("cantilever large", cases::cantilever_large(Size::Ci));
}

#[test]
fn euler_buckling() {
    check("buckling", cases::buckling(Size::Ci));
}

#[test]
fn pure_torsion() {
    check("torsion", cases::torsion(Size::Ci));
}

#[test]
fn intrinsic_curvature_arc() {
    check("arc", cases::intrinsic_arc(Size::Ci));
}

#[test]
fn intrinsic_curvature_and_twist_helix() {
    check("helix", cases::intrinsic_helix(Size::Ci));
}

#[test]
fn bending_frequencies() {
    check("frequencies", cases::frequencies(Size::Ci));
}

#[test]
fn pendulum_energy_convergence_and_inextensibility() {
    check("pendulum", cases::pendulum_cases(Size::Ci));
}

#[test]
fn stiff_scheme_statics_and_frequencies() {
    check("stiff scheme", cases::stiff_scheme(Size::Ci));
}

#[test]
fn references_are_self_consistent() {
    support::reference::self_check();
}

#[test]
fn coulomb_friction_on_an_incline_in_both_schemes() {
    check("incline friction", cases::incline_friction(Size::Ci));
}
