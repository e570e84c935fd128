//! Random access to PLY vertices for the face readers, in two forms:
//! [`MappedVertices`] reads fixed-size binary vertex records straight from the memory map
//! (nothing is copied), [`CompactVertices`] holds only position, normal and colour of each
//! vertex for inputs that can only be read front to back (ASCII, gzip) — O(vertices) memory.

use crate::bounds::PointBounds;
use crate::ply_header::{Element, Kind, Layout, Role, Scalar};
use crate::ply_records::{decode_f32, decode_f64, Records};
use crate::{IngestError, Location};
use std::path::Path;
use voxlod_geom::{Triangle, DEFAULT_COLOR, TRI_HAS_UV};

/// One vertex's attributes as a triangle corner.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Corner {
    pub p: [f32; 3],
    pub n: [f32; 3],
    pub c: [u8; 4],
    /// Texture coordinates (zero without them).
    pub uv: [f32; 2],
}

pub(crate) trait VertexSource {
    fn count(&self) -> u64;
    /// Vertex `i < count()`.
    fn corner(&self, i: usize) -> Corner;
}

/// A colour channel to 8 bits: floats are 0–1, 16-bit unsigned 0–65535, other integers 0–255.
#[inline]
pub(crate) fn color_byte(v: f64, ty: Scalar) -> u8 {
    let v = match ty {
        Scalar::F32 | Scalar::F64 => v * 255.0,
        Scalar::U16 => v / 257.0,
        _ => v,
    };
    // NaN becomes 0 through the saturating cast
    v.round().clamp(0.0, 255.0) as u8
}

/// Vertices parsed into compact arrays. Normals, colours and texture coordinates are empty
/// when absent.
pub(crate) struct CompactVertices {
    pos: Vec<[f32; 3]>,
    nrm: Vec<[f32; 3]>,
    col: Vec<[u8; 4]>,
    uv: Vec<[f32; 2]>,
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
        let mut uv = Vec::with_capacity(if layout.has_texcoords { cap } else { 0 });
        src.element(&el.name, el.count);
        for i in 0..el.count {
            src.begin(i)?;
            let mut a = [0f32; 12];
            let mut c = DEFAULT_COLOR;
            let at = src.location();
            for (p, role) in el.props.iter().zip(&layout.roles) {
                match (*role, p.kind) {
                    (Role::Attr(s), Kind::Scalar(ty)) if !(6..10).contains(&s) => {
                        a[s] = src.f32(ty)?
                    }
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
            if layout.has_texcoords {
                uv.push([a[10], a[11]]);
            }
            if i & 0xffff == 0 {
                progress(src.bytes_done());
            }
        }
        Ok(CompactVertices { pos, nrm, col, uv })
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
            uv: if self.uv.is_empty() {
                [0.0; 2]
            } else {
                self.uv[i]
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
    /// (byte offset in the record, type) of x, y, z, nx, ny, nz, r, g, b, a, u, v.
    attr: [Option<(usize, Scalar)>; 12],
    has_normals: bool,
    has_colors: bool,
    /// The usual record, decoded without per-property dispatch, if this is one.
    packed: Option<Packed>,
}

/// The record layout nearly every writer produces: `float x, y, z` side by side, and if present
/// `float nx, ny, nz` side by side and `uchar red, green, blue[, alpha]` side by side (byte
/// offsets in the record).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Packed {
    p: usize,
    n: Option<usize>,
    /// offset of red and the number of channels (3 or 4)
    c: Option<(usize, usize)>,
}

impl Packed {
    /// The packed form of `attr`, if it has one.
    fn of(
        attr: &[Option<(usize, Scalar)>; 12],
        has_normals: bool,
        has_colors: bool,
    ) -> Option<Self> {
        // `ty` channels `from..from + n` at consecutive offsets of `step` bytes: the first's offset
        let run = |from: usize, n: usize, ty: Scalar| -> Option<usize> {
            let (o, _) = attr[from]?;
            (0..n)
                .all(|k| attr[from + k] == Some((o + k * ty.size(), ty)))
                .then_some(o)
        };
        Some(Packed {
            p: run(0, 3, Scalar::F32)?,
            n: if has_normals {
                Some(run(3, 3, Scalar::F32)?)
            } else {
                None
            },
            c: if has_colors {
                let o = run(6, 3, Scalar::U8)?;
                match attr[9] {
                    None => Some((o, 3)),
                    Some(a) if a == (o + 3, Scalar::U8) => Some((o, 4)),
                    Some(_) => return None,
                }
            } else {
                None
            },
        })
    }
}

impl<'a, const BE: bool> MappedVertices<'a, BE> {
    /// `data` is the vertex element's bytes; the element must have no list property.
    pub fn new(data: &'a [u8], el: &Element, layout: &Layout) -> Self {
        let stride = el.fixed_size().unwrap_or(0);
        debug_assert!(stride > 0 && data.len() as u64 == el.count * stride as u64);
        let mut attr = [None; 12];
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
            // texture coordinates only through the general decoding
            packed: Packed::of(&attr, layout.has_normals, layout.has_colors)
                .filter(|_| !layout.has_texcoords),
        }
    }
}

impl<const BE: bool> MappedVertices<'_, BE> {
    /// Position of vertex `i < count`.
    #[inline]
    pub fn position(&self, i: usize) -> [f32; 3] {
        let rec = &self.data[i * self.stride..(i + 1) * self.stride];
        if let Some(pk) = self.packed {
            return packed_f32s::<BE>(rec, pk.p);
        }
        let f = |s: usize| match self.attr[s] {
            Some((o, ty)) => decode_f32::<BE>(&rec[o..], ty),
            None => 0.0,
        };
        [f(0), f(1), f(2)]
    }
}

