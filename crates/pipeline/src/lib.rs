//! The voxlod build, end to end: ingest → tile → voxelize → LOD → write.
//!
//! Each stage's algorithms are a crate of their own and meet the next only through plain types
//! (`voxlod_geom::Triangle`, on-disk bins, `voxlod_format::Voxel`); this crate runs them in
//! order (`stages/`: one file per stage, each taking the previous stage's artifact and
//! returning its own, which is also its resume marker) over explicit on-disk intermediates in
//! a work folder, with a memory plan, progress bars and a summary.
//!
//! ```no_run
//! use voxlod_pipeline::{build, BuildSettings};
//! let settings = BuildSettings { resolution: 1024, ..Default::default() };
//! let summary = build("bunny.ply".as_ref(), "bunny.voxlod".as_ref(), &settings).unwrap();
//! println!("{} voxels at level 0", summary.levels[0].voxels);
//! ```

mod backend;
mod content_hash;
mod error;
mod leaf_log;
mod memory;
mod merge;
mod octree_writer;
mod output;
mod passes;
mod plan;
mod progress;
mod shard_file;
mod size;
mod source_clip;
mod source_mesh;
mod stages;
mod system;
mod textures;
mod window;
mod work;

pub use backend::{Backend, Cutoff, GpuMethod};
pub use error::StageError;
pub use memory::MemoryPlan;
pub use merge::{merge, MergeSummary};
pub use octree_writer::{LevelStats, NodeSink, OctreeWriter, StoredPayloads};
pub use output::{OutputGuard, OutputKind};
pub use plan::{
    Balance, Fingerprint, LoadedPlan, Plan, PlanGrid, PlanIngest, PlanInput, PlanSummary,
    ShardRange, ShardScope, PLAN_FORMAT, PLAN_VERSION,
};
pub use size::{format_size, parse_size};
pub use system::{interrupted, peak_rss, request_interrupt};
pub use textures::TextureCacheSummary;
pub use work::{find_work_folders, remove_stale_work_folder, WorkFolder, WORK_PREFIX};

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use voxlod_geom::Grid;
use voxlod_ingest::MeshSource;
use voxlod_voxelize::{Method, Mode};

use stages::{BuildContext, Built};
use work::WorkDir;

/// Everything a build depends on. Only `resolution`, `mode` and `zstd_level` affect the output
/// bytes (and `voxelizer` when it is the approximate `scanline-ilv`, `source_geometry` when it
/// adds the source-triangle channel); `threads`, `memory`,
/// `tmp_dir` and `progress` do not.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BuildSettings {
    /// Voxels per axis of the whole grid, 256·2^k.
    pub resolution: u32,
    /// Conservative (26-separating) or thin (6-separating).
    pub mode: Mode,
    /// CPU voxelizer method: sat (overlap tests) or scanline (Zhang et al.), the same voxels;
    /// scanline-ilv (integer-only, approximate, conservative only).
    pub voxelizer: Method,
    /// Worker threads; 0 = one per core.
    pub threads: usize,
    /// Memory budget in bytes for the whole process.
    #[serde(with = "size::serde_size")]
    pub memory: u64,
    /// zstd level of the node payloads.
    pub zstd_level: i32,
    /// Folder for temporary files (default: the output's folder).
    pub tmp_dir: Option<PathBuf>,
    /// Voxelizer: auto (a hardware GPU if found, else the CPU), cpu or gpu.
    pub backend: Backend,
    /// GPU method: hybrid, triangle or fragment.
    pub gpu_method: GpuMethod,
    /// GPU hybrid cutoff in voxels², or auto.
    pub cutoff: Cutoff,
    /// Store each leaf chunk's source triangles beside its voxels (FORMAT.md 14.4).
    pub source_geometry: bool,
    /// Show progress bars on stderr.
    #[serde(skip)]
    pub progress: bool,
    /// Replace an existing output file that is not a voxlod octree.
    #[serde(skip)]
    pub force: bool,
    /// For tests of resuming: request an interrupt after this many leaf chunks.
    #[serde(skip)]
    #[doc(hidden)]
    pub interrupt_after_chunks: Option<u64>,
    /// A sharded build (`build --plan --shard`): the plan's shard to build; `None` for a
    /// whole build.
    #[serde(skip)]
    pub shard: Option<ShardScope>,
}

