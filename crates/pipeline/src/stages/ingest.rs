//! The ingest stage: one pass over the input for the triangles' bounds (which fix the grid),
//! spooling the triangles (world coordinates) to `spool.tri` unless the input is memory-mapped
//! and can be parsed again by the tile passes. When the grid is known before the pass (from the
//! vertex list's bounds) the tile stage's chunk counts are taken during it too.
//!
//! Artifact and resume marker: [`IngestMarker`] (`spool.json`).

use std::time::Instant;

use anyhow::Context;
use voxlod_geom::{demorton3, Bounds, Grid, Triangle};
use voxlod_ingest::IngestError;
use voxlod_tile::{Bins, ChunkCounts, RecordLayout, RunScatter, Spooler, RUN_SCATTER_MAX_CHUNKS};

use crate::context::{BuildContext, Scope, Stage};
use crate::error::StageError;
use crate::files::markers::IngestMarker;
use crate::files::work::WorkFile;
use crate::progress::Bar;
use crate::resume::Resume;
use crate::shard::plan_file::{PlanIngest, ShardScope};
use crate::size::format_size;

/// The ingest stage's artifact: its marker and what follows from it.
pub(crate) struct Ingested {
    pub marker: IngestMarker,
    /// Which attributes the triangle records hold (those the mesh has).
    pub layout: RecordLayout,
    /// The grid fitted to the triangles' bounds.
    pub grid: Grid,
    /// The tile stage's chunk counts, if this pass took them on `grid` (then the tile stage
    /// has no count pass; it takes them).
    pub early_counts: Option<ChunkCounts>,
    /// The bins, if this pass wrote them on `grid` ([`RunScatter`]: the tile stage has no
    /// pass of its own; it takes them).
    pub early_bins: Option<Bins>,
    /// True if the ingest pass took the chunk counts (the tile stage has no count pass).
    pub counted_during_ingest: bool,
    /// True if the ingest pass wrote the bins (`early_bins`; the tile stage reads nothing).
    pub binned_during_ingest: bool,
    /// Largest temporary disk use planned (bytes): spool (if one is written) plus bins.
    pub temp_disk: u64,
    /// Bytes this process wrote to the spool and bins files (a stage taken from the work
    /// folder adds nothing); the tile stage adds the bins it writes.
    pub temp_written: u64,
}

impl Ingested {
    /// The triangles' bounds.
    pub(crate) fn bounds(&self) -> Bounds {
        Bounds {
            min: self.marker.min,
            max: self.marker.max,
        }
    }
}

