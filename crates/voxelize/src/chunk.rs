//! Voxelizing one 256³ chunk (Chajdas, Reitinger & Westermann, "Scalable rendering for very
//! large meshes", WSCG 2014, section 3) with the overlap tests of [`crate::overlap`] and
//! clipped-area weighted attributes ([`crate::clip`]).
//!
//! Memory is bounded by the chunk: a two-level slot index by Morton code (a table of the 32³
//! bricks of 8³ voxels, 128 KiB, and a 2 KiB block of slots per touched brick, allocated in
//! touch order so that one triangle's voxels stay in cache) and one accumulator per occupied
//! voxel. Global Morton code = brick Morton code · 512 + Morton code inside the brick.

use voxlod_format::voxel::{border_caps, face_mask, morton8, pack_color, pack_normal, Voxel};
use voxlod_geom::{demorton3, Triangle, CHUNK, TRI_HAS_NORMALS};

use crate::clip::{area_scale, triangle_area_centroid};
use crate::column::Columns;
use crate::overlap::{
    cross_f64, dominant_axis, interior_voxel, swizzle, to_f64, unswizzle, TriSetup,
};
use crate::{scanline, Method, Mode};

/// Bricks of 8³ voxels per chunk, slots per brick.
const BRICKS: usize = 32 * 32 * 32;
const BRICK: usize = 512;

/// Sums of one voxel's contributions, in f64 and in triangle order.
///
/// The unweighted sums `Σ n`, `Σ c` are only used if `Σ w = 0`, i.e. if every contribution has
/// zero weight, and then the weighted sums are all zero; so both share `s`: it holds the
/// unweighted sums while `w == 0` and restarts as the weighted sums with the first positive
/// weight (the zero-weight terms before it add only zeros to them). The averages are the same as
/// with separate sums (up to the sign of a zero sum, which encodes the same).
#[derive(Clone, Copy, Debug)]
struct Acc {
    /// Morton code of the in-chunk position.
    idx: u32,
    /// number of contributions
    k: u32,
    /// Σ w
    w: f64,
    /// `w > 0`: Σ w·n, Σ w·c; `w == 0`: Σ n, Σ c
    s: [f64; 7],
}

impl Acc {
    /// The sums after one contribution.
    #[inline]
    fn first(idx: u32, w: f64, n: [f64; 3], c: [f64; 4]) -> Acc {
        let f = if w > 0.0 { w } else { 1.0 };
        Acc {
            idx,
            k: 1,
            w: 0.0 + w,
            s: [
                0.0 + f * n[0],
                0.0 + f * n[1],
                0.0 + f * n[2],
                0.0 + f * c[0],
                0.0 + f * c[1],
                0.0 + f * c[2],
                0.0 + f * c[3],
            ],
        }
    }

    #[inline]
    fn add(&mut self, w: f64, n: [f64; 3], c: [f64; 4]) {
        self.k += 1;
        let x = [n[0], n[1], n[2], c[0], c[1], c[2], c[3]];
        if self.w > 0.0 {
            self.w += w;
            for (s, x) in self.s.iter_mut().zip(x) {
                *s += w * x;
            }
        } else if w > 0.0 {
            // the first positive weight: the weighted sums so far are zero
            self.w += w;
            for (s, x) in self.s.iter_mut().zip(x) {
                *s = 0.0 + w * x;
            }
        } else {
            for (s, x) in self.s.iter_mut().zip(x) {
                *s += x;
            }
        }
    }
}

