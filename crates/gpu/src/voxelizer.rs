//! The GPU hybrid voxelizer (Rauwendaal & Bailey, "Hybrid Computational Voxelization Using the
//! Graphics Pipeline", JCGT 2(1) 2013, sections 3.2-3.6): buffers, pipelines and the per-chunk
//! sequence of passes. The shaders are in `shaders/` (see [`crate::shaders`]).

use bytemuck::{Pod, Zeroable};
use voxlod_format::Voxel;
use voxlod_geom::{Triangle, CHUNK};
use voxlod_voxelize::Mode;

use crate::device::{open, Gpu};
use crate::encode::{decode, SLOT_BYTES};
use crate::shaders::{classify_source, raster_source, Precision};
use crate::{GpuError, GpuMethod};

/// Occupancy bitset of a chunk: 256³ bits.
const OCC_WORDS: u64 = (CHUNK as u64).pow(3) / 32;
const OCC_BYTES: u64 = OCC_WORDS * 4;
/// Triangles per batch (88 bytes each: under 6 MiB). The sweep pass dispatches one workgroup
/// per deferred triangle, and a dispatch dimension is at most 65535.
const BATCH: usize = 65535;
/// Bytes of one deferred triangle record.
const DEFERRED_BYTES: u64 = 48;
/// Most voxel slots accumulated per pass (96 MiB of accumulators, under the 128 MiB binding limit).
const MAX_WINDOW: u64 = 1 << 19;
const WG: u32 = 64;

/// `Params` of voxelize.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Params {
    origin: [i32; 3],
    mode: u32,
    tri_count: u32,
    cutoff: f32,
    phase: u32,
    slot_lo: u32,
    slot_hi: u32,
    groups_x: u32,
    pad: [u32; 2],
}

const PHASE_MARK: u32 = 0;
const PHASE_ACCUMULATE: u32 = 1;

/// Reusable GPU voxelizer of 256³ chunks; see the crate docs.
pub struct GpuVoxelizer {
    gpu: Gpu,
    mode: Mode,
    method: GpuMethod,
    cutoff: f32,
    precision: Precision,
    classify: wgpu::ComputePipeline,
    compact: wgpu::ComputePipeline,
    sweep: wgpu::ComputePipeline,
    raster: wgpu::RenderPipeline,
    bgl_compute: wgpu::BindGroupLayout,
    bgl_raster: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    tris: wgpu::Buffer,
    occ: wgpu::Buffer,
    deferred: wgpu::Buffer,
    args: wgpu::Buffer,
    base: wgpu::Buffer,
    accum: wgpu::Buffer,
    counter: wgpu::Buffer,
    staging: wgpu::Buffer,
    target: wgpu::TextureView,
    /// stands in for `args` in the sweep pass's bind group (a buffer cannot be bound as storage
    /// in the dispatch that reads it as indirect arguments)
    args_dummy: wgpu::Buffer,
    bind: Option<(wgpu::BindGroup, wgpu::BindGroup, wgpu::BindGroup)>,
    split: (u64, u64),
}

