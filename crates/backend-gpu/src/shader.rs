//! Composition of the WGSL kernels from their `.wgsl` files.
//!
//! The kernels are specialised to the scene by text, not by run-time branches: a prelude of
//! constants (threads per workgroup, points per thread, constraint iterations, halo width) is
//! prepended, the shared helpers of `common.wgsl` follow, and `//#if FLAG` / `//#else` /
//! `//#endif` lines select the terms the scene uses. A scene without extensibility or damping
//! therefore compiles none of that code. `override` constants cannot size function-scope arrays
//! in WGSL, which is why text composition is used.
//!
//! Per-thread loops over a thread's points (`//#for V A B [S]` … `//#endfor`, bounds in terms of
//! `EPT` and `XP = EPT + 2`) are **unrolled** here: every `{V}` / `{V+k}` / `{V-k}` in the block
//! becomes a literal, so each per-thread array is indexed only by constants and the driver can
//! keep it in registers. Dynamically indexed private arrays (what a WGSL loop over them
//! produces) go to local memory on NVIDIA's compiler unless it happens to unroll the loop
//! itself, and the constraint sweeps then become chains of dependent local-memory accesses; the
//! benchmark's `loop` variant ([`KernelConfig::unroll`] off) measures exactly that difference.

/// The shared quaternion / Darboux / energy helpers.
pub(crate) const COMMON_WGSL: &str = include_str!("shaders/common.wgsl");
/// The time-step kernel.
pub(crate) const ROD_STEP_WGSL: &str = include_str!("shaders/rod_step.wgsl");
/// The wall-contact queries, composed after `common.wgsl` into kernels with `MESH`.
pub(crate) const WALL_CONTACT_WGSL: &str = include_str!("shaders/wall_contact.wgsl");
/// Rod–rod and self-contact (closest points, the contact impulse), composed after
/// `common.wgsl` into kernels with `RODC`.
pub(crate) const ROD_CONTACT_WGSL: &str = include_str!("shaders/rod_contact.wgsl");
/// The stiff scheme's banded factorisation and solve (`banded.rs`).
pub(crate) const BANDED_SOLVE_WGSL: &str = include_str!("shaders/banded_solve.wgsl");
/// The Cholesky factor of a 3×3 block, put before either banded solve (`banded.rs`).
pub(crate) const CHOLESKY_WGSL: &str = include_str!("shaders/cholesky.wgsl");
/// The stiff scheme's banded solve, one rod per workgroup, partitioned (`banded.rs`).
pub(crate) const BANDED_PARTITIONED_WGSL: &str = include_str!("shaders/banded_partitioned.wgsl");
/// The stiff scheme's whole step, one rod per workgroup, around the partitioned solve
/// (`stiff.rs`).
pub(crate) const STIFF_STEP_WGSL: &str = include_str!("shaders/stiff_step.wgsl");
/// The mesh queries of the stiff step's contacts, in `f64` (`stiff.rs`, with a mesh).
pub(crate) const STIFF_WALL_WGSL: &str = include_str!("shaders/stiff_wall.wgsl");
/// The stiff step's contacts (`stiff.rs`, with a mesh), after `stiff_wall.wgsl`.
pub(crate) const STIFF_CONTACT_WGSL: &str = include_str!("shaders/stiff_contact.wgsl");
/// The partitioned solve's buffers and entry point, for the solve alone.
pub(crate) const BANDED_PARTITIONED_MAIN_WGSL: &str =
    include_str!("shaders/banded_partitioned_main.wgsl");

/// Every flag `rod_step.wgsl` understands, in a fixed order.
#[cfg(test)]
pub(crate) const FLAGS: [&str; 15] = [
    "EXTENSIBLE",
    "STRETCH_DAMP",
    "BEND_DAMP",
    "DRAG",
    "LOADS",
    "CLAMP",
    "REACT",
    "GRID",
    "PERSTEP",
    "SUBGROUP",
    "SHFL",
    "MESH",
    "GUIDE",
    "BIND",
    "RODC",
];

