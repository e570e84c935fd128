//! The streamed entry point (`voxelize_chunk_streamed`: a chunk's triangles replayed in small
//! batches, two triangle buffers in flight, the second pass left out when the host sees it
//! would draw nothing) against one-batch voxelization, and the small/large split
//! (`last_split`) against a CPU recomputation of the classification rule of
//! shaders/classify.wgsl. These tests need an adapter (lavapipe is enough): without one they
//! FAIL.

use crate::common;

use common::*;
use voxlod_format::Voxel;
use voxlod_geom::Triangle;
use voxlod_gpu::{Feed, GpuError, GpuMethod, GpuVoxelizer, DEFAULT_CUTOFF};
use voxlod_voxelize::Mode;

/// `tris` through the streamed entry point in caller batches of `piece` triangles; returns the
/// voxels, the split and how many times the chunk was replayed.
fn streamed(
    g: &mut GpuVoxelizer,
    origin: [u32; 3],
    tris: &[Triangle],
    piece: usize,
) -> (Vec<Voxel>, (u64, u64), usize) {
    let mut replays = 0;
    let v = g
        .voxelize_chunk_streamed(origin, &mut |feed: &mut Feed<'_>| {
            replays += 1;
            for p in tris.chunks(piece) {
                feed(p);
            }
            Ok::<(), GpuError>(())
        })
        .unwrap();
    (v, g.last_split(), replays)
}

/// Every scheme and mode: small GPU batches fed in odd-sized pieces (with non-finite
/// triangles in between, which are skipped) give the same bytes and the same split as one
/// batch of the whole chunk.
fn same_as_one_batch(name: &str, origin: [u32; 3], tris: &[Triangle], batch: usize, window: u64) {
    let mut g = gpu();
    g.set_max_window(window);
    let mut noisy = Vec::with_capacity(tris.len() + tris.len() / 50);
    for (i, t) in tris.iter().enumerate() {
        if i % 50 == 7 {
            let mut bad = *t;
            bad.v[1][2] = f32::NAN;
            noisy.push(bad);
        }
        noisy.push(*t);
    }
    for mode in [Mode::Conservative, Mode::Thin] {
        g.set_mode(mode);
        for m in [GpuMethod::Hybrid, GpuMethod::Triangle, GpuMethod::Fragment] {
            g.set_method(m, DEFAULT_CUTOFF);
            g.set_batch_size(usize::MAX);
            let (want, want_split, _) = streamed(&mut g, origin, tris, tris.len());
            assert!(!want.is_empty());
            g.set_batch_size(batch);
            let (got, split, replays) = streamed(&mut g, origin, &noisy, 7);
            eprintln!(
                "{name} {mode} {m}: {} voxels, split {split:?}, {replays} replays",
                got.len()
            );
            assert!(replays >= 2, "{name}: a multi-batch chunk is replayed");
            assert_eq!(split, want_split, "{name} {mode} {m}: split");
            assert!(
                got == want,
                "{name} {mode} {m}: streamed batches differ from one batch: {:?}",
                compare(&want, &got)
            );
            // and the slice wrapper
            assert!(g.voxelize_chunk(origin, &noisy).unwrap() == want);
        }
    }
}

#[test]
fn npm_bunny_in_small_batches() {
    let Some(dir) = meshes_dir() else { return };
    let tris = load_mesh(&dir.join("npm-bunny/bunny.ply"));
    assert_eq!(tris.len(), 3674);
    let mut rng = Rng(7);
    // fitted to 256³, then shrunk to the middle 128³ of the chunk: a quarter of the voxels
    // and fragments (lavapipe's cost), the same triangles and batches as the whole chunk
    let tris: Vec<Triangle> = to_grid(&tris, 256)
        .into_iter()
        .enumerate()
        .map(|(i, t)| {
            let mut t = Triangle::new(t.v.map(|p| p.map(|x| 64.0 + 0.5 * x)));
            decorate(&mut t, &mut rng, i % 2 == 0);
            t
        })
        .collect();
    // GPU batches of 1,300 triangles: three batches of the chunk, so the mark pass and the
    // accumulation replay each cross two batch boundaries
    same_as_one_batch("npm-bunny@128 in a chunk", [0; 3], &tris, 1300, 1 << 19);
}

