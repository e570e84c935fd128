//! Sort-and-compact OR-merge of eight child chunks into their parent (Chajdas et al. 2014,
//! section 4, Figures 4 and 5).

use voxlod_format::voxel::{border_caps, morton8, pack_normal, unpack_normal, Voxel};

/// Parent position and its Morton key for a child voxel at `pos` in child `octant`
/// (`octant = dx | dy<<1 | dz<<2`): each coordinate without its last bit, offset by the octant.
#[inline]
pub fn parent_key(octant: usize, pos: [u8; 3]) -> ([u8; 3], u32) {
    debug_assert!(octant < 8);
    let p = [
        ((octant & 1) as u8) << 7 | pos[0] >> 1,
        ((octant >> 1 & 1) as u8) << 7 | pos[1] >> 1,
        ((octant >> 2 & 1) as u8) << 7 | pos[2] >> 1,
    ];
    (p, morton8(p[0], p[1], p[2]))
}

/// Reusable buffers for [`MergeScratch::merge`], so building many parents allocates once.
#[derive(Default)]
pub struct MergeScratch {
    keys: Vec<u32>,
    vox: Vec<Voxel>,
    order: Vec<u32>,
    starts: Vec<u32>,
}

impl MergeScratch {
    pub fn new() -> Self {
        Self::default()
    }

    /// Builds the parent of `children` (indexed by octant) into `out` (cleared first). Each child
    /// must be sorted by `morton8` of its positions, as every stored node is.
    pub fn merge(&mut self, children: &[&[Voxel]; 8], out: &mut Vec<Voxel>) {
        out.clear();
        self.keys.clear();
        self.vox.clear();
        let n: usize = children.iter().map(|c| c.len()).sum();
        if n == 0 {
            return;
        }
        self.keys.reserve(n);
        self.vox.reserve(n);

        // Sort key of every child voxel: the Morton code of its parent position. Children are
        // gathered in octant order; octant i owns parent keys [i·2^21, (i+1)·2^21), and inside a
        // child the parent key is the child's Morton code shifted right by 3, so keys arrive
        // already non-decreasing and the paper's radix sort reduces to this concatenation.
        for (octant, child) in children.iter().enumerate() {
            for v in child.iter() {
                self.keys.push(parent_key(octant, v.pos()).1);
                self.vox.push(*v);
            }
        }
        // Inputs that break the Morton precondition still merge correctly, through a stable sort.
        let sorted = self.keys.windows(2).all(|w| w[0] <= w[1]);
        let order: Option<&[u32]> = if sorted {
            None
        } else {
            self.order.clear();
            self.order.extend(0..n as u32);
            let keys = &self.keys;
            self.order.sort_by_key(|&i| keys[i as usize]);
            Some(&self.order)
        };
        let at = |i: usize| order.map_or(i, |o| o[i] as usize);

        // Prefix scan over run heads (a key that differs from its predecessor): the scan gives
        // each run its output slot; `starts` keeps where each run begins.
        self.starts.clear();
        let mut prev = u32::MAX;
        for i in 0..n {
            let k = self.keys[at(i)];
            if k != prev {
                self.starts.push(i as u32);
                prev = k;
            }
        }
        self.starts.push(n as u32);

        // Compact each run into one voxel.
        out.reserve(self.starts.len() - 1);
        for r in self.starts.windows(2) {
            let (s, e) = (r[0] as usize, r[1] as usize);
            let mut mask = 0u8;
            let mut nsum = [0i64; 3];
            let mut csum = [0u32; 4];
            let mut ppos = [0u8; 3];
            for i in s..e {
                let j = at(i);
                let v = &self.vox[j];
                let octant = octant_of(self.keys[j]);
                ppos = parent_key(octant, v.pos()).0;
                mask |= v.mask();
                let q = unpack_normal(v.normal);
                for a in 0..3 {
                    nsum[a] += q[a] as i64;
                }
                for (a, c) in v.rgba().iter().enumerate() {
                    csum[a] += *c as u32;
                }
            }
            let cnt = (e - s) as u32;
            let normal = pack_normal([nsum[0] as f32, nsum[1] as f32, nsum[2] as f32]);
            let color = u32::from_le_bytes(csum.map(|c| ((c + cnt / 2) / cnt) as u8));
            out.push(Voxel::new(ppos, mask | border_caps(ppos), normal, color));
        }
    }
}

/// The octant a parent key lies in (its top three Morton bits).
#[inline]
fn octant_of(key: u32) -> usize {
    (key >> 21) as usize & 7
}

