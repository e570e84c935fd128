//! A memory-mapped input (binary PLY, binary STL) truncated while it is streamed ends the
//! process with a message naming the file and exit status `TRUNCATED_EXIT`, not a bare
//! SIGBUS (an input is still memory-mapped while it is read). The test re-runs its own binary as a
//! child that streams a mesh and truncates it from the first batch's callback, so the rest of
//! the read touches pages past the new end of the file — exactly what `truncate` from another
//! program does to a running build.

use crate::common;
use common::*;

use std::os::unix::process::ExitStatusExt;
use std::process::Command;
use voxlod_ingest::{MeshSource, TRUNCATED_EXIT};

const CHILD: &str = "VOXLOD_TRUNCATE_CHILD";

/// A binary STL of `n` small facets (50 bytes each).
fn big_stl(n: usize) -> Vec<u8> {
    let tris: Vec<[[f32; 3]; 3]> = (0..n)
        .map(|i| {
            let x = (i % 1000) as f32;
            let y = (i / 1000) as f32;
            [[x, y, 0.0], [x + 1.0, y, 0.0], [x, y + 1.0, 0.5]]
        })
        .collect();
    stl_binary(&tris, b"truncated while read")
}

/// A binary PLY of `n` faces over a grid of vertices.
fn big_ply(n: usize) -> Vec<u8> {
    let side = 500usize;
    let vertex = El {
        name: "vertex",
        props: vec!["float x", "float y", "float z"],
        rows: (0..side * side)
            .map(|i| vec![V::S((i % side) as f64), V::S((i / side) as f64), V::S(0.0)])
            .collect(),
    };
    let face = El {
        name: "face",
        props: vec!["list uchar int vertex_indices"],
        rows: (0..n)
            .map(|i| {
                let a = (i % (side * (side - 1))) as f64;
                V::L(vec![a, a + 1.0, a + side as f64])
            })
            .map(|l| vec![l])
            .collect(),
    };
    ply("binary_little_endian", &[vertex, face])
}

/// The child: streams the file named by the environment and truncates it after the first
/// batch. Reaching the end means the fault was not seen (which the parent reports).
#[test]
fn child_streams_and_truncates() {
    let Ok(path) = std::env::var(CHILD) else {
        return; // only as the child
    };
    let path = std::path::PathBuf::from(path);
    let mesh = MeshSource::open(&path).unwrap();
    let mut first = true;
    let r = mesh.stream(
        &mut |_batch| {
            if first {
                first = false;
                let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
                f.set_len(100).unwrap();
            }
            Ok(())
        },
        &mut |_, _| {},
    );
    println!("child finished: {r:?}");
}

/// The child test's full name as the harness knows it: its module path without the crate's
/// name (`truncated_while_read::child_streams_and_truncates` in the crate's one test binary),
/// so that `--exact` selects it however the test files are grouped into binaries.
fn child_test_name() -> String {
    let module = module_path!().split_once("::").map_or("", |(_, m)| m);
    let name = "child_streams_and_truncates";
    assert!(!module.is_empty(), "a module of tests/all/main.rs");
    format!("{module}::{name}")
}

#[test]
fn truncated_mapped_input_is_an_error_exit_not_sigbus() {
    if std::env::var(CHILD).is_ok() {
        return;
    }
    let dir = TempDir::new("truncate");
    for (name, bytes) in [
        ("big.stl", big_stl(600_000)),
        ("big.ply", big_ply(1_500_000)),
    ] {
        let path = dir.write(name, &bytes);
        let out = Command::new(std::env::current_exe().unwrap())
            .args([
                child_test_name().as_str(),
                "--exact",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD, &path)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert_eq!(
            out.status.signal(),
            None,
            "{name}: killed by signal {:?}\n{stderr}",
            out.status.signal()
        );
        assert_eq!(
            out.status.code(),
            Some(TRUNCATED_EXIT),
            "{name}: stdout {stdout}\nstderr {stderr}"
        );
        assert!(
            stderr.contains(&*path.to_string_lossy()) && stderr.contains("truncated"),
            "{name}: {stderr}"
        );
    }
}
