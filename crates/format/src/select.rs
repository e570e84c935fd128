//! Choosing which nodes to draw: walking the octree, picking a level, and the screen-space
//! error cut of a streaming renderer (Chajdas, Reitinger & Westermann 2014, section 5: a
//! chunk is refined while its voxels project to more than a threshold of pixels), plus the
//! conservative world-space boxes that culling needs.
//!
//! Everything here works on the validated index only (no payload is read), so it is cheap
//! and cannot fail: a [`Reader`] that opened has a consistent tree.
//!
//! ```
//! use voxlod_format::voxel::{pack_color, pack_normal, Voxel};
//! use voxlod_format::{encode_node, Camera, FileSpec, Reader, Writer, MODE_THIN};
//!
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("two_levels.voxlod");
//! // 512³ grid: 2 levels; one leaf chunk (1,0,0) and the root above it
//! let spec = FileSpec::new(512, MODE_THIN, [0.0; 3], 1.0);
//! let v = Voxel::new([0, 0, 0], 0x3f, pack_normal([0.0, 0.0, 1.0]), pack_color([9, 9, 9, 255]));
//! let mut w = Writer::create(&path, spec).unwrap();
//! w.write_node(0, [1, 0, 0], 0, &encode_node(&[v], 3).unwrap()).unwrap();
//! // the leaf's voxel (0,0,0) in chunk (1,0,0) is root voxel (128,0,0)
//! let root_voxel = Voxel::new([128, 0, 0], 0x3f, v.normal, v.color);
//! w.write_node(1, [0, 0, 0], 0b10, &encode_node(&[root_voxel], 3).unwrap()).unwrap();
//! w.finish(&serde_json::json!({})).unwrap();
//!
//! let r = Reader::open(&path).unwrap();
//! let root = r.root().unwrap();
//! // depth-first from the root: the root, then its child
//! let order: Vec<usize> = r.depth_first().collect();
//! assert_eq!(order, vec![root, 0]);
//! assert_eq!(r.level_nodes(0).collect::<Vec<_>>(), vec![0]);
//! // the root voxel is 2 world units wide; the leaf's voxel starts at x = 256
//! let b = r.node_bounds(root).unwrap();
//! assert_eq!((b.min, b.max), ([256.0, 0.0, 0.0], [258.0, 2.0, 2.0]));
//! // far away, a root voxel covers less than a pixel: the root alone is drawn
//! let far = Camera::new([256.0, 0.0, 10_000.0], 60f64.to_radians(), 1080.0);
//! assert!(far.error(r.node_bounds(root).unwrap(), 2.0) < 1.0);
//! assert_eq!(r.select_by_error(&far, 1.0), vec![root]);
//! // close up, the root is refined into its stored child
//! let near = Camera::new([256.0, 0.0, 50.0], 60f64.to_radians(), 1080.0);
//! assert_eq!(r.select_by_error(&near, 1.0), vec![0]);
//! ```

use crate::{FileSpec, Reader, CHUNK};

/// An axis-aligned box in world coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Minimum corner.
    pub min: [f64; 3],
    /// Maximum corner.
    pub max: [f64; 3],
}

impl Aabb {
    /// Euclidean distance from `p` to the box (0 inside).
    pub fn distance_to(&self, p: [f64; 3]) -> f64 {
        let mut d2 = 0.0;
        for a in 0..3 {
            let d = (self.min[a] - p[a]).max(p[a] - self.max[a]).max(0.0);
            d2 += d * d;
        }
        d2.sqrt()
    }
    /// True if `other` lies inside this box (boundaries included).
    pub fn contains(&self, other: &Aabb) -> bool {
        (0..3).all(|a| self.min[a] <= other.min[a] && other.max[a] <= self.max[a])
    }
    /// The smallest box holding both.
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            min: std::array::from_fn(|a| self.min[a].min(other.min[a])),
            max: std::array::from_fn(|a| self.max[a].max(other.max[a])),
        }
    }
    /// Centre of the box.
    pub fn center(&self) -> [f64; 3] {
        std::array::from_fn(|a| 0.5 * (self.min[a] + self.max[a]))
    }
}

/// A pinhole camera for [screen-space error](Camera::error): where it is, its vertical field
/// of view and the viewport height in pixels. Orientation does not matter for the error (it
/// uses the distance to the node, the conservative choice for any view direction).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position in world coordinates.
    pub position: [f64; 3],
    /// Vertical field of view in radians, in (0, π).
    pub fov_y: f64,
    /// Viewport height in pixels.
    pub viewport_height: f64,
}

impl Camera {
    /// A camera at `position` with vertical field of view `fov_y` (radians) and a viewport
    /// `viewport_height` pixels high.
    pub fn new(position: [f64; 3], fov_y: f64, viewport_height: f64) -> Camera {
        Camera {
            position,
            fov_y,
            viewport_height,
        }
    }

    /// Pixels covered by a length of one world unit seen face-on at `distance`:
    /// `viewport_height / (2·tan(fov_y/2)·distance)`; infinite at distance 0.
    pub fn pixels_per_unit(&self, distance: f64) -> f64 {
        let denom = 2.0 * (0.5 * self.fov_y).tan() * distance;
        if denom > 0.0 {
            self.viewport_height / denom
        } else {
            f64::INFINITY
        }
    }

    /// Screen-space error of drawing voxels of edge `voxel_edge` inside `bounds`: the edge's
    /// projected size in pixels at the box's nearest point (an upper bound over the box).
    /// Infinite when the camera is inside the box.
    pub fn error(&self, bounds: Aabb, voxel_edge: f64) -> f64 {
        voxel_edge * self.pixels_per_unit(bounds.distance_to(self.position))
    }
}

