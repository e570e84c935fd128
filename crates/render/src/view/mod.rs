//! The streaming viewer behind `voxlod view`: a frame loop over a [`Stream`] (the node cache
//! with its upload limit, after Chajdas et al. 2014, Figure 14) drawing with the [`Renderer`]'s
//! voxel-face pipeline, and with its source-triangle pipeline the leaves whose voxels are
//! coarser than the pixel error (section 4 of the paper; files built with `--source-geometry`). The headless mode ([`fly`]) renders a [`FlyPath`] to pictures; the
//! interactive window (`window` feature, module `window`) runs the same [`Viewer::frame`] per
//! redraw and copies the picture to the window.

mod path;
mod source;
mod stream;
#[cfg(feature = "window")]
pub mod window;

pub use path::{Coordinates, FlyPath, Keyframe};
pub use stream::{FrameStats, Stream, StreamConfig};

use glam::DVec3;
use voxlod_format::{Aabb, Reader};

use crate::camera::{model_bounds, Shot};
use crate::picture::Picture;
use crate::{RenderError, Renderer};

/// A file, its node cache and a renderer: one [`frame`](Viewer::frame) per camera.
#[derive(Debug)]
pub struct Viewer<'a> {
    reader: &'a Reader,
    renderer: Renderer,
    stream: Stream,
    bounds: Aabb,
}

/// One rendered frame: the picture and what the stream did.
#[derive(Debug)]
pub struct Frame {
    /// The picture (its `nodes` are the nodes drawn).
    pub picture: Picture,
    /// Counters of the frame.
    pub stats: FrameStats,
}

