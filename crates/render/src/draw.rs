//! Headless GPU rendering on wgpu (lavapipe on machines without a GPU): the selected nodes'
//! active voxel faces as instances of a 6-vertex quad, depth-tested, 4× multisampled, drawn
//! into an offscreen texture and read back. Only faces turned towards the eye are uploaded
//! (back faces can never be seen), which halves the buffer.

use std::sync::{Arc, Mutex};

use glam::DVec3;
use voxlod_format::Reader;

use crate::camera::Shot;
use crate::faces::{face_direction, node_faces_by, ColorBy};
use crate::picture::Picture;
use crate::RenderError;

const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
const SAMPLES: u32 = 4;
/// Background of the picture (light grey); covered pixels have alpha 255, the rest 0.
pub const BACKGROUND: [u8; 3] = [236, 238, 242];

/// One face instance as the vertex shader reads it (28 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct FaceInstance {
    min_corner: [f32; 3],
    edge: f32,
    dir: u32,
    normal: u32,
    color: u32,
}

/// A GPU device with the voxel-face pipeline, reusable for many pictures.
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    adapter: String,
    error: Arc<Mutex<Option<String>>>,
}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer")
            .field("adapter", &self.adapter)
            .finish_non_exhaustive()
    }
}

fn request_adapter(backends: Option<wgpu::Backends>) -> Result<wgpu::Adapter, String> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if let Some(b) = backends {
        desc.backends = b;
    }
    let instance = wgpu::Instance::new(desc);
    pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: None,
        ..Default::default()
    }))
    .map_err(|e| e.to_string())
}

impl Renderer {
    /// Finds an adapter (Vulkan first, then GL; `WGPU_BACKEND` overrides) and builds the
    /// pipeline.
    pub fn new() -> Result<Renderer, RenderError> {
        let adapter = if std::env::var_os("WGPU_BACKEND").is_some() {
            request_adapter(None).map_err(RenderError::NoAdapter)?
        } else {
            match request_adapter(Some(wgpu::Backends::VULKAN)) {
                Ok(a) => a,
                Err(vk) => request_adapter(Some(wgpu::Backends::GL))
                    .map_err(|gl| RenderError::NoAdapter(format!("Vulkan: {vk}; GL: {gl}")))?,
            }
        };
        let info = adapter.get_info();
        let name = format!("{} ({:?})", info.name, info.backend);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("voxlod-render"),
            required_features: wgpu::Features::empty(),
            required_limits: adapter.limits(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| RenderError::Gpu {
            adapter: name.clone(),
            reason: e.to_string(),
        })?;
        let error = Arc::new(Mutex::new(None::<String>));
        let sink = error.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut slot) = sink.lock() {
                slot.get_or_insert_with(|| e.to_string());
            }
        }));
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
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("voxel faces"),
            layout: Some(&pl),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<FaceInstance>() as u64,
                    step_mode: wgpu::VertexStepMode::Instance,
                    attributes: &attributes,
                })],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                front_face: wgpu::FrontFace::Ccw,
                cull_mode: Some(wgpu::Face::Back),
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: wgpu::MultisampleState {
                count: SAMPLES,
                ..Default::default()
            },
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: COLOR_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let r = Renderer {
            device,
            queue,
            pipeline,
            layout,
            adapter: name,
            error,
        };
        r.check()?;
        Ok(r)
    }

    /// The adapter's name and backend, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)".
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    fn check(&self) -> Result<(), RenderError> {
        match self.error.lock().ok().and_then(|mut s| s.take()) {
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
        let centre = shot.target;
        let mut faces: Vec<FaceInstance> = Vec::new();
        let mut buf = Vec::new();
        let mut voxels = 0u64;
        for &i in nodes {
            node_faces_by(reader, i, &mut buf, color, &mut |f| {
                // a face is seen only from its outer side: (eye − point on its plane)·d > 0
                let d = face_direction(f.dir);
                let a = (f.dir >> 1) as usize;
                let plane = f.min[a] + if f.dir & 1 == 0 { f.edge } else { 0.0 };
                let side = (shot.eye[a] - plane) * d[a] as f64;
                if side <= 0.0 {
                    return;
                }
                let rel = DVec3::from(f.min) - centre;
                faces.push(FaceInstance {
                    min_corner: rel.as_vec3().into(),
                    edge: f.edge as f32,
                    dir: f.dir as u32,
                    normal: f.normal,
                    color: u32::from_le_bytes(f.rgba),
                });
            })?;
            voxels += buf.len() as u64;
        }
        let (w, h) = (shot.width, shot.height);
        let max_dim = self.device.limits().max_texture_dimension_2d;
        if w > max_dim || h > max_dim {
            return Err(RenderError::Option(format!(
                "image {w}x{h} exceeds the adapter's {max_dim} pixels per side"
            )));
        }
        let face_bytes = std::mem::size_of_val(faces.as_slice()) as u64;
        if face_bytes > self.device.limits().max_buffer_size {
            return Err(RenderError::Option(format!(
                "{} faces ({face_bytes} bytes) exceed the adapter's largest buffer; draw a coarser level or a larger --error",
                faces.len()
            )));
        }

        let view_proj = shot.view_proj(centre).as_mat4();
        // light from the upper left behind the eye, fixed relative to the camera
        let fwd = (shot.target - shot.eye).normalize();
        let right = fwd.cross(shot.up).normalize();
        let light = (-fwd * 0.8 + shot.up * 0.7 - right * 0.45)
            .normalize()
            .as_vec3();
        let mut uniforms = [0f32; 20];
        uniforms[..16].copy_from_slice(&view_proj.to_cols_array());
        uniforms[16..19].copy_from_slice(&light.to_array());

        use wgpu::util::DeviceExt;
        let ubuf = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("uniforms"),
                contents: bytemuck::cast_slice(&uniforms),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let bind = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: ubuf.as_entire_binding(),
            }],
        });
        let vbuf = (!faces.is_empty()).then(|| {
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("faces"),
                    contents: bytemuck::cast_slice(&faces),
                    usage: wgpu::BufferUsages::VERTEX,
                })
        });
        let size = wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        };
        let texture = |format, samples, usage| {
            self.device.create_texture(&wgpu::TextureDescriptor {
                label: None,
                size,
                mip_level_count: 1,
                sample_count: samples,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let msaa = texture(
            COLOR_FORMAT,
            SAMPLES,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let resolved = texture(
            COLOR_FORMAT,
            1,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let depth = texture(
            DEPTH_FORMAT,
            SAMPLES,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let (msaa_view, resolved_view, depth_view) = (
            msaa.create_view(&Default::default()),
            resolved.create_view(&Default::default()),
            depth.create_view(&Default::default()),
        );
        let bg = BACKGROUND.map(|c| c as f64 / 255.0);
        let mut enc = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("voxel faces"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &msaa_view,
                    depth_slice: None,
                    resolve_target: Some(&resolved_view),
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
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            if let Some(vbuf) = &vbuf {
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.set_vertex_buffer(0, vbuf.slice(..));
                pass.draw(0..6, 0..faces.len() as u32);
            }
        }
        let row = (4 * w).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: row as u64 * h as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        enc.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &resolved,
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
            size,
        );
        self.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        let gpu = |reason: String| RenderError::Gpu {
            adapter: self.adapter.clone(),
            reason,
        };
        self.device
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
        Ok(Picture {
            width: w,
            height: h,
            rgba,
            shot: *shot,
            nodes: nodes.to_vec(),
            voxels,
            faces_drawn: faces.len() as u64,
        })
    }
}
