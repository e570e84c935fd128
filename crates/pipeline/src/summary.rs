//! What a build reports: [`BuildSummary`], with its per-stage times.

use std::path::PathBuf;

use serde::Serialize;
use voxlod_voxelize::{Method, Mode};

pub use crate::context::StageTime;
use crate::memory::MemoryPlan;
use crate::stages::lod_write::octree_writer::LevelStats;
use crate::stages::voxelize::textures::TextureCacheSummary;
#[cfg(doc)]
use voxlod_ingest::MeshSource;

/// The source triangles a build stored (`--source-geometry`, docs/FORMAT.md 14.4).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct SourceSummary {
    /// Triangle/chunk pairs of the bins whose triangle touches its chunk.
    pub triangles_kept: u64,
    /// Of those, the pairs whose triangle reached past the quantization box and was clipped.
    pub triangles_clipped: u64,
    /// Triangles stored in the file (whole ones and clipped pieces), over the leaves with
    /// voxels: a chunk that triangles touch but that gets no voxel is not written.
    pub triangles_stored: u64,
    /// Their compressed payload bytes in the file.
    pub payload_bytes: u64,
    /// `payload_bytes / triangles_stored` (0 without triangles).
    pub bytes_per_triangle: f64,
}

/// What a build did.
#[derive(Clone, Debug, Serialize)]
pub struct BuildSummary {
    /// The input mesh's path as given.
    pub input: PathBuf,
    /// The octree file written.
    pub output: PathBuf,
    /// Input format as detected (e.g. `binary_little_endian PLY`).
    pub input_format: String,
    /// Triangles read, degenerate ones included.
    pub triangles: u64,
    /// Zero-area triangles skipped.
    pub degenerate_skipped: u64,
    /// Voxels per axis of the whole grid.
    pub resolution: u32,
    /// Edge of a level-0 voxel, in the input's units.
    pub voxel_size: f64,
    /// World position of the grid's minimum corner, x y z (the input's units).
    pub origin: [f64; 3],
    /// Conservative or thin.
    pub mode: Mode,
    /// The CPU voxelizer method (the GPU backend computes the overlap tests' set itself).
    pub voxelizer: Method,
    /// Worker threads used.
    pub threads: usize,
    /// The voxelizer that ran (backend, adapter, method, cutoff).
    pub backend: String,
    /// GPU backend: triangles voxelized in the classification pass (projected area under the
    /// cutoff) and triangles deferred to the second pass, summed over the chunks this run
    /// voxelized (a triangle counts once per chunk it was binned to). `None` on the CPU.
    pub gpu_split: Option<[u64; 2]>,
    /// GPU backend: chunks re-voxelized on the CPU as a whole, because more than 65,536 of
    /// their triangles had a decision inside its rounding band (the list's capacity).
    pub gpu_cpu_fallback_chunks: Option<u64>,
    /// GPU backend: triangles decided on the host with the CPU's exact test because one of
    /// their decisions was inside its rounding band (a triangle counts once per chunk).
    pub gpu_cpu_fallback_triangles: Option<u64>,
    /// GPU backend: chunks with a decision inside its rounding band.
    pub gpu_uncertain_chunks: Option<u64>,
    /// Non-empty leaf chunk bins (chunks some triangle's range touches).
    pub chunk_bins: usize,
    /// Triangle records in the bins (a triangle spanning k chunks counts k times).
    pub binned_triangles: u64,
    /// Nodes and voxels per level, finest first.
    pub levels: Vec<LevelStats>,
    /// Voxels over all levels.
    pub total_voxels: u64,
    /// Size of the octree file, bytes.
    pub bytes: u64,
    /// `bytes / total_voxels`.
    pub bytes_per_voxel: f64,
    /// How the memory budget was split.
    pub memory_plan: MemoryPlan,
    /// The tile cache of decoded textures larger than their share of the plan; `None` when
    /// they were held whole, the mesh has none, or a resumed build skipped the voxelize stage.
    pub texture_cache: Option<TextureCacheSummary>,
    /// Peak resident memory of the whole process (bytes).
    pub peak_rss: u64,
    /// Largest temporary disk use planned (bytes): spool (if one is written) plus bins.
    pub temp_disk: u64,
    /// Bytes this process wrote to the temporary triangle files, spool plus bins (a stage
    /// taken from the work folder of an interrupted build adds nothing).
    pub temp_bytes_written: u64,
    /// How the tile stage read the triangles: `"input"` (passes over the memory-mapped input,
    /// no spool) or `"spool"` (the input was parsed once into a spool).
    pub tile_source: &'static str,
    /// True if the chunk counts were taken during the ingest pass (the grid was known from the
    /// bounds of the vertex list before it, see [`MeshSource::vertex_bounds`]), so the tile
    /// stage had no count pass.
    pub counted_during_ingest: bool,
    /// True if the ingest pass also wrote the bins (in runs sorted by chunk, on the grid known
    /// before it: `voxlod_tile::RunScatter`), so the tile stage read nothing: one parse of the
    /// input in all.
    pub binned_during_ingest: bool,
    /// Bytes of one triangle record in the spool and in the bins' blocks before they are
    /// indexed (40–112: only the attributes the mesh has).
    pub record_bytes: usize,
    /// 0 if the bins held blocks of triangle records; 4 (or 8 past 2³² faces) if they held
    /// each triangle's face record instead, the voxelize stage reading the triangles from the
    /// memory-mapped input by index (a binary PLY of fixed-size triangle records).
    pub bin_index_bytes: usize,
    /// `--source-geometry`: the leaves' source triangles; `None` without it.
    pub source_geometry: Option<SourceSummary>,
    /// True if the build continued an interrupted one.
    pub resumed: bool,
    /// Time and peak memory of each stage, in the order they ran.
    pub stages: Vec<StageTime>,
    /// Wall time of the whole build, seconds.
    pub seconds: f64,
    /// Warnings (lossy conversions, skipped data).
    pub warnings: Vec<String>,
}