impl<const BE: bool> MappedVertices<'_, BE> {
    /// Adds the positions of the vertices in `r` (within `0..count`) to `b`: in the packed
    /// layout straight from the records, without the per-vertex layout test.
    pub(crate) fn add_positions(&self, r: std::ops::Range<u64>, b: &mut PointBounds) {
        let (a, e) = (r.start as usize, r.end as usize);
        match self.packed {
            Some(pk) => {
                let (recs, s) = (&self.data[a * self.stride..e * self.stride], self.stride);
                b.add_many(e - a, |i| packed_f32s::<BE>(&recs[i * s..], pk.p));
            }
            None => (a..e).for_each(|i| b.add(self.position(i))),
        }
    }
}

impl<const BE: bool> VertexSource for MappedVertices<'_, BE> {
    fn count(&self) -> u64 {
        self.count
    }
    #[inline]
    fn corner(&self, i: usize) -> Corner {
        let rec = &self.data[i * self.stride..(i + 1) * self.stride];
        if let Some(pk) = self.packed {
            return packed_corner::<BE>(rec, pk);
        }
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
            uv: [f(10), f(11)],
        }
    }
}

/// [`VertexSource::corner`] of a record in the [`Packed`] layout: what the general decoding gives.
#[inline]
fn packed_corner<const BE: bool>(rec: &[u8], pk: Packed) -> Corner {
    let f32s = |o: usize| packed_f32s::<BE>(rec, o);
    let mut c = DEFAULT_COLOR;
    // fixed lengths: a copy of `n` bytes would be a call to memmove per corner
    match pk.c {
        Some((o, 3)) => c[..3].copy_from_slice(&rec[o..o + 3]),
        Some((o, _)) => c.copy_from_slice(&rec[o..o + 4]),
        None => {}
    }
    Corner {
        p: f32s(pk.p),
        n: pk.n.map_or([0.0; 3], f32s),
        c,
        uv: [0.0; 2],
    }
}

