//! A camera path for the headless viewer (`voxlod view FILE --fly PATH.json`): keyframes of
//! eye and target, and the number of frames.
//!
//! ```json
//! {"keyframes": [{"eye": [0, 0.4, 6], "target": [0, 0, 0]}, {"eye": [0.1, 0.1, 0.6], "target": [0, 0, 0]}],
//!  "frames": 24, "up": [0, 1, 0], "fov": 45}
//! ```
//! Coordinates: by default (`"coordinates": "cube"`) eye and target are in the model's bounding
//! cube mapped to [−1, 1]³ (the centre of the root node's box is 0, ±1 its largest half extent,
//! the same scale on every axis), so one path suits any model; with `"coordinates": "world"`
//! they are world coordinates, the units of the input mesh, as `render --target` takes them.
//! `up` (default +Y, world axes in both cases) and `fov` (vertical, degrees, default 45) are
//! optional. Frame `i` of `N` is at `t = i/(N−1)` of the path; the keyframes are spaced evenly
//! in `t` (K keyframes: keyframe `k` at `t = k/(K−1)`, so each segment gets the same number of
//! frames, whatever its length); eye and target move linearly between neighbouring keyframes,
//! eased (smoothstep) inside each segment so the camera starts and stops gently at every
//! keyframe. One keyframe or one frame: a still.

use std::path::Path;

use glam::DVec3;
use serde::Deserialize;
use voxlod_format::Aabb;

use crate::camera::Shot;
use crate::RenderError;

/// One keyframe: where the eye is and what it looks at, in the path's [`Coordinates`].
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Keyframe {
    /// Eye position (in cube coordinates it may lie outside [−1, 1]³).
    pub eye: [f64; 3],
    /// Point looked at, same coordinates.
    pub target: [f64; 3],
}

/// What the numbers of a path's keyframes mean.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Coordinates {
    /// The model's bounding cube mapped to [−1, 1]³ (any model, one path).
    #[default]
    Cube,
    /// World coordinates, as `render --target` takes them.
    World,
}

/// A camera path (see the module docs for the JSON).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FlyPath {
    /// At least one keyframe.
    pub keyframes: Vec<Keyframe>,
    /// Frames to render, at least 1.
    pub frames: u32,
    /// World up vector.
    #[serde(default = "default_up")]
    pub up: [f64; 3],
    /// Vertical field of view, degrees.
    #[serde(default = "default_fov")]
    pub fov: f64,
    /// What the keyframes' numbers mean (default: the unit cube of the model).
    #[serde(default)]
    pub coordinates: Coordinates,
}

fn default_up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}

fn default_fov() -> f64 {
    45.0
}

/// The largest camera path file read (a keyframe is about a hundred bytes of JSON).
pub const FLY_PATH_LIMIT: u64 = 64 << 20;

impl FlyPath {
    /// Reads and checks a path file.
    pub fn load(path: &Path) -> Result<FlyPath, RenderError> {
        // a camera path is a small JSON file: a regular file, read with a bound
        let bytes = voxlod_io::read_bounded(path, FLY_PATH_LIMIT).map_err(|e| match e {
            voxlod_io::BoundError::Io(source) => RenderError::Io {
                path: path.to_owned(),
                op: "reading the camera path",
                source,
            },
            e => RenderError::Option(format!("{}: cannot be a camera path: {e}", path.display())),
        })?;
        let text = String::from_utf8_lossy(&bytes);
        let p: FlyPath = serde_json::from_str(&text).map_err(|e| {
            RenderError::Option(format!(
                "{}: not a camera path ({e}); expected {{\"keyframes\": [{{\"eye\": [x,y,z], \"target\": [x,y,z]}}, ...], \"frames\": N}}",
                path.display()
            ))
        })?;
        p.check().map_err(|e| match e {
            RenderError::Option(m) => RenderError::Option(format!("{}: {m}", path.display())),
            other => other,
        })?;
        Ok(p)
    }