/// Flags of `rod_step.wgsl` chosen by [`crate::KernelVariant`], each validated with every scene
/// and path combination (`FAST` and the measurement-only `SWEEP_LOADS` / `RSQRT`: inextensible
/// only; `NBR_SYNC`: with `GRID` only).
#[cfg(test)]
pub(crate) const VARIANT_FLAGS: [&[&str]; 7] = [
    &["SWEEP_LOADS"],
    &["RSQRT"],
    &["FAST"],
    &["REGC"],
    &["FAST", "REGC"],
    &["FAST", "REGC", "NBR_SYNC"],
    &["FAST", "REGC", "NBR_SYNC", "COHERENT"],
];

/// Compile-time shape and feature set of one step kernel.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub(crate) struct KernelConfig {
    /// Threads per workgroup.
    pub(crate) threads: u32,
    /// Points (and elements) per thread; even.
    pub(crate) per_thread: u32,
    /// Distance-constraint sweeps per step.
    pub(crate) iterations: u32,
    /// Halo width in points of the multi-workgroup paths (0 when unused).
    pub(crate) halo: u32,
    /// Steps between halo exchanges of the multi-workgroup paths (1 otherwise).
    pub(crate) exchange_steps: u32,
    /// Iteration cap of the grid barrier's spin loop.
    pub(crate) spin_cap: u32,
    /// `BIND`: the outer rods' points of the largest group, which the binding exchanges in
    /// workgroup memory (0 otherwise).
    pub(crate) bind_points: u32,
    /// `BIND`: the inner rods' points of the largest group (0 otherwise).
    pub(crate) bind_inner: u32,
    /// `RODC`: the sizes of the workgroup's rod-contact arrays (all 0 otherwise).
    pub(crate) rodc: RodcShape,
    /// Invocations per rod with `SUBGROUP` (the adapter's subgroup size); 1 otherwise.
    pub(crate) group: u32,
    /// Unroll the per-thread `//#for` loops (the default); `false` emits them as WGSL loops.
    pub(crate) unroll: bool,
    /// Enabled flags (members of [`FLAGS`]).
    pub(crate) flags: Vec<&'static str>,
}

/// The sizes a kernel with `RODC` gives its rod-contact arrays (`shaders/rod_contact.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub(crate) struct RodcShape {
    /// Points of the largest group's rods (`RC_PTS`).
    pub(crate) points: u32,
    /// Their bounding spheres (`RC_SPH`).
    pub(crate) spheres: u32,
    /// Segments per bounding sphere (`RC_K`).
    pub(crate) per_sphere: u32,
    /// Overlapping sphere pairs one step can hold (`RC_PAIRS`).
    pub(crate) pairs: u32,
    /// Contacts one thread can hold (`RC_CAP`).
    pub(crate) per_thread: u32,
}

impl KernelConfig {
    /// The complete WGSL source of this kernel.
    pub(crate) fn source(&self) -> String {
        self.source_of(ROD_STEP_WGSL)
    }

