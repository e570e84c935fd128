//! Triangles by face record (`MeshSource::stream_indexed_prepared`, `MeshSource::triangles_at`:
//! the bins of face indices of a build): the indexed stream gives exactly the triangles and
//! counts of the plain stream, each with the record it came from (checked against the mesh's
//! own construction), and `triangles_at` rebuilds the same triangles bit for bit from those
//! records (plain and general records, per-face colours, both byte orders, one and several
//! threads). Inputs whose faces cannot be found by index have no `fixed_face_count`, and
//! records that turn out not to be triangle records stop the indexed stream with a typed error.

use crate::common;
use crate::parallel_faces::mesh;

use common::{ply, TempDir, V};
use voxlod_geom::Triangle;
use voxlod_ingest::{IngestError, IngestStats, MeshSource};

/// The plain stream's triangles and counts (the reference), on one thread.
fn stream(src: &MeshSource) -> (Vec<Triangle>, IngestStats) {
    let mut tris = Vec::new();
    let st = src
        .stream(
            &mut |b| {
                tris.extend_from_slice(b);
                Ok(())
            },
            &mut |_, _| {},
        )
        .unwrap();
    (tris, st)
}

/// The indexed stream on `threads`: triangles, their face records, counts.
fn indexed(
    src: &MeshSource,
    threads: usize,
) -> Result<(Vec<Triangle>, Vec<u64>, IngestStats), IngestError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let (mut tris, mut faces) = (Vec::new(), Vec::new());
        let st = src.stream_indexed_prepared(
            &|b| b.len(),
            &mut |b, f, n| {
                assert_eq!(n, b.len(), "prepare ran on this batch");
                tris.extend_from_slice(b);
                faces.extend_from_slice(f);
                Ok(())
            },
            &mut |_, _| {},
        )?;
        Ok((tris, faces, st))
    })
}

/// The corners of face `f` of [`mesh`] as built there (side 400; vertex `(x, y, z)`), for a
/// face that is not a repeated-index or quad record: an independent reference of which
/// record a triangle came from.
fn corners_of(f: u64) -> [[f32; 3]; 3] {
    let side = 400usize;
    let f = f as usize;
    let i = (f / 2) % ((side - 1) * (side - 1));
    let (x, y) = (i % (side - 1), i / (side - 1));
    let v = y * side + x;
    let idx = if f % 1009 == 7 {
        [v, v + 1, v + 2] // along x, not flat where z bends
    } else if f % 2 == 0 {
        [v, v + 1, v + side]
    } else {
        [v + 1, v + side + 1, v + side]
    };
    idx.map(|id| {
        let (x, y) = (id % side, id / side);
        [x as f32, y as f32, ((x * 13 + y * 7) % 11) as f32 * 0.25]
    })
}

