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

/// The GPU renderer; no adapter is a failure, never a skip (lavapipe without a GPU).
pub fn renderer() -> voxlod_render::Renderer {
    match voxlod_render::Renderer::new() {
        Ok(x) => x,
        Err(e) => panic!("no GPU adapter: the render tests need one (lavapipe: apt-get install mesa-vulkan-drivers libvulkan1): {e}"),
    }
}

/// The camera path `configs/NAME` of the repository.
pub fn fly_path(name: &str) -> voxlod_render::view::FlyPath {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../configs")
        .join(name);
    voxlod_render::view::FlyPath::load(&p).unwrap()
}
