//! The GPU voxelizer against the CPU reference (`voxlod_voxelize::ChunkVoxelizer`), in both modes
//! and with all three schemes, on made-up triangles (small, large, slivers, axis-aligned, one
//! chunk-spanning triangle) and real meshes. These tests need an adapter (lavapipe is enough):
//! without one they FAIL.
//!
//! The contract (crate docs, "Exactness" and "Attributes"): the voxel sets are equal (chunks with
//! a decision the shaders cannot certify are re-voxelized on the CPU); normals agree within one
//! 10-bit step per component, colours within 1 per channel (the GPU sums in fixed point, the CPU
//! in f32).

use crate::common;

use common::*;
use voxlod_format::Voxel;
use voxlod_geom::Triangle;
use voxlod_gpu::{GpuMethod, GpuVoxelizer, DEFAULT_CUTOFF};
use voxlod_voxelize::Mode;

/// Runs every mode and scheme on one chunk, checks against the CPU and that the three schemes
/// agree bit for bit where none fell back to the CPU; returns the CPU voxel count.
fn check(g: &mut GpuVoxelizer, name: &str, origin: [u32; 3], tris: &[Triangle]) -> usize {
    let mut total = 0;
    for mode in [Mode::Conservative, Mode::Thin] {
        let want = cpu(mode, origin, tris);
        total += want.len();
        g.set_mode(mode);
        let mut first: Option<(Vec<Voxel>, bool)> = None;
        for m in METHODS {
            g.set_method(m, DEFAULT_CUTOFF);
            let got = g.voxelize_chunk(origin, tris).unwrap();
            let d = compare(&want, &got);
            let (small, large) = g.last_split();
            let fell_back = g.last_fell_back();
            eprintln!(
                "{name} {mode} {m}: split {small}/{large}, uncertain {}, on the CPU {fell_back}, {d:?}",
                g.last_uncertain()
            );
            assert!(
                d.only_cpu + d.only_gpu == 0,
                "{name} {mode} {m}: voxel sets differ: {d:?}"
            );
            if fell_back {
                assert!(
                    got == want,
                    "a chunk re-voxelized on the CPU has the CPU's bytes"
                );
            }
            assert_eq!(
                (d.normal, d.colour, d.mask),
                (0, 0, 0),
                "{name} {mode} {m}: attributes differ: {d:?}"
            );
            match m {
                GpuMethod::Fragment => assert_eq!(small, 0),
                GpuMethod::Triangle | GpuMethod::Hybrid => {}
            }
            match &first {
                None => first = Some((got, fell_back)),
                Some((f, f_back)) => assert!(
                    *f_back || fell_back || f == &got,
                    "{name} {mode}: {m} differs from hybrid: {:?}",
                    compare(f, &got)
                ),
            }
        }
    }
    total
}

fn o(origin: [u32; 3], p: [f32; 3]) -> [f32; 3] {
    [
        origin[0] as f32 + p[0],
        origin[1] as f32 + p[1],
        origin[2] as f32 + p[2],
    ]
}

fn random_point(rng: &mut Rng, origin: [u32; 3], lo: f32, hi: f32) -> [f32; 3] {
    o(
        origin,
        [
            rng.range_f32(lo, hi),
            rng.range_f32(lo, hi),
            rng.range_f32(lo, hi),
        ],
    )
}

#[test]
fn small_triangles() {
    let mut g = gpu();
    let mut rng = Rng(0x1234_5678);
    let origin = [256, 0, 512];
    let mut tris = Vec::new();
    for i in 0..4000 {
        let c = random_point(&mut rng, origin, -3.0, 259.0);
        let s = if i % 4 == 0 { 3.0 } else { 1.0 };
        let v = [0, 1, 2].map(|_| {
            [
                c[0] + rng.range_f32(-s, s),
                c[1] + rng.range_f32(-s, s),
                c[2] + rng.range_f32(-s, s),
            ]
        });
        let mut t = Triangle::new(v);
        decorate(&mut t, &mut rng, i % 2 == 0);
        tris.push(t);
    }
    assert!(check(&mut g, "small", origin, &tris) > 10_000);
}

#[test]
fn large_triangles() {
    let mut g = gpu();
    let mut rng = Rng(0x9e37_79b9);
    let origin = [0, 256, 0];
    let mut tris = Vec::new();
    for i in 0..16 {
        let v = [0, 1, 2].map(|_| random_point(&mut rng, origin, -80.0, 336.0));
        let mut t = Triangle::new(v);
        decorate(&mut t, &mut rng, i % 2 == 0);
        tris.push(t);
    }
    assert!(check(&mut g, "large", origin, &tris) > 100_000);
}

#[test]
fn slivers() {
    let mut g = gpu();
    let mut rng = Rng(42);
    let origin = [0, 0, 0];
    let mut tris = Vec::new();
    for i in 0..300 {
        let a = random_point(&mut rng, origin, 0.0, 256.0);
        let len = if i % 3 == 0 { 200.0 } else { 20.0 };
        let d = [
            rng.range_f32(-len, len),
            rng.range_f32(-len, len),
            rng.range_f32(-len, len),
        ];
        let b = [a[0] + d[0], a[1] + d[1], a[2] + d[2]];
        let t_ = rng.f32();
        let w = 10f32.powf(rng.range_f32(-3.0, -1.0));
        let c = [
            a[0] + t_ * d[0] + w,
            a[1] + t_ * d[1] - w,
            a[2] + t_ * d[2] + w * 0.5,
        ];
        let mut t = Triangle::new([a, b, c]);
        decorate(&mut t, &mut rng, i % 2 == 0);
        tris.push(t);
    }
    assert!(check(&mut g, "slivers", origin, &tris) > 1000);
}

