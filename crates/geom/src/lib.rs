//! Shared geometry types of voxlod: the [`Triangle`] record every stage passes on, the
//! voxel [`Grid`] (world-to-voxel transform and chunk addressing) and Morton codes.
//!
//! Every other stage crate depends on this one and on nothing else of voxlod's, so the
//! stages only meet through these plain types.
//!
//! ```
//! use voxlod_geom::{Grid, morton3};
//! // a 1024³ grid over the cube [0,2]³: 4×4×4 leaf chunks, 3 levels
//! let grid = Grid::new([0.0; 3], 2.0, 1024).unwrap();
//! assert_eq!(grid.chunks_per_axis(), 4);
//! assert_eq!(grid.levels(), 3);
//! assert_eq!(grid.to_grid([1.0, 1.0, 1.0]), [512.0, 512.0, 512.0]);
//! assert_eq!(morton3(1, 0, 0), 1);
//! assert_eq!(morton3(0, 1, 0), 2);
//! ```

use bytemuck::{Pod, Zeroable};

pub mod morton;

pub use morton::{compact1by2, demorton3, morton3, morton8, part1by2};

/// Voxels per chunk along one axis (the Chajdas paper's 256³ chunks: 8 bits per coordinate).
pub const CHUNK: u32 = 256;
/// log2 of [`CHUNK`].
pub const CHUNK_BITS: u32 = 8;

/// `flags` bit: the triangle carries per-vertex normals in `n`; otherwise `n` is zero and the
/// face normal is used.
pub const TRI_HAS_NORMALS: u32 = 1;
/// `flags` bit: the colours come from the mesh (vertex or material colour), not the default.
pub const TRI_HAS_COLORS: u32 = 2;

/// `flags` bit: the triangle carries texture coordinates in `uv` (its material may have a
/// base colour texture, see [`Triangle::material`]).
pub const TRI_HAS_UV: u32 = 4;
/// The material index is stored in the `flags` bits from this one up (16 bits: up to 65,535
/// materials; index 0 also means "no material" for meshes without a material table).
pub const TRI_MATERIAL_SHIFT: u32 = 16;
/// The largest material index a triangle can carry.
pub const MAX_MATERIAL: u32 = u16::MAX as u32;

/// Colour given to triangles whose mesh has neither vertex nor material colours: opaque white.
pub const DEFAULT_COLOR: [u8; 4] = [255, 255, 255, 255];

/// One triangle with its per-vertex attributes, as ingest yields it and as tile bins store it
/// (112 bytes, plain old data, little-endian on disk).
///
/// Positions are in world units when ingest yields them and in the tile stage's bins (the
/// voxelizer decides on them exactly); the voxelizer's weights and the source geometry use them
/// moved to grid units (voxels, see [`Grid::to_grid`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Triangle {
    /// Vertex positions.
    pub v: [[f32; 3]; 3],
    /// Vertex normals (not necessarily unit length); all zero unless `flags & TRI_HAS_NORMALS`.
    pub n: [[f32; 3]; 3],
    /// Vertex colours, RGBA8.
    pub c: [[u8; 4]; 3],
    /// `TRI_HAS_NORMALS | TRI_HAS_COLORS | TRI_HAS_UV`, and the material index shifted by
    /// [`TRI_MATERIAL_SHIFT`].
    pub flags: u32,
    /// Per-vertex texture coordinates `(u, v)` (OBJ/glTF convention: `v` up from the image's
    /// bottom row, i.e. texel row `(1 − v)·height`); all zero unless `flags & TRI_HAS_UV`.
    pub uv: [[f32; 2]; 3],
}

impl Triangle {
    /// A triangle with face normal and the default colour.
    pub fn new(v: [[f32; 3]; 3]) -> Self {
        Triangle {
            v,
            n: [[0.0; 3]; 3],
            c: [DEFAULT_COLOR; 3],
            flags: 0,
            uv: [[0.0; 2]; 3],
        }
    }

    /// The triangle's material index (an index into the mesh's material table; 0 for a mesh
    /// without one).
    #[inline]
    pub fn material(&self) -> u32 {
        self.flags >> TRI_MATERIAL_SHIFT
    }

    /// Sets the material index (`m <= MAX_MATERIAL`).
    #[inline]
    pub fn set_material(&mut self, m: u32) {
        assert!(m <= MAX_MATERIAL, "material index {m} > {MAX_MATERIAL}");
        self.flags = (self.flags & ((1 << TRI_MATERIAL_SHIFT) - 1)) | (m << TRI_MATERIAL_SHIFT);
    }

