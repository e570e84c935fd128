//! Faces that carry per-face data (Chajdas, Reitinger & Westermann, "Scalable rendering for
//! very large meshes", WSCG 2014, section 3.1: per-face data such as material ids kept beside
//! the voxels): a `material` / `material_index` key, a face colour `red green blue [alpha]`,
//! and the MeshLab/OpenMVS `texcoord` list of two floats per corner.
//!
//! The properties may come in any order in a record, so each record is decoded whole (its
//! indices and texture coordinates into buffers kept across records) before its triangles
//! are fanned from corner 0, as the plain face reader does: the same triangles, each with the
//! record's material, colour and its corners' texture coordinates.

use crate::batch::{repeats, Sink};
use crate::ply_header::{Element, Kind};
use crate::ply_records::Records;
use crate::ply_vertices::{color_byte, gather, non_finite, VertexSource};
use crate::{IngestError, Location};
use std::path::Path;
use voxlod_geom::{TRI_HAS_COLORS, TRI_HAS_UV};

/// The face element being read and what its triangles get.
pub(crate) struct FaceRecords<'a, V> {
    pub path: &'a Path,
    pub el: &'a Element,
    /// The vertex index list property.
    pub list: usize,
    pub verts: &'a V,
    /// The flags every triangle gets (`TRI_HAS_UV` if the texture coordinates are used).
    pub flags: u32,
}

/// One record's decoded data.
#[derive(Default)]
struct Record {
    idx: Vec<usize>,
    uv: Vec<f32>,
    material: u32,
    color: Option<[u8; 4]>,
}

impl<V: VertexSource> FaceRecords<'_, V> {
    /// Streams the records `range` (`src` positioned at `range.start`) into `em`. With
    /// `only_triangles`, stops before the first record whose index list does not hold exactly
    /// 3 indices and returns its index (nothing of that record is emitted).
    pub fn stream<R: Records, S: Sink>(
        &self,
        src: &mut R,
        em: &mut S,
        range: std::ops::Range<u64>,
        only_triangles: bool,
    ) -> Result<Option<u64>, IngestError> {
        let mut r = Record::default();
        src.element(&self.el.name, self.el.count);
        for rec in range {
            src.begin(rec)?;
            let at = src.location();
            if !self.decode(src, rec, &mut r, only_triangles)? {
                return Ok(Some(rec));
            }
            src.end()?;
            em.polygon();
            self.emit(&r, rec, at.clone(), em)?;
            em.bytes_done(src.bytes_done());
        }
        Ok(None)
    }

    /// Reads record `rec`'s properties into `r`; false if `only_triangles` and it is not one.
    fn decode<R: Records>(
        &self,
        src: &mut R,
        rec: u64,
        r: &mut Record,
        only_triangles: bool,
    ) -> Result<bool, IngestError> {
        let d = &self.el.data;
        let nv = self.verts.count();
        r.idx.clear();
        r.uv.clear();
        r.material = 0;
        let mut color = [0u8, 0, 0, 255];
        for (pi, p) in self.el.props.iter().enumerate() {
            match p.kind {
                Kind::List { count, item } if pi == self.list => {
                    let k = src.list_count(count, item)?;
                    if only_triangles && k != 3 {
                        return Ok(false);
                    }
                    for j in 0..k {
                        let idx = src.int(item)?;
                        if idx < 0 || idx as u64 >= nv {
                            return Err(IngestError::IndexOutOfRange {
                                path: self.path.to_path_buf(),
                                at: src.location(),
                                face: rec,
                                corner: j,
                                index: idx,
                                vertices: nv,
                            });
                        }
                        r.idx.push(idx as usize);
                    }
                }
                Kind::List { count, item } if Some(pi) == d.texcoord => {
                    let k = src.list_count(count, item)?;
                    for _ in 0..k {
                        r.uv.push(src.f32(item)?);
                    }
                }
                Kind::Scalar(ty) if d.key.map(|k| k.0) == Some(pi) => {
                    r.material = d.material(src.int(ty)?);
                }
                Kind::Scalar(ty) => match d.color.iter().position(|c| c.map(|c| c.0) == Some(pi)) {
                    Some(ch) => color[ch] = color_byte(src.f64(ty)?, ty),
                    None => src.skip(p.kind)?,
                },
                kind => src.skip(kind)?,
            }
        }
        r.color = d.color[0].is_some().then_some(color);
        Ok(true)
    }

    /// The record's polygon fanned from corner 0, each triangle with the record's data.
    fn emit<S: Sink>(
        &self,
        r: &Record,
        rec: u64,
        at: Location,
        em: &mut S,
    ) -> Result<(), IngestError> {
        let uv_used = self.flags & TRI_HAS_UV != 0 && self.el.data.texcoord.is_some();
        if uv_used && r.uv.len() != 2 * r.idx.len() {
            return Err(IngestError::malformed(
                self.path,
                at,
                format!(
                    "face {rec} has {} corners but its texcoord list holds {} values, not {} (two per corner)",
                    r.idx.len(),
                    r.uv.len(),
                    2 * r.idx.len()
                ),
            ));
        }
        for j in 2..r.idx.len() {
            let corners = [0, j - 1, j];
            let tri = corners.map(|k| r.idx[k]);
            if repeats(tri) {
                em.repeated_index();
                continue;
            }
            let mut t = match gather(self.verts, tri, self.flags) {
                Ok(t) => t,
                Err((vi, p)) => return Err(non_finite(self.path, at, vi as u64, p)),
            };
            if let Some(c) = r.color {
                t.c = [c; 3];
                t.flags |= TRI_HAS_COLORS;
            }
            if uv_used {
                t.uv = corners.map(|k| [r.uv[2 * k], r.uv[2 * k + 1]]);
            }
            if r.material != 0 {
                t.set_material(r.material);
            }
            em.push(t)?;
        }
        Ok(())
    }
}