/// Two slightly tilted chunk-spanning planes (over 2^16 voxels: several accumulation windows
/// of 2^16 slots, each replaying the chunk) among small triangles, twelve triangles per batch.
/// (Nine planes, over 2^19 voxels for the default window, checked the same at three times
/// the CPU time: lavapipe's cost is the planes' fragments, drawn once more per window.)
#[test]
fn many_windows_in_small_batches() {
    let origin = [256, 0, 512];
    let mut rng = Rng(0xabcd);
    let mut tris = Vec::new();
    for k in 0..2 {
        let z = origin[2] as f32 + 10.0 + 27.0 * k as f32;
        let (x0, y0) = (origin[0] as f32 - 1.0, origin[1] as f32 - 1.0);
        let (x1, y1) = (x0 + 258.0, y0 + 258.0);
        for v in [
            [[x0, y0, z], [x1, y0, z + 3.0], [x0, y1, z + 1.0]],
            [[x1, y1, z + 4.0], [x0, y1, z + 1.0], [x1, y0, z + 3.0]],
        ] {
            let mut t = Triangle::new(v);
            decorate(&mut t, &mut rng, k % 2 == 0);
            tris.push(t);
        }
        for _ in 0..10 {
            let c = [0, 1, 2].map(|a| origin[a] as f32 + rng.range_f32(0.0, 256.0));
            let mut t = Triangle::new([0, 1, 2].map(|_| c.map(|x| x + rng.range_f32(-2.0, 2.0))));
            decorate(&mut t, &mut rng, true);
            tris.push(t);
        }
    }
    let window = 1 << 16;
    let mut g = gpu();
    g.set_mode(Mode::Thin);
    let (v, _, _) = streamed(&mut g, origin, &tris, tris.len());
    assert!(
        v.len() as u64 > window,
        "{} voxels: one window only",
        v.len()
    );
    same_as_one_batch("planes", origin, &tris, 12, window);
}

/// A replay that yields fewer triangles the second time is an error, not wrong voxels; the
/// replay's own errors come back unchanged.
#[test]
fn replay_errors() {
    let mut g = gpu();
    g.set_batch_size(2);
    let t = Triangle::new([[1.0, 1.0, 1.5], [9.0, 1.0, 1.5], [1.0, 9.0, 1.5]]);
    let want = g.voxelize_chunk([0; 3], &[t, t, t]).unwrap();
    assert!(!want.is_empty());
    let mut calls = 0;
    let r = g.voxelize_chunk_streamed([0; 3], &mut |feed: &mut Feed<'_>| {
        calls += 1;
        feed(&[t, t, t][..if calls == 1 { 3 } else { 2 }]);
        Ok::<(), GpuError>(())
    });
    assert!(
        matches!(r, Err(GpuError::Replay { first: 3, again: 2 })),
        "{r:?}"
    );
    #[derive(Debug)]
    #[allow(dead_code)] // the payload is only printed
    enum MyError {
        Disk,
        Gpu(GpuError),
    }
    impl From<GpuError> for MyError {
        fn from(e: GpuError) -> Self {
            MyError::Gpu(e)
        }
    }
    let r = g.voxelize_chunk_streamed([0; 3], &mut |feed: &mut Feed<'_>| {
        feed(&[t]);
        Err(MyError::Disk)
    });
    assert!(matches!(r, Err(MyError::Disk)), "{r:?}");
    // still usable afterwards
    assert!(g.voxelize_chunk([0; 3], &[t, t, t]).unwrap() == want);
}

/// The classification rule of shaders/classify.wgsl, recomputed on the CPU in f64: None for a
/// triangle the pass drops (zero area, outside the chunk), else whether it is voxelized in
/// the classification pass (dominant projected area under `cutoff`, at most 64 columns of the
/// dominant projection inside the chunk). Also returns the area and whether the dominant axis
/// is a near tie (the test avoids such triangles and areas near the cutoff).
fn classify_cpu(t: &Triangle, origin: [u32; 3], cutoff: f32) -> (Option<bool>, f64, bool) {
    let v = t.v.map(|p| p.map(f64::from));
    let e1 = [0, 1, 2].map(|k| v[1][k] - v[0][k]);
    let e2 = [0, 1, 2].map(|k| v[2][k] - v[0][k]);
    let n = [
        e1[1] * e2[2] - e1[2] * e2[1],
        e1[2] * e2[0] - e1[0] * e2[2],
        e1[0] * e2[1] - e1[1] * e2[0],
    ];
    let an = n.map(f64::abs);
    if an == [0.0; 3] {
        return (None, 0.0, false);
    }
    let axis = if an[2] >= an[0] && an[2] >= an[1] {
        2
    } else if an[0] >= an[1] {
        0
    } else {
        1
    };
    let mut sorted = an;
    sorted.sort_by(f64::total_cmp);
    let tie = sorted[1] > sorted[2] * (1.0 - 1e-6);
    let area = 0.5 * an[axis];
    let lo: [i64; 3] = std::array::from_fn(|k| {
        let mn = v[0][k].min(v[1][k]).min(v[2][k]);
        (mn.ceil() as i64 - 1).max(origin[k] as i64)
    });
    let hi: [i64; 3] = std::array::from_fn(|k| {
        let mx = v[0][k].max(v[1][k]).max(v[2][k]);
        (mx.floor() as i64).min(origin[k] as i64 + 255)
    });
    if (0..3).any(|k| lo[k] > hi[k]) {
        return (None, area, tie);
    }
    let columns: i64 = (0..3)
        .filter(|&k| k != axis)
        .map(|k| hi[k] - lo[k] + 1)
        .product();
    (Some((area as f32) < cutoff && columns <= 64), area, tie)
}

