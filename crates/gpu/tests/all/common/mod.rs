//! Test helpers of the GPU tests: mesh loading and the RNG from `voxlod-testkit`, grid fitting,
//! random attributes and the CPU-vs-GPU comparison.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use voxlod_format::voxel::unpack_normal;
use voxlod_format::Voxel;
use voxlod_geom::{Bounds, Grid, Triangle};
use voxlod_gpu::{GpuMethod, GpuVoxelizer, DEFAULT_CUTOFF};
use voxlod_voxelize::{ChunkVoxelizer, Mode};

pub use voxlod_testkit::Rng;

/// The shared meshes folder, or None (test skipped, with a message) when it is missing;
/// with CI=true a missing folder is a failure.
pub fn meshes_dir() -> Option<PathBuf> {
    voxlod_testkit::shared_meshes("voxlod-gpu tests")
}

/// Positions of a mesh's triangles (fan-triangulated polygons), read by the test kit's
/// reader (independent of voxlod-ingest): PLY (ASCII, binary) or OBJ by extension.
pub fn load_mesh(path: &Path) -> Vec<[[f32; 3]; 3]> {
    voxlod_testkit::mesh::triangles_f32(&voxlod_testkit::mesh::read_mesh(path))
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

/// Random per-vertex colours and (when `normals`) random vertex normals near a common direction.
pub fn decorate(t: &mut Triangle, rng: &mut Rng, normals: bool) {
    for k in 0..3 {
        t.c[k] = [
            rng.next_u64() as u8,
            rng.next_u64() as u8,
            rng.next_u64() as u8,
            rng.next_u64() as u8,
        ];
    }
    t.flags |= voxlod_geom::TRI_HAS_COLORS;
    if normals {
        // vertex normals around one random direction, as on a real surface: independent random
        // ones can cancel inside the triangle, where the voxel's normal is rounding noise on
        // either side (the documented exception of the GPU/CPU contract, gpu crate docs)
        let d = loop {
            let d = [0, 1, 2].map(|_| rng.range_f32(-1.0, 1.0));
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if (0.1..=1.0).contains(&l) {
                break d.map(|x| x / l);
            }
        };
        for k in 0..3 {
            t.n[k] = d.map(|x| x + 0.3 * rng.range_f32(-1.0, 1.0));
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

/// Every GPU voxelization method (the same voxels, different passes).
pub const METHODS: [GpuMethod; 3] = [GpuMethod::Hybrid, GpuMethod::Triangle, GpuMethod::Fragment];

/// A conservative hybrid GPU voxelizer; no adapter is a test FAILURE (lavapipe is enough).
pub fn gpu() -> GpuVoxelizer {
    GpuVoxelizer::new(Mode::Conservative, GpuMethod::Hybrid, DEFAULT_CUTOFF)
        .unwrap_or_else(|e| panic!("this test needs a GPU adapter (lavapipe is enough): {e}"))
}

/// The CPU chunk voxelizer's voxels of `tris` in the chunk at `origin` (the exact reference).
pub fn cpu(mode: Mode, origin: [u32; 3], tris: &[Triangle]) -> Vec<Voxel> {
    let mut c = ChunkVoxelizer::new(mode);
    c.begin(origin);
    c.add(tris);
    c.finish()
}
