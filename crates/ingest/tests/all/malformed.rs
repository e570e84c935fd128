//! Broken input gives an error naming the file, what is wrong and where — never a panic.

use crate::common;
use common::*;

const HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
element face 2\nproperty list uchar int vertex_indices\nend_header\n";
const VERTS: &str = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n";

fn check(dir: &TempDir, name: &str, data: impl AsRef<[u8]>, wants: &[&str]) {
    let path = dir.write(name, data);
    let msg = read_err(&path);
    eprintln!("{msg}");
    assert!(msg.contains(name), "message does not name the file: {msg}");
    for w in wants {
        assert!(msg.contains(w), "{name}: message lacks {w:?}: {msg}");
    }
}

fn binary_mesh(be: bool) -> Vec<u8> {
    let vertex = El {
        name: "vertex",
        props: vec!["float x", "float y", "float z"],
        rows: (0..4)
            .map(|i| vec![V::S(i as f64), V::S((i * i) as f64), V::S(1.0)])
            .collect(),
    };
    let face = El {
        name: "face",
        props: vec!["list uchar int vertex_indices"],
        rows: vec![
            vec![V::L(vec![0., 1., 2.])],
            vec![V::L(vec![0., 2., 3.])],
            vec![V::L(vec![1., 2., 3.])],
        ],
    };
    ply(
        if be {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        },
        &[vertex, face],
    )
}

/// A vertex-only PLY (a scan's point cloud) is named as one, with what to do, before any read.
#[test]
fn point_cloud_ply_is_named() {
    let d = TempDir::new("points");
    let head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
property float z\nend_header\n";
    check(
        &d,
        "points.ply",
        format!("{head}0 0 0\n1 0 0\n0 1 0\n"),
        &["a point cloud", "reconstruct a surface"],
    );
}

#[test]
fn empty_and_unknown() {
    let d = TempDir::new("empty");
    for name in ["empty.ply", "empty.obj", "empty.stl", "empty.ply.gz"] {
        check(&d, name, b"", &["is empty"]);
    }
    check(&d, "mesh.xyz", b"0 0 0\n1 1 1\n", &["unknown mesh format"]);
    check(&d, "mesh.obj.gz", gzip(b"v 0 0 0\n"), &["not supported"]);
}

#[test]
fn bad_ply_headers() {
    let d = TempDir::new("hdr");
    let cases: &[(&str, String, &[&str])] = &[
        (
            "notply.ply",
            "plx\nformat ascii 1.0\nend_header\n".into(),
            &["line 1", "not \"ply\""],
        ),
        (
            "type.ply",
            HEAD.replace("property float y", "property flot y") + VERTS,
            &["line 5", "unknown property type \"flot\""],
        ),
        (
            "noformat.ply",
            HEAD.replace("format ascii 1.0\n", "") + VERTS,
            &["no format line"],
        ),
        (
            "encoding.ply",
            HEAD.replace("ascii", "binary_middle_endian"),
            &["line 2", "unknown encoding"],
        ),
        (
            "count.ply",
            HEAD.replace("vertex 4", "vertex four"),
            &["line 3", "not a non-negative integer"],
        ),
        (
            "noend.ply",
            HEAD.replace("end_header\n", ""),
            &["no end_header"],
        ),
        (
            "novertex.ply",
            HEAD.replace("element vertex", "element point"),
            &["no \"vertex\" element"],
        ),
        (
            "noxyz.ply",
            HEAD.replace("property float z", "property float w"),
            &["lacks one of the scalar properties x, y, z"],
        ),
        (
            "nolist.ply",
            HEAD.replace("vertex_indices", "corners"),
            &["no list property vertex_indices"],
        ),
        (
            "floatidx.ply",
            HEAD.replace("uchar int", "uchar float"),
            &["float index type"],
        ),
        (
            "orphan.ply",
            "ply\nformat ascii 1.0\nproperty float x\nend_header\n".into(),
            &["line 3", "property before any element"],
        ),
    ];
    for (name, data, wants) in cases {
        check(&d, name, data, wants);
    }
    // and the same through gzip
    check(
        &d,
        "type.ply.gz",
        gzip((HEAD.replace("property float y", "property flot y") + VERTS).as_bytes()),
        &["line 5"],
    );
}

