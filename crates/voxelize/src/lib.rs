//! CPU surface voxelization of one 256³ chunk at a time, with the factored triangle/box overlap
//! tests of Rauwendaal & Bailey, "Hybrid Computational Voxelization Using the Graphics
//! Pipeline", JCGT 2(1) 2013 (section 3.1 and the Appendix, Figures 17 and 18).
//!
//! * [`overlap`]: the per-triangle setup [`TriSetup`] and [`voxelize_triangle`], in two modes
//!   ([`Mode::Conservative`], 26-separating: every voxel the closed triangle touches;
//!   [`Mode::Thin`], 6-separating: the naive digital plane restricted to the triangle). The exact
//!   definitions, and where they differ from the paper's pseudocode, are in that module's docs.
//!   Every overlap decision is exact for the f32 input: f64 evaluation with a proven error bound
//!   per triangle, and Shewchuk's adaptive exact predicates ([`predicates`]) inside that bound
//!   (`tests/exact.rs` compares the voxel sets with a big-integer reference).
//! * [`predicates`]: exact orient2d / orient3d signs (the `robust` crate).
//! * [`scanline`]: the projected scanline voxelizer of Zhang, Garcia, Xu, Shao & Yang,
//!   "Efficient Voxelization Using Projected Optimal Scanline": the same voxels as
//!   [`TriSetup::scan`], in the same order, found by settling interval ends (slices, a run of
//!   columns per slice where the side tests cannot cut) instead of testing every column of the
//!   bounding box; and its integer-only variant (ILV), an approximation. Chosen by [`Method`]
//!   ([`ChunkVoxelizer::set_method`], `voxlod build --voxelizer`).
//! * [`clip`]: [`clipped_area`], the triangle's area inside a voxel and its centroid (the
//!   definition of the weights).
//! * [`column`](mod@column): [`voxel_areas`], the same areas and centroids for all the voxels of a triangle,
//!   factored column by column, with closed forms for the common cases (what the chunk
//!   voxelizer uses).
//! * [`chunk`]: [`ChunkVoxelizer`], which accumulates attributes per voxel of a chunk and emits
//!   the 12-byte [`voxlod_format::Voxel`] records sorted by Morton code.
//! * [`single`]: which (triangle, voxel) pairs need no clipped area (one contribution of a
//!   triangle with flat attributes).
//! * `small`: small triangles (a closed voxel range of at most two voxels per axis,
//!   conservative mode): the exact set against the octants around one grid point and the
//!   clipped areas by one cut per split axis, added at once without the scan or the pair list.
//! * [`grid`]: [`voxelize_grid`], a whole in-memory grid, chunks in parallel.
//! * [`texcolor`]: colour from a base colour texture (linear light, mip level of the part's
//!   footprint; docs/TEXTURES.md).
//!
//! Grid coordinates: voxel `p` is the closed box `[p, p+1]³`; triangles are given in grid
//! coordinates (`Grid::to_grid`).
//!
//! # Attributes (the GPU voxelizer reproduces these)
//!
//! For every triangle `T` (in `add` order) and every voxel `p` that the overlap test marks:
//! * weight `w` = area of `T ∩ [p, p+1]³` in voxel² ([`clipped_area`]: Sutherland–Hodgman in f64,
//!   swizzled to `T`'s dominant axis, planes in the order x−, x+, y−, y+, z−, z+; area from the
//!   xy shoelace of the fan from the first vertex times `|n|/|n_z|`). The boxes are closed, so a
//!   triangle lying exactly in a voxel face plane gives its full area to both voxels sharing
//!   that face (the weights only serve averaging);
//! * interpolation point `q` = centroid of that clipped polygon (mean of its vertices if its area
//!   is zero, the triangle's centroid if it is empty);
//! * barycentrics at `q`: with `e1 = v1−v0`, `e2 = v2−v0`, `n = e1×e2`, `d = q−v0`:
//!   `λ1 = ((d×e2)·n)/(n·n)`, `λ2 = ((e1×d)·n)/(n·n)`, `λ0 = 1−λ1−λ2` (not clamped);
//! * normal = `normalize(Σ λ_k n_k)` of the vertex normals if `flags & TRI_HAS_NORMALS` (the unit
//!   face normal `n/|n|` if that sum is zero or not finite), else the unit face normal `n/|n|`
//!   (its sign follows the winding `v0, v1, v2`);
//! * colour = `Σ λ_k c_k` of the RGBA8 vertex colours as reals in 0..255; in a build with
//!   textures ([`ChunkVoxelizer::set_textures`], [`texcolor`]) that colour in linear light times
//!   the triangle's texture sampled at `q`, and the mean below is sRGB-encoded.
//!
//! Per voxel, in triangle order: `W = Σ w`, `N = Σ w·normal`, `C = Σ w·colour`, plus the count
//! `K` and the unweighted sums `N′`, `C′`. If `W > 0` the voxel's normal is `N / W` and its
//! colour `C / W`; otherwise (only touched on its boundary, e.g. conservative ties) `N′ / K` and
//! `C′ / K`. Encoding: normal word = `pack_normal` of that normal, face mask =
//! `face_mask(normal word) | border_caps(pos)`, colour = `pack_color(round(colour) clamped to
//! 0..255)` with round half away from zero. Voxels are sorted by `morton8` of their in-chunk
//! position.
//!
//! That is the definition, in exact arithmetic on the triangles as [`ChunkVoxelizer`] is given
//! them: corners in grid coordinates as f32 (`Grid::to_grid` of the input's positions, each
//! coordinate rounded to f32 once), vertex normals, colours and texture coordinates as read.
//! The overlap test is exact for the input's own (world) numbers where the caller passes them
//! (`add_world`); the attributes are not: against the input's own positions each grid
//! coordinate has moved by at most ε ≤ 2⁻²⁴·R voxel (half an f32 unit in the last place, R the
//! grid's resolution), so to first order a contribution's face normal turns by at most
//! `√3·ε·(|e1|+|e2|)/A` radians (edges and area of the triangle in voxels), its weight changes
//! by at most `√3·ε·P` (`P` the perimeter of its part inside the voxel), and the voxel's mean
//! normal turns by at most `(Σ w·θ + 2·Σ Δw)/|N|`: far below one normal step for triangles
//! much larger than ε, up to several steps for slivers and triangles much smaller than a voxel
//! (docs/FORMAT.md section 6 states the same). [`ChunkVoxelizer`] evaluates it as follows, and
//! its records are within one quantization step of the exact ones (normal: one 10-bit step per
//! component; colour: one unit per channel) except where the normals of a voxel's
//! contributions nearly cancel (`|N|/W` below about `1.06e-4·(K+2)`, opposite faces in one
//! voxel), where the direction is rounding noise in any precision:
//! * `w` and `q` in f64 as above, by the column method below (equal to [`clipped_area`] up to
//!   rounding);
//! * normal and colour at `q` in f64 as affine functions of `q`'s coordinates in the dominant
//!   projection with per-triangle gradients (the same barycentrics: `q` lies in the plane);
//! * the sums `W`, `N`, `C` (or `N′`, `C′`) in **f32**, in triangle order, which makes the
//!   result deterministic (one chunk is voxelized by one thread) and halves the accumulator
//!   (32 bytes per voxel, and a 4-byte count). Error bound (proved on `chunk::Acc`): every sum is within
//!   `γ_{K+2} = (K+2)·2⁻²⁴/(1 − (K+2)·2⁻²⁴)` of the sum of its terms' absolute values, so the
//!   mean colour is off by less than 0.13 for `K ≤ 4094` contributions and the normal by less
//!   than one step wherever `|N|/W ≥ 1.06e-4·(K+2)`; `tests/attributes.rs` checks the bound
//!   against the f64 reference on random triangles and the npm bunny;
//! * encoding: the normal is packed from `N` itself (`pack_normal_f64`: normalized in f64, one
//!   square root, one division), the colour as `C · (1/W)` in f32; without textures a chunk's
//!   records are encoded in branch-free batches of 64 (SIMD lanes, the same bits).
//!
//! The GPU voxelizer (crates/gpu) computes the definition (without textures: the pipeline
//! voxelizes textured meshes on the CPU) in f64 (or f32) with 96-bit
//! fixed-point sums; its tests accept one quantization step against this one.
//!
//! # How the chunk voxelizer computes this quickly
//!
//! In conservative mode a triangle inside the open interior of one voxel (most triangles of a
//! scan voxelized coarser than its triangles, [`overlap::interior_voxel`]) marks only that voxel,
//! with the whole triangle's area `|n|/2` and its centroid, where the barycentrics are all ⅓:
//! no overlap test, no clipping, no interpolation (normal = normalized sum of the vertex
//! normals or the face normal, colour = mean vertex colour). Other triangles:
//! the weights and centroids are computed column by column ([`column`](mod@column)): the triangle's part
//! above a column of its dominant projection is clipped once, each voxel of the column only
//! clips that part to its depth slab, and a column part lying in one voxel is measured once.
//! Where the column's square lies inside the triangle's projection (most columns of a large
//! triangle), the part is the square lifted to the plane: no edge clipping, and if the plane
//! stays inside one voxel layer over the square, weight `|n|/|n_z|` and centroid the lifted
//! square centre in closed form. These fast paths differ from [`clipped_area`] only by rounding
//! (measured below 1e-12 relative, `tests/column.rs`); ties, where a voxel boundary passes
//! within 1e-7 of a square corner, take the general path.
//! Only where the weights matter: [`ChunkVoxelizer::add`] marks (voxel sets and a count of
//! contributions per voxel) and [`ChunkVoxelizer::finish`] computes the contributions, giving a
//! voxel whose one contribution comes from a triangle with flat attributes (face normal, one
//! colour, no texture) that triangle's normal and colour without clipping, since its record
//! does not depend on the weight ([`single`]: within one normal step of the clipped result,
//! bit-identical wherever a voxel has two or more contributions).
//! [`ChunkVoxelizer::set_fast_paths`]`(false)` computes every weight by the general clipping;
//! on the npm bunny at 4096³ (54 M conservative, 32 M thin voxels) both give identical
//! records. Where coplanar triangles of opposite orientation overlap (double-sided walls of CAD
//! meshes), `Σ w·normal` cancels to rounding noise and the packed normal of such a voxel is that
//! noise, so it can differ (with the earlier f64 sums, where `|N|/W < 1e-8`: 202 of 3.4 M
//! records of the conference room at 1024³, conservative; 31,186 of 8.0 M of Munich at 2048³,
//! conservative, 14,367 of 6.9 M thin); colours and voxel sets never differ.
//!
//! # Exact in the input's own coordinates
//!
//! **The promise.** [`ChunkVoxelizer::add_world`] (what a build calls) marks, in conservative
//! mode, exactly the voxels whose closed box `[origin + i·s, origin + (i+1)·s]` (per axis, real
//! arithmetic) meets the closed triangle, and in thin mode exactly the voxels of the thin
//! definition ([`overlap`]) on that box, where `origin` and `s` (the voxel size) are the f64
//! numbers of the file's header and the vertices are the f32 positions read. Binary PLY
//! `float`, STL and glTF `FLOAT` positions are those numbers exactly; PLY `double` and decimal
//! text are rounded to the nearest f32 when read, glTF node transforms are applied in f64 and
//! rounded to f32, and the promise holds for those f32 values. No rounding of the grid
//! transform adds or drops a voxel; a triangle collinear in those coordinates marks nothing.
//!
//! **The structure.** The scan runs on f32 grid coordinates `g̃ = f32((p − origin)/s)`
//! (`Grid::to_grid`) with the f64 filter of [`TriSetup`]; a decision outside the filter's band
//! is the exact one, a decision inside it is taken again on the world values ([`world`]:
//! Shewchuk's predicates when every voxel corner `origin + c·s` is an f64, big integers
//! otherwise). The bands, with `u = 2⁻⁵³`, `M` the triangle's largest coordinate magnitude
//! plus 2, `E` its extent and `A_k` the magnitude of the products of normal component `k`:
//! * f64 rounding (a forward error analysis in [`TriSetup::new`]): `8u·(|ne₀|+|ne₁|)·(2M+1)`
//!   for an edge function, `16u·Σ_k A_k·(2M+2)` for the plane, `5u·A_k` for the sign of a
//!   normal component;
//! * the f32 rounding of the grid coordinates: `g̃` is within `η = 2⁻²³·M + 2⁻¹⁴⁰` of the exact
//!   `(p − origin)/s`, and each band is widened by what `η` can do to its predicate
//!   ([`world::Perturbation`]: `8η(E+η)` for a normal component, `8η(E+1)` for an edge
//!   function, `3dn(E+2) + 2η(Σ|n| + 3dn)` for the plane).
//!
//! `to_grid` is monotone and keeps integers below 2²⁴, so only a closed-box end that `g̃` puts
//! exactly on an integer can be one voxel off; it is settled on the world value. In the band
//! the edge tests try every corner of the cell's square (or diamond), since `g̃`'s edge
//! direction can have a zero component the exact one has not. The small-triangle path
//! (`small`) is taken only when each of its decisions is outside its band; the
//! scanline ([`scanline`]) widens its margins by the same band. The GPU voxelizer (crates/gpu,
//! "Exactness") evaluates the same bands in its shaders and lists the triangles with a decision
//! inside one, which the host decides with [`voxelize_world_triangle`]: the same sets.
//!
//! **Why not an exact grid.** A voxel size of few significant bits with the origin a multiple
//! of its last bit would still leave `(p − origin)/s` inexact in f32 near the world origin
//! (where f32 positions have finer ulps than the grid coordinates), and it would move every
//! voxel boundary; deciding the rare near-ties on the world values changes only the voxels
//! whose exact answer differs.
//!
//! # Precision of the attributes
//!
//! The f32 sums are within `γ_{K+2}·Σ|terms|` (above), so without textures a colour stays
//! within one unit of the exact mean for up to 4,094 contributions per voxel and a normal
//! within one 10-bit step wherever `|N|/W ≥ 1.06e-4·(K+2)`. With textures the sums are in
//! linear light and the mean is sRGB-encoded, whose slope is at most 12.92 (near black): one
//! step for up to about 1,200 contributions. A voxel skipped by [`single`] carries its
//! triangle's face normal and colour: the same colour as the clipped path, and the same normal
//! except where `511·n_j/|n|` lies within about 1e-4 of a rounding half (one step). A small
//! triangle's contributions are summed before the general path's in the same voxel, another
//! f32 order within the same bound.
//!
//! # How it is tested
//!
//! Every voxel set is compared with a reference written from the definitions in big-integer
//! arithmetic (13 separating axes for conservative, the diamond for thin), never from the code
//! under test, on adversarial triangles (vertices on voxel corners, edges and faces nudged by
//! ulps, planes rounded through a corner, slivers, dominant-axis near-ties, coordinates up to
//! 2²³ and down to subnormal) and on real meshes; the attributes against f64 references:
//! * `tests/all/exact.rs`: `chunk_voxelizer_sets_equal_the_reference`,
//!   `adversarial_triangles_near_the_origin`, `tiny_and_subnormal_coordinates`,
//!   `stanford_bunny_exact` and the other real meshes, `small_triangles_sets_equal_the_reference`
//!   (0 missed, 0 added);
//! * `tests/all/world_exact.rs`: `real_meshes_are_exact_in_world_coordinates`,
//!   `near_ties_are_decided_on_the_input` (a reference from the world f32 positions and the
//!   header's f64 grid, never from `to_grid`; 3,000 triangles within 3 ulps of voxel corners,
//!   edges and faces of a grid with an inexact origin and size);
//! * `tests/all/attributes.rs`: the f32 sums within the bound against the f64 reference
//!   ([`clipped_area`], sub-triangle barycentrics), random triangles and the npm bunny;
//! * `tests/all/column.rs`: the column fast paths against general clipping (below 1e-12
//!   relative), and whole chunks with the fast paths on and off;
//! * `tests/all/single.rs`: the skip changes only single-contribution voxels of flat
//!   triangles, within the bound, and nothing past the deferral limit;
//! * `tests/all/small.rs`: the small path's records within one step of the path off, and every
//!   voxel's summed weight against an f64 sum of [`clipped_area`];
//! * crates/gpu `tests/all/exactness.rs`, `world.rs`, `fallback.rs`: the GPU's sets equal these
//!   in f64 and f32, uncertain triangles listed and decided on the host.
//!
//! # Example
//!
//! ```
//! use voxlod_geom::Triangle;
//! use voxlod_voxelize::{voxelize_triangle, clipped_area, ChunkVoxelizer, Mode};
//!
//! // a triangle in the plane z = 2.5 covering the lower-left half of [0,2]²
//! let v = [[0.0, 0.0, 2.5], [2.0, 0.0, 2.5], [0.0, 2.0, 2.5]];
//! let mut thin = Vec::new();
//! voxelize_triangle(&v, [0; 3], [255; 3], Mode::Thin, &mut |p| thin.push(p));
//! assert_eq!(thin, vec![[0, 0, 2], [0, 1, 2], [1, 0, 2]]);
//! let (area, centroid) = clipped_area(&v, [1, 0, 2]);
//! assert!((area - 0.5).abs() < 1e-12);
//! assert!((centroid[0] - 4.0 / 3.0).abs() < 1e-12 && (centroid[1] - 1.0 / 3.0).abs() < 1e-12);
//!
//! let mut cv = ChunkVoxelizer::new(Mode::Conservative);
//! cv.begin([0, 0, 0]);
//! cv.add(&[Triangle::new(v)]);
//! let voxels = cv.finish();
//! // (1,1,2) is touched at the corner (1,1), (2,0,2) and (0,2,2) at a vertex
//! assert_eq!(voxels.len(), 6);
//! assert_eq!(voxels[0].pos(), [0, 0, 2]);
//! assert_eq!(voxels[0].normal_f32(), [0.0, 0.0, 1.0]);
//! ```

