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

mod backend;
mod leaf_log;
mod memory;
mod octree_writer;
mod output;
mod passes;
mod progress;
mod size;
mod system;
mod textures;
mod window;
mod work;

pub use backend::{Backend, Cutoff};
pub use memory::MemoryPlan;
pub use octree_writer::{LevelStats, OctreeWriter};
pub use output::{OutputGuard, OutputKind};
pub use size::{format_size, parse_size};
pub use system::{interrupted, peak_rss, request_interrupt};
pub use work::{find_work_folders, remove_stale_work_folder, WorkFolder, WORK_PREFIX};

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use voxlod_format::{encode_node, EncodedNode, FileSpec, Voxel, Writer};
use voxlod_geom::{Bounds, Grid, Triangle};
use voxlod_ingest::{IngestError, MeshSource};
use voxlod_tile::{Bins, ChunkBin, ChunkCounts, Passes, RecordLayout, Spool, Spooler, TileError};
use voxlod_voxelize::{Method, Mode};

use leaf_log::LeafLog;
use progress::Stage;
use work::WorkDir;

/// Everything a build depends on. Only `resolution`, `mode` and `zstd_level` affect the output
/// bytes (and `voxelizer` when it is the approximate `scanline-ilv`); `threads`, `memory`,
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
    pub gpu_method: String,
    /// GPU hybrid cutoff in voxels², or auto.
    pub cutoff: Cutoff,
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
            gpu_method: "hybrid".into(),
            cutoff: Cutoff::default(),
            progress: false,
            force: false,
            interrupt_after_chunks: None,
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
    /// GPU backend: chunks re-voxelized on the CPU because a decision was inside its rounding
    /// band (f64; in f32 only an uncertain normal sign), so that the sets are exact.
    pub gpu_cpu_fallback_chunks: Option<u64>,
    /// GPU backend: chunks with a decision inside its rounding band (in f32 counted as inside
    /// unless the chunk fell back: the set is then a conservative superset).
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
    /// Peak resident memory of the whole process (bytes).
    pub peak_rss: u64,
    /// Largest temporary disk use planned (bytes): spool (if one is written) plus bins.
    pub temp_disk: u64,
    /// How the tile stage read the triangles: `"input"` (passes over the memory-mapped input,
    /// no spool) or `"spool"` (the input was parsed once into a spool).
    pub tile_source: &'static str,
    /// True if the chunk counts were taken during the ingest pass (the grid was known from the
    /// bounds of the vertex list before it, see [`MeshSource::vertex_bounds`]), so the tile
    /// stage had no count pass.
    pub counted_during_ingest: bool,
    /// Bytes of one triangle record in the spool and bins (40–112: only the attributes the
    /// mesh has).
    pub record_bytes: usize,
    /// True if the build continued an interrupted one.
    pub resumed: bool,
    /// Time and peak memory of each stage, in the order they ran.
    pub stages: Vec<StageTime>,
    /// Wall time of the whole build, seconds.
    pub seconds: f64,
    /// Warnings (lossy conversions, skipped data).
    pub warnings: Vec<String>,
}

fn tile_err(e: TileError) -> IngestError {
    IngestError::Callback(e.to_string())
}

/// What the ingest stage leaves for a resumed run (`spool.json`).
#[derive(Serialize, Deserialize)]
struct SpoolMarker {
    /// True if the triangles were written to `spool.tri`; false if the tile stage reads the
    /// input again.
    spooled: bool,
    count: u64,
    min: [f64; 3],
    max: [f64; 3],
    triangles: u64,
    degenerate_skipped: u64,
    warnings: Vec<String>,
}

/// The bins layout (`bins.json`): `[x, y, z, start, count]` per non-empty chunk.
#[derive(Serialize, Deserialize)]
struct BinsMarker {
    chunks: Vec<[u64; 5]>,
}

/// The voxelize stage's totals (`leaves.json`).
#[derive(Serialize, Deserialize)]
struct LeavesMarker {
    records: u64,
    skipped: u64,
    binned_triangles: u64,
}