impl Default for BuildSettings {
    fn default() -> Self {
        BuildSettings {
            resolution: 1024,
            mode: Mode::Conservative,
            voxelizer: Method::default(),
            threads: 0,
            memory: 2 << 30,
            zstd_level: voxlod_format::DEFAULT_ZSTD_LEVEL,
            tmp_dir: None,
            backend: Backend::Auto,
            gpu_method: GpuMethod::default(),
            cutoff: Cutoff::default(),
            source_geometry: false,
            progress: false,
            force: false,
            interrupt_after_chunks: None,
            shard: None,
        }
    }
}

/// A setting that is wrong on its own, named as in a settings file (`resolution`,
/// `zstd_level`), so that the command line can say where the value came from.
#[derive(Debug)]
pub struct SettingError {
    /// The setting's name in a settings file.
    pub field: &'static str,
    /// The value, as given.
    pub value: String,
    /// What is wrong with it.
    pub message: String,
}

impl std::fmt::Display for SettingError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} = {}: {}", self.field, self.value, self.message)
    }
}

impl std::error::Error for SettingError {}

impl BuildSettings {
    /// Checks the settings that can be wrong on their own (the memory budget is checked by
    /// [`MemoryPlan::new`], which knows the thread count).
    pub fn validate(&self) -> std::result::Result<(), SettingError> {
        if let Err(e) = Grid::new([0.0; 3], 1.0, self.resolution) {
            return Err(SettingError {
                field: "resolution",
                value: self.resolution.to_string(),
                message: e.to_string(),
            });
        }
        if !(-7..=22).contains(&self.zstd_level) {
            return Err(SettingError {
                field: "zstd_level",
                value: self.zstd_level.to_string(),
                message: "outside -7..=22".into(),
            });
        }
        Ok(())
    }
}

/// Wall-clock seconds and peak memory per stage.
#[derive(Clone, Debug, Serialize)]
pub struct StageTime {
    /// Stage name: `ingest`, `tile`, `voxelize` or `lod+write`.
    pub stage: &'static str,
    /// Wall time of the stage, seconds.
    pub seconds: f64,
    /// Peak resident memory of the process at the end of the stage (bytes; monotone).
    pub peak_rss: u64,
    /// True if the stage's result was taken from an interrupted earlier run.
    pub resumed: bool,
}

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