pub mod chunk;
pub mod clip;
pub mod column;
pub mod grid;
mod interp;
pub mod material;
pub mod overlap;
pub mod predicates;
pub mod scanline;
pub mod single;
mod small;
#[cfg(test)]
mod small_reference;
pub mod texcolor;
pub mod world;

pub use chunk::{ChunkVoxelizer, VoxelSums};
pub use clip::clipped_area;
pub use column::voxel_areas;
pub use grid::{voxelize_grid, GridVoxels};
pub use overlap::{voxelize_triangle, voxelize_world_triangle, TriSetup};
pub use scanline::voxelize_triangle_with;

use std::fmt;
use std::str::FromStr;

// The chunk edge is defined twice on purpose: by the mesh side (`voxlod_geom`, the grid the
// voxelizer cuts triangles into) and by the file (`voxlod_format`, 8-bit positions in a node),
// two crates that do not depend on each other. This crate turns one into the other, so it
// holds them equal at compile time.
const _: () = assert!(voxlod_geom::CHUNK == voxlod_format::CHUNK);

/// Surface voxelization mode (Schwarz & Seidel 2010 separability).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// 26-separating: every voxel whose closed box meets the closed triangle.
    Conservative,
    /// 6-separating: the triangle against the diamond inscribed in each voxel.
    Thin,
}