/// Runs the ingest stage, or takes its marker from the work folder.
pub(crate) fn run(ctx: &mut BuildContext, resume: &Resume) -> Result<Ingested, StageError> {
    let info = ctx.source.info();
    let input = ctx.input.display().to_string();
    ctx.warnings
        .extend(info.warnings.iter().map(|w| format!("{input}: {w}")));
    // Records hold only the attributes the mesh has; an input that is memory-mapped is read
    // again by the tile passes instead of being copied to a spool.
    let layout = RecordLayout {
        normals: info.has_normals,
        colors: info.has_colors,
        texcoords: info.has_texcoords,
    };
    // a shard reads the input once, in the tile stage's scatter pass, whatever its format
    let spooled = !ctx.source.rereadable() && ctx.scope.shard().is_none();
    let t = Instant::now();
    if let Some(scope) = ctx.scope.shard() {
        if !scope.parts.is_empty() {
            let ingested = from_parts(ctx, scope, layout)?;
            ctx.stage_done(Stage::Ingest, t, false);
            return Ok(ingested);
        }
        // the bins of its own chunks, exactly; the tile stage checks them against the free space
        let bins: u64 = scope.chunks.iter().map(|c| c[1]).sum();
        let ingested = from_plan(ctx, scope, layout, bins * layout.bytes() as u64)?;
        ctx.stage_done(Stage::Ingest, t, false);
        return Ok(ingested);
    }
    // the bins' entry: a face index (4 or 8 bytes) where the faces can be found by index again,
    // else a record (blocks are at most the records)
    let indexed = index_bins(ctx);
    let entry = bin_entry_bytes(ctx, layout, indexed);
    let temp_disk = check_temp_disk(ctx, layout, entry, spooled)?;
    // a later stage's marker: the spool is not needed again, nor are counts
    let later_done = resume.past_ingest();
    let resumed = resume.ingest.clone().filter(|m| {
        m.spooled == spooled
            && (later_done
                || !m.spooled
                || std::fs::metadata(ctx.work.file(WorkFile::Spool))
                    .is_ok_and(|md| md.len() == m.count * layout.bytes() as u64))
    });
    let mut temp_written = 0;
    let (marker, early) = match resumed {
        Some(m) => {
            ctx.stage_done(Stage::Ingest, t, true);
            (m, Early::None)
        }
        None => {
            // bins of face indices where the faces can be found by index again (a mapped PLY
            // of fixed-size triangle records); else, or if a record turns out not to be a
            // triangle record after all, bins of blocks
            let r = read_input(ctx, layout, spooled, !later_done, temp_disk, indexed);
            let (m, early) = match r {
                Err(StageError::Ingest(IngestError::NotFixedRecords { .. })) if indexed => {
                    // blocks need the records' bound of the disk, not the indices'
                    let blocks = temp_disk / entry * layout.bytes() as u64;
                    read_input(ctx, layout, spooled, !later_done, blocks, false)?
                }
                r => r?,
            };
            if m.spooled {
                temp_written += m.count * layout.bytes() as u64;
            }
            if let Early::Bins(b, _) = &early {
                temp_written += b.bytes();
            }
            ctx.work.set_marker(&m)?;
            ctx.stage_done(Stage::Ingest, t, false);
            (m, early)
        }
    };
    ctx.warnings.extend(marker.warnings.iter().cloned());
    if marker.count == 0 {
        return Err(StageError::NoTriangles(ctx.input.to_path_buf()));
    }
    let bounds = Bounds {
        min: marker.min,
        max: marker.max,
    };
    let grid = Grid::fit(&bounds, ctx.settings.resolution)
        .with_context(|| format!("{input}: fitting the grid"))?;
    // counts or bins on the vertex list's grid serve if it is the grid of the triangles' bounds
    let (early_counts, early_bins) = match early {
        Early::Counts(c) if *c.grid() == grid => (Some(c), None),
        Early::Bins(b, g) if g == grid => (None, Some(b)),
        Early::Bins(b, _) => {
            b.remove()?;
            (None, None)
        }
        _ => (None, None),
    };
    Ok(Ingested {
        marker,
        layout,
        grid,
        counted_during_ingest: early_counts.is_some() || early_bins.is_some(),
        binned_during_ingest: early_bins.is_some(),
        early_counts,
        early_bins,
        temp_disk,
        temp_written,
    })
}

/// What the plan's pass found (bounds, counts, warnings), for the plan file.
pub(crate) fn planned(m: &IngestMarker) -> PlanIngest {
    debug_assert_eq!(m.count, m.triangles, "the pass's count is what it yielded");
    PlanIngest {
        triangles: m.count,
        degenerate_skipped: m.degenerate_skipped,
        min: m.min,
        max: m.max,
        warnings: m.warnings.clone(),
    }
}

