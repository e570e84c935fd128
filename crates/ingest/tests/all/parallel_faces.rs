//! The parallel decoding of memory-mapped binary triangle faces must be invisible: the same
//! triangles in the same order, the same counts and the same first error as reading one
//! record after another (a one-thread pool) and as the ASCII encoding of the same mesh.

use crate::common;

use common::{ply, El, TempDir, V};
use voxlod_geom::Triangle;
use voxlod_ingest::{IngestStats, MeshSource};

/// What is wrong with face `bad_at` of [`mesh`].
#[derive(Clone, Copy)]
pub(crate) enum Bad {
    /// an index past the last vertex
    OutOfRange,
    /// the index -1
    Negative,
    /// a corner whose vertex has a NaN coordinate
    NaN,
}

/// A mesh of `n` faces over a wavy grid: triangles, with an extra `uchar flags` property after
/// the list unless `plain` (then the faces are the usual `list uchar int` records alone, which
/// have their own decoding loop), degenerate ones (repeated index, collinear), a quad at
/// `quad_at` (breaks the uniform record size) and, if given, a bad face at `bad_at`.
pub(crate) fn mesh(
    n: usize,
    plain: bool,
    quad_at: Option<usize>,
    bad_at: Option<(usize, Bad)>,
) -> Vec<El> {
    let side = 400usize;
    let mut vrows = Vec::new();
    for y in 0..side {
        for x in 0..side {
            vrows.push(vec![
                V::S(x as f64),
                V::S(y as f64),
                V::S(((x * 13 + y * 7) % 11) as f64 * 0.25),
                V::S(((x + y) % 256) as f64),
            ]);
        }
    }
    let mut frows = Vec::new();
    for f in 0..n {
        let i = (f / 2) % ((side - 1) * (side - 1));
        let (x, y) = (i % (side - 1), i / (side - 1));
        let v = (y * side + x) as f64;
        let s = side as f64;
        let mut idx = if f % 2 == 0 {
            vec![v, v + 1.0, v + s]
        } else {
            vec![v + 1.0, v + s + 1.0, v + s]
        };
        if f % 997 == 5 {
            idx[2] = idx[0]; // repeated index
        }
        if f % 1009 == 7 {
            idx = vec![v, v + 1.0, v + 2.0]; // collinear along x: zero area unless z bends
        }
        if Some(f) == quad_at {
            idx = vec![v, v + 1.0, v + s + 1.0, v + s];
        }
        match bad_at {
            Some((at, Bad::OutOfRange)) if at == f => idx[1] = (side * side + 3) as f64,
            Some((at, Bad::Negative)) if at == f => idx[1] = -1.0,
            Some((at, Bad::NaN)) if at == f => vrows[idx[1] as usize][2] = V::S(f64::NAN),
            _ => {}
        }
        if plain {
            frows.push(vec![V::L(idx)]);
        } else {
            frows.push(vec![V::L(idx), V::S((f % 200) as f64)]);
        }
    }
    let face_props = if plain {
        vec!["list uchar int vertex_indices"]
    } else {
        vec!["list uchar int vertex_indices", "uchar flags"]
    };
    vec![
        El {
            name: "vertex",
            props: vec!["float x", "float y", "float z", "uchar red"],
            rows: vrows,
        },
        El {
            name: "face",
            props: face_props,
            rows: frows,
        },
    ]
}

fn read_with(
    threads: usize,
    path: &std::path::Path,
) -> Result<(Vec<Triangle>, IngestStats), String> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let src = MeshSource::open(path).map_err(|e| e.to_string())?;
        let mut tris = Vec::new();
        let st = src
            .stream(
                &mut |b| {
                    tris.extend_from_slice(b);
                    Ok(())
                },
                &mut |_, _| {},
            )
            .map_err(|e| e.to_string())?;
        Ok((tris, st))
    })
}

#[test]
fn parallel_equals_sequential_and_ascii() {
    let dir = TempDir::new("parallel");
    // several rounds of 16 Ki records per thread, a quad late in the file, none
    for (name, plain, quad) in [
        ("tris", false, None),
        ("quad", false, Some(61_234)),
        ("plain", true, None),
        ("plain_quad", true, Some(61_234)),
    ] {
        let els = mesh(100_000, plain, quad, None);
        let bin = dir.write(&format!("{name}.ply"), ply("binary_little_endian", &els));
        let be = dir.write(&format!("{name}_be.ply"), ply("binary_big_endian", &els));
        let ascii = dir.write(&format!("{name}_ascii.ply"), ply("ascii", &els));
        let (want, want_st) = read_with(1, &ascii).unwrap();
        assert!(want_st.degenerate_skipped > 100 && want_st.repeated_index > 50);
        assert_eq!(want_st.polygons, 100_000);
        assert_eq!(
            want.len() as u64,
            100_000 + quad.is_some() as u64 - want_st.degenerate_skipped
        );
        for path in [&bin, &be] {
            for threads in [1, 2, 3] {
                let (got, st) = read_with(threads, path).unwrap();
                assert_eq!(st, want_st, "{name} {threads} threads");
                assert!(got == want, "{name}, {threads} threads: triangles differ");
            }
        }
    }
}

