//! The map phase of a sharded build (`voxlod map --plan P --part I`): the map/reduce of Dean &
//! Ghemawat ("MapReduce", OSDI 2004) over the input's face records, with the shards of
//! Entwine's subset/merge scheme as the reduce keys.
//!
//! A plan with parts cuts the face records of a binary PLY into consecutive ranges
//! (`MeshSource::face_parts`). Map task I decodes its range once (and the vertices it uses),
//! moves the triangles to the plan's grid and bins them by leaf chunk in runs
//! (`voxlod_tile::RunScatter`, the compact blocks of the one-machine build) into
//! `part-IIII.bins` beside the plan; `part-IIII.json`, written atomically after the bins are
//! complete, commits the output: the plan it was made for, the input's fingerprint, its
//! counts and bounds, and every chunk's pieces in the bins file.
//!
//! A shard task reads only the pieces of its own chunks from every part's bins
//! ([`gather`]), part after part, so each chunk holds its triangles in input order: the same
//! bins as a one-machine build, hence the same bytes after the merge.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use voxlod_geom::{demorton3, Bounds, Grid, Triangle};
use voxlod_ingest::{IngestError, MeshSource};
use voxlod_tile::{Bins, ChunkBin, ChunkCounts, RecordLayout, RunScatter};

use super::plan_file::{Fingerprint, LoadedPlan, PlanPart, ShardScope};
use crate::memory::MemoryPlan;
use crate::progress::Bar;
use crate::settings::BuildSettings;

/// The map marker's `format` value.
pub const MAP_FORMAT: &str = "voxlod-map";
/// Version of the map marker.
pub const MAP_VERSION: u32 = 1;
/// The largest map marker read (a chunk list with its pieces).
const MARKER_LIMIT: u64 = 256 << 20;

/// A map task's output, committed: `part-IIII.json` beside its bins `part-IIII.bins`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapMarker {
    /// [`MAP_FORMAT`].
    pub format: String,
    /// [`MAP_VERSION`].
    pub version: u32,
    /// SHA-256 of the plan file it was made for, hex.
    pub plan_sha256: String,
    /// The input's fingerprint when it was read.
    pub fingerprint: Fingerprint,
    /// The part.
    pub part: PlanPart,
    /// Triangles binned (degenerate ones skipped).
    pub triangles: u64,
    /// Zero-area triangles skipped.
    pub degenerate_skipped: u64,
    /// Bounds of its triangles (world coordinates), minimum corner; none without triangles.
    pub min: [f64; 3],
    /// 〃 maximum corner.
    pub max: [f64; 3],
    /// Bytes of the bins file.
    pub bins_bytes: u64,
    /// Per non-empty chunk, in Morton order: `[Morton code, triangles]`.
    pub chunks: Vec<[u64; 2]>,
    /// Per chunk (same order): its pieces `[byte offset, bytes, triangles]` in the bins file.
    pub pieces: Vec<Vec<[u64; 3]>>,
}

/// The name of part `index`'s bins file.
fn bins_name(index: u32) -> String {
    format!("part-{index:04}.bins")
}

/// The name of part `index`'s marker.
fn marker_name(index: u32) -> String {
    format!("part-{index:04}.json")
}

/// What `voxlod map` did.
#[derive(Clone, Debug, Serialize)]
pub struct MapSummary {
    /// The part.
    pub part: u32,
    /// The marker that commits its output.
    pub marker: PathBuf,
    /// Face records of the part.
    pub records: u64,
    /// Bytes of the input's face records it decoded.
    pub face_bytes: u64,
    /// Triangles binned.
    pub triangles: u64,
    /// Non-empty chunks it binned to.
    pub chunks: u64,
    /// Bytes of its bins file.
    pub bins_bytes: u64,
    /// True if a committed output for this plan was found and kept (nothing was done).
    pub already_done: bool,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Peak resident memory of the process (bytes).
    pub peak_rss: u64,
}

/// The layout of the triangle records of a plan's input (the attributes the mesh has).
fn layout_of(source: &MeshSource) -> RecordLayout {
    let info = source.info();
    RecordLayout {
        normals: info.has_normals,
        colors: info.has_colors,
        texcoords: info.has_texcoords,
    }
}

