//! The source-geometry channel (id 2, docs/FORMAT.md section 14.4): a leaf chunk's input
//! triangles beside its voxels. Chajdas, Reitinger & Westermann, "Scalable rendering for very
//! large meshes" (WSCG 2014), section 4 and Figure 10: "if the camera moves close enough to an
//! octree leaf that the voxel resolution is no longer sufficient to maintain the pixel error
//! guarantee, the leaf node is replaced by the actual input geometry".
//!
//! A payload is one zstd frame holding an indexed triangle mesh in the chunk's own frame:
//! positions quantized to 16 bits per axis on a grid of [`STEP`] voxels over the chunk box
//! grown by [`MARGIN`] voxels on every side (so each stored coordinate is within
//! [`MAX_ERROR`] = 1/256 voxel of the coordinate it was made from), shared vertices stored
//! once, and per vertex an octahedral normal and an RGBA colour, per triangle a material id,
//! each only when the mesh has it. Indices are coded by *first use*: vertices are numbered in
//! the order the triangles first use them, and each index is stored as its distance back from
//! the next new vertex (0 = a new vertex), so an index is valid exactly when the code is at
//! most the number of vertices seen so far, and the coding of a mesh is unique.

use crate::channel::EncodedChannel;
use crate::FormatError;

/// Channel id of the source triangles (section 14.3).
pub use crate::channel::CHANNEL_TRIANGLES;

/// Quantization steps per voxel: a stored coordinate `q` is `q / 128 − MARGIN` voxels from the
/// chunk's minimum corner (exact in binary floating point).
pub const STEPS_PER_VOXEL: u32 = 128;
/// The quantization step in voxels.
pub const STEP: f64 = 1.0 / STEPS_PER_VOXEL as f64;
/// Voxels the quantization box extends past the chunk on every side: positions cover
/// `[−128, 384 − 1/128]` voxels of the chunk's frame (`u16` codes 0..=65535).
pub const MARGIN: u32 = 128;
/// Largest distance, per axis, between a stored coordinate and the one it was rounded from,
/// in voxels: half a step.
pub const MAX_ERROR: f64 = STEP / 2.0;
/// The largest coordinate a code can hold, in voxels of the chunk's frame.
pub const BOX_MAX: f64 = 65535.0 * STEP - MARGIN as f64;
/// The smallest, in voxels of the chunk's frame.
pub const BOX_MIN: f64 = -(MARGIN as f64);

/// Attribute bit: vertices carry octahedral normals.
pub const ATTR_NORMALS: u32 = 1;
/// Attribute bit: vertices carry RGBA8 colours.
pub const ATTR_COLORS: u32 = 2;
/// Attribute bit: triangles carry a 16-bit material id.
pub const ATTR_MATERIALS: u32 = 4;
/// Bytes of the block's head (vertex count, triangle count, attributes, reserved).
pub const HEAD_BYTES: u64 = 16;
/// Most triangles one payload may hold (so every size below fits in a u32 and a u64 sum).
pub const MAX_TRIANGLES: u32 = 1 << 26;

/// One leaf chunk's source triangles, as stored (codes, not floats).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SourceMesh {
    /// Quantized vertex positions: `q / 128 − 128` voxels from the chunk's minimum corner.
    pub positions: Vec<[u16; 3]>,
    /// Octahedral normals (see [`oct_decode`]), one per vertex, if the mesh has normals.
    pub normals: Option<Vec<[u16; 2]>>,
    /// RGBA8 colours, one per vertex, if the mesh has colours.
    pub colors: Option<Vec<[u8; 4]>>,
    /// Vertex indices of each triangle, in first-use order (see the module documentation).
    pub triangles: Vec<[u32; 3]>,
    /// Material id of each triangle (indexing the manifest's `"materials"`), if stored.
    pub materials: Option<Vec<u16>>,
}

/// The block size of a mesh of `v` vertices and `t` triangles with attribute bits `attrs`.
pub fn block_size(v: u64, t: u64, attrs: u32) -> u64 {
    let per_vertex = 6
        + if attrs & ATTR_NORMALS != 0 { 4 } else { 0 }
        + if attrs & ATTR_COLORS != 0 { 4 } else { 0 };
    let per_triangle = 12 + if attrs & ATTR_MATERIALS != 0 { 2 } else { 0 };
    HEAD_BYTES + v * per_vertex + t * per_triangle
}

