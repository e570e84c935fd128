//! `voxlod-voxelize`'s integration tests as one test binary: one link instead of one per file, and the
//! tests of every module run in parallel threads of one process. Each module is a former
//! `tests/*.rs` file; a new test file goes into this folder with a `mod` line here
//! (`every_file_is_a_module` fails otherwise). Run one module with
//! `cargo test -p voxlod-voxelize --test all MODULE::`.

// Real meshes on the tool's grid: outside `common`, which the gpu crate's tests include too.
mod attributes;
mod chunk;
mod clip;
mod column;
mod common;
mod exact;
mod f32_grid_bound;
#[path = "common/grid.rs"]
mod grid;
mod materials;
mod overlap;
mod scanline;
mod single;
mod small;
mod textures;
mod thin_separating;
mod world_exact;

/// Every file of this folder is compiled as a module of this binary.
#[test]
fn every_file_is_a_module() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/all");
    voxlod_testkit::suite::assert_every_file_is_a_module(&dir, include_str!("main.rs"));
}
