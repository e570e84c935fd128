//! PLY per-face data and texture coordinates (docs/INGEST.md "Per-face data"): the material
//! table from `material` / `material_index` values and `comment material N = NAME`, face
//! colours, vertex `s t` / `u v` and face `texcoord` lists with `comment TextureFile`, the
//! warnings for what is present but unused; every encoding against the values the test wrote,
//! and the shared Munich city against a count made from its bytes by the test.

use crate::common;
use common::{gzip, ply_commented, read, read_err, El, TempDir, V};
use voxlod_geom::{TRI_HAS_COLORS, TRI_HAS_UV};
use voxlod_ingest::MeshSource;

const ENCODINGS: [&str; 3] = ["ascii", "binary_little_endian", "binary_big_endian"];

fn vertices(props: Vec<&'static str>, rows: Vec<Vec<f64>>) -> El {
    El {
        name: "vertex",
        props,
        rows: rows
            .into_iter()
            .map(|r| r.into_iter().map(V::S).collect())
            .collect(),
    }
}

/// Five vertices: a quad 0-1-2-3 and a triangle 0-3-4 beside it.
fn five(uv: bool) -> El {
    let mut props = vec!["float x", "float y", "float z"];
    if uv {
        props.extend(["float s", "float t"]);
    }
    let p = [[0., 0.], [1., 0.], [1., 1.], [0., 1.], [-1., 0.5]];
    let rows = p
        .iter()
        .enumerate()
        .map(|(i, q)| {
            let mut r = vec![q[0], q[1], 0.0];
            if uv {
                r.extend([0.125 * i as f64, 1.0 - 0.25 * i as f64]);
            }
            r
        })
        .collect();
    vertices(props, rows)
}

#[test]
fn per_face_materials_colours_and_unused_properties() {
    let d = TempDir::new("facedata");
    // (material value, colour) of the three faces; the material property comes before the list
    let faces: [(&[f64], f64, [f64; 4]); 3] = [
        (&[0., 1., 2., 3.], 2., [10., 20., 30., 255.]),
        (&[0., 3., 4.], 0., [200., 100., 50., 128.]),
        (&[4., 1., 0.], 7., [1., 2., 3., 4.]),
    ];
    for (k, enc) in ENCODINGS.iter().enumerate() {
        let (ty, name) = [
            ("uchar", "material"),
            ("ushort", "material_index"),
            ("int", "material"),
        ][k];
        let decl: &'static str = Box::leak(format!("{ty} {name}").into_boxed_str());
        let face = El {
            name: "face",
            props: vec![
                decl,
                "list uchar int vertex_indices",
                "uchar red",
                "uchar green",
                "uchar blue",
                "uchar alpha",
                "float quality",
            ],
            rows: faces
                .iter()
                .map(|(ix, m, c)| {
                    let mut r = vec![V::S(*m), V::L(ix.to_vec())];
                    r.extend(c.iter().map(|&x| V::S(x)));
                    r.push(V::S(0.5));
                    r
                })
                .collect(),
        };
        let bytes = ply_commented(
            enc,
            &["material 0 = marble", "material 2 = red brick"],
            &[five(false), face],
        );
        for gz in [false, true] {
            let p = if gz {
                d.write(&format!("m{k}.ply.gz"), gzip(&bytes))
            } else {
                d.write(&format!("m{k}.ply"), &bytes)
            };
            let src = MeshSource::open(&p).unwrap();
            let info = src.info();
            let names: Vec<&str> = info.materials.iter().map(|m| m.name.as_str()).collect();
            assert_eq!(names, ["", "marble", "red brick", "material 7"], "{enc}");
            assert!(info.has_colors && !info.has_texcoords);
            assert_eq!(info.warnings.len(), 1, "{:?}", info.warnings);
            let w = &info.warnings[0];
            assert!(
                // the build prefixes the input's name; the warning does not repeat it
                !w.contains(&p.display().to_string()) && w.contains("quality"),
                "{w}"
            );
            let (tris, st) = read(&p).unwrap();
            assert_eq!((st.polygons, tris.len()), (3, 4));
            // the quad's two fan triangles, then the two triangles
            let want = [(2, 0), (2, 0), (1, 1), (3, 2)];
            for (t, (m, f)) in tris.iter().zip(want) {
                assert_eq!(t.material(), m, "{enc}");
                let c = faces[f].2.map(|x| x as u8);
                assert_eq!(t.c, [c; 3]);
                assert!(t.flags & TRI_HAS_COLORS != 0 && t.flags & TRI_HAS_UV == 0);
            }
            assert_eq!(tris[1].v[2], [0.0, 1.0, 0.0]); // fanned from corner 0: 0-2-3
        }
    }
}

