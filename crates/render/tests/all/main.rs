//! `voxlod-render`'s integration tests as one test binary: one link instead of one per file, and the
//! tests of every module run in parallel threads of one process. Each module is a former
//! `tests/*.rs` file; a new test file goes into this folder with a `mod` line here
//! (`every_file_is_a_module` fails otherwise). Run one module with
//! `cargo test -p voxlod-render --test all MODULE::`.

mod common;
mod export;
mod occlusion;
mod render;
mod source;
mod source_attributes;
mod two_sided;
mod view;
mod view_source;
mod viewing;

/// Every file of this folder is compiled as a module of this binary.
#[test]
fn every_file_is_a_module() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/all");
    voxlod_testkit::suite::assert_every_file_is_a_module(&dir, include_str!("main.rs"));
}
