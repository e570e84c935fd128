//! A leaf chunk's source mesh (docs/FORMAT.md 14.4) from the triangles of its bin: the
//! geometry a renderer draws instead of the chunk's voxels at close range (Chajdas, Reitinger
//! & Westermann 2014, section 4).
//!
//! A triangle is kept if it touches the chunk's closed box (its bin holds every triangle whose
//! *bounding box* does; the polygon clipped to the box, grown by a hair for rounding, must be
//! non-empty). A kept triangle lying inside the quantization box (the chunk grown by
//! [`MARGIN`] = 128 voxels on every side) is stored whole, so a scan's small triangles along a
//! chunk border are stored whole in each chunk they touch, their vertices shared as in the
//! input; one reaching past it (a large CAD or architecture triangle) is clipped to the
//! chunk's box and the piece stored as a fan of triangles (each then touches the chunk, and
//! the pieces of neighbouring chunks meet on the chunk faces without overlapping). Positions are quantized
//! ([`quantize`]), normals octahedral, and equal vertices (same codes for position, normal and
//! colour) stored once, numbered in first-use order.

use std::collections::HashMap;

use voxlod_format::triangles::{oct_encode, quantize, SourceMesh, BOX_MAX, BOX_MIN, MARGIN};
use voxlod_geom::{Triangle, CHUNK};

use crate::stages::source::clip::{clip_to_box, ClipVertex};

/// How far past the chunk box a triangle may reach and still count as touching it, in voxels
/// (rounding of the clip; far below the quantization step of 1/128).
const TOUCH_SLACK: f64 = 1.0 / 4096.0;

/// Which attributes a build stores with its source triangles.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct SourceAttributes {
    pub normals: bool,
    pub colors: bool,
    pub materials: bool,
}

/// Counts of one chunk's (or a build's) source triangles.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub(crate) struct SourceCounts {
    /// Triangles of the bin that touch the chunk.
    pub kept: u64,
    /// Of those, the ones clipped to the quantization box.
    pub clipped: u64,
    /// Triangles stored (the whole ones and the clipped pieces).
    pub stored: u64,
}

/// Builds one chunk's source mesh from its triangles in bin order.
pub(crate) struct SourceBuilder {
    /// The chunk's minimum corner in grid coordinates (leaf voxels).
    origin: [f64; 3],
    attrs: SourceAttributes,
    index: HashMap<u128, u32>,
    mesh: SourceMesh,
    pub counts: SourceCounts,
}

impl SourceBuilder {
    /// A builder for the leaf chunk at `coord` (in chunks).
    pub(crate) fn new(coord: [u32; 3], attrs: SourceAttributes) -> SourceBuilder {
        SourceBuilder {
            origin: coord.map(|c| (c as u64 * CHUNK as u64) as f64),
            attrs,
            index: HashMap::new(),
            mesh: SourceMesh {
                normals: attrs.normals.then(Vec::new),
                colors: attrs.colors.then(Vec::new),
                materials: attrs.materials.then(Vec::new),
                ..Default::default()
            },
            counts: SourceCounts::default(),
        }
    }

    /// Adds a triangle in grid coordinates (as the bins hold it).
    pub(crate) fn add(&mut self, t: &Triangle) {
        let poly: [ClipVertex; 3] = std::array::from_fn(|k| ClipVertex {
            // exact: an f32 minus an integer below 2^31, in f64
            p: std::array::from_fn(|a| t.v[k][a] as f64 - self.origin[a]),
            n: t.n[k].map(|x| x as f64),
            c: t.c[k].map(|x| x as f64),
        });
        let (lo, hi) = bounds(&poly);
        let chunk = CHUNK as f64;
        let inside_chunk = lo.iter().all(|&x| x >= 0.0) && hi.iter().all(|&x| x <= chunk);
        if !inside_chunk && clip_to_box(&poly, -TOUCH_SLACK, chunk + TOUCH_SLACK).is_empty() {
            return;
        }
        self.counts.kept += 1;
        let material = t.material() as u16;
        if lo.iter().all(|&x| x >= BOX_MIN) && hi.iter().all(|&x| x <= BOX_MAX) {
            self.push_triangle(&poly, material);
            return;
        }
        self.counts.clipped += 1;
        let piece = clip_to_box(&poly, 0.0, chunk);
        for k in 1..piece.len().saturating_sub(1) {
            self.push_triangle(&[piece[0], piece[k], piece[k + 1]], material);
        }
    }

    fn push_triangle(&mut self, tri: &[ClipVertex; 3], material: u16) {
        let idx = tri.map(|v| self.vertex(&v));
        self.mesh.triangles.push(idx);
        if let Some(m) = &mut self.mesh.materials {
            m.push(material);
        }
        self.counts.stored += 1;
    }

