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
    let budgets = [
        "--cache-mib",
        "4",
        "--upload-kib-per-frame",
        "512",
        "--real-time",
    ];
    let (lines, pixels) = fly_in(&file, &frames, &budgets);
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
    }
    assert!(lines.last().unwrap()["drawn_nodes"].as_u64().unwrap() > 0);
    let last = image::open(frames.join("frame_00023.png"))
        .unwrap()
        .to_rgb8();
    assert_eq!(last.dimensions(), (96, 72));
    let model = pixels[23];
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

/// Pixels of a frame that are not the background.
fn model_pixels(png: &Path) -> usize {
    let bg = voxlod_render_background();
    let img = image::open(png).unwrap().to_rgb8();
    img.pixels().filter(|p| p.0 != bg).count()
}

/// The fly-in's frames lines and the model pixels of each frame, with `extra` options.
fn fly_in(file: &Path, frames: &Path, extra: &[&str]) -> (Vec<serde_json::Value>, Vec<usize>) {
    let fly = Path::new(REPO).join("configs/fly-in.json");
    let mut args = vec![
        "view",
        file.to_str().unwrap(),
        "--fly",
        fly.to_str().unwrap(),
        "--frames",
        frames.to_str().unwrap(),
        "--size",
        "96x72",
    ];
    args.extend(extra);
    let out = ok(&voxlod(&args, frames.parent().unwrap()));
    let lines: Vec<serde_json::Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
        .collect();
    let pixels = (0..lines.len())
        .map(|i| model_pixels(&frames.join(format!("frame_{i:05}.png"))))
        .collect();
    (lines, pixels)
}

/// Headless frames are complete by default: with an upload limit far below the root's size,
/// every frame of the fly-in still shows the model and draws its whole cut (nothing pending,
/// the close-up down to level 0), where `--real-time` frames show nothing until the root has
/// arrived, and its close-up fewer levels. Before complete frames, frames 0–2 of the fly-in
/// were blank grey and its close-up showed only the root level at the default limit.
#[test]
fn fly_frames_are_complete_unless_real_time() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bunny.voxlod");
    let args = build_args(&sample(), &file, &["--resolution", "1024"]);
    ok(&voxlod(
        &args.iter().map(|s| s.as_str()).collect::<Vec<_>>(),
        dir.path(),
    ));
    let limit = ["--upload-kib-per-frame", "64"];
    let (complete, pixels) = fly_in(&file, &dir.path().join("complete"), &limit);
    assert_eq!(complete.len(), 24);
    for (i, (s, &px)) in complete.iter().zip(&pixels).enumerate() {
        assert_eq!(s["frame"], i);
        assert_eq!(s["pending"], 0, "frame {i}: {s}");
        assert_eq!(s["drawn_nodes"], s["cut_nodes"], "frame {i}: {s}");
        assert!(px > 96 * 72 / 50, "frame {i}: {px} pixels show the model");
        let passes = s["passes"].as_u64().unwrap();
        // each pass uploads at most the limit
        assert!(
            s["bytes_uploaded"].as_u64().unwrap() <= passes * (64 << 10),
            "{s}"
        );
    }
    assert!(
        complete[0]["passes"].as_u64().unwrap() > 1,
        "{}",
        complete[0]
    );
    let last = complete.last().unwrap();
    assert_eq!(last["finest_level_drawn"], 0, "{last}");
    // the GPU holds 12 bytes per resident voxel (nothing partly uploaded in a complete frame)
    for s in &complete {
        let voxel_bytes =
            s["bytes_resident"].as_u64().unwrap() - s["source_bytes_resident"].as_u64().unwrap();
        assert_eq!(
            voxel_bytes,
            12 * s["voxels_resident"].as_u64().unwrap(),
            "{s}"
        );
        assert!(
            s["occluded_nodes"].is_u64() && s["draws"].as_u64().unwrap() >= 1,
            "{s}"
        );
    }
    // without occlusion culling: nothing occluded, the same pictures
    let (plain, plain_pixels) = fly_in(
        &file,
        &dir.path().join("plain"),
        &[limit[0], limit[1], "--no-occlusion"],
    );
    for (i, s) in plain.iter().enumerate() {
        assert_eq!(s["occluded_nodes"], 0, "{s}");
        assert_eq!(s["probe_nodes"], 0, "{s}");
        let (a, b) = (pixels[i] as f64, plain_pixels[i] as f64);
        assert!(
            (a - b).abs() <= 0.01 * b,
            "frame {i}: {a} vs {b} model pixels"
        );
    }

    let (real, real_pixels) = fly_in(
        &file,
        &dir.path().join("real"),
        &[limit[0], limit[1], "--real-time"],
    );
    assert_eq!(real.len(), 24);
    for s in &real {
        assert_eq!(s["passes"], 1, "{s}");
        assert!(s["bytes_uploaded"].as_u64().unwrap() <= 64 << 10, "{s}");
    }
    assert_eq!(real[0]["drawn_nodes"], 0, "{}", real[0]);
    assert_eq!(real_pixels[0], 0);
    assert!(real.last().unwrap()["pending"].as_u64().unwrap() > 0);
}

/// Without a display, the window is not attempted: the error says what to do (`--fly`, or a
/// virtual display with `xvfb-run`), not a path inside winit's source.
#[test]
fn view_without_a_display_suggests_fly_or_xvfb() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bunny.voxlod");
    let args = build_args(&sample(), &file, &["--resolution", "256"]);
    ok(&voxlod(
        &args.iter().map(|s| s.as_str()).collect::<Vec<_>>(),
        dir.path(),
    ));
    let o = std::process::Command::new(BIN)
        .arg("view")
        .arg(&file)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        .env("NO_COLOR", "1")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no display"), "{err}");
    assert!(err.contains("--fly") && err.contains("xvfb-run"), "{err}");
    assert!(!err.contains(".cargo") && !err.contains(".rs:"), "{err}");
}

/// The renderer's clear colour (`voxlod_render::BACKGROUND`, light grey).
fn voxlod_render_background() -> [u8; 3] {
    [236, 238, 242]
}