/// The largest block a payload of `t` triangles may declare (every attribute, `3t` vertices):
/// readers refuse a frame declaring more before decompressing it.
pub fn max_block_size(t: u32) -> u64 {
    block_size(
        3 * t as u64,
        t as u64,
        ATTR_NORMALS | ATTR_COLORS | ATTR_MATERIALS,
    )
}

/// The code of a coordinate `u` (voxels in the chunk's frame): the nearest multiple of
/// [`STEP`], or `None` outside `[BOX_MIN − MAX_ERROR, BOX_MAX + MAX_ERROR]` (ties round away
/// from zero, in f64: for f32 grid coordinates `u` and the product are exact).
pub fn quantize(u: f64) -> Option<u16> {
    let q = ((u + MARGIN as f64) * STEPS_PER_VOXEL as f64).round();
    (0.0..=65535.0).contains(&q).then_some(q as u16)
}

/// The coordinate of a code, voxels in the chunk's frame (exact).
pub fn dequantize(q: u16) -> f64 {
    q as f64 * STEP - MARGIN as f64
}

/// Octahedral code of a normal (Meyer et al., "On floating-point normal vectors", 2010): the
/// unit vector projected on the octahedron `|x|+|y|+|z| = 1`, the lower half folded over, the
/// two coordinates in `[−1, 1]` mapped to 16 bits. A zero vector gets the code of `+z`.
pub fn oct_encode(n: [f32; 3]) -> [u16; 2] {
    let n = n.map(|c| c as f64);
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if !(l1 > 0.0) || !l1.is_finite() {
        return [32768, 32768]; // ≈ (0, 0, 1)
    }
    let (mut x, mut y) = (n[0] / l1, n[1] / l1);
    if n[2] < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * sign(ox);
        y = (1.0 - ox.abs()) * sign(oy);
    }
    let code = |c: f64| ((c.clamp(-1.0, 1.0) * 0.5 + 0.5) * 65535.0).round() as u16;
    [code(x), code(y)]
}

/// The unit normal of an octahedral code (inverse of [`oct_encode`] up to the 16-bit step:
/// the angle between a unit normal and the decoded one is below 0.01°).
pub fn oct_decode(c: [u16; 2]) -> [f32; 3] {
    let x = c[0] as f64 / 65535.0 * 2.0 - 1.0;
    let y = c[1] as f64 / 65535.0 * 2.0 - 1.0;
    let z = 1.0 - x.abs() - y.abs();
    let (x, y) = if z < 0.0 {
        ((1.0 - y.abs()) * sign(x), (1.0 - x.abs()) * sign(y))
    } else {
        (x, y)
    };
    let len = (x * x + y * y + z * z).sqrt();
    [(x / len) as f32, (y / len) as f32, (z / len) as f32]
}

fn sign(v: f64) -> f64 {
    if v < 0.0 {
        -1.0
    } else {
        1.0
    }
}

impl SourceMesh {
    /// The attribute bits of the mesh.
    pub fn attributes(&self) -> u32 {
        (if self.normals.is_some() {
            ATTR_NORMALS
        } else {
            0
        }) | (if self.colors.is_some() {
            ATTR_COLORS
        } else {
            0
        }) | (if self.materials.is_some() {
            ATTR_MATERIALS
        } else {
            0
        })
    }

    /// Vertex `i`'s position in voxels of the chunk's frame (exact).
    pub fn position(&self, i: u32) -> [f64; 3] {
        self.positions[i as usize].map(dequantize)
    }

