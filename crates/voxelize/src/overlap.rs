//! Factored triangle/voxel overlap tests: Rauwendaal & Bailey, "Hybrid Computational
//! Voxelization Using the Graphics Pipeline", JCGT 2(1) 2013, section 3.1 and the Appendix
//! (Figure 17 conservative, Figure 18 thin), after Schwarz & Seidel, "Fast Parallel Surface and
//! Solid Voxelization on GPUs", SIGGRAPH Asia 2010.
//!
//! Voxel `p` (integer grid coordinates) is the closed box `[p, p+1]³`. The triangle is swizzled
//! so that its dominant axis (largest `|n|` component) becomes the depth axis z; we iterate
//! columns (x, y) of the dominant projection ([`TriSetup::column_inside`]), get the depth range
//! from the plane ([`TriSetup::column_depth`]), and test the two other projections
//! ([`TriSetup::side_inside`]).
//!
//! **Exactness.** Every decision is exact for the f32 input (vertices in grid coordinates):
//! each one is the sign of a low-degree polynomial in the vertex coordinates and integer or
//! half-integer corner coordinates, all exact in f64:
//! * the sign `s_k` of each normal component (the orientation of the projection ⟂ k: which side
//!   of each projected edge is inside, and which box corners are critical);
//! * each 2D edge test: `s_k · orient2d(v_i, v_{i+1}, q)` at the most interior corner `q` of the
//!   unit square (conservative) or the most interior vertex of the inscribed diamond (thin);
//! * the plane test: the sign of `n·(q − v₀)` (orient3d with `q` as fourth point) at the box
//!   corner furthest along `n` and at the nearest one (conservative) or at the diamond's
//!   extreme vertices (thin).
//!
//! The scan evaluates these incrementally in f64 as the paper does (the fast path) and compares
//! each value with a per-triangle bound on its rounding error, proven in [`TriSetup::new`]; only
//! a value inside `[−B, B)` is decided again by Shewchuk's adaptive exact predicates
//! ([`crate::predicates`]). Exact ties (a triangle touching a box face, edge or corner) are
//! decided as ties: the closed box counts. The result does not depend on which axis is chosen
//! as dominant (that choice only factors the test). [`interior_voxel`] is exact as it is
//! (strict f64 comparisons of f32 values with integers). A triangle whose vertices are exactly
//! collinear marks nothing.
//!
//! Deviations from the paper's pseudocode (typos there, derivations here):
//! * Figure 17/18 line 19 use `p_xy` for all projections; the YZ test uses `(p_y, p_z)` and the ZX
//!   test `(p_z, p_x)`.
//! * Figure 17 lines 16–17 iterate `floor(z_lo) ..= ceil(z_hi)`, one voxel too many above (and
//!   one too few below on exact ties). The voxels whose closed z-extent `[p_z, p_z+1]` meets the
//!   plane's z-range `[z_lo, z_hi]` over the column are `ceil(z_lo)-1 ..= floor(z_hi)`. We compute
//!   that range with a division and then settle both ends with the (filtered, exact) plane
//!   predicates `n_z·(p_z+1) ≥ d_lo − n_x p_x − n_y p_y` and `n_z·p_z ≤ d_hi − n_x p_x − n_y p_y`,
//!   so the division's rounding never decides (the z that meet the plane form an interval).
//! * Figure 18 lines 16–17 likewise give two voxels per column; the thin test keeps the voxels
//!   whose diamond meets the plane (`|n·(c−v₀)| ≤ ½‖n‖∞`): one voxel, two only on a tie. Same
//!   predicates with `d_lo = d_hi = d_cen`; the f64 form takes `‖n‖∞ = n_z`, the exact one
//!   evaluates every diamond vertex that can be extreme, so a near-tie of the dominant axis
//!   cannot change the result.
//! * Figure 18 lines 7–9 take `max(|n^XY|, |n^YZ|)`; the support of the 2D diamond
//!   `{x : |x − c|₁ ≤ ½}` along `n_e` is `½·max(|n_e,0|, |n_e,1|)` of that edge normal alone.
//! * `sign(0) = 0` (not Rust's `signum`): a projection of zero area gets zero edge normals and
//!   its edge tests pass; in that case those axes are parallel to the plane normal, which the
//!   depth test already covers.
//!
//! **Conservative** (26-separating): a voxel is marked iff the closed triangle and the closed box
//! intersect, i.e. no separating axis among the 13 of Akenine-Möller (box bbox, plane, 9 edge ×
//! axis products, the latter as the 2D edge tests of the three projections).
//!
//! **Thin** (6-separating): let `D_p = {x : |x − (p + ½)|₁ ≤ ½}` be the diamond (octahedron)
//! inscribed in voxel `p`. A voxel is marked iff it lies in the conservative bounding box, the
//! triangle's plane meets `D_p` (`|n·(c−v₀)| ≤ ½‖n‖∞`, the naive digital plane), and for each of
//! the three projections and each edge the edge's inner half-plane meets the projected 2D
//! diamond. Every condition is necessary for `T ∩ D_p ≠ ∅`, so the marked set contains
//! `{p : T ∩ D_p ≠ ∅}`, which is 6-separating for a closed surface: a 6-path of voxel centres from
//! outside to inside crosses the surface on a segment `c → c + e_a`, and every point of that
//! segment lies in `D` of one of its two end voxels. Each condition also implies its
//! conservative counterpart (`D_p ⊂ p`), so thin ⊆ conservative.

use crate::predicates::{orient2d, plane_side};
use crate::world::{self, Frame, Perturbation};
use crate::Mode;
use voxlod_geom::Grid;