/// A sharded build's ingest stage: what the plan's pass found, without reading the input. The
/// grid is fitted to the plan's bounds, and the chunk counts are the plan's counts of the
/// shard's chunks (the tile stage drops the others), so the tile stage's scatter pass is the
/// shard's only pass over the input.
fn from_plan(
    ctx: &mut BuildContext,
    scope: &ShardScope,
    layout: RecordLayout,
    temp_disk: u64,
) -> Result<Ingested, StageError> {
    let p = scope
        .ingest
        .as_ref()
        .expect("a plan without parts has the ingest pass's findings");
    let marker = IngestMarker {
        spooled: false,
        count: p.triangles,
        min: p.min,
        max: p.max,
        triangles: p.triangles,
        degenerate_skipped: p.degenerate_skipped,
        warnings: p.warnings.clone(),
    };
    ctx.warnings.extend(marker.warnings.iter().cloned());
    let plan = scope.plan_path.display();
    let bounds = Bounds {
        min: p.min,
        max: p.max,
    };
    let grid = Grid::fit(&bounds, ctx.settings.resolution)
        .with_context(|| format!("{plan}: fitting the grid to the plan's bounds"))?;
    let mut counts = ChunkCounts::new(&grid)?;
    let n = grid.chunks_per_axis();
    for &[m, c] in &scope.chunks {
        let coord = demorton3(m);
        if coord.iter().any(|&a| a >= n) {
            return Err(anyhow::anyhow!("{plan}: chunk {m} lies outside the grid").into());
        }
        counts.set(coord, c);
    }
    Ok(Ingested {
        marker,
        layout,
        grid,
        early_counts: Some(counts),
        early_bins: None,
        counted_during_ingest: true,
        binned_during_ingest: false,
        temp_disk,
        temp_written: 0,
    })
}

/// A sharded build's ingest stage when the plan has parts: the map outputs' counts and bounds,
/// and the bins of the shard's chunks: the map outputs' pieces, read in place (the tile stage takes them); the
/// input is not read. Refuses map outputs that are missing or not this plan's, and a grid
/// (fitted by the plan to the vertex list's bounds) that is not the triangles' grid.
fn from_parts(
    ctx: &mut BuildContext,
    scope: &ShardScope,
    layout: RecordLayout,
) -> Result<Ingested, StageError> {
    use crate::shard::map_part;
    let markers = map_part::load_markers(
        &scope.plan_path,
        &scope.plan_sha256_hex,
        &scope.parts,
        &scope.grid,
    )?;
    let (triangles, degenerate, tb) = map_part::totals(&markers);
    let plan = scope.plan_path.display();
    let Some(tb) = tb else {
        return Err(StageError::NoTriangles(ctx.input.to_path_buf()));
    };
    // the plan fitted the grid to the vertex list's bounds: the build's grid is the triangles'
    let grid = Grid::fit(&tb, ctx.settings.resolution)
        .with_context(|| format!("{plan}: fitting the grid to the map outputs' bounds"))?;
    if grid != scope.grid {
        // the plan's grid holds every vertex: bounds reaching outside it are no vertex's, so
        // only a marker's own numbers can have put them there
        let g = &scope.grid;
        let edge = g.voxel_size * g.resolution as f64;
        let outside = (0..3).any(|a| tb.min[a] < g.origin[a] || tb.max[a] > g.origin[a] + edge);
        return Err(if outside {
            anyhow::anyhow!(
                "{plan}: the map outputs' bounds (the min and max of their markers, part-IIII.json) reach outside the plan's grid, which holds every vertex of {}: a marker was edited or damaged; run the map tasks again",
                ctx.input.display()
            )
        } else {
            anyhow::anyhow!(
                "{}: the map outputs' bounds (the min and max of their markers, part-IIII.json) give another grid than the one {plan} fitted to the vertex list: either some vertices are used by no triangle and lie outside the triangles' bounds (plan it without --parts), or a marker was edited or damaged (run the map tasks again)",
                ctx.input.display()
            )
        }
        .into());
    }
    let warnings: Vec<String> = (degenerate > 0)
        .then(|| {
            format!(
                "{}: {degenerate} degenerate (zero-area) triangles skipped",
                ctx.input.display()
            )
        })
        .into_iter()
        .collect();
    ctx.warnings.extend(warnings.iter().cloned());
    let marker = IngestMarker {
        spooled: false,
        count: triangles,
        min: tb.min,
        max: tb.max,
        triangles,
        degenerate_skipped: degenerate,
        warnings,
    };
    // the shard's bins are the map outputs' pieces of its chunks, read in place (no copy, no
    // temporary disk); nothing to resume from but the voxelize stage's leaves
    let bins = map_part::gather(scope, &markers, layout)?;
    Ok(Ingested {
        marker,
        layout,
        grid,
        early_counts: None,
        binned_during_ingest: true,
        counted_during_ingest: true,
        early_bins: Some(bins),
        temp_disk: 0,
        temp_written: 0,
    })
}

