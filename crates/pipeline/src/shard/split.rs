//! The split of a plan: the split level S and the shards' Morton ranges of level-S subtrees.
//!
//! Split rule: the coarsest level S whose non-empty subtrees, cut into `shards` contiguous
//! ranges with the smallest possible largest range (by binned triangles: a triangle counts
//! once per chunk it is binned to, the voxelizer's work), has no shard above 1.5× the mean.
//! When no level allows that (fewer subtrees than shards, one dominant subtree), the level
//! with the smallest largest shard is taken and the plan says it is unbalanced.

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

/// The shards for split level `s` over `leaves` (see [`subtrees`]) in a tree of `levels`
/// levels, and their balance.
pub(crate) fn shards_at(
    leaves: &[(u64, u64)],
    levels: u32,
    s: u32,
    n: usize,
) -> (Vec<ShardRange>, Balance) {
    let trees = subtrees(leaves, s);
    let weights: Vec<u64> = trees.iter().map(|t| t.1).collect();
    let ends = partition(&weights, n);
    let full = 1u64 << (3 * (levels - 1 - s));
    let mut shards = Vec::with_capacity(n);
    let mut from = 0usize;
    for i in 0..n {
        let to = ends.get(i).copied().unwrap_or(trees.len());
        let morton_start = shards.last().map_or(0, |p: &ShardRange| p.morton_end);
        let morton_end = if i + 1 == n {
            full
        } else if to < trees.len() {
            trees[to].0
        } else {
            full
        };
        shards.push(ShardRange {
            index: i as u32,
            morton_start,
            morton_end,
            subtrees: (to - from) as u64,
            triangles: weights[from..to].iter().sum(),
        });
        from = to;
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
        let mut rng = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
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
        assert_eq!(shards.first().unwrap().morton_start, 0);
        assert_eq!(shards.last().unwrap().morton_end, 64);
        assert_eq!(shards.iter().map(|r| r.triangles).sum::<u64>(), 100);
        // one shard: the whole tree, split at the root
        let (s, shards, _) = choose_split(&leaves, 3, 1);
        assert_eq!((s, shards[0].morton_end), (2, 1));
        // more shards than leaves: unbalanced at best, some shards empty
        let (_, shards, b) = choose_split(&leaves[..2], 3, 4);
        assert!(!b.balanced && shards.iter().filter(|r| r.triangles == 0).count() == 2);
    }
}
