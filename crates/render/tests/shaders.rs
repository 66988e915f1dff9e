//! Every WGSL file of the crate parses and validates with naga, without a GPU.

use std::path::Path;

#[test]
fn every_shader_validates() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "wgsl") {
            let source = std::fs::read_to_string(&path).unwrap();
            let module = naga::front::wgsl::parse_str(&source)
                .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&source)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::empty(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{}: {e:?}", path.display()));
            for entry_point in ["vs_main", "fs_main"] {
                assert!(
                    module.entry_points.iter().any(|e| e.name == entry_point),
                    "{}: no `{entry_point}`",
                    path.display()
                );
            }
            checked += 1;
        }
    }
    assert!(checked >= 2, "found {checked} shaders in {}", dir.display());
}