impl Mode {
    /// Both modes, in the order of their codes.
    pub const ALL: [Mode; 2] = [Mode::Conservative, Mode::Thin];

    /// The mode's number in the octree file's header ([`voxlod_format::MODE_CONSERVATIVE`],
    /// [`voxlod_format::MODE_THIN`]; the GPU shaders' mode parameter uses the same numbers).
    pub const fn code(self) -> u32 {
        match self {
            Mode::Conservative => voxlod_format::MODE_CONSERVATIVE,
            Mode::Thin => voxlod_format::MODE_THIN,
        }
    }

    /// The mode's name, as `FromStr`, `Display`, serde and the command line spell it.
    pub const fn name(self) -> &'static str {
        match self {
            Mode::Conservative => "conservative",
            Mode::Thin => "thin",
        }
    }

    /// The mode of a file header's code; None for a code no mode has.
    pub fn from_code(code: u32) -> Option<Mode> {
        Mode::ALL.into_iter().find(|m| m.code() == code)
    }
}

/// `--mode` on the command line (the same names as `Display` and serde).
#[cfg(feature = "clap")]
impl clap::ValueEnum for Mode {
    fn value_variants<'a>() -> &'a [Self] {
        &Mode::ALL
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()))
    }
}

/// `--voxelizer` on the command line (the names of [`Method::NAMES`]).
#[cfg(feature = "clap")]
impl clap::ValueEnum for Method {
    fn value_variants<'a>() -> &'a [Self] {
        &Method::ALL
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()))
    }
}

