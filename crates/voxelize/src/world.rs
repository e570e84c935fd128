//! Exact overlap decisions in the input's own coordinates (the promise is in the crate docs,
//! "Exact in the input's own coordinates").
//!
//! The scan runs on f32 grid coordinates `g̃ = f32((p − origin) / voxel_size)` (`Grid::to_grid`),
//! a perturbation of the exact grid coordinates `g = (p − origin) / voxel_size` of the input's
//! f32 world positions `p`. This module decides the predicates of [`crate::overlap`] on the
//! exact `g`, by evaluating them in world coordinates: a voxel corner `c` (integer or
//! half-integer) is the world point `origin + c·voxel_size`, and since `g ↦ p` is a translation
//! and a positive uniform scale, `sign orient2d(g_a, g_b, c) = sign orient2d(p_a, p_b, origin +
//! c·voxel_size)` and likewise for orient3d (Shewchuk, "Adaptive Precision Floating-Point
//! Arithmetic and Fast Robust Geometric Predicates", DCG 18, 1997, for the f64 case).
//!
//! * When every corner coordinate `origin + c·voxel_size` is an f64 (checked exactly with a fused
//!   multiply-add and Knuth's two-sum: both error terms zero), Shewchuk's predicates (the
//!   `robust` crate, exact for any f64 input) decide on the world values.
//! * Otherwise the determinant is evaluated in big-integer arithmetic: every input is a dyadic
//!   rational `m·2^e`, all are scaled to the smallest exponent present, and the sign of the
//!   integer determinant is the answer.
//!
//! [`Perturbation`] bounds how far the f32 grid coordinates can be from the exact ones, and
//! how much each predicate's value can move with them; [`crate::overlap::TriSetup`] widens its
//! floating-point filter by these amounts, so only decisions within them reach this module.

use num_bigint::BigInt;
use std::cmp::Ordering;
use voxlod_geom::Grid;

/// A grid's origin and voxel size (one axis order: the caller swizzles).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// World coordinates of the grid's minimum corner.
    pub origin: [f64; 3],
    /// World units per voxel (finite, > 0).
    pub voxel_size: f64,
}

impl Frame {
    /// The frame of `grid`.
    pub fn of(grid: &Grid) -> Frame {
        Frame {
            origin: grid.origin,
            voxel_size: grid.voxel_size,
        }
    }

    /// The frame with axes permuted: axis `k` of the result is axis `swz[k]` of `self`.
    pub fn swizzled(&self, swz: [usize; 3]) -> Frame {
        Frame {
            origin: swz.map(|j| self.origin[j]),
            voxel_size: self.voxel_size,
        }
    }

    /// `origin[k] + c·voxel_size` if it is exactly an f64 (`c` a multiple of ½ below 2⁵²).
    #[inline]
    fn corner_f64(&self, k: usize, c: f64) -> Option<f64> {
        let s = self.voxel_size;
        let hi = c * s;
        if c.mul_add(s, -hi) != 0.0 || !hi.is_finite() {
            return None;
        }
        let o = self.origin[k];
        let w = o + hi;
        // two-sum: w is exact iff its error term is 0
        let bb = w - o;
        let err = (o - (w - bb)) + (hi - bb);
        (err == 0.0 && w.is_finite()).then_some(w)
    }
}

/// `x = m·2^e` exactly (finite `x`).
#[inline]
fn decode(x: f64) -> (i64, i32) {
    debug_assert!(x.is_finite());
    let bits = x.to_bits();
    let exp = ((bits >> 52) & 0x7ff) as i32;
    let frac = (bits & ((1u64 << 52) - 1)) as i64;
    let (m, e) = if exp == 0 {
        (frac, -1074)
    } else {
        (frac | 1 << 52, exp - 1075)
    };
    (if bits >> 63 == 1 { -m } else { m }, e)
}

/// Exact dyadic values at one common scale: collects `m·2^e` terms, then gives each as an
/// integer multiple of `2^min_e`.
struct Scale {
    min_e: i32,
}

impl Scale {
    fn new(values: &[f64], frame: &Frame) -> Scale {
        let mut min_e = decode(frame.voxel_size).1 - 1; // half-integer corners
        for &x in values.iter().chain(&frame.origin) {
            if x != 0.0 {
                min_e = min_e.min(decode(x).1);
            }
        }
        Scale { min_e }
    }
    fn big(&self, x: f64) -> BigInt {
        if x == 0.0 {
            return BigInt::from(0);
        }
        let (m, e) = decode(x);
        BigInt::from(m) << ((e - self.min_e) as usize)
    }
    /// `origin[k] + c·voxel_size` (`c` a multiple of ½) exactly.
    fn corner(&self, frame: &Frame, k: usize, c: f64) -> BigInt {
        let h = (2.0 * c) as i64;
        debug_assert_eq!(h as f64, 2.0 * c);
        let (m, e) = decode(frame.voxel_size);
        // c·s = h·m·2^(e−1)
        self.big(frame.origin[k])
            + ((BigInt::from(h) * BigInt::from(m)) << ((e - 1 - self.min_e) as usize))
    }
}

