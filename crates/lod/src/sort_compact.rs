//! Sort-and-compact OR-merge of eight child chunks into their parent (Chajdas et al. 2014,
//! section 4, Figures 4 and 5).

use voxlod_format::voxel::{border_caps, morton8, pack_normals, Voxel};
use voxlod_geom::morton::morton8_word_by_table;

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
    /// Copy of a child that broke the Morton precondition, sorted.
    sorted: Vec<Voxel>,
    /// The run totals of the block being scanned (12 KiB, kept off the stack).
    runs: Box<Runs>,
}

impl MergeScratch {
    /// Empty scratch buffers (they grow on first use).
    pub fn new() -> Self {
        Self::default()
    }

    /// Builds the parent of `children` (indexed by octant) into `out` (cleared first). Each child
    /// should be sorted by `morton8` of its positions, as every stored node is; a child that is
    /// not is sorted first (a slower path with the same result). A child must not hold a
    /// position twice (no stored node does); that panics.
    pub fn merge(&mut self, children: &[&[Voxel]; 8], out: &mut Vec<Voxel>) {
        out.clear();
        // At most one parent voxel per child voxel (a quarter of that on a surface).
        out.reserve(children.iter().map(|c| c.len()).sum::<usize>() / 2);
        // No sort: octant i owns parent keys [i·2^21, (i+1)·2^21), and inside a sorted child
        // the parent key is the child's Morton code shifted right by 3, so the concatenation of
        // the children's runs in octant order is already the parent's Morton order.
        for (octant, &child) in children.iter().enumerate() {
            self.append_half(child, octant, out);
        }
    }

    /// The parent voxels of one child alone (octant `octant`) into `out` (cleared first): its
    /// *half*. A parent's runs never span two children, so [`merge`](Self::merge) is the
    /// concatenation of its children's halves in octant order, and a leaf's half can be made
    /// on the worker that voxelized it (the pipeline's level-1 merge is then a concatenation).
    /// Same preconditions as `merge`.
    pub fn halve(&mut self, child: &[Voxel], octant: usize, out: &mut Vec<Voxel>) {
        assert!(octant < 8, "octant {octant} is not 0..8");
        out.clear();
        out.reserve(child.len() / 2);
        self.append_half(child, octant, out);
    }

    /// Appends the half of `child` (octant `octant`) to `out`.
    fn append_half(&mut self, child: &[Voxel], octant: usize, out: &mut Vec<Voxel>) {
        let runs = &mut *self.runs;
        let before = out.len();
        if !runs.merge_child(child, octant, out) {
            // the child broke the precondition: merge a sorted copy instead
            out.truncate(before);
            self.sorted.clear();
            self.sorted.extend_from_slice(child);
            self.sorted.sort_by_key(Voxel::morton);
            assert!(
                runs.merge_child(&self.sorted, octant, out),
                "child octant {octant} holds a position twice"
            );
        }
    }
}

/// Runs accumulated per block of a child before they are compacted together.
const BLOCK: usize = 512;

/// The totals of the runs of one block of child voxels, as the scan leaves them: slot `r`
/// holds run `r` (the last may continue in the next block).
struct Runs {
    /// The OR of the run's position words: the parent position times two in the high seven
    /// bits of each axis, the OR of the face masks in bits 24–29.
    pos: [u32; BLOCK + 1],
    /// The sums of the run's normal components, each offset by 512, in 16-bit lanes (x, y, z),
    /// and the run length in bits 48–63.
    nsum: [u64; BLOCK + 1],
    /// The sums of the run's colour channels in 16-bit lanes (R, G, B, A).
    csum: [u64; BLOCK + 1],
}

impl Default for Runs {
    fn default() -> Self {
        Runs {
            pos: [0; BLOCK + 1],
            nsum: [0; BLOCK + 1],
            csum: [0; BLOCK + 1],
        }
    }
}

impl Runs {
    /// Appends the parent voxels of one child (octant `octant`) to `out`, block by block.
    /// Returns false if the child is not in strictly increasing Morton order (then `out` holds
    /// garbage past its former length).
    fn merge_child(&mut self, child: &[Voxel], octant: usize, out: &mut Vec<Voxel>) -> bool {
        let high = octant_bits(octant);
        let mut sorted = true;
        let mut prev_code = None;
        let mut open = false; // slot 0 holds a run carried over from the previous block
        for block in child.chunks(BLOCK) {
            let (end, ok) = self.scan(block, open, &mut prev_code);
            sorted &= ok;
            // every run but the last is complete; the last may go on in the next block
            self.compact(end - 1, high, out);
            let last = end - 1;
            self.pos[0] = self.pos[last];
            self.nsum[0] = self.nsum[last];
            self.csum[0] = self.csum[last];
            open = true;
        }
        if open {
            self.compact(1, high, out);
        }
        sorted
    }

