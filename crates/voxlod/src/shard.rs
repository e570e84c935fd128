//! Sharded builds on a cluster: `voxlod plan`, `voxlod map P --part I`, `voxlod build --plan P
//! --shard I` and `voxlod merge` (the pipeline's `plan`, `map_part`, `build_shard` and `merge`).

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use voxlod_pipeline::{format_size, BuildSettings};

pub(crate) const EXAMPLES_PLAN: &str = "\
Examples:
  voxlod plan scan.ply -o scan.plan.json --shards 16 -r 8192        # then one build per shard
  voxlod plan scan.ply -o scan.plan.json --shards 16 --parts 16 -r 8192   # map tasks, then shards
  voxlod plan city.obj -o city.plan.json --shards 64 --config configs/scan.toml --json
  voxlod build --plan scan.plan.json --shard 0                      # writes shard-0000.vlshard
  voxlod merge scan.plan.json -o scan.voxlod                        # the same bytes as `voxlod build scan.ply -r 8192`
Every build option that changes the output goes to `plan`; the shards take them from the plan.";

pub(crate) const EXAMPLES_MAP: &str = "\
Examples:
  voxlod map scan.plan.json --part 3 -j 2      # writes part-0003.bins and part-0003.json beside the plan
A part whose output for this plan is already committed is left as it is.";

pub(crate) const EXAMPLES_MERGE: &str = "\
Examples:
  voxlod merge scan.plan.json -o scan.voxlod                        # shard files beside the plan
  voxlod merge scan.plan.json -o scan.voxlod --shard-dir /scratch/shards --json
A missing, corrupt or stale shard is refused, naming its file; nothing is written then.";

/// `build`'s options for one shard of a plan.
#[derive(Args)]
pub(crate) struct ShardArgs {
    /// Build one shard of a plan written by `voxlod plan` (input and settings come from the
    /// plan; only -j, --memory, --tmp, --allow-path, --out-dir, -q, --json, --force may be given).
    #[arg(long, requires = "index")]
    pub plan: Option<PathBuf>,
    /// The shard to build, 0-based (Slurm: $SLURM_ARRAY_TASK_ID; a Kubernetes Indexed Job:
    /// $JOB_COMPLETION_INDEX).
    #[arg(long = "shard", requires = "plan")]
    pub index: Option<u32>,
    /// Folder for the shard file `shard-IIII.vlshard` [default: the plan's folder].
    #[arg(long, requires = "plan")]
    pub out_dir: Option<PathBuf>,
}

#[derive(Args)]
pub(crate) struct PlanArgs {
    /// Input mesh; every shard reads it again, so it must be on a filesystem all machines see
    /// (the plan stores its absolute path).
    input: PathBuf,
    /// The plan file to write (JSON, docs/FORMAT.md "Sharded builds"); shard files go beside
    /// it unless `build --out-dir`.
    #[arg(short, long)]
    output: PathBuf,
    /// Number of shards (machines or array tasks).
    #[arg(long)]
    shards: u32,
    /// Cut the input into this many parts for map tasks (`voxlod map`), so that it is decoded
    /// once in all instead of once per shard; the plan then reads only the vertex list and a
    /// sample of the faces. Binary PLY of triangles only; any other input is planned without
    /// parts (with a warning). 0: no parts.
    #[arg(long, default_value_t = 0)]
    parts: u32,
    #[command(flatten)]
    settings: super::SettingsArgs,
    /// No progress.
    #[arg(short, long)]
    quiet: bool,
    /// Print the summary as JSON on stdout (fields: docs/JSON.md).
    #[arg(long)]
    json: bool,
    /// Replace an existing output file even if it is not a voxlod plan.
    #[arg(long)]
    force: bool,
}

#[derive(Args)]
pub(crate) struct MergeArgs {
    /// The plan file the shards were built from.
    plan: PathBuf,
    /// The octree file to write.
    #[arg(short, long)]
    output: PathBuf,
    /// Folder of the shard files [default: the plan's folder].
    #[arg(long)]
    shard_dir: Option<PathBuf>,
    /// Worker threads for the levels above the shards; 0 = one per core.
    #[arg(short = 'j', long, default_value_t = 0)]
    threads: usize,
    /// No summary on stderr.
    #[arg(short, long)]
    quiet: bool,
    /// Print the summary as JSON on stdout (fields: docs/JSON.md).
    #[arg(long)]
    json: bool,
    /// Replace an existing output file even if it is not a voxlod octree.
    #[arg(long)]
    force: bool,
}

pub(crate) fn run_plan(a: PlanArgs) -> Result<()> {
    let mut s = super::settings(&a.settings)?;
    s.progress = !a.quiet;
    s.force = a.force;
    super::install_ctrlc();
    let p = voxlod_pipeline::plan(&a.input, &a.output, &s, a.shards, a.parts)?;
    if a.json {
        return super::json::print(&p);
    }
    for w in &p.warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "{}: {} shards of {} triangles ({} leaf chunks), split level {} ({} subtrees), largest shard {:.2}× the mean ({:.1} s)",
        p.plan.display(),
        p.shards.len(),
        p.triangles,
        p.chunks,
        p.split_level,
        p.balance.subtrees,
        p.balance.ratio,
        p.seconds
    );
    if p.parts > 0 {
        println!(
            "  {} parts for map tasks (`voxlod map {} --part I`); shard weights from {} sampled triangles",
            p.parts,
            p.plan.display(),
            p.sampled_triangles.unwrap_or(0)
        );
    }
    for r in &p.shards {
        let ranges: Vec<String> = r
            .ranges
            .iter()
            .map(|m| format!("{}..{}", m[0], m[1]))
            .collect();
        println!(
            "  shard {:4}: Morton {}, {} subtrees, {} binned triangles",
            r.index,
            if ranges.is_empty() {
                "none".to_string()
            } else {
                ranges.join(" ")
            },
            r.subtrees,
            r.triangles
        );
    }
    Ok(())
}

