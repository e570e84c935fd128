//! The GPU voxelizer's sets against the exact CPU sets, on the adversarial
//! triangles of `crates/voxelize/tests/all/exact.rs` (the same generator, included by path): there
//! `ChunkVoxelizer`'s sets are proven equal to a big-integer reference, so here the CPU set is
//! the exact set. Each triangle is voxelized alone, so that a triangle the shaders list (a
//! decision inside its rounding band) is decided on the host, and the triangles that are not
//! listed show the shaders' own decisions.
//!
//! * f64: every set equals the exact one; some triangles are listed and decided on the host
//!   (asserted: the per-triangle fallback, never the whole chunk), the others come from the
//!   shaders unchanged.
//! * f32 (forced with `GpuVoxelizer::with_precision`): the same, with many more listed.
//!
//! These tests need an adapter (lavapipe is enough): without one they FAIL.

#[path = "../../../voxelize/tests/all/common/mod.rs"]
pub(crate) mod vcommon;

use std::collections::BTreeSet;

use vcommon::adversarial::adversarial;
use vcommon::Rng;
use voxlod_format::Voxel;
use voxlod_geom::Triangle;
use voxlod_gpu::{GpuMethod, GpuVoxelizer, Precision, DEFAULT_CUTOFF};
use voxlod_voxelize::{ChunkVoxelizer, Mode};

/// (offset of the triangles, origin of their chunk, seed): near the origin, at 2^20 (f32
/// spacing 1/8) and just below 2^23 (spacing 1/2), every triangle inside one chunk.
const PLACES: [(f64, u32, u64); 3] = [
    (100.0, 0, 1),
    ((1u32 << 20) as f64 + 100.0, 1 << 20, 4),
    (((1u32 << 23) - 156) as f64, (1 << 23) - 256, 5),
];
/// Triangles per place and mode.
const COUNT: usize = 60;

fn gpu(p: Precision) -> GpuVoxelizer {
    GpuVoxelizer::with_precision(
        Mode::Conservative,
        GpuMethod::Hybrid,
        DEFAULT_CUTOFF,
        Some(p),
    )
    .unwrap_or_else(|e| panic!("this test needs a GPU adapter (lavapipe is enough): {e}"))
}

fn positions(v: &[Voxel]) -> BTreeSet<[u8; 3]> {
    v.iter().map(|v| v.pos()).collect()
}

fn exact(cpu: &mut ChunkVoxelizer, origin: [u32; 3], t: &Triangle) -> BTreeSet<[u8; 3]> {
    cpu.begin(origin);
    cpu.add(std::slice::from_ref(t));
    positions(&cpu.finish())
}

/// `check(got, exact, voxelizer, what)`: checks one triangle's set.
type Check<'a> = dyn FnMut(&BTreeSet<[u8; 3]>, &BTreeSet<[u8; 3]>, &GpuVoxelizer, &str) + 'a;

/// (flagged, clean) triangles over every place, mode and scheme, after checking each set with
/// `check(got, exact, flagged)`.
fn run(g: &mut GpuVoxelizer, check: &mut Check<'_>) -> (usize, usize) {
    let (mut flagged, mut clean) = (0, 0);
    for mode in [Mode::Conservative, Mode::Thin] {
        g.set_mode(mode);
        let mut cpu = ChunkVoxelizer::new(mode);
        for (o, origin, seed) in PLACES {
            let origin = [origin; 3];
            let mut rng = Rng(seed);
            for i in 0..COUNT {
                let t = Triangle::new(adversarial(&mut rng, i, o));
                let want = exact(&mut cpu, origin, &t);
                // the hybrid scheme on most, the other two on some (the fragment pass and the
                // sweep evaluate the same filtered decisions)
                let m = match i % 6 {
                    2 => GpuMethod::Fragment,
                    5 => GpuMethod::Triangle,
                    _ => GpuMethod::Hybrid,
                };
                g.set_method(m, DEFAULT_CUTOFF);
                let got = positions(&g.voxelize_chunk(origin, &[t]).unwrap());
                let what = format!("{mode} {m} at {o}, triangle {i} {:?}", t.v);
                check(&got, &want, g, &what);
                assert!(!g.last_fell_back(), "{what}: the whole chunk fell back");
                assert_eq!(
                    g.last_uncertain(),
                    g.last_fallback_triangles() == 1,
                    "{what}: an uncertain decision lists its triangle"
                );
                if g.last_uncertain() {
                    flagged += 1;
                } else {
                    clean += 1;
                }
            }
        }
    }
    (flagged, clean)
}

#[test]
fn f64_sets_equal_the_exact_sets_on_adversarial_triangles() {
    let mut g = gpu(Precision::F64);
    let (flagged, clean) = run(&mut g, &mut exact_sets);
    eprintln!("f64: {flagged} triangles listed (decided on the host), {clean} not");
    assert!(
        flagged > 0,
        "no triangle was listed: the adversarial cases do not reach the bands"
    );
    assert!(
        clean > 0,
        "every triangle was listed: the shaders decided nothing"
    );
}

fn exact_sets(got: &BTreeSet<[u8; 3]>, want: &BTreeSet<[u8; 3]>, g: &GpuVoxelizer, what: &str) {
    assert!(
        got == want,
        "{what}: missed {:?}, added {:?} (listed: {})",
        want.difference(got).collect::<Vec<_>>(),
        got.difference(want).collect::<Vec<_>>(),
        g.last_fallback_triangles()
    );
}

#[test]
fn f32_sets_equal_the_exact_sets_too() {
    let mut g = gpu(Precision::F32);
    assert_eq!(g.precision(), Precision::F32);
    let (flagged, clean) = run(&mut g, &mut exact_sets);
    eprintln!("f32: {flagged} triangles listed (decided on the host), {clean} not");
    assert!(flagged > 0 && clean > 0, "{flagged} / {clean}");
}
