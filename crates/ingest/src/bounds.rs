//! The bounds of a memory-mapped input's vertices before its faces are read
//! ([`crate::MeshSource::vertex_bounds`]): a parallel scan in rounds, the map's resident pages
//! released after each round so that the process's memory stays bounded whatever the file size.

use voxlod_geom::Bounds;

/// Items (vertices, facets) per parallel part.
const PART: u64 = 1 << 16;

/// The bounds of items `0..n`: `add(i, b)` adds item `i`'s positions to `b`, or returns `false`
/// if one is not finite (the result is then `None`). Rounds of `round` items run in parallel
/// parts on the current rayon pool, `release()` after each; min and max do not depend on the
/// order, so neither does the result.
pub(crate) fn parallel_bounds(
    n: u64,
    round: u64,
    release: &dyn Fn(),
    add: &(dyn Fn(u64, &mut Bounds) -> bool + Sync),
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
                let mut b = Bounds::default();
                let a = first + k * PART;
                for i in a..(a + PART).min(end) {
                    if !add(i, &mut b) {
                        return None;
                    }
                }
                Some(b)
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
        let b = parallel_bounds(n, 100_000, &release, &|i, b| {
            b.add_point([x(i), -x(i), 0.5]);
            true
        })
        .unwrap();
        assert_eq!((b.min, b.max), ([-7.0, -11.0, 0.5], [11.0, 7.0, 0.5]));
        // three full rounds and one of a single item, each released
        assert_eq!(releases.load(std::sync::atomic::Ordering::Relaxed), 4);
        let none = parallel_bounds(n, 1 << 20, &|| {}, &|i, b| {
            b.add_point([0.0; 3]);
            i != 250_000
        });
        assert!(none.is_none());
        assert!(parallel_bounds(0, 10, &|| {}, &|_, _| true)
            .unwrap()
            .is_empty());
    }
}
