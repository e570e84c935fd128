//! The split of a plan: the split level S and which level-S subtrees each shard builds.
//!
//! Split rule: the coarsest level S whose non-empty subtrees, given to `shards` shards with
//! the smallest largest shard we find (by binned triangles: a triangle counts once per chunk
//! it is binned to, the voxelizer's work), has no shard above 1.5× the mean. When no level
//! allows that (fewer subtrees than shards, one dominant subtree), the level with the smallest
//! largest shard is taken and the plan says it is unbalanced.
//!
//! At a level, two assignments are tried and the one with the smaller largest shard kept
//! (contiguous on a tie): the best cut of the subtrees in Morton order into contiguous ranges
//! ([`partition`], optimal among contiguous cuts), and longest-processing-time-first
//! ([`lpt`]: heaviest subtree to the least loaded shard; Graham, "Bounds on multiprocessing
//! timing anomalies", 1969, within 4/3 of the best assignment of any shape). With a few
//! subtrees per shard the contiguous cut is coarse (the 1e8 scan at 2048³ in 16 shards: 61
//! non-empty subtrees in the plan's sample, the best contiguous cut's largest shard 1.18× the
//! mean, LPT's 1.07×), so a shard may hold several
//! ranges; the merge takes subtrees in Morton order from whichever shard holds them.

use super::plan_file::{Balance, ShardRange};

/// A shard may hold at most this many times the mean (as the fraction 3/2).
const BALANCE: (u64, u64) = (3, 2);

/// Subtrees at level `s`: (Morton code, binned triangles) of the non-empty ones, in Morton
/// order, from the non-empty leaf chunks `leaves` (Morton code, triangles) in Morton order.
pub(crate) fn subtrees(leaves: &[(u64, u64)], s: u32) -> Vec<(u64, u64)> {
    let mut out: Vec<(u64, u64)> = Vec::new();
    for &(m, w) in leaves {
        let code = m >> (3 * s);
        match out.last_mut() {
            Some(last) if last.0 == code => last.1 += w,
            _ => out.push((code, w)),
        }
    }
    out
}

/// Cuts `weights` into at most `n` contiguous groups with the smallest possible largest sum
/// (binary search on that sum, greedy check), then splits the heaviest groups of more than one
/// item while fewer than `n` groups exist (never raising the largest sum). Returns each
/// group's end index (exclusive), at most `n` of them.
pub(crate) fn partition(weights: &[u64], n: usize) -> Vec<usize> {
    assert!(n >= 1, "at least one shard");
    let greedy = |cap: u64| -> Option<Vec<usize>> {
        let mut ends = Vec::new();
        let mut sum = 0u64;
        for (i, &w) in weights.iter().enumerate() {
            if sum + w > cap && i > 0 && sum > 0 {
                ends.push(i);
                sum = 0;
            }
            sum += w;
        }
        ends.push(weights.len());
        (ends.len() <= n).then_some(ends)
    };
    let (mut lo, mut hi) = (
        weights.iter().copied().max().unwrap_or(0),
        weights.iter().sum::<u64>(),
    );
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if greedy(mid).is_some() {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    let mut ends = greedy(lo).expect("the total always fits one group per shard");
    if weights.is_empty() {
        return ends;
    }
    // use the idle shards: split the heaviest splittable group at its most even point
    while ends.len() < n {
        let start = |g: usize| if g == 0 { 0 } else { ends[g - 1] };
        let sum = |a: usize, b: usize| weights[a..b].iter().sum::<u64>();
        let Some(g) = (0..ends.len())
            .filter(|&g| ends[g] - start(g) > 1)
            .max_by_key(|&g| (sum(start(g), ends[g]), std::cmp::Reverse(g)))
        else {
            break;
        };
        let (a, b) = (start(g), ends[g]);
        let cut = (a + 1..b)
            .min_by_key(|&c| (sum(a, c).max(sum(c, b)), c))
            .expect("a group of two or more items");
        ends.insert(g, cut);
    }
    ends
}

/// Each subtree's shard under longest-processing-time-first: subtrees by weight, heaviest
/// first (ties by Morton order), each to the least loaded of `n` shards (ties to the lowest
/// index). Deterministic.
pub(crate) fn lpt(weights: &[u64], n: usize) -> Vec<usize> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    assert!(n >= 1, "at least one shard");
    let mut order: Vec<usize> = (0..weights.len()).collect();
    order.sort_by_key(|&i| (Reverse(weights[i]), i));
    let mut load: BinaryHeap<Reverse<(u64, usize)>> = (0..n).map(|k| Reverse((0, k))).collect();
    let mut owner = vec![0usize; weights.len()];
    for i in order {
        let Reverse((l, k)) = load.pop().expect("n >= 1 shards");
        owner[i] = k;
        load.push(Reverse((l + weights[i], k)));
    }
    owner
}

