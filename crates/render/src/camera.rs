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
    /// The point looked at, for close-ups of one part [default: the centre of the framed
    /// bounds]; the camera keeps the distance `zoom` gives and the direction.
    pub target: Option<[f64; 3]>,
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
            target: None,
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
        let mut centre = (lo + hi) * 0.5;
        let radius = ((hi - lo).length() * 0.5).max(1e-9);
        // near and far planes enclose the bounds around the point looked at
        let mut cover = radius;
        if let Some(t) = view.target {
            let t = DVec3::from(t);
            if !t.is_finite() {
                return bad(format!("target {t} is not a point"));
            }
            let far_corner = (t - lo).abs().max((t - hi).abs());
            (centre, cover) = (t, far_corner.length().max(radius));
        }
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
            near: (dist - cover * 1.01).max(cover * 1e-4),
            far: dist + cover * 1.01,
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

/// The up axis a model says by its shape, or `None`: +Z when it is flat in z (its z extent
/// under a quarter of both its x and y extents: a Z-up city, terrain or floor plan, as GIS
/// data and many scans are), else nothing (the caller's default, +Y as in glTF). A flat
/// model standing in the xy plane of a Y-up file (a relief) is taken for Z-up too; `--up`
/// overrides.
pub fn up_from_shape(bounds: Aabb) -> Option<[f64; 3]> {
    let e: [f64; 3] = std::array::from_fn(|a| bounds.max[a] - bounds.min[a]);
    (e[2] * 4.0 < e[0] && e[2] * 4.0 < e[1]).then_some([0.0, 0.0, 1.0])
}

/// Voxels sampled for [`robust_bounds`]: the coarsest level with at least this many.
const ROBUST_SAMPLE: u64 = 20_000;

/// The box holding the bulk of the model, for framing: per axis, the 1st to the 99th
/// percentile of the voxel centres of a coarse level (the coarsest with at least 20,000
/// voxels, or level 0), widened by one voxel of that level. Stray fragments (a scan's far
/// outliers) hold few voxels and fall outside it, so they do not shrink the subject in the
/// picture. `None` for an empty file.
pub fn robust_bounds(reader: &voxlod_format::Reader) -> Result<Option<Aabb>, RenderError> {
    let spec = reader.spec();
    let mut per_level = vec![0u64; spec.levels as usize];
    for e in reader.nodes() {
        per_level[e.level as usize] += e.voxel_count as u64;
    }
    let Some(level) = (0..spec.levels)
        .rev()
        .find(|&l| per_level[l as usize] >= ROBUST_SAMPLE)
        .or_else(|| (per_level.first() > Some(&0)).then_some(0))
    else {
        return Ok(None);
    };
    let edge = spec.voxel_size_at(level);
    let mut axes: [Vec<f64>; 3] = Default::default();
    let mut buf = Vec::new();
    for i in reader.level_nodes(level) {
        reader.read_node_into(i, &mut buf)?;
        let e = reader.nodes()[i];
        for v in &buf {
            let c = spec.voxel_min_corner(level, e.pos(), v.pos());
            for a in 0..3 {
                axes[a].push(c[a] + 0.5 * edge);
            }
        }
    }
    if axes[0].is_empty() {
        return Ok(None);
    }
    let mut min = [0.0; 3];
    let mut max = [0.0; 3];
    for a in 0..3 {
        min[a] = percentile(&mut axes[a], 0.01) - edge;
        max[a] = percentile(&mut axes[a], 0.99) + edge;
    }
    Ok(Some(Aabb { min, max }))
}

