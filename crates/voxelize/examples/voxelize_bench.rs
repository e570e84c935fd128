//! Voxelization throughput on a made-up mesh: an icosphere filling a grid.
//!
//! `cargo run --release -p voxlod-voxelize --example voxelize_bench -- [subdiv=6] [resolution=1024] [mesh]`
//!
//! With a mesh file (PLY, OBJ, STL) its triangles, fitted to the grid, replace the icosphere
//! (`-` keeps the icosphere). A fifth argument `fast` or `general` runs only that chunk path and
//! skips the grid driver (for profiling); `small` runs the fast path with and without the small
//! triangle path (`ChunkVoxelizer::set_small_path`) and counts the records that differ. A sixth argument `sums` also counts, per mode, the
//! voxels whose normal sum nearly cancels (`|N|/W < 1.06e-4·(K+2)`, where the f32 sums do not
//! bound the normal to one step; see `chunk::Acc`), and the voxels with one contribution (whose
//! records need no clipped area when the mesh's attributes are flat).
//!
//! Reports, per mode: the bare overlap test (`voxelize_triangle`, counting voxels), the full
//! chunk voxelizer on one thread (overlap + clipping + attributes + encoding) with the fast paths
//! and with the general clipping only (`ChunkVoxelizer::set_fast_paths(false)`), whether both
//! give the same voxel records, and `voxelize_grid` on all rayon threads.
//!
//! Comparing voxelizer methods (the paper's Table 2: one thread, set only and with attributes):
//!
//! `voxelize_bench - RES MESH methods sat,scanline [conservative|thin|both] [rounds=3] [set]`
//!
//! runs, per mode and round, each method in turn (interleaved): the set only
//! (`voxelize_triangle_with`, whole triangles, counting voxels) and the chunk voxelizer with
//! attributes on one thread (fast paths), both as CPU time of the thread; then prints the
//! median per method, the voxel counts, and whether the sets and records equal the first
//! method's. A last argument `set` skips the chunk voxelizer.

use std::collections::HashMap;
use std::time::Instant;

use voxlod_format::Voxel;
use voxlod_geom::{Bounds, Grid, Triangle, CHUNK};
use voxlod_voxelize::{
    voxelize_grid, voxelize_triangle, voxelize_triangle_with, ChunkVoxelizer, Method, Mode,
};

/// The icosphere filling 90% of the grid, vertex colours red, green, blue.
fn sphere(subdiv: u32, res: u32) -> Vec<Triangle> {
    let r = 0.45 * res as f64;
    let c = 0.5 * res as f64 + 0.123;
    println!("icosphere subdiv {subdiv}, radius {r:.0}");
    voxlod_testkit::mesh::triangles(&voxlod_testkit::mesh::icosphere(subdiv))
        .iter()
        .map(|t| {
            let mut tri = Triangle::new(t.map(|p| p.map(|x| (c + r * x) as f32)));
            tri.c = [[200, 30, 30, 255], [30, 200, 30, 255], [30, 30, 200, 255]];
            tri
        })
        .collect()
}

/// A mesh file's triangles in grid coordinates (the grid fitted to its bounds).
fn mesh(path: &std::path::Path, res: u32) -> Vec<Triangle> {
    let src = voxlod_ingest::MeshSource::open(path).expect("open mesh");
    let mut tris = Vec::new();
    src.stream(
        &mut |b| {
            tris.extend_from_slice(b);
            Ok(())
        },
        &mut |_, _| {},
    )
    .expect("read mesh");
    let mut bounds = Bounds::default();
    for t in &tris {
        bounds.add_triangle(t);
    }
    let grid = Grid::fit(&bounds, res).expect("grid");
    for t in &mut tris {
        t.v = t.v.map(|p| grid.to_grid(p));
    }
    println!("{}: {}", path.display(), src.info().format);
    tris
}

