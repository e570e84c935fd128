//! Seeded mutation fuzzing of every mesh parser, bounded to a few seconds so it runs in CI
//! (a fuzz target per parser). Small valid inputs, made here, are mutated — bit
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

fn iterations() -> usize {
    std::env::var("VOXLOD_FUZZ_ITERS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(150)
}

/// Mutates `seed` `iters` times; each mutant is written as `name` and read.
fn fuzz(name: &str, seed: &[u8], rng_seed: u64, extra: &[(&str, &str)]) -> (usize, usize) {
    let iters = iterations();
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
                // the glTF reader catches a panic of the gltf crate as a last resort: the
                // checks before it must leave none to catch
                assert!(
                    !msg.contains("panic of the gltf crate"),
                    "{name} mutant {i} (seed {rng_seed}) reached a panic: {msg}"
                );
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

/// A glTF seed: an indexed, coloured, textured quad (embedded PNG) and a strip, under a node
/// tree (a parent with a TRS child), written by the test kit as `name` (`.gltf` beside its
/// `.bin`, or `.glb`); returns the file's bytes.
fn gltf_seed(dir: &TempDir, name: &str) -> Vec<u8> {
    use voxlod_testkit::gltf::{write, Image, Mat, Node, Prim};
    let png = {
        let mut b = Vec::new();
        image_png_2x2(&mut b);
        b
    };
    let quad = Prim {
        colors: Some(vec![[1.0, 0.5, 0.25, 1.0]; 4]),
        ..Prim::textured_quad()
    };
    let strip = Prim {
        positions: vec![[0., 0., 1.], [1., 0., 1.], [0., 1., 1.], [1., 1., 2.]],
        mode: 5,
        ..Prim::default()
    };
    let mat = Mat {
        name: "m".into(),
        base_color: [1.0, 0.9, 0.8, 1.0],
        texture: Some(Image::View(png)),
        wrap: [10497, 33071],
    };
    let nodes = [
        Node {
            children: vec![1],
            ..Node::default()
        },
        Node {
            mesh: Some(0),
            translation: Some([1.0, 2.0, 3.0]),
            scale: Some([2.0, 2.0, 2.0]),
            ..Node::default()
        },
    ];
    let p = dir.path(name);
    write(&p, &[vec![quad, strip]], &nodes, &[0], &[mat]);
    std::fs::read(p).unwrap()
}

/// A 2×2 RGBA PNG, written by hand (stored deflate blocks) so the test needs no encoder.
fn image_png_2x2(out: &mut Vec<u8>) {
    fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend((data.len() as u32).to_be_bytes());
        let mut c = kind.to_vec();
        c.extend_from_slice(data);
        out.extend_from_slice(&c);
        out.extend(crc32(&c).to_be_bytes());
    }
    fn crc32(b: &[u8]) -> u32 {
        let mut c = !0u32;
        for &x in b {
            c ^= x as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xedb8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }
    let raw: Vec<u8> = [
        [0u8, 255, 0, 0, 255, 0, 255, 0, 255],
        [0, 0, 0, 255, 255, 255, 255, 255, 255],
    ]
    .concat();
    let (mut a, mut b) = (1u32, 0u32);
    for &x in &raw {
        a = (a + x as u32) % 65521;
        b = (b + a) % 65521;
    }
    let mut z = vec![0x78, 0x01, 1];
    z.extend((raw.len() as u16).to_le_bytes());
    z.extend((!(raw.len() as u16)).to_le_bytes());
    z.extend(&raw);
    z.extend(((b << 16) | a).to_be_bytes());
    out.extend(b"\x89PNG\r\n\x1a\n");
    let mut ihdr = Vec::new();
    ihdr.extend(2u32.to_be_bytes());
    ihdr.extend(2u32.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    chunk(out, b"IHDR", &ihdr);
    chunk(out, b"IDAT", &z);
    chunk(out, b"IEND", &[]);
}

/// One structural mutation of a glTF document: a value somewhere replaced by one the
/// specification's tables care about (a component type, an accessor type, a huge count, an
/// index out of range, a negative number, a wrong JSON kind), a key removed, an array
/// element duplicated or a node made its own ancestor.
fn mutate_json(rng: &mut Rng, v: &mut serde_json::Value) {
    use serde_json::{json, Value};
    // every path to a value
    fn paths(v: &Value, at: &mut Vec<Value>, out: &mut Vec<Vec<Value>>) {
        out.push(at.clone());
        match v {
            Value::Object(m) => {
                for (k, x) in m {
                    at.push(Value::String(k.clone()));
                    paths(x, at, out);
                    at.pop();
                }
            }
            Value::Array(a) => {
                for (i, x) in a.iter().enumerate() {
                    at.push(json!(i));
                    paths(x, at, out);
                    at.pop();
                }
            }
            _ => {}
        }
    }
    fn at<'a>(v: &'a mut Value, path: &[Value]) -> &'a mut Value {
        path.iter().fold(v, |v, k| match k {
            Value::String(s) => &mut v[s.as_str()],
            k => &mut v[k.as_u64().unwrap() as usize],
        })
    }
    let mut all = Vec::new();
    paths(v, &mut Vec::new(), &mut all);
    all.remove(0); // the root stays an object
    if !v.is_object() || all.is_empty() {
        return;
    }
    let path = all[rng.index(all.len())].clone();
    let replacements = [
        json!(5120),
        json!(5121),
        json!(5122),
        json!(5123),
        json!(5125),
        json!(5126),
        json!(0),
        json!(1),
        json!(2),
        json!(3),
        json!(4),
        json!(7),
        json!(-1),
        json!(255),
        json!(4294967296u64),
        json!(u64::MAX),
        json!(1e300),
        json!("SCALAR"),
        json!("VEC2"),
        json!("VEC3"),
        json!("VEC4"),
        json!("MAT4"),
        json!(null),
        json!([]),
        json!({}),
        json!(true),
        json!("../x.bin"),
        json!("data:application/octet-stream;base64,AAAA"),
    ];
    match rng.index(5) {
        0 | 1 => *at(v, &path) = replacements[rng.index(replacements.len())].clone(),
        2 => {
            if let Some((last, parent)) = path.split_last() {
                match (at(v, parent), last) {
                    (Value::Object(m), Value::String(k)) => {
                        m.remove(k);
                    }
                    (Value::Array(a), k) => {
                        let i = k.as_u64().unwrap() as usize;
                        let x = a[i].clone();
                        a.insert(i, x);
                    }
                    _ => {}
                }
            }
        }
        3 => {
            // a node made a child of itself or of its child
            let n = v["nodes"].as_array().map_or(0, Vec::len);
            if n > 0 {
                let (i, j) = (rng.index(n), rng.index(n));
                if !v["nodes"][i].is_object() {
                    return;
                }
                if let Some(c) = v["nodes"][i]["children"].as_array_mut() {
                    c.push(json!(j));
                } else {
                    v["nodes"][i]["children"] = json!([j]);
                }
            }
        }
        _ => {
            // a field set to a small or huge number where the tables look
            let keys = [
                "byteStride",
                "byteOffset",
                "count",
                "byteLength",
                "componentType",
                "normalized",
            ];
            let k = keys[rng.index(keys.len())];
            let list = ["accessors", "bufferViews", "buffers"][rng.index(3)];
            let n = v[list].as_array().map_or(0, Vec::len);
            if n > 0 {
                let x = [
                    json!(1),
                    json!(4),
                    json!(6),
                    json!(252),
                    json!(256),
                    json!(u32::MAX),
                    json!(true),
                ][rng.index(7)]
                .clone();
                let i = rng.index(n);
                if v[list][i].is_object() {
                    v[list][i][k] = x;
                }
            }
        }
    }
}

/// Structural mutants of a `.gltf` document (its `.bin` beside it, unchanged), each opened and
/// streamed in-process: no panic (none even caught inside the reader), every error naming the
/// file.
#[test]
fn fuzz_gltf_json() {
    let dir = TempDir::new("fuzzgltf");
    let seed = gltf_seed(&dir, "m.gltf");
    let path = dir.path("m.gltf");
    if let Err(e) = read(&path) {
        panic!("m.gltf: the unmutated seed fails: {e}");
    }
    let doc: serde_json::Value = serde_json::from_slice(&seed).unwrap();
    let mut rng = Rng(8);
    let (mut ok, mut err) = (0, 0);
    for i in 0..iterations() * 2 {
        let mut m = doc.clone();
        for _ in 0..1 + rng.index(2) {
            mutate_json(&mut rng, &mut m);
        }
        let data = serde_json::to_vec(&m).unwrap();
        std::fs::write(&path, &data).unwrap();
        match catch_unwind(AssertUnwindSafe(|| read(&path))) {
            Ok(Ok(_)) => ok += 1,
            Ok(Err(e)) => {
                let msg = e.to_string();
                assert!(
                    msg.contains("m.gltf"),
                    "mutant {i}: the error does not name the file: {msg}"
                );
                assert!(
                    !msg.contains("panic of the gltf crate"),
                    "mutant {i} reached a panic of the gltf crate: {msg}\n{}",
                    String::from_utf8_lossy(&data)
                );
                err += 1;
            }
            Err(_) => {
                let keep = std::env::temp_dir().join("voxlod-fuzz-panic-m.gltf");
                std::fs::write(&keep, &data).unwrap();
                panic!(
                    "m.gltf mutant {i} panicked; the input is saved as {}",
                    keep.display()
                );
            }
        }
    }
    eprintln!(
        "m.gltf: {} mutants, {ok} read, {err} refused with an error",
        ok + err
    );
    assert!(
        ok > 0 && err > 0,
        "{ok} read, {err} refused: the mutants test nothing"
    );
}

/// Byte mutants of a GLB (header, chunk lengths, JSON and binary chunk alike).
#[test]
fn fuzz_glb() {
    let dir = TempDir::new("glbseed");
    let seed = gltf_seed(&dir, "seed.glb");
    fuzz("m.glb", &seed, 9, &[]);
}