/// Per-triangle attribute interpolation: barycentrics at a point, vertex normals / colours.
struct Attrs {
    v0: [f64; 3],
    e1: [f64; 3],
    e2: [f64; 3],
    n: [f64; 3],
    inv_nn: f64,
    face: [f64; 3],
    vn: Option<[[f64; 3]; 3]>,
    vc: [[f64; 4]; 3],
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Attrs {
    fn new(t: &Triangle) -> Attrs {
        let v = to_f64(&t.v);
        let e1 = sub(v[1], v[0]);
        let e2 = sub(v[2], v[0]);
        let n = cross(e1, e2);
        let nn = dot(n, n);
        let len = nn.sqrt();
        let face = [n[0] / len, n[1] / len, n[2] / len];
        let vn = (t.flags & TRI_HAS_NORMALS != 0).then(|| t.n.map(|q| q.map(|c| c as f64)));
        let vc = t.c.map(|q| q.map(|c| c as f64));
        Attrs {
            v0: v[0],
            e1,
            e2,
            n,
            inv_nn: 1.0 / nn,
            face,
            vn,
            vc,
        }
    }

    /// (normal, colour) at point `q` of the triangle's plane.
    #[inline]
    fn at(&self, q: [f64; 3]) -> ([f64; 3], [f64; 4]) {
        let d = sub(q, self.v0);
        let l1 = dot(cross(d, self.e2), self.n) * self.inv_nn;
        let l2 = dot(cross(self.e1, d), self.n) * self.inv_nn;
        let l = [1.0 - l1 - l2, l1, l2];
        let normal = match &self.vn {
            Some(vn) => {
                let m = [0, 1, 2].map(|k| l[0] * vn[0][k] + l[1] * vn[1][k] + l[2] * vn[2][k]);
                let len = dot(m, m).sqrt();
                if len > 0.0 && len.is_finite() {
                    [m[0] / len, m[1] / len, m[2] / len]
                } else {
                    self.face
                }
            }
            None => self.face,
        };
        let c = &self.vc;
        let colour = [0, 1, 2, 3].map(|k| l[0] * c[0][k] + l[1] * c[1][k] + l[2] * c[2][k]);
        (normal, colour)
    }
}

/// Reusable per-thread chunk voxelizer; see the crate docs for the attribute rules.
pub struct ChunkVoxelizer {
    mode: Mode,
    origin: [u32; 3],
    /// block + 1 of each brick (`morton >> 9`), 0 = none yet
    bricks: Vec<u32>,
    /// per touched brick, slot + 1 of each voxel (`morton & 511`), 0 = empty
    blocks: Vec<u32>,
    acc: Vec<Acc>,
    skipped: u64,
    /// the column clipping state, reused from triangle to triangle
    cols: Columns,
    /// how each triangle's voxels are found
    method: Method,
}

impl ChunkVoxelizer {
    /// A voxelizer for `mode`.
    pub fn new(mode: Mode) -> Self {
        ChunkVoxelizer {
            mode,
            origin: [0; 3],
            bricks: vec![0u32; BRICKS],
            blocks: Vec::new(),
            acc: Vec::new(),
            skipped: 0,
            cols: Columns::idle(true),
            method: Method::default(),
        }
    }

    /// How each triangle's voxels are found ([`Method::default`] unless set). The exact methods
    /// give the same voxels in the same order, so the same records.
    ///
    /// # Panics
    /// If `method` does not support the voxelizer's mode ([`Method::supports`]).
    pub fn set_method(&mut self, method: Method) {
        assert!(
            method.supports(self.mode),
            "voxelizer {method} does not support {} mode",
            self.mode
        );
        self.method = method;
    }

    /// The method set with [`ChunkVoxelizer::set_method`].
    pub fn method(&self) -> Method {
        self.method
    }

    /// For tests and benchmarks: `false` computes every weight by the general clipping of
    /// [`crate::clipped_area`] (bit-identical to it), `true` (the default) uses the closed forms
    /// of [`crate::column`](mod@crate::column) where they apply (equal up to rounding, so
    /// the records are equal except where opposite normals cancel; see the crate docs).
    pub fn set_fast_paths(&mut self, on: bool) {
        self.cols = Columns::idle(on);
    }