impl<'a> Viewer<'a> {
    /// A viewer of `reader` with an empty cache; fails for a file without voxels.
    pub fn new(
        reader: &'a Reader,
        renderer: Renderer,
        config: StreamConfig,
    ) -> Result<Viewer<'a>, RenderError> {
        let bounds = model_bounds(reader)
            .ok_or_else(|| RenderError::Option("the file has no voxels to draw".into()))?;
        let origin = DVec3::from(bounds.center());
        Ok(Viewer {
            reader,
            renderer,
            stream: Stream::new(reader, origin, config)?,
            bounds,
        })
    }

    /// The model's bounding box (the root node's box), which [`FlyPath`] coordinates map to.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The renderer.
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// Changes the pixel error the cut refines to (the cache is kept).
    pub fn set_max_error(&mut self, px: f64) {
        self.stream.set_max_error(px);
    }

    /// The node cache.
    pub fn stream(&self) -> &Stream {
        &self.stream
    }

    /// Turns occlusion culling on or off (the cache is kept).
    pub fn set_occlusion(&mut self, on: bool) {
        self.stream.set_occlusion(on);
    }

    /// Streams and draws one real-time frame for `shot`: one stream pass, at most the upload
    /// limit, and what is resident drawn (as the window does: after a jump, coarse levels or
    /// nothing until the cut arrives over the next frames; with occlusion culling, a node
    /// seen again after being hidden is refined from the next frame).
    pub fn frame(&mut self, shot: &Shot) -> Result<Frame, RenderError> {
        let (stats, drawn) = self.stream.frame(self.reader, &self.renderer, shot)?;
        let (frame, _) = self.draw(shot, stats, drawn)?;
        Ok(frame)
    }

    /// Streams and draws one complete frame for `shot`: stream passes (each within the upload
    /// limit, as in [`frame`](Self::frame)) repeat until nothing the frame wants is pending,
    /// or until a pass makes no progress (the cache budget is full of entries this frame needs,
    /// or an entry exceeds it: then what fits is drawn, as `starved` and `too_big` say). With
    /// occlusion culling, if a probe (a node hidden in the last draw) passes a sample, the
    /// frame is streamed and drawn again, refined there (`draws`), so the picture is the one
    /// without occlusion culling. The picture is the one the camera gets once streaming has
    /// caught up, whatever the upload limit. Counters: hits and misses are those of the first
    /// pass (the cache as the frame found it), bytes uploaded, evictions and completions are
    /// summed over the passes, the rest are the last pass's; `passes` says how many there
    /// were.
    pub fn complete_frame(&mut self, shot: &Shot) -> Result<Frame, RenderError> {
        /// A bound on the passes, far above any need (each pass that continues uploads bytes).
        const MAX_PASSES: u32 = 1 << 20;
        /// A bound on the draws of one frame (each after probes passed).
        const MAX_DRAWS: u32 = 8;
        let mut first: Option<FrameStats> = None;
        let mut sum = FrameStats::default();
        loop {
            let (stats, drawn) = self.stream.frame(self.reader, &self.renderer, shot)?;
            sum.bytes_uploaded += stats.bytes_uploaded;
            sum.source_bytes_uploaded += stats.source_bytes_uploaded;
            sum.evictions += stats.evictions;
            sum.nodes_completed += stats.nodes_completed;
            sum.source_completed += stats.source_completed;
            sum.passes += 1;
            let progress = stats.bytes_uploaded > 0
                || stats.nodes_completed > 0
                || stats.source_completed > 0
                || stats.evictions > 0;
            let first = first.get_or_insert_with(|| stats.clone());
            if stats.pending == 0 || !progress || sum.passes == MAX_PASSES {
                let stats = FrameStats {
                    frame: first.frame,
                    cache_hits: first.cache_hits,
                    cache_misses: first.cache_misses,
                    source_hits: first.source_hits,
                    source_misses: first.source_misses,
                    bytes_uploaded: sum.bytes_uploaded,
                    source_bytes_uploaded: sum.source_bytes_uploaded,
                    evictions: sum.evictions,
                    nodes_completed: sum.nodes_completed,
                    source_completed: sum.source_completed,
                    passes: sum.passes,
                    ..stats
                };
                let (mut frame, revealed) = self.draw(shot, stats, drawn)?;
                sum.draws += 1;
                sum.draw_ms += frame.stats.draw_ms;
                frame.stats.draws = sum.draws;
                frame.stats.draw_ms = sum.draw_ms;
                if revealed == 0 || sum.draws == MAX_DRAWS {
                    return Ok(frame);
                }
            }
        }
    }

    /// Draws the entries `drawn` of a stream pass and takes the occlusion results; also
    /// returns how many probes passed.
    fn draw(
        &mut self,
        shot: &Shot,
        mut stats: FrameStats,
        drawn: Vec<stream::Drawn>,
    ) -> Result<(Frame, usize), RenderError> {
        let two_sided = self.renderer.two_sided();
        let (batches, which, counts) = self.stream.batches(self.reader, shot, &drawn, two_sided);
        let source = self.stream.source_batches(&drawn);
        stats.faces_resident_in_drawn = counts.resident;
        stats.faces_drawn = counts.drawn;
        stats.voxels_drawn = counts.voxels;
        stats.draws = 1;
        let t = std::time::Instant::now();
        let drawing = self
            .renderer
            .draw(shot, self.stream.origin(), &batches, &source.batches)?;
        stats.draw_ms = t.elapsed().as_secs_f64() * 1e3;
        let (source_leaves, source_triangles) = (source.leaves, source.triangles);
        drop(batches);
        drop(source);
        let mut passed = vec![None; drawn.len()];
        for (k, p) in which.iter().zip(&drawing.passed) {
            passed[*k] = *p;
        }
        let revealed = self
            .stream
            .occlusion_results(self.reader, shot, &drawn, &passed);
        stats.probes_passed = revealed;
        let nodes: Vec<usize> = drawn.iter().map(|d| d.index).collect();
        let voxels = drawn
            .iter()
            .filter(|d| !d.triangles)
            .map(|d| self.reader.nodes()[d.index].voxel_count as u64)
            .sum();
        let frame = Frame {
            picture: Picture {
                width: drawing.width,
                height: drawing.height,
                rgba: drawing.rgba,
                shot: *shot,
                nodes,
                voxels,
                faces_drawn: counts.drawn,
                source_leaves,
                source_triangles,
            },
            stats,
        };
        Ok((frame, revealed))
    }
}

/// Renders every frame of `path` at `width`×`height` and hands each to `each` (which may write
/// it out); stops at the first error. Frames are complete ([`Viewer::complete_frame`]: each
/// waits until what its camera wants is resident), or with `real_time` one stream pass each
/// ([`Viewer::frame`], what the window would show at that frame). Frame numbers in the
/// counters are the path's, from 0.
pub fn fly(
    viewer: &mut Viewer,
    path: &FlyPath,
    (width, height): (u32, u32),
    real_time: bool,
    each: &mut dyn FnMut(u32, Frame) -> Result<(), RenderError>,
) -> Result<(), RenderError> {
    path.check()?;
    if width == 0 || height == 0 || width > 16384 || height > 16384 {
        return Err(RenderError::Option(format!(
            "image size {width}x{height} must be 1..=16384 on each side"
        )));
    }
    for i in 0..path.frames {
        let shot = path.shot(i, viewer.bounds(), width, height);
        let mut frame = if real_time {
            viewer.frame(&shot)?
        } else {
            viewer.complete_frame(&shot)?
        };
        frame.stats.frame = i as u64;
        each(i, frame)?;
    }
    Ok(())
}