#[test]
fn one_material_and_vertex_colours_win() {
    let d = TempDir::new("facedata1");
    // one material value only: no table (as for OBJ); face colours beside vertex colours: unused
    let v = vertices(
        vec![
            "float x",
            "float y",
            "float z",
            "uchar red",
            "uchar green",
            "uchar blue",
        ],
        vec![
            vec![0., 0., 0., 9., 9., 9.],
            vec![1., 0., 0., 9., 9., 9.],
            vec![0., 1., 0., 9., 9., 9.],
        ],
    );
    let f = El {
        name: "face",
        props: vec![
            "list uchar int vertex_indices",
            "uchar material",
            "uchar red",
            "uchar green",
            "uchar blue",
        ],
        rows: vec![vec![
            V::L(vec![0., 1., 2.]),
            V::S(4.),
            V::S(1.),
            V::S(2.),
            V::S(3.),
        ]],
    };
    let p = d.write("one.ply", ply_commented("ascii", &[], &[v, f]));
    let src = MeshSource::open(&p).unwrap();
    assert!(src.info().materials.is_empty());
    let w = &src.info().warnings;
    assert!(
        w.len() == 1 && w[0].contains("colours are not used"),
        "{w:?}"
    );
    let (tris, _) = read(&p).unwrap();
    assert_eq!((tris[0].material(), tris[0].c[0]), (0, [9, 9, 9, 255]));
}

/// The texture beside the PLY, named in another letter case by the header.
fn texture(d: &TempDir) {
    std::fs::create_dir_all(d.path("Maps")).unwrap();
    std::fs::write(d.path("Maps/Tex.PNG"), b"not decoded by ingest").unwrap();
}

#[test]
fn vertex_and_face_texture_coordinates() {
    let d = TempDir::new("facetex");
    texture(&d);
    let tf = ["TextureFile maps/tex.png"];
    // the vertex convention: s t per vertex
    let quad = El {
        name: "face",
        props: vec!["list uchar int vertex_indices"],
        rows: vec![vec![V::L(vec![0., 1., 2., 3.])]],
    };
    let vuv = |i: usize| [0.125 * i as f32, 1.0 - 0.25 * i as f32];
    for enc in ENCODINGS {
        let p = d.write(
            "v.ply",
            ply_commented(enc, &tf, &[five(true), quad_clone(&quad)]),
        );
        let src = MeshSource::open(&p).unwrap();
        let info = src.info();
        assert!(
            info.has_texcoords && info.warnings.is_empty(),
            "{:?}",
            info.warnings
        );
        assert_eq!(info.materials.len(), 2);
        assert_eq!(info.materials[1].texture, Some(d.path("Maps/Tex.PNG")));
        let (tris, _) = read(&p).unwrap();
        assert_eq!(tris[0].uv, [vuv(0), vuv(1), vuv(2)], "{enc}");
        assert_eq!(tris[1].uv, [vuv(0), vuv(2), vuv(3)], "{enc}");
        assert!(tris
            .iter()
            .all(|t| t.material() == 1 && t.flags & TRI_HAS_UV != 0));
    }
    // the MeshLab convention: a texcoord list per face, two floats per corner
    let tc: Vec<f64> = (0..8).map(|k| k as f64 / 8.0).collect();
    let faces = El {
        name: "face",
        props: vec!["list uchar int vertex_indices", "list uchar float texcoord"],
        rows: vec![vec![V::L(vec![0., 1., 2., 3.]), V::L(tc.clone())]],
    };
    for enc in ENCODINGS {
        let p = d.write(
            "f.ply",
            ply_commented(enc, &tf, &[five(false), quad_clone(&faces)]),
        );
        let (tris, _) = read(&p).unwrap();
        let c = |k: usize| [tc[2 * k] as f32, tc[2 * k + 1] as f32];
        assert_eq!(tris[0].uv, [c(0), c(1), c(2)], "{enc}");
        assert_eq!(tris[1].uv, [c(0), c(2), c(3)], "{enc}");
    }
    // a texcoord list of the wrong length is an error naming the file and the face
    let bad = El {
        name: "face",
        props: vec!["list uchar int vertex_indices", "list uchar float texcoord"],
        rows: vec![vec![V::L(vec![0., 1., 2., 3.]), V::L(vec![0.; 6])]],
    };
    let p = d.write("bad.ply", ply_commented("ascii", &tf, &[five(false), bad]));
    let e = read_err(&p);
    assert!(
        e.contains("bad.ply") && e.contains("face 0") && e.contains("texcoord"),
        "{e}"
    );
}

fn quad_clone(e: &El) -> El {
    El {
        name: e.name,
        props: e.props.clone(),
        rows: e.rows.clone(),
    }
}

