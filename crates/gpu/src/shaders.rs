//! The WGSL sources and how the host assembles them. The one source is `shaders/` at the
//! repository root; the crate reaches it through `crates/gpu/shaders`, a symbolic link to that
//! folder, so that `cargo package` puts the files into the crate (a path out of the crate is
//! not packaged); `tests/shaders.rs` checks that both hold the same files. The assembly:
//! each entry file gets the shared routines of `voxelize.wgsl` appended and the `real` alias
//! (f64 or f32) prepended, with the constants of the filter bounds for that type: `UNIT`, the
//! unit roundoff (2⁻⁵³ or 2⁻²⁴), and `TINY`, an absolute slack covering underflow (in f32 also
//! denormals flushed to zero: at most 2⁻¹²⁶ per operation), and `EXACT_TIES`, whether faces in
//! an axis plane get the exact integer depth test (f64 only: recognizing them relies on
//! products of f32 differences never underflowing to 0, true in f64; see the top of
//! `voxelize.wgsl`), and `ETA_MIN`, the absolute part of the bound on a grid coordinate's
//! distance from its world value's exact image (2⁻¹⁴⁰ for a subnormal f32 in
//! `voxlod_voxelize::world::Perturbation`; in f32 shaders 10⁻³⁰, as denormals may flush). The host's certification flags are likewise set for f64 shaders only.

/// Classification and compaction compute entry points (`classify`, `compact`).
pub const CLASSIFY_WGSL: &str = include_str!("../shaders/classify.wgsl");
/// Fragment-parallel pass (`vs`, `fs`).
pub const RASTER_WGSL: &str = include_str!("../shaders/raster.wgsl");
/// Setup, overlap tests, clipping and attribute accumulation shared by both.
pub const VOXELIZE_WGSL: &str = include_str!("../shaders/voxelize.wgsl");

/// Floating-point type of the overlap tests and clipping in the shaders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// f64 (needs `wgpu::Features::SHADER_F64`): the same arithmetic as the CPU reference.
    F64,
    /// f32: the same filter with f32's unit roundoff; triangles with a decision inside the
    /// (wider) bands are decided on the host, as in f64, only many more of them.
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
    // abstract-float literals, converted to `real` exactly (both are powers of two or far
    // above the bounds' own rounding)
    let (ty, unit, tiny, ties, eta_min) = match p {
        Precision::F64 => ("f64", "1.1102230246251565e-16", "1e-300", true, "1e-42"),
        Precision::F32 => ("f32", "5.9604644775390625e-8", "1e-30", false, "1e-30"),
    };
    format!(
        "alias real = {ty};\nconst UNIT: real = {unit};\nconst TINY: real = {tiny};\nconst EXACT_TIES: bool = {ties};\nconst ETA_MIN: real = {eta_min};\n{entry}\n{VOXELIZE_WGSL}"
    )
}
