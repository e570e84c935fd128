//! Shared by the render crate's tests: the shared meshes and octrees built from them.

use std::path::{Path, PathBuf};

use voxlod_pipeline::BuildSettings;
use voxlod_voxelize::Mode;

/// The shared test meshes; `None` with a note when missing, a failure under CI=true.
pub fn meshes() -> Option<PathBuf> {
    let dir = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/meshes"
    ))
    .to_path_buf();
    if dir.is_dir() {
        return Some(dir);
    }
    if std::env::var("CI").as_deref() == Ok("true") {
        panic!(
            "CI=true but the shared test meshes are missing at {}",
            dir.display()
        );
    }
    eprintln!("skipped: shared test meshes not found at {}", dir.display());
    None
}

/// Builds `mesh` (relative to the meshes folder) into `out` with the pipeline.
pub fn build(meshes: &Path, mesh: &str, out: &Path, resolution: u32, mode: Mode) {
    let s = BuildSettings {
        resolution,
        mode,
        progress: false,
        ..Default::default()
    };
    voxlod_pipeline::build(&meshes.join(mesh), out, &s).unwrap();
}
