//! The entry points that run the stages over a mesh: [`build`] (the whole octree),
//! [`build_shard`] (one shard of a plan) and [`plan`] (the plan of a sharded build). Each
//! opens a [`Runner`] and ends it with `finish` or `fail`; `merge` is in `shard/merge.rs`.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};

use crate::context::BuildContext;
use crate::context::Scope;
use crate::runner::{Job, Runner};
use crate::settings::BuildSettings;
use crate::shard::plan_file::{
    hex64, Fingerprint, LoadedPlan, PlanInput, PlanPages, PlanSummary, ShardPlan, PLAN_FORMAT,
    PLAN_VERSION,
};
use crate::shard::{content_hash, split};
use crate::stages;
use crate::stages::Built;
use crate::summary::{BuildSummary, SourceSummary};

/// Builds the octree file `output` from the mesh `input`. A build that was killed or
/// interrupted resumes from its work folder when started again with the same arguments.
pub fn build(input: &Path, output: &Path, s: &BuildSettings) -> Result<BuildSummary> {
    run_build(input, output, s, Scope::Whole)
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
    s.allow_paths = runtime.allow_paths.clone();
    s.progress = runtime.progress;
    s.force = runtime.force;
    run_build(
        input,
        &plan.shard_path(index, out_dir),
        &s,
        Scope::Shard(Box::new(scope)),
    )
}

/// A build of `scope` (the whole octree or one shard).
fn run_build(input: &Path, output: &Path, s: &BuildSettings, scope: Scope) -> Result<BuildSummary> {
    let job = Job::Mesh {
        input,
        output,
        scope: &scope,
    };
    let runner = Runner::open(job, s)?;
    let mut ctx = runner.context();
    match stages::run(&mut ctx) {
        Ok(built) => {
            let mut summary = summarize(ctx, built, runner.mesh().resumed, runner.t0);
            runner.finish(&mut summary.warnings)?;
            Ok(summary)
        }
        Err(e) => {
            drop(ctx);
            Err(runner.fail(e))
        }
    }
}

/// Plans a sharded build of `input` (`voxlod plan`), written to `plan_path` as JSON: the grid,
/// the split level and `shards` Morton ranges (`shard/split.rs`). With `parts` > 0 and an
/// input that can be cut into face records read on their own (a binary PLY of triangles), the
/// plan reads only the vertex list (the bounds) and a sample of the faces (the per-chunk
/// weights of the split), and cuts the faces into `parts` parts for map tasks
/// (`shard/map_part.rs`). Otherwise one pass for the bounds and the per-chunk triangle counts
/// (the ingest and count passes of a build, on the same grid), and no parts.
pub fn plan(
    input: &Path,
    plan_path: &Path,
    s: &BuildSettings,
    shards: u32,
    parts: u32,
) -> Result<PlanSummary> {
    crate::settings::check_settings(s)?;
    if shards == 0 {
        bail!("--shards 0: a plan needs at least one shard");
    }
    let job = Job::Mesh {
        input,
        output: plan_path,
        scope: &Scope::Plan,
    };
    let runner = Runner::open(job, s)?;
    let mut parts_warning = None;
    if parts > 0 {
        let ctx = runner.context();
        let cut = ctx
            .source
            .face_parts(parts as u64)
            .zip(ctx.pool.install(|| ctx.source.vertex_bounds()));
        drop(ctx);
        match cut {
            Some((cut, vb)) => return plan_parts(runner, input, plan_path, shards, cut, vb),
            None => {
                parts_warning = Some(format!(
                    "{}: cannot be cut into parts (only a binary PLY whose faces are triangle records of one size, after a vertex list of fixed-size records, can): planned without parts, so every shard reads the whole input",
                    input.display()
                ))
            }
        }
    }
    let mut ctx = runner.context();
    ctx.warnings.extend(parts_warning);
    let resume = crate::resume::Resume::read(ctx.work);
    // the content checksum on a thread of its own beside the passes
    let (counted, xxh3) = content_hash::beside(input, ctx.interrupt, || {
        stages::ingest::run(&mut ctx, &resume).and_then(|mut ing| {
            let counts = stages::tile::counts(&ctx, &mut ing)?;
            Ok((ing, counts))
        })
    });
    let (ingested, counts, xxh3) = match (counted, xxh3) {
        (Ok((i, c)), Ok(Some(h))) => (i, c, h),
        (Err(e), _) | (_, Err(e)) => {
            drop(ctx);
            return Err(runner.fail(e));
        }
        (Ok(_), Ok(None)) => {
            let e = ctx.interrupted();
            drop(ctx);
            return Err(runner.fail(e));
        }
    };
    let leaves: Vec<(u64, u64)> = counts
        .layout()
        .iter()
        .map(|c| (c.morton, c.count))
        .collect();
    let levels = ingested.grid.levels();
    let (split_level, ranges, balance) = split::choose_split(&leaves, levels, shards as usize);
    let mut warnings = ctx.warnings.clone();
    warnings.extend(split::balance_warning(shards, split_level, &balance));
    let fingerprint = runner
        .mesh()
        .fingerprint
        .clone()
        .expect("a plan's runner takes the input's fingerprint");
    let mut p = ShardPlan {
        format: PLAN_FORMAT.into(),
        version: PLAN_VERSION,
        tool_version: env!("CARGO_PKG_VERSION").into(),
        input: PlanInput::of(input, fingerprint, Some(xxh3))?,
        settings: s.clone(),
        grid: ingested.grid.into(),
        ingest: Some(stages::ingest::planned(&ingested.marker)),
        chunks: leaves.iter().map(|&(m, c)| [m, c]).collect(),
        parts: Vec::new(),
        levels,
        manifest: stages::lod_write::manifest_fields(
            &ctx,
            &ingested.grid,
            ingested.marker.triangles,
            ingested.marker.degenerate_skipped,
        ),
        channels: stages::lod_write::channels(&ctx),
        split_level,
        shards: ranges.clone(),
        balance: balance.clone(),
        checksum: String::new(),
    };
    drop(ctx);
    let text = p.sealed_json();
    runner.guard.write_whole(&text)?;
    let t0 = runner.t0;
    runner.finish(&mut Vec::new())?;
    Ok(PlanSummary {
        plan: plan_path.to_path_buf(),
        triangles: ingested.marker.triangles,
        chunks: leaves.len() as u64,
        split_level,
        shards: ranges,
        parts: 0,
        sampled_triangles: None,
        seconds: t0.elapsed().as_secs_f64(),
        balance,
        warnings,
    })
}

