//! Synthetic but realistic voxels for tests and measurements: the surface of a sphere inside
//! one 256³ chunk, as a conservative surface voxelizer would give it (every voxel whose cube
//! the sphere touches), with the sphere's smooth normal, face masks with border caps and one
//! of three colour models. Voxels come sorted by Morton code, as a node stores them.

use voxlod_format::voxel::{border_caps, face_mask, morton8, pack_color, pack_normal};
use voxlod_format::Voxel;

/// How the sphere is coloured.
#[allow(dead_code)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Colour {
    /// Opaque white everywhere (meshes without colour get the default colour).
    White,
    /// A smooth gradient over the surface (painted or textured models).
    Smooth,
    /// The gradient plus per-voxel noise of ±8 levels per channel (scanned colour).
    Noisy,
}

/// Every voxel of the 256³ chunk whose unit cube meets the sphere of `radius` around `centre`
/// (in chunk voxel units), sorted by Morton code.
#[allow(dead_code)]
pub fn sphere(centre: [f64; 3], radius: f64, colour: Colour) -> Vec<Voxel> {
    let mut out: Vec<Voxel> = sphere_grid(256, centre, radius, colour)
        .into_iter()
        .map(|(p, v)| Voxel {
            pos_mask: v.pos_mask | p[0] | p[1] << 8 | p[2] << 16,
            ..v
        })
        .collect();
    out.sort_by_key(|v| morton8(v.pos()[0], v.pos()[1], v.pos()[2]));
    out
}

/// The same over a `resolution`³ grid: (grid position, voxel) pairs in no particular order,
/// the voxel's position bits zero but its face mask already with the caps of its chunk.
/// Only columns near the surface are visited, so large grids are cheap.
#[allow(dead_code)]
pub fn sphere_grid(
    resolution: u32,
    centre: [f64; 3],
    radius: f64,
    colour: Colour,
) -> Vec<([u32; 3], Voxel)> {
    let mut out = Vec::new();
    let r2 = radius * radius;
    // squared distance range from c to the interval [lo, lo+1] along one axis
    let range = |lo: f64, c: f64| {
        let (a, b) = (lo - c, lo + 1.0 - c);
        let near = if a > 0.0 {
            a
        } else if b < 0.0 {
            b
        } else {
            0.0
        };
        (near * near, a.abs().max(b.abs()).powi(2))
    };
    for y in 0..resolution {
        for x in 0..resolution {
            let (nx, fx) = range(x as f64, centre[0]);
            let (ny, fy) = range(y as f64, centre[1]);
            if nx + ny > r2 {
                continue;
            }
            // |z − c| must lie in [sqrt(r² − far_xy) − 1, sqrt(r² − near_xy) + 1]
            let inner = (r2 - fx - fy).max(0.0).sqrt() - 1.0;
            let outer = (r2 - nx - ny).sqrt() + 1.0;
            let mut zs = Vec::new();
            for sign in [-1.0, 1.0] {
                let (a, b) = (centre[2] + sign * inner, centre[2] + sign * outer);
                let (lo, hi) = (
                    a.min(b).floor().max(0.0),
                    a.max(b).ceil().min(resolution as f64 - 1.0),
                );
                let mut z = lo;
                while z <= hi {
                    zs.push(z as u32);
                    z += 1.0;
                }
            }
            zs.sort_unstable();
            zs.dedup();
            for z in zs {
                let (nz, fz) = range(z as f64, centre[2]);
                if nx + ny + nz > r2 || fx + fy + fz < r2 {
                    continue;
                }
                let p = [x as f64, y as f64, z as f64];
                let d = [
                    p[0] + 0.5 - centre[0],
                    p[1] + 0.5 - centre[1],
                    p[2] + 0.5 - centre[2],
                ];
                let normal = pack_normal([d[0] as f32, d[1] as f32, d[2] as f32]);
                let local = [(x & 255) as u8, (y & 255) as u8, (z & 255) as u8];
                let rgba = match colour {
                    Colour::White => [255, 255, 255, 255],
                    Colour::Smooth => gradient(p),
                    Colour::Noisy => {
                        let g = gradient(p);
                        let h = hash(x | y << 8 | z << 16);
                        let mut c = [0u8; 4];
                        for i in 0..3 {
                            let noise = ((h >> (8 * i)) & 15) as i32 - 8;
                            c[i] = (g[i] as i32 + noise).clamp(0, 255) as u8;
                        }
                        c[3] = 255;
                        c
                    }
                };
                let mask = face_mask(normal) | border_caps(local);
                out.push((
                    [x, y, z],
                    Voxel::new([0; 3], mask, normal, pack_color(rgba)),
                ));
            }
        }
    }
    out
}

fn gradient(p: [f64; 3]) -> [u8; 4] {
    [
        (40.0 + p[0] * 0.7) as u8,
        (90.0 + 60.0 * (p[1] / 40.0).sin()) as u8,
        (200.0 - p[2] * 0.5) as u8,
        255,
    ]
}

/// splitmix32-style integer hash (deterministic noise).
pub fn hash(mut x: u32) -> u32 {
    x = x.wrapping_add(0x9e37_79b9);
    x = (x ^ (x >> 16)).wrapping_mul(0x85eb_ca6b);
    x = (x ^ (x >> 13)).wrapping_mul(0xc2b2_ae35);
    x ^ (x >> 16)
}
