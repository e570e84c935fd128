//! Headless GPU rendering on wgpu (lavapipe on machines without a GPU): the selected nodes'
//! active voxel faces as instances of a 6-vertex quad, depth-tested, 4× multisampled, drawn
//! into an offscreen texture and read back. Only faces turned towards the eye are uploaded
//! (back faces can never be seen), which halves the buffer. The device comes from
//! `voxlod_gpu::open_device` (the workspace's one device setup); the streaming viewer
//! (`crate::view`) draws its cached per-node face buffers with the same pipeline through
//! [`Renderer::draw`].

use std::ops::Range;

use glam::DVec3;
use voxlod_format::{Reader, Voxel};

use crate::camera::Shot;
use crate::faces::{material_color, ColorBy};
use crate::pass::{pass_pipeline, Targets};
use crate::picture::Picture;
use crate::source_draw;
use crate::RenderError;

/// Background of the picture (light grey); covered pixels have alpha 255, the rest 0.
pub const BACKGROUND: [u8; 3] = [236, 238, 242];

/// Bytes of one resident voxel on the GPU: the three words of its record as the file stores
/// them (FORMAT.md section 6; `--color material` replaces the colour word), nothing per face.
/// The vertex shader makes the faces from them.
pub const VOXEL_BYTES: u64 = std::mem::size_of::<Voxel>() as u64;

/// The constants of one node's draw (group 1 at a dynamic offset): the minimum corner of its
/// chunk relative to the picture's origin (computed in f64, so f32 keeps the precision near
/// the camera's subject), the voxel edge, and flags (bit 0: two-sided).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct NodeConstants {
    pub min_edge: [f32; 4],
    pub flags: [u32; 4],
}

impl NodeConstants {
    /// The constants of node `index` of `reader`, relative to `origin` (flags 0).
    pub(crate) fn of(reader: &Reader, index: usize, origin: DVec3) -> Self {
        let e = reader.nodes()[index];
        let spec = reader.spec();
        let min = DVec3::from(spec.voxel_min_corner(e.level, e.pos(), [0; 3])) - origin;
        let edge = spec.voxel_size_at(e.level) as f32;
        NodeConstants {
            min_edge: [min.x as f32, min.y as f32, min.z as f32, edge],
            flags: [0; 4],
        }
    }
}

/// One node's voxels to draw: instances `voxels` of `buffer` (records of [`VOXEL_BYTES`]),
/// with the node's constants; `probe`: drawn as occlusion culling's test of a hidden node
/// (depth tested, no colour or depth written); `query`: inside an occlusion query.
pub(crate) struct Batch<'a> {
    pub buffer: &'a wgpu::Buffer,
    pub voxels: Range<u32>,
    pub node: NodeConstants,
    pub probe: bool,
    pub query: bool,
}

/// Source triangles to draw: vertices (`SourceVertex`), `u32` indices and the number of
/// indices.
pub(crate) type SourceBatch<'a> = (wgpu::BufferSlice<'a>, wgpu::BufferSlice<'a>, u32);

/// Vertices per voxel instance: three slots (x, y, z) of one face (two triangles) each.
const VERTICES_PER_VOXEL: u32 = 18;

/// Flag bit of [`NodeConstants::flags`]: an axis with either face-mask bit draws the face on
/// the eye's side (open surfaces seen from behind).
const FLAG_TWO_SIDED: u32 = 1;

/// Faces the vertex shader draws for a voxel with minimum corner `min`, edge `edge` and face
/// mask `mask` seen from `eye` (the shader's rule, in f64): per axis the face on the eye's side
/// if the eye is outside the voxel's slab and the mask has that face's bit (`two_sided`: either
/// bit of the axis).
pub fn faces_seen(eye: DVec3, min: [f64; 3], edge: f64, mask: u8, two_sided: bool) -> u32 {
    (0..3)
        .filter(|&a| {
            let dir = if eye[a] > min[a] + edge {
                2 * a
            } else if eye[a] < min[a] {
                2 * a + 1
            } else {
                return false;
            };
            mask >> dir & 1 == 1 || (two_sided && mask >> (2 * a) & 3 != 0)
        })
        .count() as u32
}

/// A GPU device with the voxel pipeline, reusable for many pictures.
pub struct Renderer {
    gpu: voxlod_gpu::Gpu,
    pipeline: wgpu::RenderPipeline,
    probe_pipeline: wgpu::RenderPipeline,
    source_pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    node_layout: wgpu::BindGroupLayout,
    adapter: String,
    two_sided: bool,
}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer")
            .field("adapter", &self.adapter)
            .field("two_sided", &self.two_sided)
            .finish_non_exhaustive()
    }
}

