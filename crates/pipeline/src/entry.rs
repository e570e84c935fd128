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
    Fingerprint, LoadedPlan, PlanInput, PlanSummary, ShardPlan, PLAN_FORMAT, PLAN_VERSION,
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

/// Plans a sharded build of `input` (`voxlod plan`): one pass for the bounds and the
/// per-chunk triangle counts (the ingest and count passes of a build, on the same grid), the
/// split level and `shards` Morton ranges (`shard/split.rs`), written to `plan_path` as JSON.
pub fn plan(input: &Path, plan_path: &Path, s: &BuildSettings, shards: u32) -> Result<PlanSummary> {
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
    let mut ctx = runner.context();
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
    let p = ShardPlan {
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
    drop(ctx);
    let text = serde_json::to_vec_pretty(&p).context("serializing the plan")?;
    runner.guard.write_whole(&text)?;
    let t0 = runner.t0;
    runner.finish(&mut Vec::new())?;
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
        source_geometry,
        resumed,
        stages: ctx.times,
        seconds: t0.elapsed().as_secs_f64(),
        warnings: ctx.warnings,
    }
}
