//! Small made-up PLY files in every encoding, with extra elements and properties, colours,
//! normals, polygons and strips, compared exactly with triangles the test builds itself.

use crate::common;
use common::*;
use voxlod_geom::{Triangle, DEFAULT_COLOR, TRI_HAS_COLORS, TRI_HAS_NORMALS};
use voxlod_ingest::{IngestError, MeshSource, BATCH};

const P: [[f32; 3]; 7] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.5, 0.5, 1.0],
    [2.0, 0.0, 0.0],
    [4.0, 0.0, 0.0], // 1, 5, 6 are collinear
];
const N: [[f32; 3]; 7] = [
    [0.0, 0.0, 1.0],
    [0.0, 0.5, 1.0],
    [0.25, 0.0, -1.0],
    [1.0, 0.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.5, 0.5, 0.5],
    [-1.0, 0.0, 0.0],
];
const C: [[u8; 4]; 7] = [
    [255, 0, 0, 255],
    [0, 255, 0, 255],
    [0, 0, 255, 255],
    [10, 20, 30, 255],
    [200, 100, 50, 255],
    [1, 2, 3, 255],
    [7, 8, 9, 255],
];

/// quad, triangle, pentagon, repeated index, collinear, a 2-gon (no triangle)
fn faces() -> Vec<Vec<usize>> {
    vec![
        vec![0, 1, 2, 3],
        vec![0, 1, 4],
        vec![1, 2, 4, 3, 0],
        vec![2, 2, 3],
        vec![1, 5, 6],
        vec![3, 4],
    ]
}

fn zero_area(t: &[[f32; 3]; 3]) -> bool {
    let d = |a: [f32; 3], b: [f32; 3]| {
        [
            b[0] as f64 - a[0] as f64,
            b[1] as f64 - a[1] as f64,
            b[2] as f64 - a[2] as f64,
        ]
    };
    let (u, v) = (d(t[0], t[1]), d(t[0], t[2]));
    let c = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    c == [0.0; 3]
}

/// Independent fan triangulation of `faces` (and strips), attributes attached.
fn expected(
    tris_idx: &[[usize; 3]],
    normals: bool,
    colors: bool,
    colors_of: &[[u8; 4]],
) -> (Vec<Triangle>, u64, u64) {
    let mut out = Vec::new();
    let (mut repeated, mut degenerate) = (0, 0);
    for t in tris_idx {
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            repeated += 1;
            continue;
        }
        let v = [P[t[0]], P[t[1]], P[t[2]]];
        if zero_area(&v) {
            degenerate += 1;
            continue;
        }
        out.push(Triangle {
            v,
            n: if normals {
                [N[t[0]], N[t[1]], N[t[2]]]
            } else {
                [[0.0; 3]; 3]
            },
            c: if colors {
                [colors_of[t[0]], colors_of[t[1]], colors_of[t[2]]]
            } else {
                [DEFAULT_COLOR; 3]
            },
            flags: if normals { TRI_HAS_NORMALS } else { 0 }
                | if colors { TRI_HAS_COLORS } else { 0 },
            uv: [[0.0; 2]; 3],
        });
    }
    (out, repeated, degenerate)
}

fn fan(faces: &[Vec<usize>]) -> Vec<[usize; 3]> {
    let mut t = Vec::new();
    for f in faces {
        for j in 1..f.len().saturating_sub(1) {
            t.push([f[0], f[j], f[j + 1]]);
        }
    }
    t
}

fn face_rows(with_extra: bool) -> Vec<Vec<V>> {
    faces()
        .into_iter()
        .enumerate()
        .map(|(i, f)| {
            let mut r = vec![V::L(f.iter().map(|&x| x as f64).collect())];
            if with_extra {
                r.extend([V::S(-(i as f64)), V::S(0.25 * i as f64), V::S(i as f64)]);
            }
            r
        })
        .collect()
}

