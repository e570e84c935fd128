//! Open surfaces seen from behind. A one-voxel-thick square sheet with its normal up (as a
//! voxelizer marks it: the +z face and the chunk border caps) is drawn from below: one-sided
//! (the default: only the mask's faces) nothing of it shows; two-sided it covers what it
//! covers from above, lit as its front would be (the normal turned towards the eye). On
//! closed surfaces seen from outside (the bunny) two-sided draws the same picture as
//! one-sided. No adapter is a FAILURE, not a skip.

use crate::common;

use glam::DVec3;
use voxlod_format::voxel::{border_caps, face_mask, pack_color, pack_normal, Voxel};
use voxlod_format::{encode_node, FileSpec, Reader, Writer, MODE_THIN};
use voxlod_render::{frame, Lod, Picture, Renderer, View};
use voxlod_voxelize::Mode;

/// The picture of level 0 seen from `direction`, and the renderer's light for it (from the
/// upper left behind the eye, fixed to the camera).
fn picture(r: &Reader, renderer: &Renderer, direction: [f64; 3], up: [f64; 3]) -> (Picture, DVec3) {
    let view = View {
        width: 200,
        height: 150,
        direction,
        up,
        ..Default::default()
    };
    let (shot, nodes) = frame(r, &view, Lod::Level(0)).unwrap();
    let fwd = (shot.target - shot.eye).normalize();
    let right = fwd.cross(shot.up).normalize();
    let light = (-fwd * 0.8 + shot.up * 0.7 - right * 0.45).normalize();
    (renderer.render(r, &nodes, &shot).unwrap(), light)
}

/// The red value of a white face with normal `n` under `light`: `255·(0.22 + 0.78·max(n·l, 0))`.
fn lit(n: DVec3, light: DVec3) -> f64 {
    255.0 * (0.22 + 0.78 * n.dot(light).max(0.0))
}

/// Covered pixels, and the mean of their red channel.
fn covered(p: &Picture) -> (usize, f64) {
    let px: Vec<&[u8]> = p.rgba.chunks_exact(4).filter(|c| c[3] >= 128).collect();
    let mean = px.iter().map(|c| c[0] as f64).sum::<f64>() / px.len().max(1) as f64;
    (px.len(), mean)
}

fn iou(a: &[bool], b: &[bool]) -> f64 {
    let inter = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
    let union = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
    inter as f64 / union.max(1) as f64
}

#[test]
fn an_open_sheet_is_drawn_and_lit_from_behind() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sheet.voxlod");
    let n = pack_normal([0.0, 0.0, 1.0]);
    let white = pack_color([255, 255, 255, 255]);
    let mut voxels = Vec::new();
    for y in 40..216u8 {
        for x in 40..216u8 {
            let p = [x, y, 128];
            voxels.push(Voxel::new(p, face_mask(n) | border_caps(p), n, white));
        }
    }
    voxels.sort_by_key(|v| v.morton());
    let mut w = Writer::create(&path, FileSpec::new(256, MODE_THIN, [0.0; 3], 0.1)).unwrap();
    w.write_node(0, [0, 0, 0], 0, &encode_node(&voxels, 3).unwrap())
        .unwrap();
    w.finish(&serde_json::json!({})).unwrap();
    let r = Reader::open(&path).unwrap();

    let mut renderer = common::renderer();
    assert!(!renderer.two_sided(), "one-sided by default");
    renderer.set_two_sided(true);
    let up = [0.0, 1.0, 0.0];
    let (above, light_above) = picture(&r, &renderer, [0.4, 0.3, 1.0], up);
    let (below, light_below) = picture(&r, &renderer, [0.4, 0.3, -1.0], up);
    renderer.set_two_sided(false);
    let (below_one, _) = picture(&r, &renderer, [0.4, 0.3, -1.0], up);
    let (above_one, _) = picture(&r, &renderer, [0.4, 0.3, 1.0], up);
    let (a, a_lit) = covered(&above);
    let (b, b_lit) = covered(&below);
    let (b1, _) = covered(&below_one);
    // the back is lit with the normal turned towards the eye (−z), the front with +z
    let (want_above, want_below) = (lit(DVec3::Z, light_above), lit(-DVec3::Z, light_below));
    eprintln!("above {a} px (red {a_lit:.1}, formula {want_above:.1}), below {b} px (red {b_lit:.1}, formula {want_below:.1}), below one-sided {b1} px");
    assert!(a > 5000, "{a} pixels from above");
    // from above the two modes agree exactly: every face drawn is a face of the mask
    assert_eq!(above.rgba, above_one.rgba);
    // from below: two-sided shows the sheet as from above (mirror image, same area) ...
    assert!((b as f64 - a as f64).abs() < 0.02 * a as f64, "{b} vs {a}");
    // ... lit as a front facing the eye would be, not by the ambient term alone (0.22 of
    // white is 56); the edge pixels blend with the background, hence the tolerance
    assert!(
        (a_lit - want_above).abs() < 0.05 * want_above,
        "{a_lit} vs {want_above}"
    );
    assert!(
        (b_lit - want_below).abs() < 0.05 * want_below,
        "{b_lit} vs {want_below}"
    );
    assert!(want_below > 1.5 * 56.0, "{want_below}");
    // one-sided, seen from behind, the sheet is missing
    assert!(b1 < a / 50, "{b1} pixels one-sided from below");
    assert_eq!(above.faces_drawn, below.faces_drawn);
    assert_eq!(below_one.faces_drawn, 0);
}

#[test]
fn closed_surfaces_look_the_same_two_sided() {
    let Some(m) = common::meshes() else { return };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bunny.voxlod");
    common::build(&m, "npm-bunny/bunny.ply", &file, 512, Mode::Thin);
    let r = Reader::open(&file).unwrap();
    let mut renderer = common::renderer();
    renderer.set_two_sided(true);
    for direction in [[0.55, 0.35, 1.0], [-1.0, 0.2, -0.3]] {
        let (two, _) = picture(&r, &renderer, direction, [0.0, 1.0, 0.0]);
        renderer.set_two_sided(false);
        let (one, _) = picture(&r, &renderer, direction, [0.0, 1.0, 0.0]);
        renderer.set_two_sided(true);
        let score = iou(&two.coverage(), &one.coverage());
        let same = two
            .rgba
            .chunks_exact(4)
            .zip(one.rgba.chunks_exact(4))
            .filter(|(p, q)| p == q)
            .count() as f64
            / (two.rgba.len() / 4) as f64;
        eprintln!("{direction:?}: IoU {score:.4}, same pixels {same:.4}");
        assert!(score >= 0.99, "{direction:?}: IoU {score}");
        assert!(same >= 0.99, "{direction:?}: {same} of the pixels equal");
    }
}
