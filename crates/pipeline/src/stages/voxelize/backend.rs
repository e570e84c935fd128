//! Which voxelizer runs the chunks: the CPU `ChunkVoxelizer` on every core, or the GPU hybrid
//! voxelizer (`voxlod-gpu`, feature `gpu`), both behind one [`Voxelize`] trait, and the GPU
//! cutoff search.

use std::ops::ControlFlow;
use std::sync::{Arc, Mutex};

use anyhow::{Context, Result};
use voxlod_format::Voxel;
use voxlod_geom::{Grid, Triangle};
use voxlod_texture::TextureSet;
use voxlod_tile::{Bins, TileError, TriangleSource};
use voxlod_voxelize::ChunkVoxelizer;

use crate::error::StageError;
use crate::settings::{Backend, BuildSettings, Cutoff, DEFAULT_CUTOFF};

/// One leaf chunk's triangles, readable as often as a voxelizer needs them (the CPU reads them
/// once, the GPU once per phase).
pub(crate) trait ChunkSource {
    /// The chunk's index in Morton order.
    fn index(&self) -> usize;
    /// Its chunk coordinates.
    fn coord(&self) -> [u32; 3];
    /// Its first voxel (grid coordinates).
    fn origin(&self) -> [u32; 3] {
        self.coord().map(|c| c * voxlod_geom::CHUNK)
    }
    /// The grid of the chunk's triangles.
    fn grid(&self) -> &Grid;
    /// Feeds the triangles to `f` in batches, from the first, until `f` breaks; in world
    /// coordinates (as the bins hold them), for voxelizers that decide on the input's own
    /// coordinates (`ChunkVoxelizer::add_world`, `GpuVoxelizer::voxelize_chunk_streamed_world`).
    fn replay_world(
        &self,
        f: &mut dyn FnMut(&[Triangle]) -> ControlFlow<()>,
    ) -> Result<(), StageError>;
}

/// Chunk `index` of the tile stage's bins (world coordinates on `grid`).
pub(crate) struct BinChunk<'a> {
    pub bins: &'a Bins,
    /// The input, for bins of face indices (`Bins::read_chunk_from`).
    pub input: Option<&'a dyn TriangleSource>,
    pub index: usize,
    pub grid: &'a Grid,
}

impl ChunkSource for BinChunk<'_> {
    fn index(&self) -> usize {
        self.index
    }
    fn coord(&self) -> [u32; 3] {
        self.bins.chunks()[self.index].coord
    }
    fn origin(&self) -> [u32; 3] {
        self.bins.chunks()[self.index].origin()
    }
    fn grid(&self) -> &Grid {
        self.grid
    }
    fn replay_world(
        &self,
        f: &mut dyn FnMut(&[Triangle]) -> ControlFlow<()>,
    ) -> Result<(), StageError> {
        // the tile crate's callback can only stop a read with an error: a break is that
        // error carrying `ReadStopped`, recognised by its type
        let r =
            self.bins.read_chunk_from(
                self.index,
                READ_BATCH,
                self.input,
                &mut |tris| match f(tris) {
                    ControlFlow::Break(()) => Err(TileError::Callback(Box::new(ReadStopped))),
                    ControlFlow::Continue(()) => Ok(()),
                },
            );
        match r {
            Err(TileError::Callback(e)) if e.is::<ReadStopped>() => Ok(()),
            r => r.map_err(StageError::from),
        }
    }
}

/// The callback error with which [`BinChunk::replay`] ends a read early; never shown.
#[derive(Debug, thiserror::Error)]
#[error("the voxelizer stopped reading the chunk")]
struct ReadStopped;

/// A leaf chunk's result: its voxels (sorted by Morton code) and the triangles the voxelizer
/// skipped (zero area after the move to grid coordinates).
pub(crate) struct ChunkVoxels {
    pub voxels: Vec<Voxel>,
    pub skipped: u64,
    /// per-voxel materials, in a build with the material channel (CPU only)
    pub materials: Option<Vec<u32>>,
}

