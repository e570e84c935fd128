//! Compact on-disk triangle records for the spool and the bins: only the attributes the mesh
//! has are stored.
//!
//! A [`Triangle`] is 112 bytes in memory; most scans have no vertex normals and many no colours,
//! and writing those zeros (and reading them back twice) was most of the tiling stages' time
//! on a 100M-triangle input (the disk, not the CPU, is the limit there). A record is, in this
//! order, little-endian:
//!
//! | field | bytes | present |
//! | --- | --- | --- |
//! | `v`: 9 × f32 positions | 36 | always |
//! | `flags`: u32 | 4 | always |
//! | `n`: 9 × f32 vertex normals | 36 | if the layout has normals |
//! | `c`: 3 × RGBA8 colours | 12 | if the layout has colours |
//! | `uv`: 3 × 2 × f32 texture coordinates | 24 | if the layout has texture coordinates |
//!
//! so 40 to 112 bytes (the material index of a textured mesh travels in `flags`, which is
//! always stored). Decoding fills absent normals and texture coordinates with zeros and absent
//! colours with [`DEFAULT_COLOR`], exactly what ingest gives a triangle without them, so a decoded record
//! equals the triangle that was encoded; [`RecordLayout::encode`] refuses a triangle whose
//! absent fields are not those defaults (the layout would lose them).

use voxlod_geom::{Triangle, DEFAULT_COLOR};

use crate::TileError;

/// Which optional attributes the records of one spool or bins file carry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RecordLayout {
    /// Vertex normals are stored (the mesh has `TRI_HAS_NORMALS` triangles).
    pub normals: bool,
    /// Vertex colours are stored (the mesh has non-default colours).
    pub colors: bool,
    /// Texture coordinates are stored (the mesh has `TRI_HAS_UV` triangles).
    pub texcoords: bool,
}

impl RecordLayout {
    /// Every attribute: records are the 112-byte [`Triangle`] in another field order.
    pub const FULL: RecordLayout = RecordLayout {
        normals: true,
        colors: true,
        texcoords: true,
    };

    /// Bytes of one record.
    pub const fn bytes(self) -> usize {
        40 + if self.normals { 36 } else { 0 }
            + if self.colors { 12 } else { 0 }
            + if self.texcoords { 24 } else { 0 }
    }

    /// Appends the record of `t` to `out`. Fails if `t` has normals or colours the layout does
    /// not store (they would be lost).
    #[inline]
    pub fn encode(self, t: &Triangle, out: &mut Vec<u8>) -> Result<(), TileError> {
        let at = out.len();
        out.resize(at + self.bytes(), 0);
        self.encode_into(t, &mut out[at..])
    }

    /// Writes the record of `t` into `out` (`out.len() == self.bytes()`); see [`Self::encode`].
    #[inline]
    pub fn encode_into(self, t: &Triangle, out: &mut [u8]) -> Result<(), TileError> {
        debug_assert_eq!(out.len(), self.bytes());
        let lost_normals = !self.normals && t.n != [[0.0; 3]; 3];
        let lost_uv = !self.texcoords && t.uv != [[0.0; 2]; 3];
        if lost_normals || lost_uv || !self.colors && t.c != [DEFAULT_COLOR; 3] {
            return Err(TileError::LostAttribute(if lost_normals {
                "vertex normals"
            } else if lost_uv {
                "texture coordinates"
            } else {
                "colours"
            }));
        }
        out[..36].copy_from_slice(bytemuck::bytes_of(&t.v));
        out[36..40].copy_from_slice(&t.flags.to_le_bytes());
        let mut at = 40;
        if self.normals {
            out[at..at + 36].copy_from_slice(bytemuck::bytes_of(&t.n));
            at += 36;
        }
        if self.colors {
            out[at..at + 12].copy_from_slice(bytemuck::bytes_of(&t.c));
            at += 12;
        }
        if self.texcoords {
            out[at..at + 24].copy_from_slice(bytemuck::bytes_of(&t.uv));
        }
        Ok(())
    }