/// `sign` with `sign(0) = 0`.
#[inline]
pub(crate) fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// The dominant axis of a normal: z if `|n_z|` is the largest (ties go to z), else x if
/// `|n_x| ≥ |n_y|`, else y.
#[inline]
pub fn dominant_axis(n: [f64; 3]) -> usize {
    let a = [n[0].abs(), n[1].abs(), n[2].abs()];
    if a[2] >= a[0] && a[2] >= a[1] {
        2
    } else if a[0] >= a[1] {
        0
    } else {
        1
    }
}

/// The swizzle for a dominant axis: swizzled axis `k` is original axis `swizzle(axis)[k]`
/// (paper 3.3.1: x dominant → yzx, y dominant → zxy, z dominant → xyz). It is a cyclic
/// permutation, so cross products commute with it.
#[inline]
pub fn swizzle(axis: usize) -> [usize; 3] {
    match axis {
        0 => [1, 2, 0],
        1 => [2, 0, 1],
        _ => [0, 1, 2],
    }
}

/// Point `p` in swizzled coordinates (swizzle `swz`) back in original ones, as
/// [`TriSetup::unswizzle`] does.
#[inline]
pub(crate) fn unswizzle<T: Copy>(swz: [usize; 3], p: [T; 3]) -> [T; 3] {
    let inv = unswizzle_of(swz);
    [p[inv[0]], p[inv[1]], p[inv[2]]]
}

/// The inverse of a [`swizzle`] permutation.
#[inline]
fn unswizzle_of(swz: [usize; 3]) -> [usize; 3] {
    let mut inv = [0; 3];
    for (k, &j) in swz.iter().enumerate() {
        inv[j] = k;
    }
    inv
}

/// `(v1 − v0) × (v2 − v0)` in f64 (same formula as `Triangle::cross`).
#[inline]
pub(crate) fn cross_f64(v: &[[f64; 3]; 3]) -> [f64; 3] {
    let a = [v[1][0] - v[0][0], v[1][1] - v[0][1], v[1][2] - v[0][2]];
    let b = [v[2][0] - v[0][0], v[2][1] - v[0][1], v[2][2] - v[0][2]];
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
pub(crate) fn to_f64(v: &[[f32; 3]; 3]) -> [[f64; 3]; 3] {
    // written out: `array::map` here compiled to calls and copies in the hot small-triangle path
    let p = |i: usize| [v[i][0] as f64, v[i][1] as f64, v[i][2] as f64];
    [p(0), p(1), p(2)]
}

/// The voxel whose open interior `(p, p+1)³` contains the whole triangle, if there is one (every
/// coordinate finite, and on every axis the triangle's extent strictly between two consecutive
/// integers). Such a triangle meets no other closed voxel box, so its conservative voxel set is
/// exactly `{p}`, without the overlap test (on scans, where triangles are much smaller than
/// voxels, most triangles are such). Not so for thin voxelization: the triangle may miss the
/// diamond inscribed in `p`.
#[inline]
pub fn interior_voxel(v: &[[f32; 3]; 3]) -> Option<[i32; 3]> {
    let mut p = [0i32; 3];
    for k in 0..3 {
        // in f64, so that `f + 1.0` is exact; every comparison is false for a NaN, and one
        // is for an infinity
        let c = [v[0][k] as f64, v[1][k] as f64, v[2][k] as f64];
        let f = c[0].floor();
        let inside = c.iter().all(|&c| c > f && c < f + 1.0);
        if !(inside && f >= i32::MIN as f64 && f < i32::MAX as f64) {
            return None;
        }
        p[k] = f as i32;
    }
    Some(p)
}

/// Unit roundoff of f64, `u = 2⁻⁵³`.
const U: f64 = f64::EPSILON / 2.0;

/// Absolute slack added to every filter bound. For f32 input no product of the filtered
/// expressions can underflow (the smallest nonzero one is `≥ 2⁻²⁹⁸·1`, see [`TriSetup::new`]),
/// so the relative error model holds and this is only a guard: it would cover up to 2⁷⁴
/// underflowing operations of absolute error `≤ 2⁻¹⁰⁷⁴` each.
const TINY: f64 = 1e-300;

/// The coordinates `(a, b)` of projection `k`: 0 = XY `(x, y)`, 1 = YZ `(y, z)`, 2 = ZX `(z, x)`.
const PLANE: [[usize; 2]; 3] = [[0, 1], [1, 2], [2, 0]];

/// Filter decision of a predicate `exact ≥ 0` evaluated as `f` with `|f − exact| ≤ b`: certain
/// outside `[−b, b)`, else `exact()`.
#[inline(always)]
fn at_least_zero(f: f64, b: f64, exact: impl FnOnce() -> bool) -> bool {
    if f >= b {
        true
    } else if f < -b {
        false
    } else {
        exact()
    }
}

/// Per-triangle setup of the factored overlap test (paper 3.1.2). All vectors are in swizzled
/// coordinates (depth axis last).
///
/// Every decision is exact for the f32 input: each test is evaluated incrementally in f64 as in
/// the paper, and compared with a per-triangle bound on its rounding error (`be`, `bp`, derived
/// in [`TriSetup::new`]); only a value inside that bound goes to an exact predicate
/// ([`crate::predicates`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriSetup {
    /// Conservative (26-separating) or thin (6-separating).
    pub mode: Mode,
    /// Dominant axis in original coordinates (0 = x, 1 = y, 2 = z).
    pub axis: usize,
    /// Swizzled axis `k` is original axis `swz[k]`; see [`swizzle`].
    pub swz: [usize; 3],
    /// The inverse permutation: original axis `j` is swizzled axis `unswz[j]`.
    unswz: [usize; 3],
    /// Swizzled vertices.
    pub v: [[f64; 3]; 3],
    /// Swizzled normal `(v1−v0)×(v2−v0)` in f64, negated if needed so that `n[2] > 0`. The sign
    /// of every component is exact (a component whose f64 sign could be wrong is replaced by the
    /// exact predicate's value, and the triangle then decides everything exactly).
    pub n: [f64; 3],
    /// Inward edge normals `ne[plane][i]` of edge `e_i = v_{i+1} − v_i`; plane 0 = XY with
    /// coordinates `(x, y)`, 1 = YZ with `(y, z)`, 2 = ZX with `(z, x)`. Zero for a projection of
    /// zero area (exactly zero: its orientation is an exact predicate).
    pub ne: [[[f64; 2]; 3]; 3],
    /// Edge distances: the edge test of voxel `p` passes iff
    /// `ne[k][i][0]·p_a + ne[k][i][1]·p_b + de[k][i] ≥ 0` with `(p_a, p_b)` the projection's
    /// coordinates of the voxel's minimum corner (evaluated exactly; in f64 up to `be[k][i]`).
    pub de: [[f64; 3]; 3],
    /// Depth test: voxel `p` meets the plane iff `n_z·(p_z+1) ≥ d_lo − n_x p_x − n_y p_y` and
    /// `n_z·p_z ≤ d_hi − n_x p_x − n_y p_y` (evaluated exactly; in f64 up to `bp`).
    /// Conservative: `d_min`, `d_max`; thin: both `d_cen`.
    pub d_lo: f64,
    /// Upper depth offset of the depth test above.
    pub d_hi: f64,
    /// Closed voxel bounding box (swizzled): voxels `i` with `[i, i+1]` meeting the triangle's
    /// bounding box, `ceil(min) − 1 ..= floor(max)`, clamped to the i32 range.
    pub bmin: [i32; 3],
    /// Maximum corner of that box (inclusive).
    pub bmax: [i32; 3],
    /// Exact orientation (−1, 0, 1) of projection `k` (numbering of `ne`), before `n` is made
    /// to point up: the sign `s` of the edge tests, `ne·(q − v_i) = s·orient2d(v_i, v_{i+1}, q)`.
    orient: [f64; 3],
    /// `±1`: `n` is the cross product times `flip`.
    flip: f64,
    /// Error bounds of the f64 edge functions `ne·p + de` (same numbering); infinite when
    /// the triangle decides everything exactly, 0 for a projection of zero area (its edge
    /// functions are exactly 0).
    be: [[f64; 3]; 3],
    /// Error bound of the f64 depth predicates (`n_z·(z+1) − (d_lo − n_x x − n_y y)` and
    /// `n_z·z − (d_hi − …)`) against the exact box/diamond extremes.
    bp: f64,
    /// The input's own coordinates ([`TriSetup::with_world`]): every exact decision is made on
    /// them, and the filter bounds above include the perturbation of the f32 grid coordinates.
    world: Option<WorldTri>,
    /// The perturbation parts of `be` and `bp` ([`Perturbation`]; 0 without `world`).
    band: (f64, f64),
}