/// A string that is neither `conservative` nor `thin`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown voxelization mode {0:?} (expected \"conservative\" or \"thin\")")]
pub struct ParseModeError(pub String);

impl FromStr for Mode {
    type Err = ParseModeError;
    fn from_str(s: &str) -> Result<Mode, ParseModeError> {
        match s {
            "conservative" => Ok(Mode::Conservative),
            "thin" => Ok(Mode::Thin),
            _ => Err(ParseModeError(s.to_string())),
        }
    }
}

impl fmt::Display for Mode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// How the CPU voxelizer finds a triangle's voxels.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Every column of the triangle's bounding box through the factored overlap tests
    /// ([`TriSetup::scan`], Rauwendaal & Bailey).
    Sat,
    /// The projected scanline of Zhang et al. ([`scanline::scan`]): the same voxels, found by
    /// settling interval ends. The default: never slower than `Sat` in our measurements, up
    /// to 1.2× faster on triangles spanning many voxels (docs/journal/benchmarks-notebook.md,
    /// "Projected scanline voxelizer").
    #[default]
    Scanline,
    /// The paper's integer-only variant ([`scanline::scan_ilv`]): approximate, conservative
    /// mode only.
    ScanlineIlv,
}

impl Method {
    /// Every method, in the order of [`Method::NAMES`].
    pub const ALL: [Method; 3] = [Method::Sat, Method::Scanline, Method::ScanlineIlv];
    /// The names `FromStr` and `Display` use.
    pub const NAMES: [&'static str; 3] = ["sat", "scanline", "scanline-ilv"];

    /// The method's name, one of [`Method::NAMES`].
    pub fn name(self) -> &'static str {
        let i = Method::ALL.iter().position(|&m| m == self).unwrap_or(0);
        Method::NAMES[i]
    }

