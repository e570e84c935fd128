//! `voxlod export FILE --3d-tiles DIR`: an OGC 3D Tiles 1.1 tileset.
//!
//! `tileset.json` is checked against the file's node index read independently: one tile per
//! node of the cut with the same tree, a content URI per node with faces whose GLB holds
//! exactly that node's active faces (and passes the Khronos glTF validator), every box holding
//! the node's decoded voxels and its children's boxes, `geometricError` the voxel edge of the
//! level (0 at the leaves of the cut); `--error` picks the level it says; the size guard and
//! the folder rules hold. Then a real consumer: three.js with the npm `3d-tiles-renderer`, in
//! headless Chromium over a loopback HTTP server (`tests/node/tiles-check.js`), loads the
//! tileset from voxlod's own camera for the view, and the silhouette of its screenshot matches
//! `voxlod render` of the same view and level (its
//! coverage mask, from the renderer `voxlod render` runs): intersection over union at least 0.97
//! (measured 0.993 on the bunny at 320×240; the rest is edge pixels of the two rasterizers).

use std::path::Path;
use std::process::Command;

use serde_json::Value;
use voxlod_format::Reader;

use super::{build_ok, ok, shared_meshes, text, voxlod, REPO};

/// (min, max) of a `box` bounding volume (axis-aligned: half axes on the diagonal).
fn box_of(t: &Value) -> ([f64; 3], [f64; 3]) {
    let b: Vec<f64> = t["boundingVolume"]["box"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(b.len(), 12);
    assert!(
        [4, 5, 6, 8, 9, 10].iter().all(|&i| b[i] == 0.0),
        "axis-aligned box {b:?}"
    );
    let h = [b[3], b[7], b[11]];
    (
        std::array::from_fn(|a| b[a] - h[a]),
        std::array::from_fn(|a| b[a] + h[a]),
    )
}

fn inside(inner: ([f64; 3], [f64; 3]), outer: ([f64; 3], [f64; 3]), eps: f64) -> bool {
    (0..3).all(|a| inner.0[a] >= outer.0[a] - eps && inner.1[a] <= outer.1[a] + eps)
}

/// The sRGB byte's linear value as a normalized `u16` (IEC 61966-2-1), written out here.
fn linear_u16(c: u8) -> u16 {
    let s = c as f64 / 255.0;
    let l = if s <= 0.04045 {
        s / 12.92
    } else {
        ((s + 0.055) / 1.055).powf(2.4)
    };
    (l * 65535.0).round() as u16
}

/// A GLB's JSON and binary chunk.
fn glb_chunks(glb: &[u8]) -> (Value, &[u8]) {
    let u = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(&glb[0..4], b"glTF");
    assert_eq!(u(8), glb.len());
    let jl = u(12);
    let bl = u(20 + jl);
    assert_eq!(&glb[24 + jl..28 + jl], b"BIN\0");
    assert_eq!(28 + jl + bl, glb.len());
    (
        serde_json::from_slice(&glb[20..20 + jl]).unwrap(),
        &glb[28 + jl..],
    )
}

/// The decoded bytes of accessor `a` (its view compressed with `EXT_meshopt_compression`),
/// one `Vec<u8>` of the view's stride per element.
fn decode_accessor(j: &Value, bin: &[u8], a: usize) -> Vec<Vec<u8>> {
    let acc = &j["accessors"][a];
    let view = &j["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    assert_eq!(view["buffer"], 1, "views are in the fallback buffer");
    let ext = &view["extensions"]["EXT_meshopt_compression"];
    assert_eq!(ext["buffer"], 0);
    let (off, len) = (
        ext["byteOffset"].as_u64().unwrap() as usize,
        ext["byteLength"].as_u64().unwrap() as usize,
    );
    let (count, stride) = (
        ext["count"].as_u64().unwrap() as usize,
        ext["byteStride"].as_u64().unwrap() as usize,
    );
    assert_eq!(count, acc["count"].as_u64().unwrap() as usize);
    assert_eq!(
        view["byteLength"].as_u64().unwrap() as usize,
        count * stride
    );
    let enc = &bin[off..off + len];
    if ext["mode"] == "TRIANGLES" {
        assert_eq!(enc[0] & 0xf0, 0xe0, "index codec header");
        let ix: Vec<u32> = meshopt::decode_index_buffer(enc, count).unwrap();
        return ix.iter().map(|i| i.to_le_bytes().to_vec()).collect();
    }
    assert_eq!(ext["mode"], "ATTRIBUTES");
    assert_eq!(
        enc[0], 0xa0,
        "vertex codec version 0 (EXT_meshopt_compression)"
    );
    match stride {
        4 => meshopt::decode_vertex_buffer::<[u8; 4]>(enc, count)
            .unwrap()
            .iter()
            .map(|v| v.to_vec())
            .collect(),
        8 => meshopt::decode_vertex_buffer::<[u8; 8]>(enc, count)
            .unwrap()
            .iter()
            .map(|v| v.to_vec())
            .collect(),
        s => panic!("stride {s}"),
    }
}

/// A triangle in node grid units (smallest corner first, winding kept), its linear colour and
/// material id; and its normal.
type Tri = (([[u16; 3]; 3], [u16; 4], u16), [f64; 3]);

fn canonical(c: [[u16; 3]; 3], col: [u16; 4], m: u16, n: [f64; 3]) -> Tri {
    let k = (0..3).min_by_key(|&i| c[i]).unwrap();
    let mut t = c.to_vec();
    t.rotate_left(k);
    (([t[0], t[1], t[2]], col, m), n)
}

/// The triangles of a tile's content, decoded.
fn content_triangles(glb: &[u8]) -> (Value, Vec<Tri>) {
    let (j, bin) = glb_chunks(glb);
    let used: Vec<&str> = j["extensionsRequired"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(used.contains(&"EXT_meshopt_compression") && used.contains(&"KHR_mesh_quantization"));
    let mut out = Vec::new();
    for p in j["meshes"][0]["primitives"].as_array().unwrap() {
        let at = |k: &str| p["attributes"][k].as_u64().unwrap() as usize;
        let pos = decode_accessor(&j, bin, at("POSITION"));
        let nrm = decode_accessor(&j, bin, at("NORMAL"));
        let col = decode_accessor(&j, bin, at("COLOR_0"));
        let fid = p["attributes"]
            .get("_FEATURE_ID_0")
            .map(|a| decode_accessor(&j, bin, a.as_u64().unwrap() as usize));
        let ix = decode_accessor(&j, bin, p["indices"].as_u64().unwrap() as usize);
        let ix: Vec<usize> = ix
            .iter()
            .map(|b| u32::from_le_bytes(b[..4].try_into().unwrap()) as usize)
            .collect();
        for t in ix.chunks(3) {
            let c: [[u16; 3]; 3] = std::array::from_fn(|k| {
                let i = t[k];
                std::array::from_fn(|a| u16::from_le_bytes([pos[i][2 * a], pos[i][2 * a + 1]]))
            });
            let i = t[0];
            let col: [u16; 4] =
                std::array::from_fn(|a| u16::from_le_bytes([col[i][2 * a], col[i][2 * a + 1]]));
            let n: [f64; 3] = std::array::from_fn(|a| nrm[i][a] as i8 as f64 / 127.0);
            let m = fid
                .as_ref()
                .map_or(0, |f| u16::from_le_bytes([f[i][0], f[i][1]]));
            out.push(canonical([c[0], c[1], c[2]], col, m, n));
        }
    }
    (j, out)
}

/// Checks the node transform of a content: turned −90° about x (glTF is y-up, for the
/// consumer's y-up to z-up turn), at the node's corner, scaled by its voxel edge.
fn check_placement(j: &Value, corner: [f64; 3], edge: f64) {
    let node = &j["nodes"][0];
    let rot: Vec<f64> = serde_json::from_value(node["rotation"].clone()).unwrap();
    let h = std::f64::consts::FRAC_1_SQRT_2;
    assert!(
        (rot[0] + h).abs() < 1e-9 && (rot[3] - h).abs() < 1e-9,
        "{rot:?}"
    );
    let tr: Vec<f64> = serde_json::from_value(node["translation"].clone()).unwrap();
    assert!(
        (tr[0] - corner[0]).abs() + (tr[1] - corner[2]).abs() + (tr[2] + corner[1]).abs() < 1e-9,
        "{tr:?} {corner:?}"
    );
    assert_eq!(node["scale"], serde_json::json!([edge, edge, edge]));
}

/// The triangles of part tile `k` (uri `PATH.glb`), or of its parts where it is split again
/// (a tile without content, error `wrapper_error`, over parts `PATH-o`); every content at
/// most 4 MB and placed at the node's corner.
fn part_triangles(
    k: &Value,
    path: &str,
    dir: &Path,
    corner: [f64; 3],
    edge: f64,
    wrapper_error: f64,
) -> Vec<Tri> {
    if let Some(uri) = k["content"]["uri"].as_str() {
        assert_eq!(uri, format!("{path}.glb"));
        let glb = std::fs::read(dir.join(uri)).unwrap();
        assert!(glb.len() <= 4_000_000, "{uri}: {} bytes", glb.len());
        let (j, tris) = content_triangles(&glb);
        check_placement(&j, corner, edge);
        return tris;
    }
    assert_eq!(k["geometricError"].as_f64().unwrap(), wrapper_error);
    let mut out = Vec::new();
    for c in k["children"].as_array().unwrap() {
        let uri = first_uri(c);
        // the sub-part's path: PATH-o
        let rest = &uri[path.len() + 1..];
        let o = &rest[..1];
        out.extend(part_triangles(
            c,
            &format!("{path}-{o}"),
            dir,
            corner,
            edge,
            wrapper_error,
        ));
    }
    out
}

/// The first content uri at or under tile `t`.
fn first_uri(t: &Value) -> String {
    match t["content"]["uri"].as_str() {
        Some(u) => u.to_string(),
        None => first_uri(&t["children"][0]),
    }
}

/// Compares decoded triangles with the wanted ones (the normals within a byte's rounding).
fn same_triangles(mut got: Vec<Tri>, mut want: Vec<Tri>, what: &str) {
    got.sort_by_key(|a| a.0);
    want.sort_by_key(|a| a.0);
    assert_eq!(got.len(), want.len(), "{what}");
    for (g, w) in got.iter().zip(&want) {
        assert_eq!(g.0, w.0, "{what}");
        // the voxel's normal (the face direction where it is zero), quantized to bytes
        let len = w.1.iter().map(|c| c * c).sum::<f64>().sqrt();
        if len > 0.0 {
            let d: f64 = (0..3).map(|a| g.1[a] * w.1[a] / len).sum();
            assert!(d > 0.99, "{what}: normal {:?} against {:?}", g.1, w.1);
        }
    }
}

/// Checks the tile of node `i` and its subtree (`parent_error`: the error of the tile above);
/// returns the number of tiles. A node whose content is over 4 MB is a tile without content
/// whose error is its parent's, over one tile per octant with faces or a child: that
/// octant's faces, the node's error, and the octant's child node below.
fn check_tile(
    r: &Reader,
    i: usize,
    t: &Value,
    min_level: u32,
    dir: &Path,
    parent_error: f64,
) -> usize {
    let e = r.nodes()[i];
    let spec = r.spec();
    let edge = spec.voxel_size_at(e.level);
    let bx = box_of(t);
    // the node's voxels, decoded, lie in its box; its active faces are its content's quads
    let voxels = r.read_node(i).unwrap();
    let materials = r.read_materials(i).unwrap();
    // the faces of each octant of the node (by the voxel's position)
    let mut by_octant: Vec<Vec<Tri>> = vec![Vec::new(); 8];
    for (k, v) in voxels.iter().enumerate() {
        let p = v.pos();
        let want = &mut by_octant[(p[0] >> 7 | (p[1] >> 7) << 1 | (p[2] >> 7) << 2) as usize];
        let lo = spec.voxel_min_corner(e.level, e.pos(), v.pos());
        let hi = lo.map(|c| c + edge);
        assert!(
            inside((lo, hi), bx, edge * 1e-6),
            "voxel {lo:?} outside {bx:?}"
        );
        let rgba = v.rgba();
        let col = [
            linear_u16(rgba[0]),
            linear_u16(rgba[1]),
            linear_u16(rgba[2]),
            rgba[3] as u16 * 257,
        ];
        let m = materials.as_ref().map_or(0, |m| m[k] as u16);
        let n = v.normal_f32().map(|c| c as f64);
        for dir in 0..6u8 {
            if v.mask() >> dir & 1 == 1 {
                let c = voxlod_render::unit_face_corners(dir)
                    .map(|c| std::array::from_fn(|a| v.pos()[a] as u16 + c[a] as u16));
                want.push(canonical([c[0], c[1], c[2]], col, m, n));
                want.push(canonical([c[0], c[2], c[3]], col, m, n));
            }
        }
    }
    let want: Vec<Tri> = by_octant.concat();
    let children: [Option<usize>; 8] = if e.level > min_level {
        r.children(i)
    } else {
        [None; 8]
    };
    let node_error = if children.iter().any(Option::is_some) {
        // voxels of at most 2 px at the consumers' default maximum screen-space error
        8.0 * edge
    } else {
        0.0
    };
    let kids = t
        .get("children")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    let corner = spec.voxel_min_corner(e.level, e.pos(), [0; 3]);
    let prefix = format!("{}/{}-{}-{}-", e.level, e.x, e.y, e.z);
    let split = kids.iter().any(|k| {
        k["content"]["uri"]
            .as_str()
            .is_some_and(|u| u.starts_with(&prefix))
    });
    let mut n = 1;
    if split {
        assert!(t.get("content").is_none());
        assert_eq!(t["geometricError"].as_f64().unwrap(), parent_error);
        let parts: Vec<u8> = (0..8u8)
            .filter(|&o| !by_octant[o as usize].is_empty() || children[o as usize].is_some())
            .collect();
        assert_eq!(parts.len(), kids.len(), "octant tiles of {prefix}");
        for (&o, k) in parts.iter().zip(&kids) {
            n += 1;
            assert!(inside(box_of(k), bx, edge * 1e-6), "octant box outside");
            if !by_octant[o as usize].is_empty() {
                let tris =
                    part_triangles(k, &format!("{prefix}{o}"), dir, corner, edge, parent_error);
                same_triangles(tris, by_octant[o as usize].clone(), &format!("{prefix}{o}"));
            } else {
                assert!(k.get("content").is_none());
            }
            let below = k
                .get("children")
                .and_then(Value::as_array)
                .cloned()
                .unwrap_or_default();
            match children[o as usize] {
                Some(c) => {
                    assert_eq!(below.len(), 1);
                    assert_eq!(k["geometricError"].as_f64().unwrap(), node_error);
                    assert!(inside(box_of(&below[0]), box_of(k), edge * 1e-6));
                    n += check_tile(r, c, &below[0], min_level, dir, node_error);
                }
                None if k.get("content").is_some() => {
                    assert!(below.is_empty());
                    assert_eq!(k["geometricError"].as_f64().unwrap(), 0.0);
                }
                // split further (checked by part_triangles)
                None => {}
            }
        }
        return n;
    }
    if !want.is_empty() {
        let uri = t["content"]["uri"].as_str().unwrap();
        assert_eq!(uri, format!("{}/{}-{}-{}.glb", e.level, e.x, e.y, e.z));
        let glb = std::fs::read(dir.join(uri)).unwrap();
        assert!(glb.len() <= 4_000_000, "{uri}: {} bytes", glb.len());
        let (j, got) = content_triangles(&glb);
        same_triangles(got, want, uri);
        check_placement(&j, corner, edge);
    } else {
        assert!(t.get("content").is_none());
    }
    let want: Vec<usize> = children.into_iter().flatten().collect();
    assert_eq!(kids.len(), want.len(), "children of {:?}", e.pos());
    let error = t["geometricError"].as_f64().unwrap();
    assert_eq!(error, node_error);
    for (c, k) in want.iter().zip(&kids) {
        assert!(
            inside(box_of(k), bx, edge * 1e-6),
            "child box outside its parent's"
        );
        n += check_tile(r, *c, k, min_level, dir, node_error);
    }
    n
}

/// Whether node, the npm packages of tests/node and Chromium are there (a failure under CI).
fn browser_tools() -> bool {
    let node = Path::new(REPO).join("tests/node/node_modules");
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    let there = [
        "three",
        "3d-tiles-renderer",
        "puppeteer-core",
        "gltf-validator",
    ]
    .iter()
    .all(|p| node.join(p).is_dir())
        && Path::new(&chromium).is_file();
    if !there {
        assert!(
            !voxlod_testkit::under_ci(),
            "node packages (npm ci in tests/node) or {chromium} missing: .ci/run installs both"
        );
        voxlod_testkit::skipped(
            "tiles (the browser check)",
            "npm ci in tests/node and apt-get install chromium",
        );
    }
    there
}

/// Pixels of a screenshot that are not its background colour.
fn silhouette(png: &Path, background: [u8; 3]) -> (Vec<bool>, u32, u32) {
    let img = image::open(png).unwrap().to_rgb8();
    let (w, h) = img.dimensions();
    let s = img
        .pixels()
        .map(|p| (0..3).any(|c| (p.0[c] as i32 - background[c] as i32).abs() > 6))
        .collect();
    (s, w, h)
}

#[test]
fn tileset_matches_the_octree_and_opens_in_three_js() {
    let Some(m) = shared_meshes("tileset_matches_the_octree_and_opens_in_three_js") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = d.join("bunny.voxlod");
    build_ok(&m.join("npm-bunny/bunny.ply"), &file, &["-r", "512"], d);
    let r = Reader::open(&file).unwrap();
    assert_eq!(r.spec().levels, 2);

    // the whole tree (levels 0 and 1)
    let said = ok(&voxlod(
        &["export", "bunny.voxlod", "--3d-tiles", "tiles"],
        d,
    ));
    let tiles = d.join("tiles");
    let ts: Value =
        serde_json::from_slice(&std::fs::read(tiles.join("tileset.json")).unwrap()).unwrap();
    assert_eq!(ts["asset"]["version"], "1.1");
    assert_eq!(ts["root"]["refine"], "REPLACE");
    let top = ts["geometricError"].as_f64().unwrap();
    let n = check_tile(&r, r.root().unwrap(), &ts["root"], 0, &tiles, top);
    // the root (3.6 MB of faces at 512³) is whole or split in its octants
    assert!(
        n == r.nodes().len() || n == r.nodes().len() + 8,
        "{n} tiles"
    );
    assert!(said.contains(&format!("{n} tiles")), "{said}");
    let bytes: u64 = walk(&tiles)
        .iter()
        .map(|p| std::fs::metadata(p).unwrap().len())
        .sum();
    assert!(
        said.contains(&voxlod_pipeline::format_size(bytes)),
        "{said}"
    );
    if browser_tools() {
        let report = Command::new("node")
            .arg(Path::new(REPO).join("tests/node/validate-gltf.js"))
            .arg(tiles.join("0/0-0-0.glb"))
            .output()
            .unwrap();
        let report: Value = serde_json::from_slice(&report.stdout).unwrap();
        assert_eq!(report["issues"]["numErrors"], 0, "{report}");
        assert_eq!(report["issues"]["numWarnings"], 0, "{report}");
    }

    // --error: the coarsest level whose voxel edge is at most E
    let e1 = r.spec().voxel_size_at(1).to_string();
    ok(&voxlod(
        &[
            "export",
            "bunny.voxlod",
            "--3d-tiles",
            "coarse",
            "--error",
            &e1,
        ],
        d,
    ));
    let ts1: Value =
        serde_json::from_slice(&std::fs::read(d.join("coarse/tileset.json")).unwrap()).unwrap();
    assert_eq!(
        check_tile(
            &r,
            r.root().unwrap(),
            &ts1["root"],
            1,
            &d.join("coarse"),
            ts1["geometricError"].as_f64().unwrap()
        ) % 8,
        1
    );

    // folder rules: a tileset is not replaced without --force; a non-empty other folder never
    let o = voxlod(
        &[
            "export",
            "bunny.voxlod",
            "--3d-tiles",
            "coarse",
            "--level",
            "1",
        ],
        d,
    );
    assert!(!o.status.success());
    assert!(
        text(&o).contains("holds a tileset already; --force replaces it"),
        "{}",
        text(&o)
    );
    ok(&voxlod(
        &[
            "export",
            "bunny.voxlod",
            "--3d-tiles",
            "coarse",
            "--level",
            "1",
            "--force",
        ],
        d,
    ));
    std::fs::create_dir(d.join("notes")).unwrap();
    std::fs::write(d.join("notes/a.txt"), "keep").unwrap();
    let o = voxlod(
        &["export", "bunny.voxlod", "--3d-tiles", "notes", "--force"],
        d,
    );
    assert!(!o.status.success());
    assert!(text(&o).contains("holds no tileset"), "{}", text(&o));
    // a file the user keeps beside a tileset, or inside one of its level folders, is never
    // removed, with --force either: refused, naming it, and the folder left as it was
    let replace = |d: &Path| {
        voxlod(
            &[
                "export",
                "bunny.voxlod",
                "--3d-tiles",
                "coarse",
                "--level",
                "1",
                "--force",
            ],
            d,
        )
    };
    for (file, named) in [
        ("coarse/index.html", "index.html"),
        ("coarse/1/notes.txt", "notes.txt"),
    ] {
        std::fs::write(d.join(file), "mine").unwrap();
        let (top, level1) = (listing(&d.join("coarse")), listing(&d.join("coarse/1")));
        let o = replace(d);
        let t = text(&o);
        assert!(!o.status.success(), "{t}");
        assert!(
            t.contains(named) && t.contains("not part of a tileset"),
            "{t}"
        );
        assert_eq!(listing(&d.join("coarse")), top);
        assert_eq!(listing(&d.join("coarse/1")), level1);
        assert_eq!(std::fs::read(d.join(file)).unwrap(), b"mine");
        std::fs::remove_file(d.join(file)).unwrap();
    }
    ok(&replace(d));

    // the size guard: refused before a byte is written, naming the level that fits
    let before = listing(d);
    let o = voxlod(
        &[
            "export",
            "bunny.voxlod",
            "--3d-tiles",
            "big",
            "--max-size",
            "10MiB",
        ],
        d,
    );
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    assert!(t.contains("big: the export of level 0 would write "), "{t}");
    assert!(t.contains("Level 1 is the coarsest that fits"), "{t}");
    assert_eq!(listing(d), before, "no folder, no staging folder");

    // the model's up (the bunny's +y, as `render` takes it) is the tileset's +z
    let m = root_matrix(&ts);
    let up = apply(&m, [0.0, 1.0, 0.0], 0.0);
    assert!(
        (up[0].abs() + up[1].abs() + (up[2] - 1.0).abs()) < 1e-12,
        "{up:?}"
    );
    assert!(
        said.contains("up: 0,1,0 (default; --up to change) is the tileset's +z"),
        "{said}"
    );

    // a real consumer: three.js + 3d-tiles-renderer in headless Chromium, from voxlod's camera
    if !browser_tools() {
        return;
    }
    let (w, h) = (320u32, 240u32);
    let view = voxlod_render::View {
        width: w,
        height: h,
        up: [0.0, 1.0, 0.0],
        ..voxlod_render::View::default()
    };
    // at this size the root's voxels are about a pixel: the root alone is drawn
    let (result, iou) = compare_with_render(&r, &tiles, &view, 1, d, "full");
    let loaded = result["loaded"].as_array().unwrap();
    assert!(
        !loaded.is_empty() && loaded.iter().all(|u| u.as_str().unwrap().starts_with("1/")),
        "{result}"
    );
    assert!(iou >= 0.97, "silhouette IoU {iou:.4}");

    // closer: the root's voxels would be over 2 px, so at the renderer's default error target
    // (16 px) its children replace it (with the voxel edge as the error they would not)
    let near = voxlod_render::View { zoom: 4.0, ..view };
    let (shot, _) = voxlod_render::frame(&r, &near, voxlod_render::Lod::Level(0)).unwrap();
    let dist = (shot.eye - shot.target).length();
    let root_px = r.spec().voxel_size_at(1) * h as f64 / (dist * 2.0 * (shot.fov_y / 2.0).tan());
    assert!(root_px > 2.0 && root_px < 16.0, "root voxels {root_px} px");
    let (result, iou) = compare_with_render(&r, &tiles, &near, 0, d, "near");
    let loaded: Vec<&str> = result["loaded"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(
        loaded.iter().filter(|u| u.starts_with("0/")).count() >= 4,
        "{result}"
    );
    assert!(iou >= 0.97, "silhouette IoU {iou:.4} against level 0");
}

/// A model with materials: every tile's faces carry their voxel's material id as an
/// `EXT_mesh_features` feature id (checked face by face against the file's material channel in
/// `check_tile`), one primitive per material named as in the source, and the Khronos
/// validator reports no error or warning on it.
#[test]
fn materials_are_feature_ids() {
    let Some(m) = shared_meshes("materials_are_feature_ids") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = d.join("sib.voxlod");
    build_ok(
        &m.join("mcguire-sibenik/sibenik.obj"),
        &file,
        &["-r", "256"],
        d,
    );
    let r = Reader::open(&file).unwrap();
    assert!(r.has_materials());
    ok(&voxlod(&["export", "sib.voxlod", "--3d-tiles", "tiles"], d));
    let tiles = d.join("tiles");
    let ts: Value =
        serde_json::from_slice(&std::fs::read(tiles.join("tileset.json")).unwrap()).unwrap();
    let top = ts["geometricError"].as_f64().unwrap();
    check_tile(&r, r.root().unwrap(), &ts["root"], 0, &tiles, top);
    let names: Vec<String> = r.manifest().unwrap()["materials"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    let mut ids = std::collections::BTreeSet::new();
    for p in walk(&tiles)
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "glb"))
    {
        let (j, tris) = content_triangles(&std::fs::read(p).unwrap());
        assert!(j["extensionsUsed"]
            .as_array()
            .unwrap()
            .contains(&serde_json::json!("EXT_mesh_features")));
        for prim in j["meshes"][0]["primitives"].as_array().unwrap() {
            let f = &prim["extensions"]["EXT_mesh_features"]["featureIds"][0];
            assert_eq!(
                (f["attribute"].as_u64(), f["label"].as_str()),
                (Some(0), Some("material"))
            );
            assert_eq!(f["featureCount"], 1);
            // the primitive's material is named as the source's material of its faces
            let name = j["materials"][prim["material"].as_u64().unwrap() as usize]["name"]
                .as_str()
                .unwrap();
            assert!(names.iter().any(|n| n == name), "{name}");
        }
        ids.extend(tris.iter().map(|t| (t.0).2));
    }
    assert!(ids.len() >= 3, "material ids {ids:?}");
    // a tileset with nodes split in parts (`X-Y-Z-o-o.glb`) is the tileset's own: replaced by
    // --force
    assert!(walk(&tiles).iter().any(|p| p
        .file_name()
        .unwrap()
        .to_string_lossy()
        .matches('-')
        .count()
        >= 4));
    ok(&voxlod(
        &["export", "sib.voxlod", "--3d-tiles", "tiles", "--force"],
        d,
    ));
    if browser_tools() {
        let any = walk(&tiles)
            .into_iter()
            .find(|p| p.extension().is_some_and(|e| e == "glb"))
            .unwrap();
        let report = Command::new("node")
            .arg(Path::new(REPO).join("tests/node/validate-gltf.js"))
            .arg(&any)
            .output()
            .unwrap();
        let report: Value = serde_json::from_slice(&report.stdout).unwrap();
        assert_eq!(report["issues"]["numErrors"], 0, "{report}");
        assert_eq!(report["issues"]["numWarnings"], 0, "{report}");
    }
}

/// The same file gives the same tiles, byte for byte. `--origin LON,LAT,HEIGHT --units mm`:
/// the root transform is the east-north-up frame at that point (its translation the point's earth-centred coordinates, its up the ellipsoid's
/// normal there, which the model's up is turned onto), the model's bottom centre sits at the
/// frame's origin, and every length is in metres; bad values are refused by name.
#[test]
fn origin_and_units_place_the_tileset() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = d.join("s.voxlod");
    build_ok(&super::sample(), &file, &["-r", "512"], d);
    let r = Reader::open(&file).unwrap();
    ok(&voxlod(&["export", "s.voxlod", "--3d-tiles", "plain"], d));
    // the same file gives the same bytes
    ok(&voxlod(&["export", "s.voxlod", "--3d-tiles", "again"], d));
    let files = walk(&d.join("plain"));
    assert!(files.len() > 2);
    for f in &files {
        let again = d
            .join("again")
            .join(f.strip_prefix(d.join("plain")).unwrap());
        assert_eq!(
            std::fs::read(f).unwrap(),
            std::fs::read(again).unwrap(),
            "{f:?}"
        );
    }
    assert_eq!(walk(&d.join("again")).len(), files.len());
    let said = ok(&voxlod(
        &[
            "export",
            "s.voxlod",
            "--3d-tiles",
            "placed",
            "--origin",
            "7.44,46.95,600",
            "--units",
            "mm",
        ],
        d,
    ));
    assert!(
        said.contains("its bottom centre at longitude 7.44°, latitude 46.95°, height 600 m"),
        "{said}"
    );
    let read = |p: &str| -> Value {
        serde_json::from_slice(&std::fs::read(d.join(p).join("tileset.json")).unwrap()).unwrap()
    };
    let (plain, placed) = (read("plain"), read("placed"));
    let m = root_matrix(&placed);
    // WGS 84, written out: N = a / sqrt(1 − e² sin²φ)
    let (a, f) = (6378137.0f64, 1.0 / 298.257223563);
    let e2 = f * (2.0 - f);
    let (lon, lat) = (7.44f64.to_radians(), 46.95f64.to_radians());
    let n = a / (1.0 - e2 * lat.sin() * lat.sin()).sqrt();
    let ecef = [
        (n + 600.0) * lat.cos() * lon.cos(),
        (n + 600.0) * lat.cos() * lon.sin(),
        (n * (1.0 - e2) + 600.0) * lat.sin(),
    ];
    let t = apply(&m, [0.0; 3], 1.0);
    assert!(
        (0..3).all(|i| (t[i] - ecef[i]).abs() < 1e-6),
        "{t:?} {ecef:?}"
    );
    let normal = [lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin()];
    let up = apply(&m, [0.0, 1.0, 0.0], 0.0);
    assert!((0..3).all(|i| (up[i] - normal[i]).abs() < 1e-12), "{up:?}");
    // the frame: (file − bottom centre) · 0.001; the bottom centre of the root box is the
    // origin, and the boxes are the plain export's scaled
    let (plo, phi) = box_of(&plain["root"]);
    let (lo, hi) = box_of(&placed["root"]);
    for k in 0..3 {
        assert!(((hi[k] - lo[k]) - (phi[k] - plo[k]) * 0.001).abs() < 1e-12);
    }
    assert!(((lo[0] + hi[0]) / 2.0).abs() < 1e-12 && ((lo[2] + hi[2]) / 2.0).abs() < 1e-12);
    assert!(
        lo[1].abs() < 1e-12,
        "the model stands on the origin: {lo:?}"
    );
    let edge = r.spec().voxel_size_at(r.nodes()[r.root().unwrap()].level);
    // the root's error: 8 voxel edges, or the tileset's (16 model extents) where the root is
    // split in octants; in metres
    let e = placed["root"]["geometricError"].as_f64().unwrap();
    let top = 16.0 * 256.0 * edge * 0.001;
    assert!((placed["geometricError"].as_f64().unwrap() / top - 1.0).abs() < 1e-12);
    assert!(
        (e / (8.0 * edge * 0.001) - 1.0).abs() < 1e-12 || (e / top - 1.0).abs() < 1e-12,
        "{e}"
    );
    // refused by name
    for (args, says) in [
        (
            &["--origin", "200,0,0"][..],
            "longitude must be in -180..180",
        ),
        (&["--origin", "1,2"][..], "is not LON,LAT,HEIGHT"),
        (&["--units", "furlong"][..], "is not a unit"),
        (&["--units", "-1"][..], "is not a unit"),
    ] {
        let mut a = vec!["export", "s.voxlod", "--3d-tiles", "bad"];
        a.extend_from_slice(args);
        let o = voxlod(&a, d);
        assert!(!o.status.success());
        assert!(text(&o).contains(says), "{}", text(&o));
    }
}

/// Colours as displayed: glTF vertex colours are linear, so the tiles hold the linear value
/// of the stored sRGB colour, and three.js (its defaults: sRGB output) shows the banana's
/// colours as `voxlod render` does. Compared over the pixels both pictures cover, under
/// render's light: the mean colour's red over green (the banana's strong channels) within 3 %
/// and its brightness 0.95–1.3 times render's (three.js shades in linear light, render in
/// sRGB, so faces turned from the light are somewhat brighter in three.js, and its default
/// material adds a little white specular light, which lifts the banana's near-zero blue).
/// sRGB bytes written as if linear show about 1.8 times as bright with red over green 10 %
/// lower (each channel's linear value raised to 1/2.4).
#[test]
fn tileset_colours_show_as_voxlod_render_shows_them() {
    let Some(m) = shared_meshes("tileset_colours_show_as_voxlod_render_shows_them") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = d.join("banana.voxlod");
    build_ok(
        &m.join("ycb-banana-textured/textured_simple_reoriented.obj"),
        &file,
        &["-r", "256"],
        d,
    );
    ok(&voxlod(
        &["export", "banana.voxlod", "--3d-tiles", "tiles"],
        d,
    ));
    if !browser_tools() {
        return;
    }
    let r = Reader::open(&file).unwrap();
    let view = voxlod_render::View {
        width: 320,
        height: 240,
        ..voxlod_render::View::default()
    };
    let (ours, _, _, png) = three_and_render(&r, &d.join("tiles"), &view, 0, d, "colour");
    let theirs = image::open(&png).unwrap().to_rgb8();
    let (mut a, mut b, mut n) = ([0f64; 3], [0f64; 3], 0usize);
    for (k, p) in theirs.pixels().enumerate() {
        let q = &ours.rgba[4 * k..4 * k + 4];
        let magenta = p.0[0] > 250 && p.0[1] < 5 && p.0[2] > 250;
        if q[3] < 128 || magenta {
            continue;
        }
        for c in 0..3 {
            a[c] += q[c] as f64;
            b[c] += p.0[c] as f64;
        }
        n += 1;
    }
    assert!(n > 2000, "only {n} pixels in both pictures");
    let (a, b) = (a.map(|c| c / n as f64), b.map(|c| c / n as f64));
    eprintln!("mean sRGB over {n} pixels: voxlod render {a:.1?}, three.js {b:.1?}");
    // red over green (the banana's two strong channels) and their brightness
    let (ra, rb) = (a[0] / a[1], b[0] / b[1]);
    assert!(
        (rb / ra - 1.0).abs() < 0.03,
        "hue: render {a:.1?}, three.js {b:.1?}"
    );
    let bright = (b[0] + b[1]) / (a[0] + a[1]);
    assert!(
        bright > 0.95 && bright < 1.3,
        "brightness: render {a:.1?}, three.js {b:.1?}"
    );
}

/// The root tile's transform (column-major), the identity when it has none.
fn root_matrix(ts: &Value) -> [f64; 16] {
    match ts["root"].get("transform") {
        Some(t) => serde_json::from_value::<Vec<f64>>(t.clone())
            .unwrap()
            .try_into()
            .unwrap(),
        None => [
            1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ],
    }
}

/// `m · (v, w)` for a column-major 4×4 `m`.
fn apply(m: &[f64; 16], v: [f64; 3], w: f64) -> [f64; 3] {
    std::array::from_fn(|i| m[i] * v[0] + m[4 + i] * v[1] + m[8 + i] * v[2] + m[12 + i] * w)
}

/// Draws `tiles` with three.js + 3d-tiles-renderer from `view`'s camera (turned into the
/// tileset's frame by its root transform) and `voxlod render --level level` of the same view;
/// returns the page's result and the silhouettes' intersection over union, and keeps both
/// pictures in `d` (`three-NAME.png`, `render-NAME.png`).
fn compare_with_render(
    r: &Reader,
    tiles: &Path,
    view: &voxlod_render::View,
    level: u32,
    d: &Path,
    name: &str,
) -> (Value, f64) {
    let (ours, shot, result, png) = three_and_render(r, tiles, view, level, d, name);
    let (w, h) = (view.width, view.height);
    let a = ours.coverage();
    let (b, bw, bh) = silhouette(&png, [255, 0, 255]);
    assert_eq!((a.len(), bw, bh), ((w * h) as usize, w, h));
    let inter = a.iter().zip(&b).filter(|(x, y)| **x && **y).count();
    let union = a.iter().zip(&b).filter(|(x, y)| **x || **y).count();
    let iou = inter as f64 / union as f64;
    eprintln!(
        "{name}: silhouette IoU three.js vs voxlod render: {iou:.4} ({inter} / {union} pixels; eye {:?})",
        shot.eye
    );
    assert!(
        union > (w * h / 20) as usize,
        "the model covers too little of the picture"
    );
    (result, iou)
}

/// `voxlod render`'s picture of `view` at `level`, its camera, and three.js's result and
/// screenshot of the tileset from the same camera and light.
fn three_and_render(
    r: &Reader,
    tiles: &Path,
    view: &voxlod_render::View,
    level: u32,
    d: &Path,
    name: &str,
) -> (
    voxlod_render::Picture,
    voxlod_render::Shot,
    Value,
    std::path::PathBuf,
) {
    let (w, h) = (view.width, view.height);
    let (shot, nodes) = voxlod_render::frame(r, view, voxlod_render::Lod::Level(level)).unwrap();
    let ours = voxlod_render::Renderer::new()
        .unwrap()
        .render(r, &nodes, &shot)
        .unwrap();
    ours.write_png(&d.join(format!("render-{name}.png")))
        .unwrap();
    // voxlod render's light: from the upper left behind the eye, fixed to the camera
    let fwd = (shot.target - shot.eye).normalize();
    let right = fwd.cross(shot.up).normalize();
    let light = (-fwd * 0.8 + shot.up * 0.7 - right * 0.45).normalize();
    let ts: Value =
        serde_json::from_slice(&std::fs::read(tiles.join("tileset.json")).unwrap()).unwrap();
    let m = root_matrix(&ts);
    let shot_json = serde_json::json!({
        "eye": apply(&m, shot.eye.to_array(), 1.0),
        "target": apply(&m, shot.target.to_array(), 1.0),
        "up": apply(&m, shot.up.to_array(), 0.0),
        "light": apply(&m, light.to_array(), 0.0),
        "fov_y_deg": shot.fov_y.to_degrees(), "near": shot.near, "far": shot.far,
        "width": w, "height": h,
    })
    .to_string();
    let png = d.join(format!("three-{name}.png"));
    let o = Command::new("node")
        .arg(Path::new(REPO).join("tests/node/tiles-check.js"))
        .arg(tiles)
        .arg(&shot_json)
        .arg(&png)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let result: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(result["errors"], serde_json::json!([]), "{result}");
    (ours, shot, result, png)
}

/// Every file under `dir`.
fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}
