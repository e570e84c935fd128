//! The per-voxel material (crate `material`, docs/FORMAT.md 14.3) against independent
//! references: hand-computed winners on made-up quads, and a brute force over every
//! (triangle, voxel) pair with the exact clipped areas of `clipped_area` summed per material
//! in f64, on random triangles and on the npm bunny with materials by region. Near ties (the
//! two largest sums within a relative 1e-5 of each other, where the voxelizer's f32 weights
//! may pick either) are counted, not compared.

use crate::common;
use common::*;
use std::collections::BTreeMap;
use voxlod_geom::{Triangle, CHUNK};
use voxlod_voxelize::material::better;
use voxlod_voxelize::{clipped_area, voxelize_triangle, ChunkVoxelizer, Mode};

fn tri(v: [[f32; 3]; 3], material: u32) -> Triangle {
    let mut t = Triangle::new(v);
    t.set_material(material);
    t
}

/// The chunk's voxels and materials from the voxelizer.
fn voxelize(tris: &[Triangle], origin: [u32; 3], mode: Mode) -> BTreeMap<[u8; 3], u32> {
    let mut cv = ChunkVoxelizer::new(mode);
    cv.set_materials(true);
    cv.begin(origin);
    cv.add(tris);
    let voxels = cv.finish();
    let mats = cv.take_materials().expect("materials are on");
    assert_eq!(mats.len(), voxels.len());
    voxels.iter().map(|v| v.pos()).zip(mats).collect()
}

/// Brute force: per voxel, per material, (Σ exact clipped area, contributions); the winner by
/// the documented rule, and whether the top two are a near tie.
fn reference(tris: &[Triangle], origin: [u32; 3], mode: Mode) -> BTreeMap<[u8; 3], (u32, bool)> {
    let lo = origin.map(|c| c as i32);
    let hi = origin.map(|c| (c + CHUNK - 1) as i32);
    let mut sums: BTreeMap<[u8; 3], BTreeMap<u32, (f64, u32)>> = BTreeMap::new();
    for t in tris {
        voxelize_triangle(&t.v, lo, hi, mode, &mut |p| {
            let (a, _) = clipped_area(&t.v, p);
            let local = [0, 1, 2].map(|k| (p[k] - lo[k]) as u8);
            let e = sums
                .entry(local)
                .or_default()
                .entry(t.material())
                .or_default();
            e.0 += a;
            e.1 += 1;
        });
    }
    sums.into_iter()
        .map(|(p, m)| {
            let mut all: Vec<(f64, u32, u32)> = m.iter().map(|(&id, &(w, k))| (w, k, id)).collect();
            all.sort_by(|a, b| {
                if better(*a, *b) {
                    std::cmp::Ordering::Less
                } else {
                    std::cmp::Ordering::Greater
                }
            });
            let near = all.len() > 1 && (all[0].0 - all[1].0).abs() <= 1e-5 * all[0].0.max(1e-30);
            (p, (all[0].2, near))
        })
        .collect()
}

fn compare(tris: &[Triangle], origin: [u32; 3], mode: Mode) -> (usize, usize) {
    let got = voxelize(tris, origin, mode);
    let want = reference(tris, origin, mode);
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        want.keys().collect::<Vec<_>>(),
        "the same voxels"
    );
    let (mut checked, mut ties) = (0, 0);
    for (p, (m, near)) in &want {
        if *near {
            ties += 1;
            continue;
        }
        assert_eq!(got[p], *m, "voxel {p:?}");
        checked += 1;
    }
    (checked, ties)
}

#[test]
fn hand_computed_winners() {
    // the plane z = 0.5 through voxel row y = 0; material 3 covers x in [0, 1.3] and material
    // 8 x in [1.3, 3]: voxel (0,0,0) is all 3, (1,0,0) is 0.3 of 3 and 0.7 of 8 → 8, (2,0,0)
    // is all 8
    let quad = |x0: f32, x1: f32, m: u32| {
        [
            tri([[x0, 0.0, 0.5], [x1, 0.0, 0.5], [x1, 1.0, 0.5]], m),
            tri([[x0, 0.0, 0.5], [x1, 1.0, 0.5], [x0, 1.0, 0.5]], m),
        ]
    };
    let mut tris = quad(0.0, 1.3, 3).to_vec();
    tris.extend(quad(1.3, 3.0, 8));
    let got = voxelize(&tris, [0; 3], Mode::Thin);
    assert_eq!(got[&[0, 0, 0]], 3);
    assert_eq!(got[&[1, 0, 0]], 8);
    assert_eq!(got[&[2, 0, 0]], 8);
    // split at 1.5: an exact tie in voxel 1 goes to the smaller id, whatever the order
    let mut tris = quad(1.5, 3.0, 8).to_vec();
    tris.extend(quad(0.0, 1.5, 3));
    assert_eq!(voxelize(&tris, [0; 3], Mode::Thin)[&[1, 0, 0]], 3);
    // three tiny triangles inside one voxel (the interior fast path): areas 1.0e-3 and 1.0e-3
    // of material 5 against 1.5e-3 of material 2 → 5 (summed, not the largest single part)
    let small =
        |o: f32, s: f32, m: u32| tri([[o, 0.2, 0.2], [o + s, 0.2, 0.2], [o, 0.2 + s, 0.2]], m);
    let tris = [
        small(0.1, 0.0447, 5),
        small(0.3, 0.0447, 5),
        small(0.5, 0.0548, 2),
    ];
    let got = voxelize(&tris, [0; 3], Mode::Conservative);
    assert_eq!(got.len(), 1);
    assert_eq!(got[&[0, 0, 0]], 5, "2·1.0e-3 > 1.5e-3");
}

#[test]
fn brute_force_on_random_triangles() {
    let mut rng = Rng(17);
    for mode in [Mode::Conservative, Mode::Thin] {
        let tris: Vec<Triangle> = (0..300)
            .map(|i| {
                let t = random_triangle(&mut rng, i % 6, 12.0);
                let t = t.map(|p| p.map(|c| c + 20.0));
                tri(f32tri(t), rng.below(4) as u32)
            })
            .collect();
        let (checked, ties) = compare(&tris, [0; 3], mode);
        assert!(checked > 1000, "{checked} voxels checked, {ties} near ties");
    }
}

#[test]
fn brute_force_on_the_npm_bunny() {
    let Some(dir) = shared_meshes() else {
        return;
    };
    let (v, f) = read_ply(&dir.join("npm-bunny/bunny.ply"));
    let g = voxlod_testkit::mesh::fit_to_grid(&v, 250.0, 2.7);
    // materials by region: bands of the x coordinate of the first corner, and every 7th
    // triangle another material, so voxels see several
    let tris: Vec<Triangle> = f
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let c = t.map(|j| g[j as usize]);
            let m = if i % 7 == 0 {
                9
            } else {
                (c[0][0] / 40.0) as u32 + 1
            };
            tri(c, m)
        })
        .collect();
    let (checked, ties) = compare(&tris, [0; 3], Mode::Conservative);
    eprintln!("npm bunny 256³: {checked} voxels' materials equal the brute force, {ties} near ties skipped");
    assert!(checked > 10_000 && ties * 100 < checked);
}

#[test]
fn off_by_default() {
    let mut cv = ChunkVoxelizer::new(Mode::Conservative);
    cv.begin([0; 3]);
    cv.add(&[tri([[0.5, 0.5, 0.5], [3.0, 0.5, 0.5], [0.5, 3.0, 0.5]], 4)]);
    assert!(!cv.finish().is_empty());
    assert_eq!(cv.take_materials(), None);
}
