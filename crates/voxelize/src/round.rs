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

/// [`voxlod_format::voxel::pack_normal`] with [`round_f32`] and one division instead of three:
/// `round((c / len) · 511)` is taken from `c · (1/len)` (within 2 ulp of `c / len`) unless that
/// lands within 1e-3 of a half-integer, where the exact division decides. Same word for every
/// input.
#[inline]
pub(crate) fn pack_normal(n: [f32; 3]) -> u32 {
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if !(len.is_finite() && len > 0.0) {
        return 0;
    }
    let inv = 1.0 / len;
    let mut w = 0u32;
    for (a, &c) in n.iter().enumerate() {
        let fast = (c * inv) * NORMAL_SCALE;
        let frac = fast - fast as i32 as f32;
        let x = if (frac.abs() - 0.5).abs() > 1e-3 && fast.abs() < 1024.0 {
            fast
        } else {
            (c / len) * NORMAL_SCALE
        };
        let q = round_f32(x).clamp(-NORMAL_SCALE, NORMAL_SCALE) as i32;
        w |= ((q as u32) & 0x3ff) << (10 * a);
    }
    w
}

/// `(s / d) as f32` given `q = s · r`, `r = 1/d` rounded (so `q` is within 2 ulp of `s / d`):
/// `q as f32` unless `q` lies within 16 ulp of a midpoint between two f32 values (the low 29
/// mantissa bits of an f64 say where it lies between them) or outside the f32 normal range,
/// where the division decides. Requires `d > 0` finite.
#[inline]
pub(crate) fn quotient_f32(s: f64, d: f64, q: f64) -> f32 {
    let low = q.to_bits() & ((1 << 29) - 1);
    let a = q.abs();
    if (1e-30..=1e30).contains(&a) && low.abs_diff(1 << 28) > 16 {
        q as f32
    } else if s == 0.0 {
        s as f32
    } else {
        (s / d) as f32
    }
}

/// `round_f64(s / d)` given `q = s · r`, `r = 1/d` rounded: from `q` unless it lies within
/// `1e-12·|q|` of a half-integer, where the division decides. Requires `d > 0` finite.
#[inline]
pub(crate) fn round_quotient(s: f64, d: f64, q: f64) -> f64 {
    if q.abs() < 1e15 {
        let f = q - q as i64 as f64;
        if (f.abs() - 0.5).abs() > 1e-12 * q.abs().max(1.0) {
            return round_f64(q);
        }
    }
    round_f64(s / d)
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
    fn quotients_match_division() {
        let mut s = 0x0123_4567_89ab_cdefu64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let unit = |r: u64| (r >> 11) as f64 / (1u64 << 53) as f64;
        let mut near = 0;
        for i in 0..4_000_000u64 {
            let (r1, r2) = (next(), next());
            let d = match i % 4 {
                0 => unit(r1) * 10.0 + 1e-9,
                1 => (r1 % 7 + 1) as f64,
                2 => unit(r1) * 1e-6 + 1e-12,
                _ => f64::from_bits(0x3f00_0000_0000_0000 + (r1 >> 14)),
            };
            // a target quotient: random, or just beside an f32 midpoint / a half-integer
            let t = match i % 3 {
                0 => (unit(r2) - 0.5) * 600.0,
                1 => {
                    let f = ((unit(r2) - 0.5) * 2.0) as f32;
                    let m = (f as f64 + f64::from(f32::from_bits(f.to_bits() + 1))) / 2.0;
                    f64::from_bits((m.to_bits() as i64 + (r2 >> 58) as i64 - 32) as u64)
                }
                _ => {
                    let h = (r2 % 512) as f64 - 128.5;
                    f64::from_bits((h.to_bits() as i64 + (r2 >> 40 & 0xffff) as i64 - 32768) as u64)
                }
            };
            let s = t * d;
            let q = s * (1.0 / d);
            assert_eq!(
                quotient_f32(s, d, q).to_bits(),
                ((s / d) as f32).to_bits(),
                "{s:e} / {d:e}"
            );
            let (a, b) = (round_quotient(s, d, q), round_f64(s / d));
            assert!(a == b, "{s:e} / {d:e}: {a} vs {b}");
            near += (((s / d) - (s / d).round()).abs() > 0.49) as usize;
        }
        assert!(near > 100_000, "{near}");
        for (s, d) in [
            (0.0, 3.0),
            (-0.0, 3.0),
            (1e-300, 7.0),
            (1e300, 3.0),
            (5.0, 2.0),
        ] {
            let q = s * (1.0 / d);
            assert_eq!(quotient_f32(s, d, q).to_bits(), ((s / d) as f32).to_bits());
            assert_eq!(round_quotient(s, d, q), round_f64(s / d));
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
