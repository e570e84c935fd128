//! The screen-space error cut that `render` and the streaming viewer draw (Chajdas,
//! Reitinger & Westermann, "Scalable rendering for very large meshes", WSCG 2014, section 5:
//! a chunk is refined while its voxels project to more than a threshold of pixels), with the
//! voxel's *real* pixel size for a [`Shot`] and view-frustum culling.
//!
//! **Pixel size.** A length `e` at view depth `z` (distance along the viewing direction, not
//! to the eye) projects to `e·f/z` pixels in the middle of the picture, `f = H / (2·tan(fov_y/2))`
//! the focal length in pixels; off the axis the perspective stretches it by at most
//! `√(1 + (x/z)² + (y/z)²)` (the largest singular value of the projection's Jacobian), and
//! inside the frustum `|x/z| ≤ tan(fov_x/2)`, `|y/z| ≤ tan(fov_y/2)`. So
//! `error = voxel edge · f · √(1 + tan²(fov_x/2) + tan²(fov_y/2)) / z_min`, with `z_min` the
//! nearest view depth of the node's box (clamped to the near plane), is an upper bound of the
//! length in pixels of any voxel edge of the node in the picture. The format crate's
//! `Camera::error` uses the Euclidean distance instead, which overstates the distance away from
//! the axis and so picks too coarse a level at the sides of a wide picture.
//!
//! **Culling.** A node whose box lies wholly outside one plane of the view frustum is neither
//! drawn nor refined.
//!
//! **The cut.** From the root, a node in the frustum is refined into its stored children while
//! its error exceeds the threshold; otherwise it is selected (leaves whatever their error).
//! The selected nodes never overlap (one per root-to-leaf path at most).
//!
//! **Source geometry.** A leaf whose error still exceeds the threshold is where the voxels no
//! longer hold the pixel error: [`CutNode::over`] marks those leaves, and `render` draws them
//! from their stored source triangles (`crate::source_draw`) when the file has them.

use glam::{DVec3, DVec4};
use voxlod_format::{Aabb, Reader};

use crate::camera::Shot;

/// A selected node of the cut.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CutNode {
    /// Node index in the file.
    pub index: usize,
    /// Its error in pixels ([`voxel_pixels`]).
    pub error: f64,
    /// A leaf (level 0) whose voxels still project above the threshold: the node a source
    /// geometry stream would draw as triangles (`render` does, see [`crate::over_leaves`]).
    pub over: bool,
}

/// Focal length in pixels times the largest off-axis stretch in the frustum (see the module
/// docs): pixels per world unit at view depth 1.
fn pixels_at_unit_depth(shot: &Shot) -> f64 {
    let ty = (0.5 * shot.fov_y).tan();
    let tx = ty * shot.width as f64 / shot.height as f64;
    shot.height as f64 / (2.0 * ty) * (1.0 + tx * tx + ty * ty).sqrt()
}

/// Nearest view depth of `b` for `shot` (the minimum over its corners of the distance along
/// the viewing direction; a linear function, so a corner attains it).
pub fn nearest_depth(shot: &Shot, b: Aabb) -> f64 {
    let fwd = (shot.target - shot.eye).normalize();
    let c = DVec3::from(b.center());
    let half = (DVec3::from(b.max) - DVec3::from(b.min)) * 0.5;
    (c - shot.eye).dot(fwd) - fwd.abs().dot(half)
}

/// Upper bound of the length in pixels of an edge `voxel_edge` anywhere in box `b` as `shot`
/// sees it; boxes reaching in front of the near plane count at the near plane.
pub fn voxel_pixels(shot: &Shot, b: Aabb, voxel_edge: f64) -> f64 {
    assert!(
        shot.near > 0.0,
        "the near plane must be in front of the eye"
    );
    voxel_edge * pixels_at_unit_depth(shot) / nearest_depth(shot, b).max(shot.near)
}

/// False when `b` lies wholly outside one plane of the view frustum of `shot` (left, right,
/// bottom, top, near, far): then nothing of it can be in the picture.
pub fn in_frustum(shot: &Shot, b: Aabb) -> bool {
    let m = shot.view_proj(shot.target);
    let clip: Vec<DVec4> = (0..8)
        .map(|k| {
            let p = DVec3::new(
                if k & 1 == 0 { b.min[0] } else { b.max[0] },
                if k & 2 == 0 { b.min[1] } else { b.max[1] },
                if k & 4 == 0 { b.min[2] } else { b.max[2] },
            );
            m * (p - shot.target).extend(1.0)
        })
        .collect();
    // clip space of wgpu: -w <= x, y <= w, 0 <= z <= w
    let planes: [fn(&DVec4) -> f64; 6] = [
        |c| c.w + c.x,
        |c| c.w - c.x,
        |c| c.w + c.y,
        |c| c.w - c.y,
        |c| c.z,
        |c| c.w - c.z,
    ];
    planes.iter().all(|p| clip.iter().any(|c| p(c) >= 0.0))
}