    /// The complete WGSL source of `kernel` (a kernel file's text) in this configuration.
    pub(crate) fn source_of(&self, kernel: &str) -> String {
        // naga 30 takes subgroup built-ins without (and rejects) `enable subgroups;`; the device
        // must have been created with `Features::SUBGROUP`.
        let prelude = format!(
            "const WG: u32 = {}u;\nconst EPT: u32 = {}u;\nconst ITER: u32 = {}u;\nconst HALO: u32 = {}u;\nconst XS: u32 = {}u;\nconst SPIN_CAP: u32 = {}u;\nconst SG: u32 = {}u;\nconst BIND_PTS: u32 = {}u;\nconst BIND_IN: u32 = {}u;\n",
            self.threads,
            self.per_thread,
            self.iterations,
            self.halo,
            self.exchange_steps.max(1),
            self.spin_cap,
            self.group.max(1),
            self.bind_points.max(1),
            self.bind_inner.max(1)
        );
        // A clamped end holds its point, and a clamp's state sits in the held ends' buffer
        // that REACT binds: CLAMP implies REACT (the plan sets both; a hand-made
        // configuration gets the same kernel).
        let mut flags = self.flags.clone();
        if flags.contains(&"CLAMP") && !flags.contains(&"REACT") {
            flags.push("REACT");
        }
        // Bindings and rod contact both put the rods they couple into one workgroup (`GROUP`:
        // the groups, each rod on its own run of threads).
        if flags.contains(&"BIND") || flags.contains(&"RODC") {
            flags.push("GROUP");
        }
        let body = preprocess(kernel, &flags);
        let body = expand_loops(&body, self.per_thread, self.unroll);
        let wall = if self.flags.contains(&"MESH") {
            WALL_CONTACT_WGSL
        } else {
            ""
        };
        // Only kernels with rod contact have its sizes and helpers: the others keep their text.
        let (rodc_prelude, rodc) = if self.flags.contains(&"RODC") {
            let r = &self.rodc;
            (
                format!(
                    "const RC_PTS: u32 = {}u;\nconst RC_SPH: u32 = {}u;\nconst RC_K: u32 = {}u;\nconst RC_PAIRS: u32 = {}u;\nconst RC_CAP: u32 = {}u;\n",
                    r.points.max(2),
                    r.spheres.max(1),
                    r.per_sphere.max(1),
                    r.pairs.max(1),
                    r.per_thread.max(1)
                ),
                format!("{ROD_CONTACT_WGSL}\n"),
            )
        } else {
            (String::new(), String::new())
        };
        format!("{prelude}{rodc_prelude}{COMMON_WGSL}\n{wall}\n{rodc}{body}")
    }
}

