//! The WGSL sources parse and validate with naga (the shader compiler inside wgpu), in both
//! precisions, without needing a device.

use voxlod_gpu::shaders::{classify_source, raster_source, Precision};
use wgpu::naga;

fn validate(name: &str, src: &str, entries: &[&str]) {
    let module = naga::front::wgsl::parse_str(src)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
    let mut v = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    );
    v.validate(&module)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
    for e in entries {
        assert!(
            module.entry_points.iter().any(|ep| ep.name == *e),
            "{name}: no entry point {e}"
        );
    }
}

#[test]
fn shaders_validate_in_both_precisions() {
    for p in [Precision::F64, Precision::F32] {
        validate(
            &format!("classify {p:?}"),
            &classify_source(p),
            &["classify", "compact"],
        );
        validate(&format!("raster {p:?}"), &raster_source(p), &["vs", "fs"]);
    }
}

#[test]
fn f32_shaders_need_no_float64() {
    // the GL fallback has no SHADER_F64: the f32 variant must validate without that capability
    for src in [
        classify_source(Precision::F32),
        raster_source(Precision::F32),
    ] {
        let module = naga::front::wgsl::parse_str(&src).unwrap();
        let caps = naga::valid::Capabilities::all() - naga::valid::Capabilities::FLOAT64;
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), caps)
            .validate(&module)
            .unwrap();
    }
}

/// Every `@group(0) @binding(n)` global of both shader modules (both precisions) has the slot
/// of the same name in `voxlod_gpu::bindings`, and the classification module binds every slot
/// (the fragment pass all but `draw_args`): the host's bind-group layouts use those constants.
#[test]
fn bind_group_slots_match_the_shaders() {
    use voxlod_gpu::bindings::SLOTS;
    let slot = |name: &str| SLOTS.iter().find(|(n, _)| *n == name).map(|s| s.1);
    for p in [Precision::F64, Precision::F32] {
        for (file, src, unbound) in [
            ("classify.wgsl", classify_source(p), &[][..]),
            ("raster.wgsl", raster_source(p), &["draw_args"][..]),
        ] {
            let module = naga::front::wgsl::parse_str(&src).unwrap();
            let mut bound = Vec::new();
            for (_, g) in module.global_variables.iter() {
                let Some(b) = &g.binding else { continue };
                let name = g.name.as_deref().unwrap_or("?");
                assert_eq!(b.group, 0, "{file}: {name} is not in bind group 0");
                assert_eq!(
                    slot(name),
                    Some(b.binding),
                    "{file} {p:?}: `{name}` is @binding({}), bindings::SLOTS says {:?}",
                    b.binding,
                    slot(name)
                );
                bound.push(name.to_string());
            }
            for (name, _) in SLOTS {
                assert_eq!(
                    bound.iter().any(|b| b == name),
                    !unbound.contains(&name),
                    "{file} {p:?}: slot `{name}`"
                );
            }
        }
    }
}

/// The shaders' mode numbers (`MODE_CONSERVATIVE`, `MODE_THIN` in voxelize.wgsl) are
/// `Mode::code()`, which the host writes into `Params.mode`.
#[test]
fn mode_constants_match_mode_code() {
    use voxlod_voxelize::Mode;
    let module = naga::front::wgsl::parse_str(&classify_source(Precision::F64)).unwrap();
    for (name, mode) in [
        ("MODE_CONSERVATIVE", Mode::Conservative),
        ("MODE_THIN", Mode::Thin),
    ] {
        let c = module
            .constants
            .iter()
            .map(|(_, c)| c)
            .find(|c| c.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no constant {name}"));
        let value = match module.global_expressions[c.init] {
            naga::Expression::Literal(naga::Literal::U32(v)) => v,
            ref e => panic!("{name} = {e:?}, not a u32 literal"),
        };
        assert_eq!(value, mode.code(), "{name}");
    }
}

/// The crate's `shaders/` (what `include_str!` and `cargo package` see; a symbolic link to the
/// repository's `shaders/`) holds the same files, byte for byte, as the repository's
/// `shaders/`, the one source: fails if the link was replaced by a copy that drifted, or
/// checked out as a plain file.
#[test]
fn crate_shaders_are_the_repository_shaders() {
    let krate = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let repo = krate.join("../../shaders");
    if !repo.is_dir() {
        // a packaged crate: only its own copy exists
        voxlod_testkit::skipped(
            "shaders::crate_shaders_are_the_repository_shaders",
            "no repository shaders/ beside the crate (a packaged crate)",
        );
        return;
    }
    let files = |dir: &std::path::Path| {
        let mut v: Vec<(std::ffi::OsString, Vec<u8>)> = std::fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|e| {
                let e = e.unwrap();
                (e.file_name(), std::fs::read(e.path()).unwrap())
            })
            .collect();
        v.sort();
        v
    };
    let (ours, theirs) = (files(&krate.join("shaders")), files(&repo));
    assert_eq!(theirs.len(), 3, "classify, raster, voxelize");
    assert!(
        ours == theirs,
        "crates/gpu/shaders differs from shaders/: {:?} against {:?}",
        ours.iter().map(|f| &f.0).collect::<Vec<_>>(),
        theirs.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
}
