//! Exact geometric predicates for the overlap tests: Shewchuk, "Adaptive Precision
//! Floating-Point Arithmetic and Fast Robust Geometric Predicates", Discrete & Computational
//! Geometry 18, 1997 (orient2d, orient3d), through the `robust` crate (georust's port).
//!
//! Both return a value whose **sign is exact** for any f64 input whose intermediate products
//! neither overflow nor underflow. The voxelizer's inputs are f32 vertex coordinates (exact in
//! f64, magnitudes in `[2⁻¹⁴⁹, 2¹²⁸)`) and integer or half-integer voxel-corner coordinates
//! (`|c| ≤ 2³¹ + 1`): the largest product of the expansions is below `(2¹²⁹)³ · 2²⁷`, the
//! smallest nonzero one above `(2⁻¹⁴⁹)³ · 2⁻⁵³`, far inside f64's normal range, so the
//! signs are exact for every input the overlap tests give them. The magnitude is an
//! approximation of the determinant (the value itself when the predicate's own filter
//! decides).
//!
//! [`crate::overlap`] evaluates its tests in plain f64 first and calls these only when the
//! f64 value lies inside its proven error bound (a floating-point filter).

use robust::{Coord, Coord3D};

/// `sign((b − a) × (c − a))`: positive if `a, b, c` turn counterclockwise in the plane
/// (the z component of the cross product of the 2D points lifted to z = 0). Exact.
#[inline]
pub fn orient2d(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let p = |q: [f64; 2]| Coord { x: q[0], y: q[1] };
    // robust's orient2d is det[a − c, b − c] = (b − a) × (c − a)
    robust::orient2d(p(a), p(b), p(c))
}

/// `sign(((v₁ − v₀) × (v₂ − v₀)) · (q − v₀))`: positive if `q` lies on the side of the
/// triangle's plane that its normal (right-hand rule, winding `v₀, v₁, v₂`) points to. Exact.
#[inline]
pub fn plane_side(v: &[[f64; 3]; 3], q: [f64; 3]) -> f64 {
    let p = |q: [f64; 3]| Coord3D {
        x: q[0],
        y: q[1],
        z: q[2],
    };
    // robust's orient3d is det[a − d, b − d, c − d] = −((b − a) × (c − a)) · (d − a)
    -robust::orient3d(p(v[0]), p(v[1]), p(v[2]), p(q))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orientation_conventions() {
        assert!(orient2d([0.0, 0.0], [1.0, 0.0], [0.0, 1.0]) > 0.0);
        assert!(orient2d([0.0, 0.0], [0.0, 1.0], [1.0, 0.0]) < 0.0);
        assert_eq!(orient2d([0.0, 0.0], [1.0, 1.0], [3.0, 3.0]), 0.0);
        let v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert!(plane_side(&v, [0.3, 0.3, 1.0]) > 0.0);
        assert!(plane_side(&v, [5.0, -7.0, -1e-30]) < 0.0);
        assert_eq!(plane_side(&v, [9.0, 4.0, 0.0]), 0.0);
    }

    #[test]
    fn exact_where_f64_rounds() {
        // (1 + 2⁻⁵²)·(1 − 2⁻⁵²) − 1 = −2⁻¹⁰⁴ rounds to 0 in f64
        let e = f64::EPSILON;
        let d = orient2d([0.0, 0.0], [1.0 + e, 1.0], [1.0, 1.0 - e]);
        assert!(d < 0.0, "{d}");
        // tiny f32 coordinates: products near 2⁻²⁹⁸
        let t = f32::from_bits(1) as f64;
        assert!(orient2d([0.0, 0.0], [t, 0.0], [0.0, t]) > 0.0);
        let v = [[0.0, 0.0, 0.0], [t, 0.0, 0.0], [0.0, t, 0.0]];
        assert!(plane_side(&v, [0.0, 0.0, t]) > 0.0);
    }
}
