//! Made-up meshes and a minimal mesh reader for tests.
//!
//! The reader is deliberately independent of `voxlod-ingest` (a few dozen lines, positions
//! and faces only, panicking on anything unexpected) so a test can compare the real reader
//! against it, and so voxelizer tests need not depend on ingest.

use std::collections::HashMap;
use std::path::Path;

/// An indexed mesh: positions and triangles (indices into the positions).
pub type Indexed = (Vec<[f64; 3]>, Vec<[u32; 3]>);

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// A closed unit icosphere with `subdiv` midpoint subdivisions: vertices and consistently
/// outward-wound (counter-clockwise seen from outside) triangles; 20·4^subdiv faces.
pub fn icosphere(subdiv: u32) -> Indexed {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let norm = |p: [f64; 3]| {
        let l = dot(p, p).sqrt();
        [p[0] / l, p[1] / l, p[2] / l]
    };
    let mut v: Vec<[f64; 3]> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .map(norm)
    .to_vec();
    #[rustfmt::skip]
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
        [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
        [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
        [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
    ];
    for _ in 0..subdiv {
        // split every edge once (midpoints shared through `mid`), each face into four
        let mut mid = HashMap::new();
        let mut nf = Vec::with_capacity(f.len() * 4);
        for tri in &f {
            let mut m = [0u32; 3];
            for i in 0..3 {
                let (a, b) = (tri[i], tri[(i + 1) % 3]);
                m[i] = *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let (pa, pb) = (v[a as usize], v[b as usize]);
                    v.push(norm([0, 1, 2].map(|k| (pa[k] + pb[k]) / 2.0)));
                    (v.len() - 1) as u32
                });
            }
            nf.push([tri[0], m[0], m[2]]);
            nf.push([tri[1], m[1], m[0]]);
            nf.push([tri[2], m[2], m[1]]);
            nf.push([m[0], m[1], m[2]]);
        }
        f = nf;
    }
    (v, f)
}

/// The closed cube `[-1, 1]³`, outward wound, 12 triangles.
pub fn cube() -> Indexed {
    let v: Vec<[f64; 3]> = (0..8)
        .map(|i| [0, 1, 2].map(|k| if i >> k & 1 == 1 { 1.0 } else { -1.0 }))
        .collect();
    #[rustfmt::skip]
    let f = vec![
        [0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], // z = -1, z = +1
        [0, 1, 5], [0, 5, 4], [2, 6, 7], [2, 7, 3], // y = -1, y = +1
        [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5], // x = -1, x = +1
    ];
    (v, f)
}

/// Applies `p ↦ s·R·p + t` to every vertex.
pub fn transform(v: &[[f64; 3]], r: [[f64; 3]; 3], s: f64, t: [f64; 3]) -> Vec<[f64; 3]> {
    v.iter()
        .map(|p| [0, 1, 2].map(|i| s * dot(r[i], *p) + t[i]))
        .collect()
}

/// The mesh's bounding cube: the lower corner of its bounding box and the box's largest edge.
pub fn bounding_cube(v: &[[f64; 3]]) -> ([f64; 3], f64) {
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    for p in v {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max))
}

/// The vertices fitted into a grid: the bounding cube scaled to `extent` voxels and shifted by
/// `offset` voxels on every axis, rounded to f32 (`((p − lo) / size · extent + offset) as f32`).
pub fn fit_to_grid(v: &[[f64; 3]], extent: f64, offset: f64) -> Vec<[f32; 3]> {
    let (lo, size) = bounding_cube(v);
    v.iter()
        .map(|p| [0, 1, 2].map(|k| ((p[k] - lo[k]) / size * extent + offset) as f32))
        .collect()
}

/// The triangles of an indexed mesh as vertex triples.
pub fn triangles(m: &Indexed) -> Vec<[[f64; 3]; 3]> {
    m.1.iter().map(|f| f.map(|i| m.0[i as usize])).collect()
}

/// The triangles of an indexed mesh as f32 vertex triples (rounded to nearest).
pub fn triangles_f32(m: &Indexed) -> Vec<[[f32; 3]; 3]> {
    m.1.iter()
        .map(|f| f.map(|i| m.0[i as usize].map(|c| c as f32)))
        .collect()
}

/// Polygons fan-triangulated around their first vertex, as the readers of voxlod do.
fn fan(polys: &[Vec<u32>]) -> Vec<[u32; 3]> {
    let mut out = Vec::new();
    for p in polys {
        for k in 1..p.len().saturating_sub(1) {
            out.push([p[0], p[k], p[k + 1]]);
        }
    }
    out
}

