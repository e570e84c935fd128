//! Merge throughput on a real octree: every parent of a voxlod file is merged again from its
//! stored children (decoded first, outside the timing) and compared with the stored parent.
//!
//! `cargo run --release -p voxlod-lod --example merge_bench -- FILE.voxlod [repeats=3]`
//!
//! Prints the CPU time of the merge calls alone (this thread's clock, so other processes on a
//! loaded machine do not count) per child voxel.

use voxlod_format::{Reader, Voxel};
use voxlod_lod::MergeScratch;

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .expect("usage: merge_bench FILE.voxlod [repeats]");
    let repeats: usize = args.next().map_or(3, |r| r.parse().expect("repeats"));
    let reader = Reader::open(path.as_ref()).expect("open");
    let nodes: Vec<Vec<Voxel>> = (0..reader.nodes().len())
        .map(|i| reader.read_node(i).expect("decode"))
        .collect();
    let parents: Vec<usize> = (0..nodes.len())
        .filter(|&i| reader.nodes()[i].level > 0)
        .collect();
    let child_voxels: usize = parents
        .iter()
        .flat_map(|&i| reader.children(i).into_iter().flatten())
        .map(|c| nodes[c].len())
        .sum();
    let parent_voxels: usize = parents.iter().map(|&i| nodes[i].len()).sum();
    let mut scratch = MergeScratch::new();
    let mut out = Vec::new();
    let mut best = f64::INFINITY;
    for _ in 0..repeats {
        let mut secs = 0.0;
        for &i in &parents {
            let kids = reader.children(i);
            let refs: [&[Voxel]; 8] =
                std::array::from_fn(|o| kids[o].map_or(&[][..], |c| &nodes[c][..]));
            let t = thread_cpu_seconds();
            scratch.merge(&refs, &mut out);
            secs += thread_cpu_seconds() - t;
            assert!(out == nodes[i], "parent {i} differs from the stored one");
        }
        best = best.min(secs);
    }
    println!(
        "{} parents, {child_voxels} child voxels -> {parent_voxels} parent voxels: best of {repeats} {:.3} s, {:.2} ns per child voxel, {:.1} M child voxels/s",
        parents.len(),
        best,
        best * 1e9 / child_voxels as f64,
        child_voxels as f64 / best / 1e6
    );
}

/// CPU time of the calling thread.
fn thread_cpu_seconds() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: a valid pointer to a timespec; CLOCK_THREAD_CPUTIME_ID exists on Linux.
    let r = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(r, 0, "clock_gettime");
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}
