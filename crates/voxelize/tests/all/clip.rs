//! clipped_area: analytic cases, area conservation over all voxels, Monte Carlo, and agreement
//! of positive-area voxels with the conservative overlap test.

use crate::common;
use common::*;
use voxlod_voxelize::{clipped_area, voxelize_triangle, Mode};

#[test]
fn analytic_cases() {
    // right triangle with legs 2 in the plane z = 0.5
    let t = [[0.0, 0.0, 0.5], [2.0, 0.0, 0.5], [0.0, 2.0, 0.5]];
    let (a, c) = clipped_area(&t, [0, 0, 0]);
    assert!(
        (a - 1.0).abs() < 1e-12
            && (c[0] - 0.5).abs() < 1e-12
            && (c[1] - 0.5).abs() < 1e-12
            && c[2] == 0.5
    );
    let (a, c) = clipped_area(&t, [1, 0, 0]);
    assert!((a - 0.5).abs() < 1e-12);
    assert!((c[0] - 4.0 / 3.0).abs() < 1e-12 && (c[1] - 1.0 / 3.0).abs() < 1e-12);
    // touching only at a corner / on a face: zero area, centroid on the contact
    let (a, c) = clipped_area(&t, [1, 1, 0]);
    assert_eq!(a, 0.0);
    assert!((c[0] - 1.0).abs() < 1e-12 && (c[1] - 1.0).abs() < 1e-12);
    assert_eq!(clipped_area(&t, [5, 5, 5]).0, 0.0);
    // tilted: the plane z = x through a unit column has area sqrt(2)
    let t = [[0.0, 0.0, 0.0], [4.0, 0.0, 4.0], [0.0, 4.0, 0.0]];
    let (a, _) = clipped_area(&t, [0, 0, 0]);
    assert!((a - 2f64.sqrt()).abs() < 1e-12, "{a}");
    let (a, _) = clipped_area(&t, [1, 1, 1]);
    assert!((a - 2f64.sqrt()).abs() < 1e-12, "{a}");
    // the same plane misses voxel (1, 1, 0) except for its edge x = 1, z = 1 (area 0)
    assert_eq!(clipped_area(&t, [1, 1, 0]).0, 0.0);
    // degenerate and non-finite: zero
    assert_eq!(
        clipped_area(&[[0.0; 3], [1.0; 3], [2.0; 3]], [0, 0, 0]).0,
        0.0
    );
    assert_eq!(
        clipped_area(
            &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, f32::NAN, 0.0]],
            [0, 0, 0]
        )
        .0,
        0.0
    );
}

#[test]
fn areas_sum_to_triangle_area_and_centroids_to_its_centroid() {
    let mut rng = Rng(21);
    let mut worst = 0.0f64;
    for i in 0..3000 {
        let t = f32tri(random_triangle(&mut rng, i, 20.0));
        if i % 8 == 6 && i > 400 {
            continue; // enough large triangles (each has up to a million bounding-box voxels)
        }
        let t64 = f64tri(&t);
        let area = tri_area(&t64);
        if area == 0.0 {
            continue;
        }
        let mut sum = 0.0;
        let mut mom = [0.0; 3];
        let mut cons = std::collections::HashSet::new();
        voxelize_triangle(&t, [-100; 3], [100; 3], Mode::Conservative, &mut |p| {
            cons.insert(p);
        });
        // every voxel of the bounding box, not only the marked ones
        let lo = [0, 1, 2].map(|k| t64[0][k].min(t64[1][k]).min(t64[2][k]).floor() as i32 - 1);
        let hi = [0, 1, 2].map(|k| t64[0][k].max(t64[1][k]).max(t64[2][k]).floor() as i32 + 1);
        for z in lo[2].max(-100)..=hi[2].min(100) {
            for y in lo[1].max(-100)..=hi[1].min(100) {
                for x in lo[0].max(-100)..=hi[0].min(100) {
                    let (a, c) = clipped_area(&t, [x, y, z]);
                    assert!(a >= 0.0);
                    if a > 0.0 {
                        assert!(
                            cons.contains(&[x, y, z]),
                            "positive area {a} in unmarked voxel {:?} of {t:?}",
                            [x, y, z]
                        );
                        for k in 0..3 {
                            assert!(
                                c[k] >= [x, y, z][k] as f64 - 1e-9
                                    && c[k] <= [x, y, z][k] as f64 + 1.0 + 1e-9
                            );
                        }
                    }
                    sum += a;
                    for k in 0..3 {
                        mom[k] += a * c[k];
                    }
                }
            }
        }
        if t64.iter().flatten().all(|c| c.abs() < 99.0) {
            // a triangle lying in a voxel face plane is inside both closed boxes sharing that
            // face, so it is counted twice (the weights are for averaging, this is by design)
            let on_face = (0..3).any(|k| {
                t64[0][k] == t64[1][k] && t64[1][k] == t64[2][k] && t64[0][k].fract() == 0.0
            });
            if on_face {
                sum *= 0.5;
                mom = mom.map(|m| 0.5 * m);
            }
            let rel = (sum - area).abs() / area;
            worst = worst.max(rel);
            assert!(rel < 1e-6, "sum {sum} vs area {area} for {t:?}");
            let cen = [0, 1, 2].map(|k| (t64[0][k] + t64[1][k] + t64[2][k]) / 3.0);
            for k in 0..3 {
                assert!(
                    (mom[k] / sum - cen[k]).abs() < 1e-6 * (1.0 + cen[k].abs()),
                    "centroid {t:?}"
                );
            }
        }
    }
    eprintln!("worst relative area error {worst:e}");
}

#[test]
fn monte_carlo_area_fractions() {
    let mut rng = Rng(5);
    let t = [[0.3, 0.2, 0.9], [3.7, 1.1, 2.4], [1.2, 3.3, 0.1]];
    let t32 = f32tri(t);
    let t = f64tri(&t32);
    let area = tri_area(&t);
    let samples = 400_000;
    let mut hits = std::collections::HashMap::new();
    for _ in 0..samples {
        let (mut a, mut b) = (rng.f64(), rng.f64());
        if a + b > 1.0 {
            a = 1.0 - a;
            b = 1.0 - b;
        }
        let p = [0, 1, 2].map(|k| t[0][k] + a * (t[1][k] - t[0][k]) + b * (t[2][k] - t[0][k]));
        *hits.entry(p.map(|x| x.floor() as i32)).or_insert(0usize) += 1;
    }
    for (v, h) in hits {
        let frac = h as f64 / samples as f64;
        let expect = clipped_area(&t32, v).0 / area;
        let sigma = (expect * (1.0 - expect) / samples as f64).sqrt();
        assert!(
            (frac - expect).abs() < 5.0 * sigma + 1e-4,
            "voxel {v:?}: MC {frac} vs {expect}"
        );
    }
}
