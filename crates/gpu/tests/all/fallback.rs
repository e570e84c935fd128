//! The GPU voxelizer's fallback for decisions the shaders cannot certify:
//! per triangle, not per chunk, and none where the shaders can certify ties themselves.
//!
//! * A block world (boxes whose faces lie on voxel planes, every coordinate on a dyadic grid):
//!   every decision is exact arithmetic in f64, so the shaders certify the ties themselves and
//!   no triangle (and no chunk) falls back; the sets equal the CPU's (the CPU's are exact,
//!   `crates/voxelize/tests/all/exact.rs`).
//! * Slivers (a vertex one ulp off the opposite edge: a normal component of doubtful sign, and
//!   edge values inside their bands) among ordinary triangles with colours and normals: the
//!   slivers are decided on the host (asserted: listed triangles > 0, no chunk falls back), their
//!   voxels merged into the GPU's before compaction and their attributes added to the GPU's
//!   fixed-point sums; the sets equal the CPU's and the attributes agree within one
//!   quantization step (as `gpu_vs_cpu.rs` checks). The same with f32 shaders, sets only (they
//!   compute the attributes in f32).
//!
//! These tests need an adapter (lavapipe is enough): without one they FAIL.

use crate::common;

use common::*;
use voxlod_geom::Triangle;
use voxlod_gpu::{GpuMethod, GpuVoxelizer, Precision, DEFAULT_CUTOFF};
use voxlod_voxelize::Mode;

/// The 12 triangles of the box `[lo, hi]` (outward winding).
fn block(lo: [f32; 3], hi: [f32; 3]) -> Vec<Triangle> {
    let c = |i: usize| {
        [
            if i & 1 != 0 { hi[0] } else { lo[0] },
            if i & 2 != 0 { hi[1] } else { lo[1] },
            if i & 4 != 0 { hi[2] } else { lo[2] },
        ]
    };
    // faces as corner quads (x-, x+, y-, y+, z-, z+)
    let quads = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    quads
        .iter()
        .flat_map(|q| {
            [
                Triangle::new([c(q[0]), c(q[1]), c(q[2])]),
                Triangle::new([c(q[0]), c(q[2]), c(q[3])]),
            ]
        })
        .collect()
}

/// Which attributes must agree within one step (normals: not where opposite faces meet in a
/// voxel and their sum nearly cancels, see the crate docs; nothing for f32 shaders, which
/// compute the attributes in f32).
#[derive(Clone, Copy, PartialEq)]
enum Attrs {
    All,
    Colours,
    None,
}

/// Runs every mode and scheme on one chunk against the CPU: equal sets, `attrs` within one
/// step; returns (listed triangles, chunks that fell back as a whole, CPU voxels) summed.
fn run(
    g: &mut GpuVoxelizer,
    name: &str,
    origin: [u32; 3],
    tris: &[Triangle],
    attrs: Attrs,
) -> [u64; 3] {
    let mut out = [0; 3];
    for mode in [Mode::Conservative, Mode::Thin] {
        let want = cpu(mode, origin, tris);
        g.set_mode(mode);
        for m in METHODS {
            g.set_method(m, DEFAULT_CUTOFF);
            let got = g.voxelize_chunk(origin, tris).unwrap();
            let d = compare(&want, &got);
            eprintln!(
                "{name} {mode} {m}: {} triangles decided on the host, whole chunk on the CPU {}, {d:?}",
                g.last_fallback_triangles(),
                g.last_fell_back()
            );
            assert_eq!(
                (d.only_cpu, d.only_gpu),
                (0, 0),
                "{name} {mode} {m}: voxel sets differ: {d:?}"
            );
            let (normal, colour) = match attrs {
                Attrs::All => (d.normal + d.mask, d.colour),
                Attrs::Colours => (0, d.colour),
                Attrs::None => (0, 0),
            };
            assert_eq!(
                (normal, colour),
                (0, 0),
                "{name} {mode} {m}: attributes differ: {d:?}"
            );
            out[0] += g.last_fallback_triangles();
            out[1] += g.last_fell_back() as u64;
            out[2] += want.len() as u64;
        }
    }
    out
}