    /// Whether this method gives exactly the overlap tests' voxels (not an approximation).
    pub fn is_exact(self) -> bool {
        self != Method::ScanlineIlv
    }

    /// Whether it supports `mode` (ILV approximates the conservative set only).
    pub fn supports(self, mode: Mode) -> bool {
        self != Method::ScanlineIlv || mode == Mode::Conservative
    }
}

/// A string that names no [`Method`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown voxelizer {0:?} (expected \"sat\", \"scanline\" or \"scanline-ilv\")")]
pub struct ParseMethodError(pub String);

impl FromStr for Method {
    type Err = ParseMethodError;
    fn from_str(s: &str) -> Result<Method, ParseMethodError> {
        Method::NAMES
            .iter()
            .position(|&n| n == s)
            .map(|i| Method::ALL[i])
            .ok_or_else(|| ParseMethodError(s.to_string()))
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

/// Which GPU voxelization scheme the GPU backend runs (Schwarz & Seidel 2010 section 3):
/// the `--gpu-method` setting, and the mode `voxlod_gpu::GpuVoxelizer` runs in.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum GpuMethod {
    /// Small triangles in the classification pass, large ones in the fragment pass (3.4). A
    /// triangle under the cutoff with more than 64 columns in the chunk (a long sliver) is
    /// deferred too (see [`GpuMethod::Triangle`]).
    #[default]
    Hybrid,
    /// No rasterizer: every triangle in compute passes (3.2), one invocation per triangle,
    /// except that triangles with more than 64 columns in the chunk are swept by one invocation
    /// per column line and 64-row strip (lavapipe ends an invocation after 65535 loop
    /// iterations, which a large triangle's single invocation exceeds).
    Triangle,
    /// Every triangle rasterized, one fragment per column (3.3).
    Fragment,
}

impl GpuMethod {
    /// Every method.
    pub const ALL: [GpuMethod; 3] = [GpuMethod::Hybrid, GpuMethod::Triangle, GpuMethod::Fragment];

