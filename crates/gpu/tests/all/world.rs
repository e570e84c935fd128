//! The GPU voxelizer's sets exact for the input's own coordinates: triangles fed in
//! world coordinates (`voxelize_chunk_world`, what a build feeds from its bins) give the voxels of
//! the exact reference of `crates/voxelize/tests/all/common/world_ref.rs` (included by path: it
//! starts from the world f32 numbers and the grid's f64 origin and voxel size, big integers
//! where f64 cannot tell), and the CPU backend's (`ChunkVoxelizer::add_world`).
//!
//! The triangles are the near-tie generator of `world_exact.rs`: vertices, edges and faces
//! within a few f32 ulps of voxel corners, edges and faces on a grid whose origin and voxel
//! size are not binary fractions, so that the f32 grid coordinates (`Grid::to_grid`) decide
//! some voxels differently from the exact ones. That is asserted too: the same triangles moved
//! to the grid first (`voxelize_chunk`, the path for triangles given in grid coordinates) miss or add voxels.
//! A block world on a dyadic grid (every grid coordinate the exact image of its world value)
//! keeps the shaders' own certificates: nothing is listed.
//!
//! These tests need an adapter (lavapipe is enough): without one they FAIL.

use std::collections::HashSet;

use crate::exactness::vcommon::world_ref::{compare, near_ties};
use crate::exactness::vcommon::Rng;
use voxlod_format::Voxel;
use voxlod_geom::{Grid, Triangle};
use voxlod_gpu::{GpuMethod, GpuVoxelizer, Precision, DEFAULT_CUTOFF};
use voxlod_voxelize::{ChunkVoxelizer, Mode};

fn gpu(p: Precision) -> GpuVoxelizer {
    GpuVoxelizer::with_precision(
        Mode::Conservative,
        GpuMethod::Hybrid,
        DEFAULT_CUTOFF,
        Some(p),
    )
    .unwrap_or_else(|e| panic!("this test needs a GPU adapter (lavapipe is enough): {e}"))
}

fn set(v: &[Voxel]) -> HashSet<[i32; 3]> {
    v.iter().map(|v| v.pos().map(|c| c as i32)).collect()
}

/// The CPU backend's set: `add_world` on the one chunk at the origin.
fn cpu_world(grid: &Grid, tris: &[Triangle], mode: Mode) -> HashSet<[i32; 3]> {
    let mut cpu = ChunkVoxelizer::new(mode);
    cpu.begin([0; 3]);
    cpu.add_world(grid, tris);
    set(&cpu.finish())
}

fn moved(grid: &Grid, tris: &[Triangle]) -> Vec<Triangle> {
    tris.iter()
        .map(|t| {
            let mut m = *t;
            m.v = t.v.map(|p| grid.to_grid(p));
            m
        })
        .collect()
}

