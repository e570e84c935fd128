//! Looking at voxlod octrees: pictures and meshes.
//!
//! - [`Renderer`] draws a file headless on wgpu (Vulkan, or lavapipe where there is no GPU)
//!   the way the renderer of Chajdas, Reitinger & Westermann ("Scalable rendering for very
//!   large meshes", WSCG 2014) does: each voxel a small cube of which only the faces in its
//!   face mask are drawn, shaded with its normal under a directional light and its colour.
//!   The nodes drawn are one level, or the screen-space error cut for the camera
//!   ([`Lod`], [`cut::select`]: the voxels' real size in pixels, frustum culled); the camera frames the bulk of the model's voxels
//!   ([`robust_bounds`], so stray fragments do not shrink it) from a [`View`].
//! - [`export_ply`] writes one level as a quad mesh (binary PLY with normals and colours);
//!   [`export_glb_with`] the same quads as glTF 2.0 binary, [`node_glb`] one node's,
//!   [`export_tileset_with`] an OGC 3D Tiles 1.1 tileset of compressed tiles ([`tile_content`]).
//! - [`view`] streams nodes by that same cut into a fixed GPU budget (least recently used
//!   eviction, an upload limit per frame) and draws frames along a camera path (`voxlod view`),
//!   or in a window with the `window` feature.
//!
//! ```
//! use voxlod_format::voxel::{border_caps, face_mask, pack_color, pack_normal, Voxel};
//! use voxlod_format::{encode_node, FileSpec, Reader, Writer, MODE_THIN};
//!
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("one.voxlod");
//! let n = pack_normal([0.0, 0.0, 1.0]);
//! let v = Voxel::new([4, 4, 4], face_mask(n) | border_caps([4, 4, 4]), n, pack_color([255, 0, 0, 255]));
//! let mut w = Writer::create(&path, FileSpec::new(256, MODE_THIN, [0.0; 3], 0.1)).unwrap();
//! w.write_node(0, [0, 0, 0], 0, &encode_node(&[v], 3).unwrap()).unwrap();
//! w.finish(&serde_json::json!({})).unwrap();
//! let reader = Reader::open(&path).unwrap();
//!
//! // one +z face: one quad
//! let out = dir.path().join("level0.ply");
//! let s = voxlod_render::export_ply(&reader, 0, &out).unwrap();
//! assert_eq!((s.voxels, s.quads, s.vertices), (1, 1, 4));
//! assert_eq!(std::fs::metadata(&out).unwrap().len(), s.bytes);
//! ```
//!
//! Rendering needs an adapter; see `tests/render.rs` for a complete example with
//! [`Renderer::new`], [`frame`] and [`Renderer::render`].

mod camera;
mod color;
pub mod cut;
mod draw;
mod error;
mod export;
mod export_source;
mod faces;
mod glb;
mod pass;
mod picture;
mod source_draw;
mod tile_glb;
mod tileset;
pub mod view;

pub use camera::{model_bounds, robust_bounds, up_from_shape, Shot, View};
pub use color::{linear_to_srgb, srgb_to_linear};
pub use draw::{Renderer, BACKGROUND};
pub use error::RenderError;
pub use export::{export_ply, export_ply_with, shading_normal, ExportSummary};
pub use export_source::{export_source_ply, source_world_position, SourceExportSummary};
pub use faces::{
    face_direction, material_color, node_faces, node_faces_by, unit_face_corners, ColorBy, Face,
};
pub use glb::{export_glb_with, node_glb, NodeGlb, UpAxis, GLB_VERTEX_BYTES};
pub use picture::Picture;
pub use tile_glb::{tile_content, TileContent, TileFrame};
pub use tileset::{
    bottom_centre, export_tileset_with, root_transform, rotation_to_z, tile_uri, wgs84_to_ecef,
    TilesetOptions, TilesetSummary, DEFAULT_MAX_SSE, GEOMETRIC_ERROR_PER_EDGE,
};

use voxlod_format::Reader;

/// Which nodes to draw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lod {
    /// Every node of one level (0 = the finest).
    Level(u32),
    /// The screen-space error cut: refine while a node's voxels project to more than this
    /// many pixels ([`cut::select`], the rule the viewer streams by).
    Error(f64),
}

/// The camera framing the model for `view`, and the nodes `lod` selects for it. The model is
/// framed by its [`robust_bounds`] (the bulk of its voxels, stray fragments left out).
pub fn frame(reader: &Reader, view: &View, lod: Lod) -> Result<(Shot, Vec<usize>), RenderError> {
    model_bounds(reader)
        .ok_or_else(|| RenderError::Option("the file has no voxels to draw".into()))?;
    let bounds = robust_bounds(reader)?
        .ok_or_else(|| RenderError::Option("the file has no voxels to draw".into()))?;
    let shot = Shot::frame(bounds, view)?;
    let nodes = match lod {
        Lod::Level(l) => faces::level_nodes(reader, l)?,
        Lod::Error(px) => {
            if !(px.is_finite() && px > 0.0) {
                return Err(RenderError::Option(format!(
                    "screen-space error {px} must be a positive number of pixels"
                )));
            }
            cut::select(reader, &shot, px)
                .into_iter()
                .map(|c| c.index)
                .collect()
        }
    };
    Ok((shot, nodes))
}

/// The leaves `lod` draws from their source triangles for `shot`: with [`Lod::Error`], the cut
/// leaves marked [`over`](cut::CutNode::over) (their voxels are coarser than the pixel error),
/// if the file stores source triangles; otherwise none.
pub fn over_leaves(reader: &Reader, shot: &Shot, lod: Lod) -> Vec<usize> {
    match lod {
        Lod::Error(px) if reader.has_source_triangles() && px.is_finite() && px > 0.0 => {
            cut::select(reader, shot, px)
                .into_iter()
                .filter(|c| c.over)
                .map(|c| c.index)
                .collect()
        }
        _ => Vec::new(),
    }
}
