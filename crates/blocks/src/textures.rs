//! One small procedural texture per face material (16×16 RGBA, row 0 at the top), in the
//! spirit of a block game's: a base colour with per-texel variation from an integer hash, and
//! a pattern that makes the faces of one block tell apart (the grass side's green fringe at the
//! top over dirt, a log's rings against its bark). The same for every seed and machine: only
//! integer arithmetic.

use std::io::Write;

use crate::faces::Material;
use crate::noise::mix;

/// Texels per side.
pub const TEXTURE_SIZE: u32 = 16;

/// The texels of `m`'s texture, row-major from the top row, RGBA8 (sRGB colour, opaque).
pub fn texels(m: Material) -> Vec<[u8; 4]> {
    let n = TEXTURE_SIZE;
    let mut out = Vec::with_capacity((n * n) as usize);
    for y in 0..n {
        for x in 0..n {
            out.push(texel(m, x, y));
        }
    }
    out
}

/// A hash of texel `(x, y)` of material `m` in `0..256`.
fn grain(m: Material, x: u32, y: u32) -> i32 {
    (mix(((m as u64) << 16) | ((y as u64) << 8) | x as u64) & 0xff) as i32
}

/// `rgb` brightened or darkened by `d` (per channel, clamped).
fn shade(rgb: [i32; 3], d: i32) -> [u8; 4] {
    let c = rgb.map(|c| (c + d).clamp(0, 255) as u8);
    [c[0], c[1], c[2], 255]
}

const GRASS: [i32; 3] = [94, 157, 52];
const DIRT: [i32; 3] = [134, 96, 67];
const STONE: [i32; 3] = [125, 125, 125];
const SAND: [i32; 3] = [219, 207, 163];
const WATER: [i32; 3] = [47, 84, 200];
const WOOD: [i32; 3] = [184, 148, 95];
const BARK: [i32; 3] = [102, 81, 50];
const LEAVES: [i32; 3] = [58, 118, 38];

fn texel(m: Material, x: u32, y: u32) -> [u8; 4] {
    let g = grain(m, x, y);
    let noise = |amp: i32| (g * (2 * amp + 1)) / 256 - amp; // in -amp..=amp
    match m {
        Material::GrassTop => shade(GRASS, noise(18)),
        Material::GrassSide => {
            // a fringe of grass 3 to 5 texels deep, ragged per column
            let depth = 3 + (grain(m, x, 99) % 3) as u32;
            if y < depth {
                shade(GRASS, noise(14))
            } else {
                dirt(g)
            }
        }
        Material::Dirt => dirt(g),
        Material::Stone => {
            // darker cracks along a few diagonal runs
            let crack = (x + 2 * y) % 7 == 0 && g < 150;
            shade(STONE, if crack { -40 } else { noise(14) })
        }
        Material::Sand => shade(SAND, noise(10)),
        Material::Water => {
            // lighter wave crests every fourth row, shifted along x
            let crest = (y + x / 4) % 4 == 0;
            shade(WATER, if crest { 35 } else { noise(8) })
        }
        Material::LogTop => {
            // growth rings around the centre, bark at the rim
            let (dx, dy) = (2 * x as i32 - 15, 2 * y as i32 - 15); // twice the offset
            let d2 = dx * dx + dy * dy;
            if d2 >= 14 * 14 {
                shade(BARK, noise(10))
            } else {
                let ring = (integer_sqrt(d2) / 4) % 2;
                shade(WOOD, if ring == 1 { -30 } else { noise(6) })
            }
        }
        Material::LogSide => {
            // vertical bark stripes
            let furrow = (x + (grain(m, 0, y) % 2) as u32) % 4 == 0;
            shade(BARK, if furrow { -28 } else { noise(12) })
        }
        Material::Leaves => {
            // dark gaps between leaves
            let gap = g < 40;
            shade(LEAVES, if gap { -35 } else { noise(20) })
        }
    }
}

fn dirt(g: i32) -> [u8; 4] {
    // pebbles: a few lighter and darker specks
    let d = match g {
        0..=20 => -30,
        236..=255 => 25,
        _ => (g * 17) / 256 - 8,
    };
    shade(DIRT, d)
}

fn integer_sqrt(v: i32) -> i32 {
    let mut r = 0;
    while (r + 1) * (r + 1) <= v {
        r += 1;
    }
    r
}

/// `m`'s texture as PNG bytes (RGBA8).
pub fn png_bytes(m: Material) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, TEXTURE_SIZE, TEXTURE_SIZE);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header()?;
        let data: Vec<u8> = texels(m).into_iter().flatten().collect();
        w.write_image_data(&data)?;
        w.finish()?;
    }
    out.flush().ok();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every texture is distinct from every other, and the textures whose difference the
    /// block world shows differ in their mean colour by a visible amount.
    #[test]
    fn textures_are_distinct() {
        let mean = |m: Material| {
            let t = texels(m);
            [0, 1, 2].map(|c| t.iter().map(|p| p[c] as i32).sum::<i32>() / t.len() as i32)
        };
        for a in Material::ALL {
            for b in Material::ALL {
                if a < b {
                    assert_ne!(texels(a), texels(b), "{a:?} {b:?}");
                }
            }
        }
        let far = |a: Material, b: Material| {
            let (p, q) = (mean(a), mean(b));
            (0..3).map(|c| (p[c] - q[c]).abs()).sum::<i32>() > 30
        };
        assert!(far(Material::GrassTop, Material::GrassSide));
        assert!(far(Material::LogTop, Material::LogSide));
        assert!(far(Material::Sand, Material::Stone));
        // the grass side: green at the top row, brown (dirt) at the bottom row
        let side = texels(Material::GrassSide);
        let n = TEXTURE_SIZE as usize;
        assert!(side[..n].iter().all(|p| p[1] > p[0] && p[1] > p[2]));
        assert!(side[n * (n - 1)..]
            .iter()
            .all(|p| p[0] > p[1] && p[1] > p[2]));
        assert_eq!(integer_sqrt(15), 3);
        assert_eq!(integer_sqrt(16), 4);
    }
}
