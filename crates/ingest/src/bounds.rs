//! The bounds of a memory-mapped input's vertices before its faces are read
//! ([`crate::MeshSource::vertex_bounds`]): a parallel scan in rounds, the map's resident pages
//! released after each round so that the process's memory stays bounded whatever the file size.

use voxlod_geom::Bounds;

/// Items (vertices, facets) per parallel part.
const PART: u64 = 1 << 16;

/// Min and max of f32 points and whether every coordinate was finite: the comparisons of
/// [`Bounds::add_point`] (strict, the first of equal values kept, so -0 and +0 come out as
/// there; NaN never taken) made in f32, to which every f32 converts exactly, so the result is
/// bit for bit `Bounds`'s; as selects rather than branches so a part's loop vectorizes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PointBounds {
    lo: [f32; 3],
    hi: [f32; 3],
    finite: bool,
}

impl Default for PointBounds {
    fn default() -> Self {
        PointBounds {
            lo: [f32::INFINITY; 3],
            hi: [f32::NEG_INFINITY; 3],
            finite: true,
        }
    }
}

impl PointBounds {
    /// Grows the box to hold `p`.
    #[inline(always)]
    pub(crate) fn add(&mut self, p: [f32; 3]) {
        for a in 0..3 {
            self.lo[a] = if p[a] < self.lo[a] { p[a] } else { self.lo[a] };
            self.hi[a] = if p[a] > self.hi[a] { p[a] } else { self.hi[a] };
            self.finite &= p[a].is_finite();
        }
    }

    /// Adds points `p(0)`, …, `p(n - 1)`: the bits [`PointBounds::add`] in that order gives, in
    /// four interleaved lanes (four independent dependency chains instead of one) merged by
    /// value. Equal values of different bits can only be ±0, so where the new minimum (or
    /// maximum) is a zero its sign is the first zero's in order, found by a scan of the points
    /// (only where an extreme is exactly 0).
    #[inline(always)]
    pub(crate) fn add_many(&mut self, n: usize, p: impl Fn(usize) -> [f32; 3]) {
        const LANES: usize = 4;
        let mut lanes = [PointBounds::default(); LANES];
        let full = n / LANES * LANES;
        for i in (0..full).step_by(LANES) {
            for (k, lane) in lanes.iter_mut().enumerate() {
                lane.add(p(i + k));
            }
        }
        for i in full..n {
            lanes[0].add(p(i));
        }
        let first_zero = |a: usize| {
            (0..n)
                .map(|i| p(i)[a])
                .find(|&v| v == 0.0)
                .expect("an extreme of 0 is one of the points")
        };
        for a in 0..3 {
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for l in &lanes {
                lo = if l.lo[a] < lo { l.lo[a] } else { lo };
                hi = if l.hi[a] > hi { l.hi[a] } else { hi };
            }
            // strict, as `add`: an earlier equal value (the box's) is kept
            if lo < self.lo[a] {
                self.lo[a] = if lo == 0.0 { first_zero(a) } else { lo };
            }
            if hi > self.hi[a] {
                self.hi[a] = if hi == 0.0 { first_zero(a) } else { hi };
            }
        }
        self.finite &= lanes.iter().all(|l| l.finite);
    }

    /// The box, or `None` if a coordinate was not finite.
    fn bounds(&self) -> Option<Bounds> {
        self.finite.then(|| Bounds {
            min: self.lo.map(f64::from),
            max: self.hi.map(f64::from),
        })
    }
}

