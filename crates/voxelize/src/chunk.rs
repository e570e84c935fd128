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
    border_caps, face_mask, pack_color, pack_normal_f64, Voxel, NORMAL_SCALE,
};
use voxlod_geom::morton::{morton8_by_table, unmorton8};
use voxlod_geom::{Grid, Triangle, CHUNK, TRI_HAS_NORMALS};
use voxlod_texture::{linear_to_srgb, TextureSet};

use crate::column::Columns;
use crate::interp::{unit_or, values, Interp};
use crate::material::MaterialSums;
use crate::overlap::{cross_f64, interior_voxel, to_f64, TriSetup};
use crate::small::{self, Small};
use crate::texcolor::{linear_color, TexAt};
use crate::{scanline, single, Method, Mode};

/// The most bytes of triangles and pairs a chunk keeps for its attribute pass
/// ([`crate::single`]); a chunk with more clips every pair instead (a mesh with very many
/// triangles per chunk, e.g. a fine scan at a coarse resolution).
pub const DEFER_BYTES: usize = 32 << 20;

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
///
/// The count `k` lives apart from the sums, in [`Slots::count`] (8 bytes per voxel with the
/// index of its sums): the marking pass and the skip's test touch only the counts, and a
/// voxel's sums are made (zero) when its first contribution is added ([`Count::at`]), so the
/// voxels the skip encodes directly have none.
#[derive(Clone, Copy, Debug)]
struct Acc {
    s: [f32; 8],
}

/// The top bit of a voxel's count ([`Count::k`]): the voxel's record words are already in the
/// voxelizer's `words` (a voxel skipped by [`crate::single`], encoded once per triangle); its
/// sums are not used.
const ENCODED: u32 = 1 << 31;

impl Acc {
    /// No contribution yet.
    const ZERO: Acc = Acc { s: [0.0; 8] };

