//! Turns PLY face and triangle-strip records into triangles: polygons are fan-triangulated
//! (corner 0 with each consecutive pair), strips alternate winding and restart at -1.
//! Indices are read one at a time and only the last two are kept, so a polygon or strip
//! of any length needs no buffer.

use crate::batch::{repeats, Emitter, LocalBatch, Sink};
use crate::ply_face_data::FaceRecords;
use crate::ply_header::{Element, Kind, Scalar};
use crate::ply_records::{Records, SliceRecords};
use crate::ply_vertices::{gather, non_finite, VertexSource};
use crate::IngestError;
use std::path::Path;
use voxlod_geom::{TRI_HAS_COLORS, TRI_HAS_NORMALS, TRI_HAS_UV};

/// Face records per worker and round of [`stream_triangles_parallel`]. A round is cut into
/// [`PARTS_PER_THREAD`] parts per worker, each handed on as one batch, so a share must not
/// exceed the batch size the callers are promised.
const PARALLEL_RECORDS: u64 = 16 * 1024;
/// Parts a round is cut into per thread (each part is one batch for the caller).
const PARTS_PER_THREAD: u64 = 4;
const _: () = assert!(PARALLEL_RECORDS as usize <= crate::batch::BATCH);

/// Bytes of one record of a `face` element if it holds a triangle: every property a scalar
/// except the index list, whose count is 3. `None` if another property is a list.
pub(crate) fn triangle_record_bytes(el: &Element, list: usize) -> Option<usize> {
    let mut n = 0;
    for (pi, p) in el.props.iter().enumerate() {
        n += match p.kind {
            Kind::Scalar(s) => s.size(),
            Kind::List { count, item } if pi == list => count.size() + 3 * item.size(),
            Kind::List { .. } => return None,
        };
    }
    Some(n)
}

