//! Thin (6-separating) voxelization of closed meshes: a 6-connected flood fill from outside must
//! never reach a voxel whose centre is inside the mesh; thin ⊆ conservative per triangle.

use crate::common;
use common::*;
use std::collections::HashSet;
use voxlod_voxelize::{voxelize_triangle, Mode};

struct Dense {
    n: i32,
    set: Vec<bool>,
}
impl Dense {
    fn idx(&self, p: [i32; 3]) -> usize {
        (p[0] + self.n * (p[1] + self.n * p[2])) as usize
    }
}

fn voxelize_mesh(v: &[[f64; 3]], f: &[[u32; 3]], n: i32, mode: Mode) -> Dense {
    let mut d = Dense {
        n,
        set: vec![false; (n * n * n) as usize],
    };
    for tri in f {
        let t = f32tri(tri.map(|i| v[i as usize]));
        voxelize_triangle(&t, [0; 3], [n - 1; 3], mode, &mut |p| {
            let i = d.idx(p);
            d.set[i] = true;
        });
    }
    d
}

/// Unmarked voxels 6-connected to the grid's corner voxel.
fn flood_outside(d: &Dense) -> Vec<bool> {
    let n = d.n;
    let mut seen = vec![false; d.set.len()];
    assert!(!d.set[0], "the corner voxel must be outside the mesh");
    let mut stack = vec![[0, 0, 0]];
    seen[0] = true;
    while let Some(p) = stack.pop() {
        for k in 0..3 {
            for s in [-1, 1] {
                let mut q = p;
                q[k] += s;
                if q[k] < 0 || q[k] >= n {
                    continue;
                }
                let i = d.idx(q);
                if !seen[i] && !d.set[i] {
                    seen[i] = true;
                    stack.push(q);
                }
            }
        }
    }
    seen
}

/// Checks that no voxel with `inside(centre)` is reached from outside; returns
/// (inside unmarked voxels, thin voxel count).
fn check_no_leak(
    d: &Dense,
    inside: impl Fn([f64; 3]) -> Option<bool>,
    what: &str,
) -> (usize, usize) {
    let reached = flood_outside(d);
    let n = d.n;
    let mut inner = 0;
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let c = [x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5];
                let i = d.idx([x, y, z]);
                if inside(c) == Some(true) && !d.set[i] {
                    inner += 1;
                    assert!(
                        !reached[i],
                        "{what}: 6-connected leak reaches inside voxel {:?}",
                        [x, y, z]
                    );
                }
            }
        }
    }
    (inner, d.set.iter().filter(|&&b| b).count())
}

/// Strictly inside every face plane of a convex mesh (None when on a plane).
fn convex_inside(v: &[[f64; 3]], f: &[[u32; 3]]) -> impl Fn([f64; 3]) -> Option<bool> {
    let planes: Vec<([f64; 3], [f64; 3])> = f
        .iter()
        .map(|t| {
            let a = v[t[0] as usize];
            (a, cross(sub(v[t[1] as usize], a), sub(v[t[2] as usize], a)))
        })
        .collect();
    // radii of the inscribed and circumscribed spheres about the vertex mean: only points
    // between them need the per-plane test
    let m = v
        .iter()
        .fold([0.0; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]])
        .map(|x| x / v.len() as f64);
    let r_out = v
        .iter()
        .map(|p| dot(sub(*p, m), sub(*p, m)).sqrt())
        .fold(0.0, f64::max);
    let r_in = planes
        .iter()
        .map(|(a, n)| -dot(*n, sub(m, *a)) / dot(*n, *n).sqrt())
        .fold(f64::INFINITY, f64::min);
    assert!(r_in > 0.0);
    move |c| {
        let r = dot(sub(c, m), sub(c, m)).sqrt();
        if r < r_in * (1.0 - 1e-9) {
            return Some(true);
        }
        if r > r_out * (1.0 + 1e-9) {
            return Some(false);
        }
        let mut strict = true;
        for (a, n) in &planes {
            let s = dot(*n, sub(c, *a));
            if s > 0.0 {
                return Some(false);
            }
            if s == 0.0 {
                strict = false;
            }
        }
        strict.then_some(true)
    }
}

