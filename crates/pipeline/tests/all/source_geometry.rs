//! `--source-geometry` (docs/FORMAT.md 14.4) end to end: an octree is built from a PLY, and
//! every leaf's stored triangles are compared with the input mesh read independently
//! (`voxlod_testkit::read_ply`), brute force: each input triangle that touches a leaf's chunk box
//! (a separating-axis test written here, not the builder's clipping) must be stored whole in
//! that leaf, within the stated 1/256-voxel quantization error, if it lies inside the
//! quantization box, and otherwise be covered by stored pieces lying in it whose area is the
//! area of the triangle inside the chunk's box (estimated by sampling); no other triangle may be
//! stored. On a made-up mesh (whole, straddling and huge triangles) and on the npm bunny; the
//! file's bytes are the same with 1 and 2 threads.

use std::path::Path;

use voxlod_format::triangles::{BOX_MAX, BOX_MIN, MAX_ERROR};
use voxlod_format::{Reader, SourceMesh};
use voxlod_pipeline::{build, Backend, BuildSettings};
use voxlod_testkit::mesh::{read_ply, write_ply, Indexed};

type Tri = [[f64; 3]; 3];

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn area(t: &Tri) -> f64 {
    let c = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    dot(c, c).sqrt() / 2.0
}

/// Separating axis test of a triangle against the box `[lo, hi]³`.
fn touches(t: &Tri, lo: f64, hi: f64) -> bool {
    let c = (lo + hi) / 2.0;
    let h = (hi - lo) / 2.0;
    let p = t.map(|q| q.map(|x| x - c));
    let e = [sub(p[1], p[0]), sub(p[2], p[1]), sub(p[0], p[2])];
    let mut axes = vec![
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        cross(e[0], e[1]),
    ];
    for ek in e {
        for u in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
            axes.push(cross(ek, u));
        }
    }
    !axes.iter().any(|&a| {
        let d = p.map(|q| dot(q, a));
        let r = h * (a[0].abs() + a[1].abs() + a[2].abs());
        d.iter().cloned().fold(f64::INFINITY, f64::min) > r
            || d.iter().cloned().fold(f64::NEG_INFINITY, f64::max) < -r
    })
}

/// The part of `t`'s area inside `[lo, hi]³`, by a regular barycentric sampling at about
/// half a voxel's spacing.
fn area_inside(t: &Tri, lo: f64, hi: f64) -> f64 {
    let edge = (0..3).map(|k| {
        let d = sub(t[(k + 1) % 3], t[k]);
        dot(d, d).sqrt()
    });
    let n = (edge.fold(0.0, f64::max) * 2.0).ceil().max(300.0) as usize;
    let (mut inside, mut all) = (0u64, 0u64);
    for i in 0..n {
        for j in 0..n - i {
            let (a, b) = (
                (i as f64 + 1.0 / 3.0) / n as f64,
                (j as f64 + 1.0 / 3.0) / n as f64,
            );
            let p: [f64; 3] = std::array::from_fn(|k| {
                t[0][k] + a * (t[1][k] - t[0][k]) + b * (t[2][k] - t[0][k])
            });
            all += 1;
            inside += p.iter().all(|&x| (lo..=hi).contains(&x)) as u64;
        }
    }
    area(t) * inside as f64 / all as f64
}

/// The input triangles in grid coordinates of the file (leaf voxels), as the build moves them.
fn grid_triangles(mesh: &Indexed, r: &Reader) -> Vec<Tri> {
    let spec = r.spec();
    let s = 1.0 / spec.voxel_size;
    mesh.1
        .iter()
        .map(|f| {
            f.map(|i| {
                let p = mesh.0[i as usize].map(|x| x as f32);
                std::array::from_fn(|a| ((p[a] as f64 - spec.origin[a]) * s) as f32 as f64)
            })
        })
        .filter(|t: &Tri| area(t) > 0.0)
        .collect()
}

