//! Voxelizing a whole grid in memory, chunk by chunk in parallel (rayon), for small meshes,
//! tests and benchmarks. The out-of-core pipeline drives [`ChunkVoxelizer`] itself from tile
//! bins; this is the same computation on one in-memory triangle list.

use std::collections::BTreeMap;
use std::sync::Mutex;

use rayon::prelude::*;
use voxlod_format::Voxel;
use voxlod_geom::{morton3, Grid, GridError, Triangle, CHUNK};

use crate::{ChunkVoxelizer, Mode, TriSetup};

/// The voxels of a grid: non-empty chunks in order of the Morton code of their chunk
/// coordinates, each with its voxels as [`ChunkVoxelizer::finish`] returns them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GridVoxels {
    /// Non-empty chunks: chunk coordinates and voxels.
    pub chunks: Vec<([u32; 3], Vec<Voxel>)>,
    /// Zero-area or non-finite triangles.
    pub skipped: u64,
}

impl GridVoxels {
    /// Total voxel count.
    pub fn len(&self) -> usize {
        self.chunks.iter().map(|c| c.1.len()).sum()
    }
    /// True if no chunk holds a voxel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Voxelizes triangles given in grid coordinates of a `resolution³` grid (256·2^k). Triangles are
/// binned to every chunk their closed voxel bounding box touches, in input order, so the result
/// does not depend on the thread count.
pub fn voxelize_grid(
    tris: &[Triangle],
    resolution: u32,
    mode: Mode,
) -> Result<GridVoxels, GridError> {
    let grid = Grid::new([0.0; 3], resolution as f64, resolution)?;
    let mut skipped = 0u64;
    let mut bins: BTreeMap<u64, ([u32; 3], Vec<Triangle>)> = BTreeMap::new();
    for t in tris {
        if TriSetup::new(&t.v, mode).is_none() {
            skipped += 1;
            continue;
        }
        let Some((lo, hi)) = grid.chunk_range(t) else {
            continue;
        };
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    bins.entry(morton3(x, y, z))
                        .or_insert_with(|| ([x, y, z], Vec::new()))
                        .1
                        .push(*t);
                }
            }
        }
    }
    // at most one voxelizer per worker thread
    let pool: Mutex<Vec<ChunkVoxelizer>> = Mutex::new(Vec::new());
    let bins: Vec<([u32; 3], Vec<Triangle>)> = bins.into_values().collect();
    let mut chunks: Vec<([u32; 3], Vec<Voxel>)> = bins
        .par_iter()
        .map(|(c, ts)| {
            let mut cv = pool
                .lock()
                .ok()
                .and_then(|mut p| p.pop())
                .unwrap_or_else(|| ChunkVoxelizer::new(mode));
            cv.begin(c.map(|x| x * CHUNK));
            cv.add(ts);
            let v = cv.finish();
            if let Ok(mut p) = pool.lock() {
                p.push(cv);
            }
            (*c, v)
        })
        .collect();
    chunks.retain(|c| !c.1.is_empty());
    Ok(GridVoxels { chunks, skipped })
}
