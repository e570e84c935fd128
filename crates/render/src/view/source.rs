//! A leaf's source triangles as one entry of the viewer's cache (Chajdas, Reitinger &
//! Westermann, "Scalable rendering for very large meshes", WSCG 2014, section 4: "if the
//! camera moves close enough to an octree leaf that the voxel resolution is no longer
//! sufficient to maintain the pixel error guarantee, the leaf node is replaced by the actual
//! input geometry"). The entry is one GPU buffer, usable as vertex and index buffer: the
//! leaf's vertices as `render` draws them (`source_draw`, 28 bytes each, shared vertices once)
//! and then its `u32` indices (12 bytes per triangle), so it streams through the same byte
//! budget and upload limit as the voxel faces.

use glam::DVec3;
use voxlod_format::Reader;

use crate::draw::SourceBatch;
use crate::faces::ColorBy;
use crate::source_draw::{self, SourceVertex};
use crate::RenderError;

/// Where the parts of a triangle entry lie in its buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct TriangleLayout {
    /// Bytes of vertices at the start of the buffer (the index buffer follows).
    pub vertex_bytes: u64,
    /// Indices after them (three per triangle).
    pub indices: u32,
}

impl TriangleLayout {
    /// Triangles of the entry.
    pub fn triangles(&self) -> u64 {
        self.indices as u64 / 3
    }

    /// The draw of the entry in `buffer`.
    pub fn batch<'a>(&self, buffer: &'a wgpu::Buffer) -> SourceBatch<'a> {
        (
            buffer.slice(..self.vertex_bytes),
            buffer.slice(self.vertex_bytes..),
            self.indices,
        )
    }
}

/// The bytes of leaf `i`'s triangle entry (positions relative to `origin`) and their layout;
/// `None` when the leaf stores no triangles.
pub(crate) fn leaf_entry(
    reader: &Reader,
    i: usize,
    origin: DVec3,
) -> Result<Option<(Vec<u8>, TriangleLayout)>, RenderError> {
    let g = source_draw::gather(reader, &[i], origin, ColorBy::Voxel)?;
    if g.leaves.is_empty() || g.indices.is_empty() {
        return Ok(None);
    }
    let mut data: Vec<u8> = bytemuck::cast_slice(&g.vertices).to_vec();
    let vertex_bytes = data.len() as u64;
    debug_assert_eq!(
        vertex_bytes,
        g.vertices.len() as u64 * std::mem::size_of::<SourceVertex>() as u64
    );
    data.extend_from_slice(bytemuck::cast_slice(&g.indices));
    Ok(Some((
        data,
        TriangleLayout {
            vertex_bytes,
            indices: g.indices.len() as u32,
        },
    )))
}
