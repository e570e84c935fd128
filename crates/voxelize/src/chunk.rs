//! Voxelizing one 256³ chunk (Chajdas, Reitinger & Westermann, "Scalable rendering for very
//! large meshes", WSCG 2014, section 3) with the overlap tests of [`crate::overlap`] and
//! clipped-area weighted attributes ([`crate::clip`]).
//!
//! Memory is bounded by the chunk: a two-level slot index by Morton code (a table of the 32³
//! bricks of 8³ voxels, 128 KiB, and a 2 KiB block of slots per touched brick, allocated in
//! touch order so that one triangle's voxels stay in cache) and one accumulator per occupied
//! voxel. Global Morton code = brick Morton code · 512 + Morton code inside the brick.

use std::sync::Arc;
use voxlod_format::voxel::{
    border_caps, face_mask, morton8, pack_color, pack_normal_f64, Voxel, NORMAL_SCALE,
};
use voxlod_geom::{demorton3, Triangle, CHUNK, TRI_HAS_NORMALS};
use voxlod_texture::{linear_to_srgb, TextureSet};

use crate::column::Columns;
use crate::material::MaterialSums;
use crate::overlap::{cross_f64, interior_voxel, to_f64, TriSetup};
use crate::texcolor::{linear_color, TexAt};
use crate::{scanline, Method, Mode};

/// Bricks of 8³ voxels per chunk, slots per brick.
const BRICKS: usize = 32 * 32 * 32;
const BRICK: usize = 512;

/// The sums of one voxel: `s = [Σ w·n_x, Σ w·n_y, Σ w·n_z, Σ w, Σ w·r, Σ w·g, Σ w·b, Σ w·a]`
/// in f32, in triangle order, and the number of contributions `k`.
///
/// The unweighted sums `Σ n`, `Σ c` are only used if `Σ w = 0`, i.e. if every contribution has
/// zero weight, and then the weighted sums are all zero; so both share `s`: it holds the
/// unweighted sums (and `s[3] = 0`) while no weight was positive and restarts as the weighted
/// sums with the first positive weight (zero-weight terms add nothing to weighted sums).
///
/// **Error bound** (Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed., §4.2,
/// recursive summation). Let `u = 2⁻²⁴` and `γ_m = m·u/(1 − m·u)`. Each term `w·x` is formed
/// from `w` and `x` rounded to f32 and one f32 product, so it carries a relative error of at
/// most `γ_3` (`x` itself is evaluated in f64, whose error is negligible here); the `k − 1`
/// additions add `γ_{k−1}`. Hence every sum satisfies `|Ŝ − S| ≤ γ_{k+2} · Σ |terms|`, with
/// `S` the exact sum of the f64 terms. The terms of `W` and of the colour sums are
/// non-negative, and `|n_j| ≤ 1`, so with `K = k + 2`:
/// * `|Ŵ − W| ≤ γ_K·W` and `|Ĉ_j − C_j| ≤ γ_K·C_j`: the mean colour `C/W ∈ [0, 255]` is off by
///   at most `255·2γ_K/(1 − γ_K)` (0.13 for `k ≤ 4094`, 3.1e-5·K in general), plus the f32
///   division of the encoding (`255·u`); so below `k = 4094` the rounded colour is within one
///   unit of the one from exact sums;
/// * `|N̂_j − N_j| ≤ γ_K·W`, so the direction `N/|N|` moves by at most `2√3·γ_K·W/|N|` per
///   component, less than one 10-bit step (1/511) whenever `|N|/W ≥ 1022·√3·γ_K`, about
///   `1.06e-4·K`: everywhere except where the contributions' normals nearly cancel (opposite
///   faces in one voxel), where the direction is rounding noise in any precision.
///
/// `tests/attributes.rs` checks these bounds against sums of the f64 reference
/// ([`crate::clipped_area`] and the barycentric interpolation of the crate docs).
#[derive(Clone, Copy, Debug)]
struct Acc {
    s: [f32; 8],
    /// Morton code of the in-chunk position
    idx: u32,
    k: u32,
}

