//! Headless GPU rendering on wgpu (lavapipe on machines without a GPU): the selected nodes'
//! active voxel faces as instances of a 6-vertex quad, depth-tested, 4× multisampled, drawn
//! into an offscreen texture and read back. Only faces turned towards the eye are uploaded
//! (back faces can never be seen), which halves the buffer. The device comes from
//! `voxlod_gpu::open_device` (the workspace's one device setup); the streaming viewer
//! (`crate::view`) draws its cached per-node face buffers with the same pipeline through
//! [`Renderer::draw`].

use std::ops::Range;

use glam::DVec3;
use voxlod_format::Reader;

use crate::camera::Shot;
use crate::faces::{face_direction, node_faces_by, ColorBy};
use crate::pass::{pass_pipeline, Targets};
use crate::picture::Picture;
use crate::source_draw;
use crate::RenderError;

/// Background of the picture (light grey); covered pixels have alpha 255, the rest 0.
pub const BACKGROUND: [u8; 3] = [236, 238, 242];

/// One face instance as the vertex shader reads it (28 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct FaceInstance {
    pub min_corner: [f32; 3],
    pub edge: f32,
    pub dir: u32,
    pub normal: u32,
    pub color: u32,
}

impl FaceInstance {
    /// The instance of a voxel face, its corner relative to `origin` (f32 keeps the precision
    /// near the camera's subject, not near the world's origin).
    pub(crate) fn of(f: &crate::faces::Face, origin: DVec3) -> Self {
        let rel = DVec3::from(f.min) - origin;
        FaceInstance {
            min_corner: rel.as_vec3().into(),
            edge: f.edge as f32,
            dir: f.dir as u32,
            normal: f.normal,
            color: u32::from_le_bytes(f.rgba),
        }
    }
}

/// Bytes of one [`FaceInstance`] in a vertex buffer.
pub(crate) const FACE_BYTES: u64 = std::mem::size_of::<FaceInstance>() as u64;

/// Instances `range` of a vertex buffer of [`FaceInstance`]s, to be drawn.
pub(crate) type Batch<'a> = (&'a wgpu::Buffer, Range<u32>);

/// Source triangles to draw: vertices (`SourceVertex`), `u32` indices and the number of
/// indices.
pub(crate) type SourceBatch<'a> = (wgpu::BufferSlice<'a>, wgpu::BufferSlice<'a>, u32);

