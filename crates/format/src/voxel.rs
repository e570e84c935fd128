//! The 12-byte voxel record of the Chajdas paper (Chajdas, Reitinger & Westermann, "Scalable
//! rendering for very large meshes", WSCG 2014, section 3): 4 bytes of position and face
//! mask, 4 bytes of 10:10:10 normal, 4 bytes of RGBA colour. Bit layouts are in
//! `docs/FORMAT.md`; this file is the one place that packs and unpacks them.

use bytemuck::{Pod, Zeroable};

/// Face-mask bit of the voxel face on the +x side.
pub const FACE_POS_X: u8 = 1 << 0;
/// Face-mask bit of the voxel face on the −x side.
pub const FACE_NEG_X: u8 = 1 << 1;
/// Face-mask bit of the voxel face on the +y side.
pub const FACE_POS_Y: u8 = 1 << 2;
/// Face-mask bit of the voxel face on the −y side.
pub const FACE_NEG_Y: u8 = 1 << 3;
/// Face-mask bit of the voxel face on the +z side.
pub const FACE_POS_Z: u8 = 1 << 4;
/// Face-mask bit of the voxel face on the −z side.
pub const FACE_NEG_Z: u8 = 1 << 5;
/// All six faces.
pub const FACE_ALL: u8 = 0x3f;

/// Largest magnitude of a 10-bit signed normal component (`round(n · 511)`).
pub const NORMAL_SCALE: f32 = 511.0;

/// One voxel: position inside its chunk (8 bits per axis) with the 6-bit face mask, the
/// quantized normal and the colour. Plain old data, 12 bytes, three little-endian u32 words.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Pod, Zeroable)]
pub struct Voxel {
    /// bits 0–7 x, 8–15 y, 16–23 z, 24–29 face mask, 30–31 zero.
    pub pos_mask: u32,
    /// bits 0–9 x, 10–19 y, 20–29 z, each a 10-bit two's-complement snorm; 30–31 zero.
    pub normal: u32,
    /// bits 0–7 red, 8–15 green, 16–23 blue, 24–31 alpha.
    pub color: u32,
}

impl Voxel {
    /// Packs a voxel. `mask` must fit in 6 bits.
    #[inline]
    pub fn new(pos: [u8; 3], mask: u8, normal: u32, color: u32) -> Voxel {
        debug_assert!(mask <= FACE_ALL);
        Voxel {
            pos_mask: pack_pos(pos, mask),
            normal,
            color,
        }
    }
    /// Position inside the chunk.
    #[inline]
    pub fn pos(&self) -> [u8; 3] {
        [
            self.pos_mask as u8,
            (self.pos_mask >> 8) as u8,
            (self.pos_mask >> 16) as u8,
        ]
    }
    /// Face mask (6 bits, `FACE_*`).
    #[inline]
    pub fn mask(&self) -> u8 {
        ((self.pos_mask >> 24) & 0x3f) as u8
    }
    /// Morton code of the position inside the chunk (the canonical order of voxels in a node).
    #[inline]
    pub fn morton(&self) -> u32 {
        let p = self.pos();
        morton8(p[0], p[1], p[2])
    }
    /// The decoded normal, components in [-1, 1] (not renormalized).
    pub fn normal_f32(&self) -> [f32; 3] {
        let q = unpack_normal(self.normal);
        [
            q[0] as f32 / NORMAL_SCALE,
            q[1] as f32 / NORMAL_SCALE,
            q[2] as f32 / NORMAL_SCALE,
        ]
    }
    /// RGBA8 colour.
    pub fn rgba(&self) -> [u8; 4] {
        self.color.to_le_bytes()
    }
}

/// Packs a position and face mask into the first voxel word.
#[inline]
pub fn pack_pos(pos: [u8; 3], mask: u8) -> u32 {
    pos[0] as u32 | (pos[1] as u32) << 8 | (pos[2] as u32) << 16 | ((mask & 0x3f) as u32) << 24
}

/// Morton code of an 8-bit-per-axis position (24 bits), defined in `voxlod-geom` with the
/// other Morton forms.
pub use voxlod_geom::morton8;

/// Quantizes a normal to 10:10:10 snorm. The input is normalized first; a zero or non-finite
/// vector packs to zero (which [`face_mask`] maps to all six faces).
#[inline]
pub fn pack_normal(n: [f32; 3]) -> u32 {
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    // Branch-free, so that loops over many normals ([`pack_normals`]) use SIMD lanes: a zero
    // or non-finite length gives NaN or garbage components, and the word is then replaced by 0.
    let valid = len.is_finite() && len > 0.0;
    let mut w = 0u32;
    for (a, &c) in n.iter().enumerate() {
        let q = ((c / len) * NORMAL_SCALE)
            .round()
            .clamp(-NORMAL_SCALE, NORMAL_SCALE) as i32;
        w |= ((q as u32) & 0x3ff) << (10 * a);
    }
    if valid {
        w
    } else {
        0
    }
}