/// The shards for split level `s` over `leaves` (see [`subtrees`]) in a tree of `levels`
/// levels, and their balance: the better of the contiguous cut and LPT (module doc).
pub(crate) fn shards_at(
    leaves: &[(u64, u64)],
    levels: u32,
    s: u32,
    n: usize,
) -> (Vec<ShardRange>, Balance) {
    let trees = subtrees(leaves, s);
    let weights: Vec<u64> = trees.iter().map(|t| t.1).collect();
    // the contiguous cut as each subtree's shard
    let mut contiguous = vec![0usize; trees.len()];
    let mut from = 0;
    for (k, &to) in partition(&weights, n).iter().enumerate() {
        contiguous[from..to].fill(k);
        from = to;
    }
    let largest = |owner: &[usize]| {
        let mut sums = vec![0u64; n];
        owner.iter().zip(&weights).for_each(|(&k, &w)| sums[k] += w);
        sums.into_iter().max().unwrap_or(0)
    };
    let by_lpt = lpt(&weights, n);
    let owner = if largest(&by_lpt) < largest(&contiguous) {
        by_lpt
    } else {
        contiguous
    };
    let full = 1u64 << (3 * (levels - 1 - s));
    let mut shards: Vec<ShardRange> = (0..n)
        .map(|i| ShardRange {
            index: i as u32,
            ranges: Vec::new(),
            subtrees: 0,
            triangles: 0,
        })
        .collect();
    // subtree j's range runs from its code (0 for the first) to the next subtree's (the
    // grid's end for the last), so the ranges cover every code; a shard's adjacent ranges join
    for (j, (&k, t)) in owner.iter().zip(&trees).enumerate() {
        let start = if j == 0 { 0 } else { t.0 };
        let end = trees.get(j + 1).map_or(full, |u| u.0);
        let sh = &mut shards[k];
        match sh.ranges.last_mut() {
            Some(r) if r[1] == start => r[1] = end,
            _ => sh.ranges.push([start, end]),
        }
        sh.subtrees += 1;
        sh.triangles += t.1;
    }
    if trees.is_empty() {
        shards[0].ranges.push([0, full]);
    }
    let total: u64 = weights.iter().sum();
    let max = shards.iter().map(|s| s.triangles).max().unwrap_or(0);
    let mean = total as f64 / n as f64;
    let balance = Balance {
        mean,
        max,
        ratio: if total > 0 { max as f64 / mean } else { 0.0 },
        balanced: max * BALANCE.1 * n as u64 <= BALANCE.0 * total,
        subtrees: trees.len() as u64,
    };
    (shards, balance)
}

/// The warning for a plan whose largest shard is over the balance bound, if it is.
pub(crate) fn balance_warning(shards: u32, split_level: u32, balance: &Balance) -> Option<String> {
    (!balance.balanced).then(|| format!(
        "the plan is not balanced: the largest of {shards} shards holds {:.2}× the mean binned triangles ({} subtrees at level {split_level}; the best any split level allows)",
        balance.ratio, balance.subtrees
    ))
}

