//! Blocks: how a run of one chunk's triangle records is stored in the bins file.
//!
//! A chunk's triangles share most of their corners (a fine mesh has about half a vertex per
//! triangle), and in a mesh the flags (material index and attribute bits) are mostly the same
//! from one triangle to the next. A block stores each distinct corner once in a vertex table
//! and the triangles as three 16-bit indices into it; flags that are the same for every
//! triangle of the block are stored once. A block holds at most [`BLOCK_TRIANGLES`] triangles
//! (so at most `3 ·` that many vertices, which 16-bit indices address, and a decoded block is
//! at most about 1.8 MiB).
//!
//! Layout, little-endian, a 16-byte header then the body:
//!
//! | field | bytes | meaning |
//! | --- | --- | --- |
//! | `triangles`: u32 | 4 | triangles in the block, 1 to [`BLOCK_TRIANGLES`] |
//! | `vertices`: u32 | 4 | entries of the vertex table (0 for a raw block) |
//! | `kind`: u32 | 4 | 0 raw, 1 indexed with shared flags, 2 indexed with flags per triangle |
//! | `flags`: u32 | 4 | the flags of every triangle (kind 1), else 0 |
//!
//! - kind 0 (raw): `triangles` records of the [`RecordLayout`], as in the spool;
//! - kind 1 and 2: the vertex table, `vertices` entries of [`RecordLayout::vertex_bytes`]
//!   each (position 3 × f32, then if the layout has them the normal 3 × f32, the colour
//!   RGBA8, the texture coordinates 2 × f32); then `3 · triangles` u16 vertex indices
//!   (corners in order); for kind 2, `triangles` u32 flags.
//!
//! A corner is one vertex-table entry exactly when all its stored bytes are equal (bit
//! patterns: `-0.0` and `0.0` are two entries), so decoding gives back the very records that
//! were encoded. The encoder writes a raw block when the indexed one would not be smaller.

use voxlod_geom::Triangle;

use crate::RecordLayout;

/// Most triangles in one block.
pub const BLOCK_TRIANGLES: usize = 16384;

/// Bytes of a block's header.
pub const BLOCK_HEADER: usize = 16;

const RAW: u32 = 0;
const SHARED_FLAGS: u32 = 1;
const OWN_FLAGS: u32 = 2;

/// Largest vertex-table entry (every attribute).
const MAX_VERTEX: usize = 36;

impl RecordLayout {
    /// Bytes of one vertex-table entry of a block: the position and the per-corner attributes
    /// the layout has.
    pub const fn vertex_bytes(self) -> usize {
        12 + if self.normals { 12 } else { 0 }
            + if self.colors { 4 } else { 0 }
            + if self.texcoords { 8 } else { 0 }
    }

    /// Largest size of the blocks of `records` triangles written in `pieces` separate runs
    /// (each run cut into blocks of at most [`BLOCK_TRIANGLES`]): a block is never larger than
    /// its records plus its header.
    pub fn blocks_bound(self, records: u64, pieces: u64) -> u64 {
        let blocks = pieces + records / BLOCK_TRIANGLES as u64;
        records * self.bytes() as u64 + blocks * BLOCK_HEADER as u64
    }
}

/// Encodes runs of records into blocks, keeping its scratch (vertex table, hash slots) from
/// one block to the next.
pub(crate) struct BlockEncoder {
    layout: RecordLayout,
    /// Open addressing: vertex index + 1, 0 for an empty slot.
    slots: Vec<u32>,
    verts: Vec<u8>,
    idx: Vec<u8>,
    flags: Vec<u8>,
}

impl BlockEncoder {
    pub(crate) fn new(layout: RecordLayout) -> BlockEncoder {
        BlockEncoder {
            layout,
            slots: Vec::new(),
            verts: Vec::new(),
            idx: Vec::new(),
            flags: Vec::new(),
        }
    }