#[test]
fn axis_aligned_ties() {
    // vertices on integer and half-integer coordinates, triangles in voxel planes and along
    // voxel edges: the exact ties of the closed-box tests
    let mut g = gpu();
    let mut rng = Rng(7);
    let origin = [0, 0, 0];
    let mut tris = Vec::new();
    for i in 0..600 {
        let q = |rng: &mut Rng, s: f32| (rng.range_f32(-s, s) * 2.0).round() / 2.0;
        let c = [
            rng.range_f32(2.0, 250.0).round(),
            rng.range_f32(2.0, 250.0).round(),
            rng.range_f32(2.0, 250.0).round(),
        ];
        let axis = i % 3;
        let s = if i % 5 == 0 { 12.0 } else { 3.0 };
        let mut v = [c; 3];
        for (k, p) in v.iter_mut().enumerate().skip(1) {
            for a in 0..3 {
                if a != axis {
                    p[a] += q(&mut rng, s);
                }
            }
            if i % 4 == 0 {
                p[axis] += k as f32 * 0.5; // tilted, still on half-integers
            }
        }
        let mut t = Triangle::new(v);
        decorate(&mut t, &mut rng, i % 2 == 1);
        tris.push(t);
    }
    // a triangle exactly on the chunk's far faces and one on its near faces
    tris.push(Triangle::new([
        [256.0, 10.0, 10.0],
        [256.0, 40.0, 10.0],
        [256.0, 10.0, 50.0],
    ]));
    tris.push(Triangle::new([
        [0.0, 10.0, 10.0],
        [0.0, 40.0, 10.0],
        [0.0, 10.0, 50.0],
    ]));
    assert!(check(&mut g, "axis-aligned", origin, &tris) > 1000);
}

#[test]
fn chunk_spanning_triangle() {
    let mut g = gpu();
    let origin = [512, 256, 0];
    let mut t = Triangle::new([
        o(origin, [-10.0, -10.0, 3.3]),
        o(origin, [300.0, 5.0, 100.0]),
        o(origin, [20.0, 290.0, 250.0]),
    ]);
    t.c = [[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 128]];
    let n = check(&mut g, "spanning", origin, &[t]);
    assert!(n > 100_000, "{n}");
}

#[test]
fn empty_and_degenerate_input() {
    let mut g = gpu();
    assert!(g.voxelize_chunk([0, 0, 0], &[]).unwrap().is_empty());
    let degenerate = Triangle::new([[1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [3.0, 3.0, 3.0]]);
    let nan = Triangle::new([[f32::NAN, 1.0, 1.0], [2.0, 2.0, 2.0], [3.0, 1.0, 3.0]]);
    let outside = Triangle::new([[1000.0, 1.0, 1.0], [1002.0, 2.0, 2.0], [1003.0, 1.0, 3.0]]);
    assert!(g
        .voxelize_chunk([0, 0, 0], &[degenerate, nan, outside])
        .unwrap()
        .is_empty());
    assert_eq!(g.last_split(), (0, 0));
    assert!(matches!(
        g.voxelize_chunk([1, 0, 0], &[]),
        Err(voxlod_gpu::GpuError::Origin(_))
    ));
}

/// `chunks`: the chunk origins checked, in chunks (every chunk of the grid when None).
fn mesh_test(name: &str, tris: Vec<[[f32; 3]; 3]>, res: u32, chunks: Option<&[[u32; 3]]>) {
    let grid = to_grid(&tris, res);
    let mut g = gpu();
    let mut rng = Rng(99);
    let grid: Vec<Triangle> = grid
        .into_iter()
        .enumerate()
        .map(|(i, mut t)| {
            decorate(&mut t, &mut rng, i % 2 == 0);
            t
        })
        .collect();
    let k = res / 256;
    let all: Vec<[u32; 3]> = (0..k * k * k)
        .map(|i| [i % k, i / k % k, i / k / k])
        .collect();
    let mut n = 0;
    for c in chunks.unwrap_or(&all) {
        assert!(c.iter().all(|&c| c < k), "{c:?} is not a chunk of {res}³");
        let here = check(&mut g, name, c.map(|c| c * 256), &grid);
        assert!(here > 1000, "{name}: chunk {c:?} has only {here} voxels");
        n += here;
    }
    assert!(n > 10_000, "{name}: only {n} voxels");
}

#[test]
fn npm_bunny_two_resolutions() {
    let Some(dir) = meshes_dir() else { return };
    let tris = load_mesh(&dir.join("npm-bunny/bunny.ply"));
    assert_eq!(tris.len(), 3674);
    mesh_test("npm-bunny@256", tris.clone(), 256, None);
    // at 512³ two of the eight chunks, at the origin and at the far corner (every coordinate
    // of the origin nonzero), with the triangles of the whole mesh crossing their faces: the
    // same check as all eight at a quarter of the time (lavapipe's cost is per chunk)
    mesh_test("npm-bunny@512", tris, 512, Some(&[[0, 0, 0], [1, 1, 1]]));
}

#[test]
fn stanford_bunny() {
    let Some(dir) = meshes_dir() else { return };
    let tris = load_mesh(&dir.join("stanford-bunny/bun_zipper.ply"));
    assert_eq!(tris.len(), 69451);
    mesh_test("bun_zipper@256", tris, 256, None);
}