/// A chunk voxelizer of the voxelize stage: begins a chunk at its origin, takes its triangles
/// (once, or replayed per phase) and finishes with the chunk's voxels. Called from several
/// worker threads at once; an implementation serializes what it must.
pub(crate) trait Voxelize: Sync {
    /// Voxelizes one chunk.
    fn voxelize(&self, chunk: &dyn ChunkSource) -> Result<ChunkVoxels, StageError>;

    /// For the GPU backend, what it did over the chunks voxelized so far ([`GpuStats`]);
    /// None for the CPU.
    fn gpu_stats(&self) -> Result<Option<GpuStats>, StageError> {
        Ok(None)
    }
}

/// The CPU backend: one `ChunkVoxelizer` per worker slot (its scratch memory is reused from
/// chunk to chunk).
pub(crate) struct CpuVoxelizers {
    slots: Vec<Mutex<ChunkVoxelizer>>,
    /// the textures, to check their tile cache for read errors after each chunk
    textures: Option<Arc<TextureSet>>,
}

impl CpuVoxelizers {
    pub(crate) fn new(
        s: &BuildSettings,
        workers: usize,
        textures: Option<Arc<TextureSet>>,
        materials: bool,
    ) -> CpuVoxelizers {
        assert!(workers > 0, "at least one chunk voxelizer");
        let slots = (0..workers)
            .map(|_| {
                let mut cv = ChunkVoxelizer::new(s.mode);
                cv.set_method(s.voxelizer);
                cv.set_textures(textures.clone());
                cv.set_materials(materials);
                Mutex::new(cv)
            })
            .collect();
        CpuVoxelizers { slots, textures }
    }
}

impl Voxelize for CpuVoxelizers {
    fn voxelize(&self, chunk: &dyn ChunkSource) -> Result<ChunkVoxels, StageError> {
        let slot = rayon::current_thread_index().unwrap_or(0) % self.slots.len();
        // a panic on another chunk left this voxelizer mid-chunk: an error, not a guess
        let mut vz = self.slots[slot].lock().map_err(|_| StageError::Poisoned {
            chunk: chunk.index(),
            coord: chunk.coord(),
        })?;
        let before = vz.skipped();
        vz.begin(chunk.origin());
        let grid = *chunk.grid();
        chunk.replay_world(&mut |tris| {
            vz.add_world(&grid, tris);
            ControlFlow::Continue(())
        })?;
        let voxels = vz.finish();
        // a texture tile that could not be read gave wrong colours: the chunk fails
        if let Some(e) = self.textures.as_ref().and_then(|t| t.tiles()?.error()) {
            return Err(StageError::Other(anyhow::anyhow!(
                "voxelizing chunk {:?}: {e}",
                chunk.coord()
            )));
        }
        Ok(ChunkVoxels {
            voxels,
            skipped: vz.skipped() - before,
            materials: vz.take_materials(),
        })
    }
}

/// The GPU voxelizer and the build's running totals.
#[cfg(feature = "gpu")]
pub(crate) struct GpuRun {
    vz: voxlod_gpu::GpuVoxelizer,
    /// triangles voxelized in the classification pass / deferred to the second pass, summed
    /// over the chunks voxelized so far
    split: (u64, u64),
    /// chunks re-voxelized as a whole on the CPU (more triangles with a decision the shaders
    /// could not certify than their list holds), chunks with such a decision at all, and the
    /// triangles decided on the host for it (per chunk)
    fallback: u64,
    uncertain: u64,
    fallback_tris: u64,
}

/// The GPU backend: one device, the chunks one after another.
#[cfg(feature = "gpu")]
pub(crate) struct GpuVoxelizers(Mutex<GpuRun>);

