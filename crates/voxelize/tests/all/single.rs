//! The clip skip of `voxlod_voxelize::single` against the clipping of every pair
//! (`ChunkVoxelizer::set_single_skip(false)`, the present column method kept as the reference):
//! the same voxels; every voxel with two or more contributions bit-identical; a voxel with one
//! contribution of a flat triangle within one normal step and with the same colour; and the
//! records of voxels with one contribution of a flat triangle equal to the triangle's own face
//! normal and colour encoded independently here (f64 normal, `pack_normal_f64`). On random
//! triangles with mixed attributes over several chunks and `add` batches, and on the npm
//! bunny (flat) and the Stanford bunny with vertex colours on half of it.

use crate::common;
use common::*;
use voxlod_format::voxel::{border_caps, face_mask, pack_color, pack_normal_f64, unpack_normal};
use voxlod_format::Voxel;
use voxlod_geom::{Triangle, CHUNK, TRI_HAS_COLORS, TRI_HAS_NORMALS};
use voxlod_testkit::Rng;
use voxlod_voxelize::{ChunkVoxelizer, Mode};

/// Records with and without the skip and the contribution counts, for one chunk.
struct Run {
    skip: Vec<Voxel>,
    clip: Vec<Voxel>,
    k: Vec<u32>,
}

fn run(tris: &[Triangle], origin: [u32; 3], mode: Mode, batch: usize) -> Run {
    let mut cv = ChunkVoxelizer::new(mode);
    let pass = |cv: &mut ChunkVoxelizer| {
        cv.begin(origin);
        for b in tris.chunks(batch) {
            cv.add(b);
        }
    };
    pass(&mut cv);
    let skip = cv.finish();
    cv.set_single_skip(false);
    pass(&mut cv);
    let clip = cv.finish();
    pass(&mut cv);
    let k = cv.finish_sums().iter().map(|s| s.k).collect();
    Run { skip, clip, k }
}

/// The record of a voxel whose one contribution is the flat triangle `t`, from the definition:
/// its unit face normal (f64) and its colour.
fn flat_record(t: &Triangle, pos: [u8; 3]) -> Voxel {
    let d = f64tri(&t.v);
    let n = cross(sub(d[1], d[0]), sub(d[2], d[0]));
    let normal = pack_normal_f64(n);
    Voxel::new(
        pos,
        face_mask(normal) | border_caps(pos),
        normal,
        pack_color(t.c[0]),
    )
}

#[derive(Debug, Default)]
struct Count {
    voxels: usize,
    single: usize,
    /// single voxels whose record changed (by one normal step at most)
    changed: usize,
    /// single voxels whose flat triangle the test knows, and how many of them equal the f64
    /// definition exactly
    owned: usize,
    exact: usize,
}

/// The largest difference of the 10-bit normal components of two records.
fn steps(a: &Voxel, b: &Voxel) -> i32 {
    let (na, nb) = (unpack_normal(a.normal), unpack_normal(b.normal));
    (0..3).map(|j| (na[j] - nb[j]).abs()).max().unwrap()
}

/// Compares one chunk's runs; `owner(pos)`: the flat triangle whose only contribution a voxel
/// with one contribution is, if the test knows it.
fn compare(r: &Run, owner: impl Fn([u8; 3]) -> Option<Triangle>, c: &mut Count) {
    assert_eq!(r.skip.len(), r.clip.len(), "voxel sets differ");
    assert_eq!(r.k.len(), r.clip.len());
    for ((a, b), &k) in r.skip.iter().zip(&r.clip).zip(&r.k) {
        assert_eq!(a.pos(), b.pos(), "voxel sets differ");
        c.voxels += 1;
        if k >= 2 {
            assert_eq!(a, b, "voxel {:?} with {k} contributions changed", a.pos());
            continue;
        }
        c.single += 1;
        if let Some(t) = owner(a.pos()) {
            // the definition in f64: the same colour, the normal within one step (the voxelizer
            // rounds the unit normal to f32 before packing)
            let want = flat_record(&t, a.pos());
            assert_eq!(a.rgba(), want.rgba(), "colour of flat single {:?}", a.pos());
            assert!(steps(a, &want) <= 1, "normal of flat single {:?}", a.pos());
            c.owned += 1;
            c.exact += (*a == want) as usize;
        }
        if a != b {
            c.changed += 1;
            assert_eq!(a.rgba(), b.rgba(), "colour of {:?}", a.pos());
            assert!(steps(a, b) <= 1, "{:?}: normals {a:?} vs {b:?}", a.pos());
        }
    }
}

/// [`with_attributes`] (vertex normals on every third triangle, random colours on every
/// second), and one colour on all three vertices of every other fifth (flat, not the default).
fn decorate(rng: &mut Rng, t: Triangle, i: usize) -> Triangle {
    let mut t = with_attributes(rng, t, i);
    if i % 10 == 5 {
        t.flags |= TRI_HAS_COLORS;
        t.c = [[rng.int(0, 255) as u8, 7, 200, 255]; 3];
    }
    t
}

#[test]
fn skip_changes_only_single_flat_voxels_on_random_triangles() {
    for mode in Mode::ALL {
        let mut c = Count::default();
        for seed in 0..3u64 {
            let mut rng = Rng(0x5191e + seed);
            // around a chunk corner, so that triangles cross into the neighbours
            let tris: Vec<Triangle> = (0..400)
                .map(|i| {
                    let span = if i % 2 == 0 { 4.0 } else { 30.0 };
                    let t = random_triangle(&mut rng, i, span).map(|p| p.map(|x| x + 240.0));
                    decorate(&mut rng, Triangle::new(f32tri(t)), i)
                })
                .collect();
            for origin in [[0, 0, 0], [256, 0, 0], [0, 256, 256], [256, 256, 256]] {
                let r = run(&tris, origin, mode, 37 + seed as usize);
                compare(&r, |_| None, &mut c);
            }
        }
        eprintln!("{mode}: {c:?}");
        assert!(
            c.voxels > 15_000 && c.single > c.voxels / 4,
            "{mode}: {c:?}"
        );
    }
}

