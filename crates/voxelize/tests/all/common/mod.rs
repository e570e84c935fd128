//! Shared test helpers: a small deterministic RNG, independent brute-force references, made-up
//! meshes and a reader for the binary PLY test meshes.
#![allow(dead_code)]

use std::path::PathBuf;

pub mod adversarial;
pub mod world_ref;

use voxlod_geom::{Triangle, TRI_HAS_COLORS, TRI_HAS_NORMALS};
#[allow(unused_imports)] // each test binary uses a different part
pub use voxlod_testkit::mesh::{cube, icosphere, read_ply, transform};
pub use voxlod_testkit::Rng;

/// Random vertex normals on every third triangle `i`, random colours on every second.
pub fn with_attributes(rng: &mut Rng, mut tri: Triangle, i: usize) -> Triangle {
    if i.is_multiple_of(3) {
        tri.flags |= TRI_HAS_NORMALS;
        tri.n = [0, 1, 2].map(|_| rng.point(-1.0, 1.0).map(|x| x as f32));
    }
    if i.is_multiple_of(2) {
        tri.flags |= TRI_HAS_COLORS;
        tri.c = [0, 1, 2].map(|_| [0, 1, 2, 3].map(|_| rng.int(0, 255) as u8));
    }
    tri
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

/// `../shared/data/meshes`, or `None` (after printing why) when it is missing; a failure when
/// `CI=true`.
pub fn shared_meshes() -> Option<PathBuf> {
    voxlod_testkit::shared_meshes("voxlod-voxelize tests")
}