/// Temporary disk: the bins (the triangles plus those that straddle chunk borders, at most
/// about 1.5× for fine meshes; faces counted twice in case they are quads), and the spool if
/// one is written, which exists during the scatter pass too. This is an upper bound: the build
/// is refused here only if even one record per face cannot fit, and the largest size of the
/// bins is checked once the count pass knows it (before anything is written to them). Returns the
/// upper bound.
/// The bytes of one (triangle, chunk) entry of the bins at most: a face index with `indexed`
/// (u32, or u64 past 2³² faces), else a record of `layout`.
fn bin_entry_bytes(ctx: &BuildContext, layout: RecordLayout, indexed: bool) -> u64 {
    match ctx.source.fixed_face_count().filter(|_| indexed) {
        Some(faces) if faces <= u32::MAX as u64 => 4,
        Some(_) => 8,
        None => layout.bytes() as u64,
    }
}

/// The stage's upper bound of the temporary disk (a spool of `layout` records if `spooled`, bins
/// of `entry`-byte entries), refused when even the least it needs is not free.
fn check_temp_disk(
    ctx: &mut BuildContext,
    layout: RecordLayout,
    entry: u64,
    spooled: bool,
) -> Result<u64, StageError> {
    // `voxlod plan` writes no bins, only the spool if there is one
    let bins = ctx.scope.writes_bins();
    if !bins && !spooled {
        return Ok(0);
    }
    let rec = layout.bytes() as u64;
    let faces = ctx.source.info().faces;
    let input_len = std::fs::metadata(ctx.input).map(|m| m.len()).unwrap_or(0);
    let (est_triangles, min_triangles) = if faces > 0 {
        (faces * 2, faces)
    } else {
        (input_len / 12, input_len / 50)
    };
    // the spool: two estimates' records; the bins: 1.5 entries per estimate (straddles)
    let spool = spooled as u64 * rec;
    let entry = bins as u64 * entry;
    // the textures' tile file, when their pyramids exceed their share of the plan: its size is
    // known from the images' headers and it is written whole, so it counts in the least too
    let info = ctx.source.info();
    let tiles = if bins && info.has_texcoords {
        voxlod_texture::TextureSet::tile_file_bytes(&info.materials, ctx.memory.texture_share())
    } else {
        0
    };
    let temp_disk = est_triangles * (2 * spool + 3 * entry) / 2 + tiles;
    let min_disk = min_triangles * (spool + entry) + tiles;
    let work = ctx.work.path();
    let Some(free) = crate::system::free_disk(work) else {
        return Ok(temp_disk);
    };
    if ctx.progress {
        let textures = if tiles > 0 {
            format!(", and texture tiles {}", format_size(tiles))
        } else {
            String::new()
        };
        eprintln!(
            "temporary disk: up to about {} in {} ({} free; {}-byte {}{}{textures})",
            format_size(temp_disk),
            work.display(),
            format_size(free),
            if spooled || entry == 0 { rec } else { entry },
            if !spooled && entry > 0 && entry < rec {
                "face indices"
            } else {
                "triangle records"
            },
            match (spooled, bins) {
                (true, true) => ", spool and bins",
                (true, false) => ", the spool only: a plan writes no bins",
                _ => ", bins only: the mapped input is read again",
            }
        );
    }
    if min_disk > free {
        return Err(StageError::TempDisk(format!(
            "not enough disk space for the temporary files: at least {} needed in {}{}, {} free (choose another folder with --tmp)",
            format_size(min_disk),
            work.display(),
            if tiles > 0 {
                format!(" (texture tiles {} of it)", format_size(tiles))
            } else {
                String::new()
            },
            format_size(free)
        )));
    }
    if temp_disk > free {
        ctx.warnings.push(format!(
            "the temporary files may need up to about {} in {}, {} free: the exact size is checked after the count pass",
            format_size(temp_disk),
            work.display(),
            format_size(free)
        ));
    }
    Ok(temp_disk)
}

