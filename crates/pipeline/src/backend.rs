//! Which voxelizer runs the chunks: the CPU `ChunkVoxelizer` on every core, or the GPU hybrid
//! voxelizer (`voxlod-gpu`, feature `gpu`), and the GPU cutoff search.

use std::sync::Mutex;

use anyhow::{Context, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use voxlod_format::Voxel;
use voxlod_tile::Bins;
use voxlod_voxelize::{ChunkVoxelizer, Method, Mode};

/// `--backend`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// A hardware GPU when one is found, else the CPU (a software rasterizer such as lavapipe
    /// is slower than the CPU backend, so `auto` does not pick it).
    #[default]
    Auto,
    /// The CPU chunk voxelizer on every core.
    Cpu,
    /// Any adapter, software ones included; an error when there is none.
    Gpu,
}

impl std::str::FromStr for Backend {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(Backend::Auto),
            "cpu" => Ok(Backend::Cpu),
            "gpu" => Ok(Backend::Gpu),
            _ => Err(format!("unknown backend '{s}' (auto, cpu or gpu)")),
        }
    }
}

impl std::fmt::Display for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Backend::Auto => "auto",
            Backend::Cpu => "cpu",
            Backend::Gpu => "gpu",
        })
    }
}

/// `--cutoff`: the projected area (voxels²) from which the GPU hybrid defers a triangle to the
/// fragment pass, or `auto` for a short bracketing search on the build's largest chunk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Cutoff {
    /// Search a cutoff on the build's largest chunk.
    Auto,
    /// This cutoff, voxels².
    Fixed(f32),
}

impl Default for Cutoff {
    fn default() -> Self {
        Cutoff::Fixed(DEFAULT_CUTOFF)
    }
}

/// The GPU crate's default (a few voxels², as the paper finds best).
pub const DEFAULT_CUTOFF: f32 = 8.0;

impl std::str::FromStr for Cutoff {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(Cutoff::Auto);
        }
        match s.parse::<f32>() {
            Ok(v) if v.is_finite() && v >= 0.0 => Ok(Cutoff::Fixed(v)),
            _ => Err(format!(
                "cutoff '{s}' is not 'auto' or a non-negative number of voxels²"
            )),
        }
    }
}

impl std::fmt::Display for Cutoff {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Cutoff::Auto => f.write_str("auto"),
            Cutoff::Fixed(v) => write!(f, "{v}"),
        }
    }
}

impl Serialize for Cutoff {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> Deserialize<'de> for Cutoff {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum V {
            N(f32),
            S(String),
        }
        match V::deserialize(d)? {
            V::N(n) => format!("{n}").parse().map_err(serde::de::Error::custom),
            V::S(s) => s.parse().map_err(serde::de::Error::custom),
        }
    }
}

/// The voxelizers of one build.
pub(crate) enum Voxelizers {
    Cpu(Vec<Mutex<ChunkVoxelizer>>),
    #[cfg(feature = "gpu")]
    Gpu(Box<Mutex<GpuRun>>),
}

/// The GPU voxelizer and the build's running totals.
#[cfg(feature = "gpu")]
pub(crate) struct GpuRun {
    vz: voxlod_gpu::GpuVoxelizer,
    /// triangles voxelized in the classification pass / deferred to the second pass, summed
    /// over the chunks voxelized so far
    split: (u64, u64),
    /// chunks re-voxelized on the CPU (a decision the shaders could not certify), and chunks
    /// with such a decision at all (in f32 mostly counted as inside: a conservative superset)
    fallback: u64,
    uncertain: u64,
}

/// What the GPU backend did, summed over the chunks `Voxelizers::run` voxelized.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct GpuStats {
    /// triangles voxelized in the classification pass / deferred to the second pass
    pub split: [u64; 2],
    /// chunks re-voxelized on the CPU
    pub cpu_fallback_chunks: u64,
    /// chunks with a decision inside its rounding band
    pub uncertain_chunks: u64,
}

/// Triangles per read of a chunk's bins (the CPU voxelizer's batch; the GPU voxelizer
/// re-batches to its own size).
const READ_BATCH: usize = 64 * 1024;

/// Result of one chunk: its voxels and the triangles the voxelizer skipped.
pub(crate) type ChunkResult = Result<(Vec<Voxel>, u64)>;

