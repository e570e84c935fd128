//! Shared test helpers: a small deterministic RNG, independent brute-force references, made-up
//! meshes and a reader for the binary PLY test meshes.
#![allow(dead_code)]

use std::path::PathBuf;

pub mod adversarial;

/// SplitMix64.
pub struct Rng(pub u64);
impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.f64()
    }
    pub fn int(&mut self, a: i64, b: i64) -> i64 {
        a + (self.next_u64() % ((b - a + 1) as u64)) as i64
    }
    pub fn point(&mut self, a: f64, b: f64) -> [f64; 3] {
        [self.range(a, b), self.range(a, b), self.range(a, b)]
    }
    /// A random rotation matrix (from a random unit quaternion).
    pub fn rotation(&mut self) -> [[f64; 3]; 3] {
        let (u1, u2, u3) = (self.f64(), self.f64(), self.f64());
        let tau = std::f64::consts::TAU;
        let q = [
            (1.0 - u1).sqrt() * (tau * u2).sin(),
            (1.0 - u1).sqrt() * (tau * u2).cos(),
            u1.sqrt() * (tau * u3).sin(),
            u1.sqrt() * (tau * u3).cos(),
        ];
        let (x, y, z, w) = (q[0], q[1], q[2], q[3]);
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - z * w),
                2.0 * (x * z + y * w),
            ],
            [
                2.0 * (x * y + z * w),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - x * w),
            ],
            [
                2.0 * (x * z - y * w),
                2.0 * (y * z + x * w),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }
}

pub fn f32tri(t: [[f64; 3]; 3]) -> [[f32; 3]; 3] {
    t.map(|p| p.map(|c| c as f32))
}
pub fn f64tri(t: &[[f32; 3]; 3]) -> [[f64; 3]; 3] {
    t.map(|p| p.map(|c| c as f64))
}

pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub fn tri_area(t: &[[f64; 3]; 3]) -> f64 {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    0.5 * dot(n, n).sqrt()
}

/// Result of a brute-force separating-axis test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sat {
    /// No axis strictly separates.
    pub overlap: bool,
    /// Some axis has separation exactly 0 (the closed sets just touch along it).
    pub tie: bool,
}

fn sat_axes(
    t: &[[f64; 3]; 3],
    c: [f64; 3],
    axes: &[[f64; 3]],
    radius: impl Fn([f64; 3]) -> f64,
) -> Sat {
    let u = [sub(t[0], c), sub(t[1], c), sub(t[2], c)];
    let mut overlap = true;
    let mut tie = false;
    for &a in axes {
        if a == [0.0; 3] {
            continue;
        }
        let p = [dot(u[0], a), dot(u[1], a), dot(u[2], a)];
        let lo = p[0].min(p[1]).min(p[2]);
        let hi = p[0].max(p[1]).max(p[2]);
        let r = radius(a);
        let s = (lo - r).max(-r - hi);
        if s > 0.0 {
            overlap = false;
        }
        if s == 0.0 {
            tie = true;
        }
    }
    Sat { overlap, tie }
}

/// Akenine-Möller's triangle/box test with the closed box `[p, p+1]³`, 13 axes, in f64.
pub fn sat_box(t: &[[f64; 3]; 3], p: [i32; 3]) -> Sat {
    let c = p.map(|x| x as f64 + 0.5);
    let e = [sub(t[1], t[0]), sub(t[2], t[1]), sub(t[0], t[2])];
    let unit = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let mut axes = vec![unit[0], unit[1], unit[2], cross(e[0], e[1])];
    for ei in e {
        for u in unit {
            axes.push(cross(ei, u));
        }
    }
    sat_axes(t, c, &axes, |a| {
        0.5 * (a[0].abs() + a[1].abs() + a[2].abs())
    })
}

/// Triangle against the closed diamond (octahedron) `|x − (p+½)|₁ ≤ ½` inscribed in voxel `p`:
/// separating axes are the triangle normal, the 4 face normals of the octahedron and the 18
/// cross products of triangle edges with octahedron edges.
pub fn sat_diamond(t: &[[f64; 3]; 3], p: [i32; 3]) -> Sat {
    let c = p.map(|x| x as f64 + 0.5);
    let e = [sub(t[1], t[0]), sub(t[2], t[1]), sub(t[0], t[2])];
    let mut axes = vec![
        cross(e[0], e[1]),
        [1.0, 1.0, 1.0],
        [1.0, 1.0, -1.0],
        [1.0, -1.0, 1.0],
        [-1.0, 1.0, 1.0],
    ];
    let dirs = [
        [1.0, 1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 0.0, 1.0],
        [1.0, 0.0, -1.0],
        [0.0, 1.0, 1.0],
        [0.0, 1.0, -1.0],
    ];
    for ei in e {
        for d in dirs {
            axes.push(cross(ei, d));
        }
    }
    sat_axes(t, c, &axes, |a| {
        0.5 * a[0].abs().max(a[1].abs()).max(a[2].abs())
    })
}

