//! Measures streaming throughput (triangles per second) of meshes, and can write any mesh as
//! an indexed binary little-endian PLY to benchmark the memory-mapped path.
//!
//! ```text
//! cargo run --release -p voxlod-ingest --example ingest_bench -- MESH... [--write-binary OUT.ply] [--reps N]
//! ```

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;
use voxlod_geom::Triangle;
use voxlod_ingest::MeshSource;

fn write_binary_ply(tris: &[Triangle], out: &Path) -> std::io::Result<()> {
    // shared vertices by exact position, so the file is an indexed mesh like the input
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let mut verts: Vec<[f32; 3]> = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::with_capacity(tris.len());
    for t in tris {
        faces.push(t.v.map(|p| {
            *ids.entry(p.map(f32::to_bits)).or_insert_with(|| {
                verts.push(p);
                verts.len() as u32 - 1
            })
        }));
    }
    let mut w = std::io::BufWriter::new(std::fs::File::create(out)?);
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        verts.len(),
        faces.len()
    )?;
    for v in &verts {
        for x in v {
            w.write_all(&x.to_le_bytes())?;
        }
    }
    for f in &faces {
        w.write_all(&[3])?;
        for i in f {
            w.write_all(&i.to_le_bytes())?;
        }
    }
    w.flush()?;
    eprintln!(
        "wrote {} ({} vertices, {} faces)",
        out.display(),
        verts.len(),
        faces.len()
    );
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut paths: Vec<PathBuf> = Vec::new();
    let mut write_to = None;
    let mut reps = 3;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--write-binary" => {
                write_to = Some(PathBuf::from(
                    args.next().ok_or("--write-binary needs a path")?,
                ))
            }
            "--reps" => reps = args.next().ok_or("--reps needs a number")?.parse()?,
            _ => paths.push(a.into()),
        }
    }
    if paths.is_empty() {
        return Err("usage: ingest_bench MESH... [--write-binary OUT.ply] [--reps N]".into());
    }
    for p in &paths {
        let t0 = Instant::now();
        let src = MeshSource::open(p)?;
        let open_s = t0.elapsed().as_secs_f64();
        let mut best = f64::INFINITY;
        let mut kept = Vec::new();
        let mut stats = Default::default();
        for rep in 0..reps {
            let keep = rep == 0 && write_to.is_some();
            let mut checksum = 0f64;
            let t = Instant::now();
            stats = src.stream(
                &mut |b| {
                    // touch every triangle so the work cannot be skipped
                    checksum += b.iter().map(|t| t.v[0][0] as f64).sum::<f64>();
                    if keep {
                        kept.extend_from_slice(b);
                    }
                    Ok(())
                },
                &mut |_, _| {},
            )?;
            best = best.min(t.elapsed().as_secs_f64());
            std::hint::black_box(checksum);
        }
        println!(
            "{}: {} | open {:.1} ms | stream best of {reps}: {:.1} ms | {} triangles ({} degenerate skipped) | {:.2} M triangles/s",
            p.display(),
            src.info().format,
            open_s * 1e3,
            best * 1e3,
            stats.triangles,
            stats.degenerate_skipped,
            (stats.triangles + stats.degenerate_skipped) as f64 / best / 1e6
        );
        if let Some(out) = write_to.take() {
            write_binary_ply(&kept, &out)?;
        }
    }
    Ok(())
}