impl Acc {
    /// The sums after one contribution of weight `w` and values `x` (`x[3] = 1`).
    #[inline]
    fn first(idx: u32, w: f32, x: [f32; 8]) -> Acc {
        if w > 0.0 {
            Acc {
                s: x.map(|v| w * v),
                idx,
                k: 1,
            }
        } else {
            let mut s = x;
            s[3] = 0.0;
            Acc { s, idx, k: 1 }
        }
    }

    #[inline]
    fn add(&mut self, w: f32, x: [f32; 8]) {
        self.k += 1;
        if self.s[3] > 0.0 {
            if w > 0.0 {
                for (s, v) in self.s.iter_mut().zip(x) {
                    *s += w * v;
                }
            }
        } else if w > 0.0 {
            // the first positive weight: the weighted sums so far are zero
            self.s = x.map(|v| w * v);
        } else {
            for (s, v) in self.s.iter_mut().zip(x) {
                *s += v;
            }
            self.s[3] = 0.0;
        }
    }
}

/// Per-triangle attribute interpolation (see the crate docs): the barycentrics are affine in
/// the point, and every interpolation point lies in the triangle's plane, so each attribute is
/// an affine function of the point's swizzled `(x, y)`, the dominant projection:
/// `a(q) = a₀ + g_x·(q_x − v0_x) + g_y·(q_y − v0_y)` with per-triangle gradients. This equals
/// `Σ λ_k a_k` with the crate docs' barycentrics up to rounding (relative 1e-15 for a
/// non-degenerate triangle: `|n_z| ≥ |n|/√3` on the dominant axis).
struct Interp<'a> {
    o: [f64; 2],
    /// colours (r, g, b, a) at v0 and their gradients
    c0: [f64; 4],
    cx: [f64; 4],
    cy: [f64; 4],
    /// vertex normals (unswizzled) at v0 and their gradients, if the triangle has them
    vn: Option<[[f64; 3]; 3]>,
    /// unit face normal `n/|n|` (unswizzled, sign of the winding)
    face: [f64; 3],
    /// the swizzled `(x, y)` of the triangle's centroid (the point of an empty part)
    centroid: [f64; 2],
    /// a build with textures: colours in linear light ([`crate::texcolor`]), and this
    /// triangle's texture if it has one
    linear: bool,
    tex: Option<TexAt<'a>>,
}

