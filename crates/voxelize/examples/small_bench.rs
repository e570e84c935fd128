//! The chunk voxelizer alone on a scan's triangles in world coordinates, as the build feeds it
//! (`ChunkVoxelizer::add_world`, chunk by chunk, in input order): for profiling and timing the
//! small-triangle path (`small.rs`) without ingest, bins and the octree.
//!
//! `small_bench dump INPUT OUT N RES` keeps the first `N` triangles of `INPUT` (their world
//! positions, colours and flags) and the grid the build fits to the whole input at `RES`³
//! (`Grid::fit` of its bounds) in `OUT`, a plain little-endian file:
//!
//! `cargo run --release -p voxlod-voxelize --example small_bench -- dump gen1e8.ply g8.bin 3000000 1024`
//!
//! `small_bench run FILE [ROUNDS=3] [small|general] [CATEGORY]` bins those triangles by chunk
//! (`Grid::world_chunk_range`, input order kept), then per round voxelizes every chunk on one
//! thread in batches of 8,192 triangles and prints the thread's CPU time, nanoseconds per
//! binned triangle (one in two chunks counts twice), the small path's share and an FNV-1a hash of every chunk's records
//! (equal hashes: equal records). `general` turns the small path off
//! (`ChunkVoxelizer::set_small_path(false)`: the reference, whose records may differ in the last
//! bits, so its hash differs). A fifth argument `0`–`4` keeps only the triangles whose closed
//! voxel range spans two voxels on that many axes (4: more than two on some axis).

use std::io::{Read, Write};

use voxlod_geom::{Bounds, Grid, Triangle};
use voxlod_voxelize::{ChunkVoxelizer, Mode};

/// CPU time of this thread in seconds (Linux schedstat).
fn thread_cpu() -> f64 {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").expect("schedstat");
    s.split_whitespace().next().unwrap().parse::<f64>().unwrap() * 1e-9
}

fn dump(input: &str, out: &str, n: usize, res: u32) {
    let src = voxlod_ingest::MeshSource::open(std::path::Path::new(input)).expect("open mesh");
    let mut bounds = Bounds::default();
    let mut kept: Vec<Triangle> = Vec::with_capacity(n);
    src.stream(
        &mut |b| {
            for t in b {
                bounds.add_triangle(t);
            }
            let room = n - kept.len().min(n);
            kept.extend_from_slice(&b[..room.min(b.len())]);
            Ok(())
        },
        &mut |_, _| {},
    )
    .expect("read mesh");
    let grid = Grid::fit(&bounds, res).expect("grid");
    let mut w = std::io::BufWriter::new(std::fs::File::create(out).expect("create"));
    for x in grid.origin {
        w.write_all(&x.to_le_bytes()).unwrap();
    }
    w.write_all(&(grid.voxel_size * res as f64).to_le_bytes())
        .unwrap();
    w.write_all(&res.to_le_bytes()).unwrap();
    w.write_all(&(kept.len() as u64).to_le_bytes()).unwrap();
    for t in &kept {
        for p in t.v {
            for c in p {
                w.write_all(&c.to_le_bytes()).unwrap();
            }
        }
        for c in t.c {
            w.write_all(&c).unwrap();
        }
        for p in t.n {
            for c in p {
                w.write_all(&c.to_le_bytes()).unwrap();
            }
        }
        w.write_all(&t.flags.to_le_bytes()).unwrap();
    }
    println!(
        "kept {} triangles, grid origin {:?} voxel {}",
        kept.len(),
        grid.origin,
        grid.voxel_size
    );
}