/// Compares every leaf's stored triangles with the input triangles (see the module docs).
/// Returns (whole triangles matched, triangles clipped).
fn compare(r: &Reader, input: &[Tri]) -> (u64, u64) {
    let tol = MAX_ERROR + r.spec().resolution as f64 * f32::EPSILON as f64;
    let (mut matched, mut clipped) = (0u64, 0u64);
    for (i, e) in r.nodes().iter().enumerate().filter(|(_, e)| e.level == 0) {
        let origin = e.pos().map(|c| c as f64 * 256.0);
        let local: Vec<Tri> = input.iter().map(|t| t.map(|p| sub(p, origin))).collect();
        let mesh: SourceMesh = match r.source_triangles(i).unwrap() {
            Some(m) => m,
            None => {
                assert!(
                    !local.iter().any(|t| touches(t, 0.0, 256.0)),
                    "leaf {:?} has no source triangles, but input triangles touch it",
                    e.pos()
                );
                continue;
            }
        };
        let stored: Vec<Tri> = mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| mesh.position(v)))
            .collect();
        let mut used = vec![false; stored.len()];
        let near =
            |a: &Tri, b: &Tri| (0..3).all(|k| (0..3).all(|x| (a[k][x] - b[k][x]).abs() <= tol));
        for t in local.iter().filter(|t| touches(t, 0.0, 256.0)) {
            let inside = t
                .iter()
                .flatten()
                .all(|&x| (BOX_MIN..=BOX_MAX).contains(&x));
            if inside {
                let k = (0..stored.len())
                    .find(|&k| !used[k] && near(&stored[k], t))
                    .unwrap_or_else(|| {
                        panic!("leaf {:?}: input triangle {t:?} is not stored", e.pos())
                    });
                used[k] = true;
                matched += 1;
                continue;
            }
            // clipped: the pieces in the triangle's plane, covering its part inside the chunk
            clipped += 1;
            let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
            let len = dot(n, n).sqrt();
            let mut got = 0.0;
            for k in 0..stored.len() {
                let on_plane = stored[k]
                    .iter()
                    .all(|p| (dot(sub(*p, t[0]), n) / len).abs() <= 2.0 * tol);
                if !used[k] && on_plane {
                    used[k] = true;
                    got += area(&stored[k]);
                }
            }
            let want = area_inside(t, 0.0, 256.0);
            assert!(
                (got - want).abs() <= 0.01 * want + 1.0,
                "leaf {:?}: the clipped pieces of {t:?} cover {got} voxels², the triangle has {want} inside the chunk",
                e.pos()
            );
        }
        // nothing else: only triangles that graze the box within the builder's slack remain
        for (k, s) in stored.iter().enumerate().filter(|(k, _)| !used[*k]) {
            let grazing = local
                .iter()
                .any(|t| near(s, t) && touches(t, -1e-3, 256.0 + 1e-3));
            assert!(
                grazing,
                "leaf {:?}: stored triangle {k} {s:?} is no input triangle touching the chunk",
                e.pos()
            );
        }
    }
    (matched, clipped)
}

fn settings(resolution: u32, threads: usize) -> BuildSettings {
    BuildSettings {
        resolution,
        threads,
        backend: Backend::Cpu,
        source_geometry: true,
        ..Default::default()
    }
}

/// A made-up mesh for 1024³ (4×4×4 leaf chunks over the bounding cube [−1.5, 2.5]³): a sphere
/// of small triangles of radius 51 voxels around the chunk corner (512, 512, 512), so many
/// straddle chunk borders, and one triangle across the whole grid, reaching past the
/// quantization box of every chunk it touches.
fn made_up(dir: &Path) -> (std::path::PathBuf, Indexed) {
    let (mut v, mut f) = voxlod_testkit::mesh::icosphere(3);
    for p in &mut v {
        *p = p.map(|x| 0.5 + 0.2 * x);
    }
    let n = v.len() as u32;
    // a plane through the sphere, much larger than the quantization box of any chunk
    v.extend([[-1.5, 0.3, -1.5], [2.5, 0.3, -1.5], [0.5, 0.3, 2.5]]);
    f.push([n, n + 1, n + 2]);
    let path = dir.join("made_up.ply");
    write_ply(&path, &(v.clone(), f.clone()));
    (path, (v, f))
}