#[cfg(feature = "gpu")]
impl Voxelize for GpuVoxelizers {
    fn voxelize(&self, chunk: &dyn ChunkSource) -> Result<ChunkVoxels, StageError> {
        let mut gpu = self.0.lock().map_err(|_| StageError::Poisoned {
            chunk: chunk.index(),
            coord: chunk.coord(),
        })?;
        let voxels = voxelize_streamed(&mut gpu.vz, chunk, u64::MAX)
            .with_context(|| format!("GPU voxelization of chunk {:?}", chunk.coord()))?;
        let (small, large) = gpu.vz.last_split();
        gpu.split.0 += small;
        gpu.split.1 += large;
        gpu.fallback += gpu.vz.last_fell_back() as u64;
        gpu.uncertain += gpu.vz.last_uncertain() as u64;
        gpu.fallback_tris += gpu.vz.last_fallback_triangles();
        Ok(ChunkVoxels {
            voxels,
            skipped: 0,
            materials: None,
        })
    }

    /// The triangles voxelized in the classification pass (small, under the cutoff) and those
    /// deferred to the second pass (the fragment pass; the sweep pass of `--gpu-method
    /// triangle`), summed over the chunks voxelized (the cutoff search not included). A
    /// triangle spanning several chunks counts once per chunk; zero-area triangles and parts
    /// outside a chunk count in neither. With them, the chunks re-voxelized on the CPU as a
    /// whole, the triangles decided on the host (per-triangle fallback) and the chunks with an
    /// uncertain decision.
    fn gpu_stats(&self) -> Result<Option<GpuStats>, StageError> {
        let g = self.0.lock().map_err(|_| {
            StageError::Other(anyhow::anyhow!(
                "the GPU voxelizer was left unusable by a panic"
            ))
        })?;
        Ok(Some(GpuStats {
            split: [g.split.0, g.split.1],
            cpu_fallback_chunks: g.fallback,
            cpu_fallback_triangles: g.fallback_tris,
            uncertain_chunks: g.uncertain,
        }))
    }
}

/// What the GPU backend did, summed over the chunks it voxelized.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct GpuStats {
    /// triangles voxelized in the classification pass / deferred to the second pass
    pub split: [u64; 2],
    /// chunks re-voxelized on the CPU as a whole
    pub cpu_fallback_chunks: u64,
    /// triangles (per chunk) decided on the host, one of their decisions being uncertain
    pub cpu_fallback_triangles: u64,
    /// chunks with a decision inside its rounding band
    pub uncertain_chunks: u64,
}

/// Triangles per read of a chunk's bins (the CPU voxelizer's batch; the GPU voxelizer
/// re-batches to its own size).
pub(crate) const READ_BATCH: usize = 64 * 1024;

