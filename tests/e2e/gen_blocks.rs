//! `voxlod gen --kind blocks`: the block world from the command line (the world itself is
//! checked against its block grid in `crates/blocks/tests`): the same bytes for the same seed,
//! a build whose manifest names the nine face materials in MTL order, and clear errors for
//! options of the other kind, an existing output and a size out of range.

use super::*;

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_name().to_string_lossy().starts_with("w"))
        .map(|e| {
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn gen_blocks_writes_a_deterministic_textured_world() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let args = [
        "gen", "--kind", "blocks", "-o", "w.obj", "--size", "32", "--seed", "4",
    ];
    for d in [a.path(), b.path()] {
        let o = voxlod(&args, d);
        ok(&o);
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            text.contains("a 32x32 block world (seed 4") && text.contains(" faces, "),
            "{text}"
        );
    }
    let (fa, fb) = (files(a.path()), files(b.path()));
    assert_eq!(fa.len(), 11, "OBJ, MTL and 9 textures");
    assert!(fa == fb, "the same seed gave other bytes");

    // built, it has the material channel with the MTL's materials in order
    let out = a.path().join("w.voxlod");
    build_ok(&a.path().join("w.obj"), &out, &["-r", "256"], a.path());
    let r = Reader::open(&out).unwrap();
    assert!(r.has_materials());
    assert_eq!(
        r.manifest().unwrap()["materials"],
        serde_json::json!([
            "",
            "grass_top",
            "grass_side",
            "dirt",
            "stone",
            "sand",
            "water",
            "log_top",
            "log_side",
            "leaves"
        ])
    );

    // errors: each names the problem, and nothing new is written
    let before = files(a.path());
    for (args, want) in [
        (&args[..], "w.obj exists (--force replaces it)"),
        (
            &["gen", "--kind", "blocks", "-o", "x.obj", "-n", "10"][..],
            "for --kind scan",
        ),
        (&["gen", "-o", "x.ply"][..], "needs the number of triangles"),
        (
            &["gen", "-o", "x.ply", "-n", "10", "--size", "64"][..],
            "--size is for --kind blocks",
        ),
        (
            &["gen", "--kind", "blocks", "-o", "x.obj", "--size", "16"][..],
            "32 to 2048",
        ),
        (
            &["gen", "--kind", "blocks", "-o", "x.ply"][..],
            "name the output NAME.obj",
        ),
    ] {
        let o = voxlod(args, a.path());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(want), "{args:?}: {err}");
    }
    assert!(files(a.path()) == before);
    assert!(!a.path().join("x.obj").exists() && !a.path().join("x.ply").exists());
}
