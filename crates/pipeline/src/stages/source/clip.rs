//! Clipping a triangle to an axis-aligned box: Sutherland & Hodgman, "Reentrant polygon
//! clipping" (CACM 1974), one box plane after the other, with the vertex attributes
//! (normal, colour) interpolated linearly along the cut edges. Used by the source-geometry
//! stage for triangles that reach past a chunk's quantization box (docs/FORMAT.md 14.4).

/// A polygon vertex: position (voxels in the chunk's frame), normal and RGBA colour (0..=255).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ClipVertex {
    pub p: [f64; 3],
    pub n: [f64; 3],
    pub c: [f64; 4],
}

impl ClipVertex {
    /// The point `t` of the way from `self` to `o`, attributes interpolated.
    fn lerp(&self, o: &ClipVertex, t: f64) -> ClipVertex {
        let mix = |a: f64, b: f64| a + (b - a) * t;
        ClipVertex {
            p: std::array::from_fn(|i| mix(self.p[i], o.p[i])),
            n: std::array::from_fn(|i| mix(self.n[i], o.n[i])),
            c: std::array::from_fn(|i| mix(self.c[i], o.c[i])),
        }
    }
}

/// Clips the convex polygon `poly` to the closed box `[lo, hi]³` (the same bounds on every
/// axis); the result is empty or a convex polygon of at most `poly.len() + 6` vertices, every
/// position inside the box (cut points are clamped onto the plane they were cut at, so
/// rounding never puts one outside). Points on a plane are kept.
pub(crate) fn clip_to_box(poly: &[ClipVertex], lo: f64, hi: f64) -> Vec<ClipVertex> {
    assert!(lo <= hi, "empty box [{lo}, {hi}]");
    let mut cur = poly.to_vec();
    let mut next = Vec::with_capacity(poly.len() + 6);
    for axis in 0..3 {
        for (bound, keep_below) in [(lo, false), (hi, true)] {
            // signed distance to the plane, ≥ 0 inside
            let dist = |v: &ClipVertex| {
                if keep_below {
                    bound - v.p[axis]
                } else {
                    v.p[axis] - bound
                }
            };
            next.clear();
            for (k, a) in cur.iter().enumerate() {
                let b = &cur[(k + 1) % cur.len()];
                let (da, db) = (dist(a), dist(b));
                if da >= 0.0 {
                    next.push(*a);
                }
                if (da >= 0.0) != (db >= 0.0) && da != db {
                    let mut cut = a.lerp(b, da / (da - db));
                    cut.p[axis] = bound;
                    next.push(cut);
                }
            }
            std::mem::swap(&mut cur, &mut next);
            if cur.is_empty() {
                return cur;
            }
        }
    }
    for v in &mut cur {
        v.p = v.p.map(|x| x.clamp(lo, hi));
    }
    cur
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(p: [f64; 3]) -> ClipVertex {
        ClipVertex {
            p,
            n: [0.0, 0.0, 1.0],
            c: [p[0], 0.0, 0.0, 255.0],
        }
    }

    fn area(poly: &[ClipVertex]) -> f64 {
        let mut s = [0.0; 3];
        for k in 1..poly.len().saturating_sub(1) {
            let a: [f64; 3] = std::array::from_fn(|i| poly[k].p[i] - poly[0].p[i]);
            let b: [f64; 3] = std::array::from_fn(|i| poly[k + 1].p[i] - poly[0].p[i]);
            s[0] += a[1] * b[2] - a[2] * b[1];
            s[1] += a[2] * b[0] - a[0] * b[2];
            s[2] += a[0] * b[1] - a[1] * b[0];
        }
        (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt() / 2.0
    }

    #[test]
    fn inside_is_unchanged_outside_is_empty() {
        let t = [v([1.0, 1.0, 1.0]), v([5.0, 1.0, 1.0]), v([1.0, 5.0, 1.0])];
        assert_eq!(clip_to_box(&t, 0.0, 10.0), t.to_vec());
        let far = [
            v([20.0, 1.0, 1.0]),
            v([25.0, 1.0, 1.0]),
            v([20.0, 5.0, 1.0]),
        ];
        assert!(clip_to_box(&far, 0.0, 10.0).is_empty());
    }

    #[test]
    fn a_big_triangle_keeps_the_area_inside_and_interpolates() {
        // the plane z = 2 cut by a triangle much larger than the box: the box's square remains
        let t = [
            v([-100.0, -100.0, 2.0]),
            v([300.0, -100.0, 2.0]),
            v([-100.0, 300.0, 2.0]),
        ];
        let p = clip_to_box(&t, 0.0, 10.0);
        assert!((area(&p) - 100.0).abs() < 1e-9, "{}", area(&p));
        for q in &p {
            assert!(q.p.iter().all(|x| (0.0..=10.0).contains(x)));
            // colour red = x, interpolated linearly
            assert!((q.c[0] - q.p[0]).abs() < 1e-9);
        }
        // x + y ≤ 15 inside the square: the square less the corner triangle of area 12.5
        let t = [v([0.0, 0.0, 2.0]), v([15.0, 0.0, 2.0]), v([0.0, 15.0, 2.0])];
        let p = clip_to_box(&t, 0.0, 10.0);
        assert_eq!(p.len(), 5);
        assert!((area(&p) - 87.5).abs() < 1e-9, "{}", area(&p));
    }
}
