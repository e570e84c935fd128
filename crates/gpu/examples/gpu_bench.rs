//! Wall time of the three GPU schemes (triangle-parallel, fragment-parallel, hybrid) on the
//! paper's kinds of scenes (Rauwendaal & Bailey 2013, Table 1): one chunk-spanning triangle, a
//! fine scan (small even triangles) and an architectural model (mixed sizes), each in one 256³
//! chunk, plus a cutoff sweep of the hybrid scheme and the CPU reference for comparison.
//!
//! Times are wall clock around `voxelize_chunk` (upload, both passes of marking and
//! accumulation, read-back, encoding), best of `--reps` runs: lavapipe's timestamps are not
//! meaningful.
//!
//! ```text
//! cargo run --release -p voxlod-gpu --example gpu_bench -- [--mode thin|conservative] [--reps N]
//! ```

#[path = "../tests/all/common/mod.rs"]
mod common;

use std::time::Instant;

use voxlod_geom::Triangle;
use voxlod_gpu::{GpuMethod, GpuVoxelizer, DEFAULT_CUTOFF};
use voxlod_voxelize::{ChunkVoxelizer, Mode};

fn best<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..reps {
        let t = Instant::now();
        let r = f();
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
        out = Some(r);
    }
    (best, out.expect("reps > 0"))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let mut mode = Mode::Thin;
    let mut reps = 3;
    let mut i = 1;
    while i < args.len() {
        match args[i].as_str() {
            "--mode" => {
                mode = args.get(i + 1).ok_or("--mode needs a value")?.parse()?;
                i += 1;
            }
            "--reps" => {
                reps = args.get(i + 1).ok_or("--reps needs a value")?.parse()?;
                i += 1;
            }
            a => return Err(format!("unknown argument {a}").into()),
        }
        i += 1;
    }
    let dir = common::meshes_dir().ok_or("../shared/data/meshes is missing")?;
    let mut scenes: Vec<(&str, Vec<Triangle>)> = vec![(
        "large triangle (1 tri)",
        vec![Triangle::new([
            [0.5, 0.5, 10.0],
            [255.5, 0.5, 128.0],
            [0.5, 255.5, 250.0],
        ])],
    )];
    let t = Instant::now();
    scenes.push((
        "bun_zipper (69,451 tris)",
        common::to_grid(
            &common::load_mesh(&dir.join("stanford-bunny/bun_zipper.ply")),
            256,
        ),
    ));
    scenes.push((
        "sponza (Dabrovic, 66,450 tris)",
        common::to_grid(
            &common::load_mesh(&dir.join("mcguire-sponza-dabrovic/sponza.obj")),
            256,
        ),
    ));
    eprintln!("meshes loaded in {:.1} s", t.elapsed().as_secs_f64());

    let mut gpu = GpuVoxelizer::new(mode, GpuMethod::Hybrid, DEFAULT_CUTOFF)?;
    println!(
        "adapter: {} ({:?}), mode {mode}, grid 256³ (one chunk), best of {reps}",
        gpu.adapter_name(),
        gpu.precision()
    );
    println!("| scene | CPU ref | triangle | fragment | hybrid @{DEFAULT_CUTOFF} | split small/large | voxels |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    let mut sweeps = Vec::new();
    for (name, tris) in &scenes {
        let mut cpu = ChunkVoxelizer::new(mode);
        let (t_cpu, want) = best(reps, || {
            cpu.begin([0; 3]);
            cpu.add(tris);
            cpu.finish()
        });
        let mut row = Vec::new();
        for m in [GpuMethod::Triangle, GpuMethod::Fragment, GpuMethod::Hybrid] {
            gpu.set_method(m, DEFAULT_CUTOFF);
            gpu.voxelize_chunk([0; 3], tris)?; // warm-up: shader JIT, buffer growth
            let (ms, got) = best(reps, || gpu.voxelize_chunk([0; 3], tris));
            let got = got?;
            if got != want {
                eprintln!(
                    "warning: {name} {m}: GPU differs from CPU: {:?}",
                    common::compare(&want, &got)
                );
            }
            row.push(ms);
        }
        let (s, l) = gpu.last_split();
        println!(
            "| {name} | {t_cpu:.1} ms | {:.1} ms | {:.1} ms | {:.1} ms | {s}/{l} | {} |",
            row[0],
            row[1],
            row[2],
            want.len()
        );
        let mut sweep = Vec::new();
        for cutoff in [0.5f32, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 128.0] {
            gpu.set_method(GpuMethod::Hybrid, cutoff);
            let (ms, r) = best(reps, || gpu.voxelize_chunk([0; 3], tris));
            r?;
            sweep.push((cutoff, ms, gpu.last_split()));
        }
        sweeps.push((name, sweep));
    }
    println!("\nhybrid cutoff sweep (voxels²: ms, small/large):");
    for (name, sweep) in sweeps {
        let cells: Vec<String> = sweep
            .iter()
            .map(|(c, ms, (s, l))| format!("{c}: {ms:.1} ({s}/{l})"))
            .collect();
        println!("- {name}: {}", cells.join(", "));
    }
    Ok(())
}