/// The voxelizer of one build for `s.backend`, with a description for the summary.
/// `cpu_workers` CPU voxelizers run on `threads` threads; `bins` (with `input`, for bins of
/// face indices) is for the cutoff search.
/// A textured mesh (`textures`) runs on the CPU whatever the backend: the GPU shaders do not
/// sample textures; nor do they weigh materials (`materials`: the material channel).
#[allow(clippy::too_many_arguments)] // the bins and their input travel together to the cutoff search
pub(crate) fn select(
    s: &BuildSettings,
    cpu_workers: usize,
    threads: usize,
    bins: &Bins,
    input: Option<&dyn TriangleSource>,
    grid: &Grid,
    textures: Option<Arc<TextureSet>>,
    materials: bool,
) -> Result<(Box<dyn Voxelize>, String)> {
    let textured = textures.as_ref().map(|t| t.bytes());
    let cpu = || -> (Box<dyn Voxelize>, String) {
        let mut d = format!(
            "cpu ({cpu_workers} chunk voxelizers on {threads} threads, {})",
            s.voxelizer
        );
        if let Some(bytes) = textured {
            d += &format!(
                "; colours from textures ({:.1} MiB decoded), averaged in linear light",
                bytes as f64 / (1u64 << 20) as f64
            );
        }
        (
            Box::new(CpuVoxelizers::new(
                s,
                cpu_workers,
                textures.clone(),
                materials,
            )),
            d,
        )
    };
    if materials && textured.is_none() && s.backend != Backend::Cpu {
        let (v, d) = cpu();
        return Ok((
            v,
            format!(
                "{d}; per-voxel materials: on the CPU (the GPU shaders do not weigh materials)"
            ),
        ));
    }
    if textured.is_some() && s.backend != Backend::Cpu {
        let (v, d) = cpu();
        let why = if s.backend == Backend::Gpu {
            "--backend gpu: the GPU shaders do not sample textures, so this textured mesh ran on the CPU"
        } else {
            "textured mesh: on the CPU (the GPU shaders do not sample textures)"
        };
        return Ok((v, format!("{d}; {why}")));
    }
    // the GPU computes the overlap tests' set; the approximate method runs on the CPU only
    match (s.backend, s.voxelizer.is_exact()) {
        (Backend::Gpu, false) => anyhow::bail!(
            "--voxelizer {} runs on the CPU only (--backend cpu or auto)",
            s.voxelizer
        ),
        (Backend::Auto, false) | (Backend::Cpu, _) => return Ok(cpu()),
        _ => {}
    }
    #[cfg(feature = "gpu")]
    {
        select_gpu(s, bins, input, grid, cpu)
    }
    #[cfg(not(feature = "gpu"))]
    {
        let _ = (bins, input, grid);
        match s.backend {
            Backend::Gpu => {
                anyhow::bail!("--backend gpu: this voxlod was built without the `gpu` feature")
            }
            _ => {
                let (v, d) = cpu();
                Ok((v, format!("{d}; built without the gpu feature")))
            }
        }
    }
}

/// [`select`] for `--backend auto` or `gpu`: a hardware GPU (any adapter for `gpu`), else the
/// CPU for `auto`.
#[cfg(feature = "gpu")]
fn select_gpu(
    s: &BuildSettings,
    bins: &Bins,
    input: Option<&dyn TriangleSource>,
    grid: &Grid,
    cpu: impl Fn() -> (Box<dyn Voxelize>, String),
) -> Result<(Box<dyn Voxelize>, String)> {
    let backend = s.backend;
    let method = s.gpu_method;
    let fixed = match s.cutoff {
        Cutoff::Fixed(c) => c,
        Cutoff::Auto => DEFAULT_CUTOFF,
    };
    if backend == Backend::Auto {
        // no GPU device node: any adapter would be a software one, which auto does not take;
        // nothing of Vulkan is loaded to learn that
        if !crate::system::may_have_gpu() {
            let (v, d) = cpu();
            return Ok((
                v,
                format!("{d}; no GPU device (/dev/dri/renderD*, /dev/nvidia*, /dev/dxg), no adapter probed (--backend gpu uses a software one)"),
            ));
        }
        // decide from the adapter alone: creating the device and its pipelines
        // costs half a second on lavapipe, for an adapter auto would not use
        match voxlod_gpu::probe_adapter() {
            Err(e) => {
                let (v, d) = cpu();
                return Ok((v, format!("{d}; no GPU: {e}")));
            }
            Ok(a) if a.software => {
                let (v, d) = cpu();
                return Ok((
                    v,
                    format!(
                        "{d}; skipped the software GPU adapter {} (--backend gpu forces it)",
                        a.name
                    ),
                ));
            }
            Ok(_) => {}
        }
    }
    let mut gpu = match voxlod_gpu::GpuVoxelizer::new(s.mode, method, fixed) {
        Ok(g) => g,
        Err(e) if backend == Backend::Auto => {
            let (v, d) = cpu();
            return Ok((v, format!("{d}; no GPU: {e}")));
        }
        Err(e) => return Err(e).context("--backend gpu"),
    };
    let mut desc = format!("gpu {} ({method}", gpu.adapter_name());
    if method == voxlod_gpu::GpuMethod::Hybrid {
        let c = match s.cutoff {
            Cutoff::Fixed(c) => c,
            Cutoff::Auto => search_cutoff(&mut gpu, bins, input, grid)?,
        };
        gpu.set_method(method, c);
        desc += &format!(
            ", cutoff {c} voxels²{}",
            if s.cutoff == Cutoff::Auto {
                " found by search"
            } else {
                ""
            }
        );
    }
    // the contract of the voxel sets (crates/gpu docs, "Exactness")
    desc += match gpu.precision() {
        voxlod_gpu::shaders::Precision::F64 => ", f64: exact sets, uncertain triangles on the CPU)",
        voxlod_gpu::shaders::Precision::F32 => ", f32: exact sets, uncertain triangles on the CPU)",
    };
    let run = GpuRun {
        vz: gpu,
        split: (0, 0),
        fallback: 0,
        uncertain: 0,
        fallback_tris: 0,
    };
    Ok((Box::new(GpuVoxelizers(Mutex::new(run))), desc))
}

