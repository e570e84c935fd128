//! Counts the level-0 voxel records that differ between two octree files of the same grid
//! (e.g. built by two versions of the voxelizer), and how much: the largest per-component step
//! of the 10:10:10 normals, the largest angle between them, the largest colour channel
//! difference. `voxlod diff` reports per node; this counts records.
//!
//! `cargo run --release -p voxlod-voxelize --example record_diff -- A.voxlod B.voxlod`
//!
//! Prints the grid position of every record whose normal moved by more than one step.

use std::path::Path;

use voxlod_format::voxel::unpack_normal;
use voxlod_format::Reader;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    assert!(args.len() == 3, "usage: record_diff A.voxlod B.voxlod");
    let a = Reader::open(Path::new(&args[1])).expect("open A");
    let b = Reader::open(Path::new(&args[2])).expect("open B");
    let (mut total, mut differ, mut normal_differ, mut colour_differ, mut mask_only) =
        (0u64, 0u64, 0u64, 0u64, 0u64);
    let (mut max_step, mut max_deg, mut max_col) = (0i32, 0f64, 0i32);
    let mut steps = [0u64; 3];
    for (i, e) in a.nodes().iter().enumerate() {
        if e.level != 0 {
            continue;
        }
        let j = b
            .find(0, e.pos())
            .unwrap_or_else(|| panic!("node {:?} missing in B", e.pos()));
        let va = a.read_node(i).expect("read A");
        let vb = b.read_node(j).expect("read B");
        assert_eq!(
            va.len(),
            vb.len(),
            "node {:?}: voxel counts differ",
            e.pos()
        );
        for (x, y) in va.iter().zip(&vb) {
            assert_eq!(x.pos(), y.pos(), "node {:?}: voxel sets differ", e.pos());
            total += 1;
            if x == y {
                continue;
            }
            differ += 1;
            let (na, nb) = (unpack_normal(x.normal), unpack_normal(y.normal));
            if na != nb {
                normal_differ += 1;
                let s = (0..3).map(|k| (na[k] - nb[k]).abs()).max().unwrap();
                max_step = max_step.max(s);
                if s > 1 {
                    // grid position, for a look at its sums (`voxel_sums`)
                    let g = [0, 1, 2].map(|k| e.pos()[k] * 256 + x.pos()[k] as u32);
                    println!("{s} steps at voxel {} {} {}", g[0], g[1], g[2]);
                }
                steps[(s as usize).min(2)] += 1;
                let fa = na.map(|c| c as f64);
                let fb = nb.map(|c| c as f64);
                let dot: f64 = (0..3).map(|k| fa[k] * fb[k]).sum();
                let la = fa.iter().map(|c| c * c).sum::<f64>().sqrt();
                let lb = fb.iter().map(|c| c * c).sum::<f64>().sqrt();
                if la > 0.0 && lb > 0.0 {
                    let deg = (dot / (la * lb)).clamp(-1.0, 1.0).acos().to_degrees();
                    max_deg = max_deg.max(deg);
                } else {
                    max_deg = max_deg.max(180.0);
                }
            } else if x.color == y.color {
                mask_only += 1;
            }
            if x.color != y.color {
                colour_differ += 1;
                let (ca, cb) = (x.rgba(), y.rgba());
                let d = (0..4)
                    .map(|k| (ca[k] as i32 - cb[k] as i32).abs())
                    .max()
                    .unwrap();
                max_col = max_col.max(d);
            }
        }
    }
    println!(
        "level-0 records: {total}, differing {differ} ({:.4} %): normal {normal_differ} \
         (one step {}, more {}; max step {max_step}, max angle {max_deg:.3}°), colour \
         {colour_differ} (max {max_col}), face mask only {mask_only}",
        100.0 * differ as f64 / total.max(1) as f64,
        steps[1],
        steps[2],
    );
}
