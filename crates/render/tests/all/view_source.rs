//! The streaming viewer with source triangles, flown from afar to a close-up and
//! held there while the stream catches up: the npm bunny built with `--source-geometry` at
//! 512³, and a made-up dense sphere whose triangles outweigh its voxels (so they take several
//! frames under the upload limit while its voxels stay drawn). Checked every frame against
//! recomputations from the file: the leaves drawn as triangles are exactly the cut's `over`
//! leaves whose triangles are resident (and their triangle count and bytes the stored ones),
//! none from afar and some close up; nothing of the cut is missing from the picture (a leaf
//! waiting for its triangles is drawn from its voxels, or an ancestor stands in); the bytes
//! resident, recounted from the voxels' face masks and the stored meshes, never exceed the
//! budget, and the upload limit holds with triangles counted. `--no-source`
//! (`StreamConfig::source` off) draws no triangle. No adapter is a FAILURE, not a skip.

use crate::common;
use crate::viewing;

use std::collections::BTreeSet;

use viewing::{ancestors, voxel_bytes};
use voxlod_format::Reader;
use voxlod_render::view::{FlyPath, FrameStats, StreamConfig, Viewer};
use voxlod_render::{cut, BACKGROUND};
use voxlod_testkit::mesh::{icosphere, write_ply};
use voxlod_voxelize::Mode;

/// From outside the bunny to a close-up of its back, then a rest there.
const BUNNY_PATH: &str = r#"{"keyframes": [
    {"eye": [0.5, 0.6, 3.6], "target": [0.0, 0.0, 0.0]},
    {"eye": [0.4, 0.45, 2.0], "target": [0.0, 0.05, 0.0]},
    {"eye": [0.2, 0.3, 0.6], "target": [0.0, 0.15, 0.0]},
    {"eye": [0.2, 0.3, 0.6], "target": [0.0, 0.15, 0.0]}
  ], "frames": 36}"#;

/// Towards the made-up sphere (radius 0.2 at the centre of the cube), then a rest close up.
const SPHERE_PATH: &str = r#"{"keyframes": [
    {"eye": [0.3, 0.4, 3.5], "target": [0.0, 0.0, 0.0]},
    {"eye": [0.3, 0.4, 3.5], "target": [0.0, 0.0, 0.0]},
    {"eye": [0.1, 0.15, 0.5], "target": [0.0, 0.0, 0.0]},
    {"eye": [0.1, 0.15, 0.5], "target": [0.0, 0.0, 0.0]}
  ], "frames": 24}"#;

/// Triangles stored beside node `i` and the bytes of their GPU entry: 28 bytes per stored
/// (shared) vertex, 12 per triangle.
fn triangle_entry(r: &Reader, i: usize) -> Option<(u64, u64)> {
    let m = r.source_triangles(i).unwrap()?;
    let t = m.triangles.len() as u64;
    Some((t, m.positions.len() as u64 * 28 + t * 12))
}

/// A checked frame: its counters, its pixels, and how many wanted leaves were drawn from
/// their voxels while their triangles were missing.
struct Checked {
    stats: FrameStats,
    rgba: Vec<u8>,
    waiting: usize,
}

