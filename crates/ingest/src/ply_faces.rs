//! Turns PLY face and triangle-strip records into triangles: polygons are fan-triangulated
//! (corner 0 with each consecutive pair), strips alternate winding and restart at -1.
//! Indices are read one at a time and only the last two are kept, so a polygon or strip
//! of any length needs no buffer.

use crate::batch::Emitter;
use crate::ply_header::{Element, Kind, Scalar};
use crate::ply_records::Records;
use crate::ply_vertices::{non_finite, VertexSource};
use crate::IngestError;
use std::path::Path;
use voxlod_geom::{Triangle, DEFAULT_COLOR, TRI_HAS_COLORS, TRI_HAS_NORMALS};

/// Streams all records of element `el` (a `face` or `tristrips` element whose vertex index
/// list is property `list`) into `em`. `flags` are the triangle flags the vertices support.
#[allow(clippy::too_many_arguments)]
pub(crate) fn stream_faces<R: Records, V: VertexSource>(
    path: &Path,
    src: &mut R,
    el: &Element,
    list: usize,
    strips: bool,
    verts: &V,
    flags: u32,
    em: &mut Emitter,
) -> Result<(), IngestError> {
    debug_assert!(flags & !(TRI_HAS_COLORS | TRI_HAS_NORMALS) == 0);
    let nv = verts.count();
    src.element(&el.name, el.count);
    for rec in 0..el.count {
        src.begin(rec)?;
        for (pi, p) in el.props.iter().enumerate() {
            let (count, item) = match p.kind {
                Kind::List { count, item } if pi == list => (count, item),
                kind => {
                    src.skip(kind)?;
                    continue;
                }
            };
            let k = src.list_count(count, item)?;
            if !strips {
                em.stats.polygons += 1;
            }
            // the first two corners of the fan, or the last two of the strip
            let mut win = [0usize; 2];
            let mut n = 0u64;
            for j in 0..k {
                let idx = src.int(item)?;
                if strips && (idx < 0 || (item == Scalar::U32 && idx == u32::MAX as i64)) {
                    n = 0; // strip restart
                    continue;
                }
                if idx < 0 || idx as u64 >= nv {
                    return Err(IngestError::IndexOutOfRange {
                        path: path.to_path_buf(),
                        at: src.location(),
                        face: rec,
                        corner: j,
                        index: idx,
                        vertices: nv,
                    });
                }
                let idx = idx as usize;
                if n >= 2 {
                    let tri = if strips && (n - 2) % 2 == 1 {
                        [win[1], win[0], idx]
                    } else {
                        [win[0], win[1], idx]
                    };
                    emit(path, src, verts, tri, flags, em)?;
                }
                if strips {
                    win = [win[1], idx];
                } else {
                    win[(n as usize).min(1)] = idx;
                }
                n += 1;
            }
        }
        src.end()?;
        em.bytes_done = src.bytes_done();
    }
    Ok(())
}

#[inline]
fn emit<R: Records, V: VertexSource>(
    path: &Path,
    src: &R,
    verts: &V,
    tri: [usize; 3],
    flags: u32,
    em: &mut Emitter,
) -> Result<(), IngestError> {
    if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
        em.repeated_index();
        return Ok(());
    }
    // filled corner by corner: `array::map` here compiled to slow copies
    let mut t = Triangle {
        v: [[0.0; 3]; 3],
        n: [[0.0; 3]; 3],
        c: [DEFAULT_COLOR; 3],
        flags,
    };
    for (k, &vi) in tri.iter().enumerate() {
        let c = verts.corner(vi);
        if !(c.p[0].is_finite() && c.p[1].is_finite() && c.p[2].is_finite()) {
            return Err(non_finite(path, src.location(), vi as u64, c.p));
        }
        t.v[k] = c.p;
        t.n[k] = c.n;
        t.c[k] = c.c;
    }
    em.push(t)
}
