//! The GPU hybrid voxelizer (Rauwendaal & Bailey, "Hybrid Computational Voxelization Using the
//! Graphics Pipeline", JCGT 2(1) 2013, sections 3.2-3.6): buffers, pipelines and the per-chunk
//! sequence of passes. The shaders are in `shaders/` (see [`crate::shaders`]).

use bytemuck::{Pod, Zeroable};
use voxlod_format::Voxel;
use voxlod_geom::{Grid, Triangle, CHUNK};
use voxlod_voxelize::{ChunkVoxelizer, Mode};

use crate::bindings::{ACCUM, BASE, COUNTER, DEFERRED, DRAW_ARGS, OCC, PARAMS, TRIS};
use crate::device::{open, Gpu};
use crate::encode::{decode, SLOT_BYTES};
use crate::fallback::{exact_flags, world_flags, Listed, HOST_FLAGS, TRI_ROUNDED};
use crate::shaders::{classify_source, raster_source, Precision};
use crate::{GpuError, GpuMethod};

/// Occupancy bitset of a chunk: 256³ bits.
const OCC_WORDS: u64 = (CHUNK as u64).pow(3) / 32;
const OCC_BYTES: u64 = OCC_WORDS * 4;
/// A triangle as the shaders read it: [`Triangle`] without its texture coordinates.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ShaderTriangle {
    v: [[f32; 3]; 3],
    n: [[f32; 3]; 3],
    c: [[u8; 4]; 3],
    flags: u32,
}

/// Triangles per batch (88 bytes each: under 6 MiB). The sweep pass dispatches one workgroup
/// per deferred triangle, and a dispatch dimension is at most 65535.
const BATCH: usize = 65535;
/// Bytes of one deferred triangle record.
const DEFERRED_BYTES: u64 = 48;
/// Most voxel slots accumulated per pass (96 MiB of accumulators, under the 128 MiB binding limit).
const MAX_WINDOW: u64 = 1 << 19;
const WG: u32 = 64;
/// Buffer sizes are rounded up to a multiple of this many bytes: a multiple of
/// `wgpu::COPY_BUFFER_ALIGNMENT` (4) and of every record the shaders index.
const BUFFER_ROUND: u64 = 256;

/// `Params` of voxelize.wgsl. Bound as a read-only storage buffer, not a uniform buffer:
/// lavapipe (Mesa 22.3) inlines uniform values into the shaders and recompiles the
/// classification pass whenever they change, about 12 ms and 1.3 MiB (never freed) per
/// batch.
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
    tri_base: u32,
    pad: u32,
}

const PHASE_MARK: u32 = 0;
const PHASE_ACCUMULATE: u32 = 1;
/// Flags of `counter[3]` (voxelize.wgsl): some decision's value lay inside its error band (it
/// was counted as inside) / some normal component's sign was uncertain.
const UNCERTAIN_DECISION: u32 = 1;
const UNCERTAIN_NORMAL: u32 = 2;
/// Word offsets in `counter` (voxelize.wgsl): the number of listed triangles, the batch's bits of
/// listed triangles (one per triangle of a batch), the list (indices in the chunk's stream).
const LIST_COUNT: usize = 4;
const LIST_FLAGS: u64 = 8;
const LIST_AT: u64 = LIST_FLAGS + 65536 / 32;
/// Most triangles listed per chunk; beyond that the whole chunk is voxelized on the CPU.
const LIST_CAP: u64 = 65536;
const COUNTER_BYTES: u64 = (LIST_AT + LIST_CAP) * 4;

/// Reusable GPU voxelizer of 256³ chunks; see the crate docs.
pub struct GpuVoxelizer {
    gpu: Gpu,
    mode: Mode,
    method: GpuMethod,
    cutoff: f32,
    precision: Precision,
    layouts: Layouts,
    pipelines: Pipelines,
    buffers: Buffers,
    /// bind groups per triangle buffer
    bind: [Option<Groups>; 2],
    /// the last submission that used each triangle buffer, until waited for
    inflight: [Option<wgpu::SubmissionIndex>; 2],
    /// the triangle buffer the next batch goes to
    next: usize,
    /// the last batch submitted (its triangles stay in their buffer until overwritten)
    resident: Option<Batch>,
    /// triangles per batch
    batch: usize,
    /// most voxel slots per accumulation window (`MAX_WINDOW` but for tests)
    max_window: u64,
    /// host copy of the batch being filled
    pending: Vec<Triangle>,
    /// leave out second passes that would draw nothing (see `may_defer`)
    skip_empty: bool,
    split: (u64, u64),
    /// the CPU voxelizer of flagged chunks (created on first use)
    cpu: Option<ChunkVoxelizer>,
    /// the last chunk's uncertainty flags, and whether it was re-voxelized on the CPU
    uncertain: u32,
    fell_back: bool,
    /// the last chunk's listed triangles (indices in its stream, sorted; decided on the host)
    listed: Vec<u32>,
    /// how many triangles the last chunk listed (more than `LIST_CAP` on overflow)
    fallback_tris: u64,
    /// the grid of the chunk being voxelized when its triangles come in world coordinates
    /// ([`GpuVoxelizer::voxelize_chunk_streamed_world`])
    world: Option<Grid>,
}

