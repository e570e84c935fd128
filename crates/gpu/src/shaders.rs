//! The WGSL sources (in `shaders/` at the repository root) and how the host assembles them:
//! each entry file gets the shared routines of `voxelize.wgsl` appended and the `real` alias
//! (f64 or f32) prepended.

/// Classification and compaction compute entry points (`classify`, `compact`).
pub const CLASSIFY_WGSL: &str = include_str!("../../../shaders/classify.wgsl");
/// Fragment-parallel pass (`vs`, `fs`).
pub const RASTER_WGSL: &str = include_str!("../../../shaders/raster.wgsl");
/// Setup, overlap tests, clipping and attribute accumulation shared by both.
pub const VOXELIZE_WGSL: &str = include_str!("../../../shaders/voxelize.wgsl");

/// Floating-point type of the overlap tests and clipping in the shaders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// f64 (needs `wgpu::Features::SHADER_F64`): the same arithmetic as the CPU reference.
    F64,
    /// f32: agrees with the CPU except near voxel-boundary ties.
    F32,
}

/// The compute module source.
pub fn classify_source(p: Precision) -> String {
    assemble(CLASSIFY_WGSL, p)
}

/// The render module source.
pub fn raster_source(p: Precision) -> String {
    assemble(RASTER_WGSL, p)
}

fn assemble(entry: &str, p: Precision) -> String {
    let ty = match p {
        Precision::F64 => "f64",
        Precision::F32 => "f32",
    };
    format!("alias real = {ty};\n{entry}\n{VOXELIZE_WGSL}")
}