/// Runs `path` with `config`, checking every frame (a frame with something drawn covers at
/// least `min_cover` of the picture).
fn run(r: &Reader, config: StreamConfig, path: &str, min_cover: f64) -> Vec<Checked> {
    let n = r.nodes().len();
    let faces: Vec<u64> = (0..n).map(|i| voxel_bytes(r, i)).collect();
    let tris: Vec<Option<(u64, u64)>> = (0..n).map(|i| triangle_entry(r, i)).collect();
    let path: FlyPath = serde_json::from_str(path).unwrap();
    let mut viewer = Viewer::new(r, common::renderer(), config).unwrap();
    let mut out = Vec::new();
    for i in 0..path.frames {
        let f = viewer
            .frame(&path.shot(i, viewer.bounds(), 160, 120))
            .unwrap();
        let s = f.stats.clone();
        let ctx = format!("frame {i}: {s:?}");
        assert!(s.bytes_resident <= config.cache_bytes, "{ctx}");
        assert!(s.bytes_uploaded <= config.upload_bytes_per_frame, "{ctx}");
        assert!(s.source_bytes_uploaded <= s.bytes_uploaded, "{ctx}");
        // the cache's bytes recounted from the file: the resident voxel nodes' faces and the
        // resident leaves' triangles (plus, while a request is pending, a partial upload)
        let stream = viewer.stream();
        let on_triangles = stream.resident_triangle_leaves();
        let recount: u64 = stream
            .resident_nodes()
            .iter()
            .map(|&i| faces[i])
            .sum::<u64>()
            + on_triangles
                .iter()
                .map(|&i| tris[i].expect("stored").1)
                .sum::<u64>();
        if s.pending == 0 {
            assert_eq!(recount, s.bytes_resident, "{ctx}");
        }
        assert!(recount <= s.bytes_resident, "{ctx}");
        let tri_bytes: u64 = on_triangles.iter().map(|&i| tris[i].unwrap().1).sum();
        assert_eq!(tri_bytes, s.source_bytes_resident, "{ctx}");
        // the leaves drawn as triangles: the cut's over leaves with resident triangles
        let want = cut::select(r, &f.picture.shot, config.max_error_px);
        let over: BTreeSet<usize> = want
            .iter()
            .filter(|c| c.over && tris[c.index].is_some())
            .map(|c| c.index)
            .collect();
        // (those an ancestor stands in for, while a sibling is missing, are not drawn at all)
        let drawn: BTreeSet<usize> = f.picture.nodes.iter().copied().collect();
        let expect: BTreeSet<usize> = if config.source {
            over.iter()
                .copied()
                .filter(|i| on_triangles.binary_search(i).is_ok())
                .filter(|&i| {
                    let stand_in = ancestors(r, i).iter().any(|a| drawn.contains(a));
                    assert_ne!(drawn.contains(&i), stand_in, "{ctx}: leaf {i}");
                    !stand_in
                })
                .collect()
        } else {
            BTreeSet::new()
        };
        let expect_tris: u64 = expect.iter().map(|&i| tris[i].unwrap().0).sum();
        assert_eq!(s.source_leaves_drawn, expect.len(), "{ctx}");
        assert_eq!(f.picture.source_leaves, expect.len() as u64, "{ctx}");
        assert_eq!(s.source_triangles_drawn, expect_tris, "{ctx}");
        assert_eq!(f.picture.source_triangles, expect_tris, "{ctx}");
        let expect_bytes: u64 = expect.iter().map(|&i| tris[i].unwrap().1).sum();
        assert_eq!(s.source_bytes_drawn, expect_bytes, "{ctx}");
        assert_eq!(
            s.source_leaves_wanted,
            if config.source { over.len() } else { 0 },
            "{ctx}"
        );
        // no hole: every cut node is drawn, or an ancestor stands in for it (a leaf waiting
        // for its triangles keeps its voxels drawn when they are resident)
        if s.drawn_nodes > 0 {
            let covered = f
                .picture
                .rgba
                .chunks_exact(4)
                .filter(|p| p[..3] != BACKGROUND[..])
                .count();
            let cover = covered as f64 / (f.picture.rgba.len() / 4) as f64;
            assert!(cover >= min_cover, "{ctx}: {cover:.4} covered");
            for c in &want {
                let stand_in = ancestors(r, c.index).iter().any(|a| drawn.contains(a));
                assert!(
                    drawn.contains(&c.index) || stand_in,
                    "{ctx}: hole at {}",
                    c.index
                );
            }
        }
        // wanted leaves drawn from their voxels while their triangles are on the way
        let waiting = over
            .iter()
            .filter(|i| !expect.contains(i) && drawn.contains(i))
            .count();
        out.push(Checked {
            stats: s,
            rgba: f.picture.rgba,
            waiting,
        });
    }
    out
}