/// What the ingest pass took for the tile stage on the vertex list's grid (the grid of the
/// triangles unless a vertex is unused, checked once their bounds are known), if anything.
pub(crate) enum Early {
    None,
    /// The per-chunk counts: the tile stage has only its scatter pass.
    Counts(ChunkCounts),
    /// The bins themselves, written in runs, on this grid: the tile stage has no pass.
    Bins(Bins, Grid),
}

/// True if the ingest pass writes bins of face indices ([`RunScatter::create_indexed`]) rather
/// than of blocks, if it bins at all: the input's faces are fixed-size triangle records of a
/// mapped PLY ([`voxlod_ingest::MeshSource::fixed_face_count`]), which the voxelize stage
/// reads again by index. `VOXLOD_BINS=blocks` in the environment turns them off (an internal
/// switch, for tests that compare both kinds and for measurements).
pub(crate) fn index_bins(ctx: &BuildContext) -> bool {
    ctx.source.fixed_face_count().is_some()
        && std::env::var_os("VOXLOD_BINS").is_none_or(|v| v != "blocks")
}

/// The pass over the input: bounds and count of the triangles, spooled or (for a mapped input,
/// if `may_count`) binned in runs on the vertex list's grid (or, where that cannot be done,
/// counted per chunk on it); with `indexed`, the bins hold each triangle's face record
/// ([`index_bins`]). `temp_disk` is the stage's upper bound of the temporary disk.
fn read_input(
    ctx: &BuildContext,
    layout: RecordLayout,
    spooled: bool,
    may_count: bool,
    temp_disk: u64,
    indexed: bool,
) -> Result<(IngestMarker, Early), StageError> {
    let input_len = std::fs::metadata(ctx.input).map(|m| m.len()).unwrap_or(0);
    let bar = Bar::bytes(ctx.progress, Stage::Ingest.name(), input_len);
    let mut spooler = spooled
        .then(|| Spooler::create(&ctx.work.file(WorkFile::Spool), layout))
        .transpose()?;
    let (mut count, mut bounds) = (0u64, Bounds::default());
    let vgrid = (!spooled && may_count).then(|| vertex_grid(ctx)).flatten();
    let mut runs = vgrid
        .filter(|g| bins_during_ingest(ctx, g, temp_disk))
        .map(|g| {
            let path = ctx.work.file(WorkFile::Bins);
            let buffer = ctx.memory.run_buffer();
            match ctx.source.fixed_face_count().filter(|_| indexed) {
                // u32 face records where they fit, else u64
                Some(faces) => {
                    let width = if faces <= u32::MAX as u64 { 4 } else { 8 };
                    RunScatter::create_indexed(&g, &path, layout, width, buffer)
                }
                None => RunScatter::create(&g, &path, layout, buffer),
            }
        })
        .transpose()?;
    // the face records only where the bins hold them
    let indexed = indexed && runs.is_some();
    let mut early_counts = vgrid.and_then(|g| ChunkCounts::new(&g).ok());
    let keys = early_counts.as_ref().map(|c| c.keys());
    // binning in runs: the chunk keys are taken where the triangles are decoded, as in the
    // tile stage's scatter pass (the records keep world coordinates)
    if runs.is_some() {
        early_counts = None;
    }
    // Inside the pool: a mapped binary PLY is decoded on its threads, and each batch's bounds
    // and chunk keys are taken there too (`prepare`); the callback, on this thread, only adds
    // them up and bins (or spools the batch).
    let prepare = |tris: &mut [Triangle]| {
        let mut b = Bounds::default();
        if spooled {
            return (b, None);
        }
        b.add_triangles(tris);
        // the bins keep world coordinates (`ChunkVoxelizer::add_world` decides on them)
        (b, keys.map(|k| k.of_world(tris)))
    };
    let mut take = |tris: &[Triangle], faces: &[u64], (b, k): (Bounds, Option<Vec<u32>>)| {
        if let Err(e) = ctx.check_interrupt() {
            return Err(IngestError::Callback(Box::new(e)));
        }
        if let Some(sp) = &mut spooler {
            return sp
                .push(tris)
                .map_err(|e| IngestError::Callback(Box::new(e)));
        }
        count += tris.len() as u64;
        bounds.merge(&b);
        match (&mut runs, &mut early_counts, k) {
            (Some(rs), _, Some(k)) if indexed => rs
                .push_indexed(tris, &k, faces)
                .map_err(|e| IngestError::Callback(Box::new(e)))?,
            (Some(rs), _, Some(k)) => rs
                .push_keyed(tris, &k)
                .map_err(|e| IngestError::Callback(Box::new(e)))?,
            (None, Some(c), Some(k)) => c.add_keyed(tris, &k),
            _ => {}
        }
        Ok(())
    };
    let stats = ctx
        .pool
        .install(|| {
            let progress = &mut |done, total| bar.set(done, total);
            if indexed {
                ctx.source
                    .stream_indexed_prepared(&prepare, &mut take, progress)
            } else {
                ctx.source
                    .stream_prepared(&prepare, &mut |tris, p| take(tris, &[], p), progress)
            }
        })
        .map_err(StageError::from)?;
    if let Some(sp) = spooler {
        let spool = sp.finish()?;
        (count, bounds) = (spool.count, spool.bounds);
    }
    let early = match (runs, early_counts) {
        (Some(rs), _) => {
            let grid = *rs.grid();
            Early::Bins(rs.finish()?, grid)
        }
        (None, Some(c)) => Early::Counts(c),
        _ => Early::None,
    };
    bar.finish();
    let warnings = (stats.degenerate_skipped > 0)
        .then(|| {
            let n = stats.degenerate_skipped;
            format!(
                "{}: {n} degenerate (zero-area) triangles skipped",
                ctx.input.display()
            )
        })
        .into_iter()
        .collect();
    let marker = IngestMarker {
        spooled,
        count,
        min: bounds.min,
        max: bounds.max,
        triangles: stats.triangles,
        degenerate_skipped: stats.degenerate_skipped,
        warnings,
    };
    Ok((marker, early))
}