    /// Twice the area vector `(v1 - v0) × (v2 - v0)` in f64.
    #[inline]
    pub fn cross(&self) -> [f64; 3] {
        let a = sub64(self.v[1], self.v[0]);
        let b = sub64(self.v[2], self.v[0]);
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    }

    /// True if all nine coordinates are finite.
    #[inline]
    pub fn is_finite(&self) -> bool {
        self.v.iter().flatten().all(|x| x.is_finite())
    }

    /// True if the triangle has zero area (two equal vertices or collinear), judged exactly in
    /// f64 on the stored f32 coordinates.
    #[inline]
    pub fn is_degenerate(&self) -> bool {
        let c = self.cross();
        c[0] == 0.0 && c[1] == 0.0 && c[2] == 0.0
    }
}

/// How texture coordinates outside `[0, 1]` are mapped into the texture (glTF sampler wrap
/// modes; OBJ textures repeat).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Wrap {
    /// The texture tiles the plane (OBJ, glTF `REPEAT`).
    #[default]
    Repeat,
    /// Coordinates are clamped to the edge texels (glTF `CLAMP_TO_EDGE`).
    Clamp,
    /// The texture tiles the plane, every other copy mirrored (glTF `MIRRORED_REPEAT`).
    Mirror,
}

/// One entry of a mesh's material table, indexed by [`Triangle::material`]. The diffuse /
/// base colour factor is already multiplied into the triangles' vertex colours by ingest; the
/// table says where a triangle's colour additionally comes from a texture.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Material {
    /// The material's name (OBJ `newmtl`, glTF material name or index).
    pub name: String,
    /// The base colour texture, resolved to an existing file (`None`: untextured).
    pub texture: Option<std::path::PathBuf>,
    /// How the texture wraps in `u` and `v`.
    pub wrap: [Wrap; 2],
    /// The texture's encoded bytes (PNG or JPEG) when the mesh file holds them (a glTF data URI
    /// or buffer view); `texture` then names it for messages (`FILE#image N`).
    #[serde(skip)]
    pub embedded: Option<Embedded>,
}

/// Encoded image bytes carried by a [`Material`] (shared, cheap to clone).
#[derive(Clone, PartialEq)]
pub struct Embedded(pub std::sync::Arc<[u8]>);

impl std::fmt::Debug for Embedded {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Embedded({} bytes)", self.0.len())
    }
}

#[inline]
fn sub64(a: [f32; 3], b: [f32; 3]) -> [f64; 3] {
    [
        a[0] as f64 - b[0] as f64,
        a[1] as f64 - b[1] as f64,
        a[2] as f64 - b[2] as f64,
    ]
}

/// Axis-aligned bounds accumulated in f64.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Smallest corner (+∞ on every axis while empty).
    pub min: [f64; 3],
    /// Largest corner (−∞ on every axis while empty).
    pub max: [f64; 3],
}

impl Default for Bounds {
    fn default() -> Self {
        Bounds {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        }
    }
}

impl Bounds {
    // Strict comparisons throughout (not `f64::min`, which may return either of -0 and +0): the
    // first of equal values stays, so the bounds of a sequence are the same bits however it is
    // cut into batches and merged in order (the ingest pass merges per-thread batches).
    // NaN is never taken.
    /// Grows the box to hold `p`.
    #[inline]
    pub fn add_point(&mut self, p: [f32; 3]) {
        for a in 0..3 {
            let x = p[a] as f64;
            if x < self.min[a] {
                self.min[a] = x;
            }
            if x > self.max[a] {
                self.max[a] = x;
            }
        }
    }
    /// Grows the box to hold the triangle's three corners.
    pub fn add_triangle(&mut self, t: &Triangle) {
        for v in &t.v {
            self.add_point(*v);
        }
    }
    /// [`Bounds::add_triangle`] of each of `tris`, with the comparisons in f32 (the same
    /// result: the values are f32 values either way), which is faster.
    #[inline]
    pub fn add_triangles(&mut self, tris: &[Triangle]) {
        let mut b = [[f32::INFINITY; 3], [f32::NEG_INFINITY; 3]];
        for t in tris {
            for v in &t.v {
                for a in 0..3 {
                    if v[a] < b[0][a] {
                        b[0][a] = v[a];
                    }
                    if v[a] > b[1][a] {
                        b[1][a] = v[a];
                    }
                }
            }
        }
        self.merge(&Bounds {
            min: b[0].map(|x| x as f64),
            max: b[1].map(|x| x as f64),
        });
    }
    /// Adds the bounds `o` of points that come after those of `self`.
    pub fn merge(&mut self, o: &Bounds) {
        for a in 0..3 {
            if o.min[a] < self.min[a] {
                self.min[a] = o.min[a];
            }
            if o.max[a] > self.max[a] {
                self.max[a] = o.max[a];
            }
        }
    }
    /// True if no point was added (NaN bounds count as empty).
    pub fn is_empty(&self) -> bool {
        !(self.min[0] <= self.max[0])
    }
    /// Largest extent over the three axes.
    pub fn max_extent(&self) -> f64 {
        (0..3)
            .map(|a| self.max[a] - self.min[a])
            .fold(0.0, f64::max)
    }
}