fn sign_of(b: &BigInt) -> f64 {
    match b.sign() {
        num_bigint::Sign::Minus => -1.0,
        num_bigint::Sign::NoSign => 0.0,
        num_bigint::Sign::Plus => 1.0,
    }
}

/// The sign of `g − c` for the exact grid coordinate `g` of world value `p` on axis `k` and the
/// (half-)integer `c`: `p` against `origin[k] + c·voxel_size`.
pub fn cmp_corner(frame: &Frame, k: usize, p: f64, c: f64) -> Ordering {
    if let Some(w) = frame.corner_f64(k, c) {
        return p.partial_cmp(&w).expect("finite coordinates");
    }
    let sc = Scale::new(&[p], frame);
    sc.big(p).cmp(&sc.corner(frame, k, c))
}

/// The sign of `orient2d(a, b, q)` (as [`crate::predicates::orient2d`]) for world points `a`,
/// `b` on axes `axes` of the frame and the grid corner `q` (multiples of ½), exactly.
pub fn orient2d(frame: &Frame, axes: [usize; 2], a: [f64; 2], b: [f64; 2], q: [f64; 2]) -> f64 {
    if let (Some(q0), Some(q1)) = (
        frame.corner_f64(axes[0], q[0]),
        frame.corner_f64(axes[1], q[1]),
    ) {
        return crate::predicates::orient2d(a, b, [q0, q1]).signum_or_zero();
    }
    let sc = Scale::new(&[a[0], a[1], b[0], b[1]], frame);
    let (a0, a1) = (sc.big(a[0]), sc.big(a[1]));
    let e0 = sc.big(b[0]) - &a0;
    let e1 = sc.big(b[1]) - &a1;
    let d0 = sc.corner(frame, axes[0], q[0]) - a0;
    let d1 = sc.corner(frame, axes[1], q[1]) - a1;
    sign_of(&(e0 * d1 - e1 * d0))
}

/// The sign of `plane_side(v, q)` (as [`crate::predicates::plane_side`]) for world vertices `v`
/// and the grid corner `q` (multiples of ½), exactly.
pub fn plane_side(frame: &Frame, v: &[[f64; 3]; 3], q: [f64; 3]) -> f64 {
    if let (Some(q0), Some(q1), Some(q2)) = (
        frame.corner_f64(0, q[0]),
        frame.corner_f64(1, q[1]),
        frame.corner_f64(2, q[2]),
    ) {
        return crate::predicates::plane_side(v, [q0, q1, q2]).signum_or_zero();
    }
    let flat: Vec<f64> = v.iter().flatten().copied().collect();
    let sc = Scale::new(&flat, frame);
    let b = v.map(|p| p.map(|x| sc.big(x)));
    let e1: [BigInt; 3] = [0, 1, 2].map(|k| &b[1][k] - &b[0][k]);
    let e2: [BigInt; 3] = [0, 1, 2].map(|k| &b[2][k] - &b[0][k]);
    let d: [BigInt; 3] = [0, 1, 2].map(|k| sc.corner(frame, k, q[k]) - &b[0][k]);
    let n = [
        &e1[1] * &e2[2] - &e1[2] * &e2[1],
        &e1[2] * &e2[0] - &e1[0] * &e2[2],
        &e1[0] * &e2[1] - &e1[1] * &e2[0],
    ];
    sign_of(&(&n[0] * &d[0] + &n[1] * &d[1] + &n[2] * &d[2]))
}

trait SignumOrZero {
    fn signum_or_zero(self) -> f64;
}
impl SignumOrZero for f64 {
    #[inline]
    fn signum_or_zero(self) -> f64 {
        if self > 0.0 {
            1.0
        } else if self < 0.0 {
            -1.0
        } else {
            0.0
        }
    }
}

/// How far a triangle's f32 grid coordinates may be from its exact ones, and what that does to
/// each predicate of [`crate::overlap`] (all zero when the grid coordinates are the input).
///
/// With `M` the largest magnitude of the triangle's f32 grid coordinates, every coordinate is
/// within `η = 2⁻²³·M + 2⁻¹⁴⁰` of the exact one: `to_grid` is a subtraction and a
/// multiplication by the rounded reciprocal in f64 (relative error below `3.01·2⁻⁵³`) and a
/// rounding to f32 (half an ulp, `2⁻²⁴` relative, or `2⁻¹⁵⁰` absolute for subnormals).
/// With `E` the triangle's largest extent (plus `2η`), the exact edge differences are within
/// `2η` of the f32 ones and at most `E` in magnitude; then
/// * each normal component `n_k = e₁ᵢe₂ⱼ − e₁ⱼe₂ᵢ` moves by at most `2·(2η·2E + 4η²) = dn`;
/// * an edge function `(b − a) × (q − a)` at a corner `q` with `|q − a| ≤ E + 1` per axis (the
///   scan only uses the filter inside the triangle's closed voxel box) moves by at most
///   `2η·2(E+1) + η·2E + 4η² ≤ de = 8η(E + 1)` (the thin diamond's support `½max|ne|` is
///   1-Lipschitz, and is inside that);
/// * the plane function `n·(q − v₀)` (`|q − v₀| ≤ E + 2` per axis) moves by at most
///   `Σ|Δn_k|·(E+2) + η·Σ|n_k| + 3·dn·η ≤ dp = 3dn(E + 2) + 2η(Σ|ñ_k| + 3dn)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Perturbation {
    /// `η`, per coordinate.
    pub eta: f64,
    /// `dn`, per normal component.
    pub dn: f64,
    /// `de`, per edge function.
    pub de: f64,
    /// `dp` without the `2η·Σ|ñ_k|` part (added by [`Perturbation::dp`]).
    dp0: f64,
}