/// A triangle's world vertices and the grid's frame, swizzled like [`TriSetup::v`].
#[derive(Clone, Copy, Debug, PartialEq)]
struct WorldTri {
    w: [[f64; 3]; 3],
    frame: Frame,
}

impl TriSetup {
    /// The setup of triangle `v` (grid coordinates); `None` if a coordinate is not finite or the
    /// area is exactly zero (collinear vertices, decided exactly).
    ///
    /// # The filter bounds (a rigorous forward error analysis)
    ///
    /// With `u = 2⁻⁵³`, every f64 operation on normal numbers returns `x(1+δ)`, `|δ| ≤ u`, and
    /// a sum of products in which each product passes through at most `m` roundings differs
    /// from its exact value by at most `γ_m·Σ|product|`, `γ_m = m·u/(1−m·u)` (Higham, *Accuracy
    /// and Stability of Numerical Algorithms*, 2nd ed., §3.1). Inputs: f32 vertices (exact in
    /// f64) and voxel coordinates `x` the scan can reach, `x ∈ [bmin, bmax]`, so every
    /// coordinate used (`x`, `x+1`, a vertex) is at most `M = max|v| + 2` in magnitude.
    ///
    /// * Differences `ẽ = fl(b − a)` of two vertices: `ẽ = ê(1+δ)`, with the **exact sign**.
    ///   Normal `n_k = fl(fl(ẽ₁ẽ₂′) − fl(ẽ₁′ẽ₂))`: `|n_k − n̂_k| ≤ γ₄·(|ê₁ê₂′| + |ê₁′ê₂|) ≤
    ///   4.01u·A_k` with `A_k = |ẽ₁ẽ₂′| + |ẽ₁′ẽ₂|` (in f64). If `|n_k| > 5u·A_k` its sign is
    ///   certain; otherwise it is the exact `orient2d` of the projection. If the exact sign
    ///   differs, `n_k` is replaced by that predicate's value and every bound is set to `∞`
    ///   (the triangle is decided exactly throughout; only near-degenerate projections).
    /// * Edge function (conservative or thin), `F = ne₀·x + ne₁·y + de` with `ne = s·(−ẽ_b, ẽ_a)`,
    ///   `de = −(ne₀a_x + ne₁a_y) + ` the corner (diamond vertex) offset. The terms
    ///   `ne_j·x, ne_j·a_j, ne_j·o_j` (`|o_j| ≤ 1`) each pass through at most 6 roundings:
    ///   `|F − F*| ≤ γ₆·(|ne₀| + |ne₁|)(2M + 1)`, `F*` the exact value with the rounded `ne`.
    ///   Replacing `ẽ` by `ê` (relative error `u`) moves it by at most `u(1+u)(|ne₀|+|ne₁|)(2M+1)`
    ///   (thin: the diamond's `½·max|ne_j|` is 1-Lipschitz in `ne`). Sum `< 7.01u·(…)`, so
    ///   `be = 8u·(|ne₀| + |ne₁|)·(2M + 1)` bounds it with room for its own rounding.
    /// * Depth predicate, `g = n_z(z+1) − (−(n_x x + n_y y) + d_lo)` with
    ///   `d_lo = n·v₀ − (corner offsets)`: eight products, each through at most 7 roundings:
    ///   `|g − g*| ≤ γ₇·Σ_k |n_k|(2M + 1)`; the rounded normal adds
    ///   `Σ_k |n_k − n̂_k|·2M ≤ 4.01u·Σ_k A_k·2M`. Thin: `g` uses `½n_z` for the diamond's
    ///   `½‖n̂‖∞`; as `|n_z| ≥ |n_k|` in f64, `‖n̂‖∞ − n̂_z ≤ 4.01u(A_k + A_z)` more. With
    ///   `|n_k| ≤ (1+u)A_k`: in total `< 11.2u·ΣA·(2M+1) + 4.1u·ΣA`, so
    ///   `bp = 16u·ΣA·(2M + 2)`.
    /// * No underflow: nonzero differences of f32 values are `≥ 2⁻¹⁴⁹`, their products
    ///   `≥ 2⁻²⁹⁸`, times a vertex `≥ 2⁻⁴⁴⁷`, all normal in f64; no overflow: `|v| < 2¹²⁸`,
    ///   products `< 2³⁸⁸`. [`TINY`] is added anyway.
    pub fn new(v: &[[f32; 3]; 3], mode: Mode) -> Option<TriSetup> {
        Self::with_world(v, None, mode)
    }