impl Voxelizers {
    /// Creates the voxelizers for `backend`; returns them with a description for the summary
    /// and any warning.
    #[allow(unused_variables, clippy::too_many_arguments)]
    pub(crate) fn new(
        backend: Backend,
        mode: Mode,
        method: Method,
        cpu_workers: usize,
        threads: usize,
        gpu_method: &str,
        cutoff: Cutoff,
        bins: &Bins,
        textures: Option<std::sync::Arc<voxlod_texture::TextureSet>>,
    ) -> Result<(Voxelizers, String)> {
        let textured = textures.as_ref().map(|t| t.bytes());
        let cpu = || {
            let v = Voxelizers::Cpu(
                (0..cpu_workers)
                    .map(|_| {
                        let mut cv = ChunkVoxelizer::new(mode);
                        cv.set_method(method);
                        cv.set_textures(textures.clone());
                        Mutex::new(cv)
                    })
                    .collect(),
            );
            let mut d =
                format!("cpu ({cpu_workers} chunk voxelizers on {threads} threads, {method})");
            if let Some(bytes) = textured {
                d += &format!(
                    "; colours from textures ({:.1} MiB decoded), averaged in linear light",
                    bytes as f64 / (1u64 << 20) as f64
                );
            }
            (v, d)
        };
        // the GPU shaders do not sample textures: a textured mesh is voxelized on the CPU
        if textured.is_some() && backend != Backend::Cpu {
            let (v, d) = cpu();
            let why = if backend == Backend::Gpu {
                "--backend gpu: the GPU shaders do not sample textures, so this textured mesh ran on the CPU"
            } else {
                "textured mesh: on the CPU (the GPU shaders do not sample textures)"
            };
            return Ok((v, format!("{d}; {why}")));
        }
        // the GPU computes the overlap tests' set; the approximate method runs on the CPU only
        match (backend, method.is_exact()) {
            (Backend::Gpu, false) => {
                anyhow::bail!("--voxelizer {method} runs on the CPU only (--backend cpu or auto)")
            }
            (Backend::Auto, false) => return Ok(cpu()),
            _ => {}
        }
        match backend {
            Backend::Cpu => Ok(cpu()),
            #[cfg(feature = "gpu")]
            Backend::Auto | Backend::Gpu => {
                let method: voxlod_gpu::GpuMethod =
                    gpu_method
                        .parse()
                        .map_err(|e: voxlod_gpu::ParseMethodError| {
                            anyhow::anyhow!("--gpu-method: {}", e.0)
                        })?;
                let fixed = match cutoff {
                    Cutoff::Fixed(c) => c,
                    Cutoff::Auto => DEFAULT_CUTOFF,
                };
                if backend == Backend::Auto {
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
                let gpu = match voxlod_gpu::GpuVoxelizer::new(mode, method, fixed) {
                    Ok(g) => g,
                    Err(e) if backend == Backend::Auto => {
                        let (v, d) = cpu();
                        return Ok((v, format!("{d}; no GPU: {e}")));
                    }
                    Err(e) => return Err(e).context("--backend gpu"),
                };
                let mut gpu = gpu;
                let mut desc = format!("gpu {} ({method}", gpu.adapter_name());
                if method == voxlod_gpu::GpuMethod::Hybrid {
                    let c = match cutoff {
                        Cutoff::Fixed(c) => c,
                        Cutoff::Auto => search_cutoff(&mut gpu, bins)?,
                    };
                    gpu.set_method(method, c);
                    desc += &format!(
                        ", cutoff {c} voxels²{}",
                        if cutoff == Cutoff::Auto {
                            " found by search"
                        } else {
                            ""
                        }
                    );
                }
                // the contract of the voxel sets (crates/gpu docs, "Exactness")
                desc += match gpu.precision() {
                    voxlod_gpu::shaders::Precision::F64 => {
                        ", f64: exact sets, uncertain chunks on the CPU)"
                    }
                    voxlod_gpu::shaders::Precision::F32 => ", f32: conservative superset)",
                };
                Ok((
                    Voxelizers::Gpu(Box::new(Mutex::new(GpuRun {
                        vz: gpu,
                        split: (0, 0),
                        fallback: 0,
                        uncertain: 0,
                    }))),
                    desc,
                ))
            }
            #[cfg(not(feature = "gpu"))]
            Backend::Auto => {
                let (v, d) = cpu();
                Ok((v, format!("{d}; built without the gpu feature")))
            }
            #[cfg(not(feature = "gpu"))]
            Backend::Gpu => {
                anyhow::bail!("--backend gpu: this voxlod was built without the `gpu` feature")
            }
        }
    }

    /// Voxelizes chunks `range` of `bins`: in parallel on the CPU, one after another on the GPU.
    pub(crate) fn run(
        &self,
        pool: &rayon::ThreadPool,
        bins: &Bins,
        range: std::ops::Range<usize>,
    ) -> Vec<ChunkResult> {
        let chunks = bins.chunks();
        match self {
            Voxelizers::Cpu(workers) => pool.install(|| {
                range
                    .into_par_iter()
                    .map(|i| {
                        let slot = rayon::current_thread_index().unwrap_or(0) % workers.len();
                        let mut vz = workers[slot].lock().unwrap_or_else(|p| p.into_inner());
                        let before = vz.skipped();
                        vz.begin(chunks[i].origin());
                        bins.read_chunk(i, READ_BATCH, &mut |tris| {
                            vz.add(tris);
                            Ok(())
                        })?;
                        let voxels = vz.finish();
                        Ok((voxels, vz.skipped() - before))
                    })
                    .collect()
            }),
            #[cfg(feature = "gpu")]
            Voxelizers::Gpu(gpu) => {
                let mut gpu = gpu.lock().unwrap_or_else(|p| p.into_inner());
                range
                    .map(|i| {
                        let voxels = voxelize_streamed(&mut gpu.vz, bins, i, u64::MAX)
                            .with_context(|| {
                                format!("GPU voxelization of chunk {:?}", chunks[i].coord)
                            })?;
                        let (small, large) = gpu.vz.last_split();
                        gpu.split.0 += small;
                        gpu.split.1 += large;
                        gpu.fallback += gpu.vz.last_fell_back() as u64;
                        gpu.uncertain += gpu.vz.last_uncertain() as u64;
                        Ok((voxels, 0))
                    })
                    .collect()
            }
        }
    }

    /// For the GPU backend, the triangles voxelized in the classification pass (small, under
    /// the cutoff) and those deferred to the second pass (the fragment pass; the sweep pass of
    /// `--gpu-method triangle`), summed over the chunks `run` has voxelized (the cutoff search
    /// not included). A triangle spanning several chunks counts once per chunk; zero-area
    /// triangles and parts outside a chunk count in neither. With them, the chunks re-voxelized
    /// on the CPU and those with an uncertain decision. None for the CPU backend.
    pub(crate) fn gpu_stats(&self) -> Option<GpuStats> {
        match self {
            Voxelizers::Cpu(_) => None,
            #[cfg(feature = "gpu")]
            Voxelizers::Gpu(gpu) => {
                let g = gpu.lock().unwrap_or_else(|p| p.into_inner());
                Some(GpuStats {
                    split: [g.split.0, g.split.1],
                    cpu_fallback_chunks: g.fallback,
                    uncertain_chunks: g.uncertain,
                })
            }
        }
    }
}

/// Voxelizes the first `limit` triangles of chunk `i` of `bins` on the GPU, streaming them
/// from the bins file (replayed once per GPU phase), so that only bounded batches are in
/// memory whatever the chunk's size.
#[cfg(feature = "gpu")]
fn voxelize_streamed(
    gpu: &mut voxlod_gpu::GpuVoxelizer,
    bins: &Bins,
    i: usize,
    limit: u64,
) -> Result<Vec<Voxel>> {
    /// Ends a read early once `limit` triangles were fed (not an error).
    const ENOUGH: &str = "voxlod: enough triangles read";
    let origin = bins.chunks()[i].origin();
    gpu.voxelize_chunk_streamed(origin, &mut |feed: &mut voxlod_gpu::Feed<'_>| {
        let mut left = limit;
        let r = bins.read_chunk(i, READ_BATCH, &mut |tris| {
            let n = (tris.len() as u64).min(left) as usize;
            feed(&tris[..n]);
            left -= n as u64;
            if left == 0 {
                return Err(voxlod_tile::TileError::Callback(ENOUGH.to_string()));
            }
            Ok(())
        });
        match r {
            Err(voxlod_tile::TileError::Callback(m)) if m == ENOUGH => Ok(()),
            r => r.map_err(anyhow::Error::from),
        }
    })
}