/// Builds the octree file `output` from the mesh `input`. A build that was killed or
/// interrupted resumes from its work folder when started again with the same arguments.
pub fn build(input: &Path, output: &Path, s: &BuildSettings) -> Result<BuildSummary> {
    let t0 = Instant::now();
    check_settings(s)?;
    let mut warnings = Vec::new();
    let threads = thread_count(s.threads, &mut warnings);
    if s.progress {
        for w in &warnings {
            eprintln!("warning: {w}");
        }
    }
    let plan = MemoryPlan::new(s.memory, threads)?;
    // The output is checked (not a folder, not the input, not another kind of file, writable
    // folder with some space) and locked before any work starts.
    let kind = match s.shard {
        Some(_) => OutputKind::Shard,
        None => OutputKind::Octree,
    };
    let guard = OutputGuard::acquire(output, &[input], kind, s.force)?;
    let source = MeshSource::open(input)?;
    let out_dir = crate::output::output_dir(output);
    let tmp_parent = s.tmp_dir.as_deref().unwrap_or(out_dir);
    let key = WorkDir::key(input, s)?;
    let (work, resumed) = WorkDir::open(tmp_parent, output, &key)?;
    if s.progress {
        eprintln!("{}", plan.describe());
        if resumed {
            eprintln!(
                "resuming the interrupted build kept in {}",
                work.path().display()
            );
        }
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("creating the thread pool")?;
    let mut ctx = BuildContext {
        settings: s,
        source: &source,
        input,
        output: &guard,
        pool,
        work: &work,
        plan,
        progress: s.progress,
        times: Vec::new(),
        warnings,
        interrupt: &system::INTERRUPTED,
    };
    match stages::run(&mut ctx) {
        Ok(built) => {
            let mut summary = summarize(ctx, built, resumed, t0);
            work.remove()?;
            warn_stale_folders(tmp_parent, &mut summary.warnings);
            Ok(summary)
        }
        Err(e) => Err(failed(e, work)),
    }
}

/// Builds shard `index` of the plan at `plan_path` (`voxlod build --plan --shard`): the
/// plan's settings, with `threads`, `memory`, `tmp_dir`, `progress` and `force` from
/// `runtime`; the shard file goes to `out_dir` (default: beside the plan). Refuses an input
/// whose fingerprint differs from the plan's. Resumable like any build.
pub fn build_shard(
    plan_path: &Path,
    index: u32,
    out_dir: Option<&Path>,
    runtime: &BuildSettings,
) -> Result<BuildSummary> {
    let plan = LoadedPlan::load(plan_path)?;
    let scope = plan.scope(index)?;
    let input = &plan.plan.input.path;
    let now = Fingerprint::of(input)?;
    if now != plan.plan.input.fingerprint {
        bail!(
            "{}: the input changed since {} was planned (size, modification time or first/last MiB differ): plan again",
            input.display(),
            plan_path.display()
        );
    }
    let mut s = plan.plan.settings.clone();
    s.threads = runtime.threads;
    s.memory = runtime.memory;
    s.tmp_dir = runtime.tmp_dir.clone();
    s.progress = runtime.progress;
    s.force = runtime.force;
    s.interrupt_after_chunks = runtime.interrupt_after_chunks;
    s.shard = Some(scope);
    build(input, &plan.shard_path(index, out_dir), &s)
}

/// Plans a sharded build of `input` (`voxlod plan`): one pass for the bounds and the
/// per-chunk triangle counts (the ingest and count passes of a build, on the same grid), the
/// split level and `shards` Morton ranges (`plan.rs`), written to `plan_path` as JSON.
pub fn plan(input: &Path, plan_path: &Path, s: &BuildSettings, shards: u32) -> Result<PlanSummary> {
    let t0 = Instant::now();
    check_settings(s)?;
    if shards == 0 {
        bail!("--shards 0: a plan needs at least one shard");
    }
    let mut warnings = Vec::new();
    let threads = thread_count(s.threads, &mut warnings);
    let mplan = MemoryPlan::new(s.memory, threads)?;
    let guard = OutputGuard::acquire(plan_path, &[input], OutputKind::Plan, s.force)?;
    let fingerprint = Fingerprint::of(input)?;
    let source = MeshSource::open(input)?;
    let tmp_parent = s
        .tmp_dir
        .as_deref()
        .unwrap_or(crate::output::output_dir(plan_path));
    let (work, _) = WorkDir::open(tmp_parent, plan_path, &WorkDir::key(input, s)?)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("creating the thread pool")?;
    let mut ctx = BuildContext {
        settings: s,
        source: &source,
        input,
        output: &guard,
        pool,
        work: &work,
        plan: mplan,
        progress: s.progress,
        times: Vec::new(),
        warnings,
        interrupt: &system::INTERRUPTED,
    };
    // the content checksum on a thread of its own beside the passes
    let (counted, xxh3) = content_hash::beside(input, &system::INTERRUPTED, || {
        stages::ingest::run(&mut ctx).and_then(|mut ing| {
            let counts = stages::tile::counts(&ctx, &mut ing)?;
            Ok((ing, counts))
        })
    });
    let (ingested, counts, xxh3) = match (counted, xxh3) {
        (Ok((i, c)), Ok(Some(h))) => (i, c, h),
        (Err(e), _) | (_, Err(e)) => return Err(failed(e, work)),
        (Ok(_), Ok(None)) => {
            let e = StageError::Interrupted {
                work: work.path().to_path_buf(),
            };
            return Err(failed(e, work));
        }
    };
    let leaves: Vec<(u64, u64)> = counts
        .layout()
        .iter()
        .map(|c| (c.morton, c.count))
        .collect();
    let levels = ingested.grid.levels();
    let (split_level, ranges, balance) = plan::choose_split(&leaves, levels, shards as usize);
    let mut warnings = ctx.warnings.clone();
    warnings.extend(plan::balance_warning(shards, split_level, &balance));
    let p = Plan {
        format: PLAN_FORMAT.into(),
        version: PLAN_VERSION,
        tool_version: env!("CARGO_PKG_VERSION").into(),
        input: PlanInput::of(input, fingerprint, xxh3)?,
        settings: s.clone(),
        grid: ingested.grid.into(),
        ingest: stages::ingest::planned(&ingested.marker),
        chunks: leaves.iter().map(|&(m, c)| [m, c]).collect(),
        levels,
        manifest: stages::lod_write::manifest_fields(&ctx, &ingested),
        channels: stages::lod_write::channels(&ctx),
        split_level,
        shards: ranges.clone(),
        balance: balance.clone(),
    };
    let text = serde_json::to_vec_pretty(&p).context("serializing the plan")?;
    plan::write_atomically(&guard, &text)?;
    work.remove()?;
    Ok(PlanSummary {
        plan: plan_path.to_path_buf(),
        triangles: ingested.marker.triangles,
        chunks: leaves.len() as u64,
        split_level,
        shards: ranges,
        balance,
        seconds: t0.elapsed().as_secs_f64(),
        warnings,
    })
}

/// The settings checks every entry makes before any work.
fn check_settings(s: &BuildSettings) -> Result<()> {
    s.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    if !s.voxelizer.supports(s.mode) {
        bail!(
            "--voxelizer {} approximates the conservative set only; use --voxelizer scanline (or sat) with {} mode",
            s.voxelizer,
            s.mode
        );
    }
    Ok(())
}

/// Worker threads for `-j n` (0: one per core). More threads than cores never helps (every
/// stage is bound by the CPU or the disk), and thousands of them only thrash.
fn thread_count(asked: usize, warnings: &mut Vec<String>) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if asked == 0 {
        cores
    } else if asked > cores {
        warnings.push(format!(
            "-j {asked}: capped at {cores}, the number of cores (more threads than cores only slow the build down)"
        ));
        cores
    } else {
        asked
    }
}