    /// Appends the blocks of `n` records to `out`, record `i` being `rec(i)` (in that order),
    /// cut into blocks of at most [`BLOCK_TRIANGLES`].
    pub(crate) fn encode<'a>(
        &mut self,
        n: usize,
        rec: impl Fn(usize) -> &'a [u8],
        out: &mut Vec<u8>,
    ) {
        let mut first = 0;
        while first < n {
            let k = (n - first).min(BLOCK_TRIANGLES);
            self.block(k, |i| rec(first + i), out);
            first += k;
        }
    }

    /// Appends one block of `n` (1 to [`BLOCK_TRIANGLES`]) records.
    fn block<'a>(&mut self, n: usize, rec: impl Fn(usize) -> &'a [u8], out: &mut Vec<u8>) {
        // the entry size a constant, so that hashing and comparing entries are a few word
        // operations, not loops and `memcmp` calls
        match self.layout.vertex_bytes() {
            12 => self.block_of::<12>(n, rec, out),
            16 => self.block_of::<16>(n, rec, out),
            20 => self.block_of::<20>(n, rec, out),
            24 => self.block_of::<24>(n, rec, out),
            28 => self.block_of::<28>(n, rec, out),
            32 => self.block_of::<32>(n, rec, out),
            _ => self.block_of::<MAX_VERTEX>(n, rec, out),
        }
    }

    /// [`Self::block`] for vertex-table entries of `VB` bytes.
    fn block_of<'a, const VB: usize>(
        &mut self,
        n: usize,
        rec: impl Fn(usize) -> &'a [u8],
        out: &mut Vec<u8>,
    ) {
        debug_assert!(n > 0 && n <= BLOCK_TRIANGLES);
        let l = self.layout;
        let (rb, vb) = (l.bytes(), VB);
        assert_eq!(vb, l.vertex_bytes(), "entry size of {l:?}");
        let size = (4 * n).next_power_of_two().max(64);
        self.slots.clear();
        self.slots.resize(size, 0);
        let mask = size - 1;
        self.verts.clear();
        self.idx.clear();
        self.flags.clear();
        let flags0 = u32::from_le_bytes(rec(0)[36..40].try_into().expect("4 bytes"));
        let mut shared = true;
        let mut nv = 0u32;
        let mut v = [0u8; MAX_VERTEX];
        for i in 0..n {
            let r = rec(i);
            debug_assert_eq!(r.len(), rb);
            let f = u32::from_le_bytes(r[36..40].try_into().expect("4 bytes"));
            shared &= f == flags0;
            self.flags.extend_from_slice(&r[36..40]);
            for k in 0..3 {
                corner(l, r, k, &mut v);
                let v: &[u8; VB] = v[..VB].try_into().expect("VB bytes");
                let mut s = hash(v) as usize & mask;
                let at = loop {
                    let e = self.slots[s];
                    if e == 0 {
                        self.slots[s] = nv + 1;
                        self.verts.extend_from_slice(v);
                        nv += 1;
                        break nv - 1;
                    }
                    let j = (e - 1) as usize;
                    let entry: &[u8; VB] = self.verts[j * VB..(j + 1) * VB]
                        .try_into()
                        .expect("VB bytes");
                    if entry == v {
                        break e - 1;
                    }
                    s = (s + 1) & mask;
                };
                self.idx.extend_from_slice(&(at as u16).to_le_bytes());
            }
        }
        let indexed = self.verts.len() + self.idx.len() + if shared { 0 } else { 4 * n };
        let (kind, vertices, flags) = if indexed < n * rb {
            (
                if shared { SHARED_FLAGS } else { OWN_FLAGS },
                nv,
                if shared { flags0 } else { 0 },
            )
        } else {
            (RAW, 0, 0)
        };
        for w in [n as u32, vertices, kind, flags] {
            out.extend_from_slice(&w.to_le_bytes());
        }
        match kind {
            RAW => (0..n).for_each(|i| out.extend_from_slice(rec(i))),
            _ => {
                out.extend_from_slice(&self.verts);
                out.extend_from_slice(&self.idx);
                if kind == OWN_FLAGS {
                    out.extend_from_slice(&self.flags);
                }
            }
        }
    }
}

/// Writes corner `k`'s vertex-table entry of record `r` into the front of `v`.
#[inline]
fn corner(l: RecordLayout, r: &[u8], k: usize, v: &mut [u8; MAX_VERTEX]) {
    v[..12].copy_from_slice(&r[12 * k..12 * k + 12]);
    let (mut at, mut from) = (12, 40);
    if l.normals {
        v[at..at + 12].copy_from_slice(&r[from + 12 * k..from + 12 * k + 12]);
        (at, from) = (at + 12, from + 36);
    }
    if l.colors {
        v[at..at + 4].copy_from_slice(&r[from + 4 * k..from + 4 * k + 4]);
        (at, from) = (at + 4, from + 12);
    }
    if l.texcoords {
        v[at..at + 8].copy_from_slice(&r[from + 8 * k..from + 8 * k + 8]);
    }
}

/// A hash of a vertex-table entry (a whole number of 32-bit words).
#[inline]
fn hash(v: &[u8]) -> u64 {
    let mut h = 0u64;
    for w in v.chunks_exact(4) {
        let w = u32::from_le_bytes([w[0], w[1], w[2], w[3]]) as u64;
        h = (h.rotate_left(5) ^ w).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
    h ^ (h >> 29)
}

/// A block's header, checked against the layout.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BlockHeader {
    pub(crate) triangles: usize,
    vertices: usize,
    kind: u32,
    flags: u32,
}