    /// The setup of triangle `v` (f32 grid coordinates, `grid.to_grid` of `world`) whose every
    /// decision is exact for the **world** vertices `world` and the grid `grid` as stated
    /// (origin and voxel size as f64 numbers), not for the rounded `v`: the filter bounds of
    /// [`TriSetup::new`] are widened by the [`Perturbation`] of `v`, and inside them the
    /// predicates are decided in world coordinates ([`crate::world`]). The closed voxel box is
    /// exact too: a box end that `v` puts on an integer is checked against the world value.
    /// `None` if a coordinate is not finite or the world vertices are exactly collinear.
    pub fn with_world(
        v: &[[f32; 3]; 3],
        world: Option<(&[[f32; 3]; 3], &Grid)>,
        mode: Mode,
    ) -> Option<TriSetup> {
        // The paper's triangle setup, in order.
        if !v.iter().flatten().all(|c| c.is_finite()) {
            return None;
        }
        let o = to_f64(v);
        let world = world.map(|(w, g)| (to_f64(w), Frame::of(g)));
        let pert = match &world {
            Some(_) => Perturbation::of(&o),
            None => Perturbation::default(),
        };
        let mut n_o = cross_f64(&o);
        let a = [o[1][0] - o[0][0], o[1][1] - o[0][1], o[1][2] - o[0][2]];
        let b = [o[2][0] - o[0][0], o[2][1] - o[0][1], o[2][2] - o[0][2]];
        // A_k, the magnitude of the two products of n_k (original axes)
        let mag = [
            (a[1] * b[2]).abs() + (a[2] * b[1]).abs(),
            (a[2] * b[0]).abs() + (a[0] * b[2]).abs(),
            (a[0] * b[1]).abs() + (a[1] * b[0]).abs(),
        ];
        let mut filtered = true;
        for k in 0..3 {
            // all products exactly 0 (no underflow, see above): n̂_k = 0, and n_k = 0 too
            if (mag[k] == 0.0 && world.is_none()) || n_o[k].abs() > 5.0 * U * mag[k] + pert.dn {
                continue;
            }
            // the projection on the plane ⟂ k: n_x over (y, z), n_y over (z, x), n_z over (x, y)
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let exact = match &world {
                // the world projection's orientation (f32 values: robust is exact), scaled
                // to grid units
                Some((w, f)) => {
                    let p = |q: [f64; 3]| [q[i], q[j]];
                    let e = orient2d(p(w[0]), p(w[1]), p(w[2]));
                    let g = e / (f.voxel_size * f.voxel_size);
                    sign(e) * g.abs().max(f64::MIN_POSITIVE)
                }
                None => {
                    let p = |w: [f64; 3]| [w[i], w[j]];
                    orient2d(p(o[0]), p(o[1]), p(o[2]))
                }
            };
            if sign(exact) != sign(n_o[k]) {
                n_o[k] = exact + 0.0;
                filtered = false;
            }
        }
        if n_o == [0.0; 3] {
            return None;
        }
        let axis = dominant_axis(n_o);
        let swz = swizzle(axis);
        let sw = |p: [f64; 3]| [p[swz[0]], p[swz[1]], p[swz[2]]];
        let v = [sw(o[0]), sw(o[1]), sw(o[2])];
        let n = sw(n_o);
        let mag = sw(mag);
        debug_assert!(n[2] != 0.0);
        // exact signs
        let s = [sign(n[0]), sign(n[1]), sign(n[2])];
        let big_m = v.iter().flatten().fold(0.0f64, |m, c| m.max(c.abs())) + 2.0;

        let mut ne = [[[0.0; 2]; 3]; 3];
        let mut de = [[0.0; 3]; 3];
        let mut be = [[0.0; 3]; 3];
        for i in 0..3 {
            let a = v[i];
            let b = v[(i + 1) % 3];
            let e = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            // (normal, projected vertex) per plane: XY (x,y), YZ (y,z), ZX (z,x)
            let planes = [
                ([s[2] * -e[1], s[2] * e[0]], [a[0], a[1]]),
                ([s[0] * -e[2], s[0] * e[1]], [a[1], a[2]]),
                ([s[1] * -e[0], s[1] * e[2]], [a[2], a[0]]),
            ];
            for (k, (nk, vk)) in planes.into_iter().enumerate() {
                // avoid -0.0 so the setup is bit-stable
                let nk = [nk[0] + 0.0, nk[1] + 0.0];
                let base = -(nk[0] * vk[0] + nk[1] * vk[1]);
                de[k][i] = match mode {
                    // most interior corner of the unit square
                    Mode::Conservative => base + nk[0].max(0.0) + nk[1].max(0.0),
                    // most interior vertex of the diamond inscribed in the unit square
                    Mode::Thin => base + 0.5 * (nk[0] + nk[1]) + 0.5 * nk[0].abs().max(nk[1].abs()),
                };
                ne[k][i] = nk;
                let w = nk[0].abs() + nk[1].abs();
                be[k][i] = if !filtered {
                    f64::INFINITY
                } else if w == 0.0 {
                    // a zero-area projection: the edge function is exactly 0, the test passes
                    // (in world coordinates only within the perturbation)
                    pert.de
                } else {
                    8.0 * U * w * (2.0 * big_m + 1.0) + TINY + pert.de
                };
            }
        }

        let flip = if n[2] < 0.0 { -1.0 } else { 1.0 };
        let n = [flip * n[0] + 0.0, flip * n[1] + 0.0, flip * n[2]];
        let dp = n[0] * v[0][0] + n[1] * v[0][1] + n[2] * v[0][2];
        let (d_lo, d_hi) = match mode {
            Mode::Conservative => (
                dp - n[0].max(0.0) - n[1].max(0.0),
                dp - n[0].min(0.0) - n[1].min(0.0),
            ),
            Mode::Thin => {
                let c = dp - 0.5 * n[0] - 0.5 * n[1];
                (c, c)
            }
        };
        let bp = if filtered {
            16.0 * U * (mag[0] + mag[1] + mag[2]) * (2.0 * big_m + 2.0) + TINY + pert.dp(n)
        } else {
            f64::INFINITY
        };
        let world = world.map(|(w, f)| WorldTri {
            w: [sw(w[0]), sw(w[1]), sw(w[2])],
            frame: f.swizzled(swz),
        });

        let mut bmin = [0i32; 3];
        let mut bmax = [0i32; 3];
        for k in 0..3 {
            let mn = v[0][k].min(v[1][k]).min(v[2][k]);
            let mx = v[0][k].max(v[1][k]).max(v[2][k]);
            bmin[k] = clamp_i32(mn.ceil() - 1.0);
            bmax[k] = clamp_i32(mx.floor());
            // `to_grid` keeps every comparison with an integer or makes it a tie, so only an
            // end on an integer can be off by one: settle it on the world values
            if let Some(wt) = &world {
                let f = &wt.frame;
                let on = |c: f64, ord: std::cmp::Ordering| {
                    (0..3).any(|i| v[i][k] == c && world::cmp_corner(f, k, wt.w[i][k], c) != ord)
                };
                // the exact minimum is above mn unless a vertex there is at or below it
                if mn == mn.floor() && mn.abs() < 2e9 && !on(mn, std::cmp::Ordering::Greater) {
                    bmin[k] = clamp_i32(mn);
                }
                if mx == mx.floor() && mx.abs() < 2e9 && !on(mx, std::cmp::Ordering::Less) {
                    bmax[k] = clamp_i32(mx - 1.0);
                }
            }
        }
        Some(TriSetup {
            mode,
            axis,
            swz,
            unswz: unswizzle_of(swz),
            v,
            n,
            ne,
            de,
            d_lo,
            d_hi,
            bmin,
            bmax,
            orient: [s[2], s[0], s[1]],
            flip,
            be,
            bp,
            world,
            band: (pert.de, pert.dp(n)),
        })
    }