    /// Adds one contribution of weight `w` and values `x` (`x[3] = 1`) to the sums (the
    /// marking pass has counted it in the voxel's `k` already).
    #[inline]
    fn add(&mut self, w: f32, x: [f32; 8]) {
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
///
/// Two passes per chunk ([`crate::single`]): [`add`](Self::add) only marks, i.e. finds each
/// triangle's voxels, counts the contributions per voxel and keeps the (triangle, voxel) pairs;
/// [`finish`](Self::finish) then computes the contributions in triangle order, clipping only
/// where the record depends on the clipped areas.
pub struct ChunkVoxelizer {
    mode: Mode,
    origin: [u32; 3],
    /// the slot index and the accumulators
    slots: Slots,
    /// the triangles that mark voxels of this chunk, in `add` order
    marked: Vec<Marked>,
    /// their (triangle, voxel) pairs, triangle after triangle, each in scan order
    pairs: Vec<Pair>,
    /// skip the clipping where it cannot change the record ([`Self::set_single_skip`])
    single_skip: bool,
    /// add the contributions of small triangles at once ([`Self::set_small_path`])
    small_path: bool,
    /// the voxels and parts of the current small triangle
    small: Small,
    /// the small path's scratch for one batch of triangles
    batch: Batch,
    /// triangles added by the small path since this voxelizer was made
    small_count: u64,
    /// this chunk's kept pairs and triangles outgrew [`DEFER_BYTES`]: the rest of the chunk is
    /// accumulated batch by batch, every pair clipped
    eager: bool,
    /// [`DEFER_BYTES`] unless set for a test
    defer_bytes: usize,
    /// pairs given their triangle's record without clipping, since this voxelizer was made
    unclipped: u64,
    /// the encoded normal and colour words of the accumulators ([`encode_words`]), reused by
    /// `finish`
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

/// A triangle that marks voxels of the chunk: its pairs are `pairs[first..]` up to the next
/// marked triangle's `first`; `interior`: it lies inside its one voxel's interior.
struct Marked {
    t: Triangle,
    first: u32,
    interior: bool,
}

/// One (triangle, voxel) pair: the voxel's accumulator slot, and its position in the chunk in
/// the triangle's swizzled coordinates, `x | y << 8 | z << 16` (0 for an interior triangle).
#[derive(Clone, Copy, Debug)]
struct Pair {
    slot: u32,
    swz: u32,
}

/// Triangles per batch of the small path ([`ChunkVoxelizer::add_world`]).
const BATCH: usize = 64;

/// The small path's scratch for one batch of triangles (reused).
#[derive(Default)]
struct Batch {
    /// per triangle: its grid vertices
    v: Vec<[[f32; 3]; 3]>,
    /// per triangle: if it lies inside one voxel's interior, that voxel's position in the
    /// chunk and the triangle's contribution (weight and values)
    interior: Vec<Option<([u32; 3], f32, [f32; 8])>>,
}

/// The in-chunk position of grid voxel `voxel` in the chunk at `o` (written out: `array::map`
/// compiled to a call here).
#[inline(always)]
fn local_of(voxel: [i32; 3], o: [i64; 3]) -> [u32; 3] {
    [
        (voxel[0] as i64 - o[0]) as u32,
        (voxel[1] as i64 - o[1]) as u32,
        (voxel[2] as i64 - o[2]) as u32,
    ]
}

/// `grid.to_grid(p)` bit for bit, with `inv = 1.0 / grid.voxel_size` given (made once per
/// batch instead of once per vertex).
#[inline(always)]
fn to_grid_by(grid: &Grid, inv: f64, p: [f32; 3]) -> [f32; 3] {
    [
        ((p[0] as f64 - grid.origin[0]) * inv) as f32,
        ((p[1] as f64 - grid.origin[1]) * inv) as f32,
        ((p[2] as f64 - grid.origin[2]) * inv) as f32,
    ]
}

impl ChunkVoxelizer {
    /// A voxelizer for `mode`.
    pub fn new(mode: Mode) -> Self {
        ChunkVoxelizer {
            mode,
            origin: [0; 3],
            slots: Slots {
                bricks: vec![0u32; BRICKS],
                blocks: Vec::new(),
                touched: Vec::new(),
                last: NO_BRICK,
                last_voxel: NO_VOXEL,
                idx: Vec::new(),
                count: Vec::new(),
                sums: Vec::new(),
            },
            marked: Vec::new(),
            pairs: Vec::new(),
            single_skip: true,
            small_path: true,
            small: Small::default(),
            batch: Batch::default(),
            small_count: 0,
            eager: false,
            defer_bytes: DEFER_BYTES,
            unclipped: 0,
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
    /// [`crate::clipped_area`] (bit-identical to it) and clips every voxel (also
    /// [`set_single_skip`](Self::set_single_skip)`(false)`), `true` (the default) uses the closed
    /// forms of [`crate::column`](mod@crate::column) where they apply (equal up to rounding) and
    /// skips the clipping where it cannot change the record.
    pub fn set_fast_paths(&mut self, on: bool) {
        self.cols = Columns::idle(on);
        self.single_skip = on;
        self.small_path = on;
    }

    /// For tests and benchmarks: `false` sends every triangle through the marking pass (the
    /// present path kept as the reference); `true` (the default) adds the contributions of a
    /// small triangle at once, without the scan, the pair list or the column clipping
    /// ([`crate::small`]: conservative mode with an exact [`Method`], without textures or
    /// materials, a closed voxel range of at most two voxels per axis inside the chunk). The
    /// same voxels and, per voxel, the same contributions (weights and centroids bit for bit
    /// those of [`crate::clipped_area`]); only the order in which a voxel's sums receive them
    /// changes, so records stay within the rounding bound of the f32 sums.
    pub fn set_small_path(&mut self, on: bool) {
        self.small_path = on;
    }

    /// Triangles the small path ([`Self::set_small_path`]) added since this voxelizer was made.
    pub fn small_triangles(&self) -> u64 {
        self.small_count
    }

    /// For tests and benchmarks: `false` clips every (triangle, voxel) pair, as the voxelizer
    /// did before [`crate::single`] (the records of the present column method, bit for bit);
    /// `true` (the default) gives a voxel with one contribution of a triangle with flat
    /// attributes that triangle's normal and colour without clipping (records within one
    /// quantization step of the clipped ones, and equal bit for bit wherever a voxel has two or
    /// more contributions).
    pub fn set_single_skip(&mut self, on: bool) {
        self.single_skip = on;
    }

    /// For tests: the most bytes of triangles and pairs a chunk keeps for the skip
    /// ([`DEFER_BYTES`] by default); past it the chunk clips every pair.
    pub fn set_defer_bytes(&mut self, bytes: usize) {
        self.defer_bytes = bytes;
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
        self.slots.clear();
        self.marked.clear();
        self.pairs.clear();
        self.eager = false;
        if let Some(m) = &mut self.materials {
            m.clear();
        }
    }

    /// Add triangles in grid coordinates. Each is clipped to the chunk (voxel range clamped to
    /// `[origin, origin+255]`). Zero-area and non-finite triangles are skipped and counted.
    ///
    /// This is the marking pass: it finds the voxels and counts the contributions; the
    /// attributes are computed by [`finish`](Self::finish), in the same triangle order.
    pub fn add(&mut self, tris: &[Triangle]) {
        self.add_in(tris, None);
    }

    /// Add triangles in **world** coordinates of `grid`: as [`add`](Self::add) of the triangles
    /// moved to the grid (`grid.to_grid` of every vertex), except that every overlap decision
    /// is exact for the world coordinates and the grid as stated (its f64 origin and voxel
    /// size), not for the f32 grid coordinates ([`TriSetup::with_world`], [`crate::world`]).
    /// The attributes are computed from the moved triangles, as `add` does.
    pub fn add_world(&mut self, grid: &Grid, tris: &[Triangle]) {
        self.add_in(tris, Some(grid));
    }

    fn add_in(&mut self, tris: &[Triangle], grid: Option<&Grid>) {
        let o = self.origin.map(|c| c as i64);
        let lo = o.map(|c| c.min(i32::MAX as i64) as i32);
        let hi = o.map(|c| (c + CHUNK as i64 - 1).min(i32::MAX as i64) as i32);
        // exact methods only (ILV's sets are its own approximation); not with materials: their
        // sums take slots in the order the attribute pass meets them
        let small = self.small_path
            && self.method.is_exact()
            && self.mode == Mode::Conservative
            && self.textures.is_none()
            && self.materials.is_none();
        // `Grid::to_grid` with its reciprocal of the voxel size made once
        let inv = grid.map(|g| 1.0 / g.voxel_size);
        let to_grid = |t: &Triangle| match (grid, inv) {
            (Some(g), Some(s)) => t.v.map(|p| to_grid_by(g, s, p)),
            _ => t.v,
        };
        if !small {
            for t in tris {
                let moved = Triangle {
                    v: to_grid(t),
                    ..*t
                };
                self.add_general(&moved, grid.map(|g| (&t.v, g)), lo, hi);
            }
        } else {
            let mut batch = std::mem::take(&mut self.batch);
            for tris in tris.chunks(BATCH) {
                // the triangles inside one voxel's interior (most of a fine scan's) and their
                // contributions first, all of them: no step waits on the previous triangle's
                // long chain of conversions, square root and divisions
                batch.v.clear();
                batch.v.extend(tris.iter().map(to_grid));
                batch.interior.clear();
                batch
                    .interior
                    .extend(batch.v.iter().zip(tris).map(|(v, t)| {
                        small::interior(v, lo, hi).map(|i| {
                            // `face(t)` from the normal `interior` computed
                            let inv = 1.0 / i.norm;
                            let face = [i.n[0] * inv, i.n[1] * inv, i.n[2] * inv];
                            let (w, x) = interior_values(t, face, i.norm, None);
                            let local = local_of(i.voxel, o);
                            (local, w, x)
                        })
                    }));
                // then every triangle in order
                for (i, t) in tris.iter().enumerate() {
                    if let Some((local, w, x)) = batch.interior[i] {
                        self.small_count += 1;
                        let slot = self.slots.mark(local);
                        self.slots.add(slot, w, x);
                        continue;
                    }
                    let v = batch.v[i];
                    // a flat triangle needs only the areas ([`crate::single`])
                    self.small.area_only = single::is_flat(t);
                    if small::split(&v, grid.map(|_| &t.v), lo, hi, &mut self.small) {
                        // `t` holds the world positions with a grid: only its attributes are
                        // read
                        self.add_small(t);
                        continue;
                    }
                    let moved = Triangle { v, ..*t };
                    self.add_general(&moved, grid.map(|g| (&t.v, g)), lo, hi);
                }
            }
            self.batch = batch;
        }
        // memory stays bounded by the chunk's voxels, not its triangles: past the budget the
        // chunk gives up the skip and clips every pair, accumulating each batch at once
        let kept = self.marked.len() * std::mem::size_of::<Marked>()
            + self.pairs.len() * std::mem::size_of::<Pair>();
        self.eager |= kept > self.defer_bytes;
        if self.eager {
            self.accumulate(false);
            self.marked.clear();
            self.pairs.clear();
        }
    }

    /// One triangle by the general path (`t` in grid coordinates; `world`: its world positions
    /// and the grid, for [`TriSetup::with_world`]): marks its voxels and keeps the pairs for
    /// the attribute pass; in conservative mode a triangle inside one voxel's interior marks
    /// that voxel without the overlap test.
    fn add_general(
        &mut self,
        t: &Triangle,
        world: Option<(&[[f32; 3]; 3], &Grid)>,
        lo: [i32; 3],
        hi: [i32; 3],
    ) {
        let o = self.origin.map(|c| c as i64);
        // a triangle inside one voxel's interior (most of a scan's): that voxel, no overlap
        // test; its contribution is the whole triangle ([`interior_contribution`])
        if self.mode == Mode::Conservative {
            if let Some(p) = interior_voxel(&t.v) {
                if (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]) && face(t).is_some() {
                    let local = [0, 1, 2].map(|k| (p[k] as i64 - o[k]) as u32);
                    let slot = self.slots.mark(local);
                    self.marked.push(Marked {
                        t: *t,
                        first: self.pairs.len() as u32,
                        interior: true,
                    });
                    self.pairs.push(Pair { slot, swz: 0 });
                    return;
                }
            }
        }
        let Some(s) = TriSetup::with_world(&t.v, world, self.mode) else {
            self.skipped += 1;
            return;
        };
        let lo_s = s.swizzle(lo);
        let hi_s = s.swizzle(hi);
        if (0..3).any(|k| s.bmax[k] < lo_s[k] || s.bmin[k] > hi_s[k]) {
            return;
        }
        let first = self.pairs.len();
        let o_s = s.swizzle(o);
        let (slots, pairs) = (&mut self.slots, &mut self.pairs);
        let each = |p: [i32; 3], _first: bool| {
            let g = s.unswizzle(p);
            let local = [0, 1, 2].map(|k| (g[k] as i64 - o[k]) as u32);
            debug_assert!(local.iter().all(|&c| c < CHUNK));
            let slot = slots.mark(local);
            let l = [0, 1, 2].map(|k| (p[k] as i64 - o_s[k]) as u32);
            pairs.push(Pair {
                slot,
                swz: l[0] | l[1] << 8 | l[2] << 16,
            });
        };
        match self.method {
            Method::Sat => s.scan(lo_s, hi_s, each),
            Method::Scanline => scanline::scan(&s, lo_s, hi_s, each),
            Method::ScanlineIlv => scanline::scan_ilv(&s, lo_s, hi_s, each),
        }
        if self.pairs.len() > first {
            self.marked.push(Marked {
                t: *t,
                first: first as u32,
                interior: false,
            });
        }
    }

    /// A small triangle ([`crate::small`], its parts in `self.small`): marks its voxels and adds
    /// its contributions at once (weights and interpolation points those the attribute pass
    /// would compute; the whole triangle for one inside a voxel's interior). Only the
    /// attributes of `t` are read (its positions may be world ones): the geometry is
    /// `self.small`'s.
    fn add_small(&mut self, t: &Triangle) {
        self.small_count += 1;
        let o = self.origin.map(|c| c as i64);
        let (slots, sm) = (&mut self.slots, &self.small);
        debug_assert!(
            self.materials.is_none(),
            "the small path takes no materials"
        );
        let mut add = |voxel: [i32; 3], w: f32, x: [f32; 8]| {
            let slot = slots.mark(local_of(voxel, o));
            slots.add(slot, w, x);
        };
        if sm.interior {
            // `face(t)` from the normal `split` computed
            let inv = 1.0 / sm.norm;
            let face = [sm.n[0] * inv, sm.n[1] * inv, sm.n[2] * inv];
            let (w, x) = interior_values(t, face, sm.norm, None);
            add(sm.pieces[0].voxel, w, x);
            return;
        }
        if sm.area_only {
            let x = single::flat_values_of(t, sm.n, sm.norm);
            for p in sm.pieces() {
                add(p.voxel, p.w as f32, x);
            }
        } else {
            let ip = Interp::from_swizzled_normal(t, &sm.sv, sm.n, sm.norm, None);
            for p in sm.pieces() {
                let q = p.q.unwrap_or(ip.centroid);
                add(p.voxel, p.w as f32, ip.at(q[0], q[1], p.w));
            }
        }
    }

    /// The attribute pass ([`crate::single`]): every marked triangle's contributions, in `add`
    /// order, into the accumulators (and the material sums). With `skip` (and
    /// [`set_single_skip`](Self::set_single_skip) on, no textures), a voxel whose only
    /// contribution comes from a triangle with flat attributes gets weight 1 and that triangle's
    /// values, without clipping; every other pair is clipped as before.
    fn accumulate(&mut self, skip: bool) {
        let ChunkVoxelizer {
            mode,
            origin,
            slots,
            marked,
            pairs,
            single_skip,
            cols,
            textures,
            materials,
            words,
            unclipped,
            ..
        } = self;
        let textures = textures.as_deref();
        let skip = skip && *single_skip && textures.is_none();
        let o = origin.map(|c| c as i64);
        let Slots { count, sums, .. } = slots;
        // the records of the skipped voxels, encoded once per triangle (`finish` encodes the rest)
        words.clear();
        if skip {
            words.resize(count.len(), [0; 2]);
        }
        for (i, m) in marked.iter().enumerate() {
            let end = marked.get(i + 1).map_or(pairs.len(), |n| n.first as usize);
            let pairs = &pairs[m.first as usize..end];
            let t = &m.t;
            let mut mats = materials.as_mut().map(|ms| ms.set_triangle(t.material()));
            // one contribution: weight `w` and values `x` into the sums, or, for a voxel the
            // skip leaves unclipped (weight 1), its record's words
            let mut add =
                |count: &mut [Count], slot: u32, w: f32, x: [f32; 8], rec: Option<[u32; 2]>| {
                    match rec {
                        Some(r) => {
                            *unclipped += 1;
                            count[slot as usize].k |= ENCODED;
                            words[slot as usize] = r;
                        }
                        None => add_sums(count, sums, slot, w, x),
                    }
                    if let Some(ms) = mats.as_deref_mut() {
                        ms.add(slot as usize, w);
                    }
                };
            if m.interior {
                let (w, x) = interior_contribution(t, textures);
                add(count, pairs[0].slot, w, x, None);
                continue;
            }
            let flat = skip && single::is_flat(t) && face(t).is_some();
            let xflat = flat.then(|| single::flat_values(t));
            let record = xflat.map(|x| (x, record_words(&x)));
            if let Some((x, r)) = record {
                if pairs.iter().all(|p| count[p.slot as usize].k == 1) {
                    for p in pairs {
                        add(count, p.slot, 1.0, x, Some(r));
                    }
                    continue;
                }
            }
            let setup = if face(t).is_some() {
                TriSetup::new(&t.v, *mode)
            } else {
                None
            };
            let Some(s) = setup else {
                // a triangle of nonzero area in world coordinates whose f32 grid coordinates
                // are collinear (smaller than their rounding; `add_world`): it touches its
                // voxels with weight 0, like a tie, with its mean vertex colour and normal
                let c = [0, 1, 2, 3].map(|k| t.c.iter().map(|c| c[k] as f64).sum::<f64>() / 3.0);
                let n = [0, 1, 2].map(|k| t.n.iter().map(|n| n[k] as f64).sum::<f64>());
                let x = values(n, c);
                for p in pairs {
                    add(count, p.slot, 0.0, x, None);
                }
                continue;
            };
            let o_s = s.swizzle(o);
            let ip = xflat.is_none().then(|| Interp::new(t, &s, textures));
            cols.set(&s);
            let mut column = u32::MAX;
            for p in pairs {
                if let (Some((x, r)), 1) = (record, count[p.slot as usize].k) {
                    add(count, p.slot, 1.0, x, Some(r));
                    continue;
                }
                let [x, y, z] = [p.swz & 255, p.swz >> 8 & 255, p.swz >> 16];
                if p.swz & 0xffff != column {
                    column = p.swz & 0xffff;
                    cols.begin((x as i64 + o_s[0]) as f64, (y as i64 + o_s[1]) as f64);
                }
                let z = (z as i64 + o_s[2]) as f64;
                let (w, x) = match (&ip, xflat) {
                    (Some(ip), _) => {
                        let (w, c) = cols.voxel(z);
                        let q = c.map_or(ip.centroid, |c| [c[0], c[1]]);
                        (w, ip.at(q[0], q[1], w))
                    }
                    // flat values: the area alone (bit for bit the clipped path's weight)
                    (None, Some(x)) => (cols.voxel_area(z), x),
                    (None, None) => unreachable!("a triangle is flat or interpolated"),
                };
                add(count, p.slot, w as f32, x, None);
            }
        }
    }

    /// Finish the chunk: encoded voxels sorted by the Morton code of their in-chunk position,
    /// with normal, colour and face mask. Resets for the next `begin`.
    ///
    /// The voxels are encoded in slot order (a sequential read) and each record is stored at
    /// its rank in Morton order, which the occupancy bits give without a sort: the voxels of
    /// the bricks before its brick (in Morton order) plus those before it in its brick.
    pub fn finish(&mut self) -> Vec<Voxel> {
        self.accumulate(!self.eager);
        let mut out = vec![Voxel::default(); self.slots.count.len()];
        // per slot (`ranked` passes it as `i`) its material
        let winners: Option<Vec<u32>> = self
            .materials
            .as_ref()
            .map(|m| (0..m.len()).map(|i| m.winner(i)).collect());
        let mut mats = vec![0u32; winners.as_ref().map_or(0, Vec::len)];
        if self.textures.is_some() {
            self.ranked(|r, i, pos, sl| {
                out[r] = encode(pos, sl.sums_of(i), sl.count[i].k, true);
                if let Some(w) = &winners {
                    mats[r] = w[i];
                }
            });
        } else {
            let mut words = std::mem::take(&mut self.words);
            encode_words(&self.slots, &mut words);
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
    /// Every pair is clipped here (no [`crate::single`] skip): `w` is the summed clipped area.
    pub fn finish_sums(&mut self) -> Vec<VoxelSums> {
        self.accumulate(false);
        let mut out = vec![VoxelSums::default(); self.slots.count.len()];
        self.ranked(|r, i, pos, sl| {
            let a = sl.sums_of(i);
            out[r] = VoxelSums {
                pos,
                k: sl.count[i].k,
                w: a.s[3],
                n: [a.s[0], a.s[1], a.s[2]],
                c: [a.s[4], a.s[5], a.s[6], a.s[7]],
            }
        });
        out
    }

    /// Calls `f(rank, slot, position, slots)` for every voxel, in slot order (the order they
    /// were marked), with its rank in Morton order; then resets.
    #[inline]
    fn ranked(&mut self, mut f: impl FnMut(usize, usize, [u8; 3], &Slots)) {
        let sl = &self.slots;
        let mut order: Vec<(u32, u32)> = sl
            .touched
            .iter()
            .enumerate()
            .map(|(i, &(b, _))| (b, i as u32))
            .collect();
        order.sort_unstable();
        // rank of the first voxel of each occupancy word of each touched brick
        let mut first = vec![[0u32; 8]; sl.touched.len()];
        let mut rank = 0u32;
        for &(_, i) in &order {
            let occ = &sl.touched[i as usize].1;
            for (f, w) in first[i as usize].iter_mut().zip(occ) {
                *f = rank;
                rank += w.count_ones();
            }
        }
        debug_assert_eq!(rank as usize, sl.idx.len());
        for (i, &idx) in sl.idx.iter().enumerate() {
            let b = sl.bricks[(idx >> 9) as usize] as usize - 1;
            let v = idx as usize & (BRICK - 1);
            let below = sl.touched[b].1[v >> 6] & ((1u64 << (v & 63)) - 1);
            let r = first[b][v >> 6] + below.count_ones();
            let pos = unmorton8(idx);
            f(r as usize, i, pos, sl);
        }
        self.reset();
    }

    /// (Triangle, voxel) pairs given their triangle's record without clipping
    /// ([`crate::single`]) since this voxelizer was made.
    pub fn unclipped(&self) -> u64 {
        self.unclipped
    }

    /// Triangles skipped (zero area or non-finite) since this voxelizer was made.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }
}

/// The slot index and the accumulators.
struct Slots {
    /// block + 1 of each brick (`morton >> 9`), 0 = none yet
    bricks: Vec<u32>,
    /// per touched brick, slot + 1 of each voxel (`morton & 511`), 0 = empty
    blocks: Vec<u32>,
    /// per touched brick: its brick index and the occupancy bits of its 512 voxels
    touched: Vec<(u32, [u64; 8])>,
    /// the brick index and block + 1 of the last voxel marked ([`NO_BRICK`]: none)
    last: (u32, u32),
    /// the in-chunk position `x | y << 8 | z << 16` and slot of the last voxel marked
    /// ([`NO_VOXEL`]: none)
    last_voxel: (u32, u32),
    /// per occupied voxel (its slot), in the order of first touch: the Morton code of its
    /// in-chunk position
    idx: Vec<u32>,
    /// per slot: its count and where its sums are
    count: Vec<Count>,
    /// the sums of the voxels with contributions added, in the order of the first one
    sums: Vec<Acc>,
}

/// No brick ([`Slots::last`]).
const NO_BRICK: (u32, u32) = (u32::MAX, 0);

/// No voxel ([`Slots::last_voxel`]; no position has the top byte set).
const NO_VOXEL: (u32, u32) = (u32::MAX, 0);

/// A voxel's count and where its sums are, side by side so that the attribute pass's test of
/// the count and its step to the sums read one cache line.
#[derive(Clone, Copy, Debug)]
struct Count {
    /// the number of contributions the marking pass counted, and [`ENCODED`]
    k: u32,
    /// its sums in [`Slots::sums`], [`NO_SUMS`] until the attribute pass adds its first
    /// contribution (`ChunkVoxelizer::accumulate`)
    at: u32,
}

/// A slot without sums ([`Count::at`]).
const NO_SUMS: u32 = u32::MAX;

/// Adds one contribution to the sums of `slot`, making them on its first ([`Slots::sums`] holds
/// only the voxels that get one).
#[inline]
fn add_sums(count: &mut [Count], sums: &mut Vec<Acc>, slot: u32, w: f32, x: [f32; 8]) {
    let j = &mut count[slot as usize].at;
    if *j == NO_SUMS {
        *j = sums.len() as u32;
        sums.push(Acc::ZERO);
    }
    sums[*j as usize].add(w, x);
}

impl Slots {
    /// Forgets every voxel (a new chunk); keeps the allocations.
    fn clear(&mut self) {
        for &(b, _) in &self.touched {
            self.bricks[b as usize] = 0;
        }
        self.touched.clear();
        self.last = NO_BRICK;
        self.last_voxel = NO_VOXEL;
        self.blocks.clear();
        self.idx.clear();
        self.count.clear();
        self.sums.clear();
    }

    /// The sums of `slot` (which has had a contribution added).
    #[inline]
    fn sums_of(&self, slot: usize) -> &Acc {
        &self.sums[self.count[slot].at as usize]
    }

    /// Adds one contribution to the sums of `slot`, making them on the first.
    #[inline]
    fn add(&mut self, slot: u32, w: f32, x: [f32; 8]) {
        add_sums(&mut self.count, &mut self.sums, slot, w, x);
    }

    /// The block + 1 of brick `bi`, made on its first touch; remembered as the last brick.
    #[inline(never)]
    fn brick(&mut self, bi: u32) -> usize {
        let mut b = self.bricks[bi as usize] as usize;
        if b == 0 {
            self.blocks.resize(self.blocks.len() + BRICK, 0);
            self.touched.push((bi, [0; 8]));
            b = self.touched.len();
            self.bricks[bi as usize] = b as u32;
        }
        self.last = (bi, b as u32);
        b
    }

    /// Counts one contribution to the voxel at in-chunk position `local` and returns its slot,
    /// making the slot (and its brick's block of slots) on first touch.
    #[inline(always)]
    fn mark(&mut self, local: [u32; 3]) -> u32 {
        // consecutive small triangles of a scan often share their voxel
        let key = local[0] | local[1] << 8 | local[2] << 16;
        if key == self.last_voxel.0 {
            let slot = self.last_voxel.1;
            self.count[slot as usize].k += 1;
            return slot;
        }
        let slot = self.mark_new(local);
        self.last_voxel = (key, slot);
        slot
    }

    /// [`Slots::mark`] of a voxel other than the last one marked.
    #[inline(always)]
    fn mark_new(&mut self, local: [u32; 3]) -> u32 {
        let idx = morton8_by_table(local[0] as u8, local[1] as u8, local[2] as u8);
        let bi = idx >> 9;
        // a column's voxels and a triangle's neighbouring columns mostly stay in one brick
        let b = if bi == self.last.0 {
            self.last.1 as usize
        } else {
            self.brick(bi)
        };
        let v = idx as usize & (BRICK - 1);
        let sl = &mut self.blocks[(b - 1) * BRICK + v];
        if *sl == 0 {
            self.idx.push(idx);
            self.count.push(Count { k: 1, at: NO_SUMS });
            *sl = self.count.len() as u32;
            self.touched[b - 1].1[v >> 6] |= 1 << (v & 63);
        } else {
            self.count[*sl as usize - 1].k += 1;
        }
        *sl - 1
    }
}

/// The unit face normal `n/|n|` of `t` and `|n|` (twice its area), in f64; `None` for a zero
/// or non-finite normal (a triangle the voxelizer skips).
#[inline]
fn face(t: &Triangle) -> Option<([f64; 3], f64)> {
    let n = cross_f64(&to_f64(&t.v));
    let nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    if !(nn > 0.0 && nn.is_finite()) {
        return None;
    }
    let len = nn.sqrt();
    let inv = 1.0 / len;
    Some((n.map(|c| c * inv), len))
}

/// The contribution of a triangle inside the interior of one voxel (marked by
/// [`ChunkVoxelizer::add`] only if [`face`] is `Some`): the whole triangle, weight = its area
/// `|n|/2`, interpolation point = its centroid, where the barycentrics are all 1/3 (so the
/// normal is the normalized sum of the vertex normals and the colour the mean vertex colour);
/// the same contribution as the general path up to rounding.
#[inline]
fn interior_contribution(t: &Triangle, textures: Option<&TextureSet>) -> (f32, [f32; 8]) {
    let (face, len) = face(t).expect("an interior triangle has a normal");
    interior_values(t, face, len, textures)
}

/// [`interior_contribution`] from the triangle's unit face normal and `|n|` ([`face`]).
#[inline]
fn interior_values(
    t: &Triangle,
    face: [f64; 3],
    len: f64,
    textures: Option<&TextureSet>,
) -> (f32, [f32; 8]) {
    let normal = if t.flags & TRI_HAS_NORMALS != 0 {
        let m = |k: usize| t.n[0][k] as f64 + t.n[1][k] as f64 + t.n[2][k] as f64;
        let m = [m(0), m(1), m(2)];
        unit_or(m, face)
    } else {
        face
    };
    // written out: `array::map` here compiled to calls in the hot small-triangle path
    let c = |k: usize| (t.c[0][k] as u32 + t.c[1][k] as u32 + t.c[2][k] as u32) as f64 / 3.0;
    let mut c = [c(0), c(1), c(2), c(3)];
    if let Some(set) = textures {
        c = linear_color(c, TexAt::centroid(t, set, len));
    }
    ((0.5 * len) as f32, values(normal, c))
}

/// The voxel record of an accumulator: area-weighted means, or unweighted means if `Σ w = 0`;
/// `linear`: the colour sums are in linear light and the mean is sRGB-encoded.
/// The normal is packed from the sum itself (packing normalizes, and `N / W` has the direction
/// of `N`), in f64 so that tiny sums neither underflow nor lose digits.
#[inline]
fn encode(pos: [u8; 3], a: &Acc, k: u32, linear: bool) -> Voxel {
    let s = &a.s;
    let normal = pack_normal_f64([s[0] as f64, s[1] as f64, s[2] as f64]);
    let mask = face_mask(normal) | border_caps(pos);
    let inv = 1.0 / if s[3] > 0.0 { s[3] } else { k as f32 };
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

/// The normal and colour words of [`encode`] (plain colours, `linear == false`) for every slot
/// of `sl` not marked [`ENCODED`], in slot order, bit for bit, into `out` (resized to the
/// number of slots; the words of marked slots are left as they are).
///
/// The sums are transposed into batches of [`LANES`] voxels and each word is computed by a loop
/// without branches, so that the compiler runs the square roots, divisions, roundings and
/// conversions in SIMD lanes (each is correctly rounded per lane, so the bits are those of the
/// scalar [`encode`]; `tests` below compares the two). A zero or non-finite normal sum computes
/// garbage in its lane (NaN, saturating conversions) and is then replaced by 0, as
/// [`pack_normal_f64`] returns.
fn encode_words(sl: &Slots, out: &mut Vec<[u32; 2]>) {
    let count = &sl.count;
    out.resize(count.len(), [0; 2]);
    let todo: Vec<u32> = (0..count.len() as u32)
        .filter(|&i| count[i as usize].k & ENCODED == 0)
        .collect();
    let mut n = [[0f64; LANES]; 3];
    let mut w = [0f32; LANES];
    let mut c = [[0f32; LANES]; 4];
    let mut nw = [0u32; LANES];
    let mut cw = [0u32; LANES];
    for batch in todo.chunks(LANES) {
        for (i, &j) in batch.iter().enumerate() {
            let a = sl.sums_of(j as usize);
            for k in 0..3 {
                n[k][i] = a.s[k] as f64;
            }
            w[i] = if a.s[3] > 0.0 {
                a.s[3]
            } else {
                count[j as usize].k as f32
            };
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
        for (i, &j) in batch.iter().enumerate() {
            out[j as usize] = [nw[i], cw[i]];
        }
    }
}

/// The normal and colour words of a voxel whose only contribution has values `x` and weight 1
/// (what [`encode`] gives it; see [`crate::single`]).
fn record_words(x: &[f32; 8]) -> [u32; 2] {
    let v = encode([0; 3], &Acc { s: *x }, 1, false);
    [v.normal, v.color]
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
        let mut ks = Vec::new();
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
            accs.push(Acc { s });
            ks.push(1 + (rng.next_u64() % 9) as u32);
        }
        // the sums of slot i at i
        let mut slots = Slots {
            bricks: Vec::new(),
            blocks: Vec::new(),
            touched: Vec::new(),
            last: NO_BRICK,
            last_voxel: NO_VOXEL,
            idx: Vec::new(),
            count: (0..accs.len())
                .map(|i| Count {
                    k: ks[i],
                    at: i as u32,
                })
                .collect(),
            sums: accs.clone(),
        };
        let mut words = Vec::new();
        encode_words(&slots, &mut words);
        assert_eq!(words.len(), accs.len());
        for ((a, &k), w) in accs.iter().zip(&ks).zip(&words) {
            let v = encode([1, 2, 3], a, k, false);
            assert_eq!([v.normal, v.color], *w, "sums {:?}, k {k}", a.s);
        }
        // accumulators marked ENCODED keep the words they have; the others are computed
        let mut marked = vec![[7u32, 9]; accs.len()];
        for (i, c) in slots.count.iter_mut().enumerate() {
            if i % 3 == 0 {
                c.k |= ENCODED;
            }
        }
        encode_words(&slots, &mut marked);
        for (i, (m, w)) in marked.iter().zip(&words).enumerate() {
            assert_eq!(*m, if i % 3 == 0 { [7, 9] } else { *w });
        }
    }
}
