//! Source triangles in `render`: the npm bunny built with and without
//! `--source-geometry`. Close up, the cut leaves marked `over` (counted from `cut::select`) are
//! drawn from their triangles: the picture is not blank, has the voxels' silhouette (the
//! triangles lie inside the voxels they made), and differs from the voxel pictures. From afar
//! no leaf is over: nothing is drawn as triangles and the picture equals the voxel-only
//! build's byte for byte. No adapter is a FAILURE, not a skip.

use crate::common;

use voxlod_format::Reader;
use voxlod_render::{cut, frame, over_leaves, ColorBy, Lod, Renderer, View};
use voxlod_voxelize::Mode;

fn iou(a: &[bool], b: &[bool]) -> f64 {
    let inter = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
    let union = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
    inter as f64 / union.max(1) as f64
}

#[test]
fn over_leaves_are_drawn_from_source_triangles() {
    let Some(m) = common::meshes() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (src, vox) = (dir.path().join("src.voxlod"), dir.path().join("vox.voxlod"));
    common::build_with(&m, "npm-bunny/bunny.ply", &src, 512, Mode::Thin, true);
    common::build(&m, "npm-bunny/bunny.ply", &vox, 512, Mode::Thin);
    let (rs, rv) = (Reader::open(&src).unwrap(), Reader::open(&vox).unwrap());
    assert!(rs.has_source_triangles() && !rv.has_source_triangles());
    let renderer = match Renderer::new() {
        Ok(x) => x,
        Err(e) => panic!("no GPU adapter: the render test needs one (lavapipe: apt-get install mesa-vulkan-drivers libvulkan1): {e}"),
    };

    // close up: the leaves' voxels are several pixels wide
    let close = View {
        width: 240,
        height: 180,
        zoom: 2.5,
        ..View::default()
    };
    let lod = Lod::Error(1.0);
    let (shot, nodes) = frame(&rs, &close, lod).unwrap();
    let marked: Vec<usize> = cut::select(&rs, &shot, 1.0)
        .into_iter()
        .filter(|c| c.over)
        .map(|c| c.index)
        .collect();
    assert!(!marked.is_empty(), "the close-up should put leaves over");
    let with_triangles = marked
        .iter()
        .filter(|&&i| rs.source_triangles(i).unwrap().is_some())
        .count();
    assert_eq!(
        with_triangles,
        marked.len(),
        "every surface leaf stores triangles"
    );
    let source = over_leaves(&rs, &shot, lod);
    let tri = renderer
        .render_with_source(&rs, &nodes, &source, &shot, ColorBy::Voxel)
        .unwrap();
    let no_source = renderer.render(&rs, &nodes, &shot).unwrap();
    let (vshot, vnodes) = frame(&rv, &close, lod).unwrap();
    let voxel_only = renderer.render(&rv, &vnodes, &vshot).unwrap();
    eprintln!(
        "close: {} nodes, {} over, {} leaves as {} triangles, {} faces",
        nodes.len(),
        marked.len(),
        tri.source_leaves,
        tri.source_triangles,
        tri.faces_drawn
    );
    assert_eq!(tri.source_leaves as usize, marked.len());
    assert!(tri.source_triangles > 0);
    assert_eq!(no_source.source_leaves, 0);
    assert!(
        no_source.rgba == voxel_only.rgba,
        "voxels alone draw the same with or without the source channel"
    );
    assert!(
        tri.rgba != no_source.rgba,
        "triangles should change the picture"
    );
    let cov = tri.coverage();
    let frac = cov.iter().filter(|&&c| c).count() as f64 / cov.len() as f64;
    assert!(frac > 0.05, "triangle picture nearly blank: {frac:.3}");
    // the triangles lie inside their voxels: the silhouettes nearly agree
    let score = iou(&cov, &no_source.coverage());
    eprintln!("close: {frac:.3} covered, IoU with the voxels {score:.4}");
    assert!(score > 0.85, "IoU {score} of triangle and voxel coverage");

    // far: a small picture of the whole model, no leaf over, same bytes as voxels only
    let far = View {
        width: 96,
        height: 72,
        ..View::default()
    };
    let (shot, nodes) = frame(&rs, &far, lod).unwrap();
    assert!(cut::select(&rs, &shot, 1.0).iter().all(|c| !c.over));
    let source = over_leaves(&rs, &shot, lod);
    assert!(source.is_empty());
    let a = renderer
        .render_with_source(&rs, &nodes, &source, &shot, ColorBy::Voxel)
        .unwrap();
    let (vshot, vnodes) = frame(&rv, &far, lod).unwrap();
    let b = renderer.render(&rv, &vnodes, &vshot).unwrap();
    assert_eq!(a.source_leaves, 0);
    assert!(a.coverage().iter().any(|&c| c), "far picture blank");
    assert!(
        a.rgba == b.rgba,
        "far picture differs from the voxel-only build"
    );
}