/// Three `float`s side by side at byte `o` of `rec`.
#[inline]
fn packed_f32s<const BE: bool>(rec: &[u8], o: usize) -> [f32; 3] {
    let b = &rec[o..o + 12];
    [0, 4, 8].map(|k| {
        let a = [b[k], b[k + 1], b[k + 2], b[k + 3]];
        if BE {
            f32::from_be_bytes(a)
        } else {
            f32::from_le_bytes(a)
        }
    })
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

/// The triangle of vertices `tri`, or the first vertex with a non-finite position.
#[inline]
pub(crate) fn gather<V: VertexSource>(
    verts: &V,
    tri: [usize; 3],
    flags: u32,
) -> Result<Triangle, (usize, [f32; 3])> {
    // filled corner by corner: `array::map` here compiled to slow copies
    let mut t = Triangle {
        v: [[0.0; 3]; 3],
        n: [[0.0; 3]; 3],
        c: [DEFAULT_COLOR; 3],
        flags,
        uv: [[0.0; 2]; 3],
    };
    for (k, &vi) in tri.iter().enumerate() {
        let c = verts.corner(vi);
        if !(c.p[0].is_finite() && c.p[1].is_finite() && c.p[2].is_finite()) {
            return Err((vi, c.p));
        }
        t.v[k] = c.p;
        t.n[k] = c.n;
        t.c[k] = c.c;
        if flags & TRI_HAS_UV != 0 {
            t.uv[k] = c.uv;
        }
    }
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::{color_byte, MappedVertices, VertexSource};
    use crate::ply_header::{parse_header, Scalar};

    /// Vertices of `props` (PLY property lines) from pseudo-random bytes, read with and without
    /// the packed decoding: the same bits. Returns whether the packed form was taken.
    fn packed_equals_general<const BE: bool>(props: &str) -> bool {
        let head = format!(
            "ply\nformat {} 1.0\nelement vertex 300\n{props}element face 0\nproperty list uchar int vertex_indices\nend_header\n",
            if BE { "binary_big_endian" } else { "binary_little_endian" }
        );
        let h = parse_header(std::path::Path::new("t.ply"), &mut head.as_bytes()).unwrap();
        let el = &h.elements[h.layout.vertex];
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let data: Vec<u8> = (0..300 * el.fixed_size().unwrap())
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 56) as u8
            })
            .collect();
        let packed = MappedVertices::<BE>::new(&data, el, &h.layout);
        let mut general = MappedVertices::<BE>::new(&data, el, &h.layout);
        general.packed = None;
        for i in 0..300 {
            let (a, b) = (packed.corner(i), general.corner(i));
            let bits = |c: super::Corner| {
                (
                    c.p.map(f32::to_bits),
                    c.n.map(f32::to_bits),
                    c.c,
                    c.uv.map(f32::to_bits),
                )
            };
            assert_eq!(bits(a), bits(b), "{props} vertex {i}");
            assert_eq!(
                packed.position(i).map(f32::to_bits),
                general.position(i).map(f32::to_bits)
            );
        }
        packed.packed.is_some()
    }

    #[test]
    fn packed_vertices_decode_as_the_general_reader() {
        let xyz = "property float x\nproperty float y\nproperty float z\n";
        let nrm = "property float nx\nproperty float ny\nproperty float nz\n";
        let rgb = "property uchar red\nproperty uchar green\nproperty uchar blue\n";
        let a = "property uchar alpha\n";
        for props in [
            xyz.to_string(),
            format!("{xyz}{rgb}"),
            format!("{xyz}{rgb}{a}"),
            format!("{xyz}{nrm}{rgb}{a}"),
            format!("property uchar flags\n{xyz}property short q\n{nrm}{rgb}"),
        ] {
            assert!(packed_equals_general::<false>(&props), "{props}");
            assert!(packed_equals_general::<true>(&props), "{props}");
        }
        // not the packed layout: the general decoding only
        for props in [
            "property double x\nproperty double y\nproperty double z\n".to_string(),
            "property float y\nproperty float x\nproperty float z\n".to_string(),
            format!("{xyz}property float red\nproperty float green\nproperty float blue\n"),
            format!("{xyz}property uchar red\nproperty uchar green\nproperty uchar q\nproperty uchar blue\n"),
            format!("{xyz}{rgb}property float alpha\n"),
            format!("{xyz}property float nx\nproperty float ny\nproperty double nz\n"),
        ] {
            assert!(!packed_equals_general::<false>(&props), "{props}");
        }
    }

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
