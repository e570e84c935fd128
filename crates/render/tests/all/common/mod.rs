//! Shared by the render crate's tests: the shared meshes and octrees built from them.

use std::path::{Path, PathBuf};

use voxlod_pipeline::BuildSettings;
use voxlod_voxelize::Mode;

/// The shared test meshes (`voxlod_testkit::shared_meshes`: skipped with a note without
/// `../shared`, a failure under CI).
pub fn meshes() -> Option<PathBuf> {
    voxlod_testkit::shared_meshes(module_path!())
}

/// Builds `mesh` (relative to the meshes folder) into `out` with the pipeline.
pub fn build(meshes: &Path, mesh: &str, out: &Path, resolution: u32, mode: Mode) {
    build_with(meshes, mesh, out, resolution, mode, false);
}

/// [`build`], storing the leaves' source triangles too when `source_geometry` is set.
pub fn build_with(
    meshes: &Path,
    mesh: &str,
    out: &Path,
    resolution: u32,
    mode: Mode,
    source_geometry: bool,
) {
    let s = BuildSettings {
        resolution,
        mode,
        source_geometry,
        progress: false,
        ..Default::default()
    };
    voxlod_pipeline::build(&meshes.join(mesh), out, &s).unwrap();
}
