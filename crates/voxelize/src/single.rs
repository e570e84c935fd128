//! Skipping the clip where it cannot change the record: voxels with a single contribution of a
//! triangle with flat attributes. The records are the area-weighted averages of Chajdas,
//! Reitinger & Westermann, "Scalable rendering for very large meshes", WSCG 2014, section 3
//! (the weights: [`crate::clip`]).
//!
//! A voxel's record depends on its sums `W = Σ wᵢ`, `N = Σ wᵢ·nᵢ`, `C = Σ wᵢ·cᵢ` only through
//! `N/|N|` (the packed normal) and `C/W` (or, if `W = 0`, the unweighted means). With **one**
//! contribution these are `n₁/|n₁|` and `c₁` whatever the weight `w₁ ≥ 0` is. The clipped area
//! matters there only through the interpolation point (the clipped part's centroid), and not
//! at all for a triangle with **flat attributes** (`is_flat`): no vertex normals (the unit face
//! normal everywhere), one colour at all three vertices, no texture. Then the record is the
//! triangle's face normal and colour, and the voxel's material the triangle's. Scans, CAD and
//! city meshes without vertex colours are flat throughout (the dragon, both bunnies, the
//! conference room, Munich).
//!
//! So the chunk voxelizer runs in two passes: [`ChunkVoxelizer::add`] only marks (the exact
//! voxel set of every triangle, a contribution count per voxel, and the (triangle, voxel) pairs
//! in scan order); [`ChunkVoxelizer::finish`] then adds the contributions in triangle order,
//! giving a pair weight 1 and the triangle's `flat_values` where the voxel's count is 1 and the
//! triangle is flat, and clipping every other pair as before (the column sweeps of
//! [`crate::column`], resumed at any column and layer, bit for bit what clipping every voxel
//! gives). A triangle none of whose voxels needs a clip is not set up at all.
//!
//! **What changes.** Voxels with two or more contributions: nothing (the same weights and
//! values, added in the same order; `tests/single.rs` checks bit equality with
//! [`ChunkVoxelizer::set_single_skip`]`(false)`). Voxels with one contribution of a flat
//! triangle: the sums are `x` instead of `fl(w·x)`. The colour `fl(fl(w·c)·fl(1/w))` of the
//! clipped path is within `3u·c < 5e-5` (`u = 2⁻²⁴`) of the integer `c`, so it rounds to `c`
//! like the new one: colours never change. The normal is packed from `n` instead of from the
//! three products `fl(w·nⱼ)`, each within a relative `u` of `w·nⱼ`: the packed components
//! `round(511·nⱼ/|n|)` can move by at most one step, and only where `511·nⱼ/|n|` lies within
//! about `1e-4` of a rounding half (or where `w·nⱼ` underflows f32, `w < 1e-30`, where the
//! clipped path loses the direction and the new one keeps it). Both are within one step of the
//! exact definition. Textured builds, and triangles with vertex normals or differing vertex
//! colours, keep the clip (their value at the centroid depends on the clipped part).
//!
//! Cost: the pairs take 8 bytes each and the marked triangles one [`Triangle`] each, per chunk,
//! beside the 40-byte accumulator per voxel; a chunk whose kept pairs and triangles pass
//! [`crate::chunk::DEFER_BYTES`] (32 MiB) clips every pair instead, so memory stays bounded by
//! the chunk's voxels, not its triangles.

use voxlod_geom::{Triangle, TRI_HAS_NORMALS};

use crate::interp::values;
use crate::overlap::{cross_f64, to_f64};

#[cfg(doc)]
use crate::ChunkVoxelizer;

/// Whether `t`'s normal and colour are the same at every point (without textures): no vertex
/// normals and one colour at its three vertices.
#[inline]
pub(crate) fn is_flat(t: &Triangle) -> bool {
    t.flags & TRI_HAS_NORMALS == 0 && t.c[0] == t.c[1] && t.c[1] == t.c[2]
}

/// The values `[n_x, n_y, n_z, 1, r, g, b, a]` of a flat triangle (`is_flat`) at every point:
/// bit for bit what the interpolation (`interp::Interp::at`) gives it at any point (the unit
/// face normal `n/|n|`, computed the same way, and the colour: its gradients are zero).
#[inline]
pub(crate) fn flat_values(t: &Triangle) -> [f32; 8] {
    let n = cross_f64(&to_f64(&t.v));
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    flat_values_of(t, n, len)
}

/// [`flat_values`] from the triangle's normal `n = (v1 − v0) × (v2 − v0)` (f64) and `|n|`,
/// computed as there.
#[inline]
pub(crate) fn flat_values_of(t: &Triangle, n: [f64; 3], len: f64) -> [f32; 8] {
    debug_assert!(is_flat(t));
    // written out: `array::map` compiled to calls here
    let face = [n[0] / len, n[1] / len, n[2] / len];
    let c = t.c[0];
    values(face, [c[0] as f64, c[1] as f64, c[2] as f64, c[3] as f64])
}