/// Random triangles inside one chunk with areas of 0–60 voxels² and extents of up to ~20
/// voxels: the split sums to the triangle count and matches the CPU recomputation, for
/// several cutoffs and per scheme; in batches of one triangle (so that every skipped second
/// pass is one triangle's decision), with and without skipping, the voxels are the same.
#[test]
fn split_matches_cpu_classification() {
    let origin = [256, 0, 512];
    let mut rng = Rng(0x5eed);
    let mut tris = Vec::new();
    while tris.len() < 1500 {
        let c = [0, 1, 2].map(|a| origin[a] as f32 + rng.range_f32(12.0, 244.0));
        let s = rng.range_f32(0.3, 10.0);
        let mut t = Triangle::new([0, 1, 2].map(|_| c.map(|x| x + rng.range_f32(-s, s))));
        let (class, area, tie) = classify_cpu(&t, origin, DEFAULT_CUTOFF);
        let near = |c: f64| (area - c).abs() < 1e-3 * c.max(1.0);
        if class.is_none() || tie || [2.0, DEFAULT_CUTOFF as f64, 32.0].into_iter().any(near) {
            continue;
        }
        decorate(&mut t, &mut rng, true);
        tris.push(t);
    }
    let n = tris.len() as u64;
    let mut g = gpu();
    for cutoff in [2.0f32, DEFAULT_CUTOFF, 32.0] {
        let small = tris
            .iter()
            .filter(|t| classify_cpu(t, origin, cutoff).0 == Some(true))
            .count() as u64;
        let inline = tris
            .iter()
            .filter(|t| classify_cpu(t, origin, f32::INFINITY).0 == Some(true))
            .count() as u64;
        eprintln!("cutoff {cutoff}: {small}/{n} small, {inline} within 64 columns");
        assert!(small > 0 && small < n, "cutoff {cutoff}: {small}/{n} small");
        for (m, want) in [
            (GpuMethod::Hybrid, (small, n - small)),
            (GpuMethod::Triangle, (inline, n - inline)),
            (GpuMethod::Fragment, (0, n)),
        ] {
            g.set_method(m, cutoff);
            g.set_batch_size(usize::MAX);
            g.voxelize_chunk(origin, &tris).unwrap();
            assert_eq!(g.last_split(), want, "{m} at cutoff {cutoff}");
        }
    }
    // one triangle per batch: a wrongly skipped fragment pass loses that triangle's voxels
    // (the first 400 triangles, a batch each: a quarter of the CPU time of all 1,500, with
    // many batches of either kind, asserted)
    let tris = &tris[..400];
    let large = tris
        .iter()
        .filter(|t| classify_cpu(t, origin, DEFAULT_CUTOFF).0 == Some(false))
        .count();
    assert!(large >= 20 && large <= 380, "{large} of 400 large");
    g.set_method(GpuMethod::Hybrid, DEFAULT_CUTOFF);
    g.set_batch_size(1);
    for mode in [Mode::Conservative, Mode::Thin] {
        g.set_mode(mode);
        g.set_skip_empty_passes(false);
        let all = g.voxelize_chunk(origin, tris).unwrap();
        g.set_skip_empty_passes(true);
        let skipping = g.voxelize_chunk(origin, tris).unwrap();
        assert!(
            all == skipping,
            "{mode}: skipping empty passes changed the voxels: {:?}",
            compare(&all, &skipping)
        );
    }
}