impl<'a> Interp<'a> {
    fn new(t: &Triangle, s: &TriSetup, textures: Option<&'a TextureSet>) -> Interp<'a> {
        let [p0, p1, p2] = s.v;
        let e1 = [p1[0] - p0[0], p1[1] - p0[1]];
        let e2 = [p2[0] - p0[0], p2[1] - p0[1]];
        // the dominant projection's signed doubled area: never 0 for a triangle TriSetup took
        let inv = 1.0 / (e1[0] * e2[1] - e1[1] * e2[0]);
        // a(d) = a0 + (a1 − a0)·λ1 + (a2 − a0)·λ2, λ1 = (d×e2)_z/det, λ2 = (e1×d)_z/det
        let grad = |a: [f64; 3]| {
            let (d1, d2) = (a[1] - a[0], a[2] - a[0]);
            (
                (d1 * e2[1] - d2 * e1[1]) * inv,
                (d2 * e1[0] - d1 * e2[0]) * inv,
            )
        };
        let mut c0 = [0.0; 4];
        let mut cx = [0.0; 4];
        let mut cy = [0.0; 4];
        for k in 0..4 {
            let a = [0, 1, 2].map(|i| t.c[i][k] as f64);
            c0[k] = a[0];
            (cx[k], cy[k]) = grad(a);
        }
        let vn = (t.flags & TRI_HAS_NORMALS != 0).then(|| {
            let (mut a0, mut gx, mut gy) = ([0.0; 3], [0.0; 3], [0.0; 3]);
            for k in 0..3 {
                let a = [0, 1, 2].map(|i| t.n[i][k] as f64);
                a0[k] = a[0];
                (gx[k], gy[k]) = grad(a);
            }
            [a0, gx, gy]
        });
        let n = cross_f64(&to_f64(&t.v));
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let face = n.map(|c| c / len);
        let centroid = [0, 1].map(|k| (p0[k] + p1[k] + p2[k]) / 3.0);
        let tex = textures.and_then(|set| TexAt::new(t, set, grad, len));
        Interp {
            o: [p0[0], p0[1]],
            c0,
            cx,
            cy,
            vn,
            face,
            centroid,
            linear: textures.is_some(),
            tex,
        }
    }

    /// The accumulated values `[n_x, n_y, n_z, 1, r, g, b, a]` at the swizzled point `(x, y)`
    /// of a part of `w` voxel².
    #[inline]
    fn at(&self, x: f64, y: f64, w: f64) -> [f32; 8] {
        let (dx, dy) = (x - self.o[0], y - self.o[1]);
        let normal = match &self.vn {
            Some([a, gx, gy]) => {
                let m = [
                    a[0] + gx[0] * dx + gy[0] * dy,
                    a[1] + gx[1] * dx + gy[1] * dy,
                    a[2] + gx[2] * dx + gy[2] * dy,
                ];
                unit_or(m, self.face)
            }
            None => self.face,
        };
        // written out: `[0, 1, 2, 3].map(..)` here compiled to a call (core's try_map, 2–3 %
        // of a build's profile)
        let (c0, cx, cy) = (&self.c0, &self.cx, &self.cy);
        let mut c = [
            c0[0] + cx[0] * dx + cy[0] * dy,
            c0[1] + cx[1] * dx + cy[1] * dy,
            c0[2] + cx[2] * dx + cy[2] * dy,
            c0[3] + cx[3] * dx + cy[3] * dy,
        ];
        if self.linear {
            c = linear_color(c, self.tex.as_ref().map(|t| t.sample(dx, dy, w)));
        }
        values(normal, c)
    }
}

/// `m / |m|`, or `fallback` if that is zero or not finite.
#[inline]
fn unit_or(m: [f64; 3], fallback: [f64; 3]) -> [f64; 3] {
    let len = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
    if len > 0.0 && len.is_finite() {
        let inv = 1.0 / len;
        m.map(|c| c * inv)
    } else {
        fallback
    }
}

#[inline]
fn values(n: [f64; 3], c: [f64; 4]) -> [f32; 8] {
    [
        n[0] as f32,
        n[1] as f32,
        n[2] as f32,
        1.0,
        c[0] as f32,
        c[1] as f32,
        c[2] as f32,
        c[3] as f32,
    ]
}

/// The unencoded sums of one voxel ([`ChunkVoxelizer::finish_sums`]): position in the chunk,
/// number of contributions `k`, and in f32 `w = Σ w_i`, `n = Σ w_i·normal_i`,
/// `c = Σ w_i·colour_i`; if `w == 0` (every weight zero), `n` and `c` are the unweighted sums.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VoxelSums {
    /// Position in the chunk.
    pub pos: [u8; 3],
    /// Number of contributions.
    pub k: u32,
    /// `Σ w_i`, the summed clipped areas.
    pub w: f32,
    /// `Σ w_i·normal_i`.
    pub n: [f32; 3],
    /// `Σ w_i·colour_i` (RGBA, 0–255 scale).
    pub c: [f32; 4],
}

/// Reusable per-thread chunk voxelizer; see the crate docs for the attribute rules.
pub struct ChunkVoxelizer {
    mode: Mode,
    origin: [u32; 3],
    /// block + 1 of each brick (`morton >> 9`), 0 = none yet
    bricks: Vec<u32>,
    /// per touched brick, slot + 1 of each voxel (`morton & 511`), 0 = empty
    blocks: Vec<u32>,
    /// per touched brick: its brick index and the occupancy bits of its 512 voxels
    touched: Vec<(u32, [u64; 8])>,
    acc: Vec<Acc>,
    /// the encoded normal and colour words of `acc` ([`encode_words`]), reused by `finish`
    words: Vec<[u32; 2]>,
    skipped: u64,
    /// the column clipping state, reused from triangle to triangle
    cols: Columns,
    /// how each triangle's voxels are found
    method: Method,
    /// the build's textures: colours from them, averaged in linear light
    textures: Option<Arc<TextureSet>>,
    /// per-voxel material weights ([`crate::material`]), only for meshes with materials
    materials: Option<MaterialSums>,
    /// the last finished chunk's per-voxel materials, in voxel order
    finished_materials: Option<Vec<u32>>,
}