/// Streams a memory-mapped binary `face` element (not strips) starting at byte `off` of
/// `data`, decoding in parallel on the current rayon pool while every record is a triangle
/// (so that record `r` starts at `off + r · size`): rounds of [`PARALLEL_RECORDS`] records per
/// thread, in [`PARTS_PER_THREAD`] parts per thread, are decoded into [`LocalBatch`]es, prepared (`em.prepare`) on the same thread, and
/// handed to `em` in record order, so the triangles, counts and the first error are those of
/// the sequential reader. At the first record that is not a triangle, the rest is read
/// sequentially. Only the records `records` are read: all of them, or (for a part of the
/// input) a range, which needs triangle records of one size.
///
/// With `indexed` (bins of face indices), each batch carries the face record of each of its
/// triangles ([`LocalBatch::faces`]); that needs every record in `records` to be a triangle
/// record at its fixed offset, so the rounds run on one thread too, and a record that is not
/// a triangle stops the stream with [`IngestError::NotFixedRecords`] instead of a sequential
/// read (whose triangles would carry no record).
pub(crate) fn stream_triangles_parallel<const BE: bool, V: VertexSource + Sync>(
    faces: &FaceRecords<V>,
    data: &[u8],
    off: usize,
    records: std::ops::Range<u64>,
    indexed: bool,
    em: &mut Emitter,
) -> Result<(), IngestError> {
    use rayon::prelude::*;
    let (path, el, list, verts, flags) =
        (faces.path, faces.el, faces.list, faces.verts, faces.flags);
    let prepare = em.prepare;
    // the sequential reader from record `first`, which starts at byte `at`
    let sequential = |first: u64, at: usize, em: &mut Emitter| {
        let mut src = SliceRecords::<BE>::new(path, data, at);
        stream_faces(faces, false, &mut src, em, first..records.end, false).map(drop)
    };
    let threads = rayon::current_num_threads() as u64;
    let not_fixed = |rec: u64| IngestError::NotFixedRecords {
        path: path.to_path_buf(),
        face: rec,
    };
    let Some(size) = triangle_record_bytes(el, list).map(|s| s as u64) else {
        assert!(
            records.start == 0 && !indexed,
            "a part of the faces or their indices need triangle records of one size"
        );
        return sequential(0, off, em);
    };
    let at = |rec: u64| off + (rec * size) as usize;
    if threads <= 1 && !indexed {
        return sequential(records.start, at(records.start), em);
    }
    // `property list uchar int|uint vertex_indices` and nothing else: what nearly every writer
    // produces, decoded by `plain_triangles`
    let plain = plain_item(el, list);
    // records that fit in the file at the uniform size (the rest, if any, is read sequentially
    // and reports the truncation as the sequential reader does)
    let fit = ((data.len() - off) as u64 / size).min(records.end);
    // one round: records [rec, rec + n) split between the threads, decoded in parallel
    type Round = Vec<(u64, Result<(LocalBatch, Option<u64>), IngestError>)>;
    let round_len = |rec: u64| (PARALLEL_RECORDS * threads).min(fit - rec);
    let decode = |rec: u64| -> Round {
        let n = round_len(rec);
        // more parts than threads, so that a thread left idle while another runs the caller's
        // callback decodes the parts that one would have taken (work stealing balances them)
        let k = threads * PARTS_PER_THREAD;
        let parts: Vec<(u64, u64)> = (0..k)
            .map(|t| (rec + n * t / k, rec + n * (t + 1) / k))
            .filter(|(a, b)| a < b)
            .collect();
        parts
            .par_iter()
            .map(|&(a, b)| {
                let mut lb = LocalBatch {
                    tris: Vec::with_capacity((b - a) as usize),
                    faces: indexed.then(|| Vec::with_capacity((b - a) as usize)),
                    first: a,
                    ..Default::default()
                };
                // the usual record in its own loop; from the first record it cannot take on,
                // the general reader, which then gives the same triangles, counts and errors
                let from = match plain {
                    Some(item) => {
                        let n = (b - a) as usize * PLAIN_RECORD;
                        let recs = &data[at(a)..at(a) + n];
                        plain_triangles::<BE, V>(recs, a, item, verts, flags, &mut lb)
                    }
                    None => a,
                };
                let r = if from < b {
                    let mut src = SliceRecords::<BE>::new(path, data, at(from));
                    stream_faces(faces, false, &mut src, &mut lb, from..b, true)
                } else {
                    Ok(None)
                };
                // the caller's prepare step here, on the worker, for a part that is complete
                if let Ok(None) = r {
                    if !lb.tris.is_empty() {
                        lb.prepared = Some(prepare(&mut lb.tris));
                    }
                }
                (a, r.map(|stop| (lb, stop)))
            })
            .collect()
    };
    // Pipelined: while the triangles of round k go to `em` on this thread (the caller's
    // callback, which need not be thread-safe), round k+1 is decoded on the pool. The order
    // of triangles, counts and the first error is unchanged.
    let mut rec = records.start;
    let mut current = (fit > rec).then(|| decode(rec));
    while let Some(results) = current.take() {
        let n = round_len(rec);
        let next_rec = rec + n;
        let mut next: Option<Round> = None;
        let handed: Result<Option<u64>, IngestError> = rayon::in_place_scope(|sc| {
            if next_rec < fit {
                let next = &mut next;
                let decode = &decode;
                sc.spawn(move |_| *next = Some(decode(next_rec)));
            }
            for (a, r) in results {
                match r {
                    Ok((lb, None)) => em.push_local(lb)?,
                    // a record that is not a triangle: the offsets from `a` on are unknown
                    Ok((_, Some(r))) if indexed => return Err(not_fixed(r)),
                    Ok((_, Some(_))) => return Ok(Some(a)),
                    Err(e) => return Err(e),
                }
            }
            Ok(None)
        });
        if let Some(a) = handed? {
            return sequential(a, at(a), em);
        }
        rec = next_rec;
        em.bytes_done = at(rec) as u64;
        current = next;
    }
    if rec < records.end {
        if indexed {
            return Err(not_fixed(rec));
        }
        return sequential(rec, at(rec), em);
    }
    Ok(())
}

/// Decodes face record `rec` (at its fixed offset `off + rec · size`, a triangle record)
/// into `lb` exactly as [`stream_triangles_parallel`] does (the plain loop for plain records,
/// else the general reader), so the triangle it gives is bit for bit the one the stream gave.
/// Returns false if the record is not a triangle record; an error as the stream reports it.
pub(crate) fn triangle_record<const BE: bool, V: VertexSource>(
    faces: &FaceRecords<V>,
    data: &[u8],
    off: usize,
    size: usize,
    plain: Option<Scalar>,
    rec: u64,
    lb: &mut LocalBatch,
) -> Result<bool, IngestError> {
    let at = off + rec as usize * size;
    if let Some(item) = plain {
        let recs = &data[at..at + PLAIN_RECORD];
        if plain_triangles::<BE, V>(recs, rec, item, faces.verts, faces.flags, lb) > rec {
            return Ok(true);
        }
    }
    let mut src = SliceRecords::<BE>::new(faces.path, data, at);
    Ok(stream_faces(faces, false, &mut src, lb, rec..rec + 1, true)?.is_none())
}

