//! The tests' random draws on [`voxlod_io::splitmix64`] (Steele, Lea & Flood, OOPSLA 2014):
//! a 64-bit state, every seed (including 0) good, the same numbers everywhere.

/// A deterministic random generator for tests; the field is the state (any seed is fine).
#[derive(Clone, Debug)]
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        voxlod_io::splitmix64(&mut self.0)
    }

    /// Uniform in [0, 1), 53 random bits.
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [0, 1), 24 random bits (every value an exact f32).
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in [a, b).
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.f64()
    }

    /// Uniform in [a, b) in f32.
    pub fn range_f32(&mut self, a: f32, b: f32) -> f32 {
        a + (b - a) * self.f32()
    }

    /// An integer in [a, b] (both ends included; `a <= b`).
    pub fn int(&mut self, a: i64, b: i64) -> i64 {
        assert!(a <= b, "empty range {a}..={b}");
        a + (self.next_u64() % ((b - a) as u64 + 1)) as i64
    }

    /// An integer in [0, n) (`n = 0` is treated as 1, giving 0).
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }

    /// An index in [0, n) (`n = 0` is treated as 1).
    pub fn index(&mut self, n: usize) -> usize {
        self.below(n as u64) as usize
    }

    /// A point with each coordinate uniform in [a, b).
    pub fn point(&mut self, a: f64, b: f64) -> [f64; 3] {
        [self.range(a, b), self.range(a, b), self.range(a, b)]
    }

    /// A uniformly random rotation matrix (from a uniform unit quaternion, Shoemake 1992).
    pub fn rotation(&mut self) -> [[f64; 3]; 3] {
        let (u1, u2, u3) = (self.f64(), self.f64(), self.f64());
        let tau = std::f64::consts::TAU;
        let (x, y) = (
            (1.0 - u1).sqrt() * (tau * u2).sin(),
            (1.0 - u1).sqrt() * (tau * u2).cos(),
        );
        let (z, w) = (u1.sqrt() * (tau * u3).sin(), u1.sqrt() * (tau * u3).cos());
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - z * w),
                2.0 * (x * z + y * w),
            ],
            [
                2.0 * (x * y + z * w),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - x * w),
            ],
            [
                2.0 * (x * z - y * w),
                2.0 * (y * z + x * w),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::Rng;

    #[test]
    fn splitmix64_reference_values() {
        // the first outputs for seed 0 from the reference C implementation (Vigna's splitmix64.c)
        let mut r = Rng(0);
        assert_eq!(r.next_u64(), 0xe220_a839_7b1d_cdaf);
        assert_eq!(r.next_u64(), 0x6e78_9e6a_a1b9_65f4);
    }

    #[test]
    fn draws_stay_in_their_ranges() {
        let mut r = Rng(42);
        for _ in 0..10_000 {
            assert!((0.0..1.0).contains(&r.f64()));
            assert!((0.0..1.0).contains(&r.f32()));
            assert!((-3..=5).contains(&r.int(-3, 5)));
            assert!(r.below(7) < 7);
        }
        let rot = r.rotation();
        for i in 0..3 {
            for j in 0..3 {
                let d: f64 = (0..3).map(|k| rot[i][k] * rot[j][k]).sum();
                assert!((d - f64::from(u8::from(i == j))).abs() < 1e-12);
            }
        }
    }
}