    /// The parts of the edge functions' and of the depth predicates' filter bounds that cover
    /// the perturbation of the f32 grid coordinates (0 for a setup of [`TriSetup::new`]);
    /// `crate::scanline` widens its runs' margins by them.
    pub(crate) fn perturbation_band(&self) -> (f64, f64) {
        self.band
    }

    /// Swizzles a point or voxel given in original coordinates.
    #[inline]
    pub fn swizzle<T: Copy>(&self, p: [T; 3]) -> [T; 3] {
        [p[self.swz[0]], p[self.swz[1]], p[self.swz[2]]]
    }

    /// Inverse of [`TriSetup::swizzle`].
    #[inline]
    pub fn unswizzle<T: Copy>(&self, p: [T; 3]) -> [T; 3] {
        // a gather (dynamic loads, fixed stores) rather than a scatter: the caller reads the
        // result as a whole, and stores at dynamic offsets would stall its loads
        [p[self.unswz[0]], p[self.unswz[1]], p[self.unswz[2]]]
    }

    /// Whether swizzled voxel coordinates lie in the closed voxel bounding box on the axes
    /// `k` given, i.e. where the filter bounds hold.
    #[inline]
    fn near(&self, p: [i32; 3], axes: usize) -> bool {
        (0..axes).all(|k| p[k] >= self.bmin[k] && p[k] <= self.bmax[k])
    }

