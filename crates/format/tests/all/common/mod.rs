//! Shared test helpers: a deterministic RNG, random node contents, the post-order walk of an
//! octree, and an independent implementation of the documented layout (`docs/FORMAT.md`)
//! that assembles file bytes field by field, without the crate's structs or writer.

#![allow(dead_code)]

pub mod sphere;

use std::collections::BTreeMap;

use voxlod_format::voxel::{border_caps, morton8, pack_normal, unpack_normal, Voxel};
use voxlod_format::FileSpec;

pub use voxlod_testkit::Rng;

/// Inverse of morton8, by bit loop (independent of the crate's).
pub fn unmorton(m: u32) -> [u8; 3] {
    let mut p = [0u8; 3];
    for b in 0..8 {
        for (a, q) in p.iter_mut().enumerate() {
            *q |= (((m >> (3 * b + a)) & 1) as u8) << b;
        }
    }
    p
}

/// `w` with every normal component of −512 (`0x200`, not allowed by FORMAT.md section 6)
/// made −511.
pub fn no_minus_512(w: u32) -> u32 {
    (0..3).fold(w, |w, a| {
        if (w >> (10 * a)) & 0x3ff == 0x200 {
            w | 1 << (10 * a)
        } else {
            w
        }
    })
}

/// `n` random voxels (n ≤ 2^24) at distinct positions, sorted by Morton code, with random
/// mask, normal (bits 0–29) and colour.
pub fn random_voxels(rng: &mut Rng, n: usize) -> Vec<Voxel> {
    assert!(n <= 1 << 24);
    let mut codes: Vec<u32> = if n > (1 << 23) {
        // dense: drop random codes from the full set
        let mut all: Vec<u32> = (0..1u32 << 24).collect();
        for i in (1..all.len()).rev() {
            all.swap(i, rng.below(i as u64 + 1) as usize);
        }
        all.truncate(n);
        all
    } else {
        let mut c = Vec::with_capacity(n);
        let mut seen = std::collections::HashSet::with_capacity(n);
        while c.len() < n {
            let m = rng.below(1 << 24) as u32;
            if seen.insert(m) {
                c.push(m);
            }
        }
        c
    };
    codes.sort_unstable();
    codes
        .iter()
        .map(|&m| {
            let r = rng.next_u64();
            Voxel::new(
                unmorton(m),
                (r & 0x3f) as u8,
                no_minus_512((r >> 6) as u32 & 0x3fff_ffff),
                (r >> 32) as u32,
            )
        })
        .collect()
}

/// Post-order over the octree with children in Morton order: every node whose subtree holds
/// a leaf of `leaves` (level-0 positions), as (level, pos, child_mask).
pub fn post_order(levels: u32, leaves: &[[u32; 3]]) -> Vec<(u32, [u32; 3], u8)> {
    fn visit(
        level: u32,
        pos: [u32; 3],
        leaves: &std::collections::HashSet<[u32; 3]>,
        out: &mut Vec<(u32, [u32; 3], u8)>,
    ) -> bool {
        if level == 0 {
            if leaves.contains(&pos) {
                out.push((0, pos, 0));
                return true;
            }
            return false;
        }
        let mut mask = 0u8;
        for i in 0..8u32 {
            let c = [
                2 * pos[0] + (i & 1),
                2 * pos[1] + (i >> 1 & 1),
                2 * pos[2] + (i >> 2 & 1),
            ];
            if visit(level - 1, c, leaves, out) {
                mask |= 1 << i;
            }
        }
        if mask != 0 {
            out.push((level, pos, mask));
        }
        mask != 0
    }
    let set = leaves.iter().copied().collect();
    let mut out = Vec::new();
    visit(levels - 1, [0, 0, 0], &set, &mut out);
    out
}

/// The documented block transform, written from `docs/FORMAT.md` ("Node payload") alone.
pub fn reference_block(voxels: &[Voxel]) -> Vec<u8> {
    let n = voxels.len();
    let mut words = [Vec::new(), Vec::new(), Vec::new()];
    let mut prev = 0u32;
    for v in voxels {
        let m = morton8(v.pos()[0], v.pos()[1], v.pos()[2]);
        words[0].push(m.wrapping_sub(prev) | (v.mask() as u32) << 24);
        prev = m;
        words[1].push(v.normal);
        words[2].push(v.color);
    }
    let mut block = vec![0u8; 12 * n];
    for (a, ws) in words.iter().enumerate() {
        for (j, w) in ws.iter().enumerate() {
            for k in 0..4 {
                block[4 * n * a + k * n + j] = w.to_le_bytes()[k];
            }
        }
    }
    // delta-code the 8 planes of the normal and colour arrays
    for plane in block[4 * n..].chunks_mut(n.max(1)) {
        for j in (1..plane.len()).rev() {
            plane[j] = plane[j].wrapping_sub(plane[j - 1]);
        }
    }
    block
}