    /// Checks the values: keyframes present and finite, eye apart from target, frames ≥ 1,
    /// a usable up vector and field of view.
    pub fn check(&self) -> Result<(), RenderError> {
        let bad = |m: String| Err(RenderError::Option(m));
        if self.keyframes.is_empty() {
            return bad("the camera path has no keyframes".into());
        }
        if self.frames == 0 || self.frames > 100_000 {
            return bad(format!("frames {} must be 1..=100000", self.frames));
        }
        for (i, k) in self.keyframes.iter().enumerate() {
            let (e, t) = (DVec3::from(k.eye), DVec3::from(k.target));
            // world coordinates may be georeferenced (metres from a far origin)
            let limit = match self.coordinates {
                Coordinates::Cube => 1e6,
                Coordinates::World => 1e12,
            };
            if !(e.is_finite() && t.is_finite())
                || e.abs().max_element() > limit
                || t.abs().max_element() > limit
            {
                return bad(format!(
                    "keyframe {i}: eye and target must be finite numbers of moderate size"
                ));
            }
            if (e - t).length() < 1e-9 {
                return bad(format!("keyframe {i}: the eye is at the target"));
            }
        }
        let up = DVec3::from(self.up);
        if !(up.is_finite() && up.length() > 0.0) {
            return bad(format!("up {:?} is not a direction", self.up));
        }
        if !(self.fov > 1.0 && self.fov < 170.0) {
            return bad(format!("fov {} must be in (1, 170) degrees", self.fov));
        }
        Ok(())
    }

    /// Eye and target of frame `i` in cube coordinates.
    pub fn at(&self, i: u32) -> (DVec3, DVec3) {
        assert!(i < self.frames && !self.keyframes.is_empty());
        let k = &self.keyframes;
        if k.len() == 1 || self.frames == 1 {
            return (k[0].eye.into(), k[0].target.into());
        }
        let t = i as f64 / (self.frames - 1) as f64 * (k.len() - 1) as f64;
        let s = (t.floor() as usize).min(k.len() - 2);
        let u = t - s as f64;
        let u = u * u * (3.0 - 2.0 * u);
        let lerp = |a: [f64; 3], b: [f64; 3]| DVec3::from(a).lerp(DVec3::from(b), u);
        (
            lerp(k[s].eye, k[s + 1].eye),
            lerp(k[s].target, k[s + 1].target),
        )
    }

    /// The camera of frame `i` for a model whose bounding box is `bounds`, `width`×`height`
    /// pixels: cube coordinates `p` are `centre + p·half` with `half` half the box's largest
    /// extent; world coordinates are taken as they are.
    pub fn shot(&self, i: u32, bounds: Aabb, width: u32, height: u32) -> Shot {
        let (eye, target) = self.at(i);
        let (centre, half) = cube(bounds);
        let world = |p: DVec3| match self.coordinates {
            Coordinates::Cube => centre + p * half,
            Coordinates::World => p,
        };
        cube_shot(
            world(eye),
            world(target),
            self.up.into(),
            self.fov.to_radians(),
            half,
            (width, height),
        )
    }
}

/// Centre and half edge of the bounding cube of `b`.
pub(crate) fn cube(b: Aabb) -> (DVec3, f64) {
    let lo = DVec3::from(b.min);
    let hi = DVec3::from(b.max);
    ((lo + hi) * 0.5, ((hi - lo).max_element() * 0.5).max(1e-12))
}

