//! The factored overlap tests against independent brute-force references, voxel by voxel.

use crate::common;
use common::*;
use std::collections::HashSet;
use voxlod_voxelize::{voxelize_triangle, Mode, TriSetup};

const LO: [i32; 3] = [0, 0, 0];
const HI: [i32; 3] = [23, 23, 23];
const KINDS: [&str; 8] = [
    "general",
    "sub-voxel",
    "sliver",
    "axis-aligned",
    "integer",
    "quarter",
    "large",
    "axis-edge",
];

fn run(t: &[[f32; 3]; 3], mode: Mode) -> Vec<[i32; 3]> {
    let mut out = Vec::new();
    voxelize_triangle(t, LO, HI, mode, &mut |p| out.push(p));
    out
}

#[derive(Default, Debug)]
struct Stats {
    tris: usize,
    marked: usize,
    ref_marked: usize,
    tie_diffs: usize,
    /// marked by the reference only (ties included)
    ref_only: usize,
    non_tie_diffs: Vec<String>,
}

/// Compares one mode against a per-voxel reference over the whole window.
fn compare(
    kind_tris: &[(usize, [[f32; 3]; 3])],
    mode: Mode,
    reference: impl Fn(&[[f64; 3]; 3], [i32; 3]) -> Sat,
) -> Stats {
    let mut st = Stats::default();
    for (kind, t) in kind_tris {
        let got = run(t, mode);
        let set: HashSet<[i32; 3]> = got.iter().copied().collect();
        assert_eq!(set.len(), got.len(), "duplicate voxels for {t:?}");
        assert_eq!(got, run(t, mode), "not deterministic");
        let t64 = f64tri(t);
        st.tris += 1;
        st.marked += got.len();
        for p in &got {
            assert!(
                (0..3).all(|k| p[k] >= LO[k] && p[k] <= HI[k]),
                "{p:?} outside the window"
            );
        }
        for z in LO[2]..=HI[2] {
            for y in LO[1]..=HI[1] {
                for x in LO[0]..=HI[0] {
                    let p = [x, y, z];
                    let r = reference(&t64, p);
                    st.ref_marked += r.overlap as usize;
                    if r.overlap && !set.contains(&p) {
                        st.ref_only += 1;
                    }
                    if r.overlap != set.contains(&p) {
                        if r.tie {
                            st.tie_diffs += 1;
                        } else {
                            st.non_tie_diffs.push(format!(
                                "{} triangle {t:?} voxel {p:?}: ref {} ours {}",
                                KINDS[*kind], r.overlap, !r.overlap
                            ));
                        }
                    }
                }
            }
        }
    }
    st
}

fn triangles(seed: u64, per_kind: usize) -> Vec<(usize, [[f32; 3]; 3])> {
    let mut rng = Rng(seed);
    let mut v = Vec::new();
    for i in 0..per_kind * KINDS.len() {
        let kind = i % KINDS.len();
        let t = f32tri(random_triangle(&mut rng, kind, 22.0));
        if TriSetup::new(&t, Mode::Conservative).is_some() {
            v.push((kind, t));
        }
    }
    v
}

#[test]
fn conservative_equals_13_axis_reference() {
    let tris = triangles(1, 300);
    let st = compare(&tris, Mode::Conservative, sat_box);
    eprintln!(
        "conservative: {} triangles, {} voxels marked, reference {}, tie differences {}, non-tie {}",
        st.tris,
        st.marked,
        st.ref_marked,
        st.tie_diffs,
        st.non_tie_diffs.len()
    );
    assert!(st.tris > 2000);
    assert!(
        st.non_tie_diffs.is_empty(),
        "{:#?}",
        &st.non_tie_diffs[..st.non_tie_diffs.len().min(10)]
    );
    // conservative must never miss a voxel the reference marks, ties included
    assert_eq!(st.ref_only, 0);
}

#[test]
fn thin_equals_direct_definition_and_covers_diamond_hits() {
    let tris = triangles(2, 300);
    let st = compare(&tris, Mode::Thin, thin_reference);
    eprintln!(
        "thin vs direct definition: {} triangles, {} voxels, reference {}, tie differences {}, non-tie {}",
        st.tris,
        st.marked,
        st.ref_marked,
        st.tie_diffs,
        st.non_tie_diffs.len()
    );
    assert!(
        st.non_tie_diffs.is_empty(),
        "{:#?}",
        &st.non_tie_diffs[..st.non_tie_diffs.len().min(10)]
    );

    // every voxel whose inscribed diamond the triangle meets is marked (the premise of the
    // 6-separation proof), and thin ⊆ conservative
    let mut diamond_hits = 0usize;
    let mut diamond_ties = 0usize;
    let (mut thin_total, mut cons_total) = (0usize, 0usize);
    for (kind, t) in &tris {
        let thin: HashSet<[i32; 3]> = run(t, Mode::Thin).into_iter().collect();
        let cons: HashSet<[i32; 3]> = run(t, Mode::Conservative).into_iter().collect();
        thin_total += thin.len();
        cons_total += cons.len();
        for p in &thin {
            assert!(
                cons.contains(p),
                "thin voxel {p:?} not conservative for {} {t:?}",
                KINDS[*kind]
            );
        }
        let t64 = f64tri(t);
        for z in LO[2]..=HI[2] {
            for y in LO[1]..=HI[1] {
                for x in LO[0]..=HI[0] {
                    let d = sat_diamond(&t64, [x, y, z]);
                    if d.overlap {
                        diamond_hits += 1;
                        if !thin.contains(&[x, y, z]) {
                            assert!(
                                d.tie,
                                "diamond of {:?} meets {} {t:?} but thin misses it",
                                [x, y, z],
                                KINDS[*kind]
                            );
                            diamond_ties += 1;
                        }
                    }
                }
            }
        }
    }
    eprintln!(
        "thin: {thin_total} voxels, conservative {cons_total}; diamond hits {diamond_hits}, missed only at ties {diamond_ties}"
    );
    assert!(thin_total < cons_total);
}

#[test]
fn window_clipping_and_setup_invariants() {
    let mut rng = Rng(3);
    for i in 0..500 {
        let t = f32tri(random_triangle(&mut rng, i, 22.0));
        for mode in [Mode::Conservative, Mode::Thin] {
            let Some(s) = TriSetup::new(&t, mode) else {
                continue;
            };
            assert!(s.n[2] > 0.0);
            assert!(s.n[0].abs() <= s.n[2] && s.n[1].abs() <= s.n[2]);
            assert_eq!(s.unswizzle(s.swizzle([1, 2, 3])), [1, 2, 3]);
            // a sub-window gives exactly the voxels of the full window inside it
            let mut full = Vec::new();
            voxelize_triangle(&t, [-100; 3], [100; 3], mode, &mut |p| full.push(p));
            let (lo, hi) = ([3, 5, 7], [12, 15, 11]);
            let mut part = Vec::new();
            voxelize_triangle(&t, lo, hi, mode, &mut |p| part.push(p));
            let expect: Vec<[i32; 3]> = full
                .iter()
                .copied()
                .filter(|p| (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]))
                .collect();
            assert_eq!(part, expect);
        }
    }
    // degenerate and non-finite triangles
    assert!(TriSetup::new(&[[0.0; 3], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]], Mode::Thin).is_none());
    assert!(TriSetup::new(
        &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, f32::NAN, 0.0]],
        Mode::Thin
    )
    .is_none());
    assert!(TriSetup::new(
        &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, f32::INFINITY, 0.0]],
        Mode::Thin
    )
    .is_none());
}
