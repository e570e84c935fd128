//! Hostile inputs, as an attacker would write them (docs/RELIABILITY.md "Hostile files"): glTF
//! files breaking the specification's accessor, stride, GLB and node rules end with an error
//! naming the file and the rule (never a panic, never an endless traversal); every file voxlod
//! opens — inputs, MTL, textures, fly paths, plans, shards, settings files — is refused quickly
//! when it is `/dev/zero` or a FIFO; files a mesh refers to are read only inside its folder
//! unless `--allow-path` allows more, and a refusal never quotes the other file's content.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use voxlod_testkit::gltf::{write, Node, Prim};

use super::{sample, BIN};

/// Runs voxlod in `cwd`, killed (and the test failed) if it has not ended within `secs`.
fn run(args: &[&str], cwd: &Path, secs: u64) -> Output {
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("running voxlod");
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if start.elapsed() > Duration::from_secs(secs) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("voxlod {args:?} did not end within {secs} s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Ends with an error (exit status 1, not a panic's 101) whose message contains each of `want`.
fn refused(o: &Output, want: &[&str]) {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(1), "not an ordinary error: {e}");
    assert!(!e.contains("panicked"), "{e}");
    for w in want {
        assert!(e.contains(w), "the message lacks {w:?}: {e}");
    }
}

fn mkfifo(p: &Path) -> bool {
    Command::new("mkfifo")
        .arg(p)
        .status()
        .is_ok_and(|s| s.success())
}

/// The shared textured quad without a material (the files here have none).
fn quad() -> Prim {
    Prim {
        material: None,
        ..Prim::textured_quad()
    }
}

fn node() -> Node {
    Node {
        mesh: Some(0),
        ..Node::default()
    }
}

/// A triangle pair (indexed, with texture coordinates) as `.gltf` beside its `.bin`; the JSON
/// is then edited by `edit`.
fn gltf_edited(dir: &Path, name: &str, edit: impl Fn(&mut serde_json::Value)) -> PathBuf {
    let p = dir.join(name);
    write(&p, &[vec![quad()]], &[node()], &[0], &[]);
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
    edit(&mut v);
    std::fs::write(&p, serde_json::to_vec(&v).unwrap()).unwrap();
    p
}

/// Each malformed glTF the probe found panicking or accepted is refused, naming the file and
/// the rule it breaks.
#[test]
fn malformed_gltf_is_refused_with_the_rule() {
    let d = tempfile::tempdir().unwrap();
    // accessors of the quad: 0 POSITION, 1 TEXCOORD_0, 2 indices
    type Edit = fn(&mut serde_json::Value);
    let cases: [(&str, Edit, &str); 12] = [
        (
            "float_indices.gltf",
            |v| v["accessors"][2]["componentType"] = 5126.into(),
            "indices must be UNSIGNED_BYTE",
        ),
        (
            "vec3_indices.gltf",
            |v| v["meshes"][0]["primitives"][0]["indices"] = 0.into(),
            "indices must be SCALAR",
        ),
        (
            "uint_uv.gltf",
            |v| v["accessors"][1]["componentType"] = 5125.into(),
            "TEXCOORD must be VEC2",
        ),
        (
            "scalar_color.gltf",
            |v| v["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"] = 2.into(),
            "COLOR must be VEC3 or VEC4",
        ),
        (
            "stride4.gltf",
            |v| v["bufferViews"][0]["byteStride"] = 4.into(),
            "byteStride 4, less than the 12 bytes",
        ),
        (
            "ubyte_position.gltf",
            |v| {
                v["accessors"][0]["componentType"] = 5121.into();
                v["accessors"][0]["type"] = "SCALAR".into();
            },
            "POSITION must be VEC3 of FLOAT",
        ),
        (
            "huge_count.gltf",
            |v| v["accessors"][0]["count"] = u64::MAX.into(),
            "count 18446744073709551615",
        ),
        (
            "self_child.gltf",
            |v| v["nodes"][0]["children"] = serde_json::json!([0]),
            "lists itself as a child",
        ),
        (
            "two_node_cycle.gltf",
            |v| {
                v["nodes"] = serde_json::json!([{"mesh": 0}, {"children": [2]}, {"children": [1]}]);
            },
            "a cycle",
        ),
        (
            // read three times over before the rule was checked
            "repeated_roots.gltf",
            |v| v["scenes"][0]["nodes"] = serde_json::json!([0, 0, 0]),
            "lists node 0 twice; the root nodes of a scene must be unique",
        ),
        (
            // five indices: one triangle and two indices that make none
            "five_indices.gltf",
            |v| v["accessors"][2]["count"] = 5.into(),
            "mode TRIANGLES takes indices in threes (glTF 2.0, 3.7.2.1), but it has 5",
        ),
        (
            // the index is the bits of the first vertex's z (0.5): past the 4 vertices, which
            // the gltf crate's reader drops without a word
            "sparse_past_count.gltf",
            |v| {
                v["accessors"][0]["sparse"] = serde_json::json!({
                    "count": 1,
                    "indices": {"bufferView": 0, "byteOffset": 8, "componentType": 5125},
                    "values": {"bufferView": 0},
                });
            },
            "sparse index 0 is 1056964608, but the accessor has 4 elements",
        ),
    ];
    for (name, edit, rule) in cases {
        let p = gltf_edited(d.path(), name, edit);
        let o = run(
            &[
                "build",
                p.to_str().unwrap(),
                "-o",
                "o.voxlod",
                "-r",
                "256",
                "-q",
            ],
            d.path(),
            60,
        );
        refused(&o, &[name, rule]);
    }
}

/// A GLB whose header gives a length of 20, or whose last chunk declares 0xfffffff0 bytes, and
/// a glTF whose JSON is not UTF-8, are refused naming the rule.
#[test]
fn broken_glb_containers_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("q.glb");
    write(&p, &[vec![quad()]], &[node()], &[0], &[]);
    let glb = std::fs::read(&p).unwrap();
    let mut short = glb.clone();
    short[8..12].copy_from_slice(&20u32.to_le_bytes());
    let mut trailing = glb.clone();
    trailing.extend(0xffff_fff0u32.to_le_bytes());
    trailing.extend(*b"BIN\0");
    let n = trailing.len() as u32;
    trailing[8..12].copy_from_slice(&n.to_le_bytes());
    for (name, bytes, rule) in [
        ("short.glb", short, "gives the file's length as 20 bytes"),
        ("trailing.glb", trailing, "declares 4294967280 bytes"),
    ] {
        std::fs::write(d.path().join(name), bytes).unwrap();
        let o = run(&["build", name, "-o", "o.voxlod", "-q"], d.path(), 60);
        refused(&o, &[name, rule]);
    }
    let g = gltf_edited(d.path(), "latin1.gltf", |v| {
        v["asset"]["generator"] = "caf\u{e9}".into()
    });
    let text = std::fs::read(&g).unwrap();
    let at = text.windows(2).position(|w| w == "é".as_bytes()).unwrap();
    let mut latin1 = text[..at].to_vec();
    latin1.push(0xe9);
    latin1.extend(&text[at + 2..]);
    std::fs::write(&g, latin1).unwrap();
    let o = run(
        &["build", "latin1.gltf", "-o", "o.voxlod", "-q"],
        d.path(),
        60,
    );
    refused(&o, &["latin1.gltf", "not valid UTF-8"]);
}