/// `--cutoff auto`: times the hybrid on the chunk with the most triangles (its first 256Ki)
/// at cutoffs 1, 4, 16, 64, 256 voxels², then at the geometric midpoints around the fastest,
/// and returns the fastest (the paper's suggested future work). The voxels do not depend on
/// the cutoff, so neither does the output file.
#[cfg(feature = "gpu")]
fn search_cutoff(gpu: &mut voxlod_gpu::GpuVoxelizer, bins: &Bins) -> Result<f32> {
    let Some(i) = (0..bins.chunks().len()).max_by_key(|&i| bins.chunks()[i].count) else {
        return Ok(DEFAULT_CUTOFF);
    };
    let mut time = |c: f32| -> Result<f64> {
        gpu.set_method(voxlod_gpu::GpuMethod::Hybrid, c);
        let t = std::time::Instant::now();
        voxelize_streamed(gpu, bins, i, 256 * 1024).context("timing a cutoff")?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_settings() {
        assert_eq!("gpu".parse::<Backend>(), Ok(Backend::Gpu));
        assert!("tpu".parse::<Backend>().is_err());
        assert_eq!("auto".parse::<Cutoff>(), Ok(Cutoff::Auto));
        assert_eq!("2.5".parse::<Cutoff>(), Ok(Cutoff::Fixed(2.5)));
        assert!("-1".parse::<Cutoff>().is_err());
        #[derive(Deserialize)]
        struct T {
            c: Cutoff,
            b: Backend,
        }
        let t: T = toml::from_str("c = 16\nb = \"cpu\"").unwrap();
        assert_eq!((t.c, t.b), (Cutoff::Fixed(16.0), Backend::Cpu));
        let t: T = toml::from_str("c = \"auto\"\nb = \"auto\"").unwrap();
        assert_eq!((t.c, t.b), (Cutoff::Auto, Backend::Auto));
    }
}
