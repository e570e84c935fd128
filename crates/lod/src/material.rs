//! The LOD rule of the material channel (docs/FORMAT.md 14.3; the per-voxel material ids of
//! Chajdas, Reitinger & Westermann, "Scalable rendering for very large meshes", WSCG 2014,
//! section 3.1, carried through their sort-and-compact LOD, section 4): a parent voxel takes
//! the material held by the most child voxels of its run, ties to the smallest id. Each child
//! voxel stands for the same area at its level, so this is the largest summed area weight with
//! the child voxel as the unit (the colour rule of section 8 makes the same assumption).
//!
//! The parent's voxels are the runs in the order [`crate::merge_children`] makes them: child
//! octants in order 0…7, and inside a child its voxels in Morton order, a run being the voxels
//! whose Morton codes agree above the lowest 3 bits (the 2×2×2 block of one parent voxel). So
//! the materials are found by one scan of each child, aligned with the merged voxels.

use voxlod_format::voxel::{morton8, Voxel};

/// The parent's per-voxel materials, in the order of [`crate::merge_children`]`(children)`:
/// `materials[i][j]` is the material of `children[i][j]`.
///
/// # Panics
/// If `materials[i]` and `children[i]` differ in length.
pub fn merge_materials(children: &[&[Voxel]; 8], materials: &[&[u32]; 8]) -> Vec<u32> {
    let mut out = Vec::new();
    for (voxels, mats) in children.iter().zip(materials) {
        append_half_materials(voxels, mats, &mut out);
    }
    out
}

/// The materials of one child's half (`voxlod_lod::MergeScratch::halve`), in its order: the
/// parent's materials are the concatenation of its children's, as the voxels are.
///
/// # Panics
/// If `voxels` and `materials` differ in length.
pub fn halve_materials(voxels: &[Voxel], materials: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(voxels.len() / 2);
    append_half_materials(voxels, materials, &mut out);
    out
}

fn append_half_materials(voxels: &[Voxel], mats: &[u32], out: &mut Vec<u32>) {
    assert_eq!(voxels.len(), mats.len(), "one material per child voxel");
    let mut j = 0;
    while j < voxels.len() {
        let p = voxels[j].pos();
        let key = morton8(p[0], p[1], p[2]) >> 3;
        let mut end = j + 1;
        while end < voxels.len() && {
            let q = voxels[end].pos();
            morton8(q[0], q[1], q[2]) >> 3 == key
        } {
            end += 1;
        }
        out.push(majority(&mats[j..end]));
        j = end;
    }
}

/// The id held most often in `run` (at most 8 entries), ties to the smallest id.
fn majority(run: &[u32]) -> u32 {
    debug_assert!(!run.is_empty() && run.len() <= 8);
    let mut best = (0usize, u32::MAX);
    for (i, &m) in run.iter().enumerate() {
        if run[..i].contains(&m) {
            continue;
        }
        let count = run[i..].iter().filter(|&&x| x == m).count();
        if count > best.0 || (count == best.0 && m < best.1) {
            best = (count, m);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{merge_children, parent_key};
    use std::collections::BTreeMap;
    use voxlod_format::voxel::{pack_color, pack_normal};

    /// Eight Morton-sorted children (clustered, so runs of several voxels occur) and a
    /// material in `0..ids` for each of their voxels.
    fn children_with_materials(seed: u64, ids: u64) -> (Vec<Vec<Voxel>>, Vec<Vec<u32>>) {
        let mut state = seed;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let n = pack_normal([0.0, 1.0, 0.0]);
        let mut kids: Vec<Vec<Voxel>> = Vec::new();
        let mut mats: Vec<Vec<u32>> = Vec::new();
        for _ in 0..8 {
            let mut codes: Vec<u32> = (0..3000).map(|_| (next() % (1 << 12)) as u32).collect();
            codes.sort_unstable();
            codes.dedup();
            let v: Vec<Voxel> = codes
                .iter()
                .map(|&c| {
                    let p: [u8; 3] = std::array::from_fn(|a| {
                        (0..8).map(|b| ((c >> (3 * b + a)) & 1) << b).sum::<u32>() as u8
                    });
                    Voxel::new(p, 0, n, pack_color([1, 2, 3, 4]))
                })
                .collect();
            mats.push(v.iter().map(|_| (next() % ids) as u32).collect());
            kids.push(v);
        }
        (kids, mats)
    }

    /// The id held most often in `list`, ties to the smallest, among `0..ids` (by counting).
    fn most_frequent(list: &[u32], ids: u32) -> u32 {
        let count = |x: u32| list.iter().filter(|&&y| y == x).count();
        (0..ids)
            .max_by_key(|&x| (count(x), std::cmp::Reverse(x)))
            .unwrap()
    }

    /// Each child's half materials, aligned with its half's voxels, hold each run's majority
    /// (checked against a map from parent position to the run's materials).
    #[test]
    fn half_materials_hold_each_runs_majority() {
        let (kids, mats) = children_with_materials(0x2545_F491_4F6C_DD1D, 5);
        let mut scratch = crate::MergeScratch::new();
        let mut half = Vec::new();
        for o in 0..8 {
            let got = halve_materials(&kids[o], &mats[o]);
            scratch.halve(&kids[o], o, &mut half);
            assert_eq!(got.len(), half.len(), "octant {o}");
            let mut by_pos: BTreeMap<[u8; 3], Vec<u32>> = BTreeMap::new();
            for (v, &m) in kids[o].iter().zip(&mats[o]) {
                by_pos.entry(parent_key(o, v.pos()).0).or_default().push(m);
            }
            for (v, m) in half.iter().zip(&got) {
                let want = most_frequent(&by_pos[&v.pos()], 5);
                assert_eq!(*m, want, "octant {o}, parent voxel {:?}", v.pos());
            }
        }
    }

    #[test]
    fn majority_then_smallest_id() {
        assert_eq!(majority(&[4]), 4);
        assert_eq!(majority(&[4, 2, 4]), 4);
        assert_eq!(majority(&[4, 2, 2, 4]), 2);
        assert_eq!(majority(&[9, 8, 7, 6, 5, 4, 3, 1]), 1);
    }

    /// Against a map from parent position to the child materials, built with `parent_key`.
    #[test]
    fn aligned_with_merge_children_and_equal_to_a_map() {
        let (kids, mats) = children_with_materials(0x9E37_79B9_7F4A_7C15, 4);
        let children: [&[Voxel]; 8] = std::array::from_fn(|i| kids[i].as_slice());
        let materials: [&[u32]; 8] = std::array::from_fn(|i| mats[i].as_slice());
        let parent = merge_children(&children);
        let got = merge_materials(&children, &materials);
        assert_eq!(got.len(), parent.len());
        let mut by_pos: BTreeMap<[u8; 3], Vec<u32>> = BTreeMap::new();
        for o in 0..8 {
            for (v, &m) in kids[o].iter().zip(&mats[o]) {
                by_pos.entry(parent_key(o, v.pos()).0).or_default().push(m);
            }
        }
        for (v, m) in parent.iter().zip(&got) {
            let want = most_frequent(&by_pos[&v.pos()], 4);
            assert_eq!(*m, want, "parent voxel {:?}", v.pos());
        }
    }
}
