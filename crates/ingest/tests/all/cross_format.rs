//! The same small mesh written as ASCII PLY, binary LE/BE PLY, gzip PLY, OBJ, binary STL and
//! ASCII STL yields the same triangle positions; OBJ materials and normals arrive as colours
//! and normals.

use crate::common;
use common::*;
use voxlod_geom::{DEFAULT_COLOR, TRI_HAS_COLORS, TRI_HAS_NORMALS};
use voxlod_ingest::MeshSource;

/// A square pyramid: a quad base (fanned 0-1-2, 0-2-3) and four sides.
const P: [[f32; 3]; 5] = [
    [0.0, 0.0, 0.0],
    [1.5, 0.0, 0.0],
    [1.5, 1.25, 0.0],
    [0.0, 1.25, 0.0],
    [0.75, 0.625, -2.0],
];
fn polys() -> Vec<Vec<usize>> {
    vec![
        vec![0, 3, 2, 1],
        vec![0, 1, 4],
        vec![1, 2, 4],
        vec![2, 3, 4],
        vec![3, 0, 4],
    ]
}
fn tris() -> Vec<[[f32; 3]; 3]> {
    let mut t = Vec::new();
    for f in polys() {
        for j in 1..f.len() - 1 {
            t.push([P[f[0]], P[f[j]], P[f[j + 1]]]);
        }
    }
    t
}

fn obj_text(mtllib: &str) -> String {
    let mut s = format!("# pyramid\nmtllib {mtllib}\n");
    for p in P {
        s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    s += "vn 0 0 -1\nvn 0 0 1\nusemtl red\n";
    // the base uses 1-based indices, the sides negative (relative) ones
    s += "f 1//1 4//1 3//1 2//1\nusemtl green\n";
    for f in &polys()[1..] {
        let c: Vec<String> = f.iter().map(|&i| format!("{}//2", i as i64 - 5)).collect();
        s += &format!("f {}\n", c.join(" "));
    }
    s
}

#[test]
fn all_formats_yield_the_same_positions() {
    let dir = TempDir::new("cross");
    let vertex = || El {
        name: "vertex",
        props: vec!["float x", "float y", "float z"],
        rows: P
            .iter()
            .map(|p| p.iter().map(|&x| V::S(x as f64)).collect())
            .collect(),
    };
    let face = || El {
        name: "face",
        props: vec!["list uchar int vertex_indices"],
        rows: polys()
            .into_iter()
            .map(|f| vec![V::L(f.iter().map(|&i| i as f64).collect())])
            .collect(),
    };
    let want = tris();
    let mut files = vec![
        dir.write("p-ascii.ply", ply("ascii", &[vertex(), face()])),
        dir.write("p-le.ply", ply("binary_little_endian", &[vertex(), face()])),
        dir.write("p-be.ply", ply("binary_big_endian", &[vertex(), face()])),
        dir.write("p-ascii.ply.gz", gzip(&ply("ascii", &[vertex(), face()]))),
        dir.write(
            "p-le.ply.gz",
            gzip(&ply("binary_little_endian", &[vertex(), face()])),
        ),
        dir.write("p.obj", obj_text("p.mtl")),
        dir.write("p-bin.stl", stl_binary(&want, b"binary stl")),
        // a binary STL whose header starts with "solid", as some exporters write
        dir.write(
            "p-bin-solid.stl",
            stl_binary(&want, b"solid exported by a binary writer"),
        ),
        dir.write("p-ascii.stl", stl_ascii(&want)),
    ];
    dir.write("p.mtl", "newmtl red\nKd 1 0 0\nnewmtl green\nKd 0 0.5 0\n");
    // no extension: recognised by content
    files.push(dir.write("p-noext", ply("binary_big_endian", &[vertex(), face()])));
    let formats: Vec<String> = files
        .iter()
        .map(|f| MeshSource::open(f).unwrap().info().format.clone())
        .collect();
    assert_eq!(
        formats,
        [
            "ply ascii",
            "ply binary_little_endian",
            "ply binary_big_endian",
            "ply ascii (gzip)",
            "ply binary_little_endian (gzip)",
            "obj",
            "stl binary",
            "stl binary",
            "stl ascii",
            "ply binary_big_endian"
        ]
    );
    for f in &files {
        let (got, st) = read(f).unwrap();
        let pos: Vec<_> = got.iter().map(|t| t.v).collect();
        assert_eq!(pos, want, "{}", f.display());
        assert_eq!(st.degenerate_skipped, 0);
    }
}

#[test]
fn obj_material_colours_and_normals() {
    let dir = TempDir::new("obj");
    let path = dir.write("p.obj", obj_text("p.mtl"));
    dir.write("p.mtl", "newmtl red\nKd 1 0 0\nnewmtl green\nKd 0 0.5 0\n");
    let src = MeshSource::open(&path).unwrap();
    assert!(src.info().has_normals && src.info().has_colors && src.info().warnings.is_empty());
    assert_eq!((src.info().vertices, src.info().faces), (5, 5));
    let (got, st) = read(&path).unwrap();
    assert_eq!((st.triangles, st.polygons), (6, 5));
    // two materials: a table (no material, red, green) for the material channel
    let names: Vec<_> = src
        .info()
        .materials
        .iter()
        .map(|m| m.name.as_str())
        .collect();
    assert_eq!(names, ["", "red", "green"]);
    for (i, t) in got.iter().enumerate() {
        let (c, n, m) = if i < 2 {
            ([255, 0, 0, 255], [0.0, 0.0, -1.0], 1)
        } else {
            ([0, 128, 0, 255], [0.0, 0.0, 1.0], 2)
        };
        assert_eq!(t.material(), m, "triangle {i}");
        assert_eq!(t.flags & 0xFFFF, TRI_HAS_NORMALS | TRI_HAS_COLORS);
        assert_eq!(t.c, [c; 3], "triangle {i}");
        assert_eq!(t.n, [n; 3], "triangle {i}");
    }
}

#[test]
fn obj_missing_mtl_warns_and_uses_the_default_colour() {
    let dir = TempDir::new("objnomtl");
    let path = dir.write("p.obj", obj_text("missing.mtl"));
    let src = MeshSource::open(&path).unwrap();
    let w = &src.info().warnings;
    assert_eq!(w.len(), 1);
    assert!(w[0].contains("missing.mtl"), "{w:?}");
    assert!(!src.info().has_colors);
    let (got, _) = read(&path).unwrap();
    assert!(got
        .iter()
        .all(|t| t.c == [DEFAULT_COLOR; 3] && t.flags == TRI_HAS_NORMALS));
}

#[test]
fn obj_vertex_colours_and_partial_normals() {
    let dir = TempDir::new("objvc");
    // vertex colours on every v line; normals on only some corners: normals are dropped
    let path = dir.write("vc.obj", "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nv 1 1 0 1 1 1\nvn 0 0 1\nf 1//1 2//1 3//1\nf 2 4 3\n");
    let src = MeshSource::open(&path).unwrap();
    assert!(!src.info().has_normals && src.info().has_colors);
    assert_eq!(src.info().warnings.len(), 1, "{:?}", src.info().warnings);
    let (got, _) = read(&path).unwrap();
    assert_eq!(got.len(), 2);
    assert_eq!(
        got[0].c,
        [[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255]]
    );
    assert_eq!(got[1].c[1], [255, 255, 255, 255]);
    assert!(got
        .iter()
        .all(|t| t.flags == TRI_HAS_COLORS && t.n == [[0.0; 3]; 3]));
}