/// Near ties on a 256³ grid of origin (0.1, −0.37, 12.3) and size 7.3 (one chunk): every
/// precision, mode and scheme gives the exact world set, by the per-triangle fallback only.
#[test]
fn world_sets_are_exact_near_ties() {
    let grid = Grid::new([0.1, -0.37, 12.3], 7.3, 256).unwrap();
    let tris = near_ties(&grid, &mut Rng(0x6e32_0001), 600);
    let grid_tris = moved(&grid, &tris);
    for p in [Precision::F64, Precision::F32] {
        let mut g = gpu(p);
        for mode in [Mode::Conservative, Mode::Thin] {
            g.set_mode(mode);
            let cpu = cpu_world(&grid, &tris, mode);
            let (m, a, checked) = compare(&tris, &grid, mode, &cpu);
            assert!(m.is_empty() && a.is_empty(), "CPU {mode}: {m:?} {a:?}");
            for (method, batch) in [
                (GpuMethod::Hybrid, 65535),
                (GpuMethod::Fragment, 65535),
                (GpuMethod::Triangle, 65535),
                // several batches: the listed triangles' stream indices across them
                (GpuMethod::Hybrid, 97),
            ] {
                g.set_method(method, DEFAULT_CUTOFF);
                g.set_batch_size(batch);
                let got = set(&g.voxelize_chunk_world(&grid, [0; 3], &tris).unwrap());
                let what = format!("{p:?} {mode} {method} batch {batch}");
                let (missed, added, _) = compare(&tris, &grid, mode, &got);
                assert!(
                    missed.is_empty() && added.is_empty(),
                    "{what}: missed {missed:?}, added {added:?}"
                );
                assert_eq!(got, cpu, "{what}: not the CPU backend's set");
                assert!(!g.last_fell_back(), "{what}: the whole chunk fell back");
                let listed = g.last_fallback_triangles();
                assert!(listed > 0, "{what}: no triangle listed near ties");
                assert!(
                    (listed as usize) < tris.len(),
                    "{what}: every triangle listed"
                );
                eprintln!("{what}: {} voxels ({checked} checked), {listed} of {} triangles decided on the host", got.len(), tris.len());
            }
            g.set_batch_size(65535);
            // the f32 grid coordinates decide differently: what this test guards
            if p == Precision::F64 {
                g.set_method(GpuMethod::Hybrid, DEFAULT_CUTOFF);
                let old = set(&g.voxelize_chunk([0; 3], &grid_tris).unwrap());
                let (m, a, _) = compare(&tris, &grid, mode, &old);
                eprintln!(
                    "{mode}: the f32 grid coordinates' set misses {} and adds {} voxels",
                    m.len(),
                    a.len()
                );
                assert!(
                    !m.is_empty() || !a.is_empty(),
                    "{mode}: the near ties do not reach a decision the rounding changes"
                );
            }
        }
    }
}

/// A block world (integer world coordinates) on a grid of origin (−3, 5, −0.5) and voxel size
/// ½: every grid coordinate is the exact image of its world value, so the shaders keep their
/// exact certificates (faces on voxel planes, ties): nothing is listed, and the sets are the
/// CPU's. On a grid of voxel size 0.3 the same blocks are rounded and still exact.
#[test]
fn exact_images_keep_the_certificates() {
    let mut tris = Vec::new();
    let quads = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    for b in 0..20 {
        let lo = [
            (b * 5 % 40) as f32,
            (b * 3 % 30) as f32 + 6.0,
            (b % 7) as f32,
        ];
        let hi = lo.map(|c| c + 1.0 + (b % 3) as f32);
        let c = |i: usize| [0, 1, 2].map(|k| if i >> k & 1 != 0 { hi[k] } else { lo[k] });
        for q in quads {
            tris.push(Triangle::new([c(q[0]), c(q[1]), c(q[2])]));
            tris.push(Triangle::new([c(q[0]), c(q[2]), c(q[3])]));
        }
    }
    let mut g = gpu(Precision::F64);
    for (grid, exact) in [
        (
            Grid::new([-3.0, 5.0, -0.5], 0.5 * 256.0, 256).unwrap(),
            true,
        ),
        (
            Grid::new([-3.0, 5.0, -0.5], 0.3 * 256.0, 256).unwrap(),
            false,
        ),
    ] {
        for mode in [Mode::Conservative, Mode::Thin] {
            g.set_mode(mode);
            let got = set(&g.voxelize_chunk_world(&grid, [0; 3], &tris).unwrap());
            let cpu = cpu_world(&grid, &tris, mode);
            assert_eq!(got, cpu, "{mode} voxel size {}", grid.voxel_size);
            let (m, a, _) = compare(&tris, &grid, mode, &got);
            assert!(m.is_empty() && a.is_empty(), "{mode}: {m:?} {a:?}");
            assert!(got.len() > 1000, "{}", got.len());
            eprintln!(
                "blocks {mode}, voxel size {}: {} voxels, {} triangles listed",
                grid.voxel_size,
                got.len(),
                g.last_fallback_triangles()
            );
            if exact {
                assert_eq!(g.last_fallback_triangles(), 0, "{mode}: listed");
            }
        }
    }
}
