//! Random access to PLY vertices for the face readers, in two forms:
//! [`MappedVertices`] reads fixed-size binary vertex records straight from the memory map
//! (nothing is copied), [`CompactVertices`] holds only position, normal and colour of each
//! vertex for inputs that can only be read front to back (ASCII, gzip) — O(vertices) memory.

use crate::ply_header::{Element, Kind, Layout, Role, Scalar};
use crate::ply_records::{decode_f32, decode_f64, Records};
use crate::{IngestError, Location};
use std::path::Path;
use voxlod_geom::DEFAULT_COLOR;

/// One vertex's attributes as a triangle corner.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Corner {
    pub p: [f32; 3],
    pub n: [f32; 3],
    pub c: [u8; 4],
}

pub(crate) trait VertexSource {
    fn count(&self) -> u64;
    /// Vertex `i < count()`.
    fn corner(&self, i: usize) -> Corner;
}

/// A colour channel to 8 bits: floats are 0–1, 16-bit unsigned 0–65535, other integers 0–255.
#[inline]
fn color_byte(v: f64, ty: Scalar) -> u8 {
    let v = match ty {
        Scalar::F32 | Scalar::F64 => v * 255.0,
        Scalar::U16 => v / 257.0,
        _ => v,
    };
    // NaN becomes 0 through the saturating cast
    v.round().clamp(0.0, 255.0) as u8
}

/// Vertices parsed into compact arrays. Normals and colours are empty when absent.
pub(crate) struct CompactVertices {
    pos: Vec<[f32; 3]>,
    nrm: Vec<[f32; 3]>,
    col: Vec<[u8; 4]>,
}

impl CompactVertices {
    /// Reads all records of the vertex element `el` from `src`, refusing non-finite positions.
    pub fn load<R: Records>(
        path: &Path,
        src: &mut R,
        el: &Element,
        layout: &Layout,
        progress: &mut dyn FnMut(u64),
    ) -> Result<Self, IngestError> {
        // The count comes from the header: don't trust it for the allocation.
        let cap = el.count.min(1 << 24) as usize;
        let mut pos = Vec::with_capacity(cap);
        let mut nrm = Vec::with_capacity(if layout.has_normals { cap } else { 0 });
        let mut col = Vec::with_capacity(if layout.has_colors { cap } else { 0 });
        src.element(&el.name, el.count);
        for i in 0..el.count {
            src.begin(i)?;
            let mut a = [0f32; 6];
            let mut c = DEFAULT_COLOR;
            let at = src.location();
            for (p, role) in el.props.iter().zip(&layout.roles) {
                match (*role, p.kind) {
                    (Role::Attr(s), Kind::Scalar(ty)) if s < 6 => a[s] = src.f32(ty)?,
                    (Role::Attr(s), Kind::Scalar(ty)) => c[s - 6] = color_byte(src.f64(ty)?, ty),
                    (_, kind) => src.skip(kind)?,
                }
            }
            src.end()?;
            let p = [a[0], a[1], a[2]];
            if !p.iter().all(|x| x.is_finite()) {
                return Err(IngestError::NonFinite {
                    path: path.to_path_buf(),
                    at,
                    vertex: i,
                    coords: p.map(|x| x as f64),
                });
            }
            pos.push(p);
            if layout.has_normals {
                nrm.push([a[3], a[4], a[5]]);
            }
            if layout.has_colors {
                col.push(c);
            }
            if i & 0xffff == 0 {
                progress(src.bytes_done());
            }
        }
        Ok(CompactVertices { pos, nrm, col })
    }
}

impl VertexSource for CompactVertices {
    fn count(&self) -> u64 {
        self.pos.len() as u64
    }
    #[inline]
    fn corner(&self, i: usize) -> Corner {
        Corner {
            p: self.pos[i],
            n: if self.nrm.is_empty() {
                [0.0; 3]
            } else {
                self.nrm[i]
            },
            c: if self.col.is_empty() {
                DEFAULT_COLOR
            } else {
                self.col[i]
            },
        }
    }
}