impl BlockHeader {
    /// The header in `h`, or what is wrong with it.
    pub(crate) fn parse(h: &[u8; BLOCK_HEADER]) -> Result<BlockHeader, String> {
        let w = |i: usize| u32::from_le_bytes([h[4 * i], h[4 * i + 1], h[4 * i + 2], h[4 * i + 3]]);
        let (t, v, kind, flags) = (w(0) as usize, w(1) as usize, w(2), w(3));
        if t == 0 || t > BLOCK_TRIANGLES {
            return Err(format!("a block of {t} triangles (1 to {BLOCK_TRIANGLES})"));
        }
        let ok = match kind {
            RAW => v == 0 && flags == 0,
            SHARED_FLAGS => v > 0 && v <= 3 * t,
            OWN_FLAGS => v > 0 && v <= 3 * t && flags == 0,
            _ => false,
        };
        if !ok {
            return Err(format!(
                "a block header of kind {kind} with {v} vertices for {t} triangles"
            ));
        }
        Ok(BlockHeader {
            triangles: t,
            vertices: v,
            kind,
            flags,
        })
    }

    /// Bytes of the block's body.
    pub(crate) fn body_bytes(&self, l: RecordLayout) -> usize {
        match self.kind {
            RAW => self.triangles * l.bytes(),
            k => {
                self.vertices * l.vertex_bytes()
                    + 6 * self.triangles
                    + if k == OWN_FLAGS {
                        4 * self.triangles
                    } else {
                        0
                    }
            }
        }
    }

    /// Appends the block's triangles, decoded from its `body`, to `out`; an index past the
    /// vertex table is an error.
    pub(crate) fn decode(
        &self,
        l: RecordLayout,
        body: &[u8],
        out: &mut Vec<Triangle>,
    ) -> Result<(), String> {
        debug_assert_eq!(body.len(), self.body_bytes(l));
        if self.kind == RAW {
            out.extend(body.chunks_exact(l.bytes()).map(|r| l.decode(r)));
            return Ok(());
        }
        // the layout a constant, so that the copies of a corner are fixed moves
        match (l.normals, l.colors, l.texcoords) {
            (false, false, false) => self.decode_of::<false, false, false>(body, out),
            (false, true, false) => self.decode_of::<false, true, false>(body, out),
            (true, false, false) => self.decode_of::<true, false, false>(body, out),
            (true, true, false) => self.decode_of::<true, true, false>(body, out),
            (false, false, true) => self.decode_of::<false, false, true>(body, out),
            (false, true, true) => self.decode_of::<false, true, true>(body, out),
            (true, false, true) => self.decode_of::<true, false, true>(body, out),
            (true, true, true) => self.decode_of::<true, true, true>(body, out),
        }
    }