/// One node for [`assemble`].
#[derive(Clone)]
pub struct RawNode {
    pub level: u32,
    pub pos: [u32; 3],
    pub child_mask: u32,
    pub voxel_count: u32,
    pub payload: Vec<u8>,
    pub block_crc32: u32,
    pub bounds_min: [u8; 3],
    pub bounds_max: [u8; 3],
}

impl RawNode {
    /// A node from voxels: the reference block compressed with zstd at `level`.
    pub fn from_voxels(
        level: u32,
        pos: [u32; 3],
        child_mask: u32,
        voxels: &[Voxel],
        zstd_level: i32,
    ) -> RawNode {
        let block = reference_block(voxels);
        let mut lo = [255u8; 3];
        let mut hi = [0u8; 3];
        for v in voxels {
            for a in 0..3 {
                lo[a] = lo[a].min(v.pos()[a]);
                hi[a] = hi[a].max(v.pos()[a]);
            }
        }
        RawNode {
            level,
            pos,
            child_mask,
            voxel_count: voxels.len() as u32,
            payload: zstd::bulk::compress(&block, zstd_level).unwrap(),
            block_crc32: crc32fast::hash(&block),
            bounds_min: lo,
            bounds_max: hi,
        }
    }
}

pub fn put(buf: &mut [u8], at: usize, bytes: &[u8]) {
    buf[at..at + bytes.len()].copy_from_slice(bytes);
}

/// File bytes assembled field by field from the offsets in `docs/FORMAT.md`.
pub fn assemble(
    resolution: u32,
    levels: u32,
    mode: u32,
    origin: [f64; 3],
    voxel_size: f64,
    nodes: &[RawNode],
    manifest: &[u8],
) -> Vec<u8> {
    let mut f = vec![0u8; 128];
    let mut index = Vec::new();
    let mut total = 0u64;
    for n in nodes {
        let mut e = [0u8; 64];
        put(&mut e, 0, &n.level.to_le_bytes());
        put(&mut e, 4, &n.pos[0].to_le_bytes());
        put(&mut e, 8, &n.pos[1].to_le_bytes());
        put(&mut e, 12, &n.pos[2].to_le_bytes());
        put(&mut e, 16, &n.voxel_count.to_le_bytes());
        put(&mut e, 20, &n.child_mask.to_le_bytes());
        put(&mut e, 24, &(f.len() as u64).to_le_bytes());
        put(&mut e, 32, &(n.payload.len() as u64).to_le_bytes());
        put(&mut e, 40, &crc32fast::hash(&n.payload).to_le_bytes());
        put(&mut e, 44, &n.block_crc32.to_le_bytes());
        put(&mut e, 48, &n.bounds_min);
        put(&mut e, 52, &n.bounds_max);
        index.extend_from_slice(&e);
        f.extend_from_slice(&n.payload);
        total += n.voxel_count as u64;
    }
    while f.len() % 8 != 0 {
        f.push(0);
    }
    let index_offset = f.len() as u64;
    f.extend_from_slice(&index);
    let manifest_offset = f.len() as u64;
    f.extend_from_slice(manifest);
    let mut h = [0u8; 128];
    put(&mut h, 0, b"VOXLOD\0\x01");
    put(&mut h, 8, &1u32.to_le_bytes());
    put(&mut h, 12, &128u32.to_le_bytes());
    put(&mut h, 16, &resolution.to_le_bytes());
    put(&mut h, 20, &levels.to_le_bytes());
    put(&mut h, 24, &mode.to_le_bytes());
    for a in 0..3 {
        put(&mut h, 32 + 8 * a, &origin[a].to_le_bytes());
    }
    put(&mut h, 56, &voxel_size.to_le_bytes());
    put(&mut h, 64, &(nodes.len() as u64).to_le_bytes());
    put(&mut h, 72, &index_offset.to_le_bytes());
    put(&mut h, 80, &(index.len() as u64).to_le_bytes());
    put(&mut h, 88, &manifest_offset.to_le_bytes());
    put(&mut h, 96, &(manifest.len() as u64).to_le_bytes());
    put(&mut h, 104, &total.to_le_bytes());
    put(&mut h, 112, &crc32fast::hash(&index).to_le_bytes());
    put(&mut h, 116, &crc32fast::hash(manifest).to_le_bytes());
    let crc = crc32fast::hash(&h[..124]);
    put(&mut h, 124, &crc.to_le_bytes());
    f[..128].copy_from_slice(&h);
    f
}