/// Reads a mesh by extension: `.ply` or `.obj` (see [`read_ply`], [`read_obj`]).
pub fn read_mesh(path: &Path) -> Indexed {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("ply") => read_ply(path),
        Some(e) if e.eq_ignore_ascii_case("obj") => read_obj(path),
        _ => panic!("{}: not a .ply or .obj", path.display()),
    }
}

/// Bytes of a PLY scalar type, or None for an unknown name.
fn scalar_size(t: &str) -> Option<usize> {
    Some(match t {
        "char" | "uchar" | "int8" | "uint8" => 1,
        "short" | "ushort" | "int16" | "uint16" => 2,
        "int" | "uint" | "float" | "int32" | "uint32" | "float32" => 4,
        "double" | "float64" => 8,
        _ => return None,
    })
}

/// Reads one binary scalar of type `t` at `at` as f64.
fn scalar(d: &[u8], at: usize, t: &str, le: bool) -> f64 {
    let n = scalar_size(t).unwrap_or_else(|| panic!("PLY type {t}"));
    let mut b = [0u8; 8];
    b[..n].copy_from_slice(&d[at..at + n]);
    if !le {
        b[..n].reverse();
    }
    match t {
        "char" | "int8" => b[0] as i8 as f64,
        "uchar" | "uint8" => b[0] as f64,
        "short" | "int16" => i16::from_le_bytes([b[0], b[1]]) as f64,
        "ushort" | "uint16" => u16::from_le_bytes([b[0], b[1]]) as f64,
        "int" | "int32" => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        "uint" | "uint32" => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        "float" | "float32" => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        _ => f64::from_le_bytes(b),
    }
}

/// One PLY element of the header: name, count and properties (name, type, list count type).
struct Element {
    name: String,
    count: usize,
    props: Vec<(String, String, Option<String>)>,
}

/// Reads a PLY's positions and faces (fan-triangulated): ASCII, binary little- or big-endian;
/// `x y z` by name among any scalar vertex properties; the face element's `vertex_indices`
/// (or `vertex_index`) list; other elements skipped. Panics on anything else (a test helper).
pub fn read_ply(path: &Path) -> Indexed {
    let d = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    // the header may end its lines with \r\n (bun_zipper.ply does)
    let at = d
        .windows(10)
        .position(|w| w == b"end_header")
        .expect("no end_header");
    let body = at
        + d[at..]
            .iter()
            .position(|&b| b == b'\n')
            .expect("header end")
        + 1;
    let header = std::str::from_utf8(&d[..body]).expect("ASCII header");
    let mut els: Vec<Element> = Vec::new();
    let mut format = "";
    for line in header.lines() {
        match line.split_whitespace().collect::<Vec<_>>().as_slice() {
            ["format", f, _] => format = f,
            ["element", name, n] => els.push(Element {
                name: name.to_string(),
                count: n.parse().expect("element count"),
                props: Vec::new(),
            }),
            ["property", "list", ct, it, name] => els.last_mut().expect("element").props.push((
                name.to_string(),
                it.to_string(),
                Some(ct.to_string()),
            )),
            ["property", t, name] => {
                els.last_mut()
                    .expect("element")
                    .props
                    .push((name.to_string(), t.to_string(), None))
            }
            _ => {}
        }
    }
    let mut verts = Vec::new();
    let mut polys: Vec<Vec<u32>> = Vec::new();
    let is_index = |n: &str| n == "vertex_indices" || n == "vertex_index";
    if format == "ascii" {
        let text = std::str::from_utf8(&d[body..]).expect("ASCII body");
        let mut words = text
            .split_whitespace()
            .map(|w| w.parse::<f64>().expect("number"));
        for el in &els {
            for _ in 0..el.count {
                let mut p = [0.0; 3];
                for (name, _, list) in &el.props {
                    if list.is_some() {
                        let n = words.next().expect("list count") as usize;
                        let idx: Vec<u32> = (0..n).map(|_| words.next().unwrap() as u32).collect();
                        if el.name == "face" && is_index(name) {
                            polys.push(idx);
                        }
                    } else {
                        let x = words.next().expect("value");
                        if let Some(k) = ["x", "y", "z"].iter().position(|a| a == name) {
                            p[k] = x;
                        }
                    }
                }
                if el.name == "vertex" {
                    verts.push(p);
                }
            }
        }
    } else {
        let le = match format {
            "binary_little_endian" => true,
            "binary_big_endian" => false,
            f => panic!("PLY format {f}"),
        };
        let mut o = body;
        for el in &els {
            for _ in 0..el.count {
                let mut p = [0.0; 3];
                for (name, t, list) in &el.props {
                    if let Some(ct) = list {
                        let n = scalar(&d, o, ct, le) as usize;
                        o += scalar_size(ct).expect("count type");
                        let s = scalar_size(t).expect("index type");
                        let idx: Vec<u32> = (0..n)
                            .map(|j| scalar(&d, o + j * s, t, le) as u32)
                            .collect();
                        o += n * s;
                        if el.name == "face" && is_index(name) {
                            polys.push(idx);
                        }
                    } else {
                        if let Some(k) = ["x", "y", "z"].iter().position(|a| a == name) {
                            p[k] = scalar(&d, o, t, le);
                        }
                        o += scalar_size(t).expect("scalar type");
                    }
                }
                if el.name == "vertex" {
                    verts.push(p);
                }
            }
        }
    }
    (verts, fan(&polys))
}