/// The error of a failed build, and what becomes of its work folder: kept after an interrupt
/// (to resume) and after a failure to write the output once every chunk is voxelized (to only
/// write the file next time), removed otherwise.
fn failed(e: StageError, work: WorkDir) -> anyhow::Error {
    if matches!(e, StageError::Interrupted { .. }) || interrupted() {
        return StageError::Interrupted {
            work: work.path().to_path_buf(),
        }
        .into();
    }
    let e = anyhow::Error::from(e);
    if work.file(work::WorkFile::LeavesMarker).exists() && is_output_failure(&e) {
        // Every chunk is voxelized: keep them, so that once the output side is fixed
        // (space, permissions) the same command only writes the file.
        return anyhow::anyhow!(
            "{}; the voxelized chunks are kept in {}: run the same command again to write only the file",
            chain_text(&e),
            work.path().display()
        );
    }
    // A failed build leaves nothing behind (a killed one keeps its folder to resume).
    let _ = work.remove();
    e
}

/// Warns of work folders of earlier builds that were killed and not resumed (issue 17).
fn warn_stale_folders(tmp_parent: &Path, warnings: &mut Vec<String>) {
    let stale: Vec<_> = find_work_folders(tmp_parent)
        .unwrap_or_default()
        .into_iter()
        .filter(WorkFolder::is_stale)
        .collect();
    if stale.is_empty() {
        return;
    }
    let bytes = stale.iter().map(|f| f.bytes).sum();
    warnings.push(format!(
        "{} stale work folder{} of earlier interrupted builds ({}) in {}: `voxlod clean {}` lists and removes them",
        stale.len(),
        if stale.len() == 1 { "" } else { "s" },
        format_size(bytes),
        tmp_parent.display(),
        tmp_parent.display()
    ));
}

/// A failure of writing the output (I/O on it, too little space, the final rename), as
/// opposed to bad data: worth keeping the work for.
fn is_output_failure(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.is::<std::io::Error>()
            || matches!(
                c.downcast_ref::<StageError>(),
                Some(
                    StageError::Output(_)
                        | StageError::Io { .. }
                        | StageError::Format(voxlod_format::FormatError::Io { .. })
                )
            )
            || matches!(
                c.downcast_ref::<voxlod_format::FormatError>(),
                Some(voxlod_format::FormatError::Io { .. })
            )
    })
}