/// (compute, raster, sweep) bind groups.
type Groups = (wgpu::BindGroup, wgpu::BindGroup, wgpu::BindGroup);

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

/// The bind group layouts, as the WGSL binds them (`crate::bindings`).
struct Layouts {
    /// The compute passes' (classify, compact, sweep).
    compute: wgpu::BindGroupLayout,
    /// The fragment pass's.
    raster: wgpu::BindGroupLayout,
}

impl Layouts {
    fn new(d: &wgpu::Device) -> Layouts {
        let cs = wgpu::ShaderStages::COMPUTE;
        let fs = wgpu::ShaderStages::FRAGMENT;
        let vfs = wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT;
        let compute = d.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("voxlod compute"),
            entries: &[
                storage_entry(PARAMS, cs, true),
                storage_entry(TRIS, cs, true),
                storage_entry(OCC, cs, false),
                storage_entry(DEFERRED, cs, false),
                storage_entry(DRAW_ARGS, cs, false),
                storage_entry(BASE, cs, false),
                storage_entry(ACCUM, cs, false),
                storage_entry(COUNTER, cs, false),
            ],
        });
        let raster = d.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("voxlod raster"),
            entries: &[
                storage_entry(PARAMS, vfs, true),
                storage_entry(TRIS, fs, true),
                storage_entry(OCC, fs, false),
                storage_entry(DEFERRED, vfs, true),
                storage_entry(BASE, fs, true),
                storage_entry(ACCUM, fs, false),
                storage_entry(COUNTER, fs, false),
            ],
        });
        Layouts { compute, raster }
    }
}

/// The passes of the hybrid algorithm: classification (section 3.2), compaction of the
/// listed triangles, the triangle-parallel sweep and the fragment pass (sections 3.3-3.6),
/// and the fragment pass's attachment.
struct Pipelines {
    classify: wgpu::ComputePipeline,
    compact: wgpu::ComputePipeline,
    sweep: wgpu::ComputePipeline,
    raster: wgpu::RenderPipeline,
    /// wgpu wants an attachment; the viewport is clipped to it, so it covers the chunk
    target: wgpu::TextureView,
}

impl Pipelines {
    fn new(d: &wgpu::Device, layouts: &Layouts, precision: Precision) -> Pipelines {
        let layout = |bgl: &wgpu::BindGroupLayout| {
            d.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: None,
                bind_group_layouts: &[Some(bgl)],
                immediate_size: 0,
            })
        };
        let compute_layout = layout(&layouts.compute);
        let raster_layout = layout(&layouts.raster);
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
        Pipelines {
            classify,
            compact,
            sweep,
            raster,
            target,
        }
    }
}

/// The storage buffers the passes share (bindings in `crate::bindings`), the indirect
/// arguments, and the staging buffer of the read-backs. The triangle, deferred, accumulator
/// and staging buffers grow on demand.
struct Buffers {
    params: wgpu::Buffer,
    /// two triangle buffers: batch k+1 is uploaded while batch k runs
    tris: [wgpu::Buffer; 2],
    occ: wgpu::Buffer,
    deferred: wgpu::Buffer,
    args: wgpu::Buffer,
    /// stands in for `args` in the sweep pass's bind group (a buffer cannot be bound as storage
    /// in the dispatch that reads it as indirect arguments)
    args_dummy: wgpu::Buffer,
    base: wgpu::Buffer,
    accum: wgpu::Buffer,
    counter: wgpu::Buffer,
    staging: wgpu::Buffer,
}

impl Buffers {
    fn new(d: &wgpu::Device) -> Buffers {
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
            U::STORAGE | U::COPY_DST,
        );
        let tris = [0, 1].map(|_| buf("triangles", 88 * 1024, U::STORAGE | U::COPY_DST));
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
        let counter = buf(
            "counter",
            COUNTER_BYTES,
            U::STORAGE | U::COPY_SRC | U::COPY_DST,
        );
        let staging = buf("staging", 2 * OCC_BYTES, U::MAP_READ | U::COPY_DST);
        Buffers {
            params,
            tris,
            occ,
            deferred,
            args,
            args_dummy,
            base,
            accum,
            counter,
            staging,
        }
    }
}

impl GpuVoxelizer {
    /// Opens an adapter (Vulkan, else GL; `WGPU_BACKEND` overrides) and builds the pipelines.
    /// `cutoff` is the dominant projected area (voxels²) from which [`GpuMethod::Hybrid`] defers
    /// a triangle to the fragment pass; the other methods ignore it.
    pub fn new(mode: Mode, method: GpuMethod, cutoff: f32) -> Result<GpuVoxelizer, GpuError> {
        GpuVoxelizer::with_precision(mode, method, cutoff, None)
    }

