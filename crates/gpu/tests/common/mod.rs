//! Test helpers: minimal mesh loaders (binary/ASCII PLY with float x y z and a face list, OBJ
//! `v`/`f` lines), grid fitting, a deterministic RNG and the CPU-vs-GPU comparison.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use voxlod_format::voxel::unpack_normal;
use voxlod_format::Voxel;
use voxlod_geom::{Bounds, Grid, Triangle};

/// The shared meshes folder, or None (test skipped, with a message) when it is missing;
/// with CI=true a missing folder is a failure.
pub fn meshes_dir() -> Option<PathBuf> {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/meshes"
    ));
    if p.is_dir() {
        return Some(p);
    }
    if std::env::var("CI").as_deref() == Ok("true") {
        panic!("{} is missing and CI=true", p.display());
    }
    eprintln!("skipped: {} is missing", p.display());
    None
}

/// Positions of a PLY's triangles (fan-triangulated polygons). Supports binary_little_endian
/// and ascii with float vertex properties of which x y z are the first three, and a face
/// `list uchar int|uint` of vertex indices as the only face property.
pub fn load_ply(path: &Path) -> Vec<[[f32; 3]; 3]> {
    let data = std::fs::read(path).unwrap();
    // the header may end its lines with \r\n (bun_zipper.ply does)
    let at = data
        .windows(10)
        .position(|w| w == b"end_header")
        .expect("no end_header");
    let end = at
        + data[at..]
            .iter()
            .position(|&b| b == b'\n')
            .expect("no newline after end_header")
        + 1;
    let header = std::str::from_utf8(&data[..end]).unwrap();
    let ascii = header.contains("format ascii");
    let mut nv = 0usize;
    let mut nf = 0usize;
    let mut vprops = 0usize;
    let mut elem = "";
    for line in header.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["element", name, n] => {
                elem = if *name == "vertex" {
                    "vertex"
                } else if *name == "face" {
                    "face"
                } else {
                    "other"
                };
                if elem == "vertex" {
                    nv = n.parse().unwrap();
                } else if elem == "face" {
                    nf = n.parse().unwrap();
                }
            }
            ["property", "float", _] if elem == "vertex" => vprops += 1,
            _ => {}
        }
    }
    let mut verts = Vec::with_capacity(nv);
    let mut faces: Vec<Vec<usize>> = Vec::with_capacity(nf);
    if ascii {
        let body = std::str::from_utf8(&data[end..]).unwrap();
        let mut lines = body.lines();
        for _ in 0..nv {
            let f: Vec<f32> = lines
                .next()
                .unwrap()
                .split_whitespace()
                .map(|s| s.parse().unwrap())
                .collect();
            verts.push([f[0], f[1], f[2]]);
        }
        for _ in 0..nf {
            let f: Vec<usize> = lines
                .next()
                .unwrap()
                .split_whitespace()
                .map(|s| s.parse().unwrap())
                .collect();
            faces.push(f[1..=f[0]].to_vec());
        }
    } else {
        assert!(header.contains("binary_little_endian"));
        let mut at = end;
        let f32_at = |i: usize| f32::from_le_bytes(data[i..i + 4].try_into().unwrap());
        for _ in 0..nv {
            verts.push([f32_at(at), f32_at(at + 4), f32_at(at + 8)]);
            at += 4 * vprops;
        }
        for _ in 0..nf {
            let k = data[at] as usize;
            at += 1;
            let f = (0..k)
                .map(|j| {
                    u32::from_le_bytes(data[at + 4 * j..at + 4 * j + 4].try_into().unwrap())
                        as usize
                })
                .collect();
            at += 4 * k;
            faces.push(f);
        }
    }
    fan(&verts, &faces)
}