/// The summary of a finished build from its stages' artifacts.
fn summarize(ctx: BuildContext, built: Built, resumed: bool, t0: Instant) -> BuildSummary {
    let Built {
        ingested,
        voxelized,
        written,
        source,
    } = built;
    // stored: what the file holds (the source log also has chunks that got no voxels)
    let stored = written.source;
    let source_geometry = source.map(|m| SourceSummary {
        triangles_kept: m.counts.kept,
        triangles_clipped: m.counts.clipped,
        triangles_stored: stored.triangles,
        payload_bytes: stored.payload_bytes,
        bytes_per_triangle: if stored.triangles > 0 {
            stored.payload_bytes as f64 / stored.triangles as f64
        } else {
            0.0
        },
    });
    let s = ctx.settings;
    let total_voxels: u64 = written.levels.iter().map(|l| l.voxels).sum();
    let gpu = voxelized.gpu_stats;
    BuildSummary {
        input: ctx.input.to_path_buf(),
        output: ctx.output.output().to_path_buf(),
        input_format: ctx.source.info().format.clone(),
        triangles: ingested.marker.triangles,
        degenerate_skipped: ingested.marker.degenerate_skipped,
        resolution: s.resolution,
        mode: s.mode,
        voxelizer: s.voxelizer,
        threads: ctx.pool.current_num_threads(),
        backend: voxelized.backend,
        gpu_split: gpu.map(|g| g.split),
        gpu_cpu_fallback_chunks: gpu.map(|g| g.cpu_fallback_chunks),
        gpu_cpu_fallback_triangles: gpu.map(|g| g.cpu_fallback_triangles),
        gpu_uncertain_chunks: gpu.map(|g| g.uncertain_chunks),
        chunk_bins: voxelized.marker.records as usize,
        binned_triangles: voxelized.marker.binned_triangles,
        total_voxels,
        bytes_per_voxel: if total_voxels > 0 {
            written.bytes as f64 / total_voxels as f64
        } else {
            0.0
        },
        bytes: written.bytes,
        levels: written.levels,
        memory_plan: ctx.plan,
        texture_cache: voxelized.texture_cache,
        peak_rss: system::peak_rss(),
        temp_disk: ingested.temp_disk,
        temp_bytes_written: ingested.temp_written,
        tile_source: if ingested.marker.spooled {
            "spool"
        } else {
            "input"
        },
        counted_during_ingest: ingested.counted_during_ingest,
        binned_during_ingest: ingested.binned_during_ingest,
        record_bytes: ingested.layout.bytes(),
        source_geometry,
        resumed,
        stages: ctx.times,
        seconds: t0.elapsed().as_secs_f64(),
        warnings: ctx.warnings,
    }
}

/// An error and its causes as one line, each cause once (an OS error is often both in its
/// wrapper's message and its source).
pub fn chain_text(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for c in e.chain() {
        let s = c.to_string();
        if text.contains(&s) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&s);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The presets in configs/ parse, with the enum settings' documented strings.
    #[test]
    fn config_presets_parse() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs");
        let d: BuildSettings =
            toml::from_str(&std::fs::read_to_string(dir.join("default.toml")).unwrap()).unwrap();
        assert_eq!(d.gpu_method, GpuMethod::Hybrid);
        assert_eq!(
            (d.mode, d.voxelizer),
            (Mode::Conservative, Method::Scanline)
        );
        assert_eq!((d.backend, d.cutoff), (Backend::Auto, Cutoff::Fixed(8.0)));
        for name in ["preview.toml", "scan.toml"] {
            let s: BuildSettings =
                toml::from_str(&std::fs::read_to_string(dir.join(name)).unwrap()).unwrap();
            assert_eq!(s.mode, Mode::Thin, "{name}");
        }
        let all = "mode = \"thin\"\nvoxelizer = \"scanline-ilv\"\nbackend = \"gpu\"\ngpu_method = \"fragment\"\ncutoff = \"auto\"";
        let s: BuildSettings = toml::from_str(all).unwrap();
        assert_eq!(
            (s.mode, s.voxelizer, s.backend, s.gpu_method, s.cutoff),
            (
                Mode::Thin,
                Method::ScanlineIlv,
                Backend::Gpu,
                GpuMethod::Fragment,
                Cutoff::Auto
            )
        );
    }

    /// A bad value of an enum setting in a settings file is refused when the file is read,
    /// with an error that names the key and the value.
    #[test]
    fn bad_enum_value_in_a_settings_file_names_the_key() {
        for (key, value) in [
            ("mode", "\"thick\""),
            ("voxelizer", "\"raster\""),
            ("backend", "\"tpu\""),
            ("gpu_method", "\"mesh\""),
            ("cutoff", "\"often\""),
            ("cutoff", "-2"),
        ] {
            let text = format!("resolution = 512\n{key} = {value}\n");
            let e = toml::from_str::<BuildSettings>(&text)
                .err()
                .unwrap_or_else(|| panic!("{key} = {value} was accepted"))
                .to_string();
            assert!(
                e.contains(&format!("{key} = {value}")) && e.contains("line 2"),
                "{key} = {value}: {e}"
            );
        }
    }
}