/// The bounds of items `0..n`: `part(range, b)` adds the positions of the items in `range` to
/// `b` (the result is `None` if one is not finite). Rounds of `round` items run in parallel
/// parts of [`PART`] items on the current rayon pool, `release()` after each; min and max do
/// not depend on the order, so neither does the result.
pub(crate) fn parallel_bounds(
    n: u64,
    round: u64,
    release: &dyn Fn(),
    part: &(dyn Fn(std::ops::Range<u64>, &mut PointBounds) + Sync),
) -> Option<Bounds> {
    use rayon::prelude::*;
    let round = round.max(PART);
    let mut total = Bounds::default();
    let mut first = 0u64;
    while first < n {
        let end = first.saturating_add(round).min(n);
        let parts = (end - first).div_ceil(PART);
        let b = (0..parts)
            .into_par_iter()
            .map(|k| {
                let mut b = PointBounds::default();
                let a = first + k * PART;
                part(a..(a + PART).min(end), &mut b);
                b.bounds()
            })
            .try_reduce(Bounds::default, |mut a, b| {
                a.merge(&b);
                Some(a)
            });
        release();
        total.merge(&b?);
        first = end;
    }
    Some(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounds_and_parts_cover_every_item_once() {
        // 300,001 items in rounds of 100,000 (parts of 65,536 and 34,464): the extremes sit in
        // the first, a middle and the last item
        let n = 300_001u64;
        let x = |i: u64| match i {
            0 => -7.0,
            150_000 => 9.0,
            300_000 => 11.0,
            _ => (i % 5) as f32,
        };
        let releases = std::sync::atomic::AtomicU32::new(0);
        let release = || {
            releases.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        };
        let b = parallel_bounds(n, 100_000, &release, &|r, b| {
            r.for_each(|i| b.add([x(i), -x(i), 0.5]))
        })
        .unwrap();
        assert_eq!((b.min, b.max), ([-7.0, -11.0, 0.5], [11.0, 7.0, 0.5]));
        // three full rounds and one of a single item, each released
        assert_eq!(releases.load(std::sync::atomic::Ordering::Relaxed), 4);
        let none = parallel_bounds(n, 1 << 20, &|| {}, &|r, b| {
            r.for_each(|i| b.add([if i == 250_000 { f32::NAN } else { 0.0 }; 3]))
        });
        assert!(none.is_none());
        assert!(parallel_bounds(0, 10, &|| {}, &|_, _| {})
            .unwrap()
            .is_empty());
    }

    /// `PointBounds` gives `Bounds::add_point`'s bits on points with signed zeros, repeats,
    /// extremes and subnormals, and says when one is not finite.
    #[test]
    fn point_bounds_are_add_points_bits() {
        let vals = [
            0.0f32,
            -0.0,
            1.0,
            -1.0,
            f32::MIN_POSITIVE / 8.0,
            -f32::MIN_POSITIVE / 8.0,
            f32::MAX,
            f32::MIN,
            3.5,
            -3.5,
        ];
        let mut state = 7u64;
        for _ in 0..2000 {
            let n = 1 + (state % 19) as usize;
            let mut points = Vec::new();
            for _ in 0..n {
                let mut p = [0.0f32; 3];
                for c in &mut p {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    *c = vals[(state >> 33) as usize % vals.len()];
                }
                points.push(p);
            }
            let (mut fast, mut slow) = (PointBounds::default(), Bounds::default());
            for &p in &points {
                fast.add(p);
                slow.add_point(p);
            }
            let f = fast.bounds().expect("all finite");
            let bits = |b: &Bounds| (b.min.map(f64::to_bits), b.max.map(f64::to_bits));
            assert_eq!(bits(&f), bits(&slow), "{points:?}");
            // in lanes, after a box that already holds some points (its equal values kept)
            let cut = n / 3;
            let mut lanes = PointBounds::default();
            points[..cut].iter().for_each(|&p| lanes.add(p));
            let rest = &points[cut..];
            lanes.add_many(rest.len(), |i| rest[i]);
            let l = lanes.bounds().expect("all finite");
            assert_eq!(bits(&l), bits(&slow), "lanes: {points:?}");
            fast.add([1.0, f32::INFINITY, 0.0]);
            assert!(fast.bounds().is_none());
        }
    }
}