#[test]
fn bad_ascii_bodies() {
    let d = TempDir::new("ascii");
    check(
        &d,
        "short.ply",
        format!("{HEAD}{VERTS}3 0 1 2\n"),
        &["line 15", "ends after 1 of the 2 face records"],
    );
    check(
        &d,
        "range.ply",
        format!("{HEAD}{VERTS}3 0 1 2\n3 0 9 3\n"),
        &[
            "line 15",
            "face 1 corner 1 refers to vertex 9",
            "4 vertices",
        ],
    );
    check(
        &d,
        "negidx.ply",
        format!("{HEAD}{VERTS}3 0 1 2\n3 0 -1 3\n"),
        &["line 15", "vertex -1"],
    );
    check(
        &d,
        "nan.ply",
        format!("{HEAD}0 0 0\n1 nan 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n"),
        &["line 11", "vertex 1", "non-finite"],
    );
    check(
        &d,
        "inf.ply",
        format!("{HEAD}0 0 0\n1 0 0\n1 1 -inf\n0 1 0\n3 0 1 2\n3 0 2 3\n"),
        &["line 12", "vertex 2"],
    );
    check(
        &d,
        "word.ply",
        format!("{HEAD}0 0 0\n1 0 zero\n"),
        &["line 11", "\"zero\" is not a valid float"],
    );
    check(
        &d,
        "few.ply",
        format!("{HEAD}0 0 0\n1 0\n"),
        &["line 11", "ends early"],
    );
    check(
        &d,
        "extra.ply",
        format!("{HEAD}0 0 0 7\n"),
        &["line 10", "extra values", "\"7\""],
    );
    check(
        &d,
        "absurd.ply",
        format!("{HEAD}{VERTS}200 0 1 2\n3 0 2 3\n"),
        &["line 14", "absurd list count 200"],
    );
    let neg = HEAD.replace("list uchar int", "list int int");
    check(
        &d,
        "negcount.ply",
        format!("{neg}{VERTS}-3 0 1 2\n3 0 2 3\n"),
        &["line 14", "negative list count -3"],
    );
    check(
        &d,
        "nan.ply.gz",
        gzip(format!("{HEAD}0 0 0\nnan 0 0\n").as_bytes()),
        &["line 11", "vertex 1"],
    );
}