    /// [`Self::decode`] of an indexed block in the layout with normals `N`, colours `C` and
    /// texture coordinates `T`.
    fn decode_of<const N: bool, const C: bool, const T: bool>(
        &self,
        body: &[u8],
        out: &mut Vec<Triangle>,
    ) -> Result<(), String> {
        let l = RecordLayout {
            normals: N,
            colors: C,
            texcoords: T,
        };
        let t = self.triangles;
        let vb = l.vertex_bytes();
        let (verts, rest) = body.split_at(self.vertices * vb);
        let (idx, flags) = rest.split_at(6 * t);
        out.reserve(t);
        for i in 0..t {
            let mut tri = Triangle::new([[0.0; 3]; 3]);
            for k in 0..3 {
                let j = u16::from_le_bytes([idx[6 * i + 2 * k], idx[6 * i + 2 * k + 1]]) as usize;
                if j >= self.vertices {
                    return Err(format!(
                        "vertex index {j} of a block with {} vertices",
                        self.vertices
                    ));
                }
                let v = &verts[j * vb..(j + 1) * vb];
                bytemuck::bytes_of_mut(&mut tri.v[k]).copy_from_slice(&v[..12]);
                let mut at = 12;
                if l.normals {
                    bytemuck::bytes_of_mut(&mut tri.n[k]).copy_from_slice(&v[at..at + 12]);
                    at += 12;
                }
                if l.colors {
                    tri.c[k].copy_from_slice(&v[at..at + 4]);
                    at += 4;
                }
                if l.texcoords {
                    bytemuck::bytes_of_mut(&mut tri.uv[k]).copy_from_slice(&v[at..at + 8]);
                }
            }
            tri.flags = if self.kind == OWN_FLAGS {
                u32::from_le_bytes([
                    flags[4 * i],
                    flags[4 * i + 1],
                    flags[4 * i + 2],
                    flags[4 * i + 3],
                ])
            } else {
                self.flags
            };
            out.push(tri);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode_all(l: RecordLayout, mut b: &[u8]) -> Vec<Triangle> {
        let mut out = Vec::new();
        while !b.is_empty() {
            let h = BlockHeader::parse(b[..BLOCK_HEADER].try_into().unwrap()).unwrap();
            let n = h.body_bytes(l);
            h.decode(l, &b[BLOCK_HEADER..BLOCK_HEADER + n], &mut out)
                .unwrap();
            b = &b[BLOCK_HEADER + n..];
        }
        out
    }

    /// A strip of triangles sharing corners, every attribute set, with flags that change or
    /// not, round-trips through blocks in every layout; shared corners make it smaller than its
    /// records, a soup of distinct corners is stored raw.
    #[test]
    fn blocks_round_trip_and_share_corners() {
        for bits in 0..8 {
            let l = RecordLayout {
                normals: bits & 1 != 0,
                colors: bits & 2 != 0,
                texcoords: bits & 4 != 0,
            };
            for (n, own_flags) in [(1, false), (5000, false), (40000, true)] {
                let p = |i: usize| [i as f32 * 0.5, (i % 7) as f32, -0.0];
                // triangle i has the vertices i, i + 1, i + 2, attributes a function of the vertex
                let tris: Vec<Triangle> = (0..n)
                    .map(|i| {
                        let mut t = Triangle::new([p(i), p(i + 1), p(i + 2)]);
                        for k in 0..3 {
                            let j = i + k;
                            if l.normals {
                                t.n[k] = p(j + 3);
                            }
                            if l.colors {
                                t.c[k] = [j as u8, 1, (j >> 8) as u8, 3];
                            }
                            if l.texcoords {
                                t.uv[k] = [0.5, j as f32];
                            }
                        }
                        t.flags = if own_flags { (i % 3) as u32 } else { 7 };
                        t
                    })
                    .collect();
                let mut recs = Vec::new();
                for t in &tris {
                    l.encode(t, &mut recs).unwrap();
                }
                let rb = l.bytes();
                let mut out = Vec::new();
                BlockEncoder::new(l).encode(n, |i| &recs[i * rb..(i + 1) * rb], &mut out);
                assert_eq!(decode_all(l, &out), tris, "{l:?} {n}");
                assert!(out.len() as u64 <= l.blocks_bound(n as u64, 1));
                if n > 1 {
                    let small = out.len() * 10 < recs.len() * 6;
                    assert!(small, "{l:?} {n}: {} bytes", out.len());
                }
            }
            // a soup: every corner distinct, stored raw
            let tris: Vec<Triangle> = (0..100)
                .map(|i| {
                    let f = i as f32;
                    Triangle::new([[f, 0.0, 0.0], [f, 1.0, 0.0], [f, 0.0, 1.0]])
                })
                .collect();
            let mut recs = Vec::new();
            for t in &tris {
                l.encode(t, &mut recs).unwrap();
            }
            let rb = l.bytes();
            let mut out = Vec::new();
            BlockEncoder::new(l).encode(100, |i| &recs[i * rb..(i + 1) * rb], &mut out);
            assert_eq!(out.len(), BLOCK_HEADER + recs.len());
            assert_eq!(decode_all(l, &out), tris);
        }
    }

    #[test]
    fn bad_headers_and_indices_are_refused() {
        let h = |w: [u32; 4]| {
            let mut b = [0u8; BLOCK_HEADER];
            for (i, x) in w.iter().enumerate() {
                b[4 * i..4 * i + 4].copy_from_slice(&x.to_le_bytes());
            }
            BlockHeader::parse(&b)
        };
        assert!(h([0, 0, 0, 0]).is_err());
        assert!(h([BLOCK_TRIANGLES as u32 + 1, 0, 0, 0]).is_err());
        assert!(h([2, 7, 1, 0]).is_err());
        assert!(h([2, 3, 3, 0]).is_err());
        assert!(h([2, 1, 0, 0]).is_err());
        let ok = h([1, 1, 1, 5]).unwrap();
        let l = RecordLayout {
            normals: false,
            colors: false,
            texcoords: false,
        };
        let mut body = vec![0u8; 12];
        body.extend_from_slice(&[0, 0, 1, 0, 0, 0]);
        let e = ok.decode(l, &body, &mut Vec::new()).unwrap_err();
        assert!(e.contains("vertex index 1"), "{e}");
    }
}