/// A GPU device with the voxel-face pipeline, reusable for many pictures.
pub struct Renderer {
    gpu: voxlod_gpu::Gpu,
    pipeline: wgpu::RenderPipeline,
    source_pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    adapter: String,
}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer")
            .field("adapter", &self.adapter)
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
            label: Some("voxel faces"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shader.wgsl").into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("uniforms"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: None,
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![
            0 => Float32x3, 1 => Float32, 2 => Uint32, 3 => Uint32, 4 => Uint32
        ];
        let pipeline = pass_pipeline(
            device,
            "voxel faces",
            &pl,
            &module,
            wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<FaceInstance>() as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &attributes,
            },
            wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                front_face: wgpu::FrontFace::Ccw,
                cull_mode: Some(wgpu::Face::Back),
                ..Default::default()
            },
        );
        let source_pipeline = source_draw::pipeline(device, &pl);
        let r = Renderer {
            gpu,
            pipeline,
            source_pipeline,
            layout,
            adapter: name,
        };
        r.check()?;
        Ok(r)
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
        let mut faces: Vec<FaceInstance> = Vec::new();
        let mut buf = Vec::new();
        let mut voxels = 0u64;
        for &i in nodes {
            if tris.leaves.binary_search(&i).is_ok() {
                continue;
            }
            node_faces_by(reader, i, &mut buf, color, &mut |f| {
                // a face is seen only from its outer side: (eye − point on its plane)·d > 0
                let d = face_direction(f.dir);
                let a = (f.dir >> 1) as usize;
                let plane = f.min[a] + if f.dir & 1 == 0 { f.edge } else { 0.0 };
                let side = (shot.eye[a] - plane) * d[a] as f64;
                if side <= 0.0 {
                    return;
                }
                faces.push(FaceInstance::of(&f, centre));
            })?;
            voxels += buf.len() as u64;
        }
        let face_bytes = std::mem::size_of_val(faces.as_slice()) as u64;
        if face_bytes > self.gpu.device.limits().max_buffer_size {
            return Err(RenderError::Option(format!(
                "{} faces ({face_bytes} bytes) exceed the adapter's largest buffer; draw a coarser level or a larger --error",
                faces.len()
            )));
        }
        use wgpu::util::DeviceExt;
        let vbuf = (!faces.is_empty()).then(|| {
            self.gpu
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("faces"),
                    contents: bytemuck::cast_slice(&faces),
                    usage: wgpu::BufferUsages::VERTEX,
                })
        });
        let batches: Vec<Batch> = vbuf.iter().map(|b| (b, 0..faces.len() as u32)).collect();
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
        let (w, h, rgba) = self.draw(shot, centre, &batches, &source_batches)?;
        Ok(Picture {
            width: w,
            height: h,
            rgba,
            shot: *shot,
            nodes: nodes.to_vec(),
            voxels,
            faces_drawn: faces.len() as u64,
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

    /// Draws `batches` of face instances (corners relative to `origin`) and `sources`, batches
    /// of source triangles (positions relative to `origin` too), as seen by `shot` into an
    /// offscreen picture and reads it back: width, height and RGBA rows.
    pub(crate) fn draw(
        &self,
        shot: &Shot,
        origin: DVec3,
        batches: &[Batch],
        sources: &[SourceBatch],
    ) -> Result<(u32, u32, Vec<u8>), RenderError> {
        let (w, h) = (shot.width, shot.height);
        let max_dim = self.gpu.device.limits().max_texture_dimension_2d;
        if w > max_dim || h > max_dim {
            return Err(RenderError::Option(format!(
                "image {w}x{h} exceeds the adapter's {max_dim} pixels per side"
            )));
        }
        let (_uniforms, bind) = self.uniforms(shot, origin);
        let targets = Targets::new(&self.gpu.device, w, h);
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        self.encode_pass(&mut enc, &targets, &bind, batches, sources);
        let rgba = self.read_back(enc, &targets, w, h)?;
        Ok((w, h, rgba))
    }

    /// The uniform buffer of `shot` (positions relative to `origin`) and its bind group:
    /// view_proj, the light (vec4), the eye relative to the origin (vec4; read by
    /// source.wgsl).
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
    /// face instances of `batches`, then the source triangles of `sources`.
    fn encode_pass(
        &self,
        enc: &mut wgpu::CommandEncoder,
        targets: &Targets,
        bind: &wgpu::BindGroup,
        batches: &[Batch],
        sources: &[SourceBatch],
    ) {
        let bg = BACKGROUND.map(|c| c as f64 / 255.0);
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("voxel faces"),
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
            ..Default::default()
        });
        if !batches.is_empty() {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, bind, &[]);
        }
        for (vbuf, range) in batches {
            pass.set_vertex_buffer(0, vbuf.slice(..));
            pass.draw(0..6, range.clone());
        }
        if !sources.is_empty() {
            pass.set_pipeline(&self.source_pipeline);
            pass.set_bind_group(0, bind, &[]);
        }
        for (vertices, indices, count) in sources {
            pass.set_vertex_buffer(0, *vertices);
            pass.set_index_buffer(*indices, wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..*count, 0, 0..1);
        }
    }

    /// Copies the resolved picture of `targets` (`w`×`h`) into a mapped buffer after the
    /// commands of `enc`, submits them, waits, and returns its RGBA rows without the row
    /// padding the copy needs.
    fn read_back(
        &self,
        mut enc: wgpu::CommandEncoder,
        targets: &Targets,
        w: u32,
        h: u32,
    ) -> Result<Vec<u8>, RenderError> {
        let row = (4 * w).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let staging = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: row as u64 * h as u64,
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
        {
            let view = staging
                .get_mapped_range(..)
                .map_err(|e| gpu(e.to_string()))?;
            for y in 0..h as usize {
                let start = y * row as usize;
                rgba.extend_from_slice(&view[start..start + 4 * w as usize]);
            }
        }
        staging.unmap();
        Ok(rgba)
    }
}