    /// The method's name in settings files and on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            GpuMethod::Hybrid => "hybrid",
            GpuMethod::Triangle => "triangle",
            GpuMethod::Fragment => "fragment",
        }
    }
}

/// A string that names no [`GpuMethod`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown GPU method {0:?} (expected \"hybrid\", \"triangle\" or \"fragment\")")]
pub struct ParseGpuMethodError(pub String);

impl FromStr for GpuMethod {
    type Err = ParseGpuMethodError;
    fn from_str(s: &str) -> Result<GpuMethod, ParseGpuMethodError> {
        GpuMethod::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| ParseGpuMethodError(s.to_string()))
    }
}

impl fmt::Display for GpuMethod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(feature = "clap")]
impl clap::ValueEnum for GpuMethod {
    fn value_variants<'a>() -> &'a [Self] {
        &GpuMethod::ALL
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The codes are the file format's, and each names its mode back; the two crates' chunk
    /// sizes are the same constant.
    #[test]
    fn mode_codes_are_the_formats() {
        assert_eq!(Mode::Conservative.code(), voxlod_format::MODE_CONSERVATIVE);
        assert_eq!(Mode::Thin.code(), voxlod_format::MODE_THIN);
        for m in Mode::ALL {
            assert_eq!(Mode::from_code(m.code()), Some(m));
        }
        assert_eq!(Mode::from_code(2), None);
        assert_eq!(voxlod_format::CHUNK, voxlod_geom::CHUNK);
    }

    #[test]
    fn mode_strings_roundtrip() {
        for m in [Mode::Conservative, Mode::Thin] {
            assert_eq!(m.to_string().parse::<Mode>(), Ok(m));
        }
        assert!("Thin".parse::<Mode>().is_err());
    }

    #[test]
    fn method_strings_roundtrip() {
        for m in Method::ALL {
            assert_eq!(m.to_string().parse::<Method>(), Ok(m));
        }
        assert!("SAT".parse::<Method>().is_err());
        assert!(!Method::ScanlineIlv.supports(Mode::Thin));
    }
}
