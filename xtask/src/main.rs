//! `cargo xtask`: maintainer tools for the workspace.
//!
//! - `cargo xtask validate` — every validation case at full size against its independent
//!   reference, the 10⁵-step long runs and the measured stable-dt map; prints the table,
//!   writes `docs/validation.md` and `docs/stability.md`, exits non-zero on a failure.
//!   `--only NAME` runs only the cases whose name contains NAME (and writes no docs);
//!   `--contact-rows BOOL` runs the stiff scheme's cases with `StiffSettings::contact_rows` set
//!   so (and writes no docs either).
//! - `cargo xtask validate --timings` — the paper's free-space test at 100 and 1000 elements
//!   next to the published timings.
//! - `cargo xtask bench --pareto` — run time against error, work-precision diagrams in
//!   `docs/benchmarks/`.
//! - `cargo xtask bench` — the criterion CPU benches with accuracy beside them, into
//!   `docs/benchmarks/cpu.md`, and the insertion benchmark into `docs/benchmarks/insertion.md`.
//! - `cargo xtask bench --insertion` — only the insertion and free-space benchmarks, into
//!   `docs/benchmarks/insertion.md`.
//! - `cargo xtask bench --stiff` — the stiff step against the explicit step at 1000 elements,
//!   into `docs/benchmarks/stiff-target.md` (exits non-zero while the 2× target is not met).
//! - `cargo xtask bench --haptic` — guidewire insertions ticked as a haptic loop calls them
//!   (the soft wire at 1 kHz and 500 Hz, the nitinol wire at 1 kHz in ten steps per tick, the
//!   nitinol wire bound in a catheter at 1 kHz in five steps per tick),
//!   tick-time percentiles against the loop's period, into `docs/benchmarks/haptic.md` (exits
//!   non-zero when a loop's 99th percentile is over its period on this machine).
//! - `cargo xtask torture` — every instrument preset pushed and twisted through hard vessels
//!   (bowed and narrowing, the phantom, the phantom with flipped patches and a fragment), each
//!   frame checked by the inside test, into `docs/benchmarks/torture.md`. `--contact-rows
//!   VALUE` gives every run `solver.stiff.contact_rows = VALUE`, `--dt SECONDS` one step for
//!   every instrument; either writes its own page beside it (`torture-dt1e-3-contact-rows-true.md`).
//! - `cargo xtask bench --gpu [--quick]` — the GPU backend's benchmark on this machine's adapter,
//!   into `docs/benchmarks/gpu-local.{md,json}` (`--quick`: two sizes, for software adapters). On
//!   a GPU host without a Rust toolchain, build the example here and run it there
//!   (`docs/benchmarks/gpu-h100.md` says how the committed tables were made).
//!
//! - `cargo xtask pictures` — the README's and the docs' pictures, made from the shipped scenes
//!   by `cosserat run` and `cosserat render`, into `docs/pictures/`.
//! - `cargo xtask bench --render` — rendering 1000 frames of a 512-element insertion at
//!   1280×720, into `docs/benchmarks/render.{md,json}`.
//!
//! The flag parser is deliberately small: a handful of commands and flags, no dependency.

#[path = "../../tests/support/mod.rs"]
#[allow(unreachable_pub)]
mod support;

mod bench;
mod haptic;
mod literature;
mod pareto;
mod pictures;
mod stability_map;
mod torture;
mod validate;

use std::process::ExitCode;

/// Parsed command line: the command, its flags, and `--key value` options.
struct Args {
    command: String,
    flags: Vec<String>,
    options: Vec<(String, String)>,
}

impl Args {
    fn parse(mut it: impl Iterator<Item = String>) -> Result<Self, String> {
        let command = it.next().ok_or_else(usage)?;
        let (mut flags, mut options) = (Vec::new(), Vec::new());
        let rest: Vec<String> = it.collect();
        let mut k = 0;
        while k < rest.len() {
            let a = &rest[k];
            let Some(name) = a.strip_prefix("--") else {
                return Err(format!("unexpected argument `{a}`\n{}", usage()));
            };
            if VALUE_OPTIONS.contains(&name) {
                let v = rest
                    .get(k + 1)
                    .ok_or_else(|| format!("`--{name}` needs a value"))?;
                options.push((name.to_string(), v.clone()));
                k += 2;
            } else {
                flags.push(name.to_string());
                k += 1;
            }
        }
        Ok(Self {
            command,
            flags,
            options,
        })
    }

    fn flag(&self, name: &str) -> bool {
        self.flags.iter().any(|f| f == name)
    }

    fn option(&self, name: &str) -> Option<&str> {
        self.options
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    fn reject_unknown(&self, known: &[&str]) -> Result<(), String> {
        match self.flags.iter().find(|f| !known.contains(&f.as_str())) {
            Some(f) => Err(format!(
                "`{}` does not take `--{f}`\n{}",
                self.command,
                usage()
            )),
            None => Ok(()),
        }
    }
}

const VALUE_OPTIONS: &[&str] = &["only", "contact-rows", "dt"];

fn usage() -> String {
    "usage: cargo xtask validate [--timings] [--only NAME] [--contact-rows BOOL]\n       cargo xtask bench [--pareto | --insertion | --stiff | --haptic | --render | --gpu [--quick]]\n       cargo xtask torture [--only TEXT] [--contact-rows VALUE] [--dt SECONDS]\n       cargo xtask pictures".into()
}

fn run() -> Result<bool, String> {
    let args = Args::parse(std::env::args().skip(1))?;
    match args.command.as_str() {
        "validate" => {
            args.reject_unknown(&["timings"])?;
            if args.flag("timings") {
                return literature::run();
            }
            let contact_rows = args
                .option("contact-rows")
                .map(|v| {
                    v.parse::<bool>()
                        .map_err(|_| format!("`--contact-rows` takes true or false, not `{v}`"))
                })
                .transpose()?;
            validate::run(args.option("only"), contact_rows)
        }
        "bench" => {
            args.reject_unknown(&[
                "pareto",
                "insertion",
                "stiff",
                "haptic",
                "render",
                "gpu",
                "quick",
            ])?;
            if args.flag("pareto") {
                pareto::run()
            } else if args.flag("insertion") {
                bench::insertion_only()
            } else if args.flag("stiff") {
                bench::stiff()
            } else if args.flag("haptic") {
                haptic::run()
            } else if args.flag("render") {
                pictures::bench()
            } else if args.flag("gpu") {
                bench::gpu(args.flag("quick"))
            } else {
                bench_criterion()
            }
        }
        "torture" => {
            args.reject_unknown(&[])?;
            let variant = torture::Variant {
                contact_rows: args.option("contact-rows").map(str::to_string),
                dt: args
                    .option("dt")
                    .map(|d| {
                        d.parse::<f64>()
                            .ok()
                            .filter(|d| *d > 0.0)
                            .ok_or_else(|| format!("`--dt` takes a step in seconds, not `{d}`"))
                    })
                    .transpose()?,
            };
            match torture::run(args.option("only"), &variant) {
                Ok(()) => Ok(true),
                Err(e) => {
                    eprintln!("{e}");
                    Ok(false)
                }
            }
        }
        "pictures" => {
            args.reject_unknown(&[])?;
            pictures::run()
        }
        "help" | "--help" | "-h" => {
            println!("{}", usage());
            Ok(true)
        }
        other => Err(format!("unknown command `{other}`\n{}", usage())),
    }
}

/// `cargo xtask bench` without flags: the criterion benches into `docs/benchmarks/`.
fn bench_criterion() -> Result<bool, String> {
    bench::criterion()
}

fn main() -> ExitCode {
    match run() {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