fn load(path: &str) -> (Grid, Vec<Triangle>) {
    let mut b = Vec::new();
    std::fs::File::open(path)
        .expect("open")
        .read_to_end(&mut b)
        .unwrap();
    let mut at = 0usize;
    let mut take = |n: usize| {
        let s = &b[at..at + n];
        at += n;
        s.to_vec()
    };
    let f64_ = |s: Vec<u8>| f64::from_le_bytes(s.try_into().unwrap());
    let origin = [f64_(take(8)), f64_(take(8)), f64_(take(8))];
    let size = f64_(take(8));
    let res = u32::from_le_bytes(take(4).try_into().unwrap());
    let n = u64::from_le_bytes(take(8).try_into().unwrap()) as usize;
    let grid = Grid::new(origin, size, res).expect("grid");
    let f32_ = |s: &[u8]| f32::from_le_bytes(s.try_into().unwrap());
    let mut tris = Vec::with_capacity(n);
    for _ in 0..n {
        let r = take(36 + 12 + 36 + 4);
        let mut t = Triangle::new([[0.0; 3]; 3]);
        for i in 0..3 {
            for k in 0..3 {
                t.v[i][k] = f32_(&r[(i * 3 + k) * 4..][..4]);
                t.n[i][k] = f32_(&r[48 + (i * 3 + k) * 4..][..4]);
            }
            t.c[i].copy_from_slice(&r[36 + i * 4..][..4]);
        }
        t.flags = u32::from_le_bytes(r[84..88].try_into().unwrap());
        tris.push(t);
    }
    (grid, tris)
}

/// The number of axes on which the closed voxel range of `t` (grid coordinates of `grid`) spans
/// two voxels, or 4 if it spans more on some axis.
fn category(grid: &Grid, t: &Triangle) -> usize {
    let v = t.v.map(|p| grid.to_grid(p).map(|c| c as f64));
    let mut count = 0;
    for k in 0..3 {
        let mn = v[0][k].min(v[1][k]).min(v[2][k]);
        let mx = v[0][k].max(v[1][k]).max(v[2][k]);
        let span = mx.floor() - (mn.ceil() - 1.0);
        if span > 1.0 {
            return 4;
        }
        count += (span == 1.0) as usize;
    }
    count
}

fn run(path: &str, rounds: usize, general: bool, only: Option<usize>) {
    let (grid, mut tris) = load(path);
    if let Some(c) = only {
        tris.retain(|t| category(&grid, t) == c);
    }
    // per chunk, its triangles in input order (as the bins replay them)
    let mut chunks: std::collections::BTreeMap<[u32; 3], Vec<Triangle>> = Default::default();
    for t in &tris {
        if let Some((lo, hi)) = grid.world_chunk_range(t) {
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        chunks.entry([x, y, z]).or_default().push(*t);
                    }
                }
            }
        }
    }
    let binned: usize = chunks.values().map(Vec::len).sum();
    println!(
        "{} triangles, {} chunks, {} binned",
        tris.len(),
        chunks.len(),
        binned
    );
    let mut vz = ChunkVoxelizer::new(Mode::Conservative);
    vz.set_small_path(!general);
    for round in 0..rounds {
        let small0 = vz.small_triangles();
        let t0 = thread_cpu();
        let mut hash = 0xcbf2_9ce4_8422_2325u64;
        let mut voxels = 0usize;
        for (c, ts) in &chunks {
            vz.begin(c.map(|x| x * 256));
            for b in ts.chunks(8192) {
                vz.add_world(&grid, b);
            }
            let out = vz.finish();
            voxels += out.len();
            for v in out {
                for w in [v.pos_mask, v.normal, v.color] {
                    for byte in w.to_le_bytes() {
                        hash = (hash ^ byte as u64).wrapping_mul(0x100_0000_01b3);
                    }
                }
            }
        }
        let cpu = thread_cpu() - t0;
        let small = vz.small_triangles() - small0;
        println!(
            "round {round}: {cpu:.3} s CPU, {:.1} ns/triangle, small {:.1} %, {voxels} voxels, hash {hash:016x}",
            cpu * 1e9 / binned as f64,
            100.0 * small as f64 / binned as f64
        );
    }
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    match a.get(1).map(String::as_str) {
        Some("dump") => dump(&a[2], &a[3], a[4].parse().unwrap(), a[5].parse().unwrap()),
        Some("run") => run(
            &a[2],
            a.get(3).map_or(3, |r| r.parse().unwrap()),
            a.get(4).is_some_and(|g| g == "general"),
            a.get(5).map(|c| c.parse().unwrap()),
        ),
        _ => eprintln!(
            "usage: small_bench dump INPUT OUT N RES | run FILE [ROUNDS] [general|small] [0-4]"
        ),
    }
}