/// Variant A: camera element first, uchar colours, extra vertex and face properties.
fn variant_a() -> Vec<El> {
    let camera = El {
        name: "camera",
        props: vec!["float view_px", "int viewportx", "double k1"],
        rows: vec![vec![V::S(1.5), V::S(640.0), V::S(0.125)]],
    };
    let vertex = El {
        name: "vertex",
        props: vec![
            "float x",
            "float y",
            "float z",
            "float confidence",
            "float nx",
            "float ny",
            "float nz",
            "uchar red",
            "uchar green",
            "uchar blue",
            "int flags",
        ],
        rows: (0..7)
            .map(|i| {
                let mut r: Vec<V> = P[i].iter().map(|&x| V::S(x as f64)).collect();
                r.push(V::S(0.75));
                r.extend(N[i].iter().map(|&x| V::S(x as f64)));
                r.extend(C[i][..3].iter().map(|&x| V::S(x as f64)));
                r.push(V::S(-3.0));
                r
            })
            .collect(),
    };
    let face = El {
        name: "face",
        props: vec![
            "list uchar int vertex_indices",
            "int flags",
            "float quality",
            // not `material`, which is per-face data now (tests/ply_face_data.rs)
            "uchar label",
        ],
        rows: face_rows(true),
    };
    vec![camera, vertex, face]
}

/// Variant B: double positions with type aliases, float colours with alpha, a list property
/// in the vertex (so binary vertices cannot be read in place), `list int uint vertex_index`,
/// and the face element *before* the vertex element.
fn variant_b(colors: &[[u8; 4]]) -> Vec<El> {
    let vertex = El {
        name: "vertex",
        props: vec![
            "float64 x",
            "list uint8 int16 extra",
            "float64 y",
            "float64 z",
            "float32 red",
            "float32 green",
            "float32 blue",
            "float32 alpha",
            "int8 tag",
        ],
        rows: (0..7)
            .map(|i| {
                let c = colors[i].map(|x| V::S(x as f64 / 255.0));
                vec![
                    V::S(P[i][0] as f64),
                    V::L(vec![-1.0; i % 3]),
                    V::S(P[i][1] as f64),
                    V::S(P[i][2] as f64),
                    c[0].clone(),
                    c[1].clone(),
                    c[2].clone(),
                    c[3].clone(),
                    V::S(-5.0),
                ]
            })
            .collect(),
    };
    let face = El {
        name: "face",
        props: vec!["list int uint vertex_index"],
        rows: face_rows(false),
    };
    vec![face, vertex]
}

const ENCODINGS: [(&str, bool); 6] = [
    ("ascii", false),
    ("binary_little_endian", false),
    ("binary_big_endian", false),
    ("ascii", true),
    ("binary_little_endian", true),
    ("binary_big_endian", true),
];

fn write_ply(dir: &TempDir, name: &str, enc: &str, gz: bool, els: &[El]) -> std::path::PathBuf {
    let data = ply(enc, els);
    if gz {
        dir.write(&format!("{name}-{enc}.ply.gz"), gzip(&data))
    } else {
        dir.write(&format!("{name}-{enc}.ply"), data)
    }
}

#[test]
fn variant_a_every_encoding() {
    let dir = TempDir::new("a");
    let (want, repeated, degenerate) = expected(&fan(&faces()), true, true, &C);
    assert_eq!(want.len(), 6);
    for (enc, gz) in ENCODINGS {
        let path = write_ply(&dir, "a", enc, gz, &variant_a());
        let src = MeshSource::open(&path).unwrap();
        let info = src.info();
        assert_eq!(
            info.format,
            format!("ply {enc}{}", if gz { " (gzip)" } else { "" })
        );
        assert_eq!(
            (info.vertices, info.faces, info.has_normals, info.has_colors),
            (7, 6, true, true)
        );
        let (got, st) = read(&path).unwrap();
        assert_eq!(got, want, "{enc} gz={gz}");
        assert_eq!(
            (st.triangles, st.polygons, st.repeated_index),
            (6, 6, repeated)
        );
        assert_eq!(st.degenerate_skipped, repeated + degenerate);
    }
}

#[test]
fn variant_b_faces_first_float_colours_every_encoding() {
    let dir = TempDir::new("b");
    let mut colors = C;
    for (i, c) in colors.iter_mut().enumerate() {
        c[3] = 40 * i as u8; // alpha given
    }
    let (want, _, _) = expected(&fan(&faces()), false, true, &colors);
    for (enc, gz) in ENCODINGS {
        let path = write_ply(&dir, "b", enc, gz, &variant_b(&colors));
        let (got, st) = read(&path).unwrap();
        assert_eq!(got, want, "{enc} gz={gz}");
        assert_eq!(st.polygons, 6);
    }
}