#[test]
fn block_world_ties_are_certified_on_the_gpu() {
    let mut g = gpu();
    let mut rng = Rng(0xb10c);
    // blocks of integer and quarter-voxel sizes, on voxel planes (and quarter planes), some
    // touching each other face to face (shared faces: ties from both sides), in two chunks:
    // near the origin and far out (grid coordinates near 2^12)
    for (origin, unit) in [
        ([0u32; 3], 1.0f32),
        ([4096, 256, 3840], 1.0),
        ([0; 3], 0.25),
    ] {
        let mut tris = Vec::new();
        let o = origin.map(|c| c as f32);
        for i in 0..60 {
            let lo: [f32; 3] = std::array::from_fn(|k| {
                o[k] + (rng.next_u64() % (240.0 / unit) as u64) as f32 * unit
            });
            let size: [f32; 3] = std::array::from_fn(|_| (1 + rng.next_u64() % 12) as f32 * unit);
            let hi: [f32; 3] = std::array::from_fn(|k| lo[k] + size[k]);
            tris.extend(block(lo, hi));
            if i % 3 == 0 {
                // a neighbour sharing the +x face
                let lo2 = [hi[0], lo[1], lo[2]];
                let hi2 = [hi[0] + size[0], hi[1], hi[2]];
                tris.extend(block(lo2, hi2));
            }
        }
        // the floor of the chunk: a face on its boundary plane
        tris.extend(
            block(o, [o[0] + 256.0, o[1] + 256.0, o[2]])
                .into_iter()
                .skip(8)
                .take(2),
        );
        for t in &mut tris {
            decorate(t, &mut rng, false);
        }
        let name = format!("blocks at {origin:?}, unit {unit}");
        // (blocks touching face to face: opposite normals in one voxel)
        let [listed, chunks, voxels] = run(&mut g, &name, origin, &tris, Attrs::Colours);
        assert!(voxels > 50_000, "{name}: {voxels}");
        assert_eq!(chunks, 0, "{name}: a chunk fell back");
        assert_eq!(listed, 0, "{name}: the shaders did not certify every tie");
    }
}

/// A sliver: `a`, `b`, and a point on segment ab (parameter `t`) moved one or two ulps in one
/// coordinate.
fn sliver(rng: &mut Rng, a: [f32; 3], b: [f32; 3]) -> Triangle {
    let t = rng.f32();
    let mut c: [f32; 3] = std::array::from_fn(|k| a[k] + t * (b[k] - a[k]));
    let k = (rng.next_u64() % 3) as usize;
    let ulps = 1 + (rng.next_u64() % 2) as u32;
    c[k] = if rng.next_u64() % 2 == 0 {
        f32::from_bits(c[k].to_bits() + ulps)
    } else {
        f32::from_bits(c[k].to_bits() - ulps)
    };
    Triangle::new([a, b, c])
}

#[test]
fn slivers_fall_back_per_triangle() {
    let mut g = gpu();
    let mut rng = Rng(0x5117e5);
    let origin = [512, 256, 0];
    let o = origin.map(|c| c as f32);
    let mut tris = Vec::new();
    for i in 0..3000 {
        let c: [f32; 3] = std::array::from_fn(|k| o[k] + rng.range_f32(4.0, 252.0));
        let s = if i % 5 == 0 { 4.0 } else { 1.5 };
        let p =
            |rng: &mut Rng| -> [f32; 3] { std::array::from_fn(|k| c[k] + rng.range_f32(-s, s)) };
        let mut t = if i % 10 == 0 {
            // slivers, some through voxel corners (integer end points)
            let (a, b) = (p(&mut rng), p(&mut rng));
            let (a, b) = if i % 20 == 0 {
                (a.map(f32::round), b.map(f32::round))
            } else {
                (a, b)
            };
            sliver(&mut rng, a, b)
        } else {
            Triangle::new([p(&mut rng), p(&mut rng), p(&mut rng)])
        };
        decorate(&mut t, &mut rng, i % 2 == 0);
        tris.push(t);
    }
    let [listed, chunks, voxels] = run(&mut g, "slivers", origin, &tris, Attrs::All);
    eprintln!("slivers: {listed} triangles decided on the host over 6 runs, {voxels} voxels");
    assert!(
        listed > 0,
        "no triangle fell back: the slivers do not reach the bands"
    );
    assert_eq!(chunks, 0, "a chunk fell back as a whole");

    // f32 shaders: many more triangles listed, the same sets
    let mut g = GpuVoxelizer::with_precision(
        Mode::Conservative,
        GpuMethod::Hybrid,
        DEFAULT_CUTOFF,
        Some(Precision::F32),
    )
    .unwrap_or_else(|e| panic!("this test needs a GPU adapter (lavapipe is enough): {e}"));
    let [listed32, chunks, _] = run(&mut g, "slivers f32", origin, &tris, Attrs::None);
    eprintln!("slivers f32: {listed32} triangles decided on the host over 6 runs");
    assert!(listed32 >= listed, "{listed32} < {listed}");
    assert_eq!(chunks, 0, "a chunk fell back as a whole");
}