    /// Scans one block (members of one parent voxel are adjacent, since the child is
    /// Morton-sorted: equal positions without their last bit). With `open`, slot 0 holds a run
    /// that the block may continue. Returns the number of slots used and whether the block
    /// continued strictly increasing Morton codes from `prev_code`.
    ///
    /// Branch-free: every voxel adds into the current slot, which restarts when the parent
    /// position changes, and the slot is stored each time, so the last store of a run holds
    /// its totals.
    #[inline(never)]
    fn scan(&mut self, block: &[Voxel], open: bool, prev_code: &mut Option<u32>) -> (usize, bool) {
        debug_assert!(block.len() <= BLOCK);
        let mut slot = open as usize; // one past the current run
                                      // no parent position has bits outside 0xfefefe
        let mut prev = if open {
            self.pos[0] & 0x00fe_fefe
        } else {
            u32::MAX
        };
        let (mut pacc, mut nacc, mut cacc) = (self.pos[0], self.nsum[0], self.csum[0]);
        let mut sorted = true;
        let mut last_code = *prev_code;
        for v in block {
            let code = Some(morton8_word_by_table(v.pos_mask));
            sorted &= code > last_code;
            last_code = code;
            let parent = v.pos_mask & 0x00fe_fefe;
            let same = parent == prev;
            prev = parent;
            slot += !same as usize;
            let keep32 = 0u32.wrapping_sub(same as u32);
            let keep = 0u64.wrapping_sub(same as u64);
            pacc = (pacc & keep32) | v.pos_mask;
            nacc = (nacc & keep) + spread_normal(v.normal);
            cacc = (cacc & keep) + spread_color(v.color);
            self.pos[slot - 1] = pacc;
            self.nsum[slot - 1] = nacc;
            self.csum[slot - 1] = cacc;
        }
        *prev_code = last_code;
        (slot, sorted)
    }

    /// Parent voxels from the runs in slots `0..n` (FORMAT.md section 8), appended to `out`:
    /// position = the members' positions without their last bit plus the octant's bit
    /// (`high`), mask = OR of the members' masks and the parent's border caps, normal = pack of
    /// the integer sums (exact in f32; packed together, in SIMD lanes), colour = rounded
    /// integer mean.
    #[inline(never)]
    fn compact(&self, n: usize, high: u32, out: &mut Vec<Voxel>) {
        debug_assert!(n <= BLOCK);
        let mut xyz = [[0f32; BLOCK]; 3];
        let mut normals = [0u32; BLOCK];
        for (r, &s) in self.nsum[..n].iter().enumerate() {
            let m = (s >> 48) as i32;
            for (a, c) in xyz.iter_mut().enumerate() {
                c[r] = ((s >> (16 * a) & 0xffff) as i32 - 512 * m) as f32;
            }
        }
        pack_normals(&xyz[0][..n], &xyz[1][..n], &xyz[2][..n], &mut normals[..n]);
        out.extend((0..n).map(|r| {
            let pw = self.pos[r];
            let p = (pw >> 1 & 0x007f_7f7f) | high;
            let caps = border_caps([p as u8, (p >> 8) as u8, (p >> 16) as u8]);
            let mask = (pw >> 24) as u8 & 0x3f | caps;
            let m = (self.nsum[r] >> 48) as u32;
            debug_assert!((1..=8).contains(&m), "a run has one to eight members");
            let mean = |lane: u32| mean_u8((self.csum[r] >> (16 * lane) & 0xffff) as u32, m);
            Voxel {
                pos_mask: p | (mask as u32) << 24,
                normal: normals[r],
                color: u32::from_le_bytes([mean(0), mean(1), mean(2), mean(3)]),
            }
        }));
    }
}

/// A normal word's components `q + 512` (0…1023: the sign bit flipped) in 16-bit lanes, and 1
/// in bits 48–63 to count the run. Eight of them cannot carry between lanes (8·1023 < 2^16).
#[inline]
fn spread_normal(w: u32) -> u64 {
    let u = (w ^ 0x2008_0200) as u64;
    (u & 0x3ff) | (u >> 10 & 0x3ff) << 16 | (u >> 20 & 0x3ff) << 32 | 1 << 48
}

/// A colour word's four channels in 16-bit lanes (8·255 < 2^16).
#[inline]
fn spread_color(c: u32) -> u64 {
    let c = c as u64;
    (c & 0xff) | (c & 0xff00) << 8 | (c & 0xff_0000) << 16 | (c & 0xff00_0000) << 24
}

/// The parent-position bits an octant adds: bit 7 of x, y, z for dx, dy, dz.
#[inline]
fn octant_bits(octant: usize) -> u32 {
    let o = octant as u32;
    (o & 1) << 7 | (o >> 1 & 1) << 15 | (o >> 2 & 1) << 23
}

