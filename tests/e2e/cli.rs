//! The bundled sample with no arguments, settings files against flags, and bad input.

use super::*;

#[test]
fn sample_builds_with_no_arguments_and_inspects() {
    let dir = tempfile::tempdir().unwrap();
    let o = voxlod(&["build", "-q", "--json"], dir.path());
    ok(&o);
    let summary: serde_json::Value =
        serde_json::from_slice(&o.stdout).expect("build --json output");
    let out = dir.path().join("bunny.voxlod");
    assert!(out.is_file());
    assert_eq!(summary["triangles"], 3674);
    assert_eq!(summary["resolution"], 1024);
    let per_level = check_octree(&out);
    assert_eq!(per_level.len(), 3);
    let o = voxlod(&["inspect", "--json", out.to_str().unwrap()], dir.path());
    ok(&o);
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // the summary states the grid in world units, as the file's header has it
    assert!(summary["voxel_size"].as_f64().unwrap() > 0.0, "{summary}");
    assert_eq!(summary["voxel_size"], info["voxel_size"]);
    assert_eq!(summary["origin"], info["origin"]);
    for (l, v) in per_level.iter().enumerate() {
        assert_eq!(info["per_level"][l]["voxels"], *v);
        assert_eq!(summary["levels"][l]["voxels"], *v);
    }
    assert_eq!(info["manifest"]["settings"]["resolution"], 1024);
    assert_eq!(info["mode"], "conservative");
    // coarser levels have fewer voxels, roughly a quarter per level for a surface
    assert!(
        per_level[1] < per_level[0] / 2 && per_level[2] < per_level[1] / 2,
        "{per_level:?}"
    );
    // text output names the levels
    let o = voxlod(&["inspect", out.to_str().unwrap()], dir.path());
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stdout).contains("bytes per voxel"));
    // nothing temporary is left behind
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 1, "{left:?}");
}

#[test]
fn bad_input_gives_clear_errors_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let valid_header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("garbage.ply", b"this is not a mesh at all".to_vec()),
        (
            "truncated.ply",
            format!("{valid_header}0 0 0\n1 0 0\n").into_bytes(),
        ),
        (
            "nan.ply",
            format!("{valid_header}0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n").into_bytes(),
        ),
        (
            "index.ply",
            format!("{valid_header}0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").into_bytes(),
        ),
        ("empty.stl", vec![]),
        ("mesh.xyz", b"1 2 3".to_vec()),
    ];
    for (name, bytes) in &cases {
        let input = d.join(name);
        std::fs::write(&input, bytes).unwrap();
        let out = d.join("out.voxlod");
        let o = voxlod(
            &[
                "build",
                "-q",
                input.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            d,
        );
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{name}: should fail");
        assert!(
            err.contains(name),
            "{name}: the error must name the file: {err}"
        );
        assert!(!err.contains("panicked"), "{name}: panic: {err}");
        assert!(!out.exists(), "{name}: an output file was left behind");
        let tmp_left = std::fs::read_dir(d)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .starts_with(".voxlod-work")
            })
            .count();
        assert_eq!(tmp_left, 0, "{name}: temporary files left behind");
    }
    let o = voxlod(&["build", "-q", d.join("missing.ply").to_str().unwrap()], d);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing.ply"));
    // a file that is not an octree
    let o = voxlod(&["inspect", d.join("garbage.ply").to_str().unwrap()], d);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("garbage.ply"));
    // bad settings
    let o = voxlod(
        &["build", "-q", sample().to_str().unwrap(), "-r", "1000"],
        d,
    );
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("256"));
    let o = voxlod(
        &[
            "build",
            "-q",
            sample().to_str().unwrap(),
            "--memory",
            "10MiB",
        ],
        d,
    );
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("too small"));
}

#[test]
fn config_file_with_flag_overrides() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cfg = d.join("c.toml");
    std::fs::write(
        &cfg,
        "resolution = 512\nmode = \"thin\"\nmemory = \"1GiB\"\n",
    )
    .unwrap();
    let out = d.join("o.voxlod");
    let run = |extra: &[&str]| {
        let mut args = vec!["--config", cfg.to_str().unwrap()];
        args.extend_from_slice(extra);
        build_ok(&sample(), &out, &args, d);
        let r = Reader::open(&out).unwrap();
        (r.header().resolution, r.header().mode)
    };
    assert_eq!(run(&[]), (512, 1));
    assert_eq!(run(&["-r", "256"]), (256, 1));
    assert_eq!(run(&["-m", "conservative"]), (512, 0));
    // the shipped presets parse
    for p in ["default", "preview", "scan"] {
        let path = Path::new(REPO).join(format!("configs/{p}.toml"));
        build_ok(
            &sample(),
            &out,
            &["--config", path.to_str().unwrap(), "-r", "256"],
            d,
        );
    }
    std::fs::write(&cfg, "resolutoin = 512\n").unwrap();
    let o = voxlod(
        &[
            "build",
            "-q",
            sample().to_str().unwrap(),
            "--config",
            cfg.to_str().unwrap(),
        ],
        d,
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("c.toml") && err.contains("resolutoin"),
        "{err}"
    );
}