/// Runs map task `index` of the plan at `plan_path`: with `runtime`'s threads, memory and
/// progress. A committed output of the same plan is kept as it is.
pub fn map_part(plan_path: &Path, index: u32, runtime: &BuildSettings) -> Result<MapSummary> {
    let t0 = Instant::now();
    let plan = LoadedPlan::load(plan_path)?;
    let p = &plan.plan;
    if p.parts.is_empty() {
        bail!(
            "{}: this plan has no parts (its input cannot be cut into face records read on their own): its shards read the input themselves, there is nothing to map",
            plan_path.display()
        );
    }
    let Some(part) = p.parts.get(index as usize).copied() else {
        bail!(
            "--part {index}: {} has {} parts, 0 to {}",
            plan_path.display(),
            p.parts.len(),
            p.parts.len() - 1
        );
    };
    let input = &p.input.path;
    let now = Fingerprint::of(input)?;
    if now != p.input.fingerprint {
        bail!(
            "part {index}: {}: the input changed since {} was planned (size, modification time or first/last MiB differ): plan again",
            input.display(),
            plan_path.display()
        );
    }
    let dir = plan.parts_dir();
    let marker_path = dir.join(marker_name(index));
    let bins_path = dir.join(bins_name(index));
    let plan_hex = voxlod_io::hex(&plan.sha256);
    let summary = |m: &MapMarker, already_done: bool| MapSummary {
        part: index,
        marker: marker_path.clone(),
        records: part.records[1] - part.records[0],
        face_bytes: part.bytes[1] - part.bytes[0],
        triangles: m.triangles,
        chunks: m.chunks.len() as u64,
        bins_bytes: m.bins_bytes,
        already_done,
        seconds: t0.elapsed().as_secs_f64(),
        peak_rss: crate::system::peak_rss(),
    };
    if let Ok(m) = read_marker(&marker_path) {
        let bins_ok = std::fs::metadata(&bins_path).is_ok_and(|md| md.len() == m.bins_bytes);
        if m.plan_sha256 == plan_hex && m.part == part && m.fingerprint == now && bins_ok {
            return Ok(summary(&m, true));
        }
    }
    let mut opts = p.settings.read_options();
    opts.allow.clone_from(&runtime.allow_paths);
    let source = MeshSource::open_with(input, &opts)?;
    let face_parts = source.face_parts(p.parts.len() as u64);
    if face_parts.as_ref().and_then(|f| f.get(index as usize)) != Some(&part.face_part()) {
        bail!(
            "part {index}: {}: its face records are not where {} says (edited plan, or another reader version?): plan again",
            input.display(),
            plan_path.display()
        );
    }
    let threads = crate::runner::thread_count(runtime.threads, &mut Vec::new());
    let memory = MemoryPlan::new(runtime.memory, threads)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("creating the thread pool")?;
    let grid: Grid = p.grid.into();
    let layout = layout_of(&source);
    // written under a name of its own (a requeued task may run beside the old one), renamed
    // once complete; the marker, written after, commits it
    let partial = dir.join(format!(
        "{}.{}.partial",
        bins_name(index),
        std::process::id()
    ));
    let bar = Bar::bytes(
        runtime.progress,
        &format!("map {index}"),
        part.bytes[1] - part.bytes[0],
    );
    let r = pool.install(|| bin_part(&source, &part, &grid, layout, &partial, memory, &bar));
    bar.finish();
    let (bins, stats, bounds) = match r {
        Ok(r) => r,
        Err(e) => {
            let _ = std::fs::remove_file(&partial);
            return Err(e.context(format!("part {index} of {}", plan_path.display())));
        }
    };
    std::fs::rename(&partial, &bins_path)
        .with_context(|| format!("renaming {} to {}", partial.display(), bins_path.display()))?;
    voxlod_io::sync_dir(dir);
    let empty = bounds.min.iter().zip(&bounds.max).any(|(a, b)| a > b);
    let m = MapMarker {
        format: MAP_FORMAT.into(),
        version: MAP_VERSION,
        plan_sha256: plan_hex,
        fingerprint: now,
        part,
        triangles: stats.triangles,
        degenerate_skipped: stats.degenerate_skipped,
        min: if empty { [0.0; 3] } else { bounds.min },
        max: if empty { [0.0; 3] } else { bounds.max },
        bins_bytes: bins.bytes(),
        chunks: bins.chunks().iter().map(|c| [c.morton, c.count]).collect(),
        pieces: bins.pieces().to_vec(),
    };
    let text = serde_json::to_vec(&m).context("serializing the map marker")?;
    voxlod_io::write_atomic(&marker_path, &text)
        .with_context(|| format!("{}: cannot write the map marker", marker_path.display()))?;
    Ok(summary(&m, false))
}