    /// Checks the invariants a payload must meet (section 14.4): at least one triangle and at
    /// most [`MAX_TRIANGLES`], attribute arrays of the right lengths, and indices in first-use
    /// order (each index at most the number of vertices used before it, every vertex used).
    pub fn check(&self) -> Result<(), String> {
        let (v, t) = (self.positions.len(), self.triangles.len());
        if t == 0 || t > MAX_TRIANGLES as usize {
            return Err(format!("{t} triangles (1..={MAX_TRIANGLES})"));
        }
        let lens = [
            self.normals.as_ref().map(|n| ("normals", n.len(), v)),
            self.colors.as_ref().map(|c| ("colours", c.len(), v)),
            self.materials.as_ref().map(|m| ("materials", m.len(), t)),
        ];
        for (what, got, want) in lens.into_iter().flatten() {
            if got != want {
                return Err(format!("{got} {what} for {want} entries"));
            }
        }
        let mut next = 0u32;
        for (k, tri) in self.triangles.iter().enumerate() {
            for &i in tri {
                if i > next {
                    return Err(format!(
                        "triangle {k} uses vertex {i} before vertex {next} (vertices are numbered in first-use order)"
                    ));
                }
                next += (i == next) as u32;
            }
        }
        if next as usize != v {
            return Err(format!(
                "{v} vertices but the triangles use {next} (every vertex is used)"
            ));
        }
        Ok(())
    }

    /// The decompressed block (section 14.4): the head, then the arrays as byte planes.
    pub fn to_block(&self) -> Vec<u8> {
        let (v, t) = (self.positions.len(), self.triangles.len());
        let attrs = self.attributes();
        let mut out = Vec::with_capacity(block_size(v as u64, t as u64, attrs) as usize);
        for w in [v as u32, t as u32, attrs, 0] {
            out.extend_from_slice(&w.to_le_bytes());
        }
        for a in 0..3 {
            planes(&mut out, self.positions.iter().map(|p| p[a] as u32), 2);
        }
        if let Some(n) = &self.normals {
            for a in 0..2 {
                planes(&mut out, n.iter().map(|c| c[a] as u32), 2);
            }
        }
        if let Some(c) = &self.colors {
            for a in 0..4 {
                out.extend(c.iter().map(|c| c[a]));
            }
        }
        let mut next = 0u32;
        let codes: Vec<u32> = self
            .triangles
            .iter()
            .flatten()
            .map(|&i| {
                let code = next - i;
                next += (i == next) as u32;
                code
            })
            .collect();
        planes(&mut out, codes.iter().copied(), 4);
        if let Some(m) = &self.materials {
            planes(&mut out, m.iter().map(|&m| m as u32), 2);
        }
        out
    }

    /// Parses a decompressed block of a payload whose entry says `t` triangles, with every
    /// check of section 14.4.
    pub fn from_block(block: &[u8], t: u32) -> Result<SourceMesh, String> {
        let word = |at: usize| u32::from_le_bytes(block[at..at + 4].try_into().expect("4 bytes"));
        if (block.len() as u64) < HEAD_BYTES {
            return Err(format!(
                "block of {} bytes has no 16-byte head",
                block.len()
            ));
        }
        let (v, bt, attrs, reserved) = (word(0), word(4), word(8), word(12));
        if bt != t || attrs & !7 != 0 || reserved != 0 {
            return Err(format!(
                "head says {bt} triangles, attributes {attrs:#x}, reserved {reserved:#x} (the entry says {t} triangles; attributes 0..=7, reserved 0)"
            ));
        }
        if v == 0 || v as u64 > 3 * t as u64 {
            return Err(format!("{v} vertices for {t} triangles (1..=3·{t})"));
        }
        let want = block_size(v as u64, t as u64, attrs);
        if block.len() as u64 != want {
            return Err(format!(
                "block is {} bytes, but {v} vertices and {t} triangles with attributes {attrs:#x} take {want}",
                block.len()
            ));
        }
        let (v, t) = (v as usize, t as usize);
        let mut at = HEAD_BYTES as usize;
        let mut take = |n: usize, width: usize| -> Vec<u32> {
            let vals = unplanes(&block[at..at + n * width], n, width);
            at += n * width;
            vals
        };
        let (x, y, z) = (take(v, 2), take(v, 2), take(v, 2));
        let positions = (0..v)
            .map(|i| [x[i] as u16, y[i] as u16, z[i] as u16])
            .collect();
        let normals = (attrs & ATTR_NORMALS != 0).then(|| {
            let (a, b) = (take(v, 2), take(v, 2));
            (0..v).map(|i| [a[i] as u16, b[i] as u16]).collect()
        });
        let colors = (attrs & ATTR_COLORS != 0).then(|| {
            let ch: Vec<Vec<u32>> = (0..4).map(|_| take(v, 1)).collect();
            (0..v)
                .map(|i| [0, 1, 2, 3].map(|c| ch[c][i] as u8))
                .collect()
        });
        let codes = take(3 * t, 4);
        let materials = (attrs & ATTR_MATERIALS != 0)
            .then(|| take(t, 2).into_iter().map(|m| m as u16).collect());
        let mut next = 0u32;
        let mut triangles = Vec::with_capacity(t);
        for (k, c) in codes.chunks_exact(3).enumerate() {
            let mut tri = [0u32; 3];
            for (j, &code) in c.iter().enumerate() {
                if code > next {
                    return Err(format!(
                        "triangle {k}: index code {code} reaches before the first vertex ({next} used so far)"
                    ));
                }
                tri[j] = next - code;
                next += (code == 0) as u32;
            }
            triangles.push(tri);
        }
        let mesh = SourceMesh {
            positions,
            normals,
            colors,
            triangles,
            materials,
        };
        mesh.check()?;
        Ok(mesh)
    }
}

