//! GPU surface voxelization of 256³ chunks: the hybrid voxelizer of Rauwendaal & Bailey,
//! "Hybrid Computational Voxelization Using the Graphics Pipeline", JCGT 2(1) 2013, on wgpu.
//!
//! Per chunk ([`GpuVoxelizer::voxelize_chunk`], the same contract as
//! `voxlod_voxelize::ChunkVoxelizer`):
//! 1. **Classification** (compute, one invocation per triangle, paper 3.4.2 / Figure 15): the
//!    per-triangle setup of the factored overlap tests; a triangle whose dominant projected area
//!    is below the *cutoff* is voxelized right there (triangle-parallel, 3.2), a larger one is
//!    appended to the deferred list with its dilated, swizzled 2D triangle (Hertel's dilation,
//!    3.3.2), and the indirect draw arguments of the next pass are written.
//! 2. **Fragment pass** (render, `draw_indirect` over the deferred triangles only, 3.3): a
//!    256×256 viewport of the chunk's columns; each fragment runs the rest of the overlap test
//!    for its column. Both passes set bits of a 256³ occupancy bitset.
//! 3. **Compaction** (3.5): every occupied voxel gets a slot (an atomic counter per bitset word).
//! 4. **Accumulation**: passes 1 and 2 again, now adding each (triangle, voxel) pair's clipped
//!    area and its area-weighted normal and colour into the voxel's slot as 64-bit fixed-point
//!    integers, so the sums do not depend on thread order.
//! 5. Read-back and encoding on the CPU, voxels sorted by Morton code.
//!
//! **Bounded memory.** [`GpuVoxelizer::voxelize_chunk_streamed`] takes a callback that replays
//! the chunk's triangles in batches of any size (once for marking, once more per accumulation
//! window when the chunk needs several GPU batches), so a chunk of tens of millions of
//! triangles never sits in host memory: the voxelizer re-batches to
//! [`GpuVoxelizer::batch_size`] triangles, uploads batch k+1 into the second of two triangle
//! buffers while the device runs batch k, and waits only for the batch whose buffer it reuses
//! and where results are read back. The second pass of a batch is left out when the host sees
//! every triangle stays in the classification pass. [`GpuVoxelizer::last_split`] reports the
//! chunk's small/large split. On lavapipe the parameters live in a storage buffer: uniform
//! values are inlined by Mesa's lavapipe, which recompiled the classification pass per batch.
//!
//! The overlap tests, clipping and attribute rules are those of `voxlod-voxelize` (see its crate
//! docs), operation for operation; with `SHADER_F64` (lavapipe, most desktop Vulkan drivers) the
//! shaders compute in f64 like the CPU's fast path, otherwise in f32. [`GpuMethod`] selects
//! hybrid, triangle-only or fragment-only voxelization (same voxels, different speed).
//!
//! **Exactness.** The CPU voxelizer decides every overlap exactly (an f64 filter with a proven
//! per-triangle error bound and Shewchuk's exact predicates inside it,
//! `voxlod_voxelize::overlap`, `TriSetup::new`). The shaders evaluate the same bounds (with the
//! unit roundoff of their float type: 2⁻⁵³, or 2⁻²⁴ in f32) and trust a decision's sign only
//! outside its band. Two cases are certified on the GPU itself (f64 shaders): a triangle whose
//! coordinates lie on a coarse dyadic grid (multiples of 2⁻q with `(max|v| + 2)·2^q < 2²⁴`: the
//! edge functions and the normal are computed without rounding; below 2¹⁴ the depth predicates
//! too; the host flags such triangles), where the computed value is exact and `f ≥ 0` decides,
//! and a face in an axis plane `z = c`, whose depth range is the integer test `z ≤ c ≤ z + 1`;
//! ties count as inside, as on the CPU (block worlds, faces on the grid's boundary planes). Every other decision inside its band, and a
//! normal component of doubtful sign, *lists the triangle*: the uncertain decision counts as
//! outside (so the GPU marks a subset of the triangle's exact set), and the triangle's index
//! goes to a list (at most 65,536 per chunk). After the marking pass the host decides the
//! listed triangles with the CPU's exact test (`voxlod_voxelize::voxelize_triangle`; the replay
//! callback feeds them), sets their voxels in the occupancy bitset before compaction, and adds
//! their attribute contributions to the GPU's fixed-point sums (integer additions: the result
//! does not depend on the order); the accumulation pass skips them. So the voxel sets equal the
//! exact CPU sets, with f64 and with f32 shaders (f32 lists many more triangles: its bands are
//! 2²⁹ times wider). Only a chunk with more listed triangles than the list holds is re-voxelized
//! as a whole on the CPU (`voxlod_voxelize::ChunkVoxelizer`, same mode).
//!
//! **Exact for the input's own coordinates** (the voxelize crate's docs say what that promises).
//! [`GpuVoxelizer::voxelize_chunk_world`] and [`GpuVoxelizer::voxelize_chunk_streamed_world`]
//! (what a build uses: its bins hold the input's world positions) take triangles in world
//! coordinates of a [`voxlod_geom::Grid`] and give the set `ChunkVoxelizer::add_world` gives:
//! every decision exact for the world f32 positions and the grid's f64 origin and voxel size as
//! stated, not for their f32 grid coordinates `g̃ = Grid::to_grid(p)`, which the shaders still
//! compute on. The host moves each triangle to the grid and flags what the rounding did
//! (`fallback.rs` `world_flags`): if every `g̃` is exactly the image `(p − origin)/voxel_size`
//! (checked exactly: an FMA and a two-sum), every decision on `g̃` is the world's (a
//! translation and a positive scale) and the shaders decide as above, certificates included;
//! otherwise (`TRI_ROUNDED`) each `g̃` is within `η = 2⁻²³·M + 2⁻¹⁴⁰` of its exact image (`M`
//! the triangle's largest grid coordinate), and the shaders widen every band by what `η` can
//! move that value (`voxlod_voxelize::world::Perturbation`, the CPU's derivation: `dn` for a
//! normal component, `de` for an edge function, `dp` for a depth predicate), take no
//! certificate, dilate the fragment pass's triangle by `1.5η` more, and list the triangle where
//! the rounding can flip a decision that is not continuous in the coordinates: a bounding box
//! end or an axis-plane face that `g̃` puts exactly on an integer (`to_grid` is monotone and keeps
//! integers, so a coordinate off an integer is on the same side of every integer as its exact
//! image). Two vertices that share a `g̃` coordinate but not the world value (`TRI_TIES_BROKEN`)
//! list the triangle too: a normal component whose products are all zero must be zero in the
//! world as well. The host decides listed triangles on world coordinates
//! (`voxlod_voxelize::voxelize_world_triangle`, the set `add_world` marks), a chunk whose list
//! overflows with `ChunkVoxelizer::add_world`; the attributes come from `g̃`, as on the CPU.
//! [`GpuVoxelizer::voxelize_chunk`] and [`GpuVoxelizer::voxelize_chunk_streamed`] take grid
//! coordinates and are exact for those (what `ChunkVoxelizer::add` decides).

