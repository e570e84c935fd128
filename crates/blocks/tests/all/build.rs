//! The block world built into an octree with textures and the material channel, checked voxel
//! by voxel against the blocks. A 32×32 world built at 256³ puts exactly k = 8 voxels along
//! each block edge (the bounding cube is the world's 32 columns: power-of-two scales, so the
//! grid is exact), so every block face covers 8 × 8 voxels and 2 × 2 texels of its 16×16
//! texture per voxel. For every level-0 voxel the faces of the OBJ touching it (read by the
//! tests' own OBJ reader, its faces checked against the block grid in `world.rs`) give, in
//! exact integer areas:
//! - its material: the face material with the largest area inside the voxel, ties to the
//!   smallest id (docs/TEXTURES.md), wherever some face covers part of it;
//! - its colour, where one face alone touches it and that face's triangle diagonal does not
//!   cross it: the mean of the texels of its 2 × 2 footprint, in linear light, within one step
//!   (textures decoded by the `image` crate, sRGB by the tests' own formula); where the
//!   diagonal crosses it, within the range of the texels around its footprint.
//!
//! Built at 512³ (eight leaf chunks), `verify` accepts the file, its parents' materials
//! recomputed, and its bytes do not depend on the thread count.

use crate::common;

use std::collections::HashMap;

use common::{read_quads, Quad};
use voxlod_blocks::{write_world, World};
use voxlod_format::Reader;
use voxlod_pipeline::{build, Backend, BuildSettings};

const K: i64 = 8;

fn settings(threads: usize) -> BuildSettings {
    BuildSettings {
        resolution: 256,
        threads,
        backend: Backend::Cpu,
        ..BuildSettings::default()
    }
}