/// A shot from `eye` towards `target` around a model of half size `half`: the near plane a
/// thousandth of the model's size in front of the eye, the far plane behind the model.
pub(crate) fn cube_shot(
    eye: DVec3,
    target: DVec3,
    up: DVec3,
    fov_y: f64,
    half: f64,
    (width, height): (u32, u32),
) -> Shot {
    let fwd = (target - eye).normalize();
    let mut up = up.normalize();
    if up.cross(fwd).length() < 1e-6 {
        up = if fwd.z.abs() < 0.9 {
            DVec3::Z
        } else {
            DVec3::X
        };
    }
    let up = (up - fwd * up.dot(fwd)).normalize();
    let dist = (target - eye).length();
    Shot {
        eye,
        target,
        up,
        fov_y,
        near: half * 1e-3,
        far: dist + half * 4.0,
        width,
        height,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_and_checks() {
        let p: FlyPath = serde_json::from_str(
            r#"{"keyframes": [{"eye": [0, 0, 4], "target": [0, 0, 0]},
                              {"eye": [0, 0, 2], "target": [0, 0, 0]},
                              {"eye": [0, 0, 1], "target": [0, 0, 0]}], "frames": 5}"#,
        )
        .unwrap();
        p.check().unwrap();
        assert_eq!(p.at(0).0, DVec3::new(0.0, 0.0, 4.0));
        assert_eq!(p.at(2).0, DVec3::new(0.0, 0.0, 2.0));
        assert_eq!(p.at(4).0, DVec3::new(0.0, 0.0, 1.0));
        let z1 = p.at(1).0.z;
        assert!(z1 < 4.0 && z1 > 2.0);
        let b = Aabb {
            min: [0.0, 0.0, 0.0],
            max: [2.0, 1.0, 1.0],
        };
        let s = p.shot(4, b, 64, 48);
        assert_eq!(s.eye, DVec3::new(1.0, 0.5, 1.5));
        assert_eq!(s.target, DVec3::new(1.0, 0.5, 0.5));
        for bad in [
            r#"{"keyframes": [], "frames": 3}"#,
            r#"{"keyframes": [{"eye": [0, 0, 0], "target": [0, 0, 0]}], "frames": 3}"#,
            r#"{"keyframes": [{"eye": [0, 0, 1], "target": [0, 0, 0]}], "frames": 0}"#,
        ] {
            let p: FlyPath = serde_json::from_str(bad).unwrap();
            assert!(p.check().is_err(), "{bad}");
        }
        assert!(serde_json::from_str::<FlyPath>(r#"{"frames": 3}"#).is_err());
    }

    #[test]
    fn world_coordinates_are_the_cube_ones_mapped() {
        // the box [0,2]×[0,1]×[0,1]: centre (1, 0.5, 0.5), half edge 1
        let b = Aabb {
            min: [0.0, 0.0, 0.0],
            max: [2.0, 1.0, 1.0],
        };
        let cube: FlyPath = serde_json::from_str(
            r#"{"keyframes": [{"eye": [0, 0, 3], "target": [0.5, 0, 0]}], "frames": 1}"#,
        )
        .unwrap();
        let world: FlyPath = serde_json::from_str(
            r#"{"keyframes": [{"eye": [1, 0.5, 3.5], "target": [1.5, 0.5, 0.5]}], "frames": 1,
                "coordinates": "world"}"#,
        )
        .unwrap();
        assert_eq!(cube.coordinates, Coordinates::Cube);
        assert_eq!(world.coordinates, Coordinates::World);
        let (c, w) = (cube.shot(0, b, 64, 48), world.shot(0, b, 64, 48));
        assert_eq!((c.eye, c.target), (w.eye, w.target));
        assert_eq!(w.target, DVec3::new(1.5, 0.5, 0.5));
        // georeferenced numbers are fine in world coordinates, not in the cube
        let far = r#"{"keyframes": [{"eye": [5e6, 0, 1], "target": [5e6, 0, 0]}], "frames": 1"#;
        let p: FlyPath =
            serde_json::from_str(&format!(r#"{far}, "coordinates": "world"}}"#)).unwrap();
        p.check().unwrap();
        let p: FlyPath = serde_json::from_str(&format!("{far}}}")).unwrap();
        assert!(p.check().is_err());
        let screen = format!(r#"{far}, "coordinates": "screen"}}"#);
        assert!(serde_json::from_str::<FlyPath>(&screen).is_err());
    }
}
