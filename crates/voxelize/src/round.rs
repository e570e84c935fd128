//! Rounding for the voxel encoding without libm calls: `f32::round` / `f64::round` (half away
//! from zero) compile to a library call on the x86-64 baseline (no SSE4.1 `roundss`), which made
//! [`voxlod_format::voxel::pack_normal`] the most expensive step of `ChunkVoxelizer::finish`.
//! Here the value is truncated by a float→integer conversion and the exact fraction `x − trunc(x)`
//! decides; the results are identical to `round` for every input (tested exhaustively for f32
//! in the normal range and against `pack_normal` on all quantization boundaries).

use voxlod_format::voxel::NORMAL_SCALE;

/// `x.round()`, bit for bit (except the sign of a zero result, which no caller observes).
#[inline]
pub(crate) fn round_f32(x: f32) -> f32 {
    // |x| < 2^22: trunc(x) is exact as i32 and x − trunc(x) is exact
    if x.abs() < 4_194_304.0 {
        let t = x as i32 as f32;
        let f = x - t;
        if f >= 0.5 {
            t + 1.0
        } else if f <= -0.5 {
            t - 1.0
        } else {
            t
        }
    } else {
        x.round()
    }
}

/// `x.round()`, bit for bit (except the sign of a zero result, which no caller observes).
#[inline]
pub(crate) fn round_f64(x: f64) -> f64 {
    // |x| < 2^51: trunc(x) is exact as i64 and x − trunc(x) is exact
    if x.abs() < 2_251_799_813_685_248.0 {
        let t = x as i64 as f64;
        let f = x - t;
        if f >= 0.5 {
            t + 1.0
        } else if f <= -0.5 {
            t - 1.0
        } else {
            t
        }
    } else {
        x.round()
    }
}

/// [`voxlod_format::voxel::pack_normal`] with [`round_f32`]: the same operations in the same
/// order, so the same word for every input.
#[inline]
pub(crate) fn pack_normal(n: [f32; 3]) -> u32 {
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if !(len.is_finite() && len > 0.0) {
        return 0;
    }
    let mut w = 0u32;
    for (a, &c) in n.iter().enumerate() {
        let q = round_f32((c / len) * NORMAL_SCALE).clamp(-NORMAL_SCALE, NORMAL_SCALE) as i32;
        w |= ((q as u32) & 0x3ff) << (10 * a);
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_f32_matches_std() {
        // every f32 with 1/4 ≤ |x| < 1024 (both signs; normal components are within ±511),
        // then every 97th bit pattern up to 2^24, plus specials
        let mut checked = 0u64;
        for bits in (0x3e80_0000u32..0x4480_0000).chain((0..=0x4b80_0000).step_by(97)) {
            for x in [f32::from_bits(bits), -f32::from_bits(bits)] {
                let (a, b) = (round_f32(x), x.round());
                assert!(a == b, "{x:e}: {a} vs {b}");
                checked += 1;
            }
        }
        for x in [f32::INFINITY, f32::NEG_INFINITY, 1e30, -1e30, f32::MAX] {
            assert_eq!(round_f32(x), x.round());
        }
        assert!(round_f32(f32::NAN).is_nan());
        assert!(checked > 200_000_000);
    }

    #[test]
    fn round_f64_matches_std() {
        let mut s = 0x1234_5678_9abc_def0u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for _ in 0..2_000_000 {
            let r = next();
            // random bits, and values near half-integers in the colour range
            let a = f64::from_bits(r);
            let k = (r % 600) as f64 - 50.0 + 0.5;
            let b = f64::from_bits((k.to_bits() as i64 + (r >> 60) as i64 - 8) as u64);
            for x in [a, b, -b] {
                let (p, q) = (round_f64(x), x.round());
                assert!(p == q || (p.is_nan() && q.is_nan()), "{x:e}: {p} vs {q}");
            }
        }
        for x in [
            0.5,
            -0.5,
            0.49999999999999994,
            2.5,
            4503599627370495.5,
            1e300,
            f64::MAX,
        ] {
            assert_eq!(round_f64(x), x.round());
        }
    }

    #[test]
    fn pack_normal_matches_format() {
        use voxlod_format::voxel::pack_normal as reference;
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for _ in 0..3_000_000 {
            let r = next();
            let f = |k: u32| ((r >> k) & 0xffff) as f32 / 32768.0 - 1.0;
            let n = [f(0), f(16), f(32)];
            assert_eq!(pack_normal(n), reference(n), "{n:?}");
            // components on quantization boundaries (q ± ½)/511 of a unit vector
            let q = ((r >> 48) % 1023) as f32 - 511.0;
            let x = (q + 0.5) / 511.0;
            let m = [x, (1.0 - x * x).max(0.0).sqrt(), 0.0];
            assert_eq!(pack_normal(m), reference(m), "{m:?}");
            let m = [x, 0.0, -(1.0 - x * x).max(0.0).sqrt()];
            assert_eq!(pack_normal(m), reference(m), "{m:?}");
        }
        for n in [
            [0.0, 0.0, 0.0],
            [f32::NAN, 0.0, 1.0],
            [f32::INFINITY, 0.0, 0.0],
            [1e30, 1e30, 0.0],
            [1e-30, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, -2.0, 0.0],
        ] {
            assert_eq!(pack_normal(n), reference(n), "{n:?}");
        }
    }
}
