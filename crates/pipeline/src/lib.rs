//! The voxlod build, end to end: ingest → tile → voxelize → LOD → write.
//!
//! Each stage is a crate of its own and meets the next only through plain types
//! (`voxlod_geom::Triangle`, on-disk bins, `voxlod_format::Voxel`); this crate runs them in
//! order over explicit on-disk intermediates in a temporary folder, with a memory plan, progress
//! bars and a summary.
//!
//! ```no_run
//! use voxlod_pipeline::{build, BuildSettings};
//! let settings = BuildSettings { resolution: 1024, ..Default::default() };
//! let summary = build("bunny.ply".as_ref(), "bunny.voxlod".as_ref(), &settings).unwrap();
//! println!("{} voxels at level 0", summary.levels[0].voxels);
//! ```

mod memory;
mod octree_writer;
mod progress;
mod size;

pub use memory::MemoryPlan;
pub use octree_writer::{LevelStats, OctreeWriter};
pub use size::{format_size, parse_size};

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use voxlod_format::{encode_node, FileSpec, Writer};
use voxlod_geom::Grid;
use voxlod_ingest::{IngestError, MeshSource};
use voxlod_tile::{Spooler, TileError};
use voxlod_voxelize::{ChunkVoxelizer, Mode};

use progress::Stage;

/// Everything a build depends on. Only `resolution`, `mode` and `zstd_level` affect the output
/// bytes; `threads`, `memory`, `tmp_dir` and `progress` do not.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BuildSettings {
    /// Voxels per axis of the whole grid, 256·2^k.
    pub resolution: u32,
    /// Conservative (26-separating) or thin (6-separating).
    pub mode: Mode,
    /// Worker threads; 0 = one per core.
    pub threads: usize,
    /// Memory budget in bytes for the whole process.
    #[serde(with = "size::serde_size")]
    pub memory: u64,
    /// zstd level of the node payloads.
    pub zstd_level: i32,
    /// Folder for temporary files (default: the output's folder).
    pub tmp_dir: Option<PathBuf>,
    /// Show progress bars on stderr.
    #[serde(skip)]
    pub progress: bool,
}

impl Default for BuildSettings {
    fn default() -> Self {
        BuildSettings {
            resolution: 1024,
            mode: Mode::Conservative,
            threads: 0,
            memory: 2 << 30,
            zstd_level: voxlod_format::DEFAULT_ZSTD_LEVEL,
            tmp_dir: None,
            progress: false,
        }
    }
}

/// Wall-clock seconds per stage.
#[derive(Clone, Debug, Serialize)]
pub struct StageTime {
    pub stage: &'static str,
    pub seconds: f64,
}

/// What a build did.
#[derive(Clone, Debug, Serialize)]
pub struct BuildSummary {
    pub input: PathBuf,
    pub output: PathBuf,
    pub input_format: String,
    pub triangles: u64,
    pub degenerate_skipped: u64,
    pub resolution: u32,
    pub mode: Mode,
    pub threads: usize,
    /// Non-empty leaf chunk bins (chunks some triangle's range touches).
    pub chunk_bins: usize,
    /// Triangle records in the bins (a triangle spanning k chunks counts k times).
    pub binned_triangles: u64,
    pub levels: Vec<LevelStats>,
    pub total_voxels: u64,
    pub bytes: u64,
    pub bytes_per_voxel: f64,
    pub memory_plan: MemoryPlan,
    pub stages: Vec<StageTime>,
    pub seconds: f64,
    pub warnings: Vec<String>,
}

fn tile_err(e: TileError) -> IngestError {
    IngestError::Callback(e.to_string())
}

