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
use sha2::{Digest, Sha256};
use voxlod_geom::{demorton3, Bounds, Grid, Triangle};
use voxlod_ingest::{IngestError, MeshSource};
use voxlod_tile::block::BLOCK_HEADER;
use voxlod_tile::{Bins, ChunkBin, ChunkCounts, RecordLayout, RunScatter};
use xxhash_rust::xxh3::{xxh3_64, Xxh3Default};

use super::plan_file::{hex64, Fingerprint, LoadedPlan, PlanPart, ShardScope};
use crate::files::output::{OutputGuard, OutputKind};
use crate::memory::MemoryPlan;
use crate::progress::Bar;
use crate::settings::BuildSettings;

/// The map marker's `format` value.
pub const MAP_FORMAT: &str = "voxlod-map";
/// Version of the map marker. 2: each piece's CRC-32, the XXH3-64 of the face records read
/// (`faces_xxh3`), the pages of the input checked (`pages_checked`) and the marker's own
/// checksum (`marker_sha256`).
pub const MAP_VERSION: u32 = 2;
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
    /// XXH3-64 of the face records the task read (the plan's `faces_xxh3` of the part, which
    /// the task checked them against), 16 hex digits.
    #[serde(with = "super::plan_file::hex_u64")]
    pub faces_xxh3: u64,
    /// Pages before the face records (the plan's `input.pages`) the task read and checked
    /// against the plan's XXH3-64: the header's and those of the vertices its faces use.
    pub pages_checked: u64,
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
    /// Per chunk (same order): its pieces `[byte offset, bytes, triangles, CRC-32 of the
    /// bytes]` in the bins file.
    pub pieces: Vec<Vec<[u64; 4]>>,
    /// Hex SHA-256 of the marker's JSON as written (compact, keys in this order) with this
    /// field empty: any edit of the other fields is found.
    pub marker_sha256: String,
}

