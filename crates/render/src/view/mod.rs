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

pub use path::{FlyPath, Keyframe};
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

    /// Streams and draws one frame for `shot`.
    pub fn frame(&mut self, shot: &Shot) -> Result<Frame, RenderError> {
        let (mut stats, drawn) = self.stream.frame(self.reader, &self.renderer, shot)?;
        let (batches, all, kept) = self.stream.batches(self.reader, shot, &drawn);
        let source = self.stream.source_batches(&drawn);
        stats.faces_resident_in_drawn = all;
        stats.faces_drawn = kept;
        let (width, height, rgba) =
            self.renderer
                .draw(shot, self.stream.origin(), &batches, &source.batches)?;
        let nodes: Vec<usize> = drawn.iter().map(|d| d.index).collect();
        let voxels = drawn
            .iter()
            .filter(|d| !d.triangles)
            .map(|d| self.reader.nodes()[d.index].voxel_count as u64)
            .sum();
        Ok(Frame {
            picture: Picture {
                width,
                height,
                rgba,
                shot: *shot,
                nodes,
                voxels,
                faces_drawn: kept,
                source_leaves: source.leaves,
                source_triangles: source.triangles,
            },
            stats,
        })
    }
}

/// Renders every frame of `path` at `width`×`height` and hands each to `each` (which may write
/// it out); stops at the first error.
pub fn fly(
    viewer: &mut Viewer,
    path: &FlyPath,
    (width, height): (u32, u32),
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
        let frame = viewer.frame(&shot)?;
        each(i, frame)?;
    }
    Ok(())
}