/// The value at fraction `q` of `v` sorted (nearest rank), reordering `v`.
fn percentile(v: &mut [f64], q: f64) -> f64 {
    assert!(!v.is_empty() && (0.0..=1.0).contains(&q));
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A made-up scene: a 40³ block of voxels (the subject) in chunk (0,0,0) and a stray
    /// fragment of five voxels in the far corner of chunk (1,1,1), 512³ grid.
    fn subject_and_stray(path: &std::path::Path) {
        use voxlod_format::voxel::{pack_color, pack_normal};
        use voxlod_format::{encode_node, FileSpec, Voxel, Writer, MODE_THIN};
        let n = pack_normal([0.0, 0.0, 1.0]);
        let c = pack_color([200, 200, 200, 255]);
        let node = |mut v: Vec<Voxel>| {
            v.sort_by_key(|v| v.morton());
            encode_node(&v, 1).unwrap()
        };
        let mut block = Vec::new();
        for x in 0..40u8 {
            for y in 0..40u8 {
                for z in 0..40u8 {
                    block.push(Voxel::new([x, y, z], 0b010000, n, c));
                }
            }
        }
        let stray: Vec<Voxel> = (251..=255u8)
            .map(|x| Voxel::new([x, 255, 255], 0b010000, n, c))
            .collect();
        let mut w = Writer::create(path, FileSpec::new(512, MODE_THIN, [0.0; 3], 0.1)).unwrap();
        w.write_node(0, [0, 0, 0], 0, &node(block)).unwrap();
        w.write_node(0, [1, 1, 1], 0, &node(stray)).unwrap();
        let root = vec![
            Voxel::new([0, 0, 0], 0b010000, n, c),
            Voxel::new([255, 255, 255], 0b010000, n, c),
        ];
        w.write_node(1, [0, 0, 0], 0b1000_0001, &node(root))
            .unwrap();
        w.finish(&serde_json::json!({})).unwrap();
    }

    /// Rows of the picture the box `b` spans, as a fraction of the image height.
    fn height_fraction(shot: &Shot, b: Aabb) -> f64 {
        let rows: Vec<f64> = (0..8)
            .map(|k| {
                let p = std::array::from_fn(|a| if k >> a & 1 == 0 { b.min[a] } else { b.max[a] });
                shot.project(p).unwrap()[1]
            })
            .collect();
        let span = rows.iter().cloned().fold(f64::MIN, f64::max)
            - rows.iter().cloned().fold(f64::MAX, f64::min);
        span / shot.height as f64
    }

    #[test]
    fn a_stray_fragment_does_not_shrink_the_subject() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.voxlod");
        subject_and_stray(&path);
        let r = voxlod_format::Reader::open(&path).unwrap();
        let all = model_bounds(&r).unwrap();
        assert!(all.max[0] > 50.0, "{all:?}");
        let robust = robust_bounds(&r).unwrap().unwrap();
        // the subject: voxels 0..40 of edge 0.1, centres 0.05..3.95
        let subject = Aabb {
            min: [0.0; 3],
            max: [4.0; 3],
        };
        for a in 0..3 {
            assert!(robust.min[a] >= -0.11 && robust.min[a] <= 0.2, "{robust:?}");
            assert!(robust.max[a] >= 3.8 && robust.max[a] <= 4.2, "{robust:?}");
        }
        let view = View::default();
        let framed = height_fraction(&Shot::frame(robust, &view).unwrap(), subject);
        let by_box = height_fraction(&Shot::frame(all, &view).unwrap(), subject);
        assert!(framed > 0.5, "the subject fills {framed} of the height");
        assert!(by_box < 0.15, "framing by the box: {by_box}");
    }

    #[test]
    fn flat_in_z_means_z_up() {
        let b = |x: f64, y: f64, z: f64| Aabb {
            min: [0.0; 3],
            max: [x, y, z],
        };
        assert_eq!(up_from_shape(b(100.0, 80.0, 10.0)), Some([0.0, 0.0, 1.0]));
        assert_eq!(up_from_shape(b(1.0, 1.0, 1.0)), None);
        // the dragon (long in x, z its smallest extent but not flat) and a Y-up city
        assert_eq!(up_from_shape(b(0.2, 0.14, 0.09)), None);
        assert_eq!(up_from_shape(b(100.0, 10.0, 80.0)), None);
    }

    #[test]
    fn percentiles_ignore_a_few_outliers() {
        let mut v: Vec<f64> = (0..1000).map(|i| i as f64 / 1000.0).collect();
        v.extend([1e6, -1e6, 5e5]);
        assert!((percentile(&mut v, 0.01) - 0.01).abs() < 0.005);
        assert!((percentile(&mut v, 0.99) - 0.99).abs() < 0.005);
        assert_eq!(percentile(&mut [3.0], 0.5), 3.0);
    }

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

    #[test]
    fn a_target_is_in_the_middle_and_the_box_between_the_planes() {
        let b = Aabb {
            min: [10.0, -2.0, 5.0],
            max: [14.0, 3.0, 6.0],
        };
        let t = [10.5, 2.5, 5.2]; // near a corner
        let whole = Shot::frame(b, &View::default()).unwrap();
        let view = View {
            zoom: 4.0,
            target: Some(t),
            ..View::default()
        };
        let s = Shot::frame(b, &view).unwrap();
        let c = s.project(t).unwrap();
        assert!((c[0] - 512.0).abs() < 1e-6 && (c[1] - 384.0).abs() < 1e-6);
        // four times closer than the whole-model framing, same direction
        let d = |s: &Shot| s.eye - s.target;
        assert!((d(&whole).length() / d(&s).length() - 4.0).abs() < 1e-9);
        assert!(d(&whole).normalize().dot(d(&s).normalize()) > 1.0 - 1e-12);
        // no corner lies beyond the far plane; the near plane is in front of the eye
        let fwd = -d(&s).normalize();
        for k in 0..8 {
            let p = DVec3::new(
                if k & 1 == 0 { b.min[0] } else { b.max[0] },
                if k & 2 == 0 { b.min[1] } else { b.max[1] },
                if k & 4 == 0 { b.min[2] } else { b.max[2] },
            );
            let depth = (p - s.eye).dot(fwd);
            assert!(
                depth < s.far && s.near > 0.0,
                "corner {p} beyond the far plane"
            );
        }
        let bad = View {
            target: Some([f64::NAN, 0.0, 0.0]),
            ..view
        };
        assert!(Shot::frame(b, &bad).is_err());
    }
}