#[test]
fn triangle_strips_with_restarts() {
    let dir = TempDir::new("strips");
    let vertex = El {
        name: "vertex",
        props: vec!["float x", "float y", "float z"],
        rows: P
            .iter()
            .map(|p| p.iter().map(|&x| V::S(x as f64)).collect())
            .collect(),
    };
    // strip 0 1 2 3 gives (0,1,2), (2,1,3); restart; 4 0 1 2 gives (4,0,1), (1,0,2)
    let strips = El {
        name: "tristrips",
        props: vec!["list int int vertex_indices"],
        rows: vec![vec![V::L(vec![0., 1., 2., 3., -1., 4., 0., 1., 2.])]],
    };
    let (want, _, _) = expected(
        &[[0, 1, 2], [2, 1, 3], [4, 0, 1], [1, 0, 2]],
        false,
        false,
        &C,
    );
    assert_eq!(want.len(), 4);
    for (enc, gz) in ENCODINGS {
        let path = write_ply(
            &dir,
            "s",
            enc,
            gz,
            &[vertex_clone(&vertex), strips_clone(&strips)],
        );
        let (got, st) = read(&path).unwrap();
        assert_eq!(got, want, "{enc} gz={gz}");
        assert_eq!(st.polygons, 0);
    }
}

fn vertex_clone(e: &El) -> El {
    El {
        name: e.name,
        props: e.props.clone(),
        rows: e.rows.clone(),
    }
}
fn strips_clone(e: &El) -> El {
    vertex_clone(e)
}

/// A grid of `n × n` quads in binary LE: more than one batch.
fn grid(n: usize) -> Vec<El> {
    let mut vrows = Vec::new();
    for y in 0..=n {
        for x in 0..=n {
            vrows.push(vec![
                V::S(x as f64),
                V::S(y as f64),
                V::S(((x * 7 + y * 3) % 5) as f64),
            ]);
        }
    }
    let mut frows = Vec::new();
    for y in 0..n {
        for x in 0..n {
            let i = (y * (n + 1) + x) as f64;
            frows.push(vec![V::L(vec![
                i,
                i + 1.0,
                i + n as f64 + 2.0,
                i + n as f64 + 1.0,
            ])]);
        }
    }
    vec![
        El {
            name: "vertex",
            props: vec!["float x", "float y", "float z"],
            rows: vrows,
        },
        El {
            name: "face",
            props: vec!["list uchar uint vertex_indices"],
            rows: frows,
        },
    ]
}

#[test]
fn batches_and_callback_errors() {
    let dir = TempDir::new("grid");
    let path = dir.write("grid.ply", ply("binary_little_endian", &grid(200)));
    let src = MeshSource::open(&path).unwrap();
    let mut sizes = Vec::new();
    let st = src
        .stream(
            &mut |b| {
                sizes.push(b.len());
                Ok(())
            },
            &mut |_, _| {},
        )
        .unwrap();
    assert_eq!(st.triangles, 80_000);
    // batches of up to BATCH triangles (the parallel reader hands on each worker's share)
    assert!(sizes.iter().all(|&n| n > 0 && n <= BATCH), "{sizes:?}");
    assert_eq!(sizes.iter().sum::<usize>(), 80_000);
    // the consumer's error stops the stream
    let mut calls = 0;
    let e = src
        .stream(
            &mut |_| {
                calls += 1;
                Err(IngestError::Callback(Box::new(std::io::Error::other(
                    "disk full",
                ))))
            },
            &mut |_, _| {},
        )
        .unwrap_err();
    assert_eq!(calls, 1);
    // the consumer's error comes back whole: its type, and its message as the error's own
    assert_eq!(e.to_string(), "disk full");
    let IngestError::Callback(inner) = e else {
        panic!("{e:?}")
    };
    let inner = inner.downcast::<std::io::Error>().expect("the io::Error");
    assert_eq!(inner.kind(), std::io::ErrorKind::Other);
}

