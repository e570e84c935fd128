//! Source triangles in the picture (Chajdas, Reitinger & Westermann, "Scalable
//! rendering for very large meshes", WSCG 2014, section 5: where the finest voxels still
//! project above the pixel error, the original geometry is drawn instead). The leaves that
//! [`crate::cut::CutNode::over`] marks are drawn from their stored source triangles
//! (docs/FORMAT.md 14.4) as one indexed triangle list, in the same pass, camera, depth buffer
//! and light as the voxel faces (`source.wgsl`): the normal is the stored octahedral normal,
//! or the face normal where none is stored; the colour is the stored vertex colour, or the
//! colour voxels get without one (white), or the triangle's material colour.

use glam::DVec3;
use voxlod_format::triangles::oct_decode;
use voxlod_format::Reader;

use crate::export_source::source_world_position;
use crate::faces::{material_color, ColorBy};
use crate::pass::pass_pipeline;
use crate::RenderError;

/// The colour of a vertex without a stored colour: the voxels' default (`voxlod_geom::DEFAULT_COLOR`).
const DEFAULT_COLOR: [u8; 4] = [255, 255, 255, 255];

/// One vertex as `source.wgsl` reads it (28 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct SourceVertex {
    pub pos: [f32; 3],
    /// Unit normal, or zero: the fragment shader uses the face normal.
    pub normal: [f32; 3],
    pub color: u32,
}

/// The source triangles of some leaves, ready to upload.
#[derive(Debug, Default)]
pub(crate) struct SourceGeometry {
    pub vertices: Vec<SourceVertex>,
    pub indices: Vec<u32>,
    /// The leaves drawn from triangles (those of the request that store some), ascending.
    pub leaves: Vec<usize>,
    /// Triangles in `indices`.
    pub triangles: u64,
}

/// Gathers the source triangles of `leaves` (node indices), positions relative to `origin`.
/// A leaf without stored triangles is left out of [`SourceGeometry::leaves`] (it is drawn as
/// voxels). Colours follow `color`; [`ColorBy::Material`] gives each triangle its own vertices
/// (one colour per triangle).
pub(crate) fn gather(
    reader: &Reader,
    leaves: &[usize],
    origin: DVec3,
    color: ColorBy,
) -> Result<SourceGeometry, RenderError> {
    let mut g = SourceGeometry::default();
    let mut sorted = leaves.to_vec();
    sorted.sort_unstable();
    sorted.dedup();
    for i in sorted {
        assert_eq!(
            reader.nodes()[i].level,
            0,
            "source triangles belong to leaves"
        );
        let Some(m) = reader.source_triangles(i)? else {
            continue;
        };
        let chunk = reader.nodes()[i].pos();
        let vertex = |k: u32, rgba: [u8; 4]| {
            let p = DVec3::from(source_world_position(reader, chunk, &m, k)) - origin;
            SourceVertex {
                pos: p.as_vec3().into(),
                normal: m
                    .normals
                    .as_ref()
                    .map_or([0.0; 3], |n| oct_decode(n[k as usize])),
                color: u32::from_le_bytes(rgba),
            }
        };
        let base = g.vertices.len() as u64;
        if base + m.positions.len() as u64 * 3 > u32::MAX as u64 {
            return Err(RenderError::Option(
                "too many source vertices for one picture; use a larger --error or --no-source"
                    .into(),
            ));
        }
        match color {
            ColorBy::Voxel => {
                for k in 0..m.positions.len() as u32 {
                    let rgba = m.colors.as_ref().map_or(DEFAULT_COLOR, |c| c[k as usize]);
                    g.vertices.push(vertex(k, rgba));
                }
                let b = base as u32;
                g.indices
                    .extend(m.triangles.iter().flat_map(|t| t.map(|v| b + v)));
            }
            ColorBy::Material => {
                for (t, tri) in m.triangles.iter().enumerate() {
                    let id = m.materials.as_ref().map_or(0, |ms| ms[t]) as u32;
                    for v in tri {
                        g.indices.push(g.vertices.len() as u32);
                        g.vertices.push(vertex(*v, material_color(id)));
                    }
                }
            }
        }
        g.triangles += m.triangles.len() as u64;
        g.leaves.push(i);
    }
    Ok(g)
}

/// The pipeline drawing [`SourceVertex`] triangle lists with `layout`'s uniforms (the voxel
/// faces' uniforms plus the eye), into the voxel pass's targets.
pub(crate) fn pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
) -> wgpu::RenderPipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("source triangles"),
        source: wgpu::ShaderSource::Wgsl(include_str!("source.wgsl").into()),
    });
    let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Uint32];
    pass_pipeline(
        device,
        "source triangles",
        layout,
        &module,
        wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<SourceVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &attributes,
        },
        // scanned meshes are not reliably wound or closed: both sides are drawn
        wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            cull_mode: None,
            ..Default::default()
        },
        false,
    )
}