/// The error of node `index` for `shot` ([`voxel_pixels`] of its box and voxel edge).
pub fn node_error(reader: &Reader, index: usize, shot: &Shot) -> f64 {
    let e = reader.nodes()[index];
    let b = reader.node_bounds(index).expect("a node of the file");
    voxel_pixels(shot, b, reader.spec().voxel_size_at(e.level))
}

/// True when node `index` is refined for `shot` at `max_error_px`: it has children and its
/// error exceeds the threshold (or is not a number).
pub fn refines(reader: &Reader, index: usize, shot: &Shot, max_error_px: f64) -> bool {
    let err = node_error(reader, index, shot);
    reader.nodes()[index].child_mask != 0 && (err > max_error_px || err.is_nan())
}

/// The cut for `shot`: the nodes in the frustum whose error is at most `max_error_px` (or
/// leaves) below ancestors that all exceed it, in depth-first order.
pub fn select(reader: &Reader, shot: &Shot, max_error_px: f64) -> Vec<CutNode> {
    assert!(max_error_px > 0.0, "the pixel threshold must be positive");
    let mut out = Vec::new();
    let mut stack: Vec<usize> = reader.root().into_iter().collect();
    while let Some(i) = stack.pop() {
        let b = reader.node_bounds(i).expect("a node of the file");
        if !in_frustum(shot, b) {
            continue;
        }
        if refines(reader, i, shot, max_error_px) {
            stack.extend(reader.children(i).iter().rev().flatten());
        } else {
            let error = node_error(reader, i, shot);
            let over = reader.nodes()[i].level == 0 && !(error <= max_error_px);
            out.push(CutNode {
                index: i,
                error,
                over,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shot() -> Shot {
        Shot {
            eye: DVec3::new(0.0, 0.0, 10.0),
            target: DVec3::ZERO,
            up: DVec3::Y,
            fov_y: 90f64.to_radians(),
            near: 0.1,
            far: 100.0,
            width: 200,
            height: 100,
        }
    }

    #[test]
    fn pixel_size_on_the_axis_and_its_bound_off_axis() {
        let s = shot();
        // a unit voxel at the origin, depth 10 - 0.5: f = 100/(2·1) = 50 px per unit at depth 1
        let b = Aabb {
            min: [-0.5; 3],
            max: [0.5; 3],
        };
        let k = (1.0f64 + 4.0 + 1.0).sqrt(); // tan(fov_x/2) = 2, tan(fov_y/2) = 1
        assert!((voxel_pixels(&s, b, 1.0) - 50.0 * k / 9.5).abs() < 1e-9);
        // the bound holds for a short edge anywhere in the frustum, measured by projecting it
        for &(x, y) in &[(0.0, 0.0), (15.0, 0.0), (0.0, 7.0), (17.0, -8.0)] {
            let p = [x, y, 1.0];
            let seg = Aabb { min: p, max: p };
            let bound = voxel_pixels(&s, seg, 1e-3);
            for d in [DVec3::X, DVec3::Y, DVec3::Z, DVec3::ONE.normalize()] {
                let q = DVec3::from(p) + d * 1e-3;
                let (a, c) = (s.project(p).unwrap(), s.project(q.into()).unwrap());
                let len = ((a[0] - c[0]).powi(2) + (a[1] - c[1]).powi(2)).sqrt();
                assert!(len <= bound * 1.0001, "{p:?} {d:?}: {len} > {bound}");
            }
        }
    }

    #[test]
    fn off_axis_the_real_size_is_finer_than_the_distance_rule() {
        // a voxel near the left edge of a wide picture: its view depth is well below its
        // distance, so `Camera::error` (by distance) understates its size in pixels
        let s = shot();
        let b = Aabb {
            min: [-15.5, -0.5, -0.5],
            max: [-14.5, 0.5, 0.5],
        };
        let by_distance = s.error_camera().error(b, 1.0);
        let real = voxel_pixels(&s, b, 1.0);
        assert!(real > 1.5 * by_distance, "{real} vs {by_distance}");
        // measured: the voxel's near face spans more pixels than the distance rule says
        let (p, q) = (
            s.project([-15.5, 0.0, 0.5]).unwrap(),
            s.project([-14.5, 0.0, 0.5]).unwrap(),
        );
        assert!((q[0] - p[0]).abs() > by_distance);
    }

    #[test]
    fn frustum() {
        let s = shot();
        let at = |c: [f64; 3]| Aabb {
            min: c.map(|v| v - 0.5),
            max: c.map(|v| v + 0.5),
        };
        assert!(in_frustum(&s, at([0.0, 0.0, 0.0])));
        assert!(in_frustum(&s, at([19.0, 0.0, 0.0])));
        assert!(!in_frustum(&s, at([25.0, 0.0, 0.0])));
        assert!(!in_frustum(&s, at([0.0, 0.0, 12.0])), "behind the eye");
        assert!(
            !in_frustum(&s, at([0.0, 0.0, -200.0])),
            "beyond the far plane"
        );
        assert!(in_frustum(&s, at([0.0, 0.0, 10.0])), "around the eye");
    }
}