#[test]
fn parallel_reports_the_first_error_as_sequential_does() {
    let dir = TempDir::new("parallel_err");
    // an out-of-range index in the second round, and one after a quad; in plain records also
    // a negative index and a NaN vertex
    const REF: &str = "refers to vertex";
    const NEG: &str = "refers to vertex -1";
    let cases = [
        ("late", false, None, (70_001, Bad::OutOfRange), REF),
        (
            "after_quad",
            false,
            Some(40_000),
            (40_010, Bad::OutOfRange),
            REF,
        ),
        ("plain_late", true, None, (70_001, Bad::OutOfRange), REF),
        ("plain_negative", true, None, (50_003, Bad::Negative), NEG),
        ("plain_nan", true, None, (33_333, Bad::NaN), "NaN"),
        (
            "plain_after_quad",
            true,
            Some(40_000),
            (40_010, Bad::Negative),
            NEG,
        ),
    ];
    for (name, plain, quad, bad, says) in cases {
        let els = mesh(100_000, plain, quad, Some(bad));
        let bin = dir.write(&format!("{name}.ply"), ply("binary_little_endian", &els));
        let seq = read_with(1, &bin).unwrap_err();
        assert!(seq.contains(says), "{name}: {seq}");
        if !matches!(bad.1, Bad::NaN) {
            assert!(seq.contains(&format!("face {}", bad.0)), "{name}: {seq}");
        }
        for threads in [2, 3] {
            assert_eq!(
                read_with(threads, &bin).unwrap_err(),
                seq,
                "{name} {threads}"
            );
        }
    }
    // truncated inside the face list: the same truncation message
    for (plain, rec) in [(false, 14), (true, 13)] {
        let els = mesh(100_000, plain, None, None);
        let mut data = ply("binary_little_endian", &els);
        data.truncate(data.len() - 3 * rec - 5);
        let cut = dir.write("cut.ply", &data);
        let seq = read_with(1, &cut).unwrap_err();
        assert!(seq.contains("truncated"), "{seq}");
        for threads in [2, 3] {
            assert_eq!(read_with(threads, &cut).unwrap_err(), seq);
        }
    }
}

/// `stream_prepared`: the callback gets each batch as `prepare` changed it, with what `prepare`
/// returned for it, in the order of `stream`. With several threads on a binary input, `prepare`
/// runs in parallel with the callback: while the callback holds the first batch, the next
/// round's batches are prepared (on the worker that decodes them). An input read sequentially
/// (ASCII) is prepared on the calling thread.
#[test]
fn prepare_runs_where_the_batch_was_decoded() {
    use std::sync::atomic::{AtomicUsize, Ordering::SeqCst};
    let dir = TempDir::new("prepared");
    let els = mesh(100_000, true, Some(81_000), None);
    let bin = dir.write("p.ply", ply("binary_little_endian", &els));
    let ascii = dir.write("p_ascii.ply", ply("ascii", &els));
    let (want, want_st) = read_with(1, &ascii).unwrap();
    let moved: Vec<Triangle> = want
        .iter()
        .map(|t| {
            let mut t = *t;
            t.v[0][0] += 1000.0;
            t
        })
        .collect();
    for (path, threads) in [(&bin, 1), (&bin, 2), (&bin, 3), (&ascii, 2)] {
        let parallel = threads > 1 && path == &bin;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let prepares = AtomicUsize::new(0);
        let (got, st) = pool.install(|| {
            let src = MeshSource::open(path).unwrap();
            let mut got: Vec<Triangle> = Vec::new();
            let prepare = |tris: &mut [Triangle]| {
                prepares.fetch_add(1, SeqCst);
                for t in tris.iter_mut() {
                    t.v[0][0] += 1000.0;
                }
                (tris.len(), tris[0])
            };
            let st = src
                .stream_prepared(
                    &prepare,
                    &mut |tris, (n, first)| {
                        assert_eq!((n, first), (tris.len(), tris[0]));
                        if parallel && got.is_empty() {
                            // hold the first batch until another batch is prepared meanwhile
                            let at = prepares.load(SeqCst);
                            let t = std::time::Instant::now();
                            while prepares.load(SeqCst) == at {
                                assert!(
                                    t.elapsed().as_secs() < 20,
                                    "{threads} threads: nothing prepared while the callback ran"
                                );
                                std::thread::sleep(std::time::Duration::from_millis(1));
                            }
                        }
                        got.extend_from_slice(tris);
                        Ok(())
                    },
                    &mut |_, _| {},
                )
                .unwrap();
            (got, st)
        });
        assert_eq!(st, want_st);
        assert!(
            got == moved,
            "{path:?}, {threads} threads: triangles differ"
        );
    }
}