#[test]
fn close_up_leaves_stream_as_source_triangles() {
    let Some(m) = common::meshes() else { return };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bunny.voxlod");
    common::build_with(&m, "npm-bunny/bunny.ply", &file, 512, Mode::Thin, true);
    let r = Reader::open(&file).unwrap();
    assert!(r.has_source_triangles());
    let config = StreamConfig {
        cache_bytes: 24 << 20,
        upload_bytes_per_frame: 2 << 20,
        max_error_px: 1.0,
        source: true,
        occlusion: false,
    };
    let mut frames = run(&r, config, BUNNY_PATH, 0.02);
    let close_up = std::mem::take(&mut frames.last_mut().unwrap().rgba);
    let with: Vec<FrameStats> = frames.into_iter().map(|c| c.stats).collect();
    for s in &with {
        eprintln!("{}", serde_json::to_string(s).unwrap());
    }
    let (first, last) = (&with[0], with.last().unwrap());
    // afar no leaf is over the error; close up some are, and are drawn as triangles
    assert_eq!((first.cut_over_error, first.source_leaves_drawn), (0, 0));
    assert!(with[..4].iter().all(|s| s.source_leaves_drawn == 0));
    assert!(last.source_leaves_wanted > 0, "{last:?}");
    assert_eq!(
        last.source_leaves_drawn, last.source_leaves_wanted,
        "{last:?}"
    );
    // the triangles were uploaded, every stored byte of them once
    let uploaded: u64 = with.iter().map(|s| s.source_bytes_uploaded).sum();
    assert_eq!(uploaded, last.source_bytes_resident);

    // --no-source: no triangle, and the frames of a build without the channel, byte for byte
    let no_source = StreamConfig {
        source: false,
        ..config
    };
    let without = run(&r, no_source, BUNNY_PATH, 0.02);
    assert!(without
        .iter()
        .all(|c| c.stats.source_leaves_drawn == 0 && c.stats.source_bytes_resident == 0));
    let last = &without.last().unwrap().stats;
    assert!(last.cut_over_error > 0 && last.drawn_nodes > 0, "{last:?}");
    let plain = dir.path().join("plain.voxlod");
    common::build(&m, "npm-bunny/bunny.ply", &plain, 512, Mode::Thin);
    let voxels = run(&Reader::open(&plain).unwrap(), config, BUNNY_PATH, 0.02);
    assert_eq!(voxels.len(), without.len());
    for (k, (a, b)) in without.iter().zip(&voxels).enumerate() {
        // the same counters (the draw's wall time aside)
        let timeless = |s: &FrameStats| FrameStats {
            draw_ms: 0.0,
            ..s.clone()
        };
        assert_eq!(timeless(&a.stats), timeless(&b.stats), "frame {k}");
        assert!(
            a.rgba == b.rgba,
            "frame {k} differs from the voxel-only build's"
        );
    }
    assert!(
        close_up != without.last().unwrap().rgba,
        "the triangles do not change the close-up"
    );
}

/// A dense sphere (81,920 triangles of radius 0.2 at the centre of the bounding cube [−1, 1]³,
/// which two tiny triangles at opposite corners span) at 256³: one leaf chunk, its source
/// triangles (about 2 MB on the GPU) several times its voxel faces.
fn dense_sphere(dir: &std::path::Path) -> std::path::PathBuf {
    let (mut v, mut f) = icosphere(6);
    v.iter_mut().for_each(|p| *p = p.map(|x| 0.2 * x));
    for c in [-1.0, 1.0] {
        let n = v.len() as u32;
        let d = -0.01 * c;
        v.extend([[c, c, c], [c + d, c, c], [c, c + d, c]]);
        f.push([n, n + 1, n + 2]);
    }
    let ply = dir.join("sphere.ply");
    write_ply(&ply, &(v, f));
    let out = dir.join("sphere.voxlod");
    common::build_with(dir, "sphere.ply", &out, 256, Mode::Thin, true);
    out
}

#[test]
fn triangles_heavier_than_voxels_arrive_while_the_voxels_stay_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let r = Reader::open(&dense_sphere(dir.path())).unwrap();
    let leaf = r.root().unwrap();
    assert_eq!(r.nodes().len(), 1);
    let (tris, tri_bytes) = triangle_entry(&r, leaf).unwrap();
    let voxel_bytes = voxel_bytes(&r, leaf);
    eprintln!("{tris} triangles, {tri_bytes} bytes; faces {voxel_bytes} bytes");
    assert!(tris >= 81920 && tri_bytes > 2 * voxel_bytes);
    let config = StreamConfig {
        cache_bytes: 4 << 20,
        upload_bytes_per_frame: 256 << 10,
        max_error_px: 1.0,
        source: true,
        occlusion: false,
    };
    assert!(tri_bytes + voxel_bytes <= config.cache_bytes);
    let (stats, waiting): (Vec<FrameStats>, Vec<usize>) = run(&r, config, SPHERE_PATH, 0.005)
        .into_iter()
        .map(|c| (c.stats, c.waiting))
        .unzip();
    for s in &stats {
        eprintln!("{}", serde_json::to_string(s).unwrap());
    }
    // from afar the leaf is drawn from its voxels; close up it is wanted as triangles, which
    // take several frames under the limit (it binds on them) while its voxels stay drawn
    assert_eq!(stats[0].source_leaves_wanted, 0);
    assert!(stats
        .iter()
        .any(|s| s.drawn_nodes == 1 && s.source_leaves_drawn == 0));
    let frames_waiting = waiting.iter().filter(|&&w| w == 1).count() as u64;
    assert!(
        frames_waiting >= tri_bytes / config.upload_bytes_per_frame,
        "{waiting:?}"
    );
    assert!(stats
        .iter()
        .any(|s| s.source_bytes_uploaded == config.upload_bytes_per_frame));
    let last = stats.last().unwrap();
    assert_eq!(
        (last.source_leaves_drawn, last.source_triangles_drawn),
        (1, tris)
    );
    assert_eq!(last.bytes_resident, tri_bytes + voxel_bytes, "{last:?}");
}