    /// The index of vertex `v` (quantized), adding it if it is new.
    fn vertex(&mut self, v: &ClipVertex) -> u32 {
        // inside the box by the callers' tests (clip results are clamped to it)
        let q =
            v.p.map(|x| quantize(x).expect("a position inside the quantization box"));
        let n = if self.attrs.normals {
            oct_encode(v.n.map(|x| x as f32))
        } else {
            [0; 2]
        };
        let c = if self.attrs.colors {
            v.c.map(|x| x.round().clamp(0.0, 255.0) as u8)
        } else {
            [0; 4]
        };
        let key = (q[0] as u128)
            | (q[1] as u128) << 16
            | (q[2] as u128) << 32
            | (n[0] as u128) << 48
            | (n[1] as u128) << 64
            | (u32::from_le_bytes(c) as u128) << 80;
        let next = self.mesh.positions.len() as u32;
        let i = *self.index.entry(key).or_insert(next);
        if i == next {
            self.mesh.positions.push(q);
            if let Some(ns) = &mut self.mesh.normals {
                ns.push(n);
            }
            if let Some(cs) = &mut self.mesh.colors {
                cs.push(c);
            }
        }
        i
    }

    /// The chunk's mesh, or `None` if no triangle touches the chunk.
    pub(crate) fn finish(self) -> Option<SourceMesh> {
        (!self.mesh.triangles.is_empty()).then_some(self.mesh)
    }
}

fn bounds(poly: &[ClipVertex; 3]) -> ([f64; 3], [f64; 3]) {
    let lo = std::array::from_fn(|a| poly.iter().map(|v| v.p[a]).fold(f64::INFINITY, f64::min));
    let hi = std::array::from_fn(|a| {
        poly.iter()
            .map(|v| v.p[a])
            .fold(f64::NEG_INFINITY, f64::max)
    });
    (lo, hi)
}

const _: () = assert!(MARGIN == 128 && CHUNK == 256);

#[cfg(test)]
mod tests {
    use super::*;
    use voxlod_format::triangles::{dequantize, MAX_ERROR};

    #[test]
    fn shared_vertices_once_far_triangles_dropped_large_ones_clipped() {
        let attrs = SourceAttributes::default();
        let mut b = SourceBuilder::new([1, 0, 0], attrs);
        // two triangles sharing an edge, inside chunk (1, 0, 0) = grid x in [256, 512]
        b.add(&Triangle::new([
            [300.0, 1.0, 1.0],
            [301.5, 1.0, 1.0],
            [300.0, 2.0, 1.0],
        ]));
        b.add(&Triangle::new([
            [301.5, 1.0, 1.0],
            [300.0, 2.0, 1.0],
            [301.5, 2.0, 1.0],
        ]));
        // bounding box touches the chunk, the triangle does not: dropped
        b.add(&Triangle::new([
            [200.0, 0.0, 5.0],
            [250.0, 0.0, 5.0],
            [250.0, 300.0, 300.0],
        ]));
        // crosses the border at x = 256: whole (inside the margin)
        b.add(&Triangle::new([
            [250.0, 9.0, 9.0],
            [260.0, 9.0, 9.0],
            [255.0, 10.0, 9.0],
        ]));
        // huge, through the chunk: clipped to the chunk's box [0, 256]³ in the chunk's frame
        b.add(&Triangle::new([
            [-5000.0, 5.0, -5000.0],
            [5000.0, 5.0, -5000.0],
            [0.0, 5.0, 5000.0],
        ]));
        let counts = b.counts;
        let m = b.finish().unwrap();
        assert_eq!((counts.kept, counts.clipped), (4, 1));
        assert_eq!(m.triangles[..3], [[0, 1, 2], [1, 2, 3], [4, 5, 6]]);
        assert_eq!(counts.stored as usize, m.triangles.len());
        m.check().unwrap();
        // the whole crossing triangle's first vertex: x = 250 − 256 = −6 in the chunk's frame
        assert_eq!(m.position(4), [-6.0, 9.0, 9.0]);
        // the clipped pieces lie in the triangle's plane y = 5, within the quantization error
        for t in &m.triangles[3..] {
            for &i in t {
                assert!((dequantize(m.positions[i as usize][1]) - 5.0).abs() <= MAX_ERROR);
            }
        }
        // the clipped pieces cover the chunk's slice y = 5: area 256²
        let area: f64 = m.triangles[3..]
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.position(i));
                ((b[0] - a[0]) * (c[2] - a[2]) - (b[2] - a[2]) * (c[0] - a[0])).abs() / 2.0
            })
            .sum();
        assert!((area - 256.0 * 256.0).abs() < 1e-6, "{area}");
    }
}