impl Perturbation {
    /// The bounds for f32 grid vertices `v` (`M` and `E` from them).
    pub fn of(v: &[[f64; 3]; 3]) -> Perturbation {
        let m = v.iter().flatten().fold(0.0f64, |m, c| m.max(c.abs()));
        let ext = (0..3)
            .map(|k| {
                let lo = v[0][k].min(v[1][k]).min(v[2][k]);
                let hi = v[0][k].max(v[1][k]).max(v[2][k]);
                hi - lo
            })
            .fold(0.0f64, f64::max);
        Self::of_bounds(m, ext)
    }

    /// The bounds from `M` (the largest coordinate magnitude) and the largest extent
    /// `max_k (max − min)` of the vertices, as [`Perturbation::of`] finds them.
    #[inline]
    pub fn of_bounds(m: f64, ext: f64) -> Perturbation {
        let eta = m * (1.0 / (1u64 << 23) as f64) + 2f64.powi(-140);
        let e = ext + 2.0 * eta;
        // a little over each bound, for the rounding of these formulas
        let dn = 8.0 * eta * (e + eta) * 1.01;
        let de = 8.0 * eta * (e + 1.0) * 1.01;
        let dp0 = (3.0 * dn * (e + 2.0) + 6.0 * eta * dn) * 1.01;
        Perturbation { eta, dn, de, dp0 }
    }

    /// `dp` for the f64 normal `n`.
    pub fn dp(&self, n: [f64; 3]) -> f64 {
        self.dp0 + 2.02 * self.eta * (n[0].abs() + n[1].abs() + n[2].abs())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn big_and_f64_paths_agree() {
        // a frame whose corners are f64 (power-of-two size) and one whose corners are not
        let exact = Frame {
            origin: [0.5, -2.0, 0.25],
            voxel_size: 0.125,
        };
        let odd = Frame {
            origin: [0.1, -2.3, 0.7],
            voxel_size: 0.0137,
        };
        assert!(exact.corner_f64(0, 3.5).is_some());
        assert!(odd.corner_f64(0, 3.0).is_none());
        // the corner's own world value: a tie, in both
        for f in [exact, odd] {
            for c in [0.0, 1.0, 2.5, 17.0] {
                let w = f.origin[0] + c * f.voxel_size;
                let got = cmp_corner(&f, 0, w, c);
                // w is the rounded corner: equal, or on the side the rounding went
                let want = {
                    let sc = Scale::new(&[w], &f);
                    sc.big(w).cmp(&sc.corner(&f, 0, c))
                };
                assert_eq!(got, want);
            }
        }
        // odd frame, point one ulp either side of a rounded corner
        let c = 7.0;
        let w = odd.origin[0] + c * odd.voxel_size;
        assert!(w > 0.0);
        let lo = f64::from_bits(w.to_bits() - 1);
        let hi = f64::from_bits(w.to_bits() + 1);
        assert_eq!(cmp_corner(&odd, 0, lo, c), Ordering::Less);
        assert_eq!(cmp_corner(&odd, 0, hi, c), Ordering::Greater);
    }

    #[test]
    fn orientation_matches_robust_where_corners_are_f64() {
        let f = Frame {
            origin: [1.0, 2.0, 3.0],
            voxel_size: 0.5,
        };
        let a = [1.25, 2.0];
        let b = [3.0, 2.75];
        for q in [[0.0, 0.0], [1.0, 1.0], [3.5, 1.5], [2.0, 4.0]] {
            let w = [f.origin[0] + q[0] * 0.5, f.origin[1] + q[1] * 0.5];
            let want = crate::predicates::orient2d(a, b, w).signum_or_zero();
            assert_eq!(orient2d(&f, [0, 1], a, b, q), want);
            // the big-integer path on the same numbers
            let sc = Scale::new(&[a[0], a[1], b[0], b[1]], &f);
            let e0 = sc.big(b[0]) - sc.big(a[0]);
            let e1 = sc.big(b[1]) - sc.big(a[1]);
            let d0 = sc.corner(&f, 0, q[0]) - sc.big(a[0]);
            let d1 = sc.corner(&f, 1, q[1]) - sc.big(a[1]);
            assert_eq!(sign_of(&(e0 * d1 - e1 * d0)), want);
        }
    }
}