/// Resolves `//#if FLAG`, `//#if !FLAG`, `//#else` and `//#endif` lines (nestable). Lines of
/// disabled blocks are dropped; everything else is kept verbatim.
pub(crate) fn preprocess(src: &str, flags: &[&str]) -> String {
    let mut out = String::with_capacity(src.len());
    // Each entry: (this block is active, the enclosing block is active).
    let mut stack: Vec<(bool, bool)> = Vec::new();
    let active = |stack: &[(bool, bool)]| stack.last().is_none_or(|&(a, p)| a && p);
    for line in src.lines() {
        let t = line.trim();
        if let Some(cond) = t.strip_prefix("//#if ") {
            let cond = cond.trim();
            let on = match cond.strip_prefix('!') {
                Some(name) => !flags.contains(&name),
                None => flags.contains(&cond),
            };
            let parent = active(&stack);
            stack.push((on, parent));
        } else if t == "//#else" {
            if let Some(top) = stack.last_mut() {
                top.0 = !top.0;
            }
        } else if t == "//#endif" {
            stack.pop();
        } else if active(&stack) {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// Evaluates a loop bound: integers, `EPT`, `XP` (= `EPT + 2`) joined by `+` / `-`.
fn bound(expr: &str, ept: u32) -> i64 {
    let mut total = 0i64;
    let mut sign = 1i64;
    let mut term = String::new();
    let mut flush = |term: &mut String, sign: i64| {
        let t = term.trim();
        if !t.is_empty() {
            let v = match t {
                "EPT" => i64::from(ept),
                "XP" => i64::from(ept) + 2,
                n => n
                    .parse::<i64>()
                    .unwrap_or_else(|_| panic!("bad loop bound term `{n}`")),
            };
            total += sign * v;
        }
        term.clear();
    };
    for c in expr.chars() {
        match c {
            '+' | '-' => {
                flush(&mut term, sign);
                sign = if c == '-' { -1 } else { 1 };
            }
            c => term.push(c),
        }
    }
    flush(&mut term, sign);
    total
}

/// Replaces `{var}`, `{var+k}` and `{var-k}` in `line` by `value(offset)`.
fn substitute(line: &str, var: &str, value: &dyn Fn(i64) -> String) -> String {
    let mut out = String::with_capacity(line.len());
    let mut rest = line;
    let open = format!("{{{var}");
    while let Some(at) = rest.find(&open) {
        let after = &rest[at + open.len()..];
        let Some(close) = after.find('}') else { break };
        let inner = after[..close].trim();
        let offset = if inner.is_empty() {
            Some(0)
        } else if let Some(k) = inner.strip_prefix('+') {
            k.trim().parse::<i64>().ok()
        } else if let Some(k) = inner.strip_prefix('-') {
            k.trim().parse::<i64>().ok().map(|k| -k)
        } else {
            None
        };
        match offset {
            Some(o) => {
                out.push_str(&rest[..at]);
                out.push_str(&value(o));
                rest = &after[close + 1..];
            }
            None => {
                out.push_str(&rest[..at + open.len()]);
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}

/// Expands `//#for VAR FROM TO [STEP]` … `//#endfor` blocks (nestable): unrolled into one
/// `{ … }` copy per index with literal indices, or emitted as a WGSL `for` loop.
pub(crate) fn expand_loops(src: &str, ept: u32, unroll: bool) -> String {
    let lines: Vec<&str> = src.lines().collect();
    let mut out = String::with_capacity(src.len() * 2);
    expand_block(&lines, ept, unroll, &mut out);
    out
}

fn expand_block(lines: &[&str], ept: u32, unroll: bool, out: &mut String) {
    let mut i = 0;
    while i < lines.len() {
        let t = lines[i].trim();
        let Some(spec) = t.strip_prefix("//#for ") else {
            out.push_str(lines[i]);
            out.push('\n');
            i += 1;
            continue;
        };
        // Find the matching //#endfor.
        let mut depth = 1;
        let mut j = i + 1;
        while j < lines.len() {
            let u = lines[j].trim();
            if u.starts_with("//#for ") {
                depth += 1;
            } else if u == "//#endfor" {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            j += 1;
        }
        assert!(j < lines.len(), "unterminated //#for {spec}");
        let parts: Vec<&str> = spec.split_whitespace().collect();
        assert!(
            parts.len() == 3 || parts.len() == 4,
            "//#for VAR FROM TO [STEP], got `{spec}`"
        );
        let var = parts[0];
        let (from, to) = (bound(parts[1], ept), bound(parts[2], ept));
        let step = parts.get(3).map_or(1, |s| bound(s, ept)).max(1);
        let body = &lines[i + 1..j];
        if unroll {
            let mut k = from;
            while k < to {
                let copy: Vec<String> = body
                    .iter()
                    .map(|l| substitute(l, var, &|o| format!("{}u", k + o)))
                    .collect();
                let copy: Vec<&str> = copy.iter().map(String::as_str).collect();
                out.push_str("{\n");
                expand_block(&copy, ept, unroll, out);
                out.push_str("}\n");
                k += step;
            }
        } else if from < to {
            out.push_str(&format!(
                "for (var {var} = {from}u; {var} < {to}u; {var} += {step}u) {{\n"
            ));
            let copy: Vec<String> = body
                .iter()
                .map(|l| {
                    substitute(l, var, &|o| match o {
                        0 => var.to_string(),
                        o if o > 0 => format!("({var} + {o}u)"),
                        o => format!("({var} - {}u)", -o),
                    })
                })
                .collect();
            let copy: Vec<&str> = copy.iter().map(String::as_str).collect();
            expand_block(&copy, ept, unroll, out);
            out.push_str("}\n");
        }
        i = j + 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::banded::{Precision, partitioned_source, source};

    #[test]
    fn preprocessor_selects_blocks() {
        let src = "a\n//#if X\nb\n//#if !Y\nc\n//#else\nd\n//#endif\n//#else\ne\n//#endif\nf\n";
        assert_eq!(preprocess(src, &["X"]), "a\nb\nc\nf\n");
        assert_eq!(preprocess(src, &["X", "Y"]), "a\nb\nd\nf\n");
        assert_eq!(preprocess(src, &["Y"]), "a\ne\nf\n");
    }

    #[test]
    fn loops_unroll_to_literal_indices() {
        let src = "a\n//#for e 0 EPT-1\nr[{e}] = s[{e+1}] + t[{e-0}];\n//#endfor\nb\n";
        assert_eq!(
            expand_loops(src, 3, true),
            "a\n{\nr[0u] = s[1u] + t[0u];\n}\n{\nr[1u] = s[2u] + t[1u];\n}\nb\n"
        );
        assert_eq!(
            expand_loops(src, 3, false),
            "a\nfor (var e = 0u; e < 2u; e += 1u) {\nr[e] = s[(e + 1u)] + t[e];\n}\nb\n"
        );
        // Strided and nested loops, bounds in XP.
        let src = "//#for x 1 XP 2\n//#for y 0 2\nq[{x}][{y}]\n//#endfor\n//#endfor\n";
        let out = expand_loops(src, 2, true);
        assert_eq!(out.matches("q[").count(), 4, "{out}");
        assert!(
            out.contains("q[1u][0u]") && out.contains("q[3u][1u]"),
            "{out}"
        );
        // The kernel itself: no loop over a per-thread array survives unrolling.
        let cfg = KernelConfig {
            threads: 64,
            per_thread: 4,
            iterations: 10,
            halo: 0,
            exchange_steps: 1,
            spin_cap: 1,
            group: 1,
            unroll: true,
            bind_points: 0,
            bind_inner: 0,
            rodc: RodcShape::default(),
            flags: vec![],
        };
        let src = cfg.source();
        assert!(!src.lines().any(|l| l.trim_start().starts_with("//#")));
        assert!(!src.contains("[{e") && !src.contains("[{x"));
        assert!(src.contains("vx[4u]") && !src.contains("vx[x]"));
        let looped = KernelConfig {
            unroll: false,
            ..cfg
        }
        .source();
        assert!(looped.contains("vx[x]") && looped.contains("for (var x = 1u; x < 5u; x += 2u)"));
    }

    /// A one-workgroup kernel of 64 threads × 2 points with `flags`.
    fn small(flags: Vec<&'static str>) -> KernelConfig {
        KernelConfig {
            threads: 64,
            per_thread: 2,
            iterations: 10,
            halo: 0,
            exchange_steps: 1,
            spin_cap: 1,
            group: 1,
            unroll: true,
            bind_points: 0,
            bind_inner: 0,
            rodc: RodcShape::default(),
            flags,
        }
    }

    /// Rod-contact arrays for two rods of 32 elements.
    const RODC_SHAPE: RodcShape = RodcShape {
        points: 66,
        spheres: 18,
        per_sphere: 4,
        pairs: 64,
        per_thread: 8,
    };

    /// FNV-1a, 64 bits: a fixed digest of a kernel's text (no dependency, the same on every
    /// machine).
    fn digest(text: &str) -> u64 {
        text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
        })
    }

    /// Kernels of scenes without rod contact are byte for byte what they were before rod
    /// contact was added (`RODC`): free space on each path, mesh contact and bindings. The
    /// digests were taken from the kernels of commit e2f0b74; a change to what these scenes
    /// compile must update them on purpose.
    #[test]
    fn kernels_without_rod_contact_keep_their_text() {
        let base = small(vec![]);
        let cases: [(KernelConfig, u64); 6] = [
            (base.clone(), 0x115e116b618b4604),
            (
                KernelConfig {
                    flags: vec!["DRAG", "CLAMP", "REACT", "FAST", "REGC"],
                    ..base.clone()
                },
                0xb8e182c452d130c6,
            ),
            (
                KernelConfig {
                    threads: 128,
                    halo: 24,
                    exchange_steps: 3,
                    spin_cap: 1024,
                    flags: vec!["BEND_DAMP", "GRID", "NBR_SYNC", "COHERENT", "FAST", "REGC"],
                    ..base.clone()
                },
                0x5488c0a7819e1c35,
            ),
            (
                KernelConfig {
                    group: 32,
                    threads: 128,
                    flags: vec!["SUBGROUP", "SHFL", "DRAG", "FAST", "REGC", "REACT"],
                    ..base.clone()
                },
                0x4384fe7abe3830ef,
            ),
            (
                KernelConfig {
                    flags: vec!["MESH", "GUIDE", "DRAG", "FAST", "REGC", "REACT"],
                    ..base.clone()
                },
                0x996ab782bc357d5e,
            ),
            (
                KernelConfig {
                    bind_points: 300,
                    bind_inner: 200,
                    rodc: RodcShape::default(),
                    flags: vec!["BIND", "DRAG", "CLAMP", "REACT", "FAST", "REGC"],
                    ..base.clone()
                },
                0xbd804de3c74c87d4,
            ),
        ];
        let got: Vec<u64> = cases.iter().map(|(c, _)| digest(&c.source())).collect();
        let want: Vec<u64> = cases.iter().map(|(_, d)| *d).collect();
        assert_eq!(got, want, "digests (got, want): {got:#x?} {want:#x?}");
    }

    #[test]
    fn disabled_terms_are_absent_from_the_source() {
        let cfg = KernelConfig {
            threads: 64,
            per_thread: 2,
            iterations: 10,
            halo: 0,
            exchange_steps: 1,
            spin_cap: 1,
            group: 1,
            unroll: true,
            bind_points: 0,
            bind_inner: 0,
            rodc: RodcShape::default(),
            flags: vec![],
        };
        let src = cfg.source();
        assert!(
            !src.contains("stretch_element(rx"),
            "extensible code compiled into an inextensible kernel"
        );
        assert!(!src.contains("bend_damping_node(qx"));
        assert!(!src.contains("clamps[") && !src.contains("clamp_torque(qc0"));
        assert!(!src.contains("atomicAdd(&sync"));
        assert!(!src.contains("subgroupShuffle"));
        let cfg = KernelConfig {
            flags: vec!["EXTENSIBLE", "BEND_DAMP", "GRID", "CLAMP"],
            ..cfg
        };
        let src = cfg.source();
        assert!(
            src.contains("stretch_element(rx")
                && src.contains("bend_damping_node(qx")
                && src.contains("atomicAdd(&sync")
                && src.contains("clamp_torque(qc0")
        );
        // The subgroup kernel has no workgroup barrier and no workgroup memory at all.
        let cfg = KernelConfig {
            group: 32,
            flags: vec!["BEND_DAMP", "SUBGROUP", "SHFL"],
            ..cfg
        };
        let src = cfg.source();
        assert!(src.contains("subgroupShuffleUp"));
        assert!(!src.contains("workgroupBarrier") && !src.contains("workgroupUniformLoad"));
        assert!(!src.contains("var<workgroup>"));
    }

    /// Composes `text` (the kernel file `name`) with the flags of `mask`, where the host ever
    /// composes them, with every shape and variant they can meet, and validates each.
    fn validate_combination(name: &str, text: &str, mask: u32) {
        let flags: Vec<&'static str> = FLAGS
            .iter()
            .enumerate()
            .filter(|(i, _)| mask & (1 << i) != 0)
            .map(|(_, f)| *f)
            .collect();
        let has = |f: &str| flags.contains(&f);
        // Combinations the host never composes.
        if (has("STRETCH_DAMP") && !has("EXTENSIBLE"))
            || (has("GRID") && has("PERSTEP"))
            || (has("SUBGROUP") && (has("GRID") || has("PERSTEP") || !has("SHFL")))
            || (has("SHFL") && !(has("SUBGROUP") || has("GRID") || has("PERSTEP")))
            || ((has("MESH") || has("GUIDE") || has("BIND") || has("RODC"))
                && (has("GRID") || has("PERSTEP") || has("SUBGROUP") || has("SHFL")))
            || ((has("BIND") || has("RODC")) && has("EXTENSIBLE"))
            // The composer adds REACT to CLAMP.
            || (has("CLAMP") && !has("REACT"))
        {
            return;
        }
        // The variant flags, with every scene/path combination they can meet.
        let mut variants = vec![flags.clone()];
        // Contact kernels are composed only with the production variant flags.
        let contact = has("MESH") || has("GUIDE") || has("RODC");
        if contact {
            variants[0].push("REGC");
            if !has("EXTENSIBLE") {
                variants[0].push("FAST");
            }
        }
        for v in VARIANT_FLAGS.iter().filter(|_| !contact) {
            let inextensible_only = v.iter().any(|f| *f != "REGC");
            if (inextensible_only && has("EXTENSIBLE"))
                || ((v.contains(&"NBR_SYNC") || v.contains(&"COHERENT")) && !has("GRID"))
            {
                return;
            }
            let mut f = flags.clone();
            f.extend_from_slice(v);
            variants.push(f);
        }
        for (v, flags) in variants.into_iter().enumerate() {
            let group = if has("SUBGROUP") { 32 } else { 1 };
            // Every shape for the scene's own flags, one for each variant on top.
            let shapes: &[(u32, u32, bool)] = if contact {
                &[(32, 2, true), (64, 6, false)]
            } else if v == 0 {
                &[(32, 2, true), (256, 4, true), (64, 6, false)]
            } else {
                &[(32, 2, true)]
            };
            for &(threads, per_thread, unroll) in shapes {
                let cfg = KernelConfig {
                    threads,
                    per_thread,
                    iterations: 10,
                    halo: 24,
                    exchange_steps: 2,
                    spin_cap: 1024,
                    group,
                    unroll,
                    bind_points: 0,
                    bind_inner: 0,
                    rodc: RODC_SHAPE,
                    flags: flags.clone(),
                };
                let composed = cfg.source_of(text);
                validate(
                    &format!("{name} {flags:?} WG={threads} EPT={per_thread} unroll={unroll}"),
                    &composed,
                );
            }
        }
    }

    fn validate(name: &str, src: &str) {
        let module = naga::front::wgsl::parse_str(src)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
    }

    fn wgsl_files(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
        for entry in std::fs::read_dir(dir).expect("readable source directory") {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                wgsl_files(&path, out);
            } else if path.extension().is_some_and(|e| e == "wgsl") {
                out.push(path);
            }
        }
    }

    /// Every `.wgsl` file under `src/` parses and validates with naga; kernels are validated in
    /// every flag combination the host can compose, unrolled and as loops. Needs no GPU.
    #[test]
    fn every_shader_file_validates() {
        let mut files = Vec::new();
        wgsl_files(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src"),
            &mut files,
        );
        assert!(files.len() >= 2, "no shader files found (found {files:?})");
        let mut kernels = 0;
        for file in &files {
            let text = std::fs::read_to_string(file).expect("readable shader");
            let name = file.display().to_string();
            if file.file_name().is_some_and(|f| f == "common.wgsl") {
                validate(&name, &text);
                assert_eq!(
                    text, COMMON_WGSL,
                    "common.wgsl on disk differs from the compiled-in copy"
                );
                continue;
            }
            if file.file_name().is_some_and(|f| f == "wall_contact.wgsl") {
                validate(&name, &text);
                assert_eq!(
                    text, WALL_CONTACT_WGSL,
                    "wall_contact.wgsl on disk differs from the compiled-in copy"
                );
                continue;
            }
            if file.file_name().is_some_and(|f| f == "rod_contact.wgsl") {
                // Composed into the kernels with `RODC` (validated in every combination with
                // rod_step.wgsl's flags); here in one such kernel.
                assert_eq!(
                    text, ROD_CONTACT_WGSL,
                    "rod_contact.wgsl on disk differs from the compiled-in copy"
                );
                let cfg = KernelConfig {
                    rodc: RODC_SHAPE,
                    ..small(vec!["RODC", "FAST", "REGC"])
                };
                validate(&name, &cfg.source());
                continue;
            }
            if file.file_name().is_some_and(|f| f == "cholesky.wgsl") {
                // Put before both banded solves, validated with them below.
                assert_eq!(
                    text, CHOLESKY_WGSL,
                    "cholesky.wgsl on disk differs from the compiled-in copy"
                );
                continue;
            }
            if file.file_name().is_some_and(|f| f == "banded_solve.wgsl") {
                // Not composed with flags: its number type is the only thing filled in.
                assert_eq!(
                    text, BANDED_SOLVE_WGSL,
                    "banded_solve.wgsl on disk differs from the compiled-in copy"
                );
                for precision in [Precision::F64, Precision::F32] {
                    validate(&format!("{name} {precision:?}"), &source(precision));
                }
                continue;
            }
            if file
                .file_name()
                .is_some_and(|f| f == "banded_partitioned.wgsl")
            {
                // Its number type, invocations per rod and elements per invocation filled in.
                assert_eq!(
                    text, BANDED_PARTITIONED_WGSL,
                    "banded_partitioned.wgsl on disk differs from the compiled-in copy"
                );
                for precision in [Precision::F64, Precision::F32] {
                    for (threads, per_thread) in [(1, 1), (1, 5), (2, 1), (64, 4), (256, 2)] {
                        validate(
                            &format!("{name} {precision:?} {threads}×{per_thread}"),
                            &partitioned_source(precision, threads, per_thread),
                        );
                    }
                }
                continue;
            }
            if file
                .file_name()
                .is_some_and(|f| f == "banded_partitioned_main.wgsl")
            {
                // Put before `banded_partitioned.wgsl`, validated with it above.
                assert_eq!(
                    text, BANDED_PARTITIONED_MAIN_WGSL,
                    "banded_partitioned_main.wgsl on disk differs from the compiled-in copy"
                );
                continue;
            }
            if file.file_name().is_some_and(|f| f == "stiff_step.wgsl") {
                // With the partitioned solve after it, for a few slicings.
                assert_eq!(
                    text, STIFF_STEP_WGSL,
                    "stiff_step.wgsl on disk differs from the compiled-in copy"
                );
                for (threads, per_thread) in [(1, 2), (2, 1), (4, 3), (64, 4)] {
                    for (mesh, guide) in
                        [(false, false), (true, false), (false, true), (true, true)]
                    {
                        validate(
                            &format!("{name} {threads}×{per_thread} mesh {mesh} guide {guide}"),
                            &crate::stiff::source_for(threads, per_thread, mesh, guide),
                        );
                    }
                }
                continue;
            }
            if let Some((file, compiled)) = [
                ("stiff_wall.wgsl", STIFF_WALL_WGSL),
                ("stiff_contact.wgsl", STIFF_CONTACT_WGSL),
            ]
            .into_iter()
            .find(|(f, _)| file.file_name().is_some_and(|n| n == *f))
            {
                // Composed into the stiff step with a mesh, validated with it above.
                assert_eq!(
                    text, compiled,
                    "{file} on disk differs from the compiled-in copy"
                );
                continue;
            }
            kernels += 1;
            if file.file_name().is_some_and(|f| f == "rod_step.wgsl") {
                assert_eq!(
                    text, ROD_STEP_WGSL,
                    "rod_step.wgsl on disk differs from the compiled-in copy"
                );
            }
            // Each thread validates every n-th combination (naga's validation of some thousand
            // kernels dominates the test).
            let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
            std::thread::scope(|s| {
                for t in 0..threads {
                    let (name, text) = (&name, &text);
                    s.spawn(move || {
                        for mask in
                            (0u32..(1 << FLAGS.len())).filter(|m| *m as usize % threads == t)
                        {
                            validate_combination(name, text, mask);
                        }
                    });
                }
            });
        }
        assert!(kernels >= 1, "no kernel files found");
    }
}