/// Windows of face records the plan with parts decodes for its per-chunk weights. A scan's
/// consecutive faces lie close together, so a window weighs one small region: many short
/// windows estimate the subtrees' weights better than a few long ones (gen 1e8 at 2048³, 16
/// shards: the largest shard 1.09× the mean with 4096 windows, 1.14× with 256; 1.07× from the
/// exact counts).
const SAMPLE_WINDOWS: u64 = 4096;
/// The sample is about 1/`SAMPLE_FRACTION` of the face records.
const SAMPLE_FRACTION: u64 = 128;

/// A plan with parts: the grid from the vertex list's bounds `vb`, the per-chunk weights from
/// a sample of [`SAMPLE_WINDOWS`] evenly spaced windows of face records (scaled to the whole),
/// and the parts `cut`.
fn plan_parts(
    runner: Runner,
    input: &Path,
    plan_path: &Path,
    shards: u32,
    cut: Vec<voxlod_ingest::FacePart>,
    vb: voxlod_geom::Bounds,
) -> Result<PlanSummary> {
    use crate::shard::plan_file::PlanPart;
    let ctx = runner.context();
    let s = ctx.settings;
    let grid = voxlod_geom::Grid::fit(&vb, s.resolution).with_context(|| {
        format!(
            "{}: fitting the grid to the vertex list's bounds",
            input.display()
        )
    })?;
    let (first, end) = (cut[0].records[0], cut[cut.len() - 1].records[1]);
    let (off, count) = (cut[0].bytes[0], end - first);
    let size = (cut[cut.len() - 1].bytes[1] - off)
        .checked_div(count)
        .unwrap_or(0);
    let windows = SAMPLE_WINDOWS.min(count);
    let w = (count / (windows.max(1) * SAMPLE_FRACTION)).max(1);
    let mut counts = voxlod_tile::ChunkCounts::new(&grid)?;
    // beside the sample, on a thread of its own: the XXH3-64 of every page before the face
    // records and of every part's face records, which the map tasks check what they read
    // against (an input changed between two map tasks, whatever it keeps)
    let page = PlanPages::page_bytes_for(off);
    let mut ends: Vec<u64> = (1..=off.div_ceil(page))
        .map(|k| (k * page).min(off))
        .collect();
    let npages = ends.len();
    ends.extend(cut.iter().map(|c| c.bytes[1]));
    let (sample, hashes) = std::thread::scope(|sc| {
        let hashes = sc.spawn(|| content_hash::xxh3_of_segments(input, &ends, ctx.interrupt));
        let r = sample_windows(&ctx, &mut counts, (first, end, off, size), windows, w);
        let h = hashes
            .join()
            .unwrap_or_else(|p| std::panic::resume_unwind(p));
        (r, h)
    });
    let sampled = sample?;
    let Some(hashes) = hashes? else {
        return Err(ctx.interrupted().into());
    };
    // each sampled chunk's count scaled to all records (at least 1); unsampled chunks weigh 0
    let leaves: Vec<(u64, u64)> = counts
        .layout()
        .iter()
        .map(|c| (c.morton, (c.count * count).div_ceil(sampled.max(1)).max(1)))
        .collect();
    let levels = grid.levels();
    let (split_level, ranges, balance) = split::choose_split(&leaves, levels, shards as usize);
    let mut warnings = ctx.warnings.clone();
    warnings.extend(split::balance_warning(shards, split_level, &balance));
    let fingerprint = runner
        .mesh()
        .fingerprint
        .clone()
        .expect("a plan's runner takes the input's fingerprint");
    let parts: Vec<PlanPart> = cut
        .iter()
        .zip(&hashes[npages..])
        .enumerate()
        .map(|(i, (c, &h))| PlanPart {
            index: i as u32,
            records: c.records,
            bytes: c.bytes,
            faces_xxh3: h,
        })
        .collect();
    let mut plan_input = PlanInput::of(input, fingerprint, None)?;
    plan_input.pages = Some(PlanPages {
        page_bytes: page,
        xxh3: hashes[..npages].iter().map(|&h| hex64(h)).collect(),
    });
    let mut p = ShardPlan {
        format: PLAN_FORMAT.into(),
        version: PLAN_VERSION,
        tool_version: env!("CARGO_PKG_VERSION").into(),
        input: plan_input,
        settings: s.clone(),
        grid: grid.into(),
        ingest: None,
        chunks: leaves.iter().map(|&(m, c)| [m, c]).collect(),
        parts,
        levels,
        // the counts are the map outputs' (`merge` sets them)
        manifest: stages::lod_write::manifest_fields(&ctx, &grid, 0, 0),
        channels: stages::lod_write::channels(&ctx),
        split_level,
        shards: ranges.clone(),
        balance: balance.clone(),
        checksum: String::new(),
    };
    drop(ctx);
    let text = p.sealed_json();
    runner.guard.write_whole(&text)?;
    let t0 = runner.t0;
    let nparts = p.parts.len() as u32;
    runner.finish(&mut Vec::new())?;
    Ok(PlanSummary {
        plan: plan_path.to_path_buf(),
        triangles: count,
        chunks: leaves.len() as u64,
        split_level,
        shards: ranges,
        parts: nparts,
        sampled_triangles: Some(sampled),
        seconds: t0.elapsed().as_secs_f64(),
        balance,
        warnings,
    })
}