/// Decodes `part` of `source` and bins its triangles on `grid` into `path`: the bins, the
/// pass's counts and the triangles' bounds (world coordinates).
fn bin_part(
    source: &MeshSource,
    part: &PlanPart,
    grid: &Grid,
    layout: RecordLayout,
    path: &Path,
    memory: MemoryPlan,
    bar: &Bar,
) -> Result<(Bins, voxlod_ingest::IngestStats, Bounds)> {
    let mut runs = RunScatter::create(grid, path, layout, memory.run_buffer())?;
    let keys = ChunkCounts::new(grid)?.keys();
    // on the decoding threads: bounds and chunk keys, as the one-machine build's ingest pass
    // takes them; the records keep world coordinates (`ChunkVoxelizer::add_world` decides on them)
    let prepare = move |tris: &mut [Triangle]| {
        let mut b = Bounds::default();
        b.add_triangles(tris);
        (b, keys.of_world(tris))
    };
    let mut bounds = Bounds::default();
    let base = part.bytes[0];
    let stats = source.stream_part_prepared(
        &part.face_part(),
        &prepare,
        &mut |tris, (b, k)| {
            if crate::system::interrupted() {
                return Err(IngestError::Callback("interrupted (Ctrl-C)".into()));
            }
            bounds.merge(&b);
            runs.push_keyed(tris, &k)
                .map_err(|e| IngestError::Callback(Box::new(e)))
        },
        &mut |done, _| bar.set(done.saturating_sub(base), part.bytes[1] - base),
    )?;
    Ok((runs.finish()?, stats, bounds))
}

/// Reads a map marker.
fn read_marker(path: &Path) -> Result<MapMarker> {
    let bytes = voxlod_io::read_bounded(path, MARKER_LIMIT)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let m: MapMarker = serde_json::from_slice(&bytes)
        .with_context(|| format!("{}: not a voxlod map marker", path.display()))?;
    if m.format != MAP_FORMAT || m.version != MAP_VERSION {
        bail!(
            "{}: a map marker of format {:?} version {}, this tool reads {MAP_FORMAT:?} version {MAP_VERSION}",
            path.display(),
            m.format,
            m.version
        );
    }
    Ok(m)
}

/// Every map output of the plan at `plan_path` (parts `parts`, SHA-256 `plan_hex`), checked:
/// present, committed for this plan and part, its bins of the size the marker gives. All
/// problems are reported together, each naming its part and file.
pub(crate) fn load_markers(
    plan_path: &Path,
    plan_hex: &str,
    parts: &[PlanPart],
) -> Result<Vec<MapMarker>> {
    let dir = crate::files::output::output_dir(plan_path);
    let mut out = Vec::new();
    let mut problems = Vec::new();
    for part in parts {
        let i = part.index;
        let (mp, bp) = (dir.join(marker_name(i)), dir.join(bins_name(i)));
        let rerun = format!("run `voxlod map {} --part {i}`", plan_path.display());
        if !mp.exists() {
            problems.push(format!(
                "part {i}: {} is missing (the map task did not finish): {rerun}",
                mp.display()
            ));
            continue;
        }
        let why = match read_marker(&mp) {
            Err(e) => Some(crate::chain_text::chain_text(&e)),
            Ok(m) if m.plan_sha256 != plan_hex => Some(format!(
                "{}: made for another plan (or the plan changed since): {rerun}",
                mp.display()
            )),
            Ok(m) if m.chunks.len() != m.pieces.len() => Some(format!(
                "{}: {} chunks but {} piece lists (damaged): {rerun}",
                mp.display(),
                m.chunks.len(),
                m.pieces.len()
            )),
            Ok(m) if m.part != *part => Some(format!(
                "{}: made for other face records than the plan's part {i}: {rerun}",
                mp.display()
            )),
            Ok(m) => match std::fs::metadata(&bp) {
                Err(_) => Some(format!("{} is missing: {rerun}", bp.display())),
                Ok(md) if md.len() != m.bins_bytes => Some(format!(
                    "{} is {} bytes, its marker says {} (changed or damaged): {rerun}",
                    bp.display(),
                    md.len(),
                    m.bins_bytes
                )),
                Ok(_) => {
                    out.push(m);
                    None
                }
            },
        };
        if let Some(w) = why {
            problems.push(format!("part {i}: {w}"));
        }
    }
    if !problems.is_empty() {
        bail!(
            "the map outputs of {} are not complete:\n  {}",
            plan_path.display(),
            problems.join("\n  ")
        );
    }
    Ok(out)
}