#[test]
fn bad_binary_bodies() {
    let d = TempDir::new("bin");
    for be in [false, true] {
        let good = binary_mesh(be);
        let tag = if be { "be" } else { "le" };
        let hlen = good.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        // cut inside the vertex array: refused at open, naming the vertex element
        let name = format!("cutvert-{tag}.ply");
        check(
            &d,
            &name,
            &good[..hlen + 20],
            &[
                "truncated",
                "element \"vertex\"",
                "needs 48 bytes but only 20",
            ],
        );
        // cut inside the last face record
        let name = format!("cutface-{tag}.ply");
        check(
            &d,
            &name,
            &good[..good.len() - 3],
            &[
                "truncated at face 2",
                "list of 3 int values",
                "needs 12 bytes but only 9",
            ],
        );
        // the same through gzip
        let name = format!("cutface-{tag}.ply.gz");
        check(
            &d,
            &name,
            gzip(&good[..good.len() - 3]),
            &["truncated at face 2"],
        );
        // index out of range in face 1
        let mut bad = good.clone();
        let f1 = hlen + 48 + 13 + 1 + 4; // face 1, corner 1
        bad[f1..f1 + 4].copy_from_slice(&if be {
            77i32.to_be_bytes()
        } else {
            77i32.to_le_bytes()
        });
        let name = format!("range-{tag}.ply");
        check(
            &d,
            &name,
            &bad,
            &[
                "face 1 corner 1 refers to vertex 77",
                "4 vertices",
                &format!("byte offset {}", f1 + 4),
            ],
        );
        let name = format!("range-{tag}.ply.gz");
        check(
            &d,
            &name,
            gzip(&bad),
            &["face 1 corner 1 refers to vertex 77"],
        );
        // a NaN in vertex 2 (used by face 0)
        let mut bad = good.clone();
        let v2 = hlen + 2 * 12 + 4;
        bad[v2..v2 + 4].copy_from_slice(&if be {
            f32::NAN.to_be_bytes()
        } else {
            f32::NAN.to_le_bytes()
        });
        let name = format!("nan-{tag}.ply");
        check(
            &d,
            &name,
            &bad,
            &["vertex 2 has a non-finite coordinate", "face 0"],
        );
        let name = format!("nan-{tag}.ply.gz");
        check(
            &d,
            &name,
            gzip(&bad),
            &["vertex 2 has a non-finite coordinate"],
        );
        // an absurd list count in face 2
        let mut bad = good.clone();
        let f2 = hlen + 48 + 2 * 13;
        bad[f2] = 250;
        let name = format!("absurd-{tag}.ply");
        check(
            &d,
            &name,
            &bad,
            &[
                "face 2",
                "list of 250 int values (absurd count or truncated file)",
            ],
        );
    }
    // a gzip stream cut short fails inside the decompressor or the reader, naming the file
    let gz = gzip(&binary_mesh(false));
    check(&d, "cutgz.ply.gz", &gz[..gz.len() - 30], &[]);
}

#[test]
fn bad_obj_and_stl() {
    let d = TempDir::new("objstl");
    check(
        &d,
        "range.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n",
        &["line 5", "face 1 corner 2 refers to vertex 4", "3 vertices"],
    );
    check(
        &d,
        "zero.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
        &["line 4", "face 0 corner 0 refers to vertex 0"],
    );
    check(
        &d,
        "nan.obj",
        "v 0 0 0\nv 1 NaN 0\nv 0 1 0\nf 1 2 3\n",
        &["line 2", "vertex 1 has a non-finite coordinate"],
    );
    check(
        &d,
        "word.obj",
        "v 0 0 zero\n",
        &["line 1", "\"zero\" is not a number"],
    );
    let t = [[[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]; 3];
    let good = stl_binary(&t, b"");
    check(
        &d,
        "cut.stl",
        &good[..good.len() - 10],
        &[
            "truncated",
            "3 binary STL facets",
            "needs 150 bytes but only 140",
        ],
    );
    check(&d, "tiny.stl", &good[..40], &["needs 84 bytes but only 40"]);
    let mut bad = good.clone();
    bad[84 + 50 + 12 + 12 + 4..84 + 50 + 12 + 12 + 8].copy_from_slice(&f32::INFINITY.to_le_bytes());
    check(
        &d,
        "inf.stl",
        &bad,
        &["facet 1", "vertex 4 has a non-finite coordinate"],
    );
    let ascii = stl_ascii(&t);
    check(
        &d,
        "noend.stl",
        &ascii[..ascii.len() - 14],
        &["without \"endsolid\""],
    );
    check(
        &d,
        "junk.stl",
        ascii.replace("outer loop", "outer space\nbanana"),
        &[
            "line 4",
            "\"banana\" where \"vertex\" or \"endloop\" was expected",
        ],
    );
    check(
        &d,
        "nan-ascii.stl",
        ascii.replacen("vertex 1 0 0", "vertex 1 nan 0", 1),
        &["line 5", "vertex 1 has a non-finite"],
    );
    check(&d, "two.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\nendsolid x\n", &["line 6", "loop with 2 vertices"]);
}