fn interrupted_error(work: &Path) -> anyhow::Error {
    anyhow::anyhow!(
        "interrupted; the work done so far is kept in {}: run the same command again to resume",
        work.display()
    )
}

/// Builds the octree file `output` from the mesh `input`. A build that was killed or
/// interrupted resumes from its work folder when started again with the same arguments.
pub fn build(input: &Path, output: &Path, s: &BuildSettings) -> Result<BuildSummary> {
    let t0 = Instant::now();
    s.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    if !s.voxelizer.supports(s.mode) {
        bail!(
            "--voxelizer {} approximates the conservative set only; use --voxelizer scanline (or sat) with {} mode",
            s.voxelizer,
            s.mode
        );
    }
    // More threads than cores never helps (every stage is bound by the CPU or the disk), and
    // thousands of them only thrash.
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut warnings = Vec::new();
    let threads = if s.threads == 0 {
        cores
    } else if s.threads > cores {
        warnings.push(format!(
            "-j {}: capped at {cores}, the number of cores (more threads than cores only slow the build down)",
            s.threads
        ));
        cores
    } else {
        s.threads
    };
    if s.progress {
        for w in &warnings {
            eprintln!("warning: {w}");
        }
    }
    let plan = MemoryPlan::new(s.memory, threads)?;
    // The output is checked (not a folder, not the input, not another kind of file, writable
    // folder with some space) and locked before any work starts.
    let guard = OutputGuard::acquire(output, &[input], OutputKind::Octree, s.force)?;
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
    let r = run(
        &source, input, &guard, s, threads, plan, &work, resumed, t0, warnings,
    );
    match r {
        Ok(mut summary) => {
            work.remove()?;
            // work folders of earlier builds that were killed and not resumed (issue 17)
            let stale: Vec<_> = find_work_folders(tmp_parent)
                .unwrap_or_default()
                .into_iter()
                .filter(WorkFolder::is_stale)
                .collect();
            if !stale.is_empty() {
                let bytes = stale.iter().map(|f| f.bytes).sum();
                summary.warnings.push(format!(
                    "{} stale work folder{} of earlier interrupted builds ({}) in {}: `voxlod clean {}` lists and removes them",
                    stale.len(),
                    if stale.len() == 1 { "" } else { "s" },
                    format_size(bytes),
                    tmp_parent.display(),
                    tmp_parent.display()
                ));
            }
            Ok(summary)
        }
        Err(_) if interrupted() => Err(interrupted_error(work.path())),
        Err(e) if work.file("leaves.json").exists() && is_output_failure(&e) => {
            // Every chunk is voxelized: keep them, so that once the output side is fixed
            // (space, permissions) the same command only writes the file.
            Err(anyhow::anyhow!(
                "{}; the voxelized chunks are kept in {}: run the same command again to write only the file",
                chain_text(&e),
                work.path().display()
            ))
        }
        Err(e) => {
            // A failed build leaves nothing behind (a killed one keeps its folder to resume).
            let _ = work.remove();
            Err(e)
        }
    }
}

/// A failure of writing the output (I/O on it, too little space, the final rename), as
/// opposed to bad data: worth keeping the work for.
#[derive(Debug)]
struct OutputFailure(String);

impl std::fmt::Display for OutputFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for OutputFailure {}

fn is_output_failure(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.is::<OutputFailure>()
            || c.is::<std::io::Error>()
            || matches!(
                c.downcast_ref::<voxlod_format::FormatError>(),
                Some(voxlod_format::FormatError::Io { .. })
            )
    })
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

