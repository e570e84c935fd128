//! The chunk voxelizer's f32 attribute sums against the f64 reference of the crate docs: per
//! voxel, in triangle order, `W = Σ w`, `N = Σ w·normal`, `C = Σ w·colour` with `w` and the
//! interpolation point from `clipped_area` (Sutherland–Hodgman in f64) and the barycentrics by
//! sub-triangle areas (a different formula from the crate's per-triangle gradients). Checks the
//! error bound stated on `chunk::Acc` (`|Ŝ − S| ≤ γ_{k+2}·Σ|terms|`), and that the encoded
//! records are within one quantization step of the reference wherever the bound promises it, on
//! random triangles (all categories of `common::random_triangle`, sub-voxel ones included) and on
//! the npm bunny.

use crate::common;
use common::*;
use std::collections::BTreeMap;
use voxlod_format::voxel::{unpack_normal, Voxel};
use voxlod_geom::{Triangle, CHUNK, TRI_HAS_COLORS, TRI_HAS_NORMALS};
use voxlod_voxelize::{clipped_area, voxelize_triangle, ChunkVoxelizer, Mode, VoxelSums};

/// `γ_m = m·u/(1 − m·u)`, `u = 2⁻²⁴`.
fn gamma(m: u32) -> f64 {
    let mu = m as f64 * (0.5f64).powi(24);
    mu / (1.0 - mu)
}

/// Barycentrics of `q` by the ratio of sub-triangle areas.
fn bary(t: &[[f64; 3]; 3], q: [f64; 3]) -> [f64; 3] {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let nn = dot(n, n);
    let a0 = dot(cross(sub(t[1], q), sub(t[2], q)), n) / nn;
    let a1 = dot(cross(sub(t[2], q), sub(t[0], q)), n) / nn;
    [a0, a1, 1.0 - a0 - a1]
}

fn normalize(v: [f64; 3]) -> Option<[f64; 3]> {
    let l = dot(v, v).sqrt();
    (l > 0.0 && l.is_finite()).then(|| v.map(|x| x / l))
}

/// Reference sums of one voxel, in f64: `k`, `W`, `N`, `C` (weighted; the unweighted ones if
/// `W = 0`), and `Σ|w·n_j|` for the normal bound.
#[derive(Default, Debug)]
struct Ref {
    k: u32,
    w: f64,
    n: [f64; 3],
    c: [f64; 4],
    un: [f64; 3],
    uc: [f64; 4],
}

fn reference(tris: &[Triangle], origin: [u32; 3]) -> BTreeMap<[u8; 3], Ref> {
    let lo = origin.map(|c| c as i32);
    let hi = origin.map(|c| (c + CHUNK - 1) as i32);
    let mut out: BTreeMap<[u8; 3], Ref> = BTreeMap::new();
    for t in tris {
        let t64 = f64tri(&t.v);
        voxelize_triangle(&t.v, lo, hi, Mode::Conservative, &mut |p| {
            let (a, q) = clipped_area(&t.v, p);
            let l = bary(&t64, q);
            let face = normalize(cross(sub(t64[1], t64[0]), sub(t64[2], t64[0]))).unwrap();
            let n = if t.flags & TRI_HAS_NORMALS != 0 {
                normalize([0, 1, 2].map(|k| (0..3).map(|j| l[j] * t.n[j][k] as f64).sum()))
                    .unwrap_or(face)
            } else {
                face
            };
            let c: [f64; 4] = [0, 1, 2, 3].map(|k| (0..3).map(|j| l[j] * t.c[j][k] as f64).sum());
            let pos = [0, 1, 2].map(|k| (p[k] - lo[k]) as u8);
            let r = out.entry(pos).or_default();
            r.k += 1;
            r.w += a;
            for ((s, u), x) in r.n.iter_mut().zip(&mut r.un).zip(n) {
                *s += a * x;
                *u += x;
            }
            for ((s, u), x) in r.c.iter_mut().zip(&mut r.uc).zip(c) {
                *s += a * x;
                *u += x;
            }
        });
    }
    out
}

#[derive(Default, Debug)]
struct Stats {
    voxels: usize,
    /// largest error / bound over all sums
    worst: f64,
    /// records whose normal differs from the reference's packing by one step / more
    normal_one: usize,
    normal_more: usize,
    /// of those differing by more, how many the bound does not cover (nearly cancelling normals)
    cancelling: usize,
    colour_one: usize,
    colour_more: usize,
}