/// The item type of a plain triangle record (`property list uchar int|uint vertex_indices`
/// and nothing else: [`PLAIN_RECORD`] bytes, decoded by `plain_triangles`), if `el`'s records
/// are that.
pub(crate) fn plain_item(el: &Element, list: usize) -> Option<Scalar> {
    match (el.props.len(), el.props[list].kind) {
        (
            1,
            Kind::List {
                count: Scalar::U8 | Scalar::I8,
                item: item @ (Scalar::I32 | Scalar::U32),
            },
        ) => Some(item),
        _ => None,
    }
}

/// Bytes of a plain triangle record: the count 3 and three 32-bit indices.
const PLAIN_RECORD: usize = 13;

/// Decodes plain triangle records (`recs`, [`PLAIN_RECORD`] bytes each, the first being record
/// `first`) into `lb` as [`stream_faces`] would, without its per-property dispatch. Stops at the
/// first record it does not take on (a count other than 3, an index out of range, a vertex
/// that is not finite) and returns its index, for the general reader to continue there with
/// the same results and errors; returns the index after the last record if it took all.
fn plain_triangles<const BE: bool, V: VertexSource>(
    recs: &[u8],
    first: u64,
    item: Scalar,
    verts: &V,
    flags: u32,
    lb: &mut LocalBatch,
) -> u64 {
    debug_assert!(recs.len() % PLAIN_RECORD == 0);
    let nv = verts.count();
    let index = |b: &[u8]| -> u64 {
        let a = [b[0], b[1], b[2], b[3]];
        let v = if BE {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        };
        // a negative int reads as ≥ 2³¹, which is never below `nv` for an int index
        if item == Scalar::I32 && v > i32::MAX as u32 {
            u64::MAX
        } else {
            v as u64
        }
    };
    for (r, rec) in recs.chunks_exact(PLAIN_RECORD).enumerate() {
        let i = [index(&rec[1..5]), index(&rec[5..9]), index(&rec[9..13])];
        if rec[0] != 3 || i.iter().any(|&i| i >= nv) {
            return first + r as u64;
        }
        lb.polygon();
        let tri = i.map(|i| i as usize);
        if repeats(tri) {
            lb.repeated_index();
            continue;
        }
        match gather(verts, tri, flags) {
            Ok(t) => lb.add(t),
            Err(_) => return first + r as u64,
        }
    }
    first + (recs.len() / PLAIN_RECORD) as u64
}

/// Streams the records `range` of `faces` (a `face` element, or with `strips` a `tristrips`
/// element; `src` positioned at record `range.start`) into `em`. `faces.flags` are the
/// triangle flags the vertices support. With `only_triangles`, stops before the first record
/// whose list does not hold exactly 3 indices and returns its index.
pub(crate) fn stream_faces<R: Records, V: VertexSource, S: Sink>(
    faces: &FaceRecords<V>,
    strips: bool,
    src: &mut R,
    em: &mut S,
    range: std::ops::Range<u64>,
    only_triangles: bool,
) -> Result<Option<u64>, IngestError> {
    let (path, el, list, verts, flags) =
        (faces.path, faces.el, faces.list, faces.verts, faces.flags);
    debug_assert!(flags & (TRI_HAS_UV - 1) & !(TRI_HAS_COLORS | TRI_HAS_NORMALS) == 0);
    if el.data.any() && !strips {
        // per-face material, colour or texture coordinates: whole records (ply_face_data.rs)
        return faces.stream(src, em, range, only_triangles);
    }
    let nv = verts.count();
    src.element(&el.name, el.count);
    for rec in range {
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
            if only_triangles && k != 3 {
                return Ok(Some(rec));
            }
            if !strips {
                em.polygon();
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
        em.bytes_done(src.bytes_done());
    }
    Ok(None)
}

#[inline]
fn emit<R: Records, V: VertexSource, S: Sink>(
    path: &Path,
    src: &R,
    verts: &V,
    tri: [usize; 3],
    flags: u32,
    em: &mut S,
) -> Result<(), IngestError> {
    if repeats(tri) {
        em.repeated_index();
        return Ok(());
    }
    match gather(verts, tri, flags) {
        Ok(t) => em.push(t),
        Err((vi, p)) => Err(non_finite(path, src.location(), vi as u64, p)),
    }
}