/// `build --plan P --shard I`.
pub(crate) fn run_build_shard(a: &super::BuildArgs) -> Result<()> {
    let st = &a.settings;
    let given = [
        ("INPUT", a.input.is_some()),
        ("-o", a.output.is_some()),
        ("--config", st.config.is_some()),
        ("-r", st.resolution.is_some()),
        ("--mode", st.mode.is_some()),
        ("--voxelizer", st.voxelizer.is_some()),
        ("--zstd-level", st.zstd_level.is_some()),
        ("--backend", st.backend.is_some()),
        ("--gpu-method", st.gpu_method.is_some()),
        ("--cutoff", st.cutoff.is_some()),
        ("--source-geometry", st.source_geometry),
    ];
    let bad: Vec<&str> = given.iter().filter(|g| g.1).map(|g| g.0).collect();
    if !bad.is_empty() {
        bail!(
            "--plan: the input and the settings that change the output come from the plan; {} not allowed here",
            bad.join(", ")
        );
    }
    let (Some(plan), Some(index)) = (&a.shard.plan, a.shard.index) else {
        bail!("--plan needs --shard I");
    };
    let defaults = BuildSettings::default();
    let runtime = BuildSettings {
        threads: st.threads.unwrap_or(defaults.threads),
        memory: st.memory.unwrap_or(defaults.memory),
        tmp_dir: st.tmp.clone(),
        allow_paths: st.allow_path.clone(),
        progress: !a.quiet,
        force: a.force,
        ..defaults
    };
    voxlod_pipeline::interrupt_after_chunks(a.debug_interrupt_after_chunks);
    super::install_ctrlc();
    let summary = voxlod_pipeline::build_shard(plan, index, a.shard.out_dir.as_deref(), &runtime)?;
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&super::json::build(&summary)?)?
        );
    } else {
        super::print_summary(&summary, &summary.input.display().to_string());
    }
    Ok(())
}

#[derive(Args)]
pub(crate) struct MapArgs {
    /// The plan file (written by `voxlod plan --parts N`); the outputs go beside it.
    plan: PathBuf,
    /// The part to map, 0-based (Slurm: $SLURM_ARRAY_TASK_ID; a Kubernetes Indexed Job:
    /// $JOB_COMPLETION_INDEX).
    #[arg(long)]
    part: u32,
    /// Worker threads; 0 = one per core.
    #[arg(short = 'j', long, default_value_t = 0)]
    threads: usize,
    /// Memory budget (the binning buffer's share), e.g. 2GiB.
    #[arg(long, value_parser = voxlod_pipeline::parse_size)]
    memory: Option<u64>,
    /// Folders besides the input's own that files it refers to may be read from.
    #[arg(long)]
    allow_path: Vec<PathBuf>,
    /// No progress.
    #[arg(short, long)]
    quiet: bool,
    /// Print the summary as JSON on stdout (fields: docs/JSON.md).
    #[arg(long)]
    json: bool,
}

pub(crate) fn run_map(a: MapArgs) -> Result<()> {
    let defaults = BuildSettings::default();
    let runtime = BuildSettings {
        threads: a.threads,
        memory: a.memory.unwrap_or(defaults.memory),
        allow_paths: a.allow_path,
        progress: !a.quiet,
        ..defaults
    };
    super::install_ctrlc();
    let m = voxlod_pipeline::map_part(&a.plan, a.part, &runtime)?;
    if a.json {
        super::json::print(&m)?;
    } else if !a.quiet {
        println!(
            "{}: part {}, {} face records ({}), {} triangles into {} chunks ({} of bins){}, {:.2} s",
            m.marker.display(),
            m.part,
            m.records,
            format_size(m.face_bytes),
            m.triangles,
            m.chunks,
            format_size(m.bins_bytes),
            if m.already_done { ", already done" } else { "" },
            m.seconds
        );
    }
    Ok(())
}

pub(crate) fn run_merge(a: MergeArgs) -> Result<()> {
    let runtime = BuildSettings {
        threads: a.threads,
        force: a.force,
        ..Default::default()
    };
    let m = voxlod_pipeline::merge(&a.plan, &a.output, a.shard_dir.as_deref(), &runtime)?;
    if a.json {
        super::json::print(&m)?;
    } else if !a.quiet {
        println!(
            "{}: {} from {} shards ({} nodes copied, {} subtree roots at level {} decoded), {:.2} s, peak memory {}",
            m.output.display(),
            format_size(m.bytes),
            m.shards,
            m.nodes_copied,
            m.roots_decoded,
            m.split_level,
            m.seconds,
            format_size(m.peak_rss)
        );
    }
    Ok(())
}