/// The plan's sample: `windows` evenly spaced windows of `w` face records over the records
/// `first..end` (record `r` at byte `off + (r − first) · size`), their triangles counted per
/// chunk into `counts`; returns the face records decoded.
fn sample_windows(
    ctx: &BuildContext,
    counts: &mut voxlod_tile::ChunkCounts,
    (first, end, off, size): (u64, u64, u64, u64),
    windows: u64,
    w: u64,
) -> Result<u64> {
    let count = end - first;
    let mut sampled = 0u64;
    let bar = crate::progress::Bar::items(ctx.progress, "sample", windows);
    // the windows are scattered: without readahead each reads its own pages only
    ctx.source.advise_random(true);
    for k in 0..windows {
        let a = first + count * k / windows;
        let b = (a + w).min(end);
        let part = voxlod_ingest::FacePart {
            records: [a, b],
            bytes: [off + a * size, off + b * size],
        };
        let st = ctx.pool.install(|| {
            ctx.source.stream_part_prepared(
                &part,
                &|_| (),
                &mut |t, ()| {
                    counts.add_triangles(t);
                    Ok(())
                },
                &mut |_, _| {},
            )
        })?;
        sampled += st.polygons;
        // the windows' vertices lie all over the vertex list: without this, the mapped pages
        // they touch add up to most of it in resident memory (2.1 GB at gen 1e9)
        if k % 64 == 63 {
            ctx.source.release_pages();
        }
        bar.set(k + 1, windows);
    }
    ctx.source.advise_random(false);
    bar.finish();
    Ok(sampled)
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
        voxel_size: ingested.grid.voxel_size,
        origin: ingested.grid.origin,
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
        memory_plan: ctx.memory,
        texture_cache: voxelized.texture_cache,
        peak_rss: crate::system::peak_rss(),
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
        bin_index_bytes: voxelized.marker.bin_index_bytes,
        source_geometry,
        resumed,
        stages: ctx.times,
        seconds: t0.elapsed().as_secs_f64(),
        warnings: ctx.warnings,
    }
}