/// CPU time of this thread in seconds (Linux schedstat), so that the one-thread numbers are
/// meaningful on a shared machine; `None` elsewhere.
fn thread_cpu() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    Some(s.split_whitespace().next()?.parse::<f64>().ok()? * 1e-9)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.get(4).map(|s| s.as_str()) == Some("methods") {
        return compare_methods(&args);
    }
    let subdiv: u32 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(6);
    let res: u32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1024);
    // (fast paths, small path)
    let paths: &[(bool, bool)] = match args.get(4).map(|s| s.as_str()) {
        Some("fast") => &[(true, true)],
        Some("general") => &[(false, false)],
        Some("small") => &[(true, true), (true, false)],
        _ => &[(true, true), (false, false)],
    };
    let tris = match args.get(3).filter(|s| *s != "-") {
        Some(path) => mesh(std::path::Path::new(path), res),
        None => sphere(subdiv, res),
    };
    println!(
        "{} triangles in a {res}³ grid, {} rayon threads",
        tris.len(),
        rayon::current_num_threads()
    );

    for mode in [Mode::Conservative, Mode::Thin] {
        // bare overlap test
        let c0 = thread_cpu();
        let t0 = Instant::now();
        let mut n = 0u64;
        for t in &tris {
            voxelize_triangle(&t.v, [0; 3], [res as i32 - 1; 3], mode, &mut |_| n += 1);
        }
        let dt = cpu_or_wall(c0, t0);
        println!(
            "{mode:>12} overlap only (cpu)  : {n:>10} voxel hits  {dt:7.3} s  {:7.2} M voxels/s",
            n as f64 / dt / 1e6
        );

        // full chunk voxelizer, one thread: bin, then chunk by chunk
        let mut outputs = Vec::new();
        let mut count = 0usize;
        for &(fast, small) in paths {
            let grid = Grid::new([0.0; 3], res as f64, res).expect("grid");
            let c0 = thread_cpu();
            let t0 = Instant::now();
            let mut bins: HashMap<[u32; 3], Vec<Triangle>> = HashMap::new();
            for t in &tris {
                if let Some((lo, hi)) = grid.chunk_range(t) {
                    for z in lo[2]..=hi[2] {
                        for y in lo[1]..=hi[1] {
                            for x in lo[0]..=hi[0] {
                                bins.entry([x, y, z]).or_default().push(*t);
                            }
                        }
                    }
                }
            }
            let mut keys: Vec<[u32; 3]> = bins.keys().copied().collect();
            keys.sort();
            let binned = cpu_or_wall(c0, t0);
            let mut cv = ChunkVoxelizer::new(mode);
            cv.set_fast_paths(fast);
            cv.set_small_path(small);
            let mut out = Vec::new();
            count = 0;
            for k in &keys {
                cv.begin(k.map(|x| x * CHUNK));
                cv.add(&bins[k]);
                let v = cv.finish();
                count += v.len();
                out.push(v);
            }
            let dt = cpu_or_wall(c0, t0);
            let name = match (fast, small) {
                (true, true) => "fast",
                (true, false) => "nosmall",
                _ => "general",
            };
            println!(
                "{mode:>12} chunk {name:>7}, 1 thread (cpu): {count:>10} voxels  {dt:7.3} s  {:7.2} M voxels/s  ({} chunks, {} small triangles; binning {binned:.3} s, then {:.0} ns per binned triangle)",
                count as f64 / dt / 1e6,
                keys.len(),
                cv.small_triangles(),
                (dt - binned) * 1e9 / bins.values().map(Vec::len).sum::<usize>() as f64
            );
            outputs.push(out);
        }
        if args.get(5).map(|s| s.as_str()) == Some("sums") {
            let grid = Grid::new([0.0; 3], res as f64, res).expect("grid");
            let mut bins: HashMap<[u32; 3], Vec<Triangle>> = HashMap::new();
            for t in &tris {
                if let Some((lo, hi)) = grid.chunk_range(t) {
                    for z in lo[2]..=hi[2] {
                        for y in lo[1]..=hi[1] {
                            for x in lo[0]..=hi[0] {
                                bins.entry([x, y, z]).or_default().push(*t);
                            }
                        }
                    }
                }
            }
            let mut cv = ChunkVoxelizer::new(mode);
            let (mut total, mut cancel) = (0u64, 0u64);
            // voxels with one contribution, and (triangle, voxel) pairs in all and in voxels
            // with two or more contributions (the ones whose records need clipped areas)
            let (mut single, mut pairs, mut multi_pairs) = (0u64, 0u64, 0u64);
            for (k, ts) in &bins {
                cv.begin(k.map(|x| x * CHUNK));
                cv.add(ts);
                for s in cv.finish_sums() {
                    total += 1;
                    pairs += s.k as u64;
                    if s.k == 1 {
                        single += 1;
                    } else {
                        multi_pairs += s.k as u64;
                    }
                    let n = s.n.map(|c| c as f64);
                    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    let w = if s.w > 0.0 { s.w as f64 } else { s.k as f64 };
                    cancel += (len < 1.06e-4 * (s.k as f64 + 2.0) * w) as u64;
                }
            }
            println!("{mode:>12} near-cancelling normal sums: {cancel} of {total} voxels");
            println!(
                "{mode:>12} contributors: {single} of {total} voxels ({:.1} %) have one; {pairs} pairs, {multi_pairs} ({:.1} %) in voxels with two or more",
                100.0 * single as f64 / total as f64,
                100.0 * multi_pairs as f64 / pairs as f64
            );
        }
        if outputs.len() < 2 {
            continue;
        }
        let differ: usize = outputs[0]
            .iter()
            .zip(&outputs[1])
            .map(|(a, b)| {
                if a.len() != b.len() {
                    a.len().max(b.len())
                } else {
                    a.iter().zip(b).filter(|(x, y)| x != y).count()
                }
            })
            .sum();
        let names = if paths[1].0 {
            "small vs nosmall"
        } else {
            "fast vs general"
        };
        println!("{mode:>12} {names}: {differ} of {count} voxel records differ");

        if paths[1].0 {
            continue;
        }
        // parallel grid driver
        let t0 = Instant::now();
        let g = voxelize_grid(&tris, res, mode).expect("grid");
        let dt = t0.elapsed().as_secs_f64();
        assert_eq!(g.len(), count);
        println!(
            "{mode:>12} voxelize_grid (wall): {:>10} voxels      {dt:7.3} s  {:7.2} M voxels/s",
            g.len(),
            g.len() as f64 / dt / 1e6
        );
    }
}