#[test]
fn thin_closed_convex_meshes_do_not_leak() {
    let mut rng = Rng(7);
    let cases: &[(&str, u32, f64, i32)] = &[
        ("icosphere/0", 0, 9.3, 24),
        ("icosphere/1", 1, 20.7, 48),
        ("icosphere/3", 3, 13.1, 32),
        ("icosphere/4", 4, 30.2, 68),
        ("icosphere/6", 6, 27.6, 60), // triangles far below a voxel
        ("cube", 99, 11.4, 32),
    ];
    for &(name, sub, radius, n) in cases {
        for rot in 0..3 {
            let (v, f) = if sub == 99 { cube() } else { icosphere(sub) };
            let r = if rot == 0 && name == "cube" {
                [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
            } else {
                rng.rotation()
            };
            let c = [
                0.5 * n as f64 + rng.range(-0.5, 0.5),
                0.5 * n as f64 + rng.range(-0.5, 0.5),
                0.5 * n as f64,
            ];
            let v = transform(&v, r, radius, c);
            // f32 vertices, as the voxelizer sees them
            let v: Vec<[f64; 3]> = v.iter().map(|p| p.map(|x| x as f32 as f64)).collect();
            let thin = voxelize_mesh(&v, &f, n, Mode::Thin);
            let cons = voxelize_mesh(&v, &f, n, Mode::Conservative);
            let (inner, count) = check_no_leak(&thin, convex_inside(&v, &f), name);
            let ccount = cons.set.iter().filter(|&&b| b).count();
            eprintln!("{name} rot {rot}: {} tris, thin {count} voxels, conservative {ccount}, inside unmarked {inner}", f.len());
            assert!(inner > 0, "{name}: nothing inside, test is vacuous");
            assert!(count <= ccount);
            if rot > 0 {
                assert!(count < ccount, "thin is not thinner than conservative");
            }
            for (a, b) in thin.set.iter().zip(&cons.set) {
                assert!(!a | b, "thin voxel not in conservative");
            }
        }
    }
}

#[test]
fn thin_integer_aligned_cube_does_not_leak() {
    // faces exactly on voxel boundaries: ties everywhere
    let (v, f) = cube();
    for (s, t) in [(5.0, 8.0), (6.0, 8.0), (7.5, 10.0), (4.25, 9.0)] {
        let v = transform(
            &v,
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            s,
            [t; 3],
        );
        let thin = voxelize_mesh(&v, &f, 20, Mode::Thin);
        let (inner, _) = check_no_leak(&thin, convex_inside(&v, &f), "aligned cube");
        assert!(inner > 0);
    }
}

/// Inside test for a closed (non-convex) mesh by parity of +z ray crossings through the voxel
/// centres, one ray per column; a column whose ray passes exactly through an edge or vertex (in
/// projection) is `None`.
struct RayInside {
    n: i32,
    columns: Vec<Option<Vec<f64>>>,
}
impl RayInside {
    fn new(tris: &[[[f64; 3]; 3]], n: i32) -> RayInside {
        let mut columns = vec![Some(Vec::new()); (n * n) as usize];
        for t in tris {
            let (mnx, mxx) = (
                t[0][0].min(t[1][0]).min(t[2][0]),
                t[0][0].max(t[1][0]).max(t[2][0]),
            );
            let (mny, mxy) = (
                t[0][1].min(t[1][1]).min(t[2][1]),
                t[0][1].max(t[1][1]).max(t[2][1]),
            );
            for y in (mny - 0.5).floor().max(0.0) as i32..=((mxy - 0.5).ceil() as i32).min(n - 1) {
                for x in
                    (mnx - 0.5).floor().max(0.0) as i32..=((mxx - 0.5).ceil() as i32).min(n - 1)
                {
                    let c = [x as f64 + 0.5, y as f64 + 0.5];
                    let e = |a: [f64; 3], b: [f64; 3]| {
                        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
                    };
                    let w = [e(t[1], t[2]), e(t[2], t[0]), e(t[0], t[1])];
                    let area = w[0] + w[1] + w[2];
                    let col = &mut columns[(x + n * y) as usize];
                    if area == 0.0 {
                        continue; // vertical triangle: the ray grazes it at most
                    }
                    if w.contains(&0.0) {
                        *col = None;
                    } else if w.iter().all(|&x| x > 0.0) || w.iter().all(|&x| x < 0.0) {
                        if let Some(zs) = col {
                            zs.push((w[0] * t[0][2] + w[1] * t[1][2] + w[2] * t[2][2]) / area);
                        }
                    }
                }
            }
        }
        RayInside { n, columns }
    }
    fn inside(&self, c: [f64; 3]) -> Option<bool> {
        let zs = self.columns[(c[0] as i32 + self.n * c[1] as i32) as usize].as_ref()?;
        if zs.contains(&c[2]) {
            return None;
        }
        Some(zs.iter().filter(|&&z| z > c[2]).count() % 2 == 1)
    }
}

#[test]
fn thin_bunny_does_not_leak() {
    let Some(dir) = shared_meshes() else { return };
    let path = dir.join("npm-bunny/bunny.ply");
    let (v0, f) = read_ply(&path);
    // the npm bunny is closed: every undirected edge is used exactly twice, once each way
    let mut edges = HashSet::new();
    for t in &f {
        for i in 0..3 {
            assert!(
                edges.insert((t[i], t[(i + 1) % 3])),
                "edge used twice in the same direction"
            );
        }
    }
    for &(a, b) in &edges {
        assert!(
            edges.contains(&(b, a)),
            "open edge: the bunny is not closed"
        );
    }
    let mut rng = Rng(11);
    for (n, rot) in [(48, 0), (96, 1), (150, 2)] {
        let r = if rot == 0 {
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        } else {
            rng.rotation()
        };
        // centre the bunny (extent < 16) and scale it to fill ~80% of the grid
        let centred: Vec<[f64; 3]> = v0.iter().map(|p| [p[0], p[1] - 4.8, p[2]]).collect();
        let s = 0.8 * n as f64 / 16.0;
        let v = transform(
            &centred,
            r,
            s,
            [
                0.5 * n as f64 + 0.17,
                0.5 * n as f64 - 0.31,
                0.5 * n as f64 + 0.05,
            ],
        );
        let v: Vec<[f64; 3]> = v.iter().map(|p| p.map(|x| x as f32 as f64)).collect();
        let thin = voxelize_mesh(&v, &f, n, Mode::Thin);
        let tris: Vec<[[f64; 3]; 3]> = f.iter().map(|t| t.map(|i| v[i as usize])).collect();
        let ray = RayInside::new(&tris, n);
        let (inner, count) = check_no_leak(&thin, |c| ray.inside(c), "bunny");
        eprintln!("bunny {n}³ rot {rot}: thin {count} voxels, inside unmarked {inner}");
        assert!(inner > 100);
    }
}
