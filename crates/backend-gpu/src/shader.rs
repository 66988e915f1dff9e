//! Composition of the WGSL kernels from their `.wgsl` files.
//!
//! The kernels are specialised to the scene by text, not by run-time branches: a prelude of
//! constants (threads per workgroup, points per thread, constraint iterations, halo width) is
//! prepended, the shared helpers of `common.wgsl` follow, and `//#if FLAG` / `//#else` /
//! `//#endif` lines select the terms the scene uses. A scene without extensibility or damping
//! therefore compiles none of that code, and the register arrays have compile-time sizes so the
//! driver can keep them in registers. `override` constants cannot size function-scope arrays in
//! WGSL, which is why text composition is used.

/// The shared quaternion / Darboux / energy helpers.
pub(crate) const COMMON_WGSL: &str = include_str!("shaders/common.wgsl");
/// The time-step kernel.
pub(crate) const ROD_STEP_WGSL: &str = include_str!("shaders/rod_step.wgsl");

/// Every flag `rod_step.wgsl` understands, in a fixed order.
#[cfg(test)]
pub(crate) const FLAGS: [&str; 7] = [
    "EXTENSIBLE",
    "STRETCH_DAMP",
    "BEND_DAMP",
    "DRAG",
    "LOADS",
    "GRID",
    "PERSTEP",
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
    /// Iteration cap of the grid barrier's spin loop.
    pub(crate) spin_cap: u32,
    /// Enabled flags (members of [`FLAGS`]).
    pub(crate) flags: Vec<&'static str>,
}

impl KernelConfig {
    /// The complete WGSL source of this kernel.
    pub(crate) fn source(&self) -> String {
        let prelude = format!(
            "const WG: u32 = {}u;\nconst EPT: u32 = {}u;\nconst ITER: u32 = {}u;\nconst HALO: u32 = {}u;\nconst SPIN_CAP: u32 = {}u;\n",
            self.threads, self.per_thread, self.iterations, self.halo, self.spin_cap
        );
        let body = preprocess(ROD_STEP_WGSL, &self.flags);
        format!("{prelude}{COMMON_WGSL}\n{body}")
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preprocessor_selects_blocks() {
        let src = "a\n//#if X\nb\n//#if !Y\nc\n//#else\nd\n//#endif\n//#else\ne\n//#endif\nf\n";
        assert_eq!(preprocess(src, &["X"]), "a\nb\nc\nf\n");
        assert_eq!(preprocess(src, &["X", "Y"]), "a\nb\nd\nf\n");
        assert_eq!(preprocess(src, &["Y"]), "a\ne\nf\n");
    }

    #[test]
    fn disabled_terms_are_absent_from_the_source() {
        let cfg = KernelConfig {
            threads: 64,
            per_thread: 2,
            iterations: 10,
            halo: 0,
            spin_cap: 1,
            flags: vec![],
        };
        let src = cfg.source();
        assert!(
            !src.contains("stretch_element(rx"),
            "extensible code compiled into an inextensible kernel"
        );
        assert!(!src.contains("bend_damping_node(qx"));
        assert!(!src.contains("atomicAdd(&sync"));
        let cfg = KernelConfig {
            flags: vec!["EXTENSIBLE", "BEND_DAMP", "GRID"],
            ..cfg
        };
        let src = cfg.source();
        assert!(
            src.contains("stretch_element(rx")
                && src.contains("bend_damping_node(qx")
                && src.contains("atomicAdd(&sync")
        );
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
    /// every flag combination the host can compose. Needs no GPU.
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
            kernels += 1;
            for mask in 0u32..(1 << FLAGS.len()) {
                let flags: Vec<&'static str> = FLAGS
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| mask & (1 << i) != 0)
                    .map(|(_, f)| *f)
                    .collect();
                let has = |f: &str| flags.contains(&f);
                // Combinations the host never composes.
                if (has("STRETCH_DAMP") && !has("EXTENSIBLE")) || (has("GRID") && has("PERSTEP")) {
                    continue;
                }
                for (threads, per_thread) in [(32, 2), (256, 4)] {
                    let cfg = KernelConfig {
                        threads,
                        per_thread,
                        iterations: 10,
                        halo: 24,
                        spin_cap: 1024,
                        flags: flags.clone(),
                    };
                    let composed = format!(
                        "const WG: u32 = {threads}u;\nconst EPT: u32 = {per_thread}u;\nconst ITER: u32 = 10u;\nconst HALO: u32 = 24u;\nconst SPIN_CAP: u32 = 1024u;\n{COMMON_WGSL}\n{}",
                        preprocess(&text, &flags)
                    );
                    if file.file_name().is_some_and(|f| f == "rod_step.wgsl") {
                        assert_eq!(
                            composed,
                            cfg.source(),
                            "rod_step.wgsl on disk differs from the compiled-in copy"
                        );
                    }
                    validate(
                        &format!("{name} {flags:?} WG={threads} EPT={per_thread}"),
                        &composed,
                    );
                }
            }
        }
        assert!(kernels >= 1, "no kernel files found");
    }
}