/// Appends `vals` as `width` byte planes (all low bytes, then the next byte of each, …).
fn planes(out: &mut Vec<u8>, vals: impl Iterator<Item = u32> + Clone, width: usize) {
    for b in 0..width {
        out.extend(vals.clone().map(|v| (v >> (8 * b)) as u8));
    }
}

/// The `n` values of `width` bytes stored as byte planes in `bytes` (`n·width` bytes).
fn unplanes(bytes: &[u8], n: usize, width: usize) -> Vec<u32> {
    let mut vals = vec![0u32; n];
    for b in 0..width {
        for (v, &byte) in vals.iter_mut().zip(&bytes[b * n..(b + 1) * n]) {
            *v |= (byte as u32) << (8 * b);
        }
    }
    vals
}

/// Compresses a chunk's source mesh as a channel payload (one zstd frame with its content
/// size); the entry's `count` is the triangle count. The mesh must pass [`SourceMesh::check`].
pub fn encode_source(mesh: &SourceMesh, zstd_level: i32) -> Result<EncodedChannel, FormatError> {
    let bad = |what: String| FormatError::Voxels { what };
    mesh.check()
        .map_err(|e| bad(format!("source triangles: {e}")))?;
    let payload = zstd::bulk::compress(&mesh.to_block(), zstd_level)
        .map_err(|e| bad(format!("zstd compression failed: {e}")))?;
    Ok(EncodedChannel {
        payload_crc32: crc32fast::hash(&payload),
        payload,
        count: mesh.triangles.len() as u32,
        voxel_count: 0,
    })
}

