//! The column-by-column clipping with its fast paths (`voxel_areas`) against the general
//! clipping (`clipped_area`, Sutherland–Hodgman per voxel) on random triangles of every kind, on
//! large shallow and steep triangles (where the Square fast path dominates), and on a real mesh;
//! and the fast ChunkVoxelizer against the general one, record for record.

use crate::common;
use common::*;
use voxlod_geom::{Triangle, TRI_HAS_COLORS, TRI_HAS_NORMALS};
use voxlod_voxelize::{clipped_area, voxel_areas, voxelize_triangle, ChunkVoxelizer, Mode};

/// Compares every voxel of `t`; returns the number of voxels. Areas and centroids must agree
/// within 1e-9 relative (to the triangle's area for areas, to the voxel's coordinates for
/// centroids), and the voxel sequence must be the overlap test's.
fn compare(t: &[[f32; 3]; 3], mode: Mode, lo: i32, hi: i32, worst: &mut (f64, f64)) -> usize {
    let mut want = Vec::new();
    voxelize_triangle(t, [lo; 3], [hi; 3], mode, &mut |p| want.push(p));
    let mut got = Vec::new();
    voxel_areas(t, [lo; 3], [hi; 3], mode, &mut |p, a, c| {
        got.push((p, a, c))
    });
    assert_eq!(got.len(), want.len(), "{t:?}");
    let tri_area = tri_area(&f64tri(t)).max(1e-300);
    for ((p, a, c), w) in got.iter().zip(&want) {
        assert_eq!(p, w, "{t:?}: voxel order");
        let (ra, rc) = clipped_area(t, *p);
        let ea = (a - ra).abs() / tri_area.min(1.0).max(ra);
        let ec = (0..3)
            .map(|k| (c[k] - rc[k]).abs() / (1.0 + rc[k].abs()))
            .fold(0.0, f64::max);
        worst.0 = worst.0.max(ea);
        worst.1 = worst.1.max(ec);
        assert!(
            ea < 1e-9,
            "{t:?} voxel {p:?}: area {a} vs clipped_area {ra}"
        );
        // the centroid of a zero-area part is the mean of its vertices, which depends on how
        // the degenerate polygon was cut; it only has to lie in the voxel then
        if ra > 1e-9 * tri_area {
            assert!(
                ec < 1e-9,
                "{t:?} voxel {p:?}: centroid {c:?} vs clipped_area {rc:?} (area {ra})"
            );
        } else if *a > 0.0 || ra > 0.0 {
            for k in 0..3 {
                assert!(c[k] >= p[k] as f64 - 1e-6 && c[k] <= p[k] as f64 + 1.0 + 1e-6);
            }
        }
    }
    got.len()
}

#[test]
fn fast_paths_match_general_clipping_on_random_triangles() {
    let mut rng = Rng(77);
    let mut worst = (0.0, 0.0);
    let mut voxels = 0;
    for i in 0..4000 {
        let t = f32tri(random_triangle(&mut rng, i, 24.0));
        for mode in [Mode::Conservative, Mode::Thin] {
            voxels += compare(&t, mode, -64, 96, &mut worst);
        }
    }
    eprintln!(
        "random: {voxels} voxels, worst relative area error {:e}, centroid {:e}",
        worst.0, worst.1
    );
    assert!(voxels > 100_000);
}

#[test]
fn fast_paths_match_general_clipping_on_large_triangles() {
    // large triangles at every slope: most columns lie inside (the Square fast path), crossing
    // one or several voxel layers
    let mut rng = Rng(78);
    let mut worst = (0.0, 0.0);
    let mut voxels = 0;
    for i in 0..60 {
        let r = rng.rotation();
        let flat = [[0.0, 0.0, 0.0], [90.0, 3.0, 0.0], [10.0, 80.0, 0.0]];
        let slope = [0.0, 0.05, 0.5, 1.0, 3.0][i % 5];
        let t = flat.map(|p| {
            let p = [p[0], p[1], p[2] + slope * (p[0] - p[1])];
            let q = if i % 2 == 0 {
                p
            } else {
                [0, 1, 2].map(|k| (0..3).map(|j| r[k][j] * p[j]).sum::<f64>())
            };
            q.map(|x| x + 100.3)
        });
        let t = f32tri(t);
        for mode in [Mode::Conservative, Mode::Thin] {
            voxels += compare(&t, mode, 0, 255, &mut worst);
        }
    }
    eprintln!(
        "large: {voxels} voxels, worst relative area error {:e}, centroid {:e}",
        worst.0, worst.1
    );
    assert!(voxels > 200_000);
}

/// The ChunkVoxelizer with the fast paths against the general clipping: the same records.
fn chunk_records_equal(tris: &[Triangle], origin: [u32; 3]) -> usize {
    let mut n = 0;
    for mode in [Mode::Conservative, Mode::Thin] {
        let mut out = Vec::new();
        for fast in [true, false] {
            let mut cv = ChunkVoxelizer::new(mode);
            cv.set_fast_paths(fast);
            cv.begin(origin);
            cv.add(tris);
            out.push(cv.finish());
        }
        assert_eq!(out[0].len(), out[1].len());
        let differ = out[0].iter().zip(&out[1]).filter(|(a, b)| a != b).count();
        assert_eq!(
            differ,
            0,
            "{mode}: {differ} of {} records differ",
            out[0].len()
        );
        n += out[0].len();
    }
    n
}

#[test]
fn fast_chunk_voxelizer_gives_the_same_records() {
    let mut rng = Rng(79);
    let mut tris = Vec::new();
    for i in 0..300 {
        let t = random_triangle(&mut rng, i, 120.0).map(|p| p.map(|x| x + 60.0));
        let mut tri = Triangle::new(f32tri(t));
        if i % 3 == 0 {
            tri.flags |= TRI_HAS_NORMALS;
            tri.n = [0, 1, 2].map(|_| rng.point(-1.0, 1.0).map(|x| x as f32));
        }
        tri.flags |= TRI_HAS_COLORS;
        tri.c = [0, 1, 2].map(|_| [0, 1, 2, 3].map(|_| rng.int(0, 255) as u8));
        tris.push(tri);
    }
    let n = chunk_records_equal(&tris, [0; 3]);
    eprintln!("random triangles: {n} records equal");
}

#[test]
fn fast_chunk_voxelizer_gives_the_same_records_on_the_npm_bunny() {
    let Some(dir) = shared_meshes() else {
        return;
    };
    let (v, f) = read_ply(&dir.join("npm-bunny/bunny.ply"));
    // fitted to a 1024³ grid; the chunk at the bunny's centre
    let (lo, size) = voxlod_testkit::mesh::bounding_cube(&v);
    let s = 1023.0 / size;
    let tris: Vec<Triangle> = f
        .iter()
        .map(|t| {
            Triangle::new(f32tri(
                t.map(|i| v[i as usize].map(|x| x))
                    .map(|p| [0, 1, 2].map(|k| (p[k] - lo[k]) * s)),
            ))
        })
        .collect();
    let mut n = 0;
    for origin in [[256, 256, 256], [512, 256, 256], [256, 512, 512]] {
        n += chunk_records_equal(&tris, origin);
    }
    eprintln!("npm bunny at 1024: {n} records equal");
    assert!(n > 100_000, "{n}");
}