    /// The triangle of one record (`rec.len() == self.bytes()`).
    #[inline]
    pub fn decode(self, rec: &[u8]) -> Triangle {
        debug_assert_eq!(rec.len(), self.bytes());
        let mut t = Triangle::new([[0.0; 3]; 3]);
        bytemuck::bytes_of_mut(&mut t.v).copy_from_slice(&rec[..36]);
        t.flags = u32::from_le_bytes([rec[36], rec[37], rec[38], rec[39]]);
        let mut at = 40;
        if self.normals {
            bytemuck::bytes_of_mut(&mut t.n).copy_from_slice(&rec[at..at + 36]);
            at += 36;
        }
        if self.colors {
            bytemuck::bytes_of_mut(&mut t.c).copy_from_slice(&rec[at..at + 12]);
            at += 12;
        }
        if self.texcoords {
            bytemuck::bytes_of_mut(&mut t.uv).copy_from_slice(&rec[at..at + 24]);
        }
        t
    }

    /// Decodes every record of `bytes` (a whole number of records) into `out` (cleared first).
    pub fn decode_all(self, bytes: &[u8], out: &mut Vec<Triangle>) {
        debug_assert_eq!(bytes.len() % self.bytes(), 0);
        out.clear();
        out.extend(bytes.chunks_exact(self.bytes()).map(|r| self.decode(r)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxlod_geom::{TRI_HAS_COLORS, TRI_HAS_NORMALS, TRI_HAS_UV};

    fn full() -> Triangle {
        let mut t = Triangle::new([[1.0, 2.0, 3.0], [4.0, 5.5, 6.0], [-7.0, 8.0, 9.25]]);
        t.n = [[0.0, 0.0, 1.0], [0.5, 0.5, 0.0], [1.0, -1.0, 0.0]];
        t.c = [[1, 2, 3, 4], [250, 251, 252, 253], [0, 128, 255, 7]];
        t.uv = [[0.25, -1.5], [3.0, 0.5], [1.0, 1e-3]];
        t.flags = TRI_HAS_NORMALS | TRI_HAS_COLORS | TRI_HAS_UV;
        t.set_material(77);
        t
    }

    #[test]
    fn every_layout_round_trips_what_it_stores() {
        for bits in 0..8 {
            let (normals, colors, texcoords) = (bits & 1 != 0, bits & 2 != 0, bits & 4 != 0);
            {
                let l = RecordLayout {
                    normals,
                    colors,
                    texcoords,
                };
                let mut t = full();
                if !normals {
                    t.n = [[0.0; 3]; 3];
                    t.flags &= !TRI_HAS_NORMALS;
                }
                if !colors {
                    t.c = [DEFAULT_COLOR; 3];
                }
                if !texcoords {
                    t.uv = [[0.0; 2]; 3];
                    t.flags &= !TRI_HAS_UV;
                }
                let mut buf = Vec::new();
                l.encode(&t, &mut buf).unwrap();
                l.encode(&t, &mut buf).unwrap();
                assert_eq!(buf.len(), 2 * l.bytes());
                let mut back = Vec::new();
                l.decode_all(&buf, &mut back);
                assert_eq!(back, vec![t, t], "{l:?}");
            }
        }
        assert_eq!(RecordLayout::FULL.bytes(), std::mem::size_of::<Triangle>());
    }

    #[test]
    fn a_layout_refuses_attributes_it_would_lose() {
        let mut buf = Vec::new();
        let l = RecordLayout {
            normals: false,
            colors: true,
            texcoords: true,
        };
        let e = l.encode(&full(), &mut buf).unwrap_err();
        assert!(
            matches!(e, TileError::LostAttribute("vertex normals")),
            "{e:?}"
        );
        assert!(e.to_string().contains("vertex normals"), "{e}");
        let l = RecordLayout {
            normals: true,
            colors: false,
            texcoords: true,
        };
        let e = l.encode(&full(), &mut buf).unwrap_err();
        assert!(matches!(e, TileError::LostAttribute("colours")), "{e:?}");
        assert!(e.to_string().contains("colours"), "{e}");
        let l = RecordLayout {
            normals: true,
            colors: true,
            texcoords: false,
        };
        let e = l.encode(&full(), &mut buf).unwrap_err();
        assert!(
            matches!(e, TileError::LostAttribute("texture coordinates")),
            "{e:?}"
        );
        assert!(e.to_string().contains("texture coordinates"), "{e}");
    }
}