/// Depth-first (pre-order) iterator over a file's nodes from the root, children in octant
/// order; see [`Reader::depth_first`].
#[derive(Debug)]
pub struct DepthFirst<'a> {
    reader: &'a Reader,
    stack: Vec<usize>,
}

impl Iterator for DepthFirst<'_> {
    type Item = usize;
    fn next(&mut self) -> Option<usize> {
        let i = self.stack.pop()?;
        // push in reverse so octant 0 is visited first
        for c in self.reader.children(i).iter().rev().flatten() {
            self.stack.push(*c);
        }
        Some(i)
    }
}

impl Reader {
    /// All nodes in depth-first pre-order from the root (a parent before its children,
    /// children in octant order 0…7). Empty for a file without nodes. Every node is visited
    /// exactly once, since `open` checked that each non-root node has its parent.
    pub fn depth_first(&self) -> DepthFirst<'_> {
        DepthFirst {
            reader: self,
            stack: self.root().into_iter().collect(),
        }
    }

    /// Indices of the nodes at `level`, in index order (Morton order of their positions).
    pub fn level_nodes(&self, level: u32) -> impl Iterator<Item = usize> + '_ {
        self.nodes()
            .iter()
            .enumerate()
            .filter(move |(_, e)| e.level == level)
            .map(|(i, _)| i)
    }

    /// World-space box of the whole chunk of node `index` (`None` if there is no such node).
    pub fn chunk_bounds(&self, index: usize) -> Option<Aabb> {
        let e = self.nodes().get(index)?;
        Some(chunk_box(&self.spec(), e.level, e.pos()))
    }

    /// Conservative world-space box of node `index`'s voxels, for culling: from the minimum
    /// corner of its `bounds_min` voxel to the maximum corner of its `bounds_max` voxel
    /// (`origin + voxel_size·2^level·(256·pos + bounds_max + 1)`).
    /// Because each parent is the OR-merge of its children, a parent's box contains its
    /// children's boxes.
    pub fn node_bounds(&self, index: usize) -> Option<Aabb> {
        let e = self.nodes().get(index)?;
        let spec = self.spec();
        let (lo, hi) = e.bounds();
        let at = |a: usize, v: u32| corner(&spec, e.level, e.pos(), a, v);
        Some(Aabb {
            min: std::array::from_fn(|a| at(a, lo[a] as u32)),
            max: std::array::from_fn(|a| at(a, hi[a] as u32 + 1)),
        })
    }

    /// Screen-space error of node `index` for `camera`: its voxel edge
    /// `voxel_size·2^level` in pixels at the nearest point of its [`node_bounds`](Self::node_bounds).
    pub fn screen_error(&self, index: usize, camera: &Camera) -> Option<f64> {
        let e = self.nodes().get(index)?;
        let b = self.node_bounds(index)?;
        Some(camera.error(b, self.spec().voxel_size_at(e.level)))
    }

    /// The cut of the octree a renderer draws for `camera`: starting at the root, a node is
    /// refined into its stored children while its [`screen_error`](Self::screen_error) exceeds
    /// `max_error_px`; leaves are taken whatever their error. Returns node indices in
    /// depth-first order. Each level-0 node has exactly one selected ancestor-or-self, so the
    /// selected nodes cover the model once without overlap.
    pub fn select_by_error(&self, camera: &Camera, max_error_px: f64) -> Vec<usize> {
        let mut out = Vec::new();
        let mut stack: Vec<usize> = self.root().into_iter().collect();
        while let Some(i) = stack.pop() {
            let e = self.nodes()[i];
            let refine = e.child_mask != 0
                && self
                    .screen_error(i, camera)
                    .is_some_and(|err| err > max_error_px || err.is_nan());
            if refine {
                for c in self.children(i).iter().rev().flatten() {
                    stack.push(*c);
                }
            } else {
                out.push(i);
            }
        }
        out
    }
}

/// The world box of chunk `pos` at `level`: `256·2^level` leaf voxels per axis.
fn chunk_box(spec: &FileSpec, level: u32, pos: [u32; 3]) -> Aabb {
    Aabb {
        min: std::array::from_fn(|a| corner(spec, level, pos, a, 0)),
        max: std::array::from_fn(|a| corner(spec, level, pos, a, CHUNK)),
    }
}

/// Axis `a` of `origin + voxel_size·2^level·(256·pos + v)` for `v` in `0..=256`: one formula
/// for voxel and chunk corners, monotone in `v` and exact in the factor 2^level, so boxes
/// computed from it nest exactly as the voxels do (a parent's box contains its children's).
fn corner(spec: &FileSpec, level: u32, pos: [u32; 3], a: usize, v: u32) -> f64 {
    debug_assert!(v <= CHUNK);
    spec.origin[a] + spec.voxel_size_at(level) * (pos[a] as f64 * CHUNK as f64 + v as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_error() {
        // 90° fov: tan(45°) = 1, so 1000 px / (2·distance) per unit
        let c = Camera::new([0.0, 0.0, 0.0], std::f64::consts::FRAC_PI_2, 1000.0);
        let b = Aabb {
            min: [10.0, -1.0, -1.0],
            max: [12.0, 1.0, 1.0],
        };
        assert!((c.error(b, 1.0) - 50.0).abs() < 1e-9);
        let inside = Aabb {
            min: [-1.0; 3],
            max: [1.0; 3],
        };
        assert_eq!(c.error(inside, 1.0), f64::INFINITY);
        assert_eq!(inside.distance_to([4.0, 5.0, 1.0]), 5.0);
        assert!(inside.contains(&Aabb {
            min: [0.0; 3],
            max: [1.0; 3]
        }));
    }
}