/// Thread CPU seconds since `c0` if available, else wall seconds since `t0`.
fn cpu_or_wall(c0: Option<f64>, t0: Instant) -> f64 {
    match (c0, thread_cpu()) {
        (Some(a), Some(b)) => b - a,
        _ => t0.elapsed().as_secs_f64(),
    }
}

/// Bins `tris` to chunks and runs the chunk voxelizer with `method` on one thread: (records per
/// chunk, thread CPU seconds).
fn chunk_run(tris: &[Triangle], res: u32, mode: Mode, method: Method) -> (Vec<Vec<Voxel>>, f64) {
    let grid = Grid::new([0.0; 3], res as f64, res).expect("grid");
    let c0 = thread_cpu();
    let t0 = Instant::now();
    let mut bins: HashMap<[u32; 3], Vec<Triangle>> = HashMap::new();
    for t in tris {
        if let Some((lo, hi)) = grid.chunk_range(t) {
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        bins.entry([x, y, z]).or_default().push(*t);
                    }
                }
            }
        }
    }
    let mut keys: Vec<[u32; 3]> = bins.keys().copied().collect();
    keys.sort();
    let mut cv = ChunkVoxelizer::new(mode);
    cv.set_method(method);
    let out = keys
        .iter()
        .map(|k| {
            cv.begin(k.map(|x| x * CHUNK));
            cv.add(&bins[k]);
            cv.finish()
        })
        .collect();
    (out, cpu_or_wall(c0, t0))
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// `voxelize_bench - RES MESH methods LIST [MODES] [ROUNDS]`: see the module docs.
fn compare_methods(args: &[String]) {
    let res: u32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1024);
    let tris = match args.get(3).filter(|s| *s != "-") {
        Some(path) => mesh(std::path::Path::new(path), res),
        None => sphere(6, res),
    };
    let methods: Vec<Method> = args
        .get(5)
        .map_or("sat,scanline", |s| s.as_str())
        .split(',')
        .map(|m| m.parse().expect("method"))
        .collect();
    let modes: &[Mode] = match args.get(6).map(|s| s.as_str()) {
        Some("thin") => &[Mode::Thin],
        Some("both") => &[Mode::Conservative, Mode::Thin],
        _ => &[Mode::Conservative],
    };
    let rounds: usize = args.get(7).and_then(|s| s.parse().ok()).unwrap_or(3);
    let set_only = args.get(8).map(|s| s.as_str()) == Some("set");
    println!(
        "{} triangles in a {res}³ grid, one thread, {rounds} interleaved rounds",
        tris.len()
    );
    for &mode in modes {
        let methods: Vec<Method> = methods
            .iter()
            .copied()
            .filter(|m| m.supports(mode))
            .collect();
        let mut set_t = vec![Vec::new(); methods.len()];
        let mut chunk_t = vec![Vec::new(); methods.len()];
        let mut counts = vec![(0u64, 0usize); methods.len()];
        let mut same = vec![(true, true); methods.len()];
        let mut first_set: Option<Vec<u64>> = None;
        let mut first_chunks: Option<Vec<Vec<Voxel>>> = None;
        for round in 0..rounds {
            for (i, &m) in methods.iter().enumerate() {
                // set only: whole triangles, the voxels hashed in order
                let c0 = thread_cpu();
                let t0 = Instant::now();
                let mut n = 0u64;
                let mut h = 0u64;
                let mut hashes = Vec::with_capacity(if round == 0 { tris.len() } else { 0 });
                for t in &tris {
                    voxelize_triangle_with(&t.v, [0; 3], [res as i32 - 1; 3], mode, m, &mut |p| {
                        n += 1;
                        h = h.rotate_left(5)
                            ^ (p[0] as u64) << 40
                            ^ (p[1] as u64) << 20
                            ^ p[2] as u64;
                    });
                    if round == 0 {
                        hashes.push(h);
                    }
                }
                set_t[i].push(cpu_or_wall(c0, t0));
                counts[i].0 = n;
                if round == 0 {
                    match &first_set {
                        None => first_set = Some(hashes),
                        Some(f) => same[i].0 = *f == hashes,
                    }
                }
                // with attributes: the chunk voxelizer
                if set_only {
                    continue;
                }
                let (out, dt) = chunk_run(&tris, res, mode, m);
                chunk_t[i].push(dt);
                counts[i].1 = out.iter().map(|c| c.len()).sum();
                if round == 0 {
                    match &first_chunks {
                        None => first_chunks = Some(out),
                        Some(f) => same[i].1 = *f == out,
                    }
                }
            }
        }
        for (i, m) in methods.iter().enumerate() {
            let s = median(&mut set_t[i]);
            let c = if set_only {
                f64::NAN
            } else {
                median(&mut chunk_t[i])
            };
            println!(
                "{mode:>12} {m:>13}: set only {s:7.3} s ({:>11} voxel hits{}), with attributes {c:7.3} s ({:>10} records{}) [cpu, median of {rounds}]",
                counts[i].0,
                if same[i].0 { "" } else { ", set DIFFERS" },
                counts[i].1,
                if same[i].1 { "" } else { ", records DIFFER" },
            );
        }
    }
}