#[test]
fn unusable_textures_are_warnings() {
    let d = TempDir::new("facetexw");
    let quad = El {
        name: "face",
        props: vec!["list uchar int vertex_indices"],
        rows: vec![vec![V::L(vec![0., 1., 2., 3.])]],
    };
    let cases: [(&[&str], bool, &str); 3] = [
        (&["TextureFile missing.png"], true, "missing.png"),
        (&[], true, "names no texture"),
        (&["TextureFile a.png"], false, "no texture coordinates"),
    ];
    std::fs::write(d.path("a.png"), b"x").unwrap();
    for (comments, uv, says) in cases {
        let p = d.write(
            "w.ply",
            ply_commented("ascii", comments, &[five(uv), quad_clone(&quad)]),
        );
        let src = MeshSource::open(&p).unwrap();
        let info = src.info();
        assert!(!info.has_texcoords && info.materials.iter().all(|m| m.texture.is_none()));
        assert!(
            info.warnings
                .iter()
                .any(|w| w.contains(says) && !w.contains("w.ply")),
            "{:?}",
            info.warnings
        );
        let (tris, _) = read(&p).unwrap();
        assert!(tris
            .iter()
            .all(|t| t.flags & TRI_HAS_UV == 0 && t.uv == [[0.0; 2]; 3]));
    }
}

#[test]
fn munich_materials_match_its_bytes() {
    let Some(p) = voxlod_testkit::shared_mesh(module_path!(), "sionna-rt-munich/munich_merged.ply")
    else {
        return;
    };
    // an independent reading: header lines, then 12-byte vertices and 14-byte faces
    // (uchar 3, three ints, uchar material)
    let bytes = std::fs::read(&p).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let head = std::str::from_utf8(&bytes[..end]).unwrap();
    let count = |el: &str| -> usize {
        let l = head
            .lines()
            .find(|l| l.starts_with(&format!("element {el} ")))
            .unwrap();
        l.rsplit(' ').next().unwrap().parse().unwrap()
    };
    let (nv, nf) = (count("vertex"), count("face"));
    let faces = &bytes[end + 12 * nv..];
    assert_eq!(faces.len(), 14 * nf);
    let mut want = std::collections::BTreeMap::new();
    for f in faces.chunks_exact(14) {
        assert_eq!(f[0], 3);
        let ix: Vec<u32> = (0..3)
            .map(|k| u32::from_le_bytes(f[1 + 4 * k..5 + 4 * k].try_into().unwrap()))
            .collect();
        if ix[0] != ix[1] && ix[1] != ix[2] && ix[0] != ix[2] {
            *want.entry(f[13] as u32 + 1).or_insert(0u64) += 1;
        }
    }
    let src = MeshSource::open(&p).unwrap();
    let names: Vec<&str> = src
        .info()
        .materials
        .iter()
        .map(|m| m.name.as_str())
        .collect();
    assert_eq!(names, ["", "marble", "metal", "brick", "wood", "concrete"]);
    assert!(src.info().warnings.is_empty(), "{:?}", src.info().warnings);
    let mut got = std::collections::BTreeMap::new();
    let st = src
        .stream(
            &mut |b| {
                for t in b {
                    *got.entry(t.material()).or_insert(0u64) += 1;
                }
                Ok(())
            },
            &mut |_, _| {},
        )
        .unwrap();
    // zero-area triangles with distinct indices are skipped too: compare with them added back
    let zero = st.degenerate_skipped - st.repeated_index;
    assert_eq!(got.values().sum::<u64>() + zero, want.values().sum::<u64>());
    assert_eq!(got.len(), want.len());
    for (m, n) in &want {
        assert!(
            got[m] <= *n && got[m] + zero >= *n,
            "material {m}: {} of {n}",
            got[m]
        );
    }
}

#[test]
fn texnumber_chooses_among_several_textures() {
    let d = TempDir::new("texnumber");
    texture(&d);
    std::fs::write(d.path("b.jpg"), b"x").unwrap();
    // OpenMVS: one TextureFile per texture, a per-face texnumber; face 1 names texture 1
    let faces = El {
        name: "face",
        props: vec![
            "list uchar int vertex_indices",
            "list uchar float texcoord",
            "int texnumber",
        ],
        rows: vec![
            vec![V::L(vec![0., 1., 2.]), V::L(vec![0.; 6]), V::S(1.)],
            vec![V::L(vec![0., 2., 3.]), V::L(vec![0.5; 6]), V::S(0.)],
            vec![V::L(vec![0., 3., 4.]), V::L(vec![0.25; 6]), V::S(1.)],
        ],
    };
    let p = d.write(
        "t.ply",
        ply_commented(
            "binary_little_endian",
            &["TextureFile Maps/Tex.PNG", "TextureFile B.JPG"],
            &[five(false), faces],
        ),
    );
    let src = MeshSource::open(&p).unwrap();
    let info = src.info();
    assert!(info.warnings.is_empty(), "{:?}", info.warnings);
    let m: Vec<(&str, Option<std::path::PathBuf>)> = info
        .materials
        .iter()
        .map(|m| (m.name.as_str(), m.texture.clone()))
        .collect();
    assert_eq!(
        m,
        [
            ("", None),
            ("Maps/Tex.PNG", Some(d.path("Maps/Tex.PNG"))),
            ("B.JPG", Some(d.path("b.jpg")))
        ]
    );
    let (tris, _) = read(&p).unwrap();
    let got: Vec<(u32, f32)> = tris.iter().map(|t| (t.material(), t.uv[0][0])).collect();
    assert_eq!(got, [(2, 0.0), (1, 0.5), (2, 0.25)]);
}
