//! `voxlod view FILE`: the streaming viewer of `voxlod-render` (`voxlod_render::view`).
//! With `--fly PATH.json --frames DIR` it renders a camera path headless to PNGs and prints one
//! JSON object of counters per frame; without `--fly` it opens a window.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use voxlod_format::Reader;
use voxlod_render::view::{fly, FlyPath, StreamConfig, Viewer};
use voxlod_render::{RenderError, Renderer};

/// Examples shown by `voxlod view --help`.
pub const EXAMPLES: &str = "\
Examples:
  voxlod view dragon.voxlod --fly configs/fly-in.json --frames frames/
  voxlod view dragon.voxlod --fly configs/fly-in.json --frames frames/ --cache-mib 16 --upload-kib-per-frame 512 --real-time
  voxlod view bunny-src.voxlod --fly configs/close-up.json --frames close/   # built with --source-geometry
  voxlod view bunny-src.voxlod --fly configs/close-up.json --frames close/ --no-source   # voxels only
  voxlod view dragon.voxlod                       # a window (orbit: drag; zoom: wheel; keys below)
Window keys: left drag or A/D/Q/E orbit, wheel or W/S move in and out, arrow keys move the
target, R resets, [ and ] halve and double the pixel error, Esc quits.
In a file built with --source-geometry, leaves whose voxels are still coarser than --error
pixels are streamed and drawn from their source triangles (in the same cache and upload limit).
Headless frames are complete (drawn once all their camera wants is resident); --real-time
draws each after one frame's upload, as the window shows it. No display: use --fly, or run the
window under xvfb-run. The camera path format: docs/VIEWER.md.
Each headless frame prints one JSON line: frame, cut_nodes, cut_leaf_nodes, drawn_nodes,
drawn_leaf_nodes, source_leaves_drawn, faces_drawn, occluded_nodes, probe_nodes,
nodes_resident, voxels_resident, bytes_resident, source_bytes_resident, cache_budget,
bytes_uploaded, upload_limit, cache_hits, cache_misses, evictions, pending, starved, passes,
draws, ... (bytes are bytes; every field in docs/JSON.md).
The GPU holds each resident node's voxels as the file stores them (12 bytes a voxel; the
faces are made in the vertex shader). Occlusion culling (default; --no-occlusion turns it
off) stops refining nodes the last frame found hidden behind nearer ones.";

#[derive(Args)]
pub struct ViewArgs {
    /// An octree file.
    file: PathBuf,
    /// Render this camera path headless instead of opening a window: JSON
    /// {"keyframes": [{"eye": [x,y,z], "target": [x,y,z]}, ...], "frames": N}, coordinates in
    /// the model's bounding cube mapped to [-1,1]^3, or with "coordinates": "world" in world
    /// units as `render --target` takes them; optional "up" (default [0,1,0]) and "fov"
    /// (vertical, degrees, default 45). Keyframes are spread evenly over the frames
    /// (docs/VIEWER.md has the format).
    #[arg(long, requires = "frames")]
    fly: Option<PathBuf>,
    /// With --fly: render each frame as the window would show it at that moment (one stream
    /// pass, at most --upload-kib-per-frame uploaded, coarse levels or nothing until the cut
    /// has arrived) instead of waiting until everything the frame's camera wants is resident.
    #[arg(long, requires = "fly")]
    real_time: bool,
    /// Folder for the frames of --fly (frame_00000.png, ...; files of those names are
    /// replaced); created if missing, but its parent folder must exist.
    #[arg(long, requires = "fly")]
    frames: Option<PathBuf>,
    /// Image (or window) size, WIDTHxHEIGHT.
    #[arg(long, default_value = "800x600", value_parser = crate::render::parse_image_size)]
    size: (u32, u32),
    /// GPU cache budget for node face buffers, MiB; least recently used nodes are evicted.
    #[arg(long, default_value_t = 256.0)]
    cache_mib: f64,
    /// Most bytes uploaded to the GPU per frame, KiB (a larger node takes several frames).
    #[arg(long, default_value_t = 4096.0)]
    upload_kib_per_frame: f64,
    /// Refine a node while its voxels project to more than this many pixels.
    #[arg(long, default_value_t = 1.0)]
    error: f64,
    /// Draw voxels everywhere, even where the file stores source triangles for leaves whose
    /// voxels are coarser than --error pixels.
    #[arg(long)]
    no_source: bool,
    /// Refine every node the cut wants. By default nodes found hidden behind nearer ones by
    /// the last frame's occlusion queries are not refined (drawn coarse as depth-only probes
    /// until a sample of them shows); complete --fly frames are the same pictures either way.
    #[arg(long)]
    no_occlusion: bool,
    /// Draw open surfaces from behind too, as `render --two-sided` does (default: only the
    /// faces of the voxels' face masks).
    #[arg(long)]
    two_sided: bool,
}