impl ChunkVoxelizer {
    /// A voxelizer for `mode`.
    pub fn new(mode: Mode) -> Self {
        ChunkVoxelizer {
            mode,
            origin: [0; 3],
            bricks: vec![0u32; BRICKS],
            blocks: Vec::new(),
            touched: Vec::new(),
            acc: Vec::new(),
            words: Vec::new(),
            skipped: 0,
            cols: Columns::idle(true),
            method: Method::default(),
            textures: None,
            materials: None,
            finished_materials: None,
        }
    }

    /// With `true`, each voxel also gets a material ([`crate::material`]: the largest summed
    /// area of its triangles' [`Triangle::material`]), taken after
    /// [`finish`](Self::finish) by [`take_materials`](Self::take_materials). Off by default
    /// (a mesh with at most one material): then nothing is accumulated.
    pub fn set_materials(&mut self, on: bool) {
        self.materials = on.then(MaterialSums::new);
    }

    /// The per-voxel material ids of the chunk the last [`finish`](Self::finish) returned, in
    /// the same order; `None` unless [`set_materials`](Self::set_materials) is on.
    pub fn take_materials(&mut self) -> Option<Vec<u32>> {
        self.finished_materials.take()
    }

    /// The textures of the mesh's materials ([`voxlod_texture::TextureSet`], indexed by
    /// [`Triangle::material`]). With `Some`, colours are accumulated in linear light and
    /// stored sRGB-encoded, textured triangles modulating their colour by their texture
    /// ([`crate::texcolor`]); with `None` (the default) colours are averaged as stored.
    pub fn set_textures(&mut self, textures: Option<Arc<TextureSet>>) {
        self.textures = textures;
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
    /// of [`crate::column`](mod@crate::column) where they apply (equal up to rounding).
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
        for &(b, _) in &self.touched {
            self.bricks[b as usize] = 0;
        }
        self.touched.clear();
        self.blocks.clear();
        self.acc.clear();
        if let Some(m) = &mut self.materials {
            m.clear();
        }
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
            let ip = Interp::new(t, &s, self.textures.as_deref());
            let cols = &mut self.cols;
            cols.set(&s);
            let mut sink = Sink {
                bricks: &mut self.bricks,
                blocks: &mut self.blocks,
                touched: &mut self.touched,
                acc: &mut self.acc,
                mats: self
                    .materials
                    .as_mut()
                    .map(|m| m.set_triangle(t.material())),
            };
            let each = |p: [i32; 3], first: bool| {
                if first {
                    // x and y one at a time: the scans store them one at a time, and the one
                    // 8-byte load the compiler makes of both fails store-to-load forwarding
                    // (≈ 2 % of the dragon's voxelize profile); black_box keeps them apart
                    let x = std::hint::black_box(p[0]);
                    cols.begin(x as f64, p[1] as f64);
                }
                let (w, c) = cols.voxel(p[2] as f64);
                let q = match c {
                    Some(c) => [c[0], c[1]],
                    None => ip.centroid,
                };
                let x = ip.at(q[0], q[1], w);
                let g = s.unswizzle(p);
                let local = [0, 1, 2].map(|k| (g[k] as i64 - o[k]) as u32);
                debug_assert!(local.iter().all(|&c| c < CHUNK));
                sink.add(local, w as f32, x);
            };
            match self.method {
                Method::Sat => s.scan(lo_s, hi_s, each),
                Method::Scanline => scanline::scan(&s, lo_s, hi_s, each),
                Method::ScanlineIlv => scanline::scan_ilv(&s, lo_s, hi_s, each),
            }
        }
    }

    /// [`ChunkVoxelizer::add`] for a triangle inside the interior of voxel `p` (grid coordinates,
    /// inside this chunk): the whole triangle, weight = its area `|n|/2`, interpolation point =
    /// its centroid, where the barycentrics are all 1/3 (so the normal is the normalized sum of
    /// the vertex normals and the colour the mean vertex colour); the same contribution as the
    /// general path up to rounding. `false` (and nothing added) for a triangle that the general
    /// path skips (zero or non-finite normal).
    #[inline]
    fn add_interior(&mut self, t: &Triangle, p: [i32; 3]) -> bool {
        let n = cross_f64(&to_f64(&t.v));
        let nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
        if !(nn > 0.0 && nn.is_finite()) {
            return false;
        }
        let len = nn.sqrt();
        let inv = 1.0 / len;
        let face = n.map(|c| c * inv);
        let normal = if t.flags & TRI_HAS_NORMALS != 0 {
            let m = [0, 1, 2].map(|k| t.n[0][k] as f64 + t.n[1][k] as f64 + t.n[2][k] as f64);
            unit_or(m, face)
        } else {
            face
        };
        let mut c = [0, 1, 2, 3]
            .map(|k| (t.c[0][k] as u32 + t.c[1][k] as u32 + t.c[2][k] as u32) as f64 / 3.0);
        if let Some(set) = self.textures.as_deref() {
            c = linear_color(c, TexAt::centroid(t, set, len));
        }
        let local = [0, 1, 2].map(|k| (p[k] as i64 - self.origin[k] as i64) as u32);
        debug_assert!(local.iter().all(|&c| c < CHUNK));
        Sink {
            bricks: &mut self.bricks,
            blocks: &mut self.blocks,
            touched: &mut self.touched,
            acc: &mut self.acc,
            mats: self
                .materials
                .as_mut()
                .map(|m| m.set_triangle(t.material())),
        }
        .add(local, (0.5 * len) as f32, values(normal, c));
        true
    }

    /// Finish the chunk: encoded voxels sorted by the Morton code of their in-chunk position,
    /// with normal, colour and face mask. Resets for the next `begin`.
    ///
    /// The accumulators are encoded in the order they were made (a sequential read) and each
    /// record is stored at its rank in Morton order, which the occupancy bits give without a
    /// sort: the voxels of the bricks before its brick (in Morton order) plus those before it
    /// in its brick.
    pub fn finish(&mut self) -> Vec<Voxel> {
        let mut out = vec![Voxel::default(); self.acc.len()];
        // per accumulator (made in slot order: `ranked` passes it as `i`) its material
        let winners: Option<Vec<u32>> = self
            .materials
            .as_ref()
            .map(|m| (0..m.len()).map(|i| m.winner(i)).collect());
        let mut mats = vec![0u32; winners.as_ref().map_or(0, Vec::len)];
        if self.textures.is_some() {
            self.ranked(|r, i, pos, a| {
                out[r] = encode(pos, a, true);
                if let Some(w) = &winners {
                    mats[r] = w[i];
                }
            });
        } else {
            let mut words = std::mem::take(&mut self.words);
            encode_words(&self.acc, &mut words);
            self.ranked(|r, i, pos, _| {
                let [normal, color] = words[i];
                let mask = face_mask(normal) | border_caps(pos);
                out[r] = Voxel::new(pos, mask, normal, color);
                if let Some(w) = &winners {
                    mats[r] = w[i];
                }
            });
            self.words = words;
        }
        self.finished_materials = winners.map(|_| mats);
        out
    }

    /// [`ChunkVoxelizer::finish`] without the encoding: the sums of each voxel, in the same
    /// order (for tests of the accumulation against an exact reference, and diagnostics).
    pub fn finish_sums(&mut self) -> Vec<VoxelSums> {
        let mut out = vec![VoxelSums::default(); self.acc.len()];
        self.ranked(|r, _, pos, a| {
            out[r] = VoxelSums {
                pos,
                k: a.k,
                w: a.s[3],
                n: [a.s[0], a.s[1], a.s[2]],
                c: [a.s[4], a.s[5], a.s[6], a.s[7]],
            }
        });
        out
    }

    /// Calls `f(rank, index, position, sums)` for every accumulator, in the order they were made
    /// (`index`), with its rank in Morton order; then resets.
    #[inline]
    fn ranked(&mut self, mut f: impl FnMut(usize, usize, [u8; 3], &Acc)) {
        let mut order: Vec<(u32, u32)> = self
            .touched
            .iter()
            .enumerate()
            .map(|(i, &(b, _))| (b, i as u32))
            .collect();
        order.sort_unstable();
        // rank of the first voxel of each occupancy word of each touched brick
        let mut first = vec![[0u32; 8]; self.touched.len()];
        let mut rank = 0u32;
        for &(_, i) in &order {
            let occ = &self.touched[i as usize].1;
            for (f, w) in first[i as usize].iter_mut().zip(occ) {
                *f = rank;
                rank += w.count_ones();
            }
        }
        debug_assert_eq!(rank as usize, self.acc.len());
        for (i, a) in self.acc.iter().enumerate() {
            let b = self.bricks[(a.idx >> 9) as usize] as usize - 1;
            let v = a.idx as usize & (BRICK - 1);
            let below = self.touched[b].1[v >> 6] & ((1u64 << (v & 63)) - 1);
            let r = first[b][v >> 6] + below.count_ones();
            let pos = demorton3(a.idx as u64).map(|c| c as u8);
            f(r as usize, i, pos, a);
        }
        self.reset();
    }

    /// Triangles skipped (zero area or non-finite) since this voxelizer was made.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }
}