/// Recomputes the index, manifest and header checksums of file bytes `f` in place (to craft
/// files whose only fault is the one a test put in).
pub fn fix_crcs(f: &mut [u8]) {
    let rd = |f: &[u8], at: usize| u64::from_le_bytes(f[at..at + 8].try_into().unwrap()) as usize;
    let (io, is, mo, ms) = (rd(f, 72), rd(f, 80), rd(f, 88), rd(f, 96));
    if io.checked_add(is).is_some_and(|e| e <= f.len()) {
        let c = crc32fast::hash(&f[io..io + is]);
        put(f, 112, &c.to_le_bytes());
    }
    if mo.checked_add(ms).is_some_and(|e| e <= f.len()) {
        let c = crc32fast::hash(&f[mo..mo + ms]);
        put(f, 116, &c.to_le_bytes());
    }
    let c = crc32fast::hash(&f[..124]);
    put(f, 124, &c.to_le_bytes());
}

/// All levels of an octree from leaf voxels given by grid position (mask, normal, colour; at
/// most one per position), merged upwards by the sort-and-compact rule of docs/FORMAT.md.
/// `levels[l]` maps node positions to their voxels in Morton order.
pub fn build_levels(
    spec: &FileSpec,
    leaves: impl Iterator<Item = ([u32; 3], u8, u32, u32)>,
) -> Vec<BTreeMap<[u32; 3], Vec<Voxel>>> {
    let mut levels: Vec<BTreeMap<[u32; 3], Vec<Voxel>>> = vec![BTreeMap::new()];
    for (g, mask, normal, color) in leaves {
        let local = [g[0] as u8, g[1] as u8, g[2] as u8];
        levels[0]
            .entry([g[0] >> 8, g[1] >> 8, g[2] >> 8])
            .or_default()
            .push(Voxel::new(local, mask, normal, color));
    }
    for node in levels[0].values_mut() {
        node.sort_by_key(|v| v.morton());
    }
    for l in 1..spec.levels as usize {
        let mut parents: BTreeMap<[u32; 3], Vec<(u32, Voxel)>> = BTreeMap::new();
        for (c, vs) in &levels[l - 1] {
            for v in vs {
                // parent position = (octant·256 + child position) >> 1 per axis
                let p: [u8; 3] =
                    std::array::from_fn(|a| (((c[a] & 1) * 256 + v.pos()[a] as u32) >> 1) as u8);
                parents
                    .entry([c[0] >> 1, c[1] >> 1, c[2] >> 1])
                    .or_default()
                    .push((
                        morton8(p[0], p[1], p[2]),
                        Voxel::new(p, v.mask(), v.normal, v.color),
                    ));
            }
        }
        levels.push(
            parents
                .into_iter()
                .map(|(pos, vs)| (pos, compact(vs)))
                .collect(),
        );
    }
    levels
}

/// Sort-and-compact (docs/FORMAT.md, "Levels of detail"): voxels keyed by parent Morton code,
/// each run of equal codes becomes one voxel.
fn compact(mut vs: Vec<(u32, Voxel)>) -> Vec<Voxel> {
    vs.sort_by_key(|&(m, _)| m);
    let mut out = Vec::new();
    for run in vs.chunk_by(|a, b| a.0 == b.0) {
        let p = run[0].1.pos();
        let n = run.len() as u32;
        let mut mask = border_caps(p);
        let mut s = [0i32; 3];
        let mut c = [0u32; 4];
        for (_, v) in run {
            mask |= v.mask();
            let q = unpack_normal(v.normal);
            for a in 0..3 {
                s[a] += q[a];
            }
            for (k, x) in v.rgba().iter().enumerate() {
                c[k] += *x as u32;
            }
        }
        let normal = pack_normal([s[0] as f32, s[1] as f32, s[2] as f32]); // direction of the sum = of the mean
        let rgba = c.map(|x| ((x + n / 2) / n) as u8);
        out.push(Voxel::new(p, mask, normal, u32::from_le_bytes(rgba)));
    }
    out
}