/// Builds the octree file `output` from the mesh `input`.
pub fn build(input: &Path, output: &Path, s: &BuildSettings) -> Result<BuildSummary> {
    let t0 = Instant::now();
    let grid_check = Grid::new([0.0; 3], 1.0, s.resolution);
    if let Err(e) = grid_check {
        bail!("--resolution: {e}");
    }
    if !(-7..=22).contains(&s.zstd_level) {
        bail!("zstd level {} is outside -7..=22", s.zstd_level);
    }
    let threads = if s.threads == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        s.threads
    };
    let plan = MemoryPlan::new(s.memory, threads)?;
    if s.progress {
        eprintln!("{}", plan.describe());
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("creating the thread pool")?;

    let source = MeshSource::open(input)?;
    let info = source.info().clone();
    let out_dir = output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let tmp_parent = s.tmp_dir.as_deref().unwrap_or(out_dir);
    let tmp = tempfile::Builder::new()
        .prefix(".voxlod-tmp-")
        .tempdir_in(tmp_parent)
        .with_context(|| format!("creating a temporary folder in {}", tmp_parent.display()))?;
    let mut stages = Vec::new();
    let mut warnings = Vec::new();

    // Ingest: parse the input once, spooling triangles (world coordinates) to disk.
    let t = Instant::now();
    let bar = Stage::bytes(
        s.progress,
        "ingest",
        std::fs::metadata(input).map(|m| m.len()).unwrap_or(0),
    );
    let mut spooler = Spooler::create(&tmp.path().join("spool.tri"))?;
    let stats = source.stream(
        &mut |tris| spooler.push(tris).map_err(tile_err),
        &mut |done, total| bar.set(done, total),
    )?;
    let spool = spooler.finish()?;
    bar.finish();
    stages.push(StageTime {
        stage: "ingest",
        seconds: t.elapsed().as_secs_f64(),
    });
    if stats.degenerate_skipped > 0 {
        warnings.push(format!(
            "{} degenerate (zero-area) triangles skipped",
            stats.degenerate_skipped
        ));
    }
    warnings.extend(
        info.warnings
            .iter()
            .map(|w| format!("{}: {w}", input.display())),
    );
    if spool.count == 0 {
        bail!(
            "{}: the mesh has no (non-degenerate) triangles",
            input.display()
        );
    }

    // Tile: count per chunk, then scatter into pre-sized on-disk bins.
    let t = Instant::now();
    let grid = Grid::fit(&spool.bounds, s.resolution)
        .with_context(|| format!("{}: fitting the grid", input.display()))?;
    let bar = Stage::items(s.progress, "count", spool.count);
    let counts = spool.count(&grid, &mut |d, n| bar.set(d, n))?;
    bar.finish();
    let bar = Stage::items(s.progress, "scatter", spool.count);
    let bins = spool.scatter(
        &grid,
        &counts,
        &tmp.path().join("bins.tri"),
        plan.scatter_buffer,
        &mut |d, n| bar.set(d, n),
    )?;
    bar.finish();
    drop(counts);
    spool.remove()?;
    stages.push(StageTime {
        stage: "tile",
        seconds: t.elapsed().as_secs_f64(),
    });

    // Voxelize the leaf chunks in parallel batches (Morton order kept), then write them and
    // their parents in post-order.
    let t = Instant::now();
    let spec = FileSpec {
        resolution: grid.resolution,
        levels: grid.levels(),
        mode: s.mode as u32,
        origin: grid.origin,
        voxel_size: grid.voxel_size,
    };
    let writer = Writer::create(output, spec)?;
    let mut octree = OctreeWriter::new(writer, grid.levels(), s.zstd_level);
    let workers: Vec<Mutex<ChunkVoxelizer>> = (0..plan.voxelizers)
        .map(|_| Mutex::new(ChunkVoxelizer::new(s.mode)))
        .collect();
    let chunks = bins.chunks();
    let bar = Stage::items(s.progress, "voxelize", chunks.len() as u64);
    let batch = plan.voxelizers * 4;
    let mut done = 0u64;
    let mut skipped = 0u64;
    for first in (0..chunks.len()).step_by(batch) {
        let last = (first + batch).min(chunks.len());
        let results: Vec<
            Result<(
                Vec<voxlod_format::Voxel>,
                Option<voxlod_format::EncodedNode>,
                u64,
            )>,
        > = pool.install(|| {
            (first..last)
                .into_par_iter()
                .map(|i| {
                    let slot = rayon::current_thread_index().unwrap_or(0) % workers.len();
                    let mut vz = workers[slot].lock().unwrap_or_else(|p| p.into_inner());
                    let before = vz.skipped();
                    vz.begin(chunks[i].origin());
                    bins.read_chunk(i, 64 * 1024, &mut |tris| {
                        vz.add(tris);
                        Ok(())
                    })?;
                    let voxels = vz.finish();
                    let skipped = vz.skipped() - before;
                    drop(vz);
                    let enc = if voxels.is_empty() {
                        None
                    } else {
                        Some(encode_node(&voxels, s.zstd_level).with_context(|| {
                            format!("encoding leaf chunk {:?}", chunks[i].coord)
                        })?)
                    };
                    Ok((voxels, enc, skipped))
                })
                .collect()
        });
        for (i, r) in (first..last).zip(results) {
            let (voxels, enc, sk) = r?;
            skipped += sk;
            octree.push_leaf(chunks[i].coord, voxels, enc.as_ref())?;
        }
        done += (last - first) as u64;
        bar.set(done, chunks.len() as u64);
    }
    bar.finish();
    drop(workers);
    if skipped > 0 {
        warnings.push(format!("{skipped} triangle/chunk pairs skipped by the voxelizer (zero area after the move to grid coordinates)"));
    }
    let chunk_bins = chunks.len();
    let binned_triangles = bins.total();
    bins.remove()?;

    let manifest_settings = serde_json::json!({
        "resolution": s.resolution,
        "mode": s.mode.to_string(),
        "zstd_level": s.zstd_level,
    });
    let input_name = input
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let bounds = spool_bounds_json(&grid);
    let (bytes, levels) = octree.finish(|levels| {
        serde_json::json!({
            "tool": "voxlod",
            "tool_version": env!("CARGO_PKG_VERSION"),
            "input": { "file": input_name, "format": info.format, "triangles": stats.triangles,
                       "degenerate_skipped": stats.degenerate_skipped },
            "settings": manifest_settings,
            "grid": bounds,
            "levels": levels,
        })
    })?;
    stages.push(StageTime {
        stage: "voxelize+lod+write",
        seconds: t.elapsed().as_secs_f64(),
    });
    tmp.close().context("removing the temporary folder")?;

    let total_voxels: u64 = levels.iter().map(|l| l.voxels).sum();
    Ok(BuildSummary {
        input: input.to_path_buf(),
        output: output.to_path_buf(),
        input_format: info.format.clone(),
        triangles: stats.triangles,
        degenerate_skipped: stats.degenerate_skipped,
        resolution: s.resolution,
        mode: s.mode,
        threads,
        chunk_bins,
        binned_triangles,
        total_voxels,
        bytes_per_voxel: if total_voxels > 0 {
            bytes as f64 / total_voxels as f64
        } else {
            0.0
        },
        bytes,
        levels,
        memory_plan: plan,
        stages,
        seconds: t0.elapsed().as_secs_f64(),
        warnings,
    })
}

fn spool_bounds_json(grid: &Grid) -> serde_json::Value {
    serde_json::json!({
        "origin": grid.origin,
        "voxel_size": grid.voxel_size,
        "resolution": grid.resolution,
        "levels": grid.levels(),
    })
}
