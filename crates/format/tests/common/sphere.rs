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
    let mut out = Vec::new();
    for z in 0..256u32 {
        for y in 0..256u32 {
            for x in 0..256u32 {
                let p = [x as f64, y as f64, z as f64];
                // nearest and farthest squared distance from the centre to the cube [p, p+1]
                let (mut near, mut far) = (0.0f64, 0.0f64);
                for a in 0..3 {
                    let lo = p[a] - centre[a];
                    let hi = lo + 1.0;
                    let n = if lo > 0.0 {
                        lo
                    } else if hi < 0.0 {
                        hi
                    } else {
                        0.0
                    };
                    near += n * n;
                    far += lo.abs().max(hi.abs()).powi(2);
                }
                if near > radius * radius || far < radius * radius {
                    continue;
                }
                let d = [
                    p[0] + 0.5 - centre[0],
                    p[1] + 0.5 - centre[1],
                    p[2] + 0.5 - centre[2],
                ];
                let normal = pack_normal([d[0] as f32, d[1] as f32, d[2] as f32]);
                let pos = [x as u8, y as u8, z as u8];
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
                out.push(Voxel::new(
                    pos,
                    face_mask(normal) | border_caps(pos),
                    normal,
                    pack_color(rgba),
                ));
            }
        }
    }
    out.sort_by_key(|v| morton8(v.pos()[0], v.pos()[1], v.pos()[2]));
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