/// [`pack_normal`] of many vectors, given as their x, y and z components: `out[i]` is
/// `pack_normal([x[i], y[i], z[i]])`, bit for bit. The loop has no branches, so the compiler
/// runs it in SIMD lanes (square root and division are correctly rounded in every lane, so
/// the bits are those of the scalar function). All four slices must have the same length.
pub fn pack_normals(x: &[f32], y: &[f32], z: &[f32], out: &mut [u32]) {
    assert!(
        x.len() == out.len() && y.len() == out.len() && z.len() == out.len(),
        "pack_normals: component and output slices differ in length"
    );
    for (((o, &x), &y), &z) in out.iter_mut().zip(x).zip(y).zip(z) {
        *o = pack_normal([x, y, z]);
    }
}

/// [`pack_normal`] of a direction given in f64 and not necessarily of unit length or of f32
/// range (e.g. an unnormalized sum of weighted normals, whose components may be tiny): it is
/// normalized in f64 with one square root and one division, `q = round(c · 511/|n|)`, round half
/// away from zero, clamped to [−511, 511]. Equal to `pack_normal(n / |n| as f32)` except where a
/// component lies within about 1e-7 of a rounding boundary, where the two may differ by one step.
/// A zero or non-finite vector packs to zero.
#[inline]
pub fn pack_normal_f64(n: [f64; 3]) -> u32 {
    let len2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    if !(len2.is_finite() && len2 > 0.0) {
        return 0;
    }
    let s = NORMAL_SCALE as f64 / len2.sqrt();
    let q = |c: f64| ((c * s).round().clamp(-511.0, 511.0) as i32 as u32) & 0x3ff;
    q(n[0]) | q(n[1]) << 10 | q(n[2]) << 20
}

/// True if a component of the packed normal is −512 (`0x200`), which the 10-bit field can
/// hold but the format does not allow (FORMAT.md section 6: components are in [−511, 511];
/// writers refuse it and readers reject it).
#[inline]
pub fn has_minus_512(w: u32) -> bool {
    let f = |s: u32| (w >> s) & 0x3ff == 0x200;
    f(0) | f(10) | f(20)
}

/// The three signed 10-bit components of a packed normal, each in [-511, 511].
#[inline]
pub fn unpack_normal(w: u32) -> [i32; 3] {
    let f = |s: u32| (((w >> s) & 0x3ff) as i32) << 22 >> 22;
    [f(0), f(10), f(20)]
}

/// The outward-facing faces of a voxel from its quantized normal: face +a when component a is
/// positive, −a when negative, nothing along a when it is zero. A zero normal (no defined
/// direction) gives all six faces.
#[inline]
pub fn face_mask(normal: u32) -> u8 {
    let q = unpack_normal(normal);
    if q == [0, 0, 0] {
        return FACE_ALL;
    }
    let mut m = 0u8;
    for (a, &c) in q.iter().enumerate() {
        if c > 0 {
            m |= 1 << (2 * a);
        } else if c < 0 {
            m |= 1 << (2 * a + 1);
        }
    }
    m
}

/// Caps: the faces of a voxel at `pos` that lie on the border of its chunk (x = 0 gets −x,
/// x = 255 gets +x, and so on), so that neighbouring chunks of different levels never show a
/// hole between them.
#[inline]
pub fn border_caps(pos: [u8; 3]) -> u8 {
    let mut m = 0u8;
    for (a, &p) in pos.iter().enumerate() {
        if p == 255 {
            m |= 1 << (2 * a);
        }
        if p == 0 {
            m |= 1 << (2 * a + 1);
        }
    }
    m
}