    /// The voxelization mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Start a chunk whose minimum voxel corner is `origin` (grid coordinates, multiples of 256).
    /// Discards anything added since the last `finish`.
    pub fn begin(&mut self, origin: [u32; 3]) {
        debug_assert!(
            origin.iter().all(|c| c % CHUNK == 0),
            "chunk origin {origin:?} not a multiple of 256"
        );
        self.reset();
        self.origin = origin;
    }

    fn reset(&mut self) {
        for a in &self.acc {
            self.bricks[(a.idx >> 9) as usize] = 0;
        }
        self.blocks.clear();
        self.acc.clear();
    }

    /// Add triangles in grid coordinates. Each is clipped to the chunk (voxel range clamped to
    /// `[origin, origin+255]`). Zero-area and non-finite triangles are skipped and counted.
    pub fn add(&mut self, tris: &[Triangle]) {
        let o = self.origin.map(|c| c as i64);
        let lo = o.map(|c| c.min(i32::MAX as i64) as i32);
        let hi = o.map(|c| (c + CHUNK as i64 - 1).min(i32::MAX as i64) as i32);
        for t in tris {
            // a triangle inside one voxel's interior (most of a scan's): that voxel, the whole
            // triangle's area and centroid, no overlap test, no clipping
            if self.mode == Mode::Conservative {
                if let Some(p) = interior_voxel(&t.v) {
                    if (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]) && self.add_interior(t, p) {
                        continue;
                    }
                }
            }
            let Some(s) = TriSetup::new(&t.v, self.mode) else {
                self.skipped += 1;
                continue;
            };
            let lo_s = s.swizzle(lo);
            let hi_s = s.swizzle(hi);
            if (0..3).any(|k| s.bmax[k] < lo_s[k] || s.bmin[k] > hi_s[k]) {
                continue;
            }
            let attrs = Attrs::new(t);
            let tri_centroid =
                [0, 1, 2].map(|k| (t.v[0][k] as f64 + t.v[1][k] as f64 + t.v[2][k] as f64) / 3.0);
            let cols = &mut self.cols;
            cols.set(&s);
            let bricks = &mut self.bricks;
            let blocks = &mut self.blocks;
            let acc = &mut self.acc;
            let each = |p: [i32; 3], first: bool| {
                if first {
                    cols.begin(p[0] as f64, p[1] as f64);
                }
                let (w, c) = cols.voxel(p[2] as f64);
                let q = match c {
                    Some(c) => s.unswizzle(c),
                    None => tri_centroid,
                };
                let (n, col) = attrs.at(q);
                let g = s.unswizzle(p);
                let local = [0, 1, 2].map(|k| (g[k] as i64 - o[k]) as u32);
                debug_assert!(local.iter().all(|&c| c < CHUNK));
                let idx = morton8(local[0] as u8, local[1] as u8, local[2] as u8);
                accumulate(bricks, blocks, acc, idx, w, n, col);
            };
            match self.method {
                Method::Sat => s.scan(lo_s, hi_s, each),
                Method::Scanline => scanline::scan(&s, lo_s, hi_s, each),
                Method::ScanlineIlv => scanline::scan_ilv(&s, lo_s, hi_s, each),
            }
        }
    }

    /// [`ChunkVoxelizer::add`] for a triangle inside the interior of voxel `p` (grid coordinates,
    /// inside this chunk): the same contribution as the general path, bit for bit (its Triangle
    /// column in one voxel: [`triangle_area_centroid`] of the swizzled triangle). `false` (and
    /// nothing added) for a triangle that the general path skips (zero or non-finite normal).
    #[inline]
    fn add_interior(&mut self, t: &Triangle, p: [i32; 3]) -> bool {
        let o = to_f64(&t.v);
        let n = cross_f64(&o);
        if n == [0.0; 3] || !n.iter().all(|c| c.is_finite()) {
            return false;
        }
        let swz = swizzle(dominant_axis(n));
        let sw = |q: [f64; 3]| [q[swz[0]], q[swz[1]], q[swz[2]]];
        let (w, c) = triangle_area_centroid(&[sw(o[0]), sw(o[1]), sw(o[2])], area_scale(sw(n)));
        let (normal, col) = Attrs::new(t).at(unswizzle(swz, c));
        let local = [0, 1, 2].map(|k| (p[k] as i64 - self.origin[k] as i64) as u32);
        debug_assert!(local.iter().all(|&c| c < CHUNK));
        let idx = morton8(local[0] as u8, local[1] as u8, local[2] as u8);
        accumulate(
            &mut self.bricks,
            &mut self.blocks,
            &mut self.acc,
            idx,
            w,
            normal,
            col,
        );
        true
    }

