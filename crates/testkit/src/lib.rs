//! Test support shared by every voxlod test suite, so each rule lives in one place:
//!
//! * [`shared_meshes`]: where the real test meshes are (`../shared/data/meshes` beside the
//!   clone), with the project's rule: missing means "skipped, and say so", except under
//!   `CI=true`, where missing is a failure.
//! * [`python_ready`]: whether python3 with numpy and zstandard (the Python reader's needs)
//!   runs, with the same rule: missing is a skip elsewhere, a failure under `CI=true`.
//! * [`Rng`]: a deterministic SplitMix64 generator (`voxlod_io::splitmix64`, same numbers on
//!   every platform), with the draws the tests need (floats, ranges, integers, points, rotations).
//! * [`gltf`]: a minimal glTF 2.0 writer (`.gltf` + `.bin`, `.glb`).
//! * [`textured`]: a textured OBJ converted to textured PLY (both texture coordinate conventions).
//! * [`mesh`]: made-up meshes (icosphere, cube, transforms) and a minimal PLY/OBJ reader
//!   written independently of `voxlod-ingest`, so tests can check the real reader against it.
//! * [`suite`]: the check that every test file of a crate's one test binary (`tests/all/`) is
//!   declared in its `main.rs`.
//! * [`skipped`] ([`skips`]): a skip said where it is seen: the test binary's output ends with
//!   the list of tests that skipped something, after the runner's summary line.
//!
//! It depends on nothing but `voxlod-io` (which depends on nothing but `std`), so any crate
//! can take it as a dev-dependency without a cycle.
//!
//! ```
//! use voxlod_testkit::{mesh, Rng};
//! let mut rng = Rng(7);
//! let (v, f) = mesh::icosphere(1);
//! assert_eq!((v.len(), f.len()), (42, 80));
//! let x = rng.range(-1.0, 1.0);
//! assert!((-1.0..1.0).contains(&x));
//! if let Some(dir) = voxlod_testkit::shared_meshes("doc example") {
//!     assert!(dir.join("SOURCES.md").is_file());
//! }
//! ```

pub mod gltf;
pub mod mesh;
mod rng;
pub mod skips;
pub mod suite;
pub mod textured;

pub use rng::Rng;
pub use skips::skipped;

use std::path::{Path, PathBuf};

/// The repository root (the workspace folder holding `Cargo.toml`, `data/`, `tests/`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap_or_else(|_| Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."))
}

/// True when the tests run under CI (`CI=true`), where nothing may be skipped.
pub fn under_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// The shared real test meshes (`../shared/data/meshes` beside the clone), or `None` when this
/// clone has none, after [`skipped`] said so (the test binary's output then ends with the list
/// of skipping tests). Under CI (`CI=true`) a missing folder is a failure (a panic naming the
/// test), never a skip.
pub fn shared_meshes(test: &str) -> Option<PathBuf> {
    let p = repo_root().join("../shared/data/meshes");
    if p.is_dir() {
        return Some(p);
    }
    if under_ci() {
        panic!(
            "{test}: {} is missing, and CI=true requires the shared test meshes",
            p.display()
        );
    }
    skipped(
        test,
        &format!(
            "{} is not beside this clone (the real-mesh part did not run)",
            p.display()
        ),
    );
    None
}

/// One shared mesh by its path under `../shared/data/meshes` (for example
/// `"stanford-dragon/dragon.ply"`), or `None` as [`shared_meshes`] says. Under CI a missing
/// file is a failure too.
pub fn shared_mesh(test: &str, rel: &str) -> Option<PathBuf> {
    let p = shared_meshes(test)?.join(rel);
    assert!(
        p.is_file(),
        "{test}: {} is missing from the shared meshes",
        p.display()
    );
    Some(p)
}

/// True if `python3` with numpy and zstandard (what `scripts/voxlod_read.py` needs) runs.
/// Otherwise says so with [`skipped`] and returns false, or under CI (`CI=true`, which
/// installs them) fails with a panic naming the test.
pub fn python_ready(test: &str) -> bool {
    let o = std::process::Command::new("python3")
        .args(["-c", "import numpy, zstandard"])
        .output();
    let why = match o {
        Ok(o) if o.status.success() => return true,
        Ok(o) => String::from_utf8_lossy(&o.stderr).into_owned(),
        Err(e) => e.to_string(),
    };
    if under_ci() {
        panic!("{test}: CI=true but python3 with numpy and zstandard is not available: {why}");
    }
    skipped(
        test,
        &format!(
            "python3 with numpy and zstandard is not available (pip install numpy zstandard): \
             {}",
            why.trim()
        ),
    );
    false
}