/// Packs RGBA8 into the colour word.
#[inline]
pub fn pack_color(c: [u8; 4]) -> u32 {
    u32::from_le_bytes(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_12_bytes() {
        assert_eq!(std::mem::size_of::<Voxel>(), 12);
    }

    #[test]
    fn pos_mask_roundtrip() {
        let v = Voxel::new([1, 2, 255], FACE_POS_X | FACE_NEG_Z, 0, 0);
        assert_eq!(v.pos(), [1, 2, 255]);
        assert_eq!(v.mask(), FACE_POS_X | FACE_NEG_Z);
        assert_eq!(v.pos_mask, 0x00ff_0201 | (0x21 << 24));
    }

    #[test]
    fn normal_quantization() {
        assert_eq!(unpack_normal(pack_normal([1.0, 0.0, 0.0])), [511, 0, 0]);
        assert_eq!(unpack_normal(pack_normal([0.0, -2.0, 0.0])), [0, -511, 0]);
        assert_eq!(pack_normal([0.0, 0.0, 0.0]), 0);
        assert_eq!(pack_normal([f32::NAN, 0.0, 1.0]), 0);
        let q = unpack_normal(pack_normal([1.0, 1.0, -1.0]));
        assert_eq!(q, [295, 295, -295]);
        assert_eq!(pack_normal([0.0, 0.0, -1.0]) >> 30, 0);
        assert_eq!(pack_normal([f32::INFINITY, 0.0, 1.0]), 0);
        assert_eq!(pack_normal([1e30, 1e30, 1e30]), 0); // the length overflows
    }

    /// FORMAT.md section 6 as written: early return for a zero or non-finite length.
    fn reference_pack(n: [f32; 3]) -> u32 {
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if !(len.is_finite() && len > 0.0) {
            return 0;
        }
        let mut w = 0u32;
        for (a, &c) in n.iter().enumerate() {
            let q = ((c / len) * 511.0).round().clamp(-511.0, 511.0) as i32;
            w |= ((q as u32) & 0x3ff) << (10 * a);
        }
        w
    }

    /// The branch-free scalar form and the batch form give the reference's bits, on integer
    /// sums as the LOD merge makes them and on arbitrary floats, zero, non-finite and
    /// denormal vectors included.
    #[test]
    fn pack_normals_matches_pack_normal() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let mut v: Vec<[f32; 3]> = (0..100_000)
            .map(|i| {
                let r = next();
                if i % 2 == 0 {
                    // integer sums of up to eight 10-bit components
                    [0, 21, 42].map(|k| ((r >> k & 0x1fff) as i32 - 4096) as f32)
                } else {
                    [0, 21, 42].map(|k| f32::from_bits((r >> k) as u32))
                }
            })
            .collect();
        v.extend([
            [0.0, 0.0, 0.0],
            [-0.0, 0.0, -0.0],
            [f32::NAN, 1.0, 1.0],
            [f32::INFINITY, 1.0, 1.0],
            [1e-45, 0.0, 0.0],
            [4088.0, -4088.0, 4088.0],
            [0.5, 0.5, 0.0],
        ]);
        let (x, y, z): (Vec<f32>, Vec<f32>, Vec<f32>) = (
            v.iter().map(|n| n[0]).collect(),
            v.iter().map(|n| n[1]).collect(),
            v.iter().map(|n| n[2]).collect(),
        );
        let mut out = vec![0u32; v.len()];
        pack_normals(&x, &y, &z, &mut out);
        for (n, w) in v.iter().zip(&out) {
            assert_eq!(*w, reference_pack(*n), "{n:?}");
            assert_eq!(pack_normal(*n), reference_pack(*n), "{n:?}");
        }
    }

    #[test]
    fn pack_normal_f64_matches_pack_normal() {
        // SplitMix64 directions of all lengths, including tiny and huge ones
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut r = || {
            x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = x;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let mut off = 0;
        for i in 0..200_000 {
            let scale = [1.0, 1e-30, 1e-300, 1e30, 3.0][i % 5];
            let n = [r() * scale, r() * scale, r() * scale];
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            let a = unpack_normal(pack_normal_f64(n));
            let unit = n.map(|c| (c / len) as f32);
            let b = unpack_normal(pack_normal(unit));
            let d = (0..3).map(|k| (a[k] - b[k]).abs()).max().unwrap();
            assert!(d <= 1, "{n:?}: {a:?} vs {b:?}");
            off += (d != 0) as usize;
        }
        assert!(off < 200, "{off} of 200000 differ by one step");
        assert_eq!(pack_normal_f64([0.0; 3]), 0);
        assert_eq!(pack_normal_f64([f64::NAN, 1.0, 0.0]), 0);
        assert_eq!(pack_normal_f64([f64::INFINITY, 1.0, 0.0]), 0);
        assert_eq!(
            pack_normal_f64([0.0, 0.0, -1e-40]),
            pack_normal([0.0, 0.0, -1.0])
        );
    }

    #[test]
    fn face_rules() {
        assert_eq!(face_mask(pack_normal([1.0, 0.0, 0.0])), FACE_POS_X);
        assert_eq!(
            face_mask(pack_normal([-1.0, 1.0, 0.0])),
            FACE_NEG_X | FACE_POS_Y
        );
        assert_eq!(face_mask(0), FACE_ALL);
        assert_eq!(border_caps([0, 5, 255]), FACE_NEG_X | FACE_POS_Z);
        assert_eq!(border_caps([3, 5, 7]), 0);
    }

    #[test]
    fn morton8_matches_bit_interleave() {
        for &(x, y, z) in &[
            (0u8, 0u8, 0u8),
            (1, 0, 0),
            (0, 1, 0),
            (0, 0, 1),
            (255, 255, 255),
            (17, 200, 3),
        ] {
            let mut m = 0u32;
            for b in 0..8 {
                m |= (((x >> b) & 1) as u32) << (3 * b);
                m |= (((y >> b) & 1) as u32) << (3 * b + 1);
                m |= (((z >> b) & 1) as u32) << (3 * b + 2);
            }
            assert_eq!(morton8(x, y, z), m);
        }
    }
}