/// Voxelizes the first `limit` triangles of `chunk` on the GPU, streaming them from the bins
/// file (replayed once per GPU phase), so that only bounded batches are in memory whatever
/// the chunk's size. The bins' world coordinates go to the GPU voxelizer as they are: its sets
/// are exact for them, as the CPU backend's (`add_world`).
#[cfg(feature = "gpu")]
fn voxelize_streamed(
    gpu: &mut voxlod_gpu::GpuVoxelizer,
    chunk: &dyn ChunkSource,
    limit: u64,
) -> Result<Vec<Voxel>> {
    let grid = *chunk.grid();
    gpu.voxelize_chunk_streamed_world(&grid, chunk.origin(), &mut |feed: &mut voxlod_gpu::Feed<
        '_,
    >| {
        let mut left = limit;
        chunk
            .replay_world(&mut |tris| {
                let n = (tris.len() as u64).min(left) as usize;
                feed(&tris[..n]);
                left -= n as u64;
                // ends the read early once `limit` triangles were fed
                if left == 0 {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            })
            .map_err(anyhow::Error::from)
    })
}

/// `--cutoff auto`: times the hybrid on the chunk with the most triangles (its first 256Ki)
/// at cutoffs 1, 4, 16, 64, 256 voxels², then at the geometric midpoints around the fastest,
/// and returns the fastest (the paper's suggested future work). The voxels do not depend on
/// the cutoff, so neither does the output file.
#[cfg(feature = "gpu")]
fn search_cutoff(
    gpu: &mut voxlod_gpu::GpuVoxelizer,
    bins: &Bins,
    input: Option<&dyn TriangleSource>,
    grid: &Grid,
) -> Result<f32> {
    let Some(i) = (0..bins.chunks().len()).max_by_key(|&i| bins.chunks()[i].count) else {
        return Ok(DEFAULT_CUTOFF);
    };
    let mut time = |c: f32| -> Result<f64> {
        gpu.set_method(voxlod_gpu::GpuMethod::Hybrid, c);
        let t = std::time::Instant::now();
        voxelize_streamed(
            gpu,
            &BinChunk {
                bins,
                input,
                index: i,
                grid,
            },
            256 * 1024,
        )
        .context("timing a cutoff")?;
        Ok(t.elapsed().as_secs_f64())
    };
    time(DEFAULT_CUTOFF)?; // warm-up: pipelines, buffers
    let mut best = (f64::INFINITY, DEFAULT_CUTOFF);
    for c in [1.0f32, 4.0, 16.0, 64.0, 256.0] {
        let t = time(c)?;
        if t < best.0 {
            best = (t, c);
        }
    }
    for c in [best.1 * 0.5, best.1 * 2.0] {
        let t = time(c)?;
        if t < best.0 {
            best = (t, c);
        }
    }
    Ok(best.1)
}