/// `vertex_bounds`: the bounds of every vertex (used or not) for a memory-mapped binary PLY
/// with fixed-size vertex records and of every facet corner for a binary STL, computed in
/// parallel parts of 65,536; `None` for ASCII, gzip, a list property in the vertex, or a
/// non-finite vertex.
#[test]
fn vertex_bounds_of_mapped_binary_ply() {
    let dir = TempDir::new("vb");
    // variant A: the bounds of P (vertices 5 and 6 are only used by a collinear face)
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &P {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k] as f64);
            hi[k] = hi[k].max(p[k] as f64);
        }
    }
    for (enc, gz) in ENCODINGS {
        let src = MeshSource::open(&write_ply(&dir, "a", enc, gz, &variant_a())).unwrap();
        let b = src.vertex_bounds();
        if enc == "ascii" || gz {
            assert!(b.is_none(), "{enc} gz={gz}: not read in place");
        } else {
            let b = b.unwrap_or_else(|| panic!("{enc}: no vertex bounds"));
            assert_eq!((b.min, b.max), (lo, hi), "{enc}");
        }
    }
    let src = MeshSource::open(&write_ply(
        &dir,
        "b",
        "binary_little_endian",
        false,
        &variant_b(&C),
    ))
    .unwrap();
    assert!(
        src.vertex_bounds().is_none(),
        "vertex records of varying size"
    );

    // many vertices, the extremes in different parts, one of them unused
    let n = 200_000usize;
    let coord = |i: usize, k: usize| (((i * (2 * k + 3) * 7919) % 100_003) as f64 - 50_000.0) * 0.5;
    let mut rows: Vec<Vec<V>> = (0..n)
        .map(|i| (0..3).map(|k| V::S(coord(i, k))).collect())
        .collect();
    rows[150_001] = vec![V::S(-1e6), V::S(2e6), V::S(0.0)];
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for r in &rows {
        for k in 0..3 {
            let V::S(c) = r[k] else { unreachable!() };
            lo[k] = lo[k].min(c as f32 as f64);
            hi[k] = hi[k].max(c as f32 as f64);
        }
    }
    let els = |rows: Vec<Vec<V>>| {
        vec![
            El {
                name: "vertex",
                props: vec!["float x", "float y", "float z"],
                rows,
            },
            El {
                name: "face",
                props: vec!["list uchar int vertex_indices"],
                rows: vec![vec![V::L(vec![0.0, 1.0, 2.0])]],
            },
        ]
    };
    for enc in ["binary_little_endian", "binary_big_endian"] {
        let src =
            MeshSource::open(&write_ply(&dir, "many", enc, false, &els(rows.clone()))).unwrap();
        let b = src.vertex_bounds().unwrap();
        assert_eq!((b.min, b.max), (lo, hi), "{enc}");
    }
    // an unused NaN vertex: the mesh reads, but it has no vertex bounds
    rows[70_000][1] = V::S(f64::NAN);
    let path = write_ply(&dir, "nan", "binary_little_endian", false, &els(rows));
    assert!(MeshSource::open(&path).unwrap().vertex_bounds().is_none());
    assert_eq!(read(&path).unwrap().0.len(), 1);

    // binary STL: every facet corner (a zero-area facet's too); ASCII STL: none
    let mut tris: Vec<[[f32; 3]; 3]> = (0..70_000)
        .map(|i| [0, 1, 2].map(|k| [0, 1, 2].map(|a| coord(3 * i + k, a) as f32)))
        .collect();
    tris[69_999] = [[5e5, 0.0, 0.0], [5e5, 0.0, 0.0], [0.0, -4e5, 0.0]];
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in tris.iter().flatten() {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k] as f64);
            hi[k] = hi[k].max(p[k] as f64);
        }
    }
    let stl = dir.write("many.stl", stl_binary(&tris, b"binary"));
    let b = MeshSource::open(&stl).unwrap().vertex_bounds().unwrap();
    assert_eq!((b.min, b.max), (lo, hi), "binary STL");
    let stl = dir.write("few.stl", stl_ascii(&tris[..10]));
    assert!(MeshSource::open(&stl).unwrap().vertex_bounds().is_none());
}