    /// The relative rounding bound of the f64 side (YZ, ZX) edge functions `ne·p + de`:
    /// wherever the scan can reach, each differs from its exact value by at most
    /// `side_slack() · (|ne₀| + |ne₁|)` (the bound `be` of [`TriSetup::new`] over the edge
    /// normal's length); infinite when the triangle is decided exactly throughout.
    /// `crate::scanline` certifies a run of columns by a float margin only when that margin is
    /// far above this.
    pub(crate) fn side_slack(&self) -> f64 {
        if self.be[1..].iter().flatten().any(|b| b.is_infinite()) {
            return f64::INFINITY;
        }
        let big_m = self.v.iter().flatten().fold(0.0f64, |m, c| m.max(c.abs())) + 2.0;
        8.0 * U * (2.0 * big_m + 1.0)
    }

    /// Dominant-projection (XY) edge tests of column (x, y), exact.
    pub fn column_inside(&self, x: i32, y: i32) -> bool {
        let b = if self.near([x, y, 0], 2) {
            self.be[0]
        } else {
            [f64::INFINITY; 3]
        };
        let (xf, yf) = (x as f64, y as f64);
        (0..3).all(|i| {
            let [na, nb] = self.ne[0][i];
            at_least_zero(na * xf + nb * yf + self.de[0][i], b[i], || {
                self.edge_exact(0, i, x, y)
            })
        })
    }

    /// The voxels z of column (x, y) whose box (conservative) / diamond (thin) meets the plane,
    /// clamped to [zlo, zhi]; None if empty. Exact.
    pub fn column_depth(&self, x: i32, y: i32, zlo: i32, zhi: i32) -> Option<(i32, i32)> {
        let near = self.near([x, y, 0], 2) && zlo >= self.bmin[2] && zhi <= self.bmax[2];
        let bp = if near { self.bp } else { f64::INFINITY };
        self.depth(x, y, zlo, zhi, bp, 1.0 / self.n[2])
    }

    /// The YZ and ZX edge tests of voxel p = (x, y, z), exact.
    pub fn side_inside(&self, p: [i32; 3]) -> bool {
        let [by, bz] = if self.near(p, 3) {
            [self.be[1], self.be[2]]
        } else {
            [[f64::INFINITY; 3]; 2]
        };
        let [x, y, z] = p.map(|c| c as f64);
        (0..3).all(|i| {
            let [na, nb] = self.ne[1][i];
            at_least_zero(na * y + nb * z + self.de[1][i], by[i], || {
                self.edge_exact(1, i, p[1], p[2])
            })
        }) && (0..3).all(|i| {
            let [na, nb] = self.ne[2][i];
            at_least_zero(na * z + nb * x + self.de[2][i], bz[i], || {
                self.edge_exact(2, i, p[2], p[0])
            })
        })
    }

    /// The depth range of column `(x, y)` in `[zl, zh]`, with filter bound `bp` (valid for the
    /// column and range given) and `inv_nz = 1 / n_z`.
    #[inline(always)]
    fn depth(&self, x: i32, y: i32, zl: i32, zh: i32, bp: f64, inv_nz: f64) -> Option<(i32, i32)> {
        if zl > zh {
            return None;
        }
        let n = self.n;
        let a = -(n[0] * x as f64 + n[1] * y as f64);
        let lo_rhs = a + self.d_lo;
        let hi_rhs = a + self.d_hi;
        // up(z): the highest point of voxel z's box (diamond) along n is on or above the plane;
        // false, …, false, true, … in z (n_z > 0)
        let up = |z: f64| {
            at_least_zero(n[2] * (z + 1.0) - lo_rhs, bp, || {
                self.up_exact(x, y, z as i32)
            })
        };
        // down(z): its lowest point is on or below the plane; true, …, true, false, …
        let down =
            |z: f64| at_least_zero(hi_rhs - n[2] * z, bp, || self.down_exact(x, y, z as i32));
        let (zl, zh) = (zl as f64, zh as f64);
        // z0 = the first z ≥ zl with up(z), or zh + 1; the division's guess, then settled (up
        // and down are only evaluated inside [zl, zh])
        let c = (lo_rhs * inv_nz).ceil() - 1.0;
        let mut z0 = if c.is_nan() {
            zl
        } else {
            c.clamp(zl, zh + 1.0)
        };
        while z0 > zl && up(z0 - 1.0) {
            z0 -= 1.0;
        }
        while z0 <= zh && !up(z0) {
            z0 += 1.0;
        }
        if z0 > zh {
            return None;
        }
        // z1 = the last z ≤ zh with down(z), or zl − 1
        let c = (hi_rhs * inv_nz).floor();
        let mut z1 = if c.is_nan() {
            zh
        } else {
            c.clamp(z0 - 1.0, zh)
        };
        while z1 < zh && down(z1 + 1.0) {
            z1 += 1.0;
        }
        while z1 >= z0 && !down(z1) {
            z1 -= 1.0;
        }
        (z0 <= z1).then_some((z0 as i32, z1 as i32))
    }