fn storage_entry(
    binding: u32,
    vis: wgpu::ShaderStages,
    read_only: bool,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: vis,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn uniform_entry(binding: u32, vis: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: vis,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

impl GpuVoxelizer {
    /// Opens an adapter (Vulkan, else GL; `WGPU_BACKEND` overrides) and builds the pipelines.
    /// `cutoff` is the dominant projected area (voxels²) from which [`GpuMethod::Hybrid`] defers
    /// a triangle to the fragment pass; the other methods ignore it.
    pub fn new(mode: Mode, method: GpuMethod, cutoff: f32) -> Result<GpuVoxelizer, GpuError> {
        let gpu = open()?;
        let precision = if gpu.f64 {
            Precision::F64
        } else {
            Precision::F32
        };
        let d = &gpu.device;
        let cs = wgpu::ShaderStages::COMPUTE;
        let fs = wgpu::ShaderStages::FRAGMENT;
        let vfs = wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT;
        let bgl_compute = d.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("voxlod compute"),
            entries: &[
                uniform_entry(0, cs),
                storage_entry(1, cs, true),
                storage_entry(2, cs, false),
                storage_entry(3, cs, false),
                storage_entry(4, cs, false),
                storage_entry(5, cs, false),
                storage_entry(6, cs, false),
                storage_entry(7, cs, false),
            ],
        });
        let bgl_raster = d.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("voxlod raster"),
            entries: &[
                uniform_entry(0, vfs),
                storage_entry(1, fs, true),
                storage_entry(2, fs, false),
                storage_entry(3, vfs, true),
                storage_entry(5, fs, true),
                storage_entry(6, fs, false),
            ],
        });
        let layout = |bgl: &wgpu::BindGroupLayout| {
            d.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: None,
                bind_group_layouts: &[Some(bgl)],
                immediate_size: 0,
            })
        };
        let compute_layout = layout(&bgl_compute);
        let raster_layout = layout(&bgl_raster);
        let cmod = d.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("classify.wgsl"),
            source: wgpu::ShaderSource::Wgsl(classify_source(precision).into()),
        });
        let rmod = d.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raster.wgsl"),
            source: wgpu::ShaderSource::Wgsl(raster_source(precision).into()),
        });
        let compute = |entry: &str| {
            d.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&compute_layout),
                module: &cmod,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let classify = compute("classify");
        let compact = compute("compact");
        let sweep = compute("sweep");
        let raster = d.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("fragment pass"),
            layout: Some(&raster_layout),
            vertex: wgpu::VertexState {
                module: &rmod,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &rmod,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: wgpu::TextureFormat::R8Unorm,
                    blend: None,
                    write_mask: wgpu::ColorWrites::empty(),
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        // wgpu wants an attachment; the viewport is clipped to it, so it covers the chunk
        let target = d
            .create_texture(&wgpu::TextureDescriptor {
                label: Some("dummy target"),
                size: wgpu::Extent3d {
                    width: CHUNK,
                    height: CHUNK,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::R8Unorm,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                view_formats: &[],
            })
            .create_view(&Default::default());
        use wgpu::BufferUsages as U;
        let buf = |label: &str, size: u64, usage: U| {
            d.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let params = buf(
            "params",
            std::mem::size_of::<Params>() as u64,
            U::UNIFORM | U::COPY_DST,
        );
        let tris = buf("triangles", 88 * 1024, U::STORAGE | U::COPY_DST);
        let occ = buf(
            "occupancy",
            OCC_BYTES,
            U::STORAGE | U::COPY_SRC | U::COPY_DST,
        );
        let deferred = buf("deferred", DEFERRED_BYTES * 1024, U::STORAGE);
        let args = buf("indirect args", 32, U::STORAGE | U::INDIRECT | U::COPY_DST);
        let base = buf("slot base", OCC_BYTES, U::STORAGE | U::COPY_SRC);
        let accum = buf(
            "accumulators",
            SLOT_BYTES * 1024,
            U::STORAGE | U::COPY_SRC | U::COPY_DST,
        );
        let args_dummy = buf("indirect args (sweep stand-in)", 32, U::STORAGE);
        let counter = buf("counter", 16, U::STORAGE | U::COPY_SRC | U::COPY_DST);
        let staging = buf("staging", 2 * OCC_BYTES, U::MAP_READ | U::COPY_DST);
        gpu.check()?;
        Ok(GpuVoxelizer {
            gpu,
            mode,
            method,
            cutoff,
            precision,
            classify,
            compact,
            sweep,
            raster,
            bgl_compute,
            bgl_raster,
            params,
            tris,
            occ,
            deferred,
            args,
            base,
            accum,
            counter,
            staging,
            target,
            args_dummy,
            bind: None,
            split: (0, 0),
        })
    }

    /// The adapter's name, backend and driver, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Mesa 22.3.6)".
    pub fn adapter_name(&self) -> String {
        self.gpu.name.clone()
    }

    /// True when the adapter is a software rasterizer running on the CPU (lavapipe,
    /// llvmpipe): correct, but slower than the CPU backend.
    pub fn is_software(&self) -> bool {
        self.gpu.software
    }

    /// Whether the shaders compute in f64 (bit-compatible with the CPU) or f32.
    pub fn precision(&self) -> Precision {
        self.precision
    }

    /// The voxelization mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The scheme.
    pub fn method(&self) -> GpuMethod {
        self.method
    }

    /// Switches the scheme and cutoff (the pipelines are shared; nothing is rebuilt).
    pub fn set_method(&mut self, method: GpuMethod, cutoff: f32) {
        self.method = method;
        self.cutoff = cutoff;
    }

    /// Switches the voxelization mode (a uniform of the shaders; nothing is rebuilt).
    pub fn set_mode(&mut self, mode: Mode) {
        self.mode = mode;
    }

    /// Last call's split: triangles voxelized in the classification pass vs deferred to the
    /// fragment pass (to the sweep pass for [`GpuMethod::Triangle`]); zero-area triangles and
    /// triangles missing the chunk are in neither.
    pub fn last_split(&self) -> (u64, u64) {
        self.split
    }

    /// Grows `buf` to at least `size` bytes (new buffers are zeroed by wgpu, which is slow on a
    /// CPU device, hence reuse with geometric growth).
    fn ensure(&mut self, which: Which, size: u64) {
        let (b, usage, label) = match which {
            Which::Tris => (
                &mut self.tris,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                "triangles",
            ),
            Which::Deferred => (&mut self.deferred, wgpu::BufferUsages::STORAGE, "deferred"),
            Which::Accum => (
                &mut self.accum,
                wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                "accumulators",
            ),
            Which::Staging => (
                &mut self.staging,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                "staging",
            ),
        };
        if b.size() >= size {
            return;
        }
        let size = size.max(b.size() * 2).next_multiple_of(256);
        *b = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false,
        });
        self.bind = None;
    }

    /// (compute, raster, sweep) bind groups.
    fn bind_groups(&mut self) -> (wgpu::BindGroup, wgpu::BindGroup, wgpu::BindGroup) {
        if let Some(b) = &self.bind {
            return b.clone();
        }
        let d = &self.gpu.device;
        fn e(binding: u32, b: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            }
        }
        let compute_group = |args: &wgpu::Buffer| {
            d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("compute"),
                layout: &self.bgl_compute,
                entries: &[
                    e(0, &self.params),
                    e(1, &self.tris),
                    e(2, &self.occ),
                    e(3, &self.deferred),
                    e(4, args),
                    e(5, &self.base),
                    e(6, &self.accum),
                    e(7, &self.counter),
                ],
            })
        };
        let compute = compute_group(&self.args);
        let sweep = compute_group(&self.args_dummy);
        let raster = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("raster"),
            layout: &self.bgl_raster,
            entries: &[
                e(0, &self.params),
                e(1, &self.tris),
                e(2, &self.occ),
                e(3, &self.deferred),
                e(5, &self.base),
                e(6, &self.accum),
            ],
        });
        self.bind = Some((compute.clone(), raster.clone(), sweep.clone()));
        (compute, raster, sweep)
    }

    /// Voxelizes the triangles (grid coordinates) of the chunk whose minimum voxel corner is
    /// `origin` (multiples of 256): the same voxels, normals, colours and face masks as
    /// `voxlod_voxelize::ChunkVoxelizer`, sorted by the Morton code of their in-chunk position.
    /// Triangles with a non-finite coordinate or zero area are skipped.
    pub fn voxelize_chunk(
        &mut self,
        origin: [u32; 3],
        tris: &[Triangle],
    ) -> Result<Vec<Voxel>, GpuError> {
        if origin
            .iter()
            .any(|&c| c % CHUNK != 0 || c > i32::MAX as u32 - CHUNK)
        {
            return Err(GpuError::Origin(origin));
        }
        self.split = (0, 0);
        let finite: Vec<Triangle>;
        let tris = if tris.iter().all(|t| t.is_finite()) {
            tris
        } else {
            finite = tris.iter().filter(|t| t.is_finite()).copied().collect();
            &finite
        };
        if tris.is_empty() {
            return Ok(Vec::new());
        }
        let batch_len = tris.len().min(BATCH);
        self.ensure(
            Which::Tris,
            (batch_len * std::mem::size_of::<Triangle>()) as u64,
        );
        self.ensure(Which::Deferred, batch_len as u64 * DEFERRED_BYTES);
        let origin_i = origin.map(|c| c as i32);
        let batches: Vec<&[Triangle]> = tris.chunks(BATCH).collect();

        // pass 1: mark the occupancy bitset
        {
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            enc.clear_buffer(&self.occ, 0, None);
            enc.clear_buffer(&self.counter, 0, None);
            self.gpu.queue.submit([enc.finish()]);
        }
        for b in &batches {
            self.run_batch(b, origin_i, PHASE_MARK, (0, 0), true)?;
        }
        // compaction: a slot per occupied voxel
        let (count, small, large) = {
            let (compute, _, _) = self.bind_groups();
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                pass.set_pipeline(&self.compact);
                pass.set_bind_group(0, &compute, &[]);
                pass.dispatch_workgroups((OCC_WORDS / WG as u64) as u32, 1, 1);
            }
            self.gpu.queue.submit([enc.finish()]);
            let c = self.gpu.read(&self.counter, &self.staging, 16)?;
            let c: &[u32] = bytemuck::cast_slice(&c);
            (c[0] as u64, c[1] as u64, c[2] as u64)
        };
        self.split = (small, large);
        if count == 0 {
            return Ok(Vec::new());
        }

        // pass 2: accumulate attributes, `window` slots at a time
        let limit = self
            .gpu
            .limits
            .max_storage_buffer_binding_size
            .min(self.gpu.limits.max_buffer_size);
        let window = count.min(MAX_WINDOW).min(limit / SLOT_BYTES).max(1);
        self.ensure(Which::Accum, window * SLOT_BYTES);
        self.ensure(Which::Staging, (window * SLOT_BYTES).max(2 * OCC_BYTES));
        // occupancy and slot bases, for decoding
        let occ_base = {
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(&self.occ, 0, &self.staging, 0, OCC_BYTES);
            enc.copy_buffer_to_buffer(&self.base, 0, &self.staging, OCC_BYTES, OCC_BYTES);
            self.gpu.queue.submit([enc.finish()]);
            self.gpu.map_staging(&self.staging, 2 * OCC_BYTES)?
        };
        let (occ, base): (&[u8], &[u8]) = occ_base.split_at(OCC_BYTES as usize);
        let occ: Vec<u32> = bytemuck::pod_collect_to_vec(occ);
        let base: Vec<u32> = bytemuck::pod_collect_to_vec(base);
        let mut voxels = Vec::with_capacity(count as usize);
        let mut lo = 0u64;
        while lo < count {
            let hi = (lo + window).min(count);
            let bytes = (hi - lo) * SLOT_BYTES;
            {
                let mut enc = self.gpu.device.create_command_encoder(&Default::default());
                enc.clear_buffer(&self.accum, 0, Some(bytes));
                self.gpu.queue.submit([enc.finish()]);
            }
            let reupload = batches.len() > 1;
            for b in &batches {
                self.run_batch(
                    b,
                    origin_i,
                    PHASE_ACCUMULATE,
                    (lo as u32, hi as u32),
                    reupload,
                )?;
            }
            let acc = self.gpu.read(&self.accum, &self.staging, bytes)?;
            decode(
                &occ,
                &base,
                bytemuck::cast_slice(&acc),
                lo as u32,
                hi as u32,
                &mut voxels,
            );
            lo = hi;
        }
        voxels.sort_unstable_by_key(|v| v.morton());
        Ok(voxels)
    }

    /// One batch of triangles through the classification pass and the fragment pass.
    fn run_batch(
        &mut self,
        tris: &[Triangle],
        origin: [i32; 3],
        phase: u32,
        slots: (u32, u32),
        upload: bool,
    ) -> Result<(), GpuError> {
        let groups = (tris.len() as u32).div_ceil(WG);
        let groups_x = groups.min(32768);
        let groups_y = groups.div_ceil(groups_x);
        let cutoff = match self.method {
            GpuMethod::Hybrid => self.cutoff,
            GpuMethod::Triangle => f32::INFINITY,
            GpuMethod::Fragment => -1.0,
        };
        let params = Params {
            origin,
            mode: match self.mode {
                Mode::Conservative => 0,
                Mode::Thin => 1,
            },
            tri_count: tris.len() as u32,
            cutoff,
            phase,
            slot_lo: slots.0,
            slot_hi: slots.1,
            groups_x,
            pad: [0; 2],
        };
        if upload {
            self.gpu
                .queue
                .write_buffer(&self.tris, 0, bytemuck::cast_slice(tris));
        }
        self.gpu
            .queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let (compute, raster, sweep) = self.bind_groups();
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&self.args, 0, None);
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.classify);
            pass.set_bind_group(0, &compute, &[]);
            pass.dispatch_workgroups(groups_x, groups_y, 1);
        }
        if self.method == GpuMethod::Triangle {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.sweep);
            pass.set_bind_group(0, &sweep, &[]);
            pass.dispatch_workgroups_indirect(&self.args, 16);
        } else {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("fragment pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Discard,
                    },
                })],
                ..Default::default()
            });
            pass.set_viewport(0.0, 0.0, CHUNK as f32, CHUNK as f32, 0.0, 1.0);
            pass.set_pipeline(&self.raster);
            pass.set_bind_group(0, &raster, &[]);
            pass.draw_indirect(&self.args, 0);
        }
        self.gpu.queue.submit([enc.finish()]);
        self.gpu.check()
    }
}

#[derive(Clone, Copy)]
enum Which {
    Tris,
    Deferred,
    Accum,
    Staging,
}