/// Checks one chunk's sums and records against the reference.
fn check_chunk(tris: &[Triangle], origin: [u32; 3], st: &mut Stats) {
    let mut cv = ChunkVoxelizer::new(Mode::Conservative);
    cv.begin(origin);
    cv.add(tris);
    let sums: Vec<VoxelSums> = cv.finish_sums();
    cv.begin(origin);
    cv.add(tris);
    let records: Vec<Voxel> = cv.finish();
    let reference = reference(tris, origin);
    assert_eq!(sums.len(), reference.len(), "voxel sets differ");
    assert_eq!(records.len(), sums.len());
    for (s, v) in sums.iter().zip(&records) {
        assert_eq!(v.pos(), s.pos);
        let r = &reference[&s.pos];
        assert_eq!(s.k, r.k, "{:?}", s.pos);
        st.voxels += 1;
        let g = gamma(r.k + 2);
        // the reference's own weights and points differ from the crate's by f64 rounding (the
        // column fast paths, the gradient barycentrics): a relative 1e-9 on top of the bound
        let slack = 1e-9;
        let weighted = s.w > 0.0;
        assert_eq!(
            weighted,
            r.w > 0.0,
            "{:?}: zero weight on one side only",
            s.pos
        );
        let mut ratio = |got: f32, want: f64, scale: f64| {
            let bound = g * scale + slack * scale + 1e-300;
            let e = (got as f64 - want).abs() / bound;
            st.worst = st.worst.max(e);
            assert!(
                e <= 1.0,
                "{:?}: sum {got} vs reference {want}, error {} > bound {bound}",
                s.pos,
                (got as f64 - want).abs()
            );
        };
        let (wn, wc) = if weighted {
            ratio(s.w, r.w, r.w);
            for k in 0..3 {
                ratio(s.n[k], r.n[k], r.w);
            }
            for k in 0..4 {
                ratio(s.c[k], r.c[k], r.c[k].abs() + slack * 255.0 * r.w);
            }
            (r.n.map(|x| x / r.w), r.c.map(|x| x / r.w))
        } else {
            let kf = r.k as f64;
            for k in 0..3 {
                ratio(s.n[k], r.un[k], kf);
            }
            for k in 0..4 {
                ratio(s.c[k], r.uc[k], r.uc[k].abs() + slack * 255.0 * kf);
            }
            (r.un.map(|x| x / kf), r.uc.map(|x| x / kf))
        };

        // the records: within one step where the bound covers it
        let q = unpack_normal(v.normal);
        let e = normalize(wn).map_or([0; 3], |u| u.map(|x| (x * 511.0).round() as i32));
        let d = (0..3).map(|k| (q[k] - e[k]).abs()).max().unwrap();
        let len = dot(wn, wn).sqrt();
        let covered = len >= 1022.0 * 3f64.sqrt() * g * 1.01 + 1e-12;
        match d {
            0 => {}
            1 => st.normal_one += 1,
            _ => {
                st.normal_more += 1;
                assert!(
                    !covered,
                    "{:?}: normal {q:?} vs reference {e:?} with |N|/W = {len}",
                    s.pos
                );
                st.cancelling += 1;
            }
        }
        let rgba = v.rgba();
        let ec = wc.map(|x| x.round().clamp(0.0, 255.0) as i32);
        let dc = (0..4)
            .map(|k| (rgba[k] as i32 - ec[k]).abs())
            .max()
            .unwrap();
        match dc {
            0 => {}
            1 => st.colour_one += 1,
            _ => st.colour_more += 1,
        }
        assert!(dc <= 1, "{:?}: colour {rgba:?} vs reference {ec:?}", s.pos);
    }
}

#[test]
fn f32_sums_within_the_bound_on_random_triangles() {
    let mut st = Stats::default();
    for seed in 0..4u64 {
        let mut rng = Rng(0xa77 + seed);
        let mut tris = Vec::new();
        for i in 0..300 {
            // small ones (sub-voxel among them) dense around a few voxels, so that voxels get
            // several contributions; the other categories over a 24³ window
            let span = if i % 2 == 0 { 3.0 } else { 24.0 };
            let t = random_triangle(&mut rng, i, span).map(|p| p.map(|x| x + 100.0));
            tris.push(with_attributes(&mut rng, Triangle::new(f32tri(t)), i));
        }
        check_chunk(&tris, [0; 3], &mut st);
    }
    eprintln!("random: {st:?}");
    assert!(st.voxels > 10_000, "{st:?}");
    assert!(st.worst > 0.0 && st.worst <= 1.0);
    assert!(st.normal_one + st.normal_more < st.voxels / 50, "{st:?}");
}

#[test]
fn f32_sums_within_the_bound_on_the_npm_bunny() {
    let Some(dir) = shared_meshes() else {
        return;
    };
    let (v, f) = read_ply(&dir.join("npm-bunny/bunny.ply"));
    // into a 512³ grid, with vertex colours from the position and smooth-ish vertex normals
    // on every other triangle
    let g = voxlod_testkit::mesh::fit_to_grid(&v, 500.0, 3.3);
    let tris: Vec<Triangle> = f
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let mut tri = Triangle::new(t.map(|j| g[j as usize]));
            tri.flags |= TRI_HAS_COLORS;
            tri.c = t.map(|j| {
                let p = g[j as usize];
                [p[0] as u8, p[1] as u8, (p[2] * 0.5) as u8, 255]
            });
            if i % 2 == 0 {
                tri.flags |= TRI_HAS_NORMALS;
                tri.n = t.map(|j| {
                    let p = v[j as usize];
                    [p[0] as f32, p[1] as f32 - 5.0, p[2] as f32]
                });
            }
            tri
        })
        .collect();
    let mut st = Stats::default();
    for z in 0..2 {
        for y in 0..2 {
            for x in 0..2 {
                check_chunk(&tris, [x * 256, y * 256, z * 256], &mut st);
            }
        }
    }
    eprintln!("npm bunny 512³: {st:?}");
    assert!(st.voxels > 200_000, "{st:?}");
    assert_eq!(st.normal_more, 0, "{st:?}");
    assert!(st.normal_one + st.colour_one < st.voxels / 50, "{st:?}");
}
