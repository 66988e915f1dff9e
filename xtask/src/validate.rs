//! `cargo xtask validate`: every validation case at full size, the long runs and the stable-dt
//! map; a table on stdout and `docs/validation.md`.

use crate::stability_map;
use crate::support::cases::{self, Check, Row, Size};
use std::fmt::Write as _;
use std::time::Instant;

type Case = (&'static str, fn() -> Result<Vec<Row>, String>);

fn case_list() -> Vec<Case> {
    vec![
        ("cantilever small deflection", || {
            cases::cantilever_small(Size::Full)
        }),
        ("cantilever large deflection", || {
            cases::cantilever_large(Size::Full)
        }),
        ("buckling", || cases::buckling(Size::Full)),
        ("torsion", || cases::torsion(Size::Full)),
        ("intrinsic arc", || cases::intrinsic_arc(Size::Full)),
        ("intrinsic helix", || cases::intrinsic_helix(Size::Full)),
        ("frequencies", || cases::frequencies(Size::Full)),
        ("pendulum", || cases::pendulum_cases(Size::Full)),
        ("stiff scheme", || cases::stiff_scheme(Size::Full)),
        ("stiff scheme at 1e-3 s", || {
            cases::stiff_scheme_at(Size::Full, 1e-3)
        }),
        ("stiff scheme at 1e-4 s", || {
            cases::stiff_scheme_at(Size::Full, 1e-4)
        }),
        ("incline friction", || cases::incline_friction(Size::Full)),
        ("binding", || cases::binding_composite(Size::Full)),
        ("long runs", cases::long_runs),
        ("stability map", stability_map::rows),
    ]
}

fn fmt_num(x: f64) -> String {
    if x.is_nan() {
        "—".into()
    } else {
        format!("{x:.6e}")
    }
}

/// The table as Markdown.
pub(crate) fn table(rows: &[Row]) -> String {
    let mut s = String::from(
        "| case | quantity | measured | reference | rel. error | tolerance | result |\n|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let (err, reference) = match r.check {
            Check::Relative => (format!("{:.2e}", r.error()), fmt_num(r.reference)),
            Check::Bound => ("(bound)".into(), fmt_num(r.reference)),
            Check::AtLeast => ("(at least)".into(), fmt_num(r.reference)),
            // A reported quantity with a reference shows its error.
            Check::Info if r.reference.is_finite() && r.reference != 0.0 => {
                (format!("{:.2e}", r.error()), fmt_num(r.reference))
            }
            Check::Info => ("—".into(), "—".into()),
        };
        let tol = if r.tolerance.is_nan() {
            "—".into()
        } else {
            format!("{:.2e}", r.tolerance)
        };
        let result = match (r.check, r.passed()) {
            (Check::Info, _) => "info",
            (_, true) => "pass",
            (_, false) => "**FAIL**",
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} |",
            r.case,
            r.quantity,
            fmt_num(r.measured),
            reference,
            err,
            tol,
            result
        );
    }
    s
}

pub(crate) fn run(only: Option<&str>, contact_rows: Option<bool>) -> Result<bool, String> {
    crate::support::reference::self_check();
    if let Some(rows) = contact_rows {
        cases::set_contact_rows(rows)?;
    }
    let mut rows = Vec::new();
    let mut errors = Vec::new();
    let mut timings = Vec::new();
    for (name, f) in case_list() {
        if only.is_some_and(|o| !name.contains(o)) {
            continue;
        }
        let t = Instant::now();
        eprintln!("running {name} ...");
        match f() {
            Ok(r) => {
                for row in &r {
                    eprintln!(
                        "  {:<30} {:<58} {:>14} ref {:>14} err {:>9} tol {:>9} {}",
                        row.case,
                        row.quantity,
                        fmt_num(row.measured),
                        fmt_num(row.reference),
                        format!("{:.2e}", row.error()),
                        format!("{:.2e}", row.tolerance),
                        if row.passed() { "ok" } else { "FAIL" }
                    );
                    eprintln!("      {}", row.note);
                }
                rows.extend(r);
            }
            Err(e) => {
                eprintln!("  {name}: ERROR {e}");
                errors.push(format!("{name}: {e}"));
            }
        }
        timings.push((name, t.elapsed().as_secs_f64()));
    }
    let md = table(&rows);
    println!("{md}");
    for (name, t) in &timings {
        println!("{name}: {t:.1} s");
    }
    let failed: Vec<&Row> = rows.iter().filter(|r| !r.passed()).collect();
    // A part of the cases, or the stiff ones with a contact treatment other than the
    // default, does not replace the page.
    if only.is_none() && contact_rows.is_none() {
        write_doc(&rows, &timings, &errors)?;
    }
    for e in &errors {
        println!("ERROR {e}");
    }
    println!(
        "{} rows, {} failed, {} cases errored",
        rows.len(),
        failed.len(),
        errors.len()
    );
    Ok(failed.is_empty() && errors.is_empty())
}

fn write_doc(rows: &[Row], timings: &[(&str, f64)], errors: &[String]) -> Result<(), String> {
    let path = cases::workspace_file("docs/validation.md");
    let mut s = String::new();
    s.push_str(include_str!("../data/validation-intro.md"));
    s.push_str(
        "\n## Results\n\nWritten by `cargo xtask validate` (release build, f64 unless stated).\n\n",
    );
    s.push_str(&table(rows));
    s.push_str("\n### Notes per row\n\n");
    for r in rows {
        let _ = writeln!(s, "- **{} — {}**: {}", r.case, r.quantity, r.note);
    }
    if !errors.is_empty() {
        s.push_str("\n### Cases that did not complete\n\n");
        for e in errors {
            let _ = writeln!(s, "- {e}");
        }
    }
    s.push_str("\n### Run time of each case\n\n");
    for (name, t) in timings {
        let _ = writeln!(s, "- {name}: {t:.1} s");
    }
    let pareto = cases::workspace_file("docs/benchmarks/pareto.md");
    if let Ok(p) = std::fs::read_to_string(&pareto) {
        s.push_str("\n## Which setting for which accuracy\n\nFrom `cargo xtask bench --pareto` (`docs/benchmarks/pareto.md`):\n\n");
        s.push_str(&p);
    }
    std::fs::write(&path, s).map_err(|e| format!("{}: {e}", path.display()))
}