#[allow(clippy::too_many_arguments)]
fn run(
    source: &MeshSource,
    input: &Path,
    guard: &OutputGuard,
    s: &BuildSettings,
    threads: usize,
    plan: MemoryPlan,
    work: &WorkDir,
    resumed: bool,
    t0: Instant,
    mut warnings: Vec<String>,
) -> Result<BuildSummary> {
    let output = guard.output();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("creating the thread pool")?;
    let info = source.info().clone();
    let mut stages = Vec::new();
    warnings.extend(
        info.warnings
            .iter()
            .map(|w| format!("{}: {w}", input.display())),
    );
    let stage_done =
        |stages: &mut Vec<StageTime>, stage: &'static str, t: Instant, resumed: bool| {
            stages.push(StageTime {
                stage,
                seconds: t.elapsed().as_secs_f64(),
                peak_rss: system::peak_rss(),
                resumed,
            });
        };

    // Records hold only the attributes the mesh has; an input that is memory-mapped is read
    // again by the tile passes instead of being copied to a spool.
    let layout = RecordLayout {
        normals: info.has_normals,
        colors: info.has_colors,
        texcoords: info.has_texcoords,
    };
    let textures = textures::load(&info, input, s.memory, &mut warnings);
    let spooled = !source.rereadable();
    let rec = layout.bytes() as u64;

    // Temporary disk: the bins (the triangles plus those that straddle chunk borders, at most
    // about 1.5× for fine meshes; faces counted twice in case they are quads), and the spool if
    // one is written, which exists during the scatter pass too. This is an upper bound: the
    // build is refused here only if even one record per face cannot fit, and the exact size of
    // the bins is checked once the count pass knows it (before anything is written to them).
    let input_len = std::fs::metadata(input).map(|m| m.len()).unwrap_or(0);
    let (est_triangles, min_triangles) = if info.faces > 0 {
        (info.faces * 2, info.faces)
    } else {
        (input_len / 12, input_len / 50)
    };
    let temp_disk = est_triangles * rec * if spooled { 5 } else { 3 } / 2;
    let min_disk = min_triangles * rec * if spooled { 2 } else { 1 };
    if let Some(free) = system::free_disk(work.path()) {
        if s.progress {
            eprintln!(
                "temporary disk: up to about {} in {} ({} free; {}-byte triangle records{})",
                format_size(temp_disk),
                work.path().display(),
                format_size(free),
                rec,
                if spooled {
                    ", spool and bins"
                } else {
                    ", bins only: the mapped input is read again"
                }
            );
        }
        if min_disk > free {
            bail!(
                "not enough disk space for the temporary files: at least {} needed in {}, {} free (choose another folder with --tmp)",
                format_size(min_disk),
                work.path().display(),
                format_size(free)
            );
        }
        if temp_disk > free {
            warnings.push(format!(
                "the temporary files may need up to about {} in {}, {} free: the exact size is checked after the count pass",
                format_size(temp_disk),
                work.path().display(),
                format_size(free)
            ));
        }
    }

    // Ingest: parse the input once, for its bounds, spooling the triangles (world
    // coordinates) to disk unless the input can be read again cheaply.
    let t = Instant::now();
    let spool_path = work.file("spool.tri");
    let leaves_path = work.file("leaves.bin");
    let leaves_done: Option<LeavesMarker> = work.marker("leaves.json");
    let bins_marker: Option<BinsMarker> = if leaves_done.is_some() {
        None
    } else {
        work.marker("bins.json")
    };
    // The chunk counts of the tile stage, taken during this pass when the grid is known before
    // it: from the vertex list's bounds, which are the triangles' bounds unless some vertex is
    // unused (checked below, when the triangles' bounds are known). Saves the count pass.
    let mut early_counts: Option<ChunkCounts> = None;
    let marker: SpoolMarker = match work.marker::<SpoolMarker>("spool.json") {
        Some(m)
            if m.spooled == spooled
                && (leaves_done.is_some()
                    || bins_marker.is_some()
                    || !m.spooled
                    || std::fs::metadata(&spool_path)
                        .is_ok_and(|md| md.len() == m.count * rec)) =>
        {
            stage_done(&mut stages, "ingest", t, true);
            m
        }
        _ => {
            let bar = Stage::bytes(s.progress, "ingest", input_len);
            let mut spooler = if spooled {
                Some(Spooler::create(&spool_path, layout)?)
            } else {
                None
            };
            let mut count = 0u64;
            let mut bounds = Bounds::default();
            if !spooled && bins_marker.is_none() && leaves_done.is_none() {
                early_counts = pool
                    .install(|| source.vertex_bounds())
                    .and_then(|vb| Grid::fit(&vb, s.resolution).ok())
                    .and_then(|g| ChunkCounts::new(&g).ok());
            }
            // Inside the pool: a mapped binary PLY is decoded on its threads, and each batch's
            // bounds and chunk keys are taken there too (`prepare`); the callback, on this
            // thread, only adds them up (or spools the batch).
            let keys = early_counts.as_ref().map(|c| c.keys());
            let prepare = |tris: &mut [Triangle]| {
                let mut b = Bounds::default();
                if spooled {
                    return (b, None);
                }
                b.add_triangles(tris);
                (b, keys.map(|k| k.of_world(tris)))
            };
            let stats = pool.install(|| {
                source.stream_prepared(
                    &prepare,
                    &mut |tris, (b, k)| {
                        if interrupted() {
                            return Err(IngestError::Callback("interrupted".into()));
                        }
                        match &mut spooler {
                            Some(sp) => sp.push(tris).map_err(tile_err),
                            None => {
                                count += tris.len() as u64;
                                bounds.merge(&b);
                                if let (Some(c), Some(k)) = (&mut early_counts, k) {
                                    c.add_keyed(tris, &k);
                                }
                                Ok(())
                            }
                        }
                    },
                    &mut |done, total| bar.set(done, total),
                )
            })?;
            if let Some(sp) = spooler {
                let spool = sp.finish()?;
                (count, bounds) = (spool.count, spool.bounds);
            }
            bar.finish();
            let mut w = vec![];
            if stats.degenerate_skipped > 0 {
                w.push(format!(
                    "{}: {} degenerate (zero-area) triangles skipped",
                    input.display(),
                    stats.degenerate_skipped
                ));
            }
            let m = SpoolMarker {
                spooled,
                count,
                min: bounds.min,
                max: bounds.max,
                triangles: stats.triangles,
                degenerate_skipped: stats.degenerate_skipped,
                warnings: w,
            };
            work.set_marker("spool.json", &m)?;
            stage_done(&mut stages, "ingest", t, false);
            m
        }
    };
    warnings.extend(marker.warnings.iter().cloned());
    if marker.count == 0 {
        bail!(
            "{}: the mesh has no (non-degenerate) triangles",
            input.display()
        );
    }
    let bounds = Bounds {
        min: marker.min,
        max: marker.max,
    };
    let grid = Grid::fit(&bounds, s.resolution)
        .with_context(|| format!("{}: fitting the grid", input.display()))?;
    // counts on the vertex list's grid serve if it is the grid of the triangles' bounds
    // (taken only when this run ingests and has no bins yet, so the tile stage will use them)
    let early_counts = early_counts.filter(|c| *c.grid() == grid);
    let counted_during_ingest = early_counts.is_some();

    let mut backend_used = String::from("(voxelized by the interrupted run)");
    let mut gpu_stats: Option<backend::GpuStats> = None;
    let leaves_marker = match leaves_done {
        Some(m) => {
            stage_done(&mut stages, "tile", Instant::now(), true);
            stage_done(&mut stages, "voxelize", Instant::now(), true);
            m
        }
        None => tile_and_voxelize(
            s,
            source,
            layout,
            &grid,
            &plan,
            &pool,
            work,
            &marker,
            bounds,
            early_counts,
            &mut stages,
            &mut backend_used,
            &mut gpu_stats,
            textures,
        )?,
    };
    if leaves_marker.skipped > 0 {
        warnings.push(format!("{} triangle/chunk pairs skipped by the voxelizer (zero area after the move to grid coordinates)", leaves_marker.skipped));
    }
    let chunk_bins = leaves_marker.records as usize;
    let binned_triangles = leaves_marker.binned_triangles;

    // LOD + write: leaves from the log in Morton order; parents by sort-and-compact, written
    // in post-order as soon as their last child is done.
    let t = Instant::now();
    let spec = FileSpec {
        resolution: grid.resolution,
        levels: grid.levels(),
        mode: s.mode as u32,
        origin: grid.origin,
        voxel_size: grid.voxel_size,
    };
    // The file holds every leaf payload: refuse before writing if the output's folder cannot
    // hold even those (the work folder is kept, see `build`).
    let leaf_payloads = std::fs::metadata(&leaves_path)
        .map_or(0, |m| m.len())
        .saturating_sub(leaf_log::RECORD_HEADER_BYTES * leaves_marker.records);
    let out_dir = crate::output::output_dir(output);
    if let Some(free) = system::free_disk(out_dir) {
        if free < leaf_payloads {
            return Err(OutputFailure(format!(
                "not enough disk space for {}: it holds at least {} of leaf chunks, {} free in {}",
                output.display(),
                format_size(leaf_payloads),
                format_size(free),
                out_dir.display()
            ))
            .into());
        }
        if free < leaf_payloads / 3 * 4 {
            warnings.push(format!(
                "{} free in {} may not hold {} (at least {} of leaf chunks, about a third more with the coarser levels)",
                format_size(free),
                out_dir.display(),
                output.display(),
                format_size(leaf_payloads)
            ));
        }
    }
    let writer = Writer::create(guard.staged(), spec)?;
    let mut octree = OctreeWriter::new(writer, grid.levels(), s.zstd_level, &pool);
    let bar = Stage::items(s.progress, "lod+write", chunk_bins as u64);
    // The leaf log is read and decoded on a second thread, one leaf ahead of the merges and
    // parent encodes of this one (two decoded leaves in flight at most).
    type Leaf = ([u32; 3], Vec<Voxel>, Option<EncodedNode>);
    let (tx, rx) = std::sync::mpsc::sync_channel::<Result<Leaf>>(1);
    std::thread::scope(|scope| -> Result<()> {
        scope.spawn(|| {
            let r = leaf_log::read_log(&leaves_path, &mut |h, payload| {
                if interrupted() {
                    return Err(interrupted_error(work.path()));
                }
                let leaf = if h.voxel_count == 0 {
                    (h.coord, Vec::new(), None)
                } else {
                    let mut voxels: Vec<Voxel> = Vec::new();
                    let enc = EncodedNode::from_payload(
                        payload,
                        h.voxel_count,
                        h.payload_crc32,
                        &mut voxels,
                    )
                    .with_context(|| format!("leaf log record {}", h.chunk))?;
                    (h.coord, voxels, Some(enc))
                };
                // a closed channel means the writer failed: stop reading
                tx.send(Ok(leaf))
                    .map_err(|_| anyhow::anyhow!("the octree writer stopped"))
            });
            if let Err(e) = r {
                let _ = tx.send(Err(e));
            }
            drop(tx);
        });
        // owned here, so that an early return closes the channel and stops the reader
        let rx = rx;
        let mut n = 0u64;
        for leaf in rx.iter() {
            let (coord, voxels, enc) = leaf?;
            octree.push_leaf(coord, voxels, enc)?;
            n += 1;
            bar.set(n, chunk_bins as u64);
        }
        Ok(())
    })?;
    bar.finish();
    let mut manifest_settings = serde_json::json!({
        "resolution": s.resolution,
        "mode": s.mode.to_string(),
        "zstd_level": s.zstd_level,
    });
    // the exact methods write the same bytes; the approximate one says so in the file
    if !s.voxelizer.is_exact() {
        manifest_settings["voxelizer"] = s.voxelizer.to_string().into();
    }
    let input_name = input
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let (bytes, levels) = octree.finish(|levels| {
        serde_json::json!({
            "tool": "voxlod",
            "tool_version": env!("CARGO_PKG_VERSION"),
            "input": { "file": input_name, "format": info.format, "triangles": marker.triangles,
                       "degenerate_skipped": marker.degenerate_skipped },
            "settings": manifest_settings,
            "grid": {
                "origin": grid.origin,
                "voxel_size": grid.voxel_size,
                "resolution": grid.resolution,
                "levels": grid.levels(),
            },
            "levels": levels,
        })
    })?;
    guard.commit().map_err(|e| OutputFailure(chain_text(&e)))?;
    stage_done(&mut stages, "lod+write", t, false);

    let total_voxels: u64 = levels.iter().map(|l| l.voxels).sum();
    Ok(BuildSummary {
        input: input.to_path_buf(),
        output: output.to_path_buf(),
        input_format: info.format.clone(),
        triangles: marker.triangles,
        degenerate_skipped: marker.degenerate_skipped,
        resolution: s.resolution,
        mode: s.mode,
        voxelizer: s.voxelizer,
        threads,
        backend: backend_used,
        gpu_split: gpu_stats.map(|g| g.split),
        gpu_cpu_fallback_chunks: gpu_stats.map(|g| g.cpu_fallback_chunks),
        gpu_uncertain_chunks: gpu_stats.map(|g| g.uncertain_chunks),
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
        peak_rss: system::peak_rss(),
        temp_disk,
        tile_source: if spooled { "spool" } else { "input" },
        counted_during_ingest,
        record_bytes: layout.bytes(),
        resumed,
        stages,
        seconds: t0.elapsed().as_secs_f64(),
        warnings,
    })
}

