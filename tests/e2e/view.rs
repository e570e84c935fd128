//! `voxlod view FILE --fly PATH --frames DIR`: the headless viewer through the binary, on the
//! bundled sample along the shipped fly-in (`configs/fly-in.json`), with small budgets: one
//! PNG and one JSON line per frame, the budgets hold in every line, the last picture shows the
//! model; a broken path file is a clear error. Needs a GPU adapter (lavapipe in CI): no
//! adapter is a failure.

use std::path::Path;

use super::*;

#[test]
fn view_flies_a_path_to_pngs_within_budgets() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bunny.voxlod");
    let args = build_args(&sample(), &file, &["--resolution", "512"]);
    ok(&voxlod(
        &args.iter().map(|s| s.as_str()).collect::<Vec<_>>(),
        dir.path(),
    ));
    let fly = Path::new(REPO).join("configs/fly-in.json");
    let frames = dir.path().join("frames");
    let o = voxlod(
        &[
            "view",
            file.to_str().unwrap(),
            "--fly",
            fly.to_str().unwrap(),
            "--frames",
            frames.to_str().unwrap(),
            "--size",
            "96x72",
            "--cache-mib",
            "4",
            "--upload-kib-per-frame",
            "512",
        ],
        dir.path(),
    );
    ok(&o);
    let lines: Vec<serde_json::Value> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
        .collect();
    assert_eq!(lines.len(), 24, "the fly-in has 24 frames");
    for (i, s) in lines.iter().enumerate() {
        assert_eq!(s["frame"], i);
        assert_eq!(s["cache_budget"], 4 << 20);
        assert_eq!(s["upload_limit"], 512 << 10);
        assert!(s["bytes_resident"].as_u64().unwrap() <= 4 << 20, "{s}");
        assert!(s["bytes_uploaded"].as_u64().unwrap() <= 512 << 10, "{s}");
        for key in [
            "nodes_resident",
            "cache_hits",
            "cache_misses",
            "evictions",
            "cut_nodes",
        ] {
            assert!(s[key].is_u64(), "{key} in {s}");
        }
        assert!(frames.join(format!("frame_{i:05}.png")).is_file());
    }
    assert!(lines.last().unwrap()["drawn_nodes"].as_u64().unwrap() > 0);
    let last = image::open(frames.join("frame_00023.png"))
        .unwrap()
        .to_rgb8();
    assert_eq!(last.dimensions(), (96, 72));
    let bg = voxlod_render_background();
    let model = last.pixels().filter(|p| p.0 != bg).count();
    assert!(model > 96 * 72 / 20, "{model} pixels show the model");

    // a broken path file: an error naming it, no panic, no frames
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"keyframes": [], "frames": 3}"#).unwrap();
    let o = voxlod(
        &[
            "view",
            file.to_str().unwrap(),
            "--fly",
            bad.to_str().unwrap(),
            "--frames",
            "f2",
        ],
        dir.path(),
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("bad.json") && err.contains("no keyframes"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");

    // a frames folder under a missing folder is not created
    let deep = dir.path().join("missing/frames");
    let o = voxlod(
        &[
            "view",
            file.to_str().unwrap(),
            "--fly",
            fly.to_str().unwrap(),
            "--frames",
            deep.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("parent folder must exist"), "{err}");
    assert!(!dir.path().join("missing").exists());
}

/// The renderer's clear colour (`voxlod_render::BACKGROUND`, light grey).
fn voxlod_render_background() -> [u8; 3] {
    [236, 238, 242]
}
