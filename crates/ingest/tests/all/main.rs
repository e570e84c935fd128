//! `voxlod-ingest`'s integration tests as one test binary: one link instead of one per file, and the
//! tests of every module run in parallel threads of one process. Each module is a former
//! `tests/*.rs` file; a new test file goes into this folder with a `mod` line here
//! (`every_file_is_a_module` fails otherwise). Run one module with
//! `cargo test -p voxlod-ingest --test all MODULE::`.

mod by_index;
mod common;
mod cross_format;
mod fuzz;
mod gltf;
mod gltf_compressed;
mod gltf_document;
mod malformed;
mod parallel_faces;
mod parts;
mod ply_face_data;
mod ply_formats;
mod real_meshes;
mod textures;
mod truncated_while_read;

/// Every file of this folder is compiled as a module of this binary.
#[test]
fn every_file_is_a_module() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/all");
    voxlod_testkit::suite::assert_every_file_is_a_module(&dir, include_str!("main.rs"));
}
