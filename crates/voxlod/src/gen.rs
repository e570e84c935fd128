//! `voxlod gen`: writes a massive, scan-like test mesh as binary PLY by streaming.
//!
//! No real scan of hundreds of millions of triangles can be downloaded here, so this lays out
//! many transformed copies of a real base mesh (by default the 871k-triangle Stanford dragon)
//! on a jittered lattice, each with its own rotation, scale and colour ramp: small, even
//! triangles with real local detail, like a scan. Deterministic from the seed: the same
//! arguments give the same bytes.
//!
//! PLY wants every vertex before the first face, so the copies are generated twice, once for
//! the vertex element and once for the face element; only the base mesh is held in memory.

use std::collections::HashMap;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{bail, Context, Result};
use voxlod_ingest::MeshSource;

/// The base mesh as an indexed triangle list, centred at the origin with unit radius.
struct Base {
    positions: Vec<[f32; 3]>,
    faces: Vec<[u32; 3]>,
}

fn load_base(path: &Path) -> Result<Base> {
    let src = MeshSource::open(path)?;
    let mut index: HashMap<[u32; 3], u32> = HashMap::new();
    let mut positions = Vec::new();
    let mut faces = Vec::new();
    src.stream(
        &mut |tris| {
            for t in tris {
                let mut f = [0u32; 3];
                for (k, v) in t.v.iter().enumerate() {
                    let key = v.map(f32::to_bits);
                    f[k] = *index.entry(key).or_insert_with(|| {
                        positions.push(*v);
                        (positions.len() - 1) as u32
                    });
                }
                faces.push(f);
            }
            Ok(())
        },
        &mut |_, _| {},
    )?;
    if faces.is_empty() {
        bail!("{}: the base mesh has no triangles", path.display());
    }
    // centre and scale to unit radius
    let n = positions.len() as f64;
    let mut c = [0f64; 3];
    for p in &positions {
        (0..3).for_each(|a| c[a] += p[a] as f64 / n);
    }
    let r = positions
        .iter()
        .map(|p| {
            (0..3)
                .map(|a| (p[a] as f64 - c[a]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max);
    for p in &mut positions {
        *p = [
            ((p[0] as f64 - c[0]) / r) as f32,
            ((p[1] as f64 - c[1]) / r) as f32,
            ((p[2] as f64 - c[2]) / r) as f32,
        ];
    }
    Ok(Base { positions, faces })
}

/// Random placements from [`voxlod_io::splitmix64`] (the same numbers on every platform).
struct Rng(u64);
impl Rng {
    /// Uniform in [0, 1), 53 random bits.
    fn unit(&mut self) -> f64 {
        (voxlod_io::splitmix64(&mut self.0) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Placement of copy `i`: rotation about y and a tilt, scale, lattice position, hue.
struct Copy {
    rot: [[f64; 3]; 3],
    scale: f64,
    offset: [f64; 3],
    hue: f64,
}

fn placement(seed: u64, i: u64, side: u64) -> Copy {
    let mut r = Rng(seed ^ i.wrapping_mul(0xd6e8_feb8_6659_fd93));
    let (a, b) = (r.unit() * std::f64::consts::TAU, (r.unit() - 0.5) * 0.6);
    let (sa, ca, sb, cb) = (a.sin(), a.cos(), b.sin(), b.cos());
    // R = Rx(b) · Ry(a)
    let rot = [
        [ca, 0.0, sa],
        [sb * sa, cb, -sb * ca],
        [-cb * sa, sb, cb * ca],
    ];
    let cell = [i % side, (i / side) % side, i / (side * side)];
    let offset = [0, 1, 2].map(|k| cell[k] as f64 * 2.2 + (r.unit() - 0.5) * 0.4);
    Copy {
        rot,
        scale: 0.8 + 0.4 * r.unit(),
        offset,
        hue: r.unit(),
    }
}

fn color(hue: f64, p: [f32; 3]) -> [u8; 3] {
    // a smooth ramp over the copy, tinted by the copy's hue
    let t = (0.5 + 0.5 * (3.0 * p[1] as f64 + 2.0 * p[0] as f64).sin()) * 0.5 + 0.25;
    let h = hue * std::f64::consts::TAU;
    [0.0, 2.094, 4.189].map(|o| {
        ((0.5 + 0.5 * (h + o).cos()) * t * 255.0)
            .round()
            .clamp(0.0, 255.0) as u8
    })
}

/// Writes `triangles` triangles (copies of `base`) to `out` as binary little-endian PLY, with
/// per-vertex colours if `colors` (positions only otherwise, like most raw scans), under the
/// temporary name `staged` beside it (the output guard's, so `voxlod clean` finds what a killed
/// run leaves), renamed to `out` when complete. Returns (vertices, triangles, copies).
pub fn generate(
    base_path: &Path,
    out: &Path,
    staged: &Path,
    triangles: u64,
    seed: u64,
    colors: bool,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<(u64, u64, u64)> {
    let r = write(base_path, out, staged, triangles, seed, colors, progress);
    if r.is_err() {
        let _ = std::fs::remove_file(staged);
    }
    r
}

fn write(
    base_path: &Path,
    out: &Path,
    tmp: &Path,
    triangles: u64,
    seed: u64,
    colors: bool,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<(u64, u64, u64)> {
    if triangles == 0 {
        bail!("--triangles must be at least 1");
    }
    let base = load_base(base_path)?;
    let per = base.faces.len() as u64;
    let copies = triangles.div_ceil(per);
    let side = (copies as f64).cbrt().ceil() as u64;
    let vertices = copies * base.positions.len() as u64;
    if vertices > u32::MAX as u64 {
        bail!("{triangles} triangles need {vertices} vertices, more than a uint index can address");
    }
    let f = std::fs::File::create(tmp).with_context(|| format!("creating {}", tmp.display()))?;
    let mut w = BufWriter::with_capacity(8 << 20, f);
    let werr = |e: std::io::Error| anyhow::anyhow!("writing {}: {e}", tmp.display());
    let mut header = voxlod_io::PlyHeader::binary_le();
    header
        .comment(&format!(
            "voxlod gen: {copies} copies of {} (seed {seed})",
            base_path
                .file_name()
                .map(|n| n.to_string_lossy())
                .unwrap_or_default()
        ))
        .element("vertex", vertices)
        .properties("float", &["x", "y", "z"]);
    if colors {
        header.properties("uchar", &["red", "green", "blue"]);
    }
    header
        .element("face", triangles)
        .list("uchar", "uint", "vertex_indices");
    w.write_all(header.end().as_bytes()).map_err(werr)?;
    let total = vertices + triangles;
    let mut done = 0u64;
    let mut rec = Vec::with_capacity(15);
    for i in 0..copies {
        let c = placement(seed, i, side);
        for p in &base.positions {
            rec.clear();
            for k in 0..3 {
                let v = c.rot[k][0] * p[0] as f64
                    + c.rot[k][1] * p[1] as f64
                    + c.rot[k][2] * p[2] as f64;
                rec.extend_from_slice(&((v * c.scale + c.offset[k]) as f32).to_le_bytes());
            }
            if colors {
                rec.extend_from_slice(&color(c.hue, *p));
            }
            w.write_all(&rec).map_err(werr)?;
        }
        done += base.positions.len() as u64;
        progress(done, total);
    }
    let mut left = triangles;
    for i in 0..copies {
        let first = i * base.positions.len() as u64;
        for f in base.faces.iter().take(left.min(per) as usize) {
            rec.clear();
            rec.push(3);
            for k in 0..3 {
                rec.extend_from_slice(&((first + f[k] as u64) as u32).to_le_bytes());
            }
            w.write_all(&rec).map_err(werr)?;
        }
        let n = left.min(per);
        left -= n;
        done += n;
        progress(done, total);
    }
    let f = w.into_inner().map_err(|e| werr(e.into_error()))?;
    voxlod_io::commit(f, tmp, out)
        .with_context(|| format!("renaming {} to {}", tmp.display(), out.display()))?;
    Ok((vertices, triangles, copies))
}