#[cfg(feature = "window")]
fn interactive(
    reader: &Reader,
    config: StreamConfig,
    size: (u32, u32),
    two_sided: bool,
) -> Result<()> {
    Ok(voxlod_render::view::window::run(
        reader, config, size, two_sided,
    )?)
}

#[cfg(not(feature = "window"))]
fn interactive(_: &Reader, _: StreamConfig, _: (u32, u32), _: bool) -> Result<()> {
    bail!("this build of voxlod has no window (feature `window`); render a camera path with --fly PATH.json --frames DIR")
}

/// Bytes of `amount` units of `unit` bytes, or an error naming the option.
fn bytes(amount: f64, unit: f64, option: &str) -> Result<u64> {
    let b = amount * unit;
    if !(b.is_finite() && b >= 1.0 && b < 1e15) {
        bail!("{option} {amount} must be a positive size");
    }
    Ok(b as u64)
}

pub fn run(a: ViewArgs) -> Result<()> {
    let config = StreamConfig {
        cache_bytes: bytes(a.cache_mib, 1048576.0, "--cache-mib")?,
        upload_bytes_per_frame: bytes(a.upload_kib_per_frame, 1024.0, "--upload-kib-per-frame")?,
        max_error_px: a.error,
        source: !a.no_source,
        occlusion: !a.no_occlusion,
    };
    let reader = Reader::open(&a.file)?;
    let (Some(path), Some(dir)) = (a.fly, a.frames) else {
        return interactive(&reader, config, a.size, a.two_sided);
    };
    let path = FlyPath::load(&path)?;
    // the folder itself may be new, its parent must exist (a typo in a path is an error, as
    // for every output of voxlod)
    if !dir.is_dir() {
        std::fs::create_dir(&dir).with_context(|| {
            format!(
                "creating the frames folder {} (its parent folder must exist)",
                dir.display()
            )
        })?;
    }
    let mut renderer = Renderer::new()?;
    renderer.set_two_sided(a.two_sided);
    let mut viewer = Viewer::new(&reader, renderer, config)?;
    fly(&mut viewer, &path, a.size, a.real_time, &mut |i, frame| {
        // each frame as every output of voxlod: not the octree viewed (nor a link to it), not
        // a file of another kind, written under a temporary name and renamed into place
        let out = dir.join(format!("frame_{i:05}.png"));
        let refused = |e: anyhow::Error| RenderError::Option(voxlod_pipeline::chain_text(&e));
        let guard = voxlod_pipeline::OutputGuard::acquire(
            &out,
            &[&a.file],
            voxlod_pipeline::OutputKind::Png,
            false,
        )
        .map_err(refused)?;
        frame.picture.write_png(guard.staged())?;
        guard.commit().map_err(refused)?;
        println!(
            "{}",
            serde_json::to_string(&frame.stats).expect("plain numbers")
        );
        Ok(())
    })?;
    Ok(())
}