//! [`GpuVoxelizer::last_uncertain`], [`GpuVoxelizer::last_fallback_triangles`] and
//! [`GpuVoxelizer::last_fell_back`] report them per chunk.
//!
//! **Attributes.** The GPU sums each voxel's area-weighted normal and colour in 96-bit fixed
//! point (exact, so independent of the order of the atomics); the CPU sums in f32 with a
//! proven bound. Both are within one quantization step of the exact means, so a voxel's normal
//! from the GPU is within one 10-bit step per component of the CPU's, and its colour within one
//! unit per channel, except where the normals inside one voxel nearly cancel (opposite faces in
//! one voxel, `|Σ w·n| ≪ Σ w`): there the direction is rounding noise in either sum, and normals
//! and face masks may differ arbitrarily. Face masks follow each file's own normals and border
//! caps. Byte-identical attributes would need the CPU's sequential f32 rounding on the GPU.

//! # Example
//!
//! ```
//! use voxlod_geom::Triangle;
//! use voxlod_gpu::{GpuMethod, GpuVoxelizer, DEFAULT_CUTOFF};
//! use voxlod_voxelize::{ChunkVoxelizer, Mode};
//!
//! let mut gpu = GpuVoxelizer::new(Mode::Conservative, GpuMethod::Hybrid, DEFAULT_CUTOFF)
//!     .expect("no GPU adapter (install mesa-vulkan-drivers for lavapipe)");
//! // a triangle in the plane z = 2.5 covering the lower-left half of [0,2]²
//! let t = Triangle::new([[0.0, 0.0, 2.5], [2.0, 0.0, 2.5], [0.0, 2.0, 2.5]]);
//! let voxels = gpu.voxelize_chunk([0, 0, 0], &[t]).unwrap();
//! // every voxel the closed triangle touches, the CPU reference's set (attributes within one
//! // quantization step; here exactly equal)
//! let mut cpu = ChunkVoxelizer::new(Mode::Conservative);
//! cpu.begin([0, 0, 0]);
//! cpu.add(&[t]);
//! let want = cpu.finish();
//! let pos = |v: &[voxlod_format::Voxel]| v.iter().map(|v| v.pos()).collect::<Vec<_>>();
//! assert_eq!(pos(&voxels), pos(&want));
//! assert_eq!(voxels.len(), 6); // columns (0,0) (1,0) (0,1) (1,1) (2,0) (0,2) at z = 2
//! assert_eq!(voxels[0].pos(), [0, 0, 2]);
//! assert_eq!(voxels[0].normal_f32(), [0.0, 0.0, 1.0]);
//! // the same chunk streamed: the callback replays the chunk's triangles (here in one piece)
//! let streamed = gpu
//!     .voxelize_chunk_streamed([0, 0, 0], &mut |feed: &mut voxlod_gpu::Feed<'_>| {
//!         feed(&[t]);
//!         Ok::<(), voxlod_gpu::GpuError>(())
//!     })
//!     .unwrap();
//! assert_eq!(streamed, voxels);
//! assert_eq!(gpu.last_split(), (1, 0)); // small: voxelized in the classification pass
//! // world coordinates of a grid (what a build feeds from its bins): add_world's set
//! let grid = voxlod_geom::Grid::new([0.1, -0.3, 2.0], 25.6, 256).unwrap(); // voxel size 0.1
//! // grid coordinates (2.5, 0.7, 2.5), (4.5, 0.7, 2.5), (2.5, 2.7, 2.5), up to rounding
//! let w = Triangle::new([[0.35, -0.23, 2.25], [0.55, -0.23, 2.25], [0.35, -0.03, 2.25]]);
//! let got = gpu.voxelize_chunk_world(&grid, [0, 0, 0], &[w]).unwrap();
//! cpu.begin([0, 0, 0]);
//! cpu.add_world(&grid, &[w]);
//! assert_eq!(pos(&got), pos(&cpu.finish()));
//! assert_eq!(got.len(), 8); // columns x 2..=4, y 0..=2 with x + y ≤ 5, at z = 2
//! ```