/// The split level by the rule at the top of this file, its shards and their balance.
pub(crate) fn choose_split(
    leaves: &[(u64, u64)],
    levels: u32,
    n: usize,
) -> (u32, Vec<ShardRange>, Balance) {
    let mut best: Option<(u32, Vec<ShardRange>, Balance)> = None;
    for s in (0..levels).rev() {
        let (shards, balance) = shards_at(leaves, levels, s, n);
        if balance.balanced {
            return (s, shards, balance);
        }
        if best.as_ref().is_none_or(|b| balance.max < b.2.max) {
            best = Some((s, shards, balance));
        }
    }
    best.expect("a tree has at least one level")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The smallest possible largest group over every cut of `w` into at most `n` contiguous
    /// groups, by enumerating the cut positions (brute force).
    fn brute(w: &[u64], n: usize) -> u64 {
        let k = w.len().saturating_sub(1);
        let mut best = u64::MAX;
        for mask in 0u32..(1 << k) {
            if mask.count_ones() as usize + 1 > n {
                continue;
            }
            let (mut cur, mut max) = (0u64, 0u64);
            for (i, &x) in w.iter().enumerate() {
                cur += x;
                if i < k && mask & (1 << i) != 0 {
                    max = max.max(cur);
                    cur = 0;
                }
            }
            best = best.min(max.max(cur));
        }
        best
    }

    /// `partition` reaches the brute-force optimum on random small cases, its groups are
    /// contiguous and non-empty, and it uses every shard when there are enough items.
    #[test]
    fn partition_is_optimal_and_uses_every_shard() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rng = move || voxlod_io::splitmix64(&mut seed);
        for _ in 0..3000 {
            let len = (rng() % 9) as usize + 1;
            let n = (rng() % 6) as usize + 1;
            let w: Vec<u64> = (0..len)
                .map(|_| {
                    if rng() % 4 == 0 {
                        rng() % 1000
                    } else {
                        rng() % 10
                    }
                })
                .collect();
            let ends = partition(&w, n);
            assert!(
                ends.len() <= n && *ends.last().unwrap() == len,
                "{w:?} {n}: {ends:?}"
            );
            assert!(
                ends.windows(2).all(|p| p[0] < p[1]) && ends[0] > 0,
                "{ends:?}"
            );
            assert_eq!(ends.len(), n.min(len), "{w:?} {n}: {ends:?}");
            let mut from = 0;
            let mut max = 0;
            for &e in &ends {
                max = max.max(w[from..e].iter().sum::<u64>());
                from = e;
            }
            assert_eq!(max, brute(&w, n), "{w:?} into {n}: {ends:?}");
        }
    }

    /// The shards' ranges are sorted within each shard and tile the codes `up` levels below
    /// the root.
    fn tiles(shards: &[ShardRange], up: u32) -> bool {
        super::super::plan_file::range_owners(shards, up).is_some()
    }

    /// The largest of `n` sums over every assignment of `w` to `n` shards (brute force).
    fn brute_any(w: &[u64], n: usize) -> u64 {
        let mut best = u64::MAX;
        let mut code = vec![0usize; w.len()];
        loop {
            let mut sums = vec![0u64; n];
            code.iter().zip(w).for_each(|(&k, &x)| sums[k] += x);
            best = best.min(sums.into_iter().max().unwrap());
            let mut i = 0;
            while i < code.len() && code[i] == n - 1 {
                code[i] = 0;
                i += 1;
            }
            if i == code.len() {
                return best;
            }
            code[i] += 1;
        }
    }

    /// LPT stays within Graham's 4/3 − 1/(3n) of the best assignment of any shape (brute
    /// force), and the chosen shards are never worse than the best contiguous cut, cover
    /// every code once, and count every subtree and triangle once.
    #[test]
    fn shards_are_lpt_or_contiguous_whichever_is_smaller() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rng = move || voxlod_io::splitmix64(&mut seed);
        let mut lpt_won = 0;
        for _ in 0..1500 {
            let len = (rng() % 8) as usize + 1;
            let n = (rng() % 4) as usize + 1;
            let w: Vec<u64> = (0..len).map(|_| rng() % 100 + 1).collect();
            let owner = lpt(&w, n);
            let mut sums = vec![0u64; n];
            owner.iter().zip(&w).for_each(|(&k, &x)| sums[k] += x);
            let got = *sums.iter().max().unwrap();
            let best = brute_any(&w, n);
            assert!(3 * n as u64 * got <= (4 * n as u64 - 1) * best, "{w:?} {n}");
            // as leaves of a 3-level tree split at level 0: codes 5 apart
            let leaves: Vec<(u64, u64)> = w
                .iter()
                .enumerate()
                .map(|(i, &x)| (5 * i as u64, x))
                .collect();
            let (shards, b) = shards_at(&leaves, 3, 0, n);
            assert!(tiles(&shards, 2), "{shards:?}");
            assert_eq!(b.max, got.min(brute(&w, n)), "{w:?} {n}");
            assert_eq!(shards.iter().map(|s| s.subtrees).sum::<u64>(), len as u64);
            assert_eq!(
                shards.iter().map(|s| s.triangles).sum::<u64>(),
                w.iter().sum::<u64>()
            );
            lpt_won += usize::from(got < brute(&w, n));
        }
        assert!(
            lpt_won > 100,
            "LPT should beat the contiguous cut often: {lpt_won}"
        );
    }

    /// Two level-1 subtrees, one of them eight times heavier: 4 shards cannot balance at level
    /// 1 (or 2), so the leaves (level 0) are the split level, and the ranges cover the codes.
    #[test]
    fn split_level_goes_down_until_balanced() {
        // 3 levels: 4³ leaf chunks; subtree 0 (leaf codes 0..8) light, subtree 7 heavy
        let mut leaves: Vec<(u64, u64)> = vec![(0, 10), (3, 10)];
        leaves.extend((56..64).map(|m| (m, 10)));
        let (s, shards, b) = choose_split(&leaves, 3, 4);
        assert_eq!(s, 0);
        assert!(b.balanced && b.max <= 30, "{b:?}");
        assert!(tiles(&shards, 2), "{shards:?}");
        assert_eq!(shards.iter().map(|r| r.triangles).sum::<u64>(), 100);
        // one shard: the whole tree, split at the root
        let (s, shards, _) = choose_split(&leaves, 3, 1);
        assert_eq!((s, shards[0].ranges.clone()), (2, vec![[0, 1]]));
        // more shards than leaves: unbalanced at best, some shards empty
        let (_, shards, b) = choose_split(&leaves[..2], 3, 4);
        assert!(!b.balanced && shards.iter().filter(|r| r.triangles == 0).count() == 2);
    }
}