#[test]
fn made_up_mesh_round_trip_and_threads() {
    let dir = tempfile::tempdir().unwrap();
    let (input, mesh) = made_up(dir.path());
    let (a, b) = (dir.path().join("a.voxlod"), dir.path().join("b.voxlod"));
    let s = build(&input, &a, &settings(1024, 1)).unwrap();
    build(&input, &b, &settings(1024, 2)).unwrap();
    assert_eq!(
        std::fs::read(&a).unwrap(),
        std::fs::read(&b).unwrap(),
        "1 and 2 threads differ"
    );
    let r = Reader::open(&a).unwrap();
    assert!(r.has_source_triangles());
    let (matched, clipped) = compare(&r, &grid_triangles(&mesh, &r));
    let src = s.source_geometry.unwrap();
    assert!(matched > 1000 && clipped >= 4, "{matched} {clipped}");
    // the builder may keep a few more: triangles grazing a chunk within its rounding slack
    assert!(src.triangles_kept >= matched + clipped);
    assert_eq!(src.triangles_clipped, clipped);
    assert_eq!(r.source_triangle_count(), src.triangles_stored);
    let v = voxlod_check::verify(&a);
    assert!(v.ok(), "{:?}", v.problems);
    assert_eq!(v.source_triangles_checked, src.triangles_stored);
}

#[test]
fn bunny_round_trip() {
    let Some(path) = voxlod_testkit::shared_mesh(module_path!(), "npm-bunny/bunny.ply") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bunny.voxlod");
    let s = build(&path, &out, &settings(1024, 2)).unwrap();
    let r = Reader::open(&out).unwrap();
    let mesh = read_ply(&path);
    let (matched, clipped) = compare(&r, &grid_triangles(&mesh, &r));
    let src = s.source_geometry.unwrap();
    // every bunny triangle is stored (some in two or more chunks), none clipped
    assert_eq!(clipped, 0);
    assert!(
        matched >= mesh.1.len() as u64 - s.degenerate_skipped,
        "{matched}"
    );
    assert!(src.triangles_kept >= matched);
    let v = voxlod_check::verify(&out);
    assert!(v.ok(), "{:?}", v.problems);
}

/// A chunk that a triangle only pokes into, by 1/80 voxel, away from the voxel centres: the
/// source stage keeps the triangle there (it touches the chunk's box), thin voxelization gives
/// the chunk no voxel, so the file does not store it. The summary counts what the file stores
/// (it counted the source log's chunks before): triangles and payload bytes equal the file's.
#[test]
fn summary_counts_the_triangles_the_file_stores() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("poke.ply");
    // over the bounding cube [−1, 1]³ (two tiny triangles at corners of z = −1 span it), a
    // triangle in z = 0.1 whose vertex at x = 0.0001 reaches 0.0128 voxels past the chunk
    // border x = 256 of the 512³ grid
    let v = vec![
        [-0.5, -0.5, 0.1],
        [0.0001, 0.2, 0.1],
        [-0.5, 0.5, 0.1],
        [-1.0, -1.0, -1.0],
        [-0.99, -1.0, -1.0],
        [-1.0, -0.99, -1.0],
        [1.0, -1.0, -1.0],
        [0.99, -1.0, -1.0],
        [1.0, -0.99, -1.0],
    ];
    write_ply(&input, &(v, vec![[0, 1, 2], [3, 4, 5], [6, 7, 8]]));
    let out = dir.path().join("poke.voxlod");
    let s = BuildSettings {
        mode: voxlod_voxelize::Mode::Thin,
        ..settings(512, 1)
    };
    let summary = build(&input, &out, &s).unwrap();
    let src = summary.source_geometry.unwrap();
    let r = Reader::open(&out).unwrap();
    let poked = r.find(0, [1, 1, 1]);
    assert!(poked.is_none(), "the poked chunk should get no voxel");
    // kept: the big triangle in its three chunks, the corner triangles in theirs
    assert_eq!(src.triangles_kept, 5);
    assert_eq!(r.source_triangle_count(), 4);
    assert_eq!(src.triangles_stored, r.source_triangle_count());
    assert_eq!(
        src.payload_bytes,
        r.channel_payload_bytes(voxlod_format::CHANNEL_TRIANGLES)
    );
    let v = voxlod_check::verify(&out);
    assert!(v.ok(), "{:?}", v.problems);
    assert_eq!(v.source_triangles_checked, src.triangles_stored);
}