/// The slot index and accumulators, borrowed apart from the column state.
struct Sink<'a> {
    bricks: &'a mut [u32],
    blocks: &'a mut Vec<u32>,
    touched: &'a mut Vec<(u32, [u64; 8])>,
    acc: &'a mut Vec<Acc>,
    /// the material hook: weights per voxel slot, if the mesh has materials
    mats: Option<&'a mut MaterialSums>,
}

impl Sink<'_> {
    /// Adds one contribution to the voxel at in-chunk position `local`, making its slot (and
    /// its brick's block of slots) on first touch.
    #[inline]
    fn add(&mut self, local: [u32; 3], w: f32, x: [f32; 8]) {
        let idx = morton8(local[0] as u8, local[1] as u8, local[2] as u8);
        let bi = (idx >> 9) as usize;
        let mut b = self.bricks[bi] as usize;
        if b == 0 {
            self.blocks.resize(self.blocks.len() + BRICK, 0);
            self.touched.push((bi as u32, [0; 8]));
            b = self.touched.len();
            self.bricks[bi] = b as u32;
        }
        let v = idx as usize & (BRICK - 1);
        let sl = &mut self.blocks[(b - 1) * BRICK + v];
        if *sl == 0 {
            self.acc.push(Acc::first(idx, w, x));
            *sl = self.acc.len() as u32;
            self.touched[b - 1].1[v >> 6] |= 1 << (v & 63);
        } else {
            self.acc[*sl as usize - 1].add(w, x);
        }
        if let Some(m) = self.mats.as_deref_mut() {
            m.add(*sl as usize - 1, w);
        }
    }
}