/// Why a grid cannot be made.
#[derive(Clone, Debug, PartialEq)]
pub enum GridError {
    /// `resolution` is not 256·2^k.
    Resolution(u32),
    /// The cube size is zero, negative or not finite.
    Size(f64),
}

impl std::fmt::Display for GridError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            GridError::Resolution(r) => {
                write!(
                    f,
                    "resolution {r} is not 256·2^k (256, 512, 1024, 2048, 4096, …, 65536)"
                )
            }
            GridError::Size(s) => write!(
                f,
                "the mesh's bounding cube has size {s}; it must be finite and > 0"
            ),
        }
    }
}
impl std::error::Error for GridError {}

/// The voxel grid: a cube of `resolution³` voxels whose minimum corner is `origin` (world units)
/// and whose voxels have edge `voxel_size`. Grid coordinate `g = (p - origin) / voxel_size`;
/// voxel `i` covers `[i, i+1]` on each axis. Leaf chunks are 256³ blocks of voxels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// World position of the grid's minimum corner.
    pub origin: [f64; 3],
    /// Edge of one voxel, world units.
    pub voxel_size: f64,
    /// Voxels per axis.
    pub resolution: u32,
}

impl Grid {
    /// Largest supported resolution (chunk coordinates then fit 8 bits per axis).
    pub const MAX_RESOLUTION: u32 = 65536;

    /// A grid over the cube of edge `size` at `origin`.
    pub fn new(origin: [f64; 3], size: f64, resolution: u32) -> Result<Grid, GridError> {
        if resolution < CHUNK || !resolution.is_power_of_two() || resolution > Self::MAX_RESOLUTION
        {
            return Err(GridError::Resolution(resolution));
        }
        if !(size.is_finite() && size > 0.0) {
            return Err(GridError::Size(size));
        }
        Ok(Grid {
            origin,
            voxel_size: size / resolution as f64,
            resolution,
        })
    }

    /// The grid that fits a mesh's bounds: the bounding cube is the bounds' largest extent,
    /// anchored at the bounds' minimum corner. A flat or point-like mesh gets a cube of edge 1.
    pub fn fit(bounds: &Bounds, resolution: u32) -> Result<Grid, GridError> {
        let mut size = bounds.max_extent();
        if size == 0.0 {
            size = 1.0;
        }
        Grid::new(bounds.min, size, resolution)
    }

    /// World position to grid coordinates (voxel units), rounded to f32.
    #[inline]
    pub fn to_grid(&self, p: [f32; 3]) -> [f32; 3] {
        let s = 1.0 / self.voxel_size;
        [
            ((p[0] as f64 - self.origin[0]) * s) as f32,
            ((p[1] as f64 - self.origin[1]) * s) as f32,
            ((p[2] as f64 - self.origin[2]) * s) as f32,
        ]
    }

    /// Leaf chunks per axis, `resolution / 256`.
    pub fn chunks_per_axis(&self) -> u32 {
        self.resolution / CHUNK
    }

    /// Number of LOD levels: level 0 are the leaf chunks, the last level is one root chunk.
    pub fn levels(&self) -> u32 {
        self.chunks_per_axis().trailing_zeros() + 1
    }

    /// The inclusive range of leaf chunk coordinates, per axis, that a triangle in grid
    /// coordinates may produce voxels in: every voxel `i` with `[i, i+1]` touching the
    /// triangle's bounding box, clamped to the grid. This is a superset of the voxels either
    /// voxelization mode marks, so binning by it loses nothing.
    #[inline]
    pub fn chunk_range(&self, t: &Triangle) -> Option<([u32; 3], [u32; 3])> {
        let (mn, mx) = corners(&t.v);
        self.box_chunk_range(mn, mx)
    }