    /// [`GpuVoxelizer::new`] with the shaders' precision chosen: `None` takes f64 when the
    /// adapter has `SHADER_F64`, else f32; `Some(Precision::F32)` forces the f32 shaders (for
    /// tests of that variant on an adapter with f64); `Some(Precision::F64)` on an adapter
    /// without f64 is an error.
    pub fn with_precision(
        mode: Mode,
        method: GpuMethod,
        cutoff: f32,
        precision: Option<Precision>,
    ) -> Result<GpuVoxelizer, GpuError> {
        let gpu = open()?;
        let precision = match precision {
            Some(Precision::F64) if !gpu.f64 => {
                return Err(GpuError::Device {
                    adapter: gpu.name.clone(),
                    reason: "f64 shaders requested, but the adapter lacks SHADER_F64".into(),
                })
            }
            Some(p) => p,
            None if gpu.f64 => Precision::F64,
            None => Precision::F32,
        };
        let layouts = Layouts::new(&gpu.device);
        let pipelines = Pipelines::new(&gpu.device, &layouts, precision);
        let buffers = Buffers::new(&gpu.device);
        gpu.check()?;
        Ok(GpuVoxelizer {
            gpu,
            mode,
            method,
            cutoff,
            precision,
            layouts,
            pipelines,
            buffers,
            bind: [None, None],
            inflight: [None, None],
            next: 0,
            resident: None,
            batch: BATCH,
            max_window: MAX_WINDOW,
            pending: Vec::new(),
            skip_empty: true,
            split: (0, 0),
            cpu: None,
            uncertain: 0,
            fell_back: false,
            listed: Vec::new(),
            fallback_tris: 0,
            world: None,
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

    /// Whether the last chunk had a decision the shaders could not certify (a value inside its
    /// rounding band, or a normal component of uncertain sign; see the crate docs).
    pub fn last_uncertain(&self) -> bool {
        self.uncertain != 0
    }

    /// Whether the last chunk was re-voxelized as a whole on the CPU
    /// (`voxlod_voxelize::ChunkVoxelizer`, same mode): only when more than 65,536 of its
    /// triangles had a decision the shaders could not certify (the list's capacity).
    pub fn last_fell_back(&self) -> bool {
        self.fell_back
    }

    /// Triangles of the last chunk decided on the host because the shaders could not certify
    /// one of their decisions (the per-triangle fallback; see the crate docs). When the chunk
    /// fell back as a whole ([`GpuVoxelizer::last_fell_back`]), more than 65,536.
    pub fn last_fallback_triangles(&self) -> u64 {
        self.fallback_tris
    }

    /// Triangles per GPU batch (default and maximum 65,535: the sweep pass dispatches one
    /// workgroup per deferred triangle, and a dispatch dimension is at most 65,535).
    pub fn batch_size(&self) -> usize {
        self.batch
    }

    /// Sets the triangles per GPU batch, clamped to 1..=65,535. Smaller batches hold less in
    /// memory (88 bytes per triangle, twice on the device, up to three times on the host) but
    /// cost more submissions; the voxels do not depend on it.
    pub fn set_batch_size(&mut self, n: usize) {
        self.batch = n.clamp(1, BATCH);
    }

    /// Caps the voxel slots accumulated per pass at `slots` (at least 1; at most the default,
    /// 2^19): a chunk with more occupied voxels is accumulated in several windows, each
    /// replaying the chunk. For tests, which reach several windows on small chunks with it;
    /// the voxels do not depend on it.
    #[doc(hidden)]
    pub fn set_max_window(&mut self, slots: u64) {
        self.max_window = slots.clamp(1, MAX_WINDOW);
    }

    /// Whether the second pass (fragment or sweep) of a batch is left out when the host can
    /// tell, from the triangles' areas and extents, that the classification pass defers
    /// nothing (default on; the voxels do not depend on it). For benchmarks.
    pub fn set_skip_empty_passes(&mut self, on: bool) {
        self.skip_empty = on;
    }

    /// Grows triangle buffer `slot` to at least `size` bytes (see [`GpuVoxelizer::ensure`]).
    fn ensure_tris(&mut self, slot: usize, size: u64) {
        let b = &mut self.buffers.tris[slot];
        if b.size() >= size {
            return;
        }
        let size = size.max(b.size() * 2).next_multiple_of(BUFFER_ROUND);
        *b = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("triangles"),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.bind[slot] = None;
    }

    /// Grows `buf` to at least `size` bytes (new buffers are zeroed by wgpu, which is slow on a
    /// CPU device, hence reuse with geometric growth).
    fn ensure(&mut self, which: Which, size: u64) {
        let (b, usage, label) = match which {
            Which::Deferred => (
                &mut self.buffers.deferred,
                wgpu::BufferUsages::STORAGE,
                "deferred",
            ),
            Which::Accum => (
                &mut self.buffers.accum,
                wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                "accumulators",
            ),
            Which::Staging => (
                &mut self.buffers.staging,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                "staging",
            ),
        };
        if b.size() >= size {
            return;
        }
        let size = size.max(b.size() * 2).next_multiple_of(BUFFER_ROUND);
        *b = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false,
        });
        self.bind = [None, None];
    }

    /// The bind groups of the passes reading triangle buffer `slot`.
    fn bind_groups(&mut self, slot: usize) -> Groups {
        if let Some(b) = &self.bind[slot] {
            return b.clone();
        }
        let tris = &self.buffers.tris[slot];
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
                layout: &self.layouts.compute,
                entries: &[
                    e(PARAMS, &self.buffers.params),
                    e(TRIS, tris),
                    e(OCC, &self.buffers.occ),
                    e(DEFERRED, &self.buffers.deferred),
                    e(DRAW_ARGS, args),
                    e(BASE, &self.buffers.base),
                    e(ACCUM, &self.buffers.accum),
                    e(COUNTER, &self.buffers.counter),
                ],
            })
        };
        let compute = compute_group(&self.buffers.args);
        let sweep = compute_group(&self.buffers.args_dummy);
        let raster = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("raster"),
            layout: &self.layouts.raster,
            entries: &[
                e(PARAMS, &self.buffers.params),
                e(TRIS, tris),
                e(OCC, &self.buffers.occ),
                e(DEFERRED, &self.buffers.deferred),
                e(BASE, &self.buffers.base),
                e(ACCUM, &self.buffers.accum),
                e(COUNTER, &self.buffers.counter),
            ],
        });
        self.bind[slot] = Some((compute.clone(), raster.clone(), sweep.clone()));
        (compute, raster, sweep)
    }

    /// Voxelizes the triangles (grid coordinates) of the chunk whose minimum voxel corner is
    /// `origin` (multiples of 256): the same voxels, normals, colours and face masks as
    /// `voxlod_voxelize::ChunkVoxelizer`, sorted by the Morton code of their in-chunk position.
    /// Triangles with a non-finite coordinate or zero area are skipped. A thin wrapper of
    /// [`GpuVoxelizer::voxelize_chunk_streamed`] for triangles already in memory.
    pub fn voxelize_chunk(
        &mut self,
        origin: [u32; 3],
        tris: &[Triangle],
    ) -> Result<Vec<Voxel>, GpuError> {
        self.voxelize_chunk_streamed(origin, &mut |feed: &mut Feed<'_>| {
            feed(tris);
            Ok::<(), GpuError>(())
        })
    }

    /// [`GpuVoxelizer::voxelize_chunk`] of triangles in **world** coordinates of `grid`: the
    /// voxels `ChunkVoxelizer::add_world` gives (every overlap decision exact for the world
    /// coordinates and the grid's origin and voxel size as stated, not for their f32 grid
    /// coordinates; see the crate docs, "Exactness"). The attributes are computed from the
    /// triangles moved to the grid (`grid.to_grid`), as on the CPU.
    pub fn voxelize_chunk_world(
        &mut self,
        grid: &Grid,
        origin: [u32; 3],
        tris: &[Triangle],
    ) -> Result<Vec<Voxel>, GpuError> {
        self.voxelize_chunk_streamed_world(grid, origin, &mut |feed: &mut Feed<'_>| {
            feed(tris);
            Ok::<(), GpuError>(())
        })
    }

    /// [`GpuVoxelizer::voxelize_chunk_streamed`] of triangles in world coordinates of `grid`
    /// (see [`GpuVoxelizer::voxelize_chunk_world`]): the replay feeds them as the input has them
    /// (the bins of a build); the voxelizer moves each batch to the grid itself and keeps what
    /// the shaders need to know of the rounding in the triangles' flags.
    pub fn voxelize_chunk_streamed_world<E: From<GpuError>>(
        &mut self,
        grid: &Grid,
        origin: [u32; 3],
        replay: &mut dyn FnMut(&mut Feed<'_>) -> Result<(), E>,
    ) -> Result<Vec<Voxel>, E> {
        self.world = Some(*grid);
        let r = self.run(origin, replay);
        self.world = None;
        r
    }

    /// [`GpuVoxelizer::voxelize_chunk`] with bounded host memory: `replay(feed)` must pass all
    /// of the chunk's triangles to `feed`, in batches of any size, and in the same order every
    /// time it is called. It is called once for marking and, when the chunk needs more than one
    /// GPU batch ([`GpuVoxelizer::batch_size`]), once more per accumulation window (at least
    /// once; a window is 2^19 voxels). At most two GPU batches are in flight: while the device
    /// works on batch k, `feed` returns and the host reads and uploads batch k+1; before batch
    /// k+2 is uploaded, batch k is waited for (so at most three batches of triangles are held
    /// on the host, wgpu's upload copies included).
    ///
    /// Errors of `replay` are returned as they are; GPU errors met while feeding stop the GPU
    /// work (the rest of the replay is ignored) and are returned when `replay` returns. A replay
    /// that yields a different number of triangles than the first is an error
    /// ([`GpuError::Replay`]).
    pub fn voxelize_chunk_streamed<E: From<GpuError>>(
        &mut self,
        origin: [u32; 3],
        replay: &mut dyn FnMut(&mut Feed<'_>) -> Result<(), E>,
    ) -> Result<Vec<Voxel>, E> {
        self.world = None;
        self.run(origin, replay)
    }

    /// The chunk's passes; the replay's triangles are in world coordinates of `self.world`
    /// if set, else in grid coordinates.
    fn run<E: From<GpuError>>(
        &mut self,
        origin: [u32; 3],
        replay: &mut dyn FnMut(&mut Feed<'_>) -> Result<(), E>,
    ) -> Result<Vec<Voxel>, E> {
        // The hybrid algorithm's phases, in order.
        if origin
            .iter()
            .any(|&c| c % CHUNK != 0 || c > i32::MAX as u32 - CHUNK)
        {
            return Err(GpuError::Origin(origin).into());
        }
        self.split = (0, 0);
        self.uncertain = 0;
        self.fell_back = false;
        self.listed.clear();
        self.fallback_tris = 0;
        self.resident = None;
        self.pending.clear();
        let origin_i = origin.map(|c| c as i32);

        // pass 1: mark the occupancy bitset
        {
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            enc.clear_buffer(&self.buffers.occ, 0, None);
            enc.clear_buffer(&self.buffers.counter, 0, None);
            self.gpu.queue.submit([enc.finish()]);
        }
        let mut st = Stream::new(origin_i, PHASE_MARK, (0, 0));
        replay(&mut |b: &[Triangle]| self.feed(&mut st, b))?;
        self.finish_stream(&mut st)?;
        let (marked_batches, marked_tris) = (st.batches, st.tris);
        if marked_tris == 0 {
            return Ok(Vec::new());
        }
        // compaction: a slot per occupied voxel
        let c = self.compact_and_count()?;
        let (mut count, small, large, flags, listed) = (
            c[0] as u64,
            c[1] as u64,
            c[2] as u64,
            c[3],
            c[LIST_COUNT] as u64,
        );
        self.inflight = [None, None];
        self.split = (small, large);
        self.uncertain = flags;
        self.fallback_tris = listed;
        debug_assert!(flags & !(UNCERTAIN_DECISION | UNCERTAIN_NORMAL) == 0);
        // the listed triangles don't fit the list, or their stream indices don't fit a u32
        let fall_back = listed > LIST_CAP || marked_tris > u32::MAX as u64;
        let mut host = None;
        if listed > 0 && !fall_back {
            // the per-triangle fallback: the listed triangles' exact voxels, set before
            // compaction (compaction runs again)
            let words = self.gpu.read(
                &self.buffers.counter,
                &self.buffers.staging,
                (LIST_AT + listed) * 4,
            )?;
            let words: &[u32] = bytemuck::cast_slice(&words);
            self.listed = words[LIST_AT as usize..].to_vec();
            self.listed.sort_unstable();
            debug_assert!(self.listed.windows(2).all(|w| w[0] < w[1]));
            let mut tris = Vec::with_capacity(self.listed.len());
            let (mut i, mut next) = (0u64, 0usize);
            let wanted = &self.listed;
            let world = self.world;
            replay(&mut |b: &[Triangle]| {
                for t in b.iter().filter(|t| fed(t, world.as_ref())) {
                    if next < wanted.len() && wanted[next] as u64 == i {
                        tris.push(*t);
                        next += 1;
                    }
                    i += 1;
                }
            })?;
            if i != marked_tris || tris.len() != self.listed.len() {
                return Err(GpuError::Replay {
                    first: marked_tris,
                    again: i,
                }
                .into());
            }
            let pairs = Listed::new(tris, self.world.as_ref(), origin, self.mode);
            let mut occ: Vec<u32> = bytemuck::pod_collect_to_vec(&self.gpu.read(
                &self.buffers.occ,
                &self.buffers.staging,
                OCC_BYTES,
            )?);
            if pairs.mark(&mut occ) {
                self.gpu
                    .queue
                    .write_buffer(&self.buffers.occ, 0, bytemuck::cast_slice(&occ));
                self.gpu
                    .queue
                    .write_buffer(&self.buffers.counter, 0, &[0; 4]);
                count = self.compact_and_count()?[0] as u64;
            }
            host = Some(pairs);
        }
        if fall_back {
            // the exact CPU decisions for the whole chunk (its attributes too)
            self.fell_back = true;
            let mode = self.mode;
            let cpu = self.cpu.get_or_insert_with(|| ChunkVoxelizer::new(mode));
            if cpu.mode() != mode {
                *cpu = ChunkVoxelizer::new(mode);
            }
            cpu.begin(origin);
            let mut again = 0u64;
            let world = self.world;
            replay(&mut |b: &[Triangle]| {
                again += b.iter().filter(|t| fed(t, world.as_ref())).count() as u64;
                match &world {
                    Some(grid) => cpu.add_world(grid, b),
                    None => cpu.add(b),
                }
            })?;
            let voxels = cpu.finish();
            if again != marked_tris {
                return Err(GpuError::Replay {
                    first: marked_tris,
                    again,
                }
                .into());
            }
            return Ok(voxels);
        }
        if count == 0 {
            return Ok(Vec::new());
        }

        // pass 2: accumulate attributes, `window` slots at a time
        let limit = self
            .gpu
            .limits
            .max_storage_buffer_binding_size
            .min(self.gpu.limits.max_buffer_size);
        let window = count.min(self.max_window).min(limit / SLOT_BYTES).max(1);
        self.ensure(Which::Accum, window * SLOT_BYTES);
        self.ensure(Which::Staging, (window * SLOT_BYTES).max(2 * OCC_BYTES));
        // occupancy and slot bases, for decoding
        let occ_base = {
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(&self.buffers.occ, 0, &self.buffers.staging, 0, OCC_BYTES);
            enc.copy_buffer_to_buffer(
                &self.buffers.base,
                0,
                &self.buffers.staging,
                OCC_BYTES,
                OCC_BYTES,
            );
            self.gpu.queue.submit([enc.finish()]);
            self.gpu.map_staging(&self.buffers.staging, 2 * OCC_BYTES)?
        };
        let (occ, base): (&[u8], &[u8]) = occ_base.split_at(OCC_BYTES as usize);
        let occ: Vec<u32> = bytemuck::pod_collect_to_vec(occ);
        let base: Vec<u32> = bytemuck::pod_collect_to_vec(base);
        if let Some(h) = &mut host {
            h.slots(&occ, &base, origin);
        }
        let mut voxels = Vec::with_capacity(count as usize);
        let mut lo = 0u64;
        while lo < count {
            let hi = (lo + window).min(count);
            let bytes = (hi - lo) * SLOT_BYTES;
            {
                let mut enc = self.gpu.device.create_command_encoder(&Default::default());
                enc.clear_buffer(&self.buffers.accum, 0, Some(bytes));
                self.gpu.queue.submit([enc.finish()]);
            }
            let slots = (lo as u32, hi as u32);
            match self.resident {
                // one batch: its triangles are still on the device
                Some(batch) if marked_batches == 1 => {
                    debug_assert_eq!(batch.tri_base, 0, "the chunk's only batch is its first");
                    let pass = Pass {
                        origin: origin_i,
                        phase: PHASE_ACCUMULATE,
                        slots,
                    };
                    self.record(batch, pass)?;
                }
                _ => {
                    let mut st = Stream::new(origin_i, PHASE_ACCUMULATE, slots);
                    replay(&mut |b: &[Triangle]| self.feed(&mut st, b))?;
                    self.finish_stream(&mut st)?;
                    if st.tris != marked_tris {
                        return Err(GpuError::Replay {
                            first: marked_tris,
                            again: st.tris,
                        }
                        .into());
                    }
                }
            }
            let acc = self
                .gpu
                .read(&self.buffers.accum, &self.buffers.staging, bytes)?;
            self.inflight = [None, None];
            let owned: Vec<u32>;
            let acc: &[u32] = match &host {
                // the listed triangles' contributions, added to the GPU's sums
                Some(h) => {
                    let mut a: Vec<u32> = bytemuck::pod_collect_to_vec(&acc);
                    h.add_to(&mut a, lo as u32, hi as u32);
                    owned = a;
                    &owned
                }
                None => bytemuck::cast_slice(&acc),
            };
            decode(&occ, &base, acc, lo as u32, hi as u32, &mut voxels);
            lo = hi;
        }
        voxels.sort_unstable_by_key(|v| v.morton());
        Ok(voxels)
    }

    /// Takes the next piece of a replay: fills the pending batch (finite triangles only) and
    /// submits every full one; a full, finite piece of the caller's batch is uploaded as is.
    fn feed(&mut self, st: &mut Stream, mut tris: &[Triangle]) {
        while !tris.is_empty() && st.error.is_none() {
            let room = self.batch - self.pending.len();
            let (head, rest) = tris.split_at(room.min(tris.len()));
            tris = rest;
            // f64 shaders: every triangle gets its certification flags, so it is copied;
            // world coordinates are moved to the grid and get the flags of their rounding
            let certify = self.precision == Precision::F64;
            let r = if !certify
                && self.world.is_none()
                && self.pending.is_empty()
                && head.len() == self.batch
                && head.iter().all(Triangle::is_finite)
            {
                self.submit(st, head)
            } else if let Some(grid) = &self.world {
                for t in head {
                    let mut m = *t;
                    m.v = t.v.map(|p| grid.to_grid(p));
                    if !m.is_finite() {
                        continue;
                    }
                    m.flags &= !HOST_FLAGS;
                    m.flags |= world_flags(&t.v, &m.v, grid);
                    if certify && m.flags & TRI_ROUNDED == 0 {
                        m.flags |= exact_flags(&m);
                    }
                    self.pending.push(m);
                }
                self.submit_full(st)
            } else {
                let at = self.pending.len();
                self.pending
                    .extend(head.iter().filter(|t| t.is_finite()).copied());
                for t in &mut self.pending[at..] {
                    t.flags &= !HOST_FLAGS;
                    if certify {
                        t.flags |= exact_flags(t);
                    }
                }
                self.submit_full(st)
            };
            if let Err(e) = r {
                st.error = Some(e);
            }
        }
    }

    /// Submits the pending batch if it is full.
    fn submit_full(&mut self, st: &mut Stream) -> Result<(), GpuError> {
        if self.pending.len() < self.batch {
            return Ok(());
        }
        let full = std::mem::take(&mut self.pending);
        let r = self.submit(st, &full);
        self.pending = full;
        self.pending.clear();
        r
    }

    /// Submits the last, partial batch of a replay; returns the first error of the replay.
    fn finish_stream(&mut self, st: &mut Stream) -> Result<(), GpuError> {
        if st.error.is_none() && !self.pending.is_empty() {
            let last = std::mem::take(&mut self.pending);
            if let Err(e) = self.submit(st, &last) {
                st.error = Some(e);
            }
            self.pending = last;
        }
        self.pending.clear();
        match st.error.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// Uploads one batch into the triangle buffer not used by the previous batch (after the
    /// batch before that, which used it, has finished) and submits its passes.
    fn submit(&mut self, st: &mut Stream, tris: &[Triangle]) -> Result<(), GpuError> {
        debug_assert!(!tris.is_empty() && tris.len() <= self.batch);
        let slot = self.next;
        self.next ^= 1;
        if let Some(idx) = self.inflight[slot].take() {
            self.gpu.wait_for(idx)?;
        }
        // the shaders read the 88-byte layout v, n, c, flags (texture coordinates, which
        // `Triangle` carries after them, are not used on the GPU: textured meshes are
        // voxelized on the CPU)
        let packed: Vec<ShaderTriangle> = tris
            .iter()
            .map(|t| ShaderTriangle {
                v: t.v,
                n: t.n,
                c: t.c,
                flags: t.flags,
            })
            .collect();
        let bytes = std::mem::size_of_val(packed.as_slice()) as u64;
        self.ensure_tris(slot, bytes);
        self.ensure(Which::Deferred, tris.len() as u64 * DEFERRED_BYTES);
        self.gpu
            .queue
            .write_buffer(&self.buffers.tris[slot], 0, bytemuck::cast_slice(&packed));
        let defers = self.may_defer(tris);
        // (a chunk whose stream exceeds u32 indices falls back as a whole)
        let tri_base = st.tris.min(u32::MAX as u64) as u32;
        let batch = Batch {
            slot,
            len: tris.len(),
            tri_base,
            defers,
        };
        let idx = self.record(batch, st.pass)?;
        self.inflight[slot] = Some(idx);
        self.resident = Some(batch);
        st.batches += 1;
        st.tris += tris.len() as u64;
        Ok(())
    }

    /// Whether the classification pass may defer a triangle of `tris` to the second pass
    /// (fragment pass, or the sweep pass of [`GpuMethod::Triangle`]). False only when every
    /// triangle is, with a margin for the shader's rounding, under the cutoff and within
    /// `INLINE_COLUMNS` columns in all three projections: then the second pass would draw
    /// nothing and is not recorded. Costs a cross product per triangle on the host.
    fn may_defer(&self, tris: &[Triangle]) -> bool {
        let cutoff = match self.method {
            _ if !self.skip_empty => return true,
            GpuMethod::Fragment => return true,
            GpuMethod::Triangle => f64::INFINITY,
            GpuMethod::Hybrid => self.cutoff as f64 * 0.999,
        };
        !tris.iter().all(|t| certainly_inline(t, cutoff))
    }

    /// Runs the compaction pass and reads `counter` up to the number of listed triangles.
    fn compact_and_count(&mut self) -> Result<[u32; LIST_COUNT + 1], GpuError> {
        let (compute, _, _) = self.bind_groups(0);
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipelines.compact);
            pass.set_bind_group(0, &compute, &[]);
            pass.dispatch_workgroups((OCC_WORDS / WG as u64) as u32, 1, 1);
        }
        self.gpu.queue.submit([enc.finish()]);
        let c = self.gpu.read(
            &self.buffers.counter,
            &self.buffers.staging,
            4 * (LIST_COUNT as u64 + 1),
        )?;
        let c: Vec<u32> = bytemuck::pod_collect_to_vec(&c);
        Ok(std::array::from_fn(|k| c[k]))
    }

    /// Records and submits `pass`'s classification pass and, if `batch.defers`, its second
    /// pass over one batch. Marking clears the batch's bits of listed triangles (the shaders
    /// set them); accumulation overwrites the listed triangles with zeros (skipped).
    fn record(&mut self, batch: Batch, pass: Pass) -> Result<wgpu::SubmissionIndex, GpuError> {
        let Batch {
            slot,
            len,
            tri_base,
            defers,
        } = batch;
        let Pass {
            origin,
            phase,
            slots,
        } = pass;
        let groups = (len as u32).div_ceil(WG);
        let groups_x = groups.min(32768);
        let groups_y = groups.div_ceil(groups_x);
        let cutoff = match self.method {
            GpuMethod::Hybrid => self.cutoff,
            GpuMethod::Triangle => f32::INFINITY,
            GpuMethod::Fragment => -1.0,
        };
        let params = Params {
            origin,
            mode: self.mode.code(),
            tri_count: len as u32,
            cutoff,
            phase,
            slot_lo: slots.0,
            slot_hi: slots.1,
            groups_x,
            tri_base,
            pad: 0,
        };
        self.gpu
            .queue
            .write_buffer(&self.buffers.params, 0, bytemuck::bytes_of(&params));
        let (compute, raster, sweep) = self.bind_groups(slot);
        let words = (len as u64).div_ceil(32);
        if phase == PHASE_ACCUMULATE {
            self.zero_listed(batch);
        }
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        if phase == PHASE_MARK {
            enc.clear_buffer(&self.buffers.counter, LIST_FLAGS * 4, Some(words * 4));
        }
        enc.clear_buffer(&self.buffers.args, 0, None);
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipelines.classify);
            pass.set_bind_group(0, &compute, &[]);
            pass.dispatch_workgroups(groups_x, groups_y, 1);
        }
        // without `defers`, the classification pass voxelized every triangle
        if defers {
            self.record_second_pass(&mut enc, &raster, &sweep);
        }
        let idx = self.gpu.queue.submit([enc.finish()]);
        self.gpu.check()?;
        Ok(idx)
    }

    /// In the accumulation phase the listed triangles' contributions come from the host:
    /// replaces the batch's listed triangles in its triangle buffer by degenerate (zero-area)
    /// triangles, which the shaders skip.
    fn zero_listed(&self, batch: Batch) {
        let first = self.listed.partition_point(|&i| i < batch.tri_base);
        let zero = [0u8; std::mem::size_of::<ShaderTriangle>()];
        for &i in &self.listed[first..] {
            let k = (i - batch.tri_base) as u64;
            if k >= batch.len as u64 {
                break;
            }
            self.gpu.queue.write_buffer(
                &self.buffers.tris[batch.slot],
                k * zero.len() as u64,
                &zero,
            );
        }
    }

    /// Records the second pass over the triangles the classification pass deferred (its
    /// indirect arguments in `args`): the sweep pass of [`GpuMethod::Triangle`], else the
    /// fragment pass, rasterized at the chunk's resolution.
    fn record_second_pass(
        &self,
        enc: &mut wgpu::CommandEncoder,
        raster: &wgpu::BindGroup,
        sweep: &wgpu::BindGroup,
    ) {
        if self.method == GpuMethod::Triangle {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipelines.sweep);
            pass.set_bind_group(0, sweep, &[]);
            pass.dispatch_workgroups_indirect(&self.buffers.args, 16);
        } else {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("fragment pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.pipelines.target,
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
            pass.set_pipeline(&self.pipelines.raster);
            pass.set_bind_group(0, raster, &[]);
            pass.draw_indirect(&self.buffers.args, 0);
        }
    }
}

