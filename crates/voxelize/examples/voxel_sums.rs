//! The f32 sums of chosen voxels, with the small-triangle path on and off, to tell whether a
//! record that moved by more than one normal step between two builds lies where the normal sum
//! nearly cancels (`|N|/W < 1.06e-4·(K+2)`, where the sums do not fix the normal; `chunk::Acc`).
//!
//! `cargo run --release -p voxlod-voxelize --example voxel_sums -- MESH RES X Y Z [X Y Z …]`
//!
//! Streams the mesh twice (bounds, then the triangles whose bounding box touches a chosen
//! voxel, in file order), voxelizes those in the voxel's chunk, and prints per voxel `K`, `W`,
//! `|N|/W` and the bound for both paths. A voxel's sums depend only on its own contributions
//! and their order, which the filter keeps.

use voxlod_geom::{Bounds, Grid, Triangle, CHUNK};
use voxlod_ingest::MeshSource;
use voxlod_voxelize::{ChunkVoxelizer, Mode};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    assert!(
        args.len() >= 6 && (args.len() - 3) % 3 == 0,
        "usage: voxel_sums MESH RES X Y Z [X Y Z …]"
    );
    let path = std::path::Path::new(&args[1]);
    let res: u32 = args[2].parse().expect("RES");
    let voxels: Vec<[i64; 3]> = args[3..]
        .chunks(3)
        .map(|c| [0, 1, 2].map(|k| c[k].parse().expect("voxel coordinate")))
        .collect();
    let src = MeshSource::open(path).expect("open mesh");
    let mut bounds = Bounds::default();
    src.stream(
        &mut |b: &[Triangle]| {
            bounds.add_triangles(b);
            Ok(())
        },
        &mut |_, _| {},
    )
    .expect("read mesh");
    let grid = Grid::fit(&bounds, res).expect("grid");
    let mut near: Vec<Vec<Triangle>> = vec![Vec::new(); voxels.len()];
    src.stream(
        &mut |b: &[Triangle]| {
            for t in b {
                let g = t.v.map(|p| grid.to_grid(p));
                for (p, list) in voxels.iter().zip(&mut near) {
                    // the closed voxel range of the triangle holds p
                    let touches = (0..3).all(|k| {
                        let mn = g.iter().map(|q| q[k] as f64).fold(f64::INFINITY, f64::min);
                        let mx = g
                            .iter()
                            .map(|q| q[k] as f64)
                            .fold(f64::NEG_INFINITY, f64::max);
                        (mn.ceil() as i64 - 1) <= p[k] && p[k] <= mx.floor() as i64
                    });
                    if touches {
                        let mut t = *t;
                        t.v = g;
                        list.push(t);
                    }
                }
            }
            Ok(())
        },
        &mut |_, _| {},
    )
    .expect("read mesh");
    for (p, tris) in voxels.iter().zip(&near) {
        let origin = p.map(|c| (c as u32 / CHUNK) * CHUNK);
        for small in [true, false] {
            let mut cv = ChunkVoxelizer::new(Mode::Conservative);
            cv.set_small_path(small);
            cv.begin(origin);
            cv.add(tris);
            let local = [0, 1, 2].map(|k| (p[k] - origin[k] as i64) as u8);
            let Some(s) = cv.finish_sums().into_iter().find(|s| s.pos == local) else {
                println!("{p:?}: not in the set ({} triangles near)", tris.len());
                continue;
            };
            let n = s.n.map(|c| c as f64);
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            let bound = 1.06e-4 * (s.k as f64 + 2.0);
            println!(
                "{p:?} small path {small}: K {} W {:.6e} |N|/W {:.3e} bound {bound:.3e} ({})",
                s.k,
                s.w,
                len / s.w as f64,
                if len / (s.w as f64) < bound {
                    "cancels: the normal is rounding noise"
                } else {
                    "fixed by the sums"
                }
            );
        }
    }
}