    /// [`Grid::chunk_range`] of a triangle given in world coordinates, exactly as of the
    /// triangle moved to the grid (`to_grid` of each vertex), without moving it: `to_grid` is
    /// monotonic per axis (a subtraction and a multiplication by a positive factor, each
    /// rounded, then a rounding to f32), so the grid box is `to_grid` of the world box.
    #[inline]
    pub fn world_chunk_range(&self, t: &Triangle) -> Option<([u32; 3], [u32; 3])> {
        let (mn, mx) = corners(&t.v);
        self.box_chunk_range(self.to_grid(mn), self.to_grid(mx))
    }

    /// The chunk range of the box `[mn, mx]` (grid coordinates).
    ///
    /// The voxels are `floor(mn) - 1 ..= floor(mx)` clamped to the grid (the one before `mn`
    /// because a box starting exactly on a voxel face touches the voxel below it); computed as
    /// `trunc(max(mn - 1, 0))` and `trunc(mx)`, the same integers: `mn - 1` is exact for the
    /// `mn ≤ R < 2²⁴` that get here, and both are non-negative.
    #[inline]
    fn box_chunk_range(&self, mn: [f32; 3], mx: [f32; 3]) -> Option<([u32; 3], [u32; 3])> {
        let r = self.resolution as f32;
        if !(0..3).all(|a| mx[a] >= 0.0 && mn[a] <= r) {
            return None;
        }
        let last = self.resolution - 1;
        let lo = mn.map(|m| ((m - 1.0).max(0.0) as u32).min(last) / CHUNK);
        let hi = mx.map(|m| (m as u32).min(last) / CHUNK);
        Some((lo, hi))
    }
}