/// Decodes a source payload whose entry says `t` triangles: the frame rules of FORMAT.md 11.2
/// with a content size of at most [`max_block_size`]`(t)` (checked before decompressing), then
/// the checks of [`SourceMesh::from_block`]. The payload's CRC is the caller's to check.
pub fn decode_source(payload: &[u8], t: u32) -> Result<SourceMesh, String> {
    if t == 0 || t > MAX_TRIANGLES {
        return Err(format!("entry count {t} is outside 1..={MAX_TRIANGLES}"));
    }
    let size = match zstd::zstd_safe::get_frame_content_size(payload) {
        Ok(Some(size)) if size <= max_block_size(t) => size,
        Ok(Some(size)) => {
            return Err(format!(
                "the frame declares {size} bytes, more than {} triangles can take ({})",
                t,
                max_block_size(t)
            ))
        }
        _ => {
            // the rules' own message (skippable frame, no magic, no content size)
            crate::rules::check_frame_of(payload, 0, "a declared size")?;
            return Err("the frame has no content size".into());
        }
    };
    crate::rules::check_frame_of(payload, size, &format!("the declared {size}"))?;
    let block = zstd::bulk::decompress(payload, size as usize)
        .map_err(|e| format!("zstd decompression failed: {e}"))?;
    if block.len() as u64 != size {
        return Err(format!(
            "decompressed to {} bytes, the frame declares {size}",
            block.len()
        ));
    }
    SourceMesh::from_block(&block, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mesh() -> SourceMesh {
        SourceMesh {
            positions: vec![
                [0, 0, 0],
                [16384, 0, 0],
                [0, 16384, 0],
                [65535, 65535, 65535],
            ],
            normals: Some(vec![oct_encode([0.0, 0.0, 1.0]); 4]),
            colors: Some(vec![[1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12], [0; 4]]),
            triangles: vec![[0, 1, 2], [2, 1, 3]],
            materials: Some(vec![7, 300]),
        }
    }

    #[test]
    fn block_layout_and_roundtrip() {
        let m = mesh();
        let block = m.to_block();
        assert_eq!(block.len() as u64, block_size(4, 2, 7));
        assert_eq!(
            &block[..16],
            &[4, 0, 0, 0, 2, 0, 0, 0, 7, 0, 0, 0, 0, 0, 0, 0]
        );
        // x plane: low bytes 00 00 00 FF, high bytes 00 40 00 FF
        assert_eq!(&block[16..24], &[0, 0, 0, 0xFF, 0, 0x40, 0, 0xFF]);
        // index codes (first use): 0 0 0 | 3−2 3−1 0 → low plane at 16 + 4·14
        let codes = 16 + 4 * 14;
        assert_eq!(&block[codes..codes + 6], &[0, 0, 0, 1, 2, 0]);
        assert_eq!(SourceMesh::from_block(&block, 2).unwrap(), m);
        let enc = encode_source(&m, 3).unwrap();
        assert_eq!(enc.count, 2);
        assert_eq!(decode_source(&enc.payload, 2).unwrap(), m);
        assert!(decode_source(&enc.payload, 1).is_err());
    }

    #[test]
    fn rejects_bad_indices_and_sizes() {
        let mut m = mesh();
        m.triangles[0] = [0, 2, 1]; // uses 2 before 1
        assert!(m.check().unwrap_err().contains("first-use"));
        let block = mesh().to_block();
        let codes = 16 + 4 * 14;
        let mut b = block.clone();
        b[codes + 4] = 9; // reaches before the first vertex
        assert!(SourceMesh::from_block(&b, 2)
            .unwrap_err()
            .contains("before the first vertex"));
        let mut b = block.clone();
        b[12] = 1; // reserved
        assert!(SourceMesh::from_block(&b, 2).is_err());
        assert!(SourceMesh::from_block(&block[..block.len() - 1], 2).is_err());
        let mut unused = mesh();
        unused.positions.push([1, 1, 1]);
        unused.normals.as_mut().unwrap().push([0, 0]);
        unused.colors.as_mut().unwrap().push([0; 4]);
        assert!(unused.check().unwrap_err().contains("every vertex"));
        // a frame that declares more than t triangles can hold is refused before decompressing
        let big = zstd::bulk::compress(&vec![0u8; max_block_size(2) as usize + 1], 1).unwrap();
        assert!(decode_source(&big, 2).unwrap_err().contains("more than"));
    }

    #[test]
    fn quantization_is_within_half_a_step() {
        assert_eq!(quantize(-128.0), Some(0));
        assert_eq!(quantize(BOX_MAX), Some(65535));
        assert_eq!(quantize(BOX_MAX + STEP), None);
        assert_eq!(quantize(-128.0 - STEP), None);
        for i in 0..10_000 {
            let u = -100.0 + i as f64 * 0.0371;
            let u = u as f32 as f64;
            let q = quantize(u).unwrap();
            assert!((dequantize(q) - u).abs() <= MAX_ERROR, "{u}");
        }
    }

    #[test]
    fn octahedral_normals_within_a_hundredth_degree() {
        let mut s = 1u64;
        for _ in 0..20_000 {
            let mut r = || {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 40) as f64 / (1u64 << 24) as f64) * 2.0 - 1.0
            };
            let n = [r(), r(), r()];
            let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if l < 1e-3 {
                continue;
            }
            let u = n.map(|c| c / l);
            let d = oct_decode(oct_encode(u.map(|c| c as f32)));
            let d = d.map(|c| c as f64);
            let dot: f64 = (0..3).map(|a| u[a] * d[a]).sum();
            let cross = [
                u[1] * d[2] - u[2] * d[1],
                u[2] * d[0] - u[0] * d[2],
                u[0] * d[1] - u[1] * d[0],
            ];
            let sin = cross.iter().map(|c| c * c).sum::<f64>().sqrt();
            assert!(sin.atan2(dot).to_degrees() < 0.01, "{u:?} → {d:?}");
        }
        assert_eq!(oct_encode([0.0; 3]), [32768, 32768]);
    }
}