/// The tile and voxelize stages (skipped as a whole when a resumed build has its leaf log).
#[allow(clippy::too_many_arguments)]
fn tile_and_voxelize(
    s: &BuildSettings,
    source: &MeshSource,
    layout: RecordLayout,
    grid: &Grid,
    plan: &MemoryPlan,
    pool: &rayon::ThreadPool,
    work: &WorkDir,
    marker: &SpoolMarker,
    bounds: Bounds,
    early_counts: Option<ChunkCounts>,
    stages: &mut Vec<StageTime>,
    backend_used: &mut String,
    gpu_stats: &mut Option<backend::GpuStats>,
    textures: Option<std::sync::Arc<voxlod_texture::TextureSet>>,
) -> Result<LeavesMarker> {
    let stage_done =
        |stages: &mut Vec<StageTime>, stage: &'static str, t: Instant, resumed: bool| {
            stages.push(StageTime {
                stage,
                seconds: t.elapsed().as_secs_f64(),
                peak_rss: system::peak_rss(),
                resumed,
            });
        };
    let spool_path = work.file("spool.tri");
    let bins_path = work.file("bins.tri");
    let leaves_path = work.file("leaves.bin");
    let bins_marker: Option<BinsMarker> = work.marker("bins.json");
    // Tile: count per chunk, then scatter into pre-sized on-disk bins.
    let t = Instant::now();
    let bins = match bins_marker.and_then(|m| {
        let chunks = m
            .chunks
            .iter()
            .map(|c| ChunkBin {
                coord: [c[0] as u32, c[1] as u32, c[2] as u32],
                morton: voxlod_geom::morton3(c[0] as u32, c[1] as u32, c[2] as u32),
                start: c[3],
                count: c[4],
            })
            .collect();
        Bins::open(&bins_path, chunks, layout).ok()
    }) {
        Some(b) => {
            stage_done(stages, "tile", t, true);
            b
        }
        None => {
            let spool;
            let input;
            let src: &dyn Passes = if marker.spooled {
                spool = Spool {
                    path: spool_path.clone(),
                    count: marker.count,
                    bounds,
                    layout,
                };
                &spool
            } else {
                input = passes::InputPasses {
                    source,
                    count: marker.count,
                };
                &input
            };
            let src = passes::Interruptible(src);
            let counts = match early_counts {
                Some(c) => c,
                None => {
                    let bar = Stage::items(s.progress, "count", marker.count);
                    let c =
                        pool.install(|| voxlod_tile::count(&src, grid, &mut |d, n| bar.set(d, n)))?;
                    bar.finish();
                    c
                }
            };
            if interrupted() {
                return Err(interrupted_error(work.path()));
            }
            // the exact size of the bins, now known
            let rec = layout.bytes() as u64;
            let bins_bytes = counts.total() * rec;
            if let Some(free) = system::free_disk(work.path()) {
                if bins_bytes > free {
                    bail!(
                        "not enough disk space for the chunk bins: {} needed in {} ({} records of {} bytes), {} free (choose another folder with --tmp)",
                        format_size(bins_bytes),
                        work.path().display(),
                        counts.total(),
                        rec,
                        format_size(free)
                    );
                }
            }
            if s.progress {
                eprintln!(
                    "chunk bins: {} ({} triangle records)",
                    format_size(bins_bytes),
                    counts.total()
                );
            }
            let bar = Stage::items(s.progress, "scatter", marker.count);
            let bins = pool.install(|| {
                voxlod_tile::scatter(
                    &src,
                    grid,
                    &counts,
                    &bins_path,
                    layout,
                    plan.scatter_buffer,
                    &mut |d, n| bar.set(d, n),
                )
            })?;
            bar.finish();
            drop(counts);
            let m = BinsMarker {
                chunks: bins
                    .chunks()
                    .iter()
                    .map(|c| {
                        [
                            c.coord[0] as u64,
                            c.coord[1] as u64,
                            c.coord[2] as u64,
                            c.start,
                            c.count,
                        ]
                    })
                    .collect(),
            };
            work.set_marker("bins.json", &m)?;
            stage_done(stages, "tile", t, false);
            bins
        }
    };
    if spool_path.exists() {
        std::fs::remove_file(&spool_path)
            .with_context(|| format!("removing {}", spool_path.display()))?;
    }

    // Voxelize the leaf chunks in parallel batches, appending results in Morton order to the
    // leaf log (resumable at chunk granularity).
    let t = Instant::now();
    let chunks = bins.chunks();
    let leaves_marker = {
        {
            let mut log = LeafLog::open(&leaves_path)?;
            let start = log.records() as usize;
            let stage_resumed = start > 0;
            let (voxelizers, description) = backend::Voxelizers::new(
                s.backend,
                s.mode,
                s.voxelizer,
                plan.voxelizers,
                pool.current_num_threads(),
                &s.gpu_method,
                s.cutoff,
                &bins,
                textures.clone(),
            )?;
            *backend_used = description;
            let bar = Stage::items(s.progress, "voxelize", chunks.len() as u64);
            bar.set(start as u64, chunks.len() as u64);
            // Workers voxelize and encode chunks in order, at most `window` ahead of the log;
            // the log receives them strictly in Morton order (deterministic output).
            let window = plan.voxelizers * 4;
            let voxelize_one = |i: usize| -> Result<(Option<EncodedNode>, u64)> {
                let (voxels, skipped) = voxelizers
                    .run(pool, &bins, i..i + 1)
                    .pop()
                    .context("the voxelizer returned no result")??;
                let enc =
                    if voxels.is_empty() {
                        None
                    } else {
                        Some(encode_node(&voxels, s.zstd_level).with_context(|| {
                            format!("encoding leaf chunk {:?}", chunks[i].coord)
                        })?)
                    };
                Ok((enc, skipped))
            };
            let appended = window::ordered(
                pool,
                plan.voxelizers,
                window,
                start..chunks.len(),
                &voxelize_one,
                &mut |i, r| {
                    if interrupted() {
                        return Err(interrupted_error(work.path()));
                    }
                    let (enc, skipped) = r?;
                    log.append(i as u64, chunks[i].coord, enc.as_ref(), skipped)?;
                    log.flush()?;
                    bar.set(i as u64 + 1, chunks.len() as u64);
                    if s.interrupt_after_chunks.is_some_and(|n| i as u64 + 1 >= n) {
                        request_interrupt();
                    }
                    Ok(())
                },
                &|i, message| {
                    anyhow::anyhow!(
                        "voxelizing leaf chunk {i} {:?} panicked: {message}",
                        chunks[i].coord
                    )
                },
            );
            if let Err(e) = appended {
                log.finish()?;
                return Err(e);
            }
            bar.finish();
            *gpu_stats = voxelizers.gpu_stats();
            drop(voxelizers);
            let records = log.records();
            log.finish()?;
            let mut skipped = 0u64;
            leaf_log::read_log(&leaves_path, &mut |h, _| {
                skipped += h.skipped as u64;
                Ok(())
            })?;
            let m = LeavesMarker {
                records,
                skipped,
                binned_triangles: bins.total(),
            };
            work.set_marker("leaves.json", &m)?;
            stage_done(stages, "voxelize", t, stage_resumed);
            m
        }
    };
    bins.remove()?;
    Ok(leaves_marker)
}