pub mod bindings;
mod device;
mod encode;
mod fallback;
pub mod shaders;
mod voxelizer;

pub use device::{open_device, open_device_for_surface, probe_adapter, AdapterProbe, Gpu};
pub use shaders::Precision;
pub use voxelizer::{Feed, GpuVoxelizer};

/// Default cutoff (voxels² of dominant projected area) between triangles voxelized in the
/// classification pass and triangles deferred to the fragment pass. The paper finds "a few
/// voxels²" best on a GTX 480. On lavapipe (2 loaded cores, thin mode, one 256³ chunk,
/// examples/gpu_bench.rs) hybrid at 8 took 2.9 s on bun_zipper against 3.8 s at 4 and 10.5 s at
/// 2; Dabrovic Sponza kept improving up to 16-128 (8.9 s at 16, 11.6 s at 8). The measurements
/// are noisy (other builds were running); an automatic cutoff search is still to do.
pub const DEFAULT_CUTOFF: f32 = 8.0;

/// Which GPU voxelization scheme to run (paper section 3); defined beside the CPU's
/// `Method` so that the settings and this crate share one type.
pub use voxlod_voxelize::{GpuMethod, ParseGpuMethodError};

/// Why the GPU voxelizer failed.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No usable adapter (no GPU and no software Vulkan/GL driver such as lavapipe).
    #[error("no GPU adapter: {0} (on Debian/Ubuntu, `apt-get install mesa-vulkan-drivers libvulkan1` provides lavapipe)")]
    NoAdapter(String),
    /// The adapter refused to create a device.
    #[error("cannot create the GPU device on {adapter}: {reason}")]
    Device {
        /// The GPU adapter's name.
        adapter: String,
        /// What the driver or wgpu reported.
        reason: String,
    },
    /// A wgpu validation or out-of-memory error.
    #[error("GPU error on {adapter}: {reason}")]
    Wgpu {
        /// The GPU adapter's name.
        adapter: String,
        /// What the driver or wgpu reported.
        reason: String,
    },
    /// Reading a buffer back failed (device lost, or polling failed).
    #[error("GPU read-back failed on {adapter}: {reason}")]
    Readback {
        /// The GPU adapter's name.
        adapter: String,
        /// What the driver or wgpu reported.
        reason: String,
    },
    /// Some occupied voxels received no attributes in the accumulation pass: a shader
    /// invocation was cut short by the driver (lavapipe stops an invocation after 65535 loop
    /// iterations). A bug of this crate if it ever happens.
    #[error("GPU voxelization incomplete on {adapter}: {voxels} marked voxels got no attributes")]
    Incomplete {
        /// The GPU adapter's name.
        adapter: String,
        /// Marked voxels that got no attributes.
        voxels: usize,
    },
    /// A replay of [`GpuVoxelizer::voxelize_chunk_streamed`] yielded a different number of
    /// (finite) triangles than the first one.
    #[error("the chunk's triangles were replayed differently: {first} triangles, then {again}")]
    Replay {
        /// Triangles in the first replay.
        first: u64,
        /// Triangles in the later replay.
        again: u64,
    },
    /// The chunk origin is not a multiple of 256 or too large for the i32 coordinates of the
    /// shaders.
    #[error("chunk origin {0:?} is not a multiple of {chunk} below 2^31", chunk = voxlod_geom::CHUNK)]
    Origin([u32; 3]),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn method_strings_roundtrip() {
        for m in [GpuMethod::Hybrid, GpuMethod::Triangle, GpuMethod::Fragment] {
            assert_eq!(m.to_string().parse::<GpuMethod>(), Ok(m));
        }
        assert!("Hybrid".parse::<GpuMethod>().is_err());
    }
}
