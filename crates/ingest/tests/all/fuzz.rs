//! Seeded mutation fuzzing of every mesh parser, bounded to a few seconds so it runs in CI
//! (issue 17, "a fuzz target per parser"). Small valid inputs, made here, are mutated — bit
//! flips, truncations, inserted and deleted bytes, duplicated spans, and "big counts" (a
//! number or a 4-byte field replaced by a huge value) — and each mutant is opened and streamed
//! in-process. Whatever the bytes, the parser must return (no panic, caught with
//! `catch_unwind`), and an error must name the file. The same seed gives the same mutants; set
//! `VOXLOD_FUZZ_ITERS` for a longer run (default 150 per input).

use crate::common;
use common::*;

use std::panic::{catch_unwind, AssertUnwindSafe};

use voxlod_testkit::Rng;

/// One random mutation of `data`.
fn mutate(rng: &mut Rng, data: &[u8]) -> Vec<u8> {
    let mut d = data.to_vec();
    let rounds = 1 + rng.index(3);
    for _ in 0..rounds {
        let at = rng.index(d.len() + 1);
        match rng.index(7) {
            0 if !d.is_empty() => {
                let i = at.min(d.len() - 1);
                d[i] ^= 1 << rng.index(8);
            }
            1 => d.truncate(at),
            2 => {
                let byte = [0u8, b' ', b'\n', b'-', b'9', 0xff, rng.next_u64() as u8][rng.index(7)];
                d.insert(at, byte);
            }
            3 if at < d.len() => {
                let end = (at + 1 + rng.index(8)).min(d.len());
                d.drain(at..end);
            }
            4 if at < d.len() => {
                // duplicate a span (repeated lines, elements, records)
                let end = (at + 1 + rng.index(40)).min(d.len());
                let span = d[at..end].to_vec();
                d.splice(at..at, span);
            }
            5 => {
                // a big count: replace the next run of ASCII digits by a huge number
                let huge: &[u8] = [
                    &b"4294967295"[..],
                    b"18446744073709551615",
                    b"99999999999999999999999",
                    b"300",
                    b"-1",
                    b"1e19",
                ][rng.index(6)];
                if let Some(s) = (at..d.len()).find(|&i| d[i].is_ascii_digit()) {
                    let e = (s..d.len())
                        .find(|&i| !d[i].is_ascii_digit())
                        .unwrap_or(d.len());
                    d.splice(s..e, huge.iter().copied());
                }
            }
            _ if d.len() >= 4 => {
                // a big 4-byte field (binary counts and indices)
                let i = at.min(d.len() - 4);
                let v: u32 = [u32::MAX, 0x8000_0000, 0x7fff_ffff, 1 << 20][rng.index(4)];
                d[i..i + 4].copy_from_slice(&v.to_le_bytes());
            }
            _ => {}
        }
    }
    d
}

fn tetra() -> Vec<[[f32; 3]; 3]> {
    let p = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
        .iter()
        .map(|t: &[usize; 3]| t.map(|i| p[i]))
        .collect()
}

/// A small PLY with normals, colours and a quad, in the given encoding.
fn ply_seed(enc: &str) -> Vec<u8> {
    let vertex = El {
        name: "vertex",
        props: vec![
            "float x",
            "float y",
            "float z",
            "float nx",
            "float ny",
            "float nz",
            "uchar red",
            "uchar green",
            "uchar blue",
        ],
        rows: (0..5)
            .map(|i| {
                let f = i as f64;
                [f, f * f, 1.0, 0.0, 0.0, 1.0, 10.0 * f, 200.0, 7.0]
                    .map(V::S)
                    .to_vec()
            })
            .collect(),
    };
    let face = El {
        name: "face",
        props: vec!["list uchar int vertex_indices"],
        rows: vec![
            vec![V::L(vec![0., 1., 2.])],
            vec![V::L(vec![0., 2., 3., 4.])],
            vec![V::L(vec![1., 2., 4.])],
        ],
    };
    ply(enc, &[vertex, face])
}

const OBJ: &str = "# a tetrahedron with normals and a material\nmtllib m.mtl\n\
v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 1\nvn 1 1 1\nusemtl red\n\
f 1//1 3//1 2//1\nf 1//2 2//2 4//2\nf 1 4 3\nf 2 3 4\nl 1 2 3\no part\nf 1 2 3 4\n";
const MTL: &str = "newmtl red\nKd 0.8 0.1 0.1\n";

/// Mutates `seed` `iters` times; each mutant is written as `name` and read.
fn fuzz(name: &str, seed: &[u8], rng_seed: u64, extra: &[(&str, &str)]) -> (usize, usize) {
    let iters = std::env::var("VOXLOD_FUZZ_ITERS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(150);
    let dir = TempDir::new("fuzz");
    for (n, text) in extra {
        dir.write(n, text);
    }
    // the seed itself is valid
    let path = dir.write(name, seed);
    if let Err(e) = read(&path) {
        panic!("{name}: the unmutated seed fails: {e}");
    }
    let mut rng = Rng(rng_seed);
    let (mut ok, mut err) = (0, 0);
    for i in 0..iters {
        let data = mutate(&mut rng, seed);
        std::fs::write(&path, &data).unwrap();
        match catch_unwind(AssertUnwindSafe(|| read(&path))) {
            Ok(Ok(_)) => ok += 1,
            Ok(Err(e)) => {
                let msg = e.to_string();
                assert!(
                    msg.contains(name),
                    "{name} mutant {i} (seed {rng_seed}): the error does not name the file: {msg}"
                );
                assert!(
                    !msg.contains("os error") || msg.matches("os error").count() == 1,
                    "{name} mutant {i}: an OS error repeated: {msg}"
                );
                err += 1;
            }
            Err(_) => {
                let keep = std::env::temp_dir().join(format!("voxlod-fuzz-panic-{name}"));
                std::fs::write(&keep, &data).unwrap();
                panic!(
                    "{name} mutant {i} (seed {rng_seed}) panicked; the input is saved as {}",
                    keep.display()
                );
            }
        }
    }
    eprintln!("{name}: {iters} mutants, {ok} read, {err} refused with an error");
    (ok, err)
}

#[test]
fn fuzz_ply_ascii() {
    fuzz("m.ply", &ply_seed("ascii"), 1, &[]);
}

#[test]
fn fuzz_ply_binary() {
    fuzz("le.ply", &ply_seed("binary_little_endian"), 2, &[]);
    fuzz("be.ply", &ply_seed("binary_big_endian"), 3, &[]);
}

#[test]
fn fuzz_ply_gzip() {
    fuzz("m.ply.gz", &gzip(&ply_seed("ascii")), 4, &[]);
}

#[test]
fn fuzz_obj() {
    fuzz("m.obj", OBJ.as_bytes(), 5, &[("m.mtl", MTL)]);
}

#[test]
fn fuzz_stl() {
    fuzz("a.stl", stl_ascii(&tetra()).as_bytes(), 6, &[]);
    fuzz("b.stl", &stl_binary(&tetra(), b"binary"), 7, &[]);
}
