//! Seeded 2D value noise for the block world's heightmap: a hash of the integer lattice point
//! gives a value in [0, 1), interpolated with smoothstep weights, summed over octaves (fractal
//! Brownian motion). Only integer hashing, `+`, `*`, `/` and `floor` in f64, all exactly
//! rounded by IEEE 754, so the same seed gives the same heights on every machine (no `sin`,
//! `exp` or other library functions whose last bit may differ).

/// SplitMix64's finaliser: a well-mixed 64-bit hash of `x`.
pub fn mix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// A hash of a lattice point `(x, z)` under `seed`, with `salt` separating uses.
pub fn hash(seed: u64, x: i64, z: i64, salt: u64) -> u64 {
    mix(mix(mix(seed ^ salt.wrapping_mul(0xd6e8_feb8_6659_fd93)) ^ x as u64) ^ z as u64)
}

/// The lattice value at `(x, z)`, uniform in [0, 1).
fn lattice(seed: u64, x: i64, z: i64, salt: u64) -> f64 {
    (hash(seed, x, z, salt) >> 11) as f64 / (1u64 << 53) as f64
}

/// Value noise with lattice spacing `cell` at `(x, z)`, in [0, 1).
fn value(seed: u64, x: f64, z: f64, cell: f64, salt: u64) -> f64 {
    let (gx, gz) = (x / cell, z / cell);
    let (ix, iz) = (gx.floor(), gz.floor());
    let (fx, fz) = (gx - ix, gz - iz);
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (sx, sz) = (s(fx), s(fz));
    let (ix, iz) = (ix as i64, iz as i64);
    let l = |dx: i64, dz: i64| lattice(seed, ix + dx, iz + dz, salt);
    let a = l(0, 0) + (l(1, 0) - l(0, 0)) * sx;
    let b = l(0, 1) + (l(1, 1) - l(0, 1)) * sx;
    a + (b - a) * sz
}

/// Octaves of the heightmap: lattice spacing in blocks and weight.
const OCTAVES: [(f64, f64); 4] = [(48.0, 1.0), (24.0, 0.5), (12.0, 0.25), (6.0, 0.125)];

/// Fractal value noise at block column `(x, z)` (sampled at the column's centre), in [0, 1).
pub fn fbm(seed: u64, x: u32, z: u32) -> f64 {
    let (px, pz) = (x as f64 + 0.5, z as f64 + 0.5);
    let mut sum = 0.0;
    let mut total = 0.0;
    for (k, (cell, w)) in OCTAVES.iter().enumerate() {
        sum += w * value(seed, px, pz, *cell, k as u64 + 1);
        total += w;
    }
    sum / total
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The noise is in range, equals the lattice values at lattice points (where smoothstep
    /// weights are 0), and is continuous: neighbouring columns differ little.
    #[test]
    fn range_lattice_points_and_continuity() {
        for x in 0..200u32 {
            for z in 0..50u32 {
                let n = fbm(7, x, z);
                assert!((0.0..1.0).contains(&n), "{n}");
                assert!((n - fbm(7, x + 1, z)).abs() < 0.2);
            }
        }
        assert_eq!(value(3, 96.0, 48.0, 48.0, 1), lattice(3, 2, 1, 1));
        assert_ne!(fbm(1, 10, 10), fbm(2, 10, 10));
    }
}