impl MapMarker {
    /// The SHA-256 of the marker with `marker_sha256` empty, serialized as it is written.
    fn own_sha256(&self) -> String {
        let mut m = self.clone();
        m.marker_sha256.clear();
        let text = serde_json::to_vec(&m).expect("a marker serializes");
        voxlod_io::hex(&Sha256::digest(&text))
    }
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
    // a committed output is kept when its marker checks and its bins hold the bytes the
    // marker's checksums give (read whole: a damaged one is made again, not kept)
    if let Ok(m) = read_marker(&marker_path) {
        let grid: Grid = p.grid.into();
        if m.fingerprint == now
            && check_marker(&m, &part, &plan_hex, &grid, &bins_path).is_none()
            && bins_match(&bins_path, &m).unwrap_or(false)
        {
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
    // the outputs' locks (a second task of this part is refused while one runs), which also
    // remove what a killed task of this part left: its staged files, and an earlier version's
    // `part-IIII.bins.PID.partial` and `part-IIII.json.tmp`
    let bins_guard = OutputGuard::acquire(&bins_path, &[input], OutputKind::MapOutput, true)?;
    let marker_guard = OutputGuard::acquire(&marker_path, &[input], OutputKind::MapOutput, true)?;
    remove_legacy_leftovers(dir, index);
    let threads = crate::runner::thread_count(runtime.threads, &mut Vec::new());
    let memory = MemoryPlan::new(runtime.memory, threads)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("creating the thread pool")?;
    let grid: Grid = p.grid.into();
    let layout = layout_of(&source);
    let bar = Bar::bytes(
        runtime.progress,
        &format!("map {index}"),
        part.bytes[1] - part.bytes[0],
    );
    // written under the guard's staged name, renamed once complete; the marker, written
    // after, commits it (a failure drops the guard, which removes the staged file)
    let staged = bins_guard.staged();
    let r = pool.install(|| bin_part(&source, &part, &grid, layout, staged, memory, &bar));
    bar.finish();
    let (bins, stats, bounds) =
        r.map_err(|e| e.context(format!("part {index} of {}", plan_path.display())))?;
    // after the pass: the bytes it read, read again and checked against the plan's checksums
    // (a change before or during the pass shows here; one after it did not reach the bins)
    let (faces_xxh3, pages_checked) = check_input(&source, &plan, &part)?;
    bins_guard.commit()?;
    let empty = bounds.min.iter().zip(&bounds.max).any(|(a, b)| a > b);
    let crcs = bins
        .piece_crcs()
        .expect("the map task's bins take their pieces' CRC-32");
    let mut m = MapMarker {
        format: MAP_FORMAT.into(),
        version: MAP_VERSION,
        plan_sha256: plan_hex,
        fingerprint: now,
        part,
        faces_xxh3,
        pages_checked,
        triangles: stats.triangles,
        degenerate_skipped: stats.degenerate_skipped,
        min: if empty { [0.0; 3] } else { bounds.min },
        max: if empty { [0.0; 3] } else { bounds.max },
        bins_bytes: bins.bytes(),
        chunks: bins.chunks().iter().map(|c| [c.morton, c.count]).collect(),
        pieces: bins
            .pieces()
            .iter()
            .zip(crcs)
            .map(|(ps, cs)| {
                ps.iter()
                    .zip(cs)
                    .map(|(p, &c)| [p[0], p[1], p[2], c as u64])
                    .collect()
            })
            .collect(),
        marker_sha256: String::new(),
    };
    m.marker_sha256 = m.own_sha256();
    debug_assert!(check_marker(&m, &part, &m.plan_sha256, &grid, &bins_path).is_none());
    let text = serde_json::to_vec(&m).context("serializing the map marker")?;
    marker_guard
        .write_whole(&text)
        .with_context(|| format!("{}: cannot write the map marker", marker_path.display()))?;
    Ok(summary(&m, false))
}

/// Removes what a map task of part `index` of an earlier voxlod left in `dir` when it was
/// killed (`part-IIII.bins.PID.partial`, `part-IIII.json.tmp`); the caller holds the part's
/// locks.
fn remove_legacy_leftovers(dir: &Path, index: u32) {
    let (bins, marker) = (bins_name(index), marker_name(index));
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let file = e.file_name().to_string_lossy().into_owned();
        if let Some(name) = crate::files::output::legacy_map_leftover(&file) {
            if name == bins || name == marker {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
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
    let mut runs = RunScatter::create_with_piece_crcs(grid, path, layout, memory.run_buffer())?;
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

/// What is wrong with marker `m` for the plan's `part` (plan SHA-256 `plan_hex`, grid
/// `grid`) and its bins at `bins`, if anything: its own checksum, the plan and part it was
/// made for, the face records it read, and its fields against each other and the bins file
/// (counts, pieces tiling the file, chunks inside the grid).
fn check_marker(
    m: &MapMarker,
    part: &PlanPart,
    plan_hex: &str,
    grid: &Grid,
    bins: &Path,
) -> Option<String> {
    if m.marker_sha256 != m.own_sha256() {
        return Some(
            "its checksum does not match its content (edited or damaged since its map task wrote it)"
                .into(),
        );
    }
    if m.plan_sha256 != plan_hex {
        return Some("made for another plan (or the plan changed since)".into());
    }
    if m.part != *part {
        return Some(format!(
            "made for other face records than the plan's part {}",
            part.index
        ));
    }
    if m.faces_xxh3 != part.faces_xxh3 {
        return Some(
            "its map task read other face records than the plan (the input changed)".into(),
        );
    }
    let records = part.records[1] - part.records[0];
    if m.triangles.checked_add(m.degenerate_skipped) != Some(records) {
        return Some(format!(
            "{} triangles and {} degenerate ones from {records} face records of one triangle each",
            m.triangles, m.degenerate_skipped
        ));
    }
    if m.chunks.len() != m.pieces.len() {
        return Some(format!(
            "{} chunks but {} piece lists",
            m.chunks.len(),
            m.pieces.len()
        ));
    }
    let n = grid.chunks_per_axis();
    let inside = m
        .chunks
        .iter()
        .all(|c| demorton3(c[0]).iter().all(|&a| a < n));
    if !inside || !m.chunks.windows(2).all(|w| w[0][0] < w[1][0]) {
        return Some("its chunks are not in increasing Morton order inside the grid".into());
    }
    let mut binned = 0u64;
    let mut all: Vec<[u64; 2]> = Vec::new();
    for (c, ps) in m.chunks.iter().zip(&m.pieces) {
        let sum = ps.iter().try_fold(0u64, |a, p| a.checked_add(p[2]));
        let pieces_ok = !ps.is_empty()
            && ps
                .iter()
                .all(|p| p[2] > 0 && p[1] >= BLOCK_HEADER as u64 && p[3] <= u32::MAX as u64);
        if !pieces_ok || sum != Some(c[1]) {
            return Some(format!(
                "chunk {:?}: its pieces do not add up to its {} triangles",
                demorton3(c[0]),
                c[1]
            ));
        }
        binned = binned.saturating_add(c[1]);
        all.extend(ps.iter().map(|p| [p[0], p[1]]));
    }
    // every triangle lies in a chunk of the grid (which the plan fitted to the vertices)
    if binned < m.triangles || (m.triangles == 0) != m.chunks.is_empty() {
        return Some(format!(
            "{} triangles but {binned} binned in {} chunks",
            m.triangles,
            m.chunks.len()
        ));
    }
    let bounds_ok = m.triangles == 0
        || (0..3).all(|a| m.min[a].is_finite() && m.max[a].is_finite() && m.min[a] <= m.max[a]);
    if !bounds_ok {
        return Some("its bounds are not a box".into());
    }
    // the pieces tile the bins file, as the runs wrote them
    all.sort_unstable();
    let mut at = 0u64;
    for p in &all {
        if p[0] != at {
            return Some(format!(
                "its pieces do not tile its bins file (a gap or overlap at byte {at})"
            ));
        }
        at += p[1];
    }
    if at != m.bins_bytes {
        return Some(format!(
            "its pieces hold {at} bytes, its bins_bytes says {}",
            m.bins_bytes
        ));
    }
    match std::fs::metadata(bins) {
        Err(_) => Some(format!("{} is missing", bins.display())),
        Ok(md) if md.len() != m.bins_bytes => Some(format!(
            "{} is {} bytes, its marker says {} (changed or damaged)",
            bins.display(),
            md.len(),
            m.bins_bytes
        )),
        Ok(_) => None,
    }
}

/// True if every piece of the bins at `path` has the CRC-32 marker `m` gives it (the file is
/// read whole; `m` passed [`check_marker`], so its pieces tile it).
fn bins_match(path: &Path, m: &MapMarker) -> Result<bool> {
    let f = voxlod_io::open_regular(path)
        .with_context(|| format!("{}: cannot open", path.display()))?;
    let mut all: Vec<[u64; 4]> = m.pieces.iter().flatten().copied().collect();
    all.sort_unstable();
    let mut buf = vec![0u8; 1 << 20];
    for p in all {
        let (mut at, end) = (p[0], p[0] + p[1]);
        let mut crc = crc32fast::Hasher::new();
        while at < end {
            let n = ((end - at) as usize).min(buf.len());
            std::os::unix::fs::FileExt::read_exact_at(&f, &mut buf[..n], at)
                .with_context(|| format!("{}: reading", path.display()))?;
            crc.update(&buf[..n]);
            at += n as u64;
        }
        if crc.finalize() as u64 != p[3] {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Reads the bytes part `part` of `plan` read from the input again (`source`, the input
/// mapped): its face records and the pages before them that it used (the header, the pages of
/// its vertices), and checks them against the plan's XXH3-64. Returns the face records' XXH3-64
/// and the pages checked; an input changed since it was planned is an error naming the part,
/// the input, the bytes and the plan.
fn check_input(source: &MeshSource, plan: &LoadedPlan, part: &PlanPart) -> Result<(u64, u64)> {
    let p = &plan.plan;
    let input = &p.input.path;
    let pages = p
        .input
        .pages
        .as_ref()
        .expect("a plan with parts lists its pages (checked when loaded)");
    let changed = |what: String| {
        anyhow::anyhow!(
            "part {}: {}: {what} differ from what {} read when it was planned: the input changed since (keeping its size, modification time and first and last MiB): plan again",
            part.index,
            input.display(),
            plan.path.display()
        )
    };
    let mut h = Xxh3Default::new();
    let Some(used) =
        source.part_footprint(&part.face_part(), pages.page_bytes, &mut |b| h.update(b))
    else {
        bail!(
            "part {}: {}: cannot be read in parts any more: plan again",
            part.index,
            input.display()
        );
    };
    let faces = h.digest();
    if faces != part.faces_xxh3 {
        return Err(changed(format!(
            "its face records (bytes {} to {})",
            part.bytes[0], part.bytes[1]
        )));
    }
    let data = source
        .mapped_bytes()
        .expect("an input cut into parts is mapped");
    let prefix = p.parts[0].bytes[0];
    for (n, &k) in used.iter().enumerate() {
        let a = k * pages.page_bytes;
        let b = (a + pages.page_bytes).min(prefix);
        let ok = pages.xxh3.get(k as usize).is_some_and(|want| {
            (a as usize) < data.len()
                && b as usize <= data.len()
                && *want == hex64(xxh3_64(&data[a as usize..b as usize]))
        });
        if !ok {
            return Err(changed(format!(
                "bytes {a} to {b} (a page of the header or vertex list its faces use)"
            )));
        }
        if n % 64 == 63 {
            source.release_pages();
        }
    }
    source.release_pages();
    Ok((faces, used.len() as u64))
}

/// Every map output of the plan at `plan_path` (parts `parts`, SHA-256 `plan_hex`, grid
/// `grid`), checked ([`check_marker`]): present, committed for this plan and part after
/// reading the plan's input, its fields consistent with each other and its bins file. All
/// problems are reported together, each naming its part and file. The bins' bytes are checked
/// piece by piece where they are read.
pub(crate) fn load_markers(
    plan_path: &Path,
    plan_hex: &str,
    parts: &[PlanPart],
    grid: &Grid,
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
        match read_marker(&mp) {
            Err(e) => problems.push(format!(
                "part {i}: {}: {rerun}",
                crate::chain_text::chain_text(&e)
            )),
            Ok(m) => match check_marker(&m, part, plan_hex, grid, &bp) {
                Some(why) => problems.push(format!("part {i}: {}: {why}: {rerun}", mp.display())),
                None => out.push(m),
            },
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
    let mut pieces: Vec<Vec<(usize, [u64; 3], u32)>> = Vec::new();
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
            .extend(ps.iter().map(|p| (pi, [p[0], p[1], p[2]], p[3] as u32)));
    }
    Bins::open_in_place(files, chunks, layout, pieces).with_context(|| {
        format!(
            "the map outputs in {} do not match their markers (damaged?): run their `voxlod map {} --part I` again",
            dir.display(),
            scope.plan_path.display()
        )
    })
}