    /// Finish the chunk: encoded voxels sorted by the Morton code of their in-chunk position,
    /// with normal, colour and face mask. Resets for the next `begin`.
    pub fn finish(&mut self) -> Vec<Voxel> {
        // encode in slot order (sequential), then sort (Morton code, slot) keys by radix and
        // gather: no comparison sort, no random access into the large accumulators
        let enc: Vec<Voxel> = self.acc.iter().map(encode).collect();
        let mut keys: Vec<u64> = self
            .acc
            .iter()
            .enumerate()
            .map(|(i, a)| (a.idx as u64) << 32 | i as u64)
            .collect();
        radix_sort_morton(&mut keys);
        let out = keys
            .iter()
            .map(|&k| enc[(k & 0xffff_ffff) as usize])
            .collect();
        self.reset();
        out
    }

    /// Triangles skipped (zero area or non-finite) since this voxelizer was made.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }
}

/// Adds one contribution to the voxel with in-chunk Morton code `idx`, making its slot (and its
/// brick's block of slots) on first touch.
#[inline]
fn accumulate(
    bricks: &mut [u32],
    blocks: &mut Vec<u32>,
    acc: &mut Vec<Acc>,
    idx: u32,
    w: f64,
    n: [f64; 3],
    c: [f64; 4],
) {
    let b = &mut bricks[(idx >> 9) as usize];
    if *b == 0 {
        blocks.resize(blocks.len() + BRICK, 0);
        *b = (blocks.len() / BRICK) as u32;
    }
    let sl = &mut blocks[(*b as usize - 1) * BRICK + (idx as usize & (BRICK - 1))];
    if *sl == 0 {
        acc.push(Acc::first(idx, w, n, c));
        *sl = acc.len() as u32;
    } else {
        acc[*sl as usize - 1].add(w, n, c);
    }
}

/// The voxel record of an accumulator: area-weighted means, or unweighted means if Σ w = 0.
#[inline]
fn encode(a: &Acc) -> Voxel {
    let pos = demorton3(a.idx as u64).map(|c| c as u8);
    let d = if a.w > 0.0 { a.w } else { a.k as f64 };
    let s = &a.s;
    let normal = pack_normal([(s[0] / d) as f32, (s[1] / d) as f32, (s[2] / d) as f32]);
    let mask = face_mask(normal) | border_caps(pos);
    let c = |k: usize| (s[k] / d).round().clamp(0.0, 255.0) as u8;
    Voxel::new(pos, mask, normal, pack_color([c(3), c(4), c(5), c(6)]))
}

/// Sorts keys `morton << 32 | slot` by their 24-bit Morton code (LSD radix, three 8-bit
/// digits); Morton codes are unique within a chunk, so this is the order of a full sort.
fn radix_sort_morton(keys: &mut Vec<u64>) {
    if keys.len() < 64 {
        keys.sort_unstable();
        return;
    }
    let mut tmp = vec![0u64; keys.len()];
    for shift in [32u32, 40, 48] {
        let mut count = [0usize; 257];
        for &k in keys.iter() {
            count[((k >> shift) & 0xff) as usize + 1] += 1;
        }
        for i in 0..256 {
            count[i + 1] += count[i];
        }
        for &k in keys.iter() {
            let d = ((k >> shift) & 0xff) as usize;
            tmp[count[d]] = k;
            count[d] += 1;
        }
        std::mem::swap(keys, &mut tmp);
    }
}