/// The thin test's definition evaluated directly per voxel: closed bounding box, the plane
/// against the 6 vertices of the voxel's diamond, and in each coordinate projection each edge's
/// inner half-plane against the 4 vertices of the projected diamond. `tie` if a deciding value
/// is exactly 0.
pub fn thin_reference(t: &[[f64; 3]; 3], p: [i32; 3]) -> Sat {
    let mut tie = false;
    for k in 0..3 {
        let lo = t[0][k].min(t[1][k]).min(t[2][k]);
        let hi = t[0][k].max(t[1][k]).max(t[2][k]);
        let (a, b) = (p[k] as f64, p[k] as f64 + 1.0);
        if b < lo || a > hi {
            return Sat {
                overlap: false,
                tie: false,
            };
        }
        if b == lo || a == hi {
            tie = true;
        }
    }
    let c = p.map(|x| x as f64 + 0.5);
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let mut mn = f64::INFINITY;
    let mut mx = f64::NEG_INFINITY;
    for k in 0..3 {
        for s in [-0.5, 0.5] {
            let mut q = c;
            q[k] += s;
            let f = dot(n, sub(q, t[0]));
            mn = mn.min(f);
            mx = mx.max(f);
        }
    }
    let mut overlap = mn <= 0.0 && mx >= 0.0;
    if mn == 0.0 || mx == 0.0 {
        tie = true;
    }
    for (a, b) in [(0usize, 1usize), (1, 2), (2, 0)] {
        let q = t.map(|v| [v[a], v[b]]);
        let cr = |o: [f64; 2], u: [f64; 2], w: [f64; 2]| {
            (u[0] - o[0]) * (w[1] - o[1]) - (u[1] - o[1]) * (w[0] - o[0])
        };
        let orient = cr(q[0], q[1], q[2]);
        if orient == 0.0 {
            continue;
        }
        let o = orient.signum();
        let cc = [c[a], c[b]];
        let dv = [
            [cc[0] - 0.5, cc[1]],
            [cc[0] + 0.5, cc[1]],
            [cc[0], cc[1] - 0.5],
            [cc[0], cc[1] + 0.5],
        ];
        for i in 0..3 {
            let best = dv
                .iter()
                .map(|&x| o * cr(q[i], q[(i + 1) % 3], x))
                .fold(f64::NEG_INFINITY, f64::max);
            if best < 0.0 {
                overlap = false;
            }
            if best == 0.0 {
                tie = true;
            }
        }
    }
    Sat { overlap, tie }
}

