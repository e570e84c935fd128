//! ChunkVoxelizer against voxelize_triangle over the whole grid and a brute-force per-voxel
//! recomputation of the attributes; batch independence, determinism, thread independence.

use crate::common;
use common::*;
use std::collections::BTreeMap;
use voxlod_format::voxel::{border_caps, face_mask, unpack_normal, Voxel};
use voxlod_geom::{Triangle, TRI_HAS_NORMALS};
use voxlod_voxelize::{clipped_area, voxelize_grid, voxelize_triangle, ChunkVoxelizer, Mode};

const RES: u32 = 512;

fn triangles(seed: u64) -> (Vec<Triangle>, u64) {
    let mut rng = Rng(seed);
    let mut out = Vec::new();
    for i in 0..400 {
        let t = random_triangle(&mut rng, i, 40.0);
        // around the centre of the grid, where four chunk boundaries meet
        let mut t = t.map(|p| p.map(|x| (x + 236.0).clamp(0.0, 511.9)));
        if i % 8 == 6 {
            // large: across the whole grid
            t = [
                rng.point(0.0, 511.9),
                rng.point(0.0, 511.9),
                rng.point(0.0, 511.9),
            ];
        }
        out.push(with_attributes(&mut rng, Triangle::new(f32tri(t)), i));
    }
    // large ones are slow to brute-force: keep only 6 of them
    let mut large = 0;
    out.retain(|t| {
        let big = (0..3).any(|k| {
            let (a, b) = (
                t.v[0][k].min(t.v[1][k]).min(t.v[2][k]),
                t.v[0][k].max(t.v[1][k]).max(t.v[2][k]),
            );
            b - a > 100.0
        });
        large += big as usize;
        !big || large <= 6
    });
    // tiny, as in a scan voxelized coarser than its triangles: inside one voxel's interior (the
    // conservative interior path), some in voxels at the chunk boundaries, and some with a
    // corner on a face of their voxel (not interior: the general path)
    for i in 0..120 {
        let c = rng.point(253.0, 259.0).map(|x| x.floor());
        let mut t = [0, 1, 2].map(|_| {
            let p = rng.point(0.02, 0.98);
            [0, 1, 2].map(|k| c[k] + p[k])
        });
        if i % 6 == 5 {
            t[1][i % 3] = c[i % 3] + (i % 2) as f64;
        }
        out.push(with_attributes(&mut rng, Triangle::new(f32tri(t)), i + 1));
    }
    // exactly on the chunk boundary planes
    out.push(Triangle::new([
        [256.0, 250.0, 250.0],
        [256.0, 262.0, 251.0],
        [256.0, 251.0, 263.0],
    ]));
    out.push(Triangle::new([
        [250.0, 256.0, 256.0],
        [262.0, 256.0, 256.0],
        [251.0, 263.0, 256.0],
    ]));
    // skipped: zero area, non-finite
    out.push(Triangle::new([
        [1.0, 1.0, 1.0],
        [2.0, 2.0, 2.0],
        [3.0, 3.0, 3.0],
    ]));
    out.push(Triangle::new([
        [1.0, 1.0, 1.0],
        [1.0, 1.0, 1.0],
        [3.0, 1.0, 3.0],
    ]));
    out.push(Triangle::new([
        [1.0, f32::NAN, 1.0],
        [2.0, 2.0, 2.0],
        [3.0, 1.0, 3.0],
    ]));
    (out, 3)
}

fn chunk_pass(
    cv: &mut ChunkVoxelizer,
    tris: &[Triangle],
    batches: &[usize],
) -> BTreeMap<[u32; 3], Vec<Voxel>> {
    let mut out = BTreeMap::new();
    let cpa = RES / 256;
    for z in 0..cpa {
        for y in 0..cpa {
            for x in 0..cpa {
                cv.begin([x * 256, y * 256, z * 256]);
                let mut rest = tris;
                let mut b = batches.iter().cycle();
                while !rest.is_empty() {
                    let n = (*b.next().unwrap()).min(rest.len());
                    cv.add(&rest[..n]);
                    rest = &rest[n..];
                }
                let v = cv.finish();
                if !v.is_empty() {
                    out.insert([x, y, z], v);
                }
            }
        }
    }
    out
}

/// Barycentrics of `q` by the ratio of sub-triangle areas (a different formula from the crate's).
fn bary(t: &[[f64; 3]; 3], q: [f64; 3]) -> [f64; 3] {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let nn = dot(n, n);
    let a0 = dot(cross(sub(t[1], q), sub(t[2], q)), n) / nn;
    let a1 = dot(cross(sub(t[2], q), sub(t[0], q)), n) / nn;
    [a0, a1, 1.0 - a0 - a1]
}

fn normalize(v: [f64; 3]) -> Option<[f64; 3]> {
    let l = dot(v, v).sqrt();
    (l > 0.0 && l.is_finite()).then(|| v.map(|x| x / l))
}

