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