fn srgb_to_linear(c: u8) -> f64 {
    let x = c as f64 / 255.0;
    if x <= 0.04045 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb8(x: f64) -> i32 {
    let s = if x <= 0.0031308 {
        x * 12.92
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as i32
}

/// The faces by plane: (normal axis, plane coordinate in blocks) → quads in that plane.
fn by_plane(quads: &[Quad]) -> HashMap<(usize, i64), Vec<usize>> {
    let mut m: HashMap<(usize, i64), Vec<usize>> = HashMap::new();
    for (i, q) in quads.iter().enumerate() {
        let (a, _) = q.normal();
        m.entry((a, q.corners[0][a])).or_default().push(i);
    }
    m
}

/// The other two axes of `a`, in order.
fn others(a: usize) -> [usize; 2] {
    [(a + 1) % 3, (a + 2) % 3]
}

/// Length of `[lo, lo + 1]` ∩ `[a, b]` in voxels, or `None` if they do not touch.
fn overlap(lo: i64, a: i64, b: i64) -> Option<i64> {
    let (s, e) = (lo.max(a), (lo + 1).min(b));
    (s <= e).then_some(e - s)
}

/// The faces touching voxel `g` (voxel units) with the area of each inside it (voxel²).
fn touching(
    g: [i64; 3],
    quads: &[Quad],
    planes: &HashMap<(usize, i64), Vec<usize>>,
) -> Vec<(usize, i64)> {
    let mut out = Vec::new();
    for a in 0..3 {
        for plane in [g[a], g[a] + 1] {
            if plane % K != 0 {
                continue;
            }
            for &i in planes.get(&(a, plane / K)).into_iter().flatten() {
                let q = &quads[i];
                let mut area = 1;
                for b in others(a) {
                    let lo = q.corners.iter().map(|c| c[b]).min().unwrap() * K;
                    let hi = q.corners.iter().map(|c| c[b]).max().unwrap() * K;
                    match overlap(g[b], lo, hi) {
                        Some(l) => area *= l,
                        None => area = -1,
                    }
                    if area < 0 {
                        break;
                    }
                }
                if area >= 0 {
                    out.push((i, area));
                }
            }
        }
    }
    out
}

/// Whether the diagonal of `q` (corner 0 to corner 2) crosses the inside of voxel `g`.
fn diagonal_crosses(q: &Quad, g: [i64; 3]) -> bool {
    let (a, _) = q.normal();
    let [u, v] = others(a);
    let p0 = [q.corners[0][u] * K, q.corners[0][v] * K];
    let p2 = [q.corners[2][u] * K, q.corners[2][v] * K];
    let side = |x: i64, y: i64| (p2[0] - p0[0]) * (y - p0[1]) - (p2[1] - p0[1]) * (x - p0[0]);
    let s = [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(dx, dy)| side(g[u] + dx, g[v] + dy).signum());
    s.contains(&1) && s.contains(&-1)
}

/// The texel rectangle (columns, rows from the top, half-open) of voxel `g` on face `q`,
/// through the face's texture coordinates (affine over the square: corner 0 is (0,0), corner
/// 1 is (1,0), corner 3 is (0,1)).
fn footprint(q: &Quad, g: [i64; 3], n: i64) -> ([i64; 2], [i64; 2]) {
    let c = q.corners;
    let eu: [i64; 3] = std::array::from_fn(|k| c[1][k] - c[0][k]);
    let ev: [i64; 3] = std::array::from_fn(|k| c[3][k] - c[0][k]);
    // texture coordinates of the voxel's corners, in texels (n per face edge, K voxels)
    let (mut us, mut vs) = (Vec::new(), Vec::new());
    for corner in 0..8 {
        let p: [i64; 3] = std::array::from_fn(|k| g[k] + (corner >> k & 1));
        let d: [i64; 3] = std::array::from_fn(|k| p[k] - c[0][k] * K);
        let dot = |e: [i64; 3]| (0..3).map(|k| e[k] * d[k]).sum::<i64>();
        us.push(dot(eu) * n / K);
        vs.push(dot(ev) * n / K);
    }
    let (u0, u1) = (*us.iter().min().unwrap(), *us.iter().max().unwrap());
    let (v0, v1) = (*vs.iter().min().unwrap(), *vs.iter().max().unwrap());
    // v up: row 0 is v = 1
    ([u0, u1], [n - v1, n - v0])
}

#[test]
fn voxels_carry_the_material_and_texture_of_their_block_face() {
    let d = tempfile::tempdir().unwrap();
    let obj = d.path().join("w.obj");
    write_world(&World::generate(32, 2).unwrap(), &obj, false).unwrap();
    let quads = read_quads(&obj);
    let planes = by_plane(&quads);
    let out = d.path().join("w.voxlod");
    build(&obj, &out, &settings(2)).unwrap();
    let r = Reader::open(&out).unwrap();
    assert!(r.has_materials());
    assert!(voxlod_check::verify(&out).ok());
    let names: Vec<String> = r.manifest().unwrap()["materials"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    let id = |name: &str| names.iter().position(|n| n == name).unwrap() as u32;
    let textures: HashMap<String, image::RgbaImage> = names[1..]
        .iter()
        .map(|n| (n.clone(), common::texture(&obj, n)))
        .collect();

    let (mut voxels, mut by_area, mut exact, mut crossed) = (0, 0, 0, 0);
    for (i, e) in r.nodes().iter().enumerate().filter(|(_, e)| e.level == 0) {
        let mats = r.read_materials(i).unwrap().unwrap();
        for (vx, m) in r.read_node(i).unwrap().iter().zip(mats) {
            voxels += 1;
            let g: [i64; 3] =
                std::array::from_fn(|k| (e.pos()[k] * 256 + vx.pos()[k] as u32) as i64);
            let faces = touching(g, &quads, &planes);
            assert!(!faces.is_empty(), "voxel {g:?} touches no face");
            // material: largest area, ties to the smallest id
            let mut area = vec![0i64; names.len()];
            for &(q, a) in &faces {
                area[id(&quads[q].material) as usize] += a;
            }
            let best = *area.iter().max().unwrap();
            if best > 0 {
                let want = area.iter().position(|&a| a == best).unwrap() as u32;
                assert_eq!(
                    m, want,
                    "voxel {g:?}: material {} not {}",
                    names[m as usize], names[want as usize]
                );
                by_area += 1;
            }
            // colour where one face alone touches the voxel, covering it
            if let [(q, 1)] = faces[..] {
                let quad = &quads[q];
                let tex = &textures[&quad.material];
                let n = tex.width() as i64;
                let (cols, rows) = footprint(quad, g, n);
                let got = vx.rgba();
                if !diagonal_crosses(quad, g) {
                    assert_eq!((cols[1] - cols[0], rows[1] - rows[0]), (2, 2));
                    for ch in 0..3 {
                        let mut sum = 0.0;
                        for y in rows[0]..rows[1] {
                            for x in cols[0]..cols[1] {
                                sum += srgb_to_linear(tex.get_pixel(x as u32, y as u32).0[ch]);
                            }
                        }
                        let want = linear_to_srgb8(sum / 4.0);
                        assert!(
                            (got[ch] as i32 - want).abs() <= 1,
                            "voxel {g:?} on {}: {got:?} channel {ch} want {want}",
                            quad.material
                        );
                    }
                    assert_eq!(got[3], 255);
                    exact += 1;
                } else {
                    // within the texels around the footprint (two texels' reach of the filter)
                    for ch in 0..3 {
                        let texels: Vec<i32> = (rows[0] - 2..rows[1] + 2)
                            .flat_map(|y| (cols[0] - 2..cols[1] + 2).map(move |x| (x, y)))
                            .map(|(x, y)| (x.clamp(0, n - 1), y.clamp(0, n - 1)))
                            .map(|(x, y)| tex.get_pixel(x as u32, y as u32).0[ch] as i32)
                            .collect();
                        let (lo, hi) =
                            (*texels.iter().min().unwrap(), *texels.iter().max().unwrap());
                        assert!(
                            (lo - 1..=hi + 1).contains(&(got[ch] as i32)),
                            "voxel {g:?}: {got:?} ch {ch} outside {lo}..={hi}"
                        );
                    }
                    crossed += 1;
                }
            }
        }
    }
    // most voxels lie inside one face: the checks cover the bulk of the world
    assert!(
        by_area * 10 > voxels * 9,
        "{by_area} of {voxels} voxels checked by area"
    );
    assert!(
        exact * 5 > voxels * 2,
        "{exact} of {voxels} voxels checked for colour"
    );
    assert!(crossed > 0);

    // at 512³ (eight leaf chunks, two levels): the same bytes on one thread and on three, and
    // verify recomputes every parent, its materials included
    let files: Vec<Vec<u8>> = [1, 3]
        .into_iter()
        .map(|t| {
            let other = d.path().join(format!("w{t}.voxlod"));
            let s = BuildSettings {
                resolution: 512,
                ..settings(t)
            };
            build(&obj, &other, &s).unwrap();
            let report = voxlod_check::verify(&other);
            assert!(report.ok(), "{:?}", report.problems);
            assert!(report.materials_checked > 0);
            assert_eq!(report.materials_checked, report.parents_checked);
            std::fs::read(&other).unwrap()
        })
        .collect();
    assert!(files[0] == files[1], "1 and 3 threads gave other bytes");
}