/// Reads an OBJ's positions and faces (fan-triangulated): `v` and `f` lines only, `i/t/n`
/// corners and negative (relative) indices supported.
pub fn read_obj(path: &Path) -> Indexed {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut verts = Vec::new();
    let mut polys = Vec::new();
    for line in text.lines() {
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") => {
                let f: Vec<f64> = w.take(3).map(|s| s.parse().expect("v")).collect();
                verts.push([f[0], f[1], f[2]]);
            }
            Some("f") => {
                let n = verts.len() as i64;
                polys.push(
                    w.map(|s| {
                        let i: i64 = s.split('/').next().unwrap().parse().expect("f");
                        (if i < 0 { n + i } else { i - 1 }) as u32
                    })
                    .collect(),
                );
            }
            _ => {}
        }
    }
    (verts, fan(&polys))
}

/// Writes a binary little-endian PLY with `float x y z` vertices and `list uchar uint`
/// triangles (what the bundled sample and most scans use).
pub fn write_ply(path: &Path, m: &Indexed) {
    let mut out = voxlod_io::PlyHeader::binary_le()
        .element("vertex", m.0.len() as u64)
        .properties("float", &["x", "y", "z"])
        .element("face", m.1.len() as u64)
        .list("uchar", "uint", "vertex_indices")
        .end()
        .into_bytes();
    for p in &m.0 {
        for c in p {
            out.extend_from_slice(&(*c as f32).to_le_bytes());
        }
    }
    for f in &m.1 {
        out.push(3);
        for i in f {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    std::fs::write(path, out).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Euler characteristic 2 and every edge shared by exactly two faces in opposite
    /// directions: closed and consistently wound.
    fn closed_and_oriented(m: &Indexed) {
        let mut edges = HashMap::new();
        for f in &m.1 {
            for i in 0..3 {
                *edges.entry((f[i], f[(i + 1) % 3])).or_insert(0) += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1);
            assert_eq!(edges.get(&(b, a)), Some(&1));
        }
        let e = edges.len() / 2;
        assert_eq!(m.0.len() + m.1.len() - e, 2);
    }

    #[test]
    fn made_up_meshes_are_closed_and_oriented() {
        closed_and_oriented(&icosphere(0));
        closed_and_oriented(&icosphere(2));
        closed_and_oriented(&cube());
        // outward: the signed volume is positive
        let (v, f) = icosphere(2);
        let vol: f64 = f
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| v[i as usize]);
                let bc = [
                    b[1] * c[2] - b[2] * c[1],
                    b[2] * c[0] - b[0] * c[2],
                    b[0] * c[1] - b[1] * c[0],
                ];
                dot(a, bc) / 6.0
            })
            .sum();
        assert!(vol > 3.5 && vol < 4.19, "{vol}");
    }

    #[test]
    fn ply_and_obj_round_trip() {
        let dir = std::env::temp_dir().join(format!("voxlod-testkit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let m = icosphere(1);
        let p = dir.join("s.ply");
        write_ply(&p, &m);
        let back = read_ply(&p);
        assert_eq!(back.1, m.1);
        for (a, b) in back.0.iter().zip(&m.0) {
            assert_eq!(*a, b.map(|c| c as f32 as f64));
        }
        // ASCII with an extra property, a quad and a CRLF header
        let a = dir.join("a.ply");
        std::fs::write(&a, "ply\r\nformat ascii 1.0\r\nelement vertex 4\r\nproperty uchar red\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\nelement face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n9 0 0 0\n9 1 0 0\n9 1 1 0\n9 0 1 0\n4 0 1 2 3\n").unwrap();
        let q = read_ply(&a);
        assert_eq!(q.1, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(q.0[2], [1.0, 1.0, 0.0]);
        let o = dir.join("q.obj");
        std::fs::write(&o, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1 2/2 -2 -1\n").unwrap();
        assert_eq!(read_obj(&o), q);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
