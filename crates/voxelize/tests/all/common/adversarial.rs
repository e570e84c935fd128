//! Adversarial triangles for the exactness tests (`tests/exact.rs` here, and the GPU backend's
//! `crates/gpu/tests/all/exactness.rs`, which includes this module by path): vertices nudged one or
//! two ulps across voxel corners, edges and faces, planes rounded through a corner, edges
//! through a voxel edge, slivers, axis-aligned triangles, near-ties of the dominant axis and
//! sliver projections, all within about 5 voxels of `o`.

use super::{cross, Rng};

/// `x`, or one of its neighbouring f32 values one or two ulps away.
pub fn nudge(rng: &mut Rng, x: f32) -> f32 {
    match rng.int(0, 3) {
        0 => x.next_up(),
        1 => x.next_down(),
        2 => x.next_up().next_up(),
        _ => x,
    }
}

/// Adversarial triangles of category `kind` near `o`.
pub fn adversarial(rng: &mut Rng, kind: usize, o: f64) -> [[f32; 3]; 3] {
    let grid_pt = |rng: &mut Rng| {
        // on a corner, an edge or a face of the grid (some coordinates integer, others
        // arbitrary), then nudged by an ulp or two
        [0, 1, 2].map(|_| {
            let c = o + rng.int(0, 4) as f64;
            let c = if rng.f64() < 0.7 { c } else { c + rng.f64() };
            nudge(rng, c as f32)
        })
    };
    match kind % 9 {
        0 => [grid_pt(rng), grid_pt(rng), grid_pt(rng)],
        // the plane through a voxel corner (rounded to f32: it passes by ~1e-7 of a voxel)
        1 | 2 => {
            let c = [0, 1, 2].map(|_| o + rng.int(1, 3) as f64);
            let n = rng.point(-1.0, 1.0);
            // two directions in the plane
            let a = cross(n, rng.point(-1.0, 1.0));
            let b = cross(n, a);
            let s = rng.range(0.5, 3.0);
            let p = |u: f64, w: f64| [0, 1, 2].map(|k| (c[k] + s * (u * a[k] + w * b[k])) as f32);
            [
                p(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)),
                p(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)),
                p(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)),
            ]
        }
        // an edge through a voxel edge: two vertices symmetric about a grid line
        3 => {
            let c = [0, 1, 2].map(|_| o + rng.int(1, 3) as f64);
            let d = rng.point(-1.5, 1.5);
            let k = rng.int(0, 2) as usize;
            let mut a = [0, 1, 2].map(|j| c[j] + d[j]);
            let mut b = [0, 1, 2].map(|j| c[j] - d[j]);
            a[k] = c[k] + rng.range(-1.0, 1.0);
            b[k] = c[k] + rng.range(-1.0, 1.0);
            let w = rng.point(o, o + 4.0);
            [a, b, w].map(|p| p.map(|x| nudge(rng, x as f32)))
        }
        // sliver: the third vertex an ulp off the segment of the first two
        4 => {
            let a = rng.point(o, o + 4.0);
            let b = rng.point(o, o + 4.0);
            let t = rng.f64();
            let m = [0, 1, 2].map(|k| a[k] + t * (b[k] - a[k]));
            [
                a.map(|x| x as f32),
                b.map(|x| x as f32),
                m.map(|x| nudge(rng, x as f32)),
            ]
        }
        // axis-aligned, on or an ulp off a grid plane
        5 => {
            let k = rng.int(0, 2) as usize;
            let c0 = (o + rng.int(0, 4) as f64) as f32;
            let c = nudge(rng, c0);
            let mut t = [grid_pt(rng), grid_pt(rng), grid_pt(rng)];
            for v in &mut t {
                v[k] = c;
            }
            t
        }
        // near-tie of the dominant axis: normal close to (1, 0, ±1)
        6 => {
            let c = rng.point(o + 1.0, o + 3.0);
            let sz = if rng.f64() < 0.5 { 1.0 } else { -1.0 };
            let n = [1.0, rng.range(-1e-6, 1e-6), sz];
            let a = cross(n, [0.0, 1.0, 0.0]);
            let b = cross(n, a);
            let p = |u: f64, w: f64| [0, 1, 2].map(|k| (c[k] + u * a[k] + w * b[k]) as f32);
            [
                p(rng.range(-1.5, 1.5), rng.range(-1.5, 1.5)),
                p(rng.range(-1.5, 1.5), rng.range(-1.5, 1.5)),
                p(rng.range(-1.5, 1.5), rng.range(-1.5, 1.5)),
            ]
        }
        // nearly collinear in one projection only (a sliver projection)
        7 => {
            let a = rng.point(o, o + 4.0);
            let b = rng.point(o, o + 4.0);
            let t = rng.f64();
            let mut m = [0, 1, 2].map(|k| a[k] + t * (b[k] - a[k]));
            let k = rng.int(0, 2) as usize;
            m[k] += rng.range(-2.0, 2.0);
            [
                a.map(|x| x as f32),
                b.map(|x| x as f32),
                m.map(|x| x as f32),
            ]
        }
        // general
        _ => [0, 1, 2].map(|_| rng.point(o, o + 4.0).map(|x| x as f32)),
    }
}
