//! Where the picture is taken from: a perspective camera that frames a box (the model) from a
//! view direction, and the matrices that project world points to pixels.

use glam::{DMat4, DVec3, DVec4};
use voxlod_format::{Aabb, Camera};

use crate::RenderError;

/// What the user asks for: image size, direction from the model towards the camera, up
/// vector, vertical field of view and a zoom factor (2 = twice as close as framing).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Direction from the model's centre towards the camera (need not be unit length).
    pub direction: [f64; 3],
    /// World up (the scanned models in the test data are y-up).
    pub up: [f64; 3],
    /// Vertical field of view, degrees.
    pub fov_y_deg: f64,
    /// Distance divisor: 1 frames the whole model, larger values move closer.
    pub zoom: f64,
}

impl Default for View {
    fn default() -> Self {
        View {
            width: 1024,
            height: 768,
            direction: [0.55, 0.35, 1.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 35.0,
            zoom: 1.0,
        }
    }
}

/// A placed camera: eye, target, up, field of view, clip planes and image size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shot {
    /// Eye position, world.
    pub eye: DVec3,
    /// Point looked at (the model's centre), world.
    pub target: DVec3,
    /// Up vector (orthogonal to the view direction).
    pub up: DVec3,
    /// Vertical field of view, radians.
    pub fov_y: f64,
    /// Near clip distance.
    pub near: f64,
    /// Far clip distance.
    pub far: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Shot {
    /// Frames `bounds` as seen from `view.direction`: the box's bounding sphere fits the
    /// narrower field of view, divided by `view.zoom`.
    pub fn frame(bounds: Aabb, view: &View) -> Result<Shot, RenderError> {
        let bad = |what: String| Err(RenderError::Option(what));
        if view.width == 0 || view.height == 0 || view.width > 16384 || view.height > 16384 {
            return bad(format!(
                "image size {}x{} must be 1..=16384 on each side",
                view.width, view.height
            ));
        }
        if !(view.fov_y_deg > 1.0 && view.fov_y_deg < 170.0) {
            return bad(format!(
                "field of view {}° must be in (1, 170)",
                view.fov_y_deg
            ));
        }
        if !(view.zoom.is_finite() && view.zoom > 0.0) {
            return bad(format!("zoom {} must be positive", view.zoom));
        }
        let dir = DVec3::from(view.direction);
        if !(dir.is_finite() && dir.length() > 0.0) {
            return bad(format!(
                "view direction {:?} is not a direction",
                view.direction
            ));
        }
        let dir = dir.normalize();
        let mut up = DVec3::from(view.up);
        if !(up.is_finite() && up.length() > 0.0) {
            return bad(format!("up vector {:?} is not a direction", view.up));
        }
        up = up.normalize();
        // an up parallel to the view direction: pick another axis
        if up.cross(dir).length() < 1e-6 {
            up = if dir.z.abs() < 0.9 {
                DVec3::Z
            } else {
                DVec3::X
            };
        }
        let up = (up - dir * up.dot(dir)).normalize();
        let lo = DVec3::from(bounds.min);
        let hi = DVec3::from(bounds.max);
        let centre = (lo + hi) * 0.5;
        let radius = ((hi - lo).length() * 0.5).max(1e-9);
        let fov_y = view.fov_y_deg.to_radians();
        let aspect = view.width as f64 / view.height as f64;
        let fov_x = 2.0 * ((fov_y * 0.5).tan() * aspect).atan();
        let half = 0.5 * fov_y.min(fov_x);
        let dist = radius / half.sin() / view.zoom;
        Ok(Shot {
            eye: centre + dir * dist,
            target: centre,
            up,
            fov_y,
            near: (dist - radius * 1.01).max(radius * 1e-4),
            far: dist + radius * 1.01,
            width: view.width,
            height: view.height,
        })
    }

    /// World → clip matrix for points given relative to `origin` (the GPU gets coordinates
    /// relative to the model's centre, which keeps f32 precise far from the world origin).
    pub fn view_proj(&self, origin: DVec3) -> DMat4 {
        let view = DMat4::look_at_rh(self.eye - origin, self.target - origin, self.up);
        let proj = DMat4::perspective_rh(
            self.fov_y,
            self.width as f64 / self.height as f64,
            self.near,
            self.far,
        );
        proj * view
    }

    /// Pixel coordinates (x right, y down, pixel centres at .5) and depth in [0, 1] of a world
    /// point, or `None` behind the eye.
    pub fn project(&self, p: [f64; 3]) -> Option<[f64; 3]> {
        let c = self.view_proj(self.target) * DVec4::from((DVec3::from(p) - self.target, 1.0));
        if c.w <= 0.0 {
            return None;
        }
        let n = c.truncate() / c.w;
        Some([
            (n.x + 1.0) * 0.5 * self.width as f64,
            (1.0 - n.y) * 0.5 * self.height as f64,
            n.z,
        ])
    }

    /// The screen-space-error camera of this shot (for `Reader::select_by_error`).
    pub fn error_camera(&self) -> Camera {
        Camera::new(self.eye.into(), self.fov_y, self.height as f64)
    }
}

/// The box around all nodes of the file (the root's box; `None` for an empty file).
pub fn model_bounds(reader: &voxlod_format::Reader) -> Option<Aabb> {
    reader.root().and_then(|r| reader.node_bounds(r))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_puts_the_centre_in_the_middle_and_the_box_inside() {
        let b = Aabb {
            min: [10.0, -2.0, 5.0],
            max: [14.0, 3.0, 6.0],
        };
        let s = Shot::frame(b, &View::default()).unwrap();
        let c = s.project(b.center()).unwrap();
        assert!((c[0] - 512.0).abs() < 1e-6 && (c[1] - 384.0).abs() < 1e-6);
        for k in 0..8 {
            let p = [
                if k & 1 == 0 { b.min[0] } else { b.max[0] },
                if k & 2 == 0 { b.min[1] } else { b.max[1] },
                if k & 4 == 0 { b.min[2] } else { b.max[2] },
            ];
            let q = s.project(p).unwrap();
            assert!(
                q[0] >= 0.0 && q[0] <= 1024.0 && q[1] >= 0.0 && q[1] <= 768.0,
                "{q:?}"
            );
            assert!(q[2] > 0.0 && q[2] < 1.0);
        }
        // y is up: a point above the centre is higher in the picture (smaller row)
        let above = s.project([12.0, 2.5, 5.5]).unwrap();
        assert!(above[1] < c[1]);
        let bad = View {
            width: 0,
            ..View::default()
        };
        assert!(Shot::frame(b, &bad).is_err());
    }
}