/// Triangle categories for randomized tests, all inside roughly `[0, span]³`.
pub fn random_triangle(rng: &mut Rng, kind: usize, span: f64) -> [[f64; 3]; 3] {
    let s = span;
    match kind % 8 {
        // general
        0 => [rng.point(0.0, s), rng.point(0.0, s), rng.point(0.0, s)],
        // sub-voxel
        1 => {
            let a = rng.point(1.0, s - 1.0);
            let d = rng.range(0.01, 0.6);
            [a, add(a, rng.point(-d, d)), add(a, rng.point(-d, d))]
        }
        // sliver: third vertex near the segment of the first two
        2 => {
            let a = rng.point(0.0, s);
            let b = rng.point(0.0, s);
            let t = rng.f64();
            let m = [
                a[0] + t * (b[0] - a[0]),
                a[1] + t * (b[1] - a[1]),
                a[2] + t * (b[2] - a[2]),
            ];
            [a, b, add(m, rng.point(-1e-3, 1e-3))]
        }
        // axis-aligned plane at a float or integer coordinate
        3 => {
            let k = rng.int(0, 2) as usize;
            let c = if rng.f64() < 0.5 {
                rng.int(1, s as i64 - 1) as f64
            } else {
                rng.range(1.0, s - 1.0)
            };
            let mut t = [rng.point(0.0, s), rng.point(0.0, s), rng.point(0.0, s)];
            for v in &mut t {
                v[k] = c;
            }
            t
        }
        // integer coordinates (ties everywhere)
        4 => {
            let m = (s as i64).min(10);
            let mut p = || {
                [
                    rng.int(0, m) as f64,
                    rng.int(0, m) as f64,
                    rng.int(0, m) as f64,
                ]
            };
            [p(), p(), p()]
        }
        // half-integer / quarter coordinates, small
        5 => {
            let mut p = || [0, 1, 2].map(|_| rng.int(0, 24) as f64 * 0.25);
            [p(), p(), p()]
        }
        // large, reaching outside the window
        6 => [
            rng.point(-2.0 * s, 3.0 * s),
            rng.point(-2.0 * s, 3.0 * s),
            rng.point(-2.0 * s, 3.0 * s),
        ],
        // edge aligned with an axis (two vertices share two coordinates)
        _ => {
            let a = rng.point(0.0, s);
            let mut b = a;
            let k = rng.int(0, 2) as usize;
            b[k] = rng.range(0.0, s);
            [a, b, rng.point(0.0, s)]
        }
    }
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// A closed icosphere: vertices and consistently outward-wound faces.
pub fn icosphere(subdiv: u32) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = vec![
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
    ];
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let norm = |p: [f64; 3]| {
        let l = dot(p, p).sqrt();
        [p[0] / l, p[1] / l, p[2] / l]
    };
    for p in &mut v {
        *p = norm(*p);
    }
    for _ in 0..subdiv {
        let mut mid = std::collections::HashMap::new();
        let mut nf = Vec::with_capacity(f.len() * 4);
        for tri in &f {
            let mut m = [0u32; 3];
            for i in 0..3 {
                let (a, b) = (tri[i], tri[(i + 1) % 3]);
                let key = (a.min(b), a.max(b));
                m[i] = *mid.entry(key).or_insert_with(|| {
                    let (pa, pb) = (v[a as usize], v[b as usize]);
                    v.push(norm([
                        (pa[0] + pb[0]) / 2.0,
                        (pa[1] + pb[1]) / 2.0,
                        (pa[2] + pb[2]) / 2.0,
                    ]));
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

/// A closed cube `[-1, 1]³`, outward wound.
pub fn cube() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let v: Vec<[f64; 3]> = (0..8)
        .map(|i| [0, 1, 2].map(|k| if i >> k & 1 == 1 { 1.0 } else { -1.0 }))
        .collect();
    let f = vec![
        [0, 2, 3],
        [0, 3, 1],
        [4, 5, 7],
        [4, 7, 6], // z = -1, z = +1
        [0, 1, 5],
        [0, 5, 4],
        [2, 6, 7],
        [2, 7, 3], // y = -1, y = +1
        [0, 4, 6],
        [0, 6, 2],
        [1, 3, 7],
        [1, 7, 5], // x = -1, x = +1
    ];
    (v, f)
}

/// Applies `p ↦ s·R·p + t` to every vertex.
pub fn transform(v: &[[f64; 3]], r: [[f64; 3]; 3], s: f64, t: [f64; 3]) -> Vec<[f64; 3]> {
    v.iter()
        .map(|p| [0, 1, 2].map(|i| s * dot(r[i], *p) + t[i]))
        .collect()
}

/// `../shared/data/meshes`, or `None` (after printing why) when it is missing; a failure when
/// `CI=true`.
pub fn shared_meshes() -> Option<PathBuf> {
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
    eprintln!(
        "SKIPPED: {} not found; the real-mesh part of this test did not run",
        p.display()
    );
    None
}

/// Reads a binary little-endian PLY with `float x, y, z` vertices (no other vertex properties)
/// and `list uchar int` triangle faces, like `npm-bunny/bunny.ply`.
pub fn read_simple_ply(path: &std::path::Path) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let d = std::fs::read(path).expect("read ply");
    let end = d
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("ply header")
        + 11;
    let header = std::str::from_utf8(&d[..end]).expect("ascii header");
    assert!(
        header.contains("binary_little_endian"),
        "unsupported PLY: {header}"
    );
    let count = |name: &str| -> usize {
        header
            .lines()
            .find_map(|l| l.strip_prefix(&format!("element {name} ")))
            .expect("element")
            .trim()
            .parse()
            .expect("count")
    };
    let (nv, nf) = (count("vertex"), count("face"));
    let f32at = |o: usize| f32::from_le_bytes(d[o..o + 4].try_into().unwrap()) as f64;
    let verts: Vec<[f64; 3]> = (0..nv)
        .map(|i| [0, 1, 2].map(|k| f32at(end + 12 * i + 4 * k)))
        .collect();
    let mut o = end + 12 * nv;
    let mut faces = Vec::with_capacity(nf);
    for _ in 0..nf {
        assert_eq!(d[o], 3, "only triangles");
        let idx =
            |k: usize| u32::from_le_bytes(d[o + 1 + 4 * k..o + 5 + 4 * k].try_into().unwrap());
        faces.push([idx(0), idx(1), idx(2)]);
        o += 13;
    }
    (verts, faces)
}