    /// Exact edge test `k, i` (numbering of `ne`) of the cell with minimum corner `(a, b)` in
    /// that projection's coordinates: `s·orient2d(v_i, v_{i+1}, q) ≥ 0` at the square's most
    /// interior corner (conservative) or at the inscribed diamond's most interior vertex (thin;
    /// both candidates when `|ne₀| = |ne₁|` in f64: the f64 magnitudes are monotone in the
    /// exact ones, so otherwise the larger one is the exact argmax).
    #[cold]
    #[inline(never)]
    fn edge_exact(&self, k: usize, i: usize, a: i32, b: i32) -> bool {
        let s = self.orient[k];
        if s == 0.0 {
            return true;
        }
        let [ca, cb] = PLANE[k];
        let p = |w: [f64; 3]| [w[ca], w[cb]];
        if let Some(wt) = &self.world {
            // on the world values, at every corner (vertex) of the cell's square (diamond):
            // the f32 edge's direction may have a zero component the exact one has not
            let (va, vb) = (p(wt.w[i]), p(wt.w[(i + 1) % 3]));
            let inside = |q: [f64; 2]| s * world::orient2d(&wt.frame, [ca, cb], va, vb, q) >= 0.0;
            let (a, b) = (a as f64, b as f64);
            let q: [[f64; 2]; 4] = match self.mode {
                Mode::Conservative => [[a, b], [a + 1.0, b], [a, b + 1.0], [a + 1.0, b + 1.0]],
                Mode::Thin => [
                    [a, b + 0.5],
                    [a + 1.0, b + 0.5],
                    [a + 0.5, b],
                    [a + 0.5, b + 1.0],
                ],
            };
            return q.into_iter().any(inside);
        }
        let (va, vb) = (p(self.v[i]), p(self.v[(i + 1) % 3]));
        let inside = |q: [f64; 2]| s * orient2d(va, vb, q) >= 0.0;
        let [n0, n1] = self.ne[k][i];
        let (a, b) = (a as f64, b as f64);
        match self.mode {
            Mode::Conservative => inside([
                a + if n0 > 0.0 { 1.0 } else { 0.0 },
                b + if n1 > 0.0 { 1.0 } else { 0.0 },
            ]),
            Mode::Thin => {
                let (m0, m1) = (n0.abs(), n1.abs());
                (m0 >= m1 && inside([a + 0.5 + 0.5 * sign(n0), b + 0.5]))
                    || (m1 >= m0 && inside([a + 0.5, b + 0.5 + 0.5 * sign(n1)]))
            }
        }
    }

    /// `n̂·(q − v₀)` with the exact normal, pointing up: its sign.
    #[inline]
    fn plane_at(&self, q: [f64; 3]) -> f64 {
        match &self.world {
            Some(wt) => self.flip * world::plane_side(&wt.frame, &wt.w, q),
            None => self.flip * plane_side(&self.v, q),
        }
    }

    /// Exact `up(z)` of column `(x, y)`: the box's corner furthest along `n`
    /// (conservative), or the diamond vertices `c + ½·sign(n_k)·e_k` (thin: every one, so that
    /// the maximum `n̂·(c − v₀) + ½‖n̂‖∞` is found whichever `|n̂_k|` is largest), on or above the
    /// plane.
    #[cold]
    #[inline(never)]
    fn up_exact(&self, x: i32, y: i32, z: i32) -> bool {
        let [x, y, z] = [x, y, z].map(|c| c as f64);
        let t = [sign(self.n[0]), sign(self.n[1]), 1.0];
        match self.mode {
            Mode::Conservative => {
                let q = [x + t[0].max(0.0), y + t[1].max(0.0), z + 1.0];
                self.plane_at(q) >= 0.0
            }
            Mode::Thin => [2, 0, 1].into_iter().any(|k| {
                let mut q = [x + 0.5, y + 0.5, z + 0.5];
                q[k] += 0.5 * t[k];
                t[k] != 0.0 && self.plane_at(q) >= 0.0
            }),
        }
    }

    /// Exact `down(z)`: as [`TriSetup::up_exact`] with the lowest corner (vertices), on or below
    /// the plane.
    #[cold]
    #[inline(never)]
    fn down_exact(&self, x: i32, y: i32, z: i32) -> bool {
        let [x, y, z] = [x, y, z].map(|c| c as f64);
        let t = [sign(self.n[0]), sign(self.n[1]), 1.0];
        match self.mode {
            Mode::Conservative => {
                let q = [x - t[0].min(0.0), y - t[1].min(0.0), z];
                self.plane_at(q) <= 0.0
            }
            Mode::Thin => [2, 0, 1].into_iter().any(|k| {
                let mut q = [x + 0.5, y + 0.5, z + 0.5];
                q[k] -= 0.5 * t[k];
                t[k] != 0.0 && self.plane_at(q) <= 0.0
            }),
        }
    }

    /// The three edge tests of one projection from their f64 values `f` (filter bounds `b`):
    /// certain ones decided in f64, the others exactly; `cell(i)` is the cell's minimum corner in
    /// that projection's coordinates.
    #[inline(always)]
    fn edges(&self, k: usize, f: [f64; 3], b: [f64; 3], cell: [i32; 2]) -> bool {
        (0..3).all(|i| at_least_zero(f[i], b[i], || self.edge_exact(k, i, cell[0], cell[1])))
    }