/// What the map outputs found together: triangles, degenerate ones skipped, and the
/// triangles' bounds (`None` without triangles).
pub(crate) fn totals(markers: &[MapMarker]) -> (u64, u64, Option<Bounds>) {
    let mut b: Option<Bounds> = None;
    for m in markers.iter().filter(|m| m.triangles > 0) {
        let mb = Bounds {
            min: m.min,
            max: m.max,
        };
        match &mut b {
            Some(b) => b.merge(&mb),
            None => b = Some(mb),
        }
    }
    (
        markers.iter().map(|m| m.triangles).sum(),
        markers.iter().map(|m| m.degenerate_skipped).sum(),
        b,
    )
}

/// The bins of `scope`'s chunks read in place from every map output (`markers`, in part
/// order): per chunk in Morton order, its pieces part after part, so the chunk's triangles are
/// in input order, each where the map task wrote it (nothing is copied; the shard reads only
/// these pieces). A piece outside its bins file (a damaged marker) is refused.
pub(crate) fn gather(
    scope: &ShardScope,
    markers: &[MapMarker],
    layout: RecordLayout,
) -> Result<Bins> {
    let dir = crate::files::output::output_dir(&scope.plan_path);
    let files: Vec<(PathBuf, std::fs::File)> = markers
        .iter()
        .map(|m| {
            let p = dir.join(bins_name(m.part.index));
            let f = voxlod_io::open_regular(&p)
                .with_context(|| format!("{}: cannot open", p.display()))?;
            Ok((p, f))
        })
        .collect::<Result<_>>()?;
    // every (chunk, part, chunk index in that part) of the shard's chunks, by Morton code
    let mut wanted: Vec<(u64, usize, usize)> = Vec::new();
    for (pi, m) in markers.iter().enumerate() {
        for (ci, c) in m.chunks.iter().enumerate() {
            if scope.contains_chunk(demorton3(c[0])) {
                wanted.push((c[0], pi, ci));
            }
        }
    }
    wanted.sort_unstable();
    let mut chunks: Vec<ChunkBin> = Vec::new();
    let mut pieces: Vec<Vec<(usize, [u64; 3])>> = Vec::new();
    for &(morton, pi, ci) in &wanted {
        if chunks.last().is_none_or(|c| c.morton != morton) {
            chunks.push(ChunkBin {
                coord: demorton3(morton),
                morton,
                start: 0,
                count: 0,
            });
            pieces.push(Vec::new());
        }
        let ps = &markers[pi].pieces[ci];
        chunks.last_mut().expect("pushed above").count += ps.iter().map(|p| p[2]).sum::<u64>();
        pieces
            .last_mut()
            .expect("pushed above")
            .extend(ps.iter().map(|&p| (pi, p)));
    }
    Bins::open_in_place(files, chunks, layout, pieces).with_context(|| {
        format!(
            "the map outputs in {} do not match their markers (damaged?): run their `voxlod map {} --part I` again",
            dir.display(),
            scope.plan_path.display()
        )
    })
}