#[test]
fn chunks_match_whole_grid_and_brute_force_attributes() {
    for mode in [Mode::Conservative, Mode::Thin] {
        let (tris, nskip) = triangles(31);
        let mut cv = ChunkVoxelizer::new(mode);
        let chunks = chunk_pass(&mut cv, &tris, &[usize::MAX]);
        assert_eq!(cv.skipped(), nskip * 8, "skipped counts each add");

        // sorted by Morton, positions unique
        for v in chunks.values() {
            for w in v.windows(2) {
                assert!(w[0].morton() < w[1].morton(), "not strictly Morton-sorted");
            }
        }

        // reference voxel sets: every triangle over the full grid, in order
        let mut reference: BTreeMap<[i32; 3], Vec<usize>> = BTreeMap::new();
        for (i, t) in tris.iter().enumerate() {
            voxelize_triangle(&t.v, [0; 3], [RES as i32 - 1; 3], mode, &mut |p| {
                reference.entry(p).or_default().push(i)
            });
        }
        let mut got: BTreeMap<[i32; 3], Voxel> = BTreeMap::new();
        for (c, vs) in &chunks {
            for v in vs {
                let p = v.pos();
                got.insert([0, 1, 2].map(|k| (c[k] * 256 + p[k] as u32) as i32), *v);
            }
        }
        assert_eq!(got.len(), reference.len(), "{mode}: voxel counts differ");
        assert!(got.keys().eq(reference.keys()), "{mode}: voxel sets differ");

        // brute-force attributes
        let (mut exact_n, mut exact_c, mut zero_w) = (0, 0, 0);
        for (p, ids) in &reference {
            let (mut w, mut wn, mut wc) = (0.0, [0.0; 3], [0.0; 4]);
            let (mut un, mut uc) = ([0.0; 3], [0.0; 4]);
            for &i in ids {
                let t = &tris[i];
                let t64 = f64tri(&t.v);
                let (a, q) = clipped_area(&t.v, *p);
                let l = bary(&t64, q);
                let face = normalize(cross(sub(t64[1], t64[0]), sub(t64[2], t64[0]))).unwrap();
                let n = if t.flags & TRI_HAS_NORMALS != 0 {
                    normalize([0, 1, 2].map(|k| (0..3).map(|j| l[j] * t.n[j][k] as f64).sum()))
                        .unwrap_or(face)
                } else {
                    face
                };
                let c: [f64; 4] =
                    [0, 1, 2, 3].map(|k| (0..3).map(|j| l[j] * t.c[j][k] as f64).sum());
                w += a;
                for k in 0..3 {
                    wn[k] += a * n[k];
                    un[k] += n[k];
                }
                for k in 0..4 {
                    wc[k] += a * c[k];
                    uc[k] += c[k];
                }
            }
            let (n, c) = if w > 0.0 {
                (wn.map(|x| x / w), wc.map(|x| x / w))
            } else {
                zero_w += 1;
                (
                    un.map(|x| x / ids.len() as f64),
                    uc.map(|x| x / ids.len() as f64),
                )
            };
            let v = got[p];
            let q = unpack_normal(v.normal);
            match normalize(n) {
                Some(u) => {
                    let e = u.map(|x| (x * 511.0).round() as i32);
                    let d = (0..3).map(|k| (q[k] - e[k]).abs()).max().unwrap();
                    assert!(d <= 1, "{mode} voxel {p:?}: normal {q:?} vs expected {e:?}");
                    exact_n += (d == 0) as usize;
                }
                None => assert_eq!(q, [0, 0, 0]),
            }
            let rgba = v.rgba();
            let e = c.map(|x| x.round().clamp(0.0, 255.0) as i32);
            let d = (0..4).map(|k| (rgba[k] as i32 - e[k]).abs()).max().unwrap();
            assert!(
                d <= 1,
                "{mode} voxel {p:?}: colour {rgba:?} vs expected {e:?}"
            );
            exact_c += (d == 0) as usize;
            assert_eq!(v.mask(), face_mask(v.normal) | border_caps(v.pos()));
        }
        eprintln!(
            "{mode}: {} voxels in {} chunks, normals exact {exact_n}, colours exact {exact_c}, zero-weight voxels {zero_w}",
            got.len(),
            chunks.len()
        );
        assert!(exact_n * 100 >= got.len() * 99 && exact_c * 100 >= got.len() * 99);
        assert!(chunks.len() == 8, "the test set should touch all 8 chunks");

        // batch independence and determinism (same voxelizer reused, fresh voxelizer)
        for batches in [&[1usize][..], &[7, 1, 30], &[100, 3]] {
            assert_eq!(
                chunk_pass(&mut cv, &tris, batches),
                chunks,
                "{mode}: depends on batching {batches:?}"
            );
        }
        assert_eq!(
            chunk_pass(&mut ChunkVoxelizer::new(mode), &tris, &[50]),
            chunks
        );

        // the parallel grid driver gives the same bytes on 1 and 2 threads
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let g = pool.install(|| voxelize_grid(&tris, RES, mode)).unwrap();
            assert_eq!(g.skipped, nskip);
            let gm: BTreeMap<[u32; 3], Vec<Voxel>> = g.chunks.into_iter().collect();
            assert_eq!(
                gm, chunks,
                "{mode}: voxelize_grid on {threads} threads differs"
            );
        }
    }
}

#[test]
fn begin_discards_unfinished_chunk() {
    let mut cv = ChunkVoxelizer::new(Mode::Thin);
    let t = Triangle::new([[1.0, 1.0, 1.5], [9.0, 1.0, 1.5], [1.0, 9.0, 1.5]]);
    cv.begin([0; 3]);
    cv.add(&[t]);
    let a = cv.finish();
    cv.begin([0; 3]);
    cv.add(&[t, t]);
    cv.begin([0; 3]);
    cv.add(&[t]);
    assert_eq!(cv.finish(), a);
    // a chunk the triangle does not reach is empty
    cv.begin([256, 0, 0]);
    cv.add(&[t]);
    assert!(cv.finish().is_empty());
}