/// Columns (2D cells of the dominant projection) up to which the classification pass voxelizes
/// a triangle itself; `INLINE_COLUMNS` of shaders/classify.wgsl.
const INLINE_COLUMNS: f64 = 64.0;

/// True when the classification pass certainly voxelizes `t` itself (or skips it): its
/// dominant projected area plus a bound on the shader's rounding (f32 on adapters without
/// f64) is below `cutoff`, and its closed voxel range spans at most `INLINE_COLUMNS` columns in
/// each of the three projections (so whichever dominant axis the shader picks at a tie).
fn certainly_inline(t: &Triangle, cutoff: f64) -> bool {
    let v = t.v.map(|p| p.map(f64::from));
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let (e1, e2) = (sub(v[1], v[0]), sub(v[2], v[0]));
    let n = [
        e1[1] * e2[2] - e1[2] * e2[1],
        e1[2] * e2[0] - e1[0] * e2[2],
        e1[0] * e2[1] - e1[1] * e2[0],
    ];
    let len = |a: [f64; 3]| (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let area = 0.5 * n[0].abs().max(n[1].abs()).max(n[2].abs());
    // (finite f32 coordinates: no NaN here)
    if area + 1e-5 * len(e1) * len(e2) >= cutoff {
        return false;
    }
    // voxel range [ceil(min) - 1, floor(max)] per axis, as the shader's setup (before clamping)
    let w: [f64; 3] = std::array::from_fn(|k| {
        let lo = v[0][k].min(v[1][k]).min(v[2][k]);
        let hi = v[0][k].max(v[1][k]).max(v[2][k]);
        hi.floor() - lo.ceil() + 2.0
    });
    w[0] * w[1] <= INLINE_COLUMNS && w[1] * w[2] <= INLINE_COLUMNS && w[0] * w[2] <= INLINE_COLUMNS
}

/// Whether the voxelizer takes triangle `t` of a replay (and counts it in the chunk's stream):
/// finite coordinates, on the grid when `world` is set (its f32 grid coordinates).
fn fed(t: &Triangle, world: Option<&Grid>) -> bool {
    match world {
        Some(g) => {
            t.v.iter()
                .all(|&p| g.to_grid(p).iter().all(|c| c.is_finite()))
        }
        None => t.is_finite(),
    }
}

/// What [`GpuVoxelizer::voxelize_chunk_streamed`]'s replay callback passes the chunk's
/// triangles to, a batch at a time.
pub type Feed<'a> = dyn FnMut(&[Triangle]) + 'a;

/// What the batches of one replay run: the chunk's origin (grid coordinates), the phase
/// (`PHASE_MARK` or `PHASE_ACCUMULATE`) and the window of slots `[lo, hi)` accumulated.
#[derive(Clone, Copy)]
struct Pass {
    origin: [i32; 3],
    phase: u32,
    slots: (u32, u32),
}

/// One replay of a chunk's triangles: what its batches run and what was submitted.
struct Stream {
    pass: Pass,
    batches: u64,
    tris: u64,
    error: Option<GpuError>,
}

impl Stream {
    fn new(origin: [i32; 3], phase: u32, slots: (u32, u32)) -> Stream {
        Stream {
            pass: Pass {
                origin,
                phase,
                slots,
            },
            batches: 0,
            tris: 0,
            error: None,
        }
    }
}

/// One batch on the device: `len` triangles in triangle buffer `slot`, the first of them
/// triangle `tri_base` of the chunk's stream, and whether the second pass is recorded for it.
/// The last batch submitted is kept ([`GpuVoxelizer`]'s `resident`) so that a chunk of one
/// batch is accumulated without uploading it again.
#[derive(Clone, Copy)]
struct Batch {
    slot: usize,
    len: usize,
    tri_base: u32,
    defers: bool,
}

#[derive(Clone, Copy)]
enum Which {
    Deferred,
    Accum,
    Staging,
}