/// `/dev/zero` and FIFOs wherever voxlod reads a file: each ends quickly, with an error (or,
/// for an MTL, a warning) that says what the path is.
#[test]
fn devices_and_fifos_are_refused_quickly() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let fifo = dir.join("fifo");
    if !mkfifo(&fifo) {
        voxlod_testkit::skipped(
            "hostile::devices_and_fifos_are_refused_quickly",
            "mkfifo is not available",
        );
        return;
    }
    let cwd = dir.to_str().unwrap();
    // an OBJ whose mtllib is /dev/zero (allowed folder) or a FIFO beside it
    for (lib, allow) in [("/dev/zero", "/dev"), ("fifo", cwd)] {
        std::fs::write(
            dir.join("m.obj"),
            format!("mtllib {lib}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n"),
        )
        .unwrap();
        let o = run(
            &[
                "build",
                "m.obj",
                "-o",
                "m.voxlod",
                "-r",
                "256",
                "-q",
                "--json",
                "--allow-path",
                allow,
                "--force",
            ],
            dir,
            60,
        );
        assert!(o.status.success(), "{lib}: {}", stderr(&o));
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(out.contains("not a regular file"), "{lib}: {out}");
    }
    let bunny = dir.join("b.voxlod");
    let o = run(
        &[
            "build",
            sample().to_str().unwrap(),
            "-o",
            "b.voxlod",
            "-r",
            "256",
            "-q",
        ],
        dir,
        300,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    for fly in ["/dev/zero", "fifo"] {
        let o = run(
            &[
                "view",
                bunny.to_str().unwrap(),
                "--fly",
                fly,
                "--frames",
                "frames",
                "--size",
                "32x24",
            ],
            dir,
            60,
        );
        refused(&o, &[fly, "not a regular file"]);
    }
    for config in ["/dev/zero", "fifo"] {
        let o = run(
            &["build", "m.obj", "-o", "c.voxlod", "--config", config, "-q"],
            dir,
            60,
        );
        refused(&o, &[config, "not a regular file"]);
    }
    for input in ["/dev/zero", "fifo"] {
        let o = run(&["inspect", input], dir, 60);
        refused(&o, &[input, "not a regular file"]);
    }
    // a plan that is a FIFO, and a merge whose shard is a FIFO
    let o = run(&["build", "--plan", "fifo", "--shard", "0", "-q"], dir, 60);
    refused(&o, &["fifo", "not a regular file"]);
    let o = run(
        &[
            "plan",
            sample().to_str().unwrap(),
            "-o",
            "plan.json",
            "--shards",
            "2",
            "-r",
            "256",
            "-q",
        ],
        dir,
        300,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(
        &["build", "--plan", "plan.json", "--shard", "0", "-q"],
        dir,
        300,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(mkfifo(&dir.join("shard-0001.vlshard")));
    let o = run(&["merge", "plan.json", "-o", "m2.voxlod", "-q"], dir, 60);
    refused(&o, &["shard-0001.vlshard", "not a regular file"]);
}

/// Files a mesh refers to outside its folder (`../`, an absolute path, a symlink, `%2E%2E`)
/// are refused with a message naming the file and `--allow-path`, never quoting its content;
/// `--allow-path` of their folder lets them be read.
#[test]
fn referenced_files_stay_in_the_mesh_folder() {
    let d = tempfile::tempdir().unwrap();
    let mesh = d.path().join("mesh");
    let other = d.path().join("other");
    std::fs::create_dir_all(&mesh).unwrap();
    std::fs::create_dir_all(&other).unwrap();
    // a secret that would make a telling error if read as a buffer or an MTL
    std::fs::write(other.join("secret.txt"), "newmtl TOPSECRET\nKd 1 0 0\n").unwrap();
    let other_s = other.to_str().unwrap();
    // glTF: the buffer by ../, %2E%2E, absolute path and symlink
    let q = mesh.join("q.gltf");
    write(&q, &[vec![quad()]], &[node()], &[0], &[]);
    std::fs::rename(mesh.join("q.bin"), other.join("q.bin")).unwrap();
    std::os::unix::fs::symlink(other.join("q.bin"), mesh.join("link.bin")).unwrap();
    let json = std::fs::read_to_string(&q).unwrap();
    let abs = other.join("q.bin");
    for uri in [
        "../other/q.bin",
        "%2E%2E/other/q.bin",
        abs.to_str().unwrap(),
        "link.bin",
    ] {
        std::fs::write(
            &q,
            json.replace(r#""uri":"q.bin""#, &format!(r#""uri":"{uri}""#)),
        )
        .unwrap();
        let o = run(
            &["build", "q.gltf", "-o", "q.voxlod", "-r", "256", "-q"],
            &mesh,
            60,
        );
        refused(&o, &["q.gltf", "outside the mesh's folder", "--allow-path"]);
        let o = run(
            &[
                "build",
                "q.gltf",
                "-o",
                "q.voxlod",
                "-r",
                "256",
                "-q",
                "--force",
                "--allow-path",
                other_s,
            ],
            &mesh,
            60,
        );
        assert!(
            o.status.success(),
            "{uri} with --allow-path: {}",
            stderr(&o)
        );
    }
    // OBJ: mtllib and map_Kd outside; PLY: TextureFile outside — warnings, no content quoted
    std::fs::write(
        mesh.join("m.obj"),
        "mtllib ../other/secret.txt\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl TOPSECRET\nf 1 2 3\n",
    )
    .unwrap();
    let o = run(
        &[
            "build", "m.obj", "-o", "m.voxlod", "-r", "256", "-q", "--json",
        ],
        &mesh,
        60,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("outside the mesh's folder"), "{out}");
    let image = other.join("t.png");
    image::RgbImage::from_pixel(2, 2, image::Rgb([255, 0, 0]))
        .save(&image)
        .unwrap();
    std::fs::write(
        mesh.join("t.mtl"),
        format!("newmtl a\nKd 1 1 1\nmap_Kd {}\n", image.display()),
    )
    .unwrap();
    std::fs::write(
        mesh.join("t.obj"),
        "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl a\nf 1/1 2/2 3/3\n",
    )
    .unwrap();
    let o = run(
        &[
            "build", "t.obj", "-o", "t.voxlod", "-r", "256", "-q", "--json",
        ],
        &mesh,
        60,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("t.png lies outside the mesh's folder"),
        "{out}"
    );
    let ply = mesh.join("t.ply");
    voxlod_testkit::textured::obj_to_textured_ply(
        &mesh.join("t.obj"),
        &ply,
        "../other/t.png",
        voxlod_testkit::textured::Convention::VertexST,
        [255; 4],
    );
    let o = run(
        &[
            "build", "t.ply", "-o", "p.voxlod", "-r", "256", "-q", "--json",
        ],
        &mesh,
        60,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("t.png lies outside the mesh's folder"),
        "{out}"
    );
    assert!(
        !out.contains("t.ply: t.ply"),
        "the path printed twice: {out}"
    );
    let o = run(
        &[
            "build",
            "t.ply",
            "-o",
            "p.voxlod",
            "-r",
            "256",
            "-q",
            "--json",
            "--force",
            "--allow-path",
            other_s,
        ],
        &mesh,
        60,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(!out.contains("outside"), "{out}");
}

/// `view --frames` follows the output rules of build, render and export: a frame path that is
/// a symlink or a hard link to the octree viewed is refused, and the octree is unchanged.
#[test]
fn view_frames_never_overwrite_the_octree() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let o = run(
        &[
            "build",
            sample().to_str().unwrap(),
            "-o",
            "b.voxlod",
            "-r",
            "256",
            "-q",
        ],
        dir,
        300,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let octree = dir.join("b.voxlod");
    let before = std::fs::read(&octree).unwrap();
    let fly = Path::new(super::REPO).join("configs/fly-in.json");
    type Link = fn(&Path, &Path) -> std::io::Result<()>;
    let links: [(&str, Link); 2] = [
        ("symlink", |a, b| std::os::unix::fs::symlink(a, b)),
        ("hard link", |a, b| std::fs::hard_link(a, b)),
    ];
    for (how, link) in links {
        let frames = dir.join(format!("frames-{}", how.replace(' ', "-")));
        std::fs::create_dir(&frames).unwrap();
        link(&octree, &frames.join("frame_00000.png")).unwrap();
        let o = run(
            &[
                "view",
                "b.voxlod",
                "--fly",
                fly.to_str().unwrap(),
                "--frames",
                frames.to_str().unwrap(),
                "--size",
                "32x24",
            ],
            dir,
            300,
        );
        assert!(!o.status.success(), "{how}: view wrote over the octree");
        assert!(
            stderr(&o).contains("frame_00000.png"),
            "{how}: {}",
            stderr(&o)
        );
        assert_eq!(
            std::fs::read(&octree).unwrap(),
            before,
            "{how}: the octree changed"
        );
    }
}