    /// The appendix routine on swizzled coordinates: calls `emit(p, first)` for every overlapped
    /// voxel `p` in `[lo, hi]` (swizzled, inclusive) in order x, y, z; `first` is true for the
    /// first voxel of each (x, y) column. The composition of [`TriSetup::column_inside`],
    /// [`TriSetup::column_depth`] and [`TriSetup::side_inside`], with the edge functions
    /// evaluated incrementally.
    #[inline]
    pub fn scan(&self, lo: [i32; 3], hi: [i32; 3], mut emit: impl FnMut([i32; 3], bool)) {
        // The paper's appendix routine.
        let lo = [
            lo[0].max(self.bmin[0]),
            lo[1].max(self.bmin[1]),
            lo[2].max(self.bmin[2]),
        ];
        let hi = [
            hi[0].min(self.bmax[0]),
            hi[1].min(self.bmax[1]),
            hi[2].min(self.bmax[2]),
        ];
        if lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2] {
            return;
        }
        let inv_nz = 1.0 / self.n[2];
        let [xy, yz, zx] = self.ne;
        let [dxy, dyz, dzx] = self.de;
        let [bxy, byz, bzx] = self.be;
        for px in lo[0]..=hi[0] {
            let x = px as f64;
            // ZX edge functions without the z term
            let czx = [
                zx[0][1] * x + dzx[0],
                zx[1][1] * x + dzx[1],
                zx[2][1] * x + dzx[2],
            ];
            for py in lo[1]..=hi[1] {
                let y = py as f64;
                // dominant projection (paper line 15)
                let f = [
                    xy[0][0] * x + xy[0][1] * y + dxy[0],
                    xy[1][0] * x + xy[1][1] * y + dxy[1],
                    xy[2][0] * x + xy[2][1] * y + dxy[2],
                ];
                if !(f[0] >= bxy[0] && f[1] >= bxy[1] && f[2] >= bxy[2])
                    && (f[0] < -bxy[0]
                        || f[1] < -bxy[1]
                        || f[2] < -bxy[2]
                        || !self.edges(0, f, bxy, [px, py]))
                {
                    continue;
                }
                // depth range from the plane (lines 16-17, corrected)
                let Some((z0, z1)) = self.depth(px, py, lo[2], hi[2], self.bp, inv_nz) else {
                    continue;
                };
                // the other two projections (line 19, with the right coordinates)
                let cyz = [
                    yz[0][0] * y + dyz[0],
                    yz[1][0] * y + dyz[1],
                    yz[2][0] * y + dyz[2],
                ];
                let mut first = true;
                for pz in z0..=z1 {
                    let z = pz as f64;
                    let g = [
                        yz[0][1] * z + cyz[0],
                        yz[1][1] * z + cyz[1],
                        yz[2][1] * z + cyz[2],
                    ];
                    let h = [
                        zx[0][0] * z + czx[0],
                        zx[1][0] * z + czx[1],
                        zx[2][0] * z + czx[2],
                    ];
                    let certain = g[0] >= byz[0]
                        && g[1] >= byz[1]
                        && g[2] >= byz[2]
                        && h[0] >= bzx[0]
                        && h[1] >= bzx[1]
                        && h[2] >= bzx[2];
                    if certain
                        || (g[0] >= -byz[0]
                            && g[1] >= -byz[1]
                            && g[2] >= -byz[2]
                            && h[0] >= -bzx[0]
                            && h[1] >= -bzx[1]
                            && h[2] >= -bzx[2]
                            && self.edges(1, g, byz, [py, pz])
                            && self.edges(2, h, bzx, [pz, px]))
                    {
                        emit([px, py, pz], first);
                        first = false;
                    }
                }
            }
        }
    }
}

#[inline]
fn clamp_i32(x: f64) -> i32 {
    x.clamp(i32::MIN as f64, i32::MAX as f64) as i32
}

/// The appendix routine: calls `emit(voxel)` for every voxel in `[bmin, bmax]` (inclusive, grid
/// coordinates, unswizzled) that the triangle overlaps under `mode`, in the deterministic order
/// swizzled x, then y, then z (depth axis innermost). Zero-area and non-finite triangles emit
/// nothing.
pub fn voxelize_triangle(
    v: &[[f32; 3]; 3],
    bmin: [i32; 3],
    bmax: [i32; 3],
    mode: Mode,
    emit: &mut impl FnMut([i32; 3]),
) {
    let Some(s) = TriSetup::new(v, mode) else {
        return;
    };
    s.scan(s.swizzle(bmin), s.swizzle(bmax), |p, _| {
        emit(s.unswizzle(p))
    });
}

/// [`voxelize_triangle`] of a triangle in **world** coordinates of `grid`, decided exactly for
/// those coordinates and the grid as stated ([`TriSetup::with_world`]): the voxels in
/// `[bmin, bmax]` (grid coordinates, inclusive) that [`crate::ChunkVoxelizer::add_world`]
/// marks for it when `[bmin, bmax]` is its chunk, in the same order of decisions: a conservative
/// triangle whose f32 grid coordinates (`grid.to_grid`) lie inside one voxel's open interior
/// (the same voxel for the exact image: `to_grid` keeps every strict comparison with an
/// integer) marks that voxel if its grid normal is nonzero, any other the scan's set. The GPU
/// voxelizer's host fallback decides its listed triangles with it.
pub fn voxelize_world_triangle(
    grid: &Grid,
    world: &[[f32; 3]; 3],
    bmin: [i32; 3],
    bmax: [i32; 3],
    mode: Mode,
    emit: &mut impl FnMut([i32; 3]),
) {
    let v = world.map(|p| grid.to_grid(p));
    if mode == Mode::Conservative {
        if let Some(p) = interior_voxel(&v) {
            // `chunk::face`: the normal ChunkVoxelizer's interior path needs
            let n = cross_f64(&to_f64(&v));
            let nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
            let inside = (0..3).all(|k| p[k] >= bmin[k] && p[k] <= bmax[k]);
            if inside && nn > 0.0 && nn.is_finite() {
                emit(p);
                return;
            }
        }
    }
    let Some(s) = TriSetup::with_world(&v, Some((world, grid)), mode) else {
        return;
    };
    s.scan(s.swizzle(bmin), s.swizzle(bmax), |p, _| {
        emit(s.unswizzle(p))
    });
}