#[test]
fn indexed_stream_and_triangles_at_give_the_streams_triangles() {
    let dir = TempDir::new("by_index");
    for kind in ["plain", "general", "face_colors"] {
        let mut els = mesh(30_000, kind == "plain", None, None);
        if kind == "face_colors" {
            // per-face colours: the records are decoded whole (ply_face_data.rs)
            els[1].props = vec![
                "list uchar int vertex_indices",
                "uchar red",
                "uchar green",
                "uchar blue",
            ];
            for (f, row) in els[1].rows.iter_mut().enumerate() {
                row.truncate(1);
                row.extend([
                    V::S((f % 256) as f64),
                    V::S(7.0),
                    V::S((f / 256 % 256) as f64),
                ]);
            }
        }
        for enc in ["binary_little_endian", "binary_big_endian"] {
            let path = dir.write(&format!("{kind}_{enc}.ply"), ply(enc, &els));
            let src = MeshSource::open(&path).unwrap();
            assert_eq!(src.fixed_face_count(), Some(30_000), "{kind} {enc}");
            let (want, want_st) = stream(&src);
            assert!(
                want_st.degenerate_skipped > 20,
                "degenerate faces in the test"
            );
            for threads in [1, 3] {
                let what = format!("{kind} {enc}, {threads} threads");
                let (tris, faces, st) = indexed(&src, threads).unwrap();
                assert_eq!(st, want_st, "{what}");
                assert!(tris == want, "{what}: other triangles than the stream's");
                assert_eq!(faces.len(), tris.len(), "{what}");
                assert!(faces.windows(2).all(|w| w[0] < w[1]), "{what}: file order");
                for (t, &f) in tris.iter().zip(&faces) {
                    assert_eq!(t.v, corners_of(f), "{what}: face {f}");
                    if kind == "face_colors" {
                        assert_eq!(t.c[0][0], (f % 256) as u8, "{what}: face {f}'s colour");
                    }
                }
                // rebuilt from the records, in any order and grouping: bit for bit the same
                let mut again = Vec::new();
                for part in faces.chunks(777) {
                    src.triangles_at(part, &mut again).unwrap();
                }
                assert_eq!(again.len(), tris.len());
                assert!(
                    again
                        .iter()
                        .zip(&tris)
                        .all(|(a, b)| bytemuck::bytes_of(a) == bytemuck::bytes_of(b)),
                    "{what}: triangles_at differs from the stream"
                );
                let picked: Vec<u64> = faces.iter().rev().step_by(97).copied().collect();
                let mut some = Vec::new();
                src.triangles_at(&picked, &mut some).unwrap();
                let k = faces.len() - 1;
                for (j, t) in some.iter().enumerate() {
                    assert!(*t == tris[k - 97 * j], "{what}: picked face {}", picked[j]);
                }
            }
            // a record with no triangle (repeated index, face 5) or past the end: refused
            for f in [5u64, 30_000] {
                let e = src.triangles_at(&[0, f], &mut Vec::new()).unwrap_err();
                assert!(
                    matches!(e, IngestError::FaceChanged { face, .. } if face == f),
                    "{kind} {enc} face {f}: {e}"
                );
                assert!(e.to_string().contains(&*path.to_string_lossy()), "{e}");
            }
        }
    }
}

/// Only a binary PLY whose faces are triangle records of one size, filling the file, can be
/// read by index; a record that is not a triangle record where the sizes still add up stops
/// the indexed stream with `NotFixedRecords` (the build then bins blocks).
#[test]
fn inputs_whose_faces_cannot_be_found_by_index() {
    let dir = TempDir::new("by_index_none");
    let quad = dir.write(
        "quad.ply",
        ply("binary_little_endian", &mesh(1000, true, Some(10), None)),
    );
    assert_eq!(MeshSource::open(&quad).unwrap().fixed_face_count(), None);
    let ascii = dir.write("a.ply", ply("ascii", &mesh(1000, true, None, None)));
    assert_eq!(MeshSource::open(&ascii).unwrap().fixed_face_count(), None);
    let mut data = ply("binary_little_endian", &mesh(1000, true, None, None));
    data.extend_from_slice(&[0; 13]);
    let trailing = dir.write("t.ply", data);
    assert_eq!(
        MeshSource::open(&trailing).unwrap().fixed_face_count(),
        None
    );
    // a quad (4 bytes longer) and a two-corner record (4 bytes shorter): the length fits
    let mut els = mesh(100_000, true, Some(50_000), None);
    els[1].rows[60_000] = vec![V::L(vec![0.0, 1.0])];
    let odd = dir.write("odd.ply", ply("binary_little_endian", &els));
    let src = MeshSource::open(&odd).unwrap();
    assert_eq!(src.fixed_face_count(), Some(100_000));
    for threads in [1, 3] {
        match indexed(&src, threads) {
            Err(IngestError::NotFixedRecords { face, .. }) => assert_eq!(face, 50_000),
            Err(e) => panic!("{threads} threads: {e}"),
            Ok(_) => panic!("{threads} threads: a quad read by index"),
        }
    }
    // the plain stream reads it (sequentially from the quad on)
    let (tris, st) = stream(&src);
    assert_eq!(st.polygons, 100_000);
    assert!(tris.len() > 99_000);
}