/// The voxel record of an accumulator: area-weighted means, or unweighted means if `Σ w = 0`;
/// `linear`: the colour sums are in linear light and the mean is sRGB-encoded.
/// The normal is packed from the sum itself (packing normalizes, and `N / W` has the direction
/// of `N`), in f64 so that tiny sums neither underflow nor lose digits.
#[inline]
fn encode(pos: [u8; 3], a: &Acc, linear: bool) -> Voxel {
    let s = &a.s;
    let normal = pack_normal_f64([s[0] as f64, s[1] as f64, s[2] as f64]);
    let mask = face_mask(normal) | border_caps(pos);
    let inv = 1.0 / if s[3] > 0.0 { s[3] } else { a.k as f32 };
    let c = |k: usize| {
        let m = s[k] * inv;
        let m = if linear && k < 7 {
            linear_to_srgb(m / 255.0) * 255.0
        } else {
            m
        };
        m.round().clamp(0.0, 255.0) as u8
    };
    Voxel::new(pos, mask, normal, pack_color([c(4), c(5), c(6), c(7)]))
}

/// Voxels per batch of [`encode_words`].
const LANES: usize = 64;

/// The normal and colour words of [`encode`] (plain colours, `linear == false`) for every
/// accumulator of `acc`, in order, bit for bit, into `out` (cleared first).
///
/// The sums are transposed into batches of [`LANES`] voxels and each word is computed by a loop
/// without branches, so that the compiler runs the square roots, divisions, roundings and
/// conversions in SIMD lanes (each is correctly rounded per lane, so the bits are those of the
/// scalar [`encode`]; `tests` below compares the two). A zero or non-finite normal sum computes
/// garbage in its lane (NaN, saturating conversions) and is then replaced by 0, as
/// [`pack_normal_f64`] returns.
fn encode_words(acc: &[Acc], out: &mut Vec<[u32; 2]>) {
    out.clear();
    out.reserve(acc.len());
    let mut n = [[0f64; LANES]; 3];
    let mut w = [0f32; LANES];
    let mut c = [[0f32; LANES]; 4];
    let mut nw = [0u32; LANES];
    let mut cw = [0u32; LANES];
    for batch in acc.chunks(LANES) {
        for (i, a) in batch.iter().enumerate() {
            for k in 0..3 {
                n[k][i] = a.s[k] as f64;
            }
            w[i] = if a.s[3] > 0.0 { a.s[3] } else { a.k as f32 };
            for k in 0..4 {
                c[k][i] = a.s[4 + k];
            }
        }
        // pack_normal_f64, branch-free
        for i in 0..LANES {
            let (x, y, z) = (n[0][i], n[1][i], n[2][i]);
            let len2 = x * x + y * y + z * z;
            let valid = len2.is_finite() & (len2 > 0.0);
            let s = NORMAL_SCALE as f64 / len2.sqrt();
            let q = |c: f64| ((c * s).round().clamp(-511.0, 511.0) as i32 as u32) & 0x3ff;
            let word = q(x) | q(y) << 10 | q(z) << 20;
            nw[i] = if valid { word } else { 0 };
        }
        // the colour of `encode`: round(C · (1/W)) clamped to 0..255, RGBA little-endian
        for i in 0..LANES {
            let inv = 1.0 / w[i];
            let q = |m: f32| (m * inv).round().clamp(0.0, 255.0) as u8 as u32;
            cw[i] = q(c[0][i]) | q(c[1][i]) << 8 | q(c[2][i]) << 16 | q(c[3][i]) << 24;
        }
        out.extend((0..batch.len()).map(|i| [nw[i], cw[i]]));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxlod_testkit::Rng;

    /// The batched encoding equals the scalar [`encode`] bit for bit: on random sums of every
    /// scale, on zero, tiny (subnormal products) and huge sums, on colour means at rounding
    /// halves, and on zero-weight voxels (unweighted means by the count).
    #[test]
    fn encode_words_is_encode() {
        let mut rng = Rng(13);
        let mut accs = Vec::new();
        let specials = [
            0.0f32, -0.0, 1e-30, -1e-38, 1e-45, 3e38, -3e38, 0.5, 1.5, 254.5, 255.5,
        ];
        for i in 0..20_000u32 {
            let mut s = [0f32; 8];
            let scale = 10f32.powi(rng.int(-30, 30) as i32);
            for v in s.iter_mut() {
                *v = rng.range_f32(-1.0, 1.0) * scale;
            }
            if i % 7 == 0 {
                for v in s.iter_mut() {
                    *v = specials[(rng.next_u64() % specials.len() as u64) as usize];
                }
            }
            if i % 5 == 0 {
                // positive weight, colour means at and near rounding halves
                s[3] = 1.0 + (rng.next_u64() % 8) as f32;
                for k in 4..8 {
                    s[k] = s[3] * ((rng.next_u64() % 512) as f32 * 0.5);
                }
            }
            let k = 1 + (rng.next_u64() % 9) as u32;
            accs.push(Acc { s, idx: i, k });
        }
        let mut words = Vec::new();
        encode_words(&accs, &mut words);
        assert_eq!(words.len(), accs.len());
        for (a, w) in accs.iter().zip(&words) {
            let v = encode([1, 2, 3], a, false);
            assert_eq!([v.normal, v.color], *w, "sums {:?}, k {}", a.s, a.k);
        }
    }
}