/// The grid of the vertex list's bounds, for the tile stage's work to be done during the
/// ingest pass: the grid is the triangles' grid unless some vertex is unused (checked once the
/// triangles' bounds are known). None when the reader cannot give the vertex bounds before the
/// pass.
fn vertex_grid(ctx: &BuildContext) -> Option<Grid> {
    ctx.pool
        .install(|| ctx.source.vertex_bounds())
        .and_then(|vb| Grid::fit(&vb, ctx.settings.resolution).ok())
        .filter(|g| ChunkCounts::new(g).is_ok())
}

/// True if the ingest pass may write the bins itself ([`RunScatter`]) on `grid`: a build of an
/// octree (a plan writes no bins), a grid of at most [`RUN_SCATTER_MAX_CHUNKS`] chunks, and
/// free disk for the stage's upper bound of the temporary files (`temp_disk`), since the
/// exact size of the bins is not known before they are written; otherwise the tile stage
/// checks the exact size before its scatter pass.
fn bins_during_ingest(ctx: &BuildContext, grid: &Grid, temp_disk: u64) -> bool {
    matches!(ctx.scope, Scope::Whole)
        && (grid.chunks_per_axis() as u64).pow(3) <= RUN_SCATTER_MAX_CHUNKS
        && crate::system::free_disk(ctx.work.path()).is_some_and(|free| free >= temp_disk)
}