/// Fixed-size binary vertex records read in place from the memory map.
pub(crate) struct MappedVertices<'a, const BE: bool> {
    /// Exactly `count * stride` bytes.
    data: &'a [u8],
    stride: usize,
    count: u64,
    /// (byte offset in the record, type) of x, y, z, nx, ny, nz, r, g, b, a.
    attr: [Option<(usize, Scalar)>; 10],
    has_normals: bool,
    has_colors: bool,
}

impl<'a, const BE: bool> MappedVertices<'a, BE> {
    /// `data` is the vertex element's bytes; the element must have no list property.
    pub fn new(data: &'a [u8], el: &Element, layout: &Layout) -> Self {
        let stride = el.fixed_size().unwrap_or(0);
        debug_assert!(stride > 0 && data.len() as u64 == el.count * stride as u64);
        let mut attr = [None; 10];
        let mut off = 0;
        for (p, role) in el.props.iter().zip(&layout.roles) {
            if let Kind::Scalar(ty) = p.kind {
                if let Role::Attr(s) = *role {
                    attr[s] = Some((off, ty));
                }
                off += ty.size();
            }
        }
        MappedVertices {
            data,
            stride,
            count: el.count,
            attr,
            has_normals: layout.has_normals,
            has_colors: layout.has_colors,
        }
    }
}

impl<const BE: bool> MappedVertices<'_, BE> {
    /// Position of vertex `i < count`.
    #[inline]
    pub fn position(&self, i: usize) -> [f32; 3] {
        let rec = &self.data[i * self.stride..(i + 1) * self.stride];
        let f = |s: usize| match self.attr[s] {
            Some((o, ty)) => decode_f32::<BE>(&rec[o..], ty),
            None => 0.0,
        };
        [f(0), f(1), f(2)]
    }
}

impl<const BE: bool> VertexSource for MappedVertices<'_, BE> {
    fn count(&self) -> u64 {
        self.count
    }
    #[inline]
    fn corner(&self, i: usize) -> Corner {
        let rec = &self.data[i * self.stride..(i + 1) * self.stride];
        let f = |s: usize| match self.attr[s] {
            Some((o, ty)) => decode_f32::<BE>(&rec[o..], ty),
            None => 0.0,
        };
        let mut c = DEFAULT_COLOR;
        if self.has_colors {
            for (k, ch) in c.iter_mut().enumerate() {
                match self.attr[6 + k] {
                    // the usual `uchar` channel is its own byte (what color_byte returns)
                    Some((o, Scalar::U8)) => *ch = rec[o],
                    Some((o, ty)) => *ch = color_byte(decode_f64::<BE>(&rec[o..], ty), ty),
                    None => {}
                }
            }
        }
        Corner {
            p: [f(0), f(1), f(2)],
            n: if self.has_normals {
                [f(3), f(4), f(5)]
            } else {
                [0.0; 3]
            },
            c,
        }
    }
}

/// Error for a face that uses a vertex with a NaN or infinite coordinate (mapped vertices
/// are only checked when used).
pub(crate) fn non_finite(path: &Path, at: Location, vertex: u64, p: [f32; 3]) -> IngestError {
    IngestError::NonFinite {
        path: path.to_path_buf(),
        at,
        vertex,
        coords: p.map(|x| x as f64),
    }
}

#[cfg(test)]
mod tests {
    use super::color_byte;
    use crate::ply_header::Scalar;

    #[test]
    fn colour_channels_to_bytes() {
        assert_eq!(color_byte(200.0, Scalar::U8), 200);
        assert_eq!(color_byte(1.0, Scalar::F32), 255);
        assert_eq!(color_byte(0.5, Scalar::F32), 128);
        assert_eq!(color_byte(2.0, Scalar::F64), 255);
        assert_eq!(color_byte(-0.1, Scalar::F32), 0);
        assert_eq!(color_byte(f64::NAN, Scalar::F32), 0);
        assert_eq!(color_byte(65535.0, Scalar::U16), 255);
        assert_eq!(color_byte(-5.0, Scalar::I8), 0);
    }
}