/// `(sum + ⌊m/2⌋) / m` for a sum of `m ≤ 8` bytes, as a multiply and shift: `RECIP[m]` is
/// `⌈2^20 / m⌉`, exact for every numerator below 2^11 (tested exhaustively).
#[inline]
fn mean_u8(sum: u32, m: u32) -> u8 {
    debug_assert!((1..=8).contains(&m) && sum <= 255 * m);
    (((sum + m / 2) * RECIP[m as usize]) >> 20) as u8
}

const RECIP: [u32; 9] = {
    let mut t = [0u32; 9];
    let mut m = 1;
    while m < 9 {
        t[m] = (1u32 << 20).div_ceil(m as u32);
        m += 1;
    }
    t
};

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
    use voxlod_format::voxel::{pack_normal, unpack_normal};

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
                    for (c, b) in cs.iter_mut().zip(v.rgba()) {
                        *c += b as u64;
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
            let p = if rng(s) & 3 == 0 { [255, p[1], 0] } else { p };
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

    /// Full runs of eight (a dense block) with the extreme attribute values: components ±511
    /// and 0, zero normals, colour channels 0 and 255, every face mask; blocks of the scan
    /// (`BLOCK`) end inside runs.
    #[test]
    fn dense_blocks_with_extreme_attributes_match_reference() {
        let mut s = 77u64;
        let extremes = [0x1ff, 0x201, 0, 0x3ff, 0x200];
        let children: [Vec<Voxel>; 8] = std::array::from_fn(|o| {
            let mut m: BTreeMap<u32, Voxel> = BTreeMap::new();
            // a 40³ dense cube (several thousand full runs), placed by octant near the borders
            let base = if o % 2 == 0 { 0u8 } else { 216 };
            for x in 0..40u8 {
                for y in 0..40u8 {
                    for z in 0..40u8 {
                        let r = rng(&mut s);
                        let pick = |k: u32| extremes[(r >> k) as usize % extremes.len()];
                        let normal = pick(0) | pick(3) << 10 | pick(6) << 20;
                        let chan = |k: u32| if r >> k & 1 == 1 { 255u8 } else { 0 };
                        let p = [base + x, base + y, base + z];
                        let v = Voxel::new(
                            p,
                            (r >> 20) as u8 & 0x3f,
                            normal,
                            pack_color([chan(26), chan(27), chan(28), chan(29)]),
                        );
                        m.insert(v.morton(), v);
                    }
                }
            }
            m.into_values().collect()
        });
        let refs: [&[Voxel]; 8] = std::array::from_fn(|o| children[o].as_slice());
        assert_eq!(merge_children(&refs), reference(&children));
    }

    /// Each child's half, made alone, is its octant's share of the reference parent: the
    /// halves concatenated in octant order equal the parent (the pipeline's level-1 merge),
    /// with a scratch reused across children of different sizes, an unsorted child among them.
    #[test]
    fn halves_concatenated_equal_the_parent() {
        let mut s = 5u64;
        let mut children: [Vec<Voxel>; 8] =
            std::array::from_fn(|o| random_child(&mut s, 300 + 700 * (o % 3)));
        children[6].reverse();
        let want = reference(&children);
        let mut scratch = MergeScratch::new();
        let mut joined = Vec::new();
        let mut half = Vec::new();
        for (o, c) in children.iter().enumerate() {
            scratch.halve(c, o, &mut half);
            // every voxel of the half lies in the octant's part of the parent
            assert!(half.iter().all(|v| v
                .pos()
                .iter()
                .enumerate()
                .all(|(a, &p)| (p >> 7) as usize == o >> a & 1)));
            joined.extend_from_slice(&half);
        }
        assert_eq!(joined, want);
    }

    /// The multiply-and-shift mean equals the integer division for every possible run.
    #[test]
    fn mean_by_reciprocal_is_exact() {
        for m in 1..=8u32 {
            for sum in 0..=255 * m {
                assert_eq!(mean_u8(sum, m) as u32, (sum + m / 2) / m, "{sum} / {m}");
            }
        }
    }

    #[test]
    fn unsorted_children_still_merge_correctly() {
        let mut s = 9u64;
        let mut children: [Vec<Voxel>; 8] = std::array::from_fn(|_| random_child(&mut s, 500));
        let want = reference(&children);
        // one child reversed among sorted ones, and one with a single pair swapped far in
        children[2].reverse();
        let k = children[5].len() * 3 / 4;
        children[5].swap(k, k + 1);
        let refs: [&[Voxel]; 8] = std::array::from_fn(|o| children[o].as_slice());
        // runs whose members came in another order give the same means (sums commute)
        assert_eq!(merge_children(&refs), want);
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