/// Convenience wrapper of [`MergeScratch::merge`] with fresh buffers.
pub fn merge_children(children: &[&[Voxel]; 8]) -> Vec<Voxel> {
    let mut out = Vec::new();
    MergeScratch::new().merge(children, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;
    use voxlod_format::voxel::pack_color;

    fn rng(s: &mut u64) -> u32 {
        *s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*s >> 33) as u32
    }

    /// Reference: a map from absolute parent position to the list of children, then the means.
    fn reference(children: &[Vec<Voxel>; 8]) -> Vec<Voxel> {
        let mut runs: BTreeMap<u32, ([u8; 3], Vec<Voxel>)> = BTreeMap::new();
        for (o, c) in children.iter().enumerate() {
            for v in c {
                let p = v.pos();
                let abs = [
                    (o & 1) as u32 * 256 + p[0] as u32,
                    (o >> 1 & 1) as u32 * 256 + p[1] as u32,
                    (o >> 2) as u32 * 256 + p[2] as u32,
                ];
                let pp = [(abs[0] / 2) as u8, (abs[1] / 2) as u8, (abs[2] / 2) as u8];
                runs.entry(morton8(pp[0], pp[1], pp[2]))
                    .or_insert((pp, Vec::new()))
                    .1
                    .push(*v);
            }
        }
        runs.values()
            .map(|(pp, vs)| {
                let mask = vs.iter().fold(0, |m, v| m | v.mask()) | border_caps(*pp);
                let mut ns = [0f64; 3];
                let mut cs = [0u64; 4];
                for v in vs {
                    let q = unpack_normal(v.normal);
                    for a in 0..3 {
                        ns[a] += q[a] as f64;
                    }
                    for a in 0..4 {
                        cs[a] += v.rgba()[a] as u64;
                    }
                }
                let n = vs.len() as u64;
                Voxel::new(
                    *pp,
                    mask,
                    pack_normal([ns[0] as f32, ns[1] as f32, ns[2] as f32]),
                    pack_color(cs.map(|c| ((c + n / 2) / n) as u8)),
                )
            })
            .collect()
    }

    fn random_child(s: &mut u64, n: usize) -> Vec<Voxel> {
        let mut m: BTreeMap<u32, Voxel> = BTreeMap::new();
        for _ in 0..n {
            // clustered positions so runs of several voxels occur
            let p = [
                (rng(s) % 40) as u8 * 6 % 255,
                (rng(s) % 40) as u8,
                (rng(s) % 256) as u8,
            ];
            let p = if rng(s) % 4 == 0 { [255, p[1], 0] } else { p };
            let nrm = pack_normal([
                rng(s) as f32 - 2e9,
                rng(s) as f32 - 2e9,
                rng(s) as f32 - 2e9,
            ]);
            let v = Voxel::new(p, (rng(s) % 64) as u8, nrm, rng(s));
            m.insert(v.morton(), v);
        }
        m.into_values().collect()
    }

    #[test]
    fn matches_reference_on_random_children() {
        let mut s = 1u64;
        for trial in 0..20 {
            let children: [Vec<Voxel>; 8] = std::array::from_fn(|o| {
                if (trial + o) % 3 == 0 {
                    vec![]
                } else {
                    random_child(&mut s, 2000)
                }
            });
            let refs: [&[Voxel]; 8] = std::array::from_fn(|o| children[o].as_slice());
            let got = merge_children(&refs);
            assert_eq!(got, reference(&children), "trial {trial}");
            // output is itself a valid node: strictly Morton-sorted
            assert!(got.windows(2).all(|w| w[0].morton() < w[1].morton()));
        }
    }

    #[test]
    fn unsorted_children_still_merge_correctly() {
        let mut s = 9u64;
        let mut children: [Vec<Voxel>; 8] = std::array::from_fn(|_| random_child(&mut s, 500));
        let want = reference(&children);
        for c in &mut children {
            c.reverse();
        }
        let refs: [&[Voxel]; 8] = std::array::from_fn(|o| children[o].as_slice());
        let mut got = merge_children(&refs);
        // runs whose members came in another order give the same means (sums commute)
        got.sort_by_key(|v| v.morton());
        assert_eq!(got, want);
    }

    #[test]
    fn parent_covers_children_faces() {
        let mut s = 3u64;
        let children: [Vec<Voxel>; 8] = std::array::from_fn(|_| random_child(&mut s, 300));
        let refs: [&[Voxel]; 8] = std::array::from_fn(|o| children[o].as_slice());
        let parent = merge_children(&refs);
        for (o, c) in children.iter().enumerate() {
            for v in c {
                let (pp, key) = parent_key(o, v.pos());
                let pv = parent
                    .iter()
                    .find(|p| p.morton() == key)
                    .expect("parent voxel exists");
                assert_eq!(pv.pos(), pp);
                assert_eq!(
                    pv.mask() & v.mask(),
                    v.mask(),
                    "OR must keep every child face"
                );
            }
        }
    }
}