/// The renderer's error for a failure to open the device.
pub(crate) fn gpu_error(e: voxlod_gpu::GpuError) -> RenderError {
    match e {
        voxlod_gpu::GpuError::NoAdapter(why) => RenderError::NoAdapter(why),
        voxlod_gpu::GpuError::Device { adapter, reason } => RenderError::Gpu { adapter, reason },
        other => RenderError::Gpu {
            adapter: String::new(),
            reason: other.to_string(),
        },
    }
}

/// Bytes between two nodes' constants in the per-draw uniform buffer (the dynamic offset
/// alignment every adapter accepts).
const NODE_STRIDE: u64 = 256;

/// Occlusion queries of one draw: results of more batches than this are not asked for (those
/// batches count as visible).
pub(crate) const MAX_QUERIES: u32 = wgpu::QUERY_SET_MAX_QUERIES;

impl Renderer {
    /// Finds an adapter (Vulkan first, then GL; `WGPU_BACKEND` overrides) and builds the
    /// pipeline.
    pub fn new() -> Result<Renderer, RenderError> {
        Renderer::with_gpu(
            voxlod_gpu::open_device("voxlod-render", wgpu::Features::empty()).map_err(gpu_error)?,
        )
    }

    /// The pipeline on a device already open (e.g. one that presents to a window).
    pub fn with_gpu(gpu: voxlod_gpu::Gpu) -> Result<Renderer, RenderError> {
        let name = format!("{} ({:?})", gpu.info.name, gpu.info.backend);
        let device = &gpu.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("voxels"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shader.wgsl").into()),
        });
        let uniform = |dynamic: bool| wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: dynamic,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("uniforms"),
            entries: &[uniform(false)],
        });
        let node_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("node constants"),
            entries: &[uniform(true)],
        });
        let source_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: None,
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let voxel_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: None,
            bind_group_layouts: &[Some(&layout), Some(&node_layout)],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![0 => Uint32x3];
        let voxel_pipeline = |probe: bool| {
            pass_pipeline(
                device,
                if probe { "voxel probes" } else { "voxels" },
                &voxel_layout,
                &module,
                wgpu::VertexBufferLayout {
                    array_stride: VOXEL_BYTES,
                    step_mode: wgpu::VertexStepMode::Instance,
                    attributes: &attributes,
                },
                wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleList,
                    front_face: wgpu::FrontFace::Ccw,
                    cull_mode: Some(wgpu::Face::Back),
                    ..Default::default()
                },
                probe,
            )
        };
        let pipeline = voxel_pipeline(false);
        let probe_pipeline = voxel_pipeline(true);
        let source_pipeline = source_draw::pipeline(device, &source_layout);
        let r = Renderer {
            gpu,
            pipeline,
            probe_pipeline,
            source_pipeline,
            layout,
            node_layout,
            adapter: name,
            two_sided: false,
        };
        r.check()?;
        Ok(r)
    }

    /// Draws open surfaces from behind too: per axis, a voxel whose face mask has either face
    /// of the axis draws the one on the eye's side, lit with the normal turned towards it
    /// where the mask lacks that face. False (the default): only the faces of the mask.
    pub fn set_two_sided(&mut self, two_sided: bool) {
        self.two_sided = two_sided;
    }

    /// True if open surfaces are drawn from behind ([`set_two_sided`](Self::set_two_sided)).
    pub fn two_sided(&self) -> bool {
        self.two_sided
    }

    /// The adapter's name and backend, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)".
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    fn check(&self) -> Result<(), RenderError> {
        match self.gpu.error.lock().ok().and_then(|mut s| s.take()) {
            Some(reason) => Err(RenderError::Gpu {
                adapter: self.adapter.clone(),
                reason,
            }),
            None => Ok(()),
        }
    }

    /// Draws the active faces of `nodes` of `reader` as seen by `shot`.
    pub fn render(
        &self,
        reader: &Reader,
        nodes: &[usize],
        shot: &Shot,
    ) -> Result<Picture, RenderError> {
        self.render_by(reader, nodes, shot, ColorBy::Voxel)
    }

    /// [`render`](Self::render) with the faces coloured as `color` says (the voxels' colours,
    /// or their materials).
    pub fn render_by(
        &self,
        reader: &Reader,
        nodes: &[usize],
        shot: &Shot,
        color: ColorBy,
    ) -> Result<Picture, RenderError> {
        self.render_with_source(reader, nodes, &[], shot, color)
    }

    /// [`render_by`](Self::render_by), but the leaves of `source` (a subset of `nodes`, e.g.
    /// the cut leaves marked [`over`](crate::cut::CutNode::over)) that store source triangles
    /// are drawn from those triangles instead of their voxels. With no such leaf the picture
    /// is that of [`render_by`](Self::render_by), byte for byte.
    pub fn render_with_source(
        &self,
        reader: &Reader,
        nodes: &[usize],
        source: &[usize],
        shot: &Shot,
        color: ColorBy,
    ) -> Result<Picture, RenderError> {
        let centre = shot.target;
        let tris = source_draw::gather(reader, source, centre, color)?;
        // every node's voxels in one buffer, each node's range and constants
        let mut words: Vec<Voxel> = Vec::new();
        let mut ranges: Vec<(Range<u32>, NodeConstants)> = Vec::new();
        let mut buf = Vec::new();
        let (mut voxels, mut faces) = (0u64, 0u64);
        let spec = reader.spec();
        for &i in nodes {
            if tris.leaves.binary_search(&i).is_ok() {
                continue;
            }
            reader.read_node_into(i, &mut buf)?;
            let materials = match color {
                ColorBy::Voxel => None,
                ColorBy::Material => Some(reader.read_materials(i)?.ok_or_else(|| {
                    RenderError::Option(
                        "the file has no material channel (built from a mesh with fewer than two materials)"
                            .into(),
                    )
                })?),
            };
            let e = reader.nodes()[i];
            let edge = spec.voxel_size_at(e.level);
            let start = words.len() as u32;
            for (j, v) in buf.iter().enumerate() {
                if v.mask() == 0 {
                    continue;
                }
                let min = spec.voxel_min_corner(e.level, e.pos(), v.pos());
                faces += faces_seen(shot.eye, min, edge, v.mask(), self.two_sided) as u64;
                let mut w = *v;
                if let Some(m) = &materials {
                    w.color = u32::from_le_bytes(material_color(m[j]));
                }
                words.push(w);
            }
            voxels += buf.len() as u64;
            ranges.push((
                start..words.len() as u32,
                NodeConstants::of(reader, i, centre),
            ));
        }
        let voxel_bytes = std::mem::size_of_val(words.as_slice()) as u64;
        if voxel_bytes > self.gpu.device.limits().max_buffer_size {
            return Err(RenderError::Option(format!(
                "{} voxels ({voxel_bytes} bytes) exceed the adapter's largest buffer; draw a coarser level or a larger --error",
                words.len()
            )));
        }
        use wgpu::util::DeviceExt;
        let vbuf = (!words.is_empty()).then(|| {
            self.gpu
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("voxels"),
                    contents: bytemuck::cast_slice(&words),
                    usage: wgpu::BufferUsages::VERTEX,
                })
        });
        let batches: Vec<Batch> = vbuf
            .iter()
            .flat_map(|b| {
                ranges
                    .iter()
                    .filter(|(r, _)| !r.is_empty())
                    .map(move |(r, node)| Batch {
                        buffer: b,
                        voxels: r.clone(),
                        node: *node,
                        probe: false,
                        query: false,
                    })
            })
            .collect();
        let tri_bufs = (!tris.indices.is_empty()).then(|| {
            let init = |label, contents, usage| {
                self.gpu
                    .device
                    .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some(label),
                        contents,
                        usage,
                    })
            };
            (
                init(
                    "source vertices",
                    bytemuck::cast_slice(&tris.vertices),
                    wgpu::BufferUsages::VERTEX,
                ),
                init(
                    "source indices",
                    bytemuck::cast_slice(&tris.indices),
                    wgpu::BufferUsages::INDEX,
                ),
            )
        });
        let source_batches: Vec<SourceBatch> = tri_bufs
            .iter()
            .map(|(v, i)| (v.slice(..), i.slice(..), tris.indices.len() as u32))
            .collect();
        let drawn = self.draw(shot, centre, &batches, &source_batches)?;
        Ok(Picture {
            width: drawn.width,
            height: drawn.height,
            rgba: drawn.rgba,
            shot: *shot,
            nodes: nodes.to_vec(),
            voxels,
            faces_drawn: faces,
            source_leaves: tris.leaves.len() as u64,
            source_triangles: tris.triangles,
        })
    }

    /// The device and adapter.
    #[cfg(feature = "window")]
    pub(crate) fn gpu(&self) -> &voxlod_gpu::Gpu {
        &self.gpu
    }

    /// The device (for the viewer's face buffers).
    pub(crate) fn device(&self) -> &wgpu::Device {
        &self.gpu.device
    }

    /// The queue (for the viewer's uploads).
    pub(crate) fn queue(&self) -> &wgpu::Queue {
        &self.gpu.queue
    }

    /// Draws `sources`, batches of source triangles, then `batches` of voxels in their order
    /// (positions relative to `origin`) as seen by `shot` into an offscreen picture and reads
    /// it back, with the results of the batches' occlusion queries.
    pub(crate) fn draw(
        &self,
        shot: &Shot,
        origin: DVec3,
        batches: &[Batch],
        sources: &[SourceBatch],
    ) -> Result<Drawing, RenderError> {
        let (w, h) = (shot.width, shot.height);
        let max_dim = self.gpu.device.limits().max_texture_dimension_2d;
        if w > max_dim || h > max_dim {
            return Err(RenderError::Option(format!(
                "image {w}x{h} exceeds the adapter's {max_dim} pixels per side"
            )));
        }
        let (_uniforms, bind) = self.uniforms(shot, origin);
        let (_nodes, node_bind) = self.node_constants(batches);
        // one occlusion query per batch that asks for one, up to the query set's size
        let mut query_of = vec![None; batches.len()];
        let mut queries = 0u32;
        for (k, b) in batches.iter().enumerate() {
            if b.query && queries < MAX_QUERIES {
                query_of[k] = Some(queries);
                queries += 1;
            }
        }
        let query_set = (queries > 0).then(|| {
            self.gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("occlusion"),
                ty: wgpu::QueryType::Occlusion,
                count: queries,
            })
        });
        let targets = Targets::new(&self.gpu.device, w, h);
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        self.encode_pass(
            &mut enc,
            &targets,
            (&bind, node_bind.as_ref()),
            batches,
            sources,
            query_set.as_ref().map(|q| (q, query_of.as_slice())),
        );
        let resolve = query_set.as_ref().map(|q| {
            let buf = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("occlusion results"),
                size: 8 * queries as u64,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            enc.resolve_query_set(q, 0..queries, &buf, 0);
            buf
        });
        let (rgba, samples) = self.read_back(enc, &targets, w, h, resolve.as_ref())?;
        let passed = query_of
            .iter()
            .map(|q| q.map(|q| samples[q as usize] > 0))
            .collect();
        Ok(Drawing {
            width: w,
            height: h,
            rgba,
            passed,
        })
    }

    /// The per-draw uniform buffer of the batches' node constants ([`NODE_STRIDE`] apart, the
    /// flags set from the renderer's settings) and its bind group; none without batches.
    fn node_constants(&self, batches: &[Batch]) -> (Option<wgpu::Buffer>, Option<wgpu::BindGroup>) {
        if batches.is_empty() {
            return (None, None);
        }
        let mut data = vec![0u8; batches.len() * NODE_STRIDE as usize];
        for (k, b) in batches.iter().enumerate() {
            let mut node = b.node;
            node.flags[0] = if self.two_sided { FLAG_TWO_SIDED } else { 0 };
            let at = k * NODE_STRIDE as usize;
            data[at..at + std::mem::size_of::<NodeConstants>()]
                .copy_from_slice(bytemuck::bytes_of(&node));
        }
        use wgpu::util::DeviceExt;
        let buf = self
            .gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("node constants"),
                contents: &data,
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let bind = self
            .gpu
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &self.node_layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &buf,
                        offset: 0,
                        size: wgpu::BufferSize::new(std::mem::size_of::<NodeConstants>() as u64),
                    }),
                }],
            });
        (Some(buf), Some(bind))
    }

    /// The uniform buffer of `shot` (positions relative to `origin`) and its bind group:
    /// view_proj, the light (vec4), the eye relative to the origin (vec4).
    fn uniforms(&self, shot: &Shot, origin: DVec3) -> (wgpu::Buffer, wgpu::BindGroup) {
        let view_proj = shot.view_proj(origin).as_mat4();
        // light from the upper left behind the eye, fixed relative to the camera
        let fwd = (shot.target - shot.eye).normalize();
        let right = fwd.cross(shot.up).normalize();
        let light = (-fwd * 0.8 + shot.up * 0.7 - right * 0.45)
            .normalize()
            .as_vec3();
        let mut uniforms = [0f32; 24];
        uniforms[..16].copy_from_slice(&view_proj.to_cols_array());
        uniforms[16..19].copy_from_slice(&light.to_array());
        uniforms[20..23].copy_from_slice(&(shot.eye - origin).as_vec3().to_array());

        use wgpu::util::DeviceExt;
        let ubuf = self
            .gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("uniforms"),
                contents: bytemuck::cast_slice(&uniforms),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let bind = self
            .gpu
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &self.layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: ubuf.as_entire_binding(),
                }],
            });
        (ubuf, bind)
    }

    /// The render pass into `targets`: cleared to [`BACKGROUND`] (alpha 0) and depth 1, the
    /// source triangles of `sources`, then the voxels of `batches` in their order (probes with
    /// the probe pipeline), each batch with a query index in `queries` inside that occlusion
    /// query.
    fn encode_pass(
        &self,
        enc: &mut wgpu::CommandEncoder,
        targets: &Targets,
        (bind, node_bind): (&wgpu::BindGroup, Option<&wgpu::BindGroup>),
        batches: &[Batch],
        sources: &[SourceBatch],
        queries: Option<(&wgpu::QuerySet, &[Option<u32>])>,
    ) {
        let bg = BACKGROUND.map(|c| c as f64 / 255.0);
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("voxels"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &targets.msaa_view,
                depth_slice: None,
                resolve_target: Some(&targets.resolved_view),
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color {
                        r: bg[0],
                        g: bg[1],
                        b: bg[2],
                        a: 0.0,
                    }),
                    store: wgpu::StoreOp::Discard,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &targets.depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            occlusion_query_set: queries.map(|(q, _)| q),
            ..Default::default()
        });
        if !sources.is_empty() {
            pass.set_pipeline(&self.source_pipeline);
            pass.set_bind_group(0, bind, &[]);
        }
        for (vertices, indices, count) in sources {
            pass.set_vertex_buffer(0, *vertices);
            pass.set_index_buffer(*indices, wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..*count, 0, 0..1);
        }
        let Some(node_bind) = node_bind else { return };
        let mut probing = None;
        for (k, b) in batches.iter().enumerate() {
            if probing != Some(b.probe) {
                pass.set_pipeline(if b.probe {
                    &self.probe_pipeline
                } else {
                    &self.pipeline
                });
                pass.set_bind_group(0, bind, &[]);
                probing = Some(b.probe);
            }
            pass.set_bind_group(1, node_bind, &[(k as u64 * NODE_STRIDE) as u32]);
            pass.set_vertex_buffer(0, b.buffer.slice(..));
            let query = queries.and_then(|(_, q)| q[k]);
            if let Some(q) = query {
                pass.begin_occlusion_query(q);
            }
            pass.draw(0..VERTICES_PER_VOXEL, b.voxels.clone());
            if query.is_some() {
                pass.end_occlusion_query();
            }
        }
    }

    /// Copies the resolved picture of `targets` (`w`×`h`) into a mapped buffer after the
    /// commands of `enc`, and after it the resolved occlusion query results of `queries`,
    /// submits them, waits, and returns the RGBA rows without the row padding the copy needs
    /// and the queries' sample counts.
    fn read_back(
        &self,
        mut enc: wgpu::CommandEncoder,
        targets: &Targets,
        w: u32,
        h: u32,
        queries: Option<&wgpu::Buffer>,
    ) -> Result<(Vec<u8>, Vec<u64>), RenderError> {
        let row = (4 * w).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let picture = row as u64 * h as u64;
        let query_bytes = queries.map_or(0, |q| q.size());
        let staging = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: picture + query_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        enc.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &targets.resolved,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(h),
                },
            },
            targets.size,
        );
        if let Some(q) = queries {
            // the picture's rows are 256-byte multiples: the results start 8-byte aligned
            enc.copy_buffer_to_buffer(q, 0, &staging, picture, query_bytes);
        }
        self.gpu.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        let gpu = |reason: String| RenderError::Gpu {
            adapter: self.adapter.clone(),
            reason,
        };
        self.gpu
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| gpu(e.to_string()))?;
        self.check()?;
        rx.recv()
            .map_err(|e| gpu(e.to_string()))?
            .map_err(|e| gpu(e.to_string()))?;
        let mut rgba = Vec::with_capacity(4 * w as usize * h as usize);
        let samples;
        {
            let view = staging
                .get_mapped_range(..)
                .map_err(|e| gpu(e.to_string()))?;
            for y in 0..h as usize {
                let start = y * row as usize;
                rgba.extend_from_slice(&view[start..start + 4 * w as usize]);
            }
            samples = view[picture as usize..]
                .chunks_exact(8)
                .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
                .collect();
        }
        staging.unmap();
        Ok((rgba, samples))
    }
}

/// What [`Renderer::draw`] returns: the picture and, per batch, whether its occlusion query
/// passed a sample (none for a batch drawn without one).
pub(crate) struct Drawing {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
    pub passed: Vec<Option<bool>>,
}