/// Positions of an OBJ's triangles (`v` and `f` lines only; negative indices supported).
pub fn load_obj(path: &Path) -> Vec<[[f32; 3]; 3]> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut verts = Vec::new();
    let mut faces = Vec::new();
    for line in text.lines() {
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") => {
                let f: Vec<f32> = w.take(3).map(|s| s.parse().unwrap()).collect();
                verts.push([f[0], f[1], f[2]]);
            }
            Some("f") => {
                let f: Vec<usize> = w
                    .map(|s| {
                        let i: i64 = s.split('/').next().unwrap().parse().unwrap();
                        if i < 0 {
                            (verts.len() as i64 + i) as usize
                        } else {
                            i as usize - 1
                        }
                    })
                    .collect();
                faces.push(f);
            }
            _ => {}
        }
    }
    fan(&verts, &faces)
}

fn fan(verts: &[[f32; 3]], faces: &[Vec<usize>]) -> Vec<[[f32; 3]; 3]> {
    let mut out = Vec::new();
    for f in faces {
        for k in 1..f.len().saturating_sub(1) {
            out.push([verts[f[0]], verts[f[k]], verts[f[k + 1]]]);
        }
    }
    out
}

/// The mesh in grid coordinates of a `res`³ grid fitted to its bounds.
pub fn to_grid(tris: &[[[f32; 3]; 3]], res: u32) -> Vec<Triangle> {
    let mut b = Bounds::default();
    for t in tris {
        for v in t {
            b.add_point(*v);
        }
    }
    let g = Grid::fit(&b, res).unwrap();
    tris.iter()
        .map(|t| Triangle::new(t.map(|v| g.to_grid(v))))
        .collect()
}

/// xorshift64*.
pub struct Rng(pub u64);
impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in [0, 1).
    pub fn f(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }
}

/// Random per-vertex colours and (for every other triangle) random vertex normals.
pub fn decorate(t: &mut Triangle, rng: &mut Rng, normals: bool) {
    for k in 0..3 {
        t.c[k] = [
            rng.next() as u8,
            rng.next() as u8,
            rng.next() as u8,
            rng.next() as u8,
        ];
    }
    t.flags |= voxlod_geom::TRI_HAS_COLORS;
    if normals {
        for k in 0..3 {
            t.n[k] = [
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ];
        }
        t.flags |= voxlod_geom::TRI_HAS_NORMALS;
    }
}

/// Differences between two voxel lists of one chunk.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct Diff {
    pub cpu: usize,
    pub gpu: usize,
    /// voxels only one side has
    pub only_cpu: usize,
    pub only_gpu: usize,
    /// common voxels whose normal differs by more than one quantization step in a component
    pub normal: usize,
    /// common voxels whose colour differs by more than 1 in a channel
    pub colour: usize,
    /// common voxels with different face masks although their normals are equal
    pub mask: usize,
    /// common voxels not bit-identical
    pub inexact: usize,
}

pub fn compare(cpu: &[Voxel], gpu: &[Voxel]) -> Diff {
    let mut d = Diff {
        cpu: cpu.len(),
        gpu: gpu.len(),
        ..Diff::default()
    };
    for w in gpu.windows(2) {
        assert!(
            w[0].morton() < w[1].morton(),
            "GPU voxels not sorted by Morton code / duplicated"
        );
    }
    let (mut i, mut j) = (0, 0);
    while i < cpu.len() || j < gpu.len() {
        let mc = cpu.get(i).map(|v| v.morton()).unwrap_or(u32::MAX);
        let mg = gpu.get(j).map(|v| v.morton()).unwrap_or(u32::MAX);
        if mc < mg {
            d.only_cpu += 1;
            i += 1;
        } else if mg < mc {
            d.only_gpu += 1;
            j += 1;
        } else {
            let (a, b) = (cpu[i], gpu[j]);
            if a != b {
                d.inexact += 1;
            }
            let (na, nb) = (unpack_normal(a.normal), unpack_normal(b.normal));
            if (0..3).any(|k| (na[k] - nb[k]).abs() > 1) {
                d.normal += 1;
            }
            let (ca, cb) = (a.rgba(), b.rgba());
            if (0..4).any(|k| (ca[k] as i32 - cb[k] as i32).abs() > 1) {
                d.colour += 1;
            }
            if a.normal == b.normal && a.mask() != b.mask() {
                d.mask += 1;
            }
            i += 1;
            j += 1;
        }
    }
    d
}