/// The per-axis minimum and maximum of three points.
#[inline]
fn corners(v: &[[f32; 3]; 3]) -> ([f32; 3], [f32; 3]) {
    let mn = [0, 1, 2].map(|a| v[0][a].min(v[1][a]).min(v[2][a]));
    let mx = [0, 1, 2].map(|a| v[0][a].max(v[1][a]).max(v[2][a]));
    (mn, mx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_rejects_bad_resolution() {
        assert!(Grid::new([0.0; 3], 1.0, 1000).is_err());
        assert!(Grid::new([0.0; 3], 1.0, 128).is_err());
        assert!(Grid::new([0.0; 3], 0.0, 256).is_err());
        assert!(Grid::new([0.0; 3], f64::NAN, 256).is_err());
        assert_eq!(Grid::new([0.0; 3], 1.0, 4096).unwrap().levels(), 5);
    }

    #[test]
    fn world_chunk_range_is_that_of_the_moved_triangle() {
        // an awkward grid: origin and voxel size not representable in binary
        let g = Grid::new([-3.7, 0.1, 12.3], 7.3, 4096).unwrap();
        let mut s = 0x1234_5678_9abc_def0u64;
        let mut unit = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut touched_borders = 0;
        for i in 0..200_000 {
            // mostly tiny triangles, some large ones, some reaching outside the grid
            let size = if i % 10 == 0 { 3.0 } else { 0.004 };
            let c = [0, 1, 2].map(|a| g.origin[a] as f32 + (unit() * 1.2 - 0.1) * 7.3);
            let t = Triangle::new([0, 1, 2].map(|_| [0, 1, 2].map(|a| c[a] + unit() * size)));
            let moved = Triangle::new(t.v.map(|p| g.to_grid(p)));
            let want = g.chunk_range(&moved);
            assert_eq!(g.world_chunk_range(&t), want, "triangle {t:?}");
            if let Some((lo, hi)) = want {
                touched_borders += (lo != hi) as u32;
            }
        }
        // the cases that matter, triangles across chunk borders, did occur
        assert!(touched_borders > 1000, "{touched_borders}");
    }

    #[test]
    fn bounds_of_many_triangles_are_those_of_each() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut f = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            f32::from_bits(s as u32)
        };
        let bits = |b: &Bounds| (b.min.map(f64::to_bits), b.max.map(f64::to_bits));
        // any bit patterns: huge, tiny, negative, infinite and NaN coordinates
        let tris: Vec<Triangle> = (0..5000)
            .map(|_| Triangle::new([0, 1, 2].map(|_| [f(), f(), f()])))
            .collect();
        // and a mesh on the plane z = 0 whose zeros come as -0 and +0 (`f64::min` may return
        // either of the two; these bounds must not depend on how the triangles are batched)
        let zeros: Vec<Triangle> = (0..999)
            .map(|i| {
                let z = if (i / 3) % 2 == 0 { -0.0 } else { 0.0 };
                Triangle::new([[0.0, 0.0, z], [1.0, 0.0, -z], [0.0, 1.0, z]])
            })
            .collect();
        for tris in [&tris, &zeros] {
            let mut one = Bounds::default();
            tris.iter().for_each(|t| one.add_triangle(t));
            for cut in [1, 7, 100, 5000] {
                let mut all = Bounds::default();
                let mut merged = Bounds::default();
                for part in tris.chunks(cut) {
                    all.add_triangles(part);
                    let mut b = Bounds::default();
                    b.add_triangles(part);
                    merged.merge(&b);
                }
                assert_eq!(bits(&one), bits(&all), "batches of {cut}");
                assert_eq!(bits(&one), bits(&merged), "batches of {cut}");
            }
        }
        let mut none = Bounds::default();
        none.add_triangles(&[]);
        assert!(none.is_empty());
    }

    /// The chunk range against its definition, `floor(mn) - 1 ..= floor(mx)` clamped, on
    /// random boxes and the edge values (integers, ±0, just below and above 1 and R, outside,
    /// infinities, NaN).
    #[test]
    fn box_chunk_range_is_its_definition() {
        fn reference(g: &Grid, mn: [f32; 3], mx: [f32; 3]) -> Option<([u32; 3], [u32; 3])> {
            let r = g.resolution as f32;
            let mut lo = [0u32; 3];
            let mut hi = [0u32; 3];
            for a in 0..3 {
                if !(mx[a] >= 0.0 && mn[a] <= r) {
                    return None;
                }
                lo[a] = (mn[a].floor() - 1.0).clamp(0.0, r - 1.0) as u32 / CHUNK;
                hi[a] = mx[a].floor().clamp(0.0, r - 1.0) as u32 / CHUNK;
            }
            Some((lo, hi))
        }
        let mut s = 0x853c_49e6_748f_ea9bu64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 33) as u32
        };
        for res in [256u32, 1024, 16384] {
            let g = Grid::new([0.0; 3], res as f64, res).unwrap();
            let r = res as f32;
            let edges = [
                0.0,
                -0.0,
                1.0,
                0.99999994,
                1.0000001,
                255.0,
                256.0,
                256.5,
                257.0,
                r - 1.0,
                r - 0.5,
                r,
                r + 1.0,
                -1.0,
                -0.5,
                1e30,
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::NAN,
            ];
            for _ in 0..200_000 {
                let mut v = || match next() % 4 {
                    0 => edges[next() as usize % edges.len()],
                    1 => (next() % (res + 3)) as f32 - 1.0,
                    _ => (next() as f32 / u32::MAX as f32) * (r + 4.0) - 2.0,
                };
                let (mn, mx) = ([v(), v(), v()], [v(), v(), v()]);
                assert_eq!(
                    g.box_chunk_range(mn, mx),
                    reference(&g, mn, mx),
                    "{mn:?} {mx:?}"
                );
            }
        }
    }

    #[test]
    fn chunk_range_covers_touching_voxels() {
        let g = Grid::new([0.0; 3], 512.0, 512).unwrap();
        // a triangle touching the plane x = 256 exactly from below touches voxel 256's face
        let t = Triangle::new([
            [250.0, 10.0, 10.0],
            [256.0, 11.0, 10.0],
            [250.0, 12.0, 11.0],
        ]);
        let (lo, hi) = g.chunk_range(&t).unwrap();
        assert_eq!(lo, [0, 0, 0]);
        assert_eq!(hi, [1, 0, 0]);
        // a triangle starting exactly at x = 256 also touches voxel 255
        let t = Triangle::new([
            [256.0, 10.0, 10.0],
            [260.0, 11.0, 10.0],
            [258.0, 12.0, 11.0],
        ]);
        assert_eq!(g.chunk_range(&t).unwrap().0, [0, 0, 0]);
        // the far face of the grid is clamped into the last voxel
        let t = Triangle::new([
            [512.0, 512.0, 512.0],
            [511.5, 512.0, 512.0],
            [512.0, 511.5, 512.0],
        ]);
        assert_eq!(g.chunk_range(&t).unwrap(), ([1, 1, 1], [1, 1, 1]));
    }
}
