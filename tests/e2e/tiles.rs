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

/// Checks the tile of node `i` and its subtree; returns the number of tiles.
fn check_tile(r: &Reader, i: usize, t: &Value, min_level: u32, dir: &Path) -> usize {
    let e = r.nodes()[i];
    let spec = r.spec();
    let edge = spec.voxel_size_at(e.level);
    let bx = box_of(t);
    // the node's voxels, decoded, lie in its box; its active faces are its content's quads
    let voxels = r.read_node(i).unwrap();
    let mut faces = 0u64;
    for v in &voxels {
        let lo = spec.voxel_min_corner(e.level, e.pos(), v.pos());
        let hi = lo.map(|c| c + edge);
        assert!(
            inside((lo, hi), bx, edge * 1e-6),
            "voxel {lo:?} outside {bx:?}"
        );
        faces += v.mask().count_ones() as u64;
    }
    if faces > 0 {
        let uri = t["content"]["uri"].as_str().unwrap();
        assert_eq!(uri, format!("{}/{}-{}-{}.glb", e.level, e.x, e.y, e.z));
        let glb = std::fs::read(dir.join(uri)).unwrap();
        let g = gltf::Gltf::from_slice_without_validation(&glb).unwrap();
        let indices: usize = g
            .meshes()
            .flat_map(|m| m.primitives())
            .map(|p| p.indices().unwrap().count())
            .sum();
        assert_eq!(indices as u64, 6 * faces, "{uri}");
        // glTF is y-up: the node is turned −90° about x for the consumer's y-up to z-up turn
        let n = g.nodes().find(|n| n.mesh().is_some()).unwrap();
        let (_, rot, _) = n.transform().decomposed();
        assert!(
            (rot[0] + std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-6 && rot[3] > 0.7,
            "{rot:?}"
        );
    } else {
        assert!(t.get("content").is_none());
    }
    let want: Vec<usize> = if e.level > min_level {
        r.children(i).into_iter().flatten().collect()
    } else {
        Vec::new()
    };
    let kids = t
        .get("children")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    assert_eq!(kids.len(), want.len(), "children of {:?}", e.pos());
    let error = t["geometricError"].as_f64().unwrap();
    assert_eq!(error, if want.is_empty() { 0.0 } else { edge });
    let mut n = 1;
    for (c, k) in want.iter().zip(&kids) {
        assert!(
            inside(box_of(k), bx, edge * 1e-6),
            "child box outside its parent's"
        );
        n += check_tile(r, *c, k, min_level, dir);
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
    let n = check_tile(&r, r.root().unwrap(), &ts["root"], 0, &tiles);
    assert_eq!(n, r.nodes().len());
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
            .arg(tiles.join("1/0-0-0.glb"))
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
        check_tile(&r, r.root().unwrap(), &ts1["root"], 1, &d.join("coarse")),
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
            "100MiB",
        ],
        d,
    );
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    assert!(t.contains("big: the export of level 0 would write "), "{t}");
    assert!(t.contains("Level 1 is the coarsest that fits"), "{t}");
    assert_eq!(listing(d), before, "no folder, no staging folder");

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
    // voxlod render's camera and picture of level 1 (what `voxlod render --level 1` draws)
    let (shot, nodes) = voxlod_render::frame(&r, &view, voxlod_render::Lod::Level(1)).unwrap();
    let ours = voxlod_render::Renderer::new()
        .unwrap()
        .render(&r, &nodes, &shot)
        .unwrap();
    let shot_json = serde_json::json!({
        "eye": shot.eye.to_array(), "target": shot.target.to_array(), "up": shot.up.to_array(),
        "fov_y_deg": shot.fov_y.to_degrees(), "near": shot.near, "far": shot.far,
        "width": w, "height": h,
    })
    .to_string();
    let shot_png = d.join("three.png");
    let o = Command::new("node")
        .arg(Path::new(REPO).join("tests/node/tiles-check.js"))
        .arg(&tiles)
        .arg(&shot_json)
        .arg(&shot_png)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let result: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(result["errors"], serde_json::json!([]), "{result}");
    // at this size the root's voxels are about a pixel: the root alone is drawn
    assert_eq!(
        result["loaded"],
        serde_json::json!(["1/0-0-0.glb"]),
        "{result}"
    );
    let a = ours.coverage();
    let (b, bw, bh) = silhouette(&shot_png, [255, 0, 255]);
    assert_eq!((a.len(), bw, bh), ((w * h) as usize, w, h));
    let inter = a.iter().zip(&b).filter(|(x, y)| **x && **y).count();
    let union = a.iter().zip(&b).filter(|(x, y)| **x || **y).count();
    let iou = inter as f64 / union as f64;
    eprintln!("silhouette IoU three.js vs voxlod render: {iou:.4} ({inter} / {union} pixels)");
    assert!(
        union > (w * h / 20) as usize,
        "the model covers too little of the picture"
    );
    assert!(iou >= 0.97, "silhouette IoU {iou:.4}");
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