/// Triangles far apart (one per 16³ cell, no two touching a common voxel): every voxel has one
/// contribution, and a flat triangle's voxels must carry exactly its face normal and colour.
#[test]
fn single_flat_voxels_carry_the_triangle_record() {
    let mut rng = Rng(77);
    let mut tris = Vec::new();
    let mut cells = Vec::new();
    for cell in 0..512u32 {
        let o = [cell % 8, cell / 8 % 8, cell / 64].map(|c| (c * 16 + 3) as f64);
        let t = random_triangle(&mut rng, cell as usize, 9.0)
            .map(|p| [0, 1, 2].map(|k| o[k] + p[k].clamp(0.0, 9.0)));
        let mut tri = decorate(&mut rng, Triangle::new(f32tri(t)), cell as usize);
        if cell % 7 == 0 {
            // the voxel grid's planes through vertices (ties)
            tri.v = tri.v.map(|p| p.map(f32::round));
        }
        tris.push(tri);
        cells.push(o);
    }
    let flat =
        |t: &Triangle| t.flags & TRI_HAS_NORMALS == 0 && t.c[0] == t.c[1] && t.c[1] == t.c[2];
    for mode in Mode::ALL {
        let mut c = Count::default();
        let r = run(&tris, [0; 3], mode, 100);
        assert!(r.k.iter().all(|&k| k == 1), "triangles share a voxel");
        compare(
            &r,
            |p| {
                let cell = p.map(|x| (x / 16) as u32);
                let t = tris[(cell[0] + 8 * cell[1] + 64 * cell[2]) as usize];
                flat(&t).then_some(t)
            },
            &mut c,
        );
        eprintln!("{mode}: {c:?}");
        assert!(c.single > 5_000 && c.owned > 1_000, "{c:?}");
        assert!(c.exact * 100 >= c.owned * 99, "{c:?}");
    }
}

/// A real mesh: `tris` (grid coordinates) over its chunks in both modes.
fn mesh_check(tris: &[Triangle], res: u32) -> Count {
    let mut c = Count::default();
    let n = res / CHUNK;
    for mode in Mode::ALL {
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let r = run(tris, [x, y, z].map(|v| v * CHUNK), mode, 4096);
                    compare(&r, |_| None, &mut c);
                }
            }
        }
    }
    c
}

#[test]
fn skip_changes_only_single_flat_voxels_on_the_bunnies() {
    let Some(dir) = shared_meshes() else {
        return;
    };
    // npm bunny at 512³: flat throughout
    let (v, f) = voxlod_testkit::mesh::read_ply(&dir.join("npm-bunny/bunny.ply"));
    let g = voxlod_testkit::mesh::fit_to_grid(&v, 500.0, 3.3);
    let tris: Vec<Triangle> = f
        .iter()
        .map(|t| Triangle::new(t.map(|j| g[j as usize])))
        .collect();
    let c = mesh_check(&tris, 512);
    eprintln!("npm bunny 512³: {c:?}");
    assert!(c.voxels > 1_000_000 && c.single > c.voxels / 4, "{c:?}");

    // Stanford bunny at 256³, vertex colours from the position on every other triangle (those
    // keep the clip), the rest flat
    let (v, f) = voxlod_testkit::mesh::read_ply(&dir.join("stanford-bunny/bun_zipper.ply"));
    let g = voxlod_testkit::mesh::fit_to_grid(&v, 250.0, 2.7);
    let tris: Vec<Triangle> = f
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let mut tri = Triangle::new(t.map(|j| g[j as usize]));
            if i % 2 == 0 {
                tri.flags |= TRI_HAS_COLORS;
                tri.c = t.map(|j| {
                    let p = g[j as usize];
                    [p[0] as u8, p[1] as u8, p[2] as u8, 255]
                });
            }
            tri
        })
        .collect();
    let c = mesh_check(&tris, 256);
    eprintln!("Stanford bunny 256³: {c:?}");
    assert!(c.voxels > 100_000, "{c:?}");
}

/// Past the memory limit for kept triangles and pairs a chunk clips every pair: its records
/// equal the reference's bit for bit, also when the limit is crossed in the middle of a batch
/// and of the chunk; below it the skip's records.
#[test]
fn chunks_over_the_defer_limit_clip_every_pair() {
    let mut rng = Rng(0xdef);
    let tris: Vec<Triangle> = (0..600)
        .map(|i| {
            let t = random_triangle(&mut rng, i, 20.0).map(|p| p.map(|x| x + 10.0));
            decorate(&mut rng, Triangle::new(f32tri(t)), i)
        })
        .collect();
    for mode in Mode::ALL {
        let r = run(&tris, [0; 3], mode, 50);
        for limit in [0, 20_000, 200_000, usize::MAX] {
            let mut cv = ChunkVoxelizer::new(mode);
            cv.set_defer_bytes(limit);
            cv.begin([0; 3]);
            for b in tris.chunks(50) {
                cv.add(b);
            }
            let got = cv.finish();
            let want = if limit == usize::MAX {
                &r.skip
            } else {
                &r.clip
            };
            assert!(got == *want, "{mode}, limit {limit}");
        }
    }
}
