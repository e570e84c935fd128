//! The exact reference of `world_exact.rs`, shared with the GPU crate's tests
//! (included there by path): overlap decisions from the input's numbers, the world f32 vertices
//! as read and the grid's origin and voxel size as the file states them (f64). It never uses the
//! project's transform (`Grid::to_grid`): a voxel `i` is the world box `[origin + i·s, origin +
//! (i+1)·s]` (per axis, exact reals), and every sign is taken either from f64 with a margin a
//! thousand times its rounding, or in big integers (every value is a dyadic rational; all are
//! scaled to one power of two). Definitions as in `exact.rs` (13 separating axes for
//! conservative, the diamond for thin).

use super::Rng;
use num_bigint::BigInt;
use num_traits::{Signed, Zero};
use std::collections::{HashMap, HashSet};
use voxlod_geom::{Grid, Triangle};
use voxlod_voxelize::Mode;

/// The exact arithmetic: every value as an integer multiple of `2^-K`.
pub struct Exact {
    k: i32,
    origin: [BigInt; 3],
    half_s: BigInt,
}

fn lowest_bit(x: f64) -> i32 {
    if x == 0.0 {
        return i32::MAX;
    }
    let bits = x.to_bits();
    let exp = ((bits >> 52) & 0x7ff) as i32;
    let frac = bits & ((1u64 << 52) - 1);
    let (m, e) = if exp == 0 {
        (frac, -1074)
    } else {
        (frac | 1 << 52, exp - 1075)
    };
    e + m.trailing_zeros() as i32
}

impl Exact {
    pub fn new(origin: [f64; 3], s: f64) -> Exact {
        // f32 values are multiples of 2^-149; corners of origin + (h/2)·s
        let mut low = -149;
        for x in origin.into_iter().chain([s / 2.0]) {
            low = low.min(lowest_bit(x));
        }
        let k = -low;
        let mut e = Exact {
            k,
            origin: [BigInt::zero(), BigInt::zero(), BigInt::zero()],
            half_s: BigInt::zero(),
        };
        e.origin = origin.map(|x| e.big(x));
        e.half_s = e.big(s / 2.0);
        e
    }
    fn big(&self, x: f64) -> BigInt {
        if x == 0.0 {
            return BigInt::zero();
        }
        let low = lowest_bit(x);
        let m = (x.abs() / 2f64.powi(low)) as u64; // exact: fewer than 54 bits
        let sh = low + self.k;
        assert!(sh >= 0);
        let b = BigInt::from(m) << (sh as usize);
        if x < 0.0 {
            -b
        } else {
            b
        }
    }
    /// The world corner coordinate `origin[k] + q·s` (`q` a multiple of ½).
    fn corner(&self, k: usize, q: f64) -> BigInt {
        let h = (2.0 * q) as i64;
        assert_eq!(h as f64, 2.0 * q);
        &self.origin[k] + BigInt::from(h) * &self.half_s
    }
}

fn sgn_big(b: &BigInt) -> i8 {
    if b.is_zero() {
        0
    } else if b.is_positive() {
        1
    } else {
        -1
    }
}
fn sgn(x: f64) -> i8 {
    (x > 0.0) as i8 - (x < 0.0) as i8
}

/// One triangle of the reference.
pub struct WRef<'a> {
    ex: &'a Exact,
    /// the approximate grid coordinates of the world vertices (f64, for the filter)
    g: [[f64; 3]; 3],
    /// 13 axes in approximate grid units: e_k, n, (e_i × e_k); exact world ones on demand
    axes: Vec<[f64; 3]>,
    /// the world vertices (f32 values), exactly: on demand
    w: [[f64; 3]; 3],
    wb: std::cell::OnceCell<[[BigInt; 3]; 3]>,
    orient: std::cell::OnceCell<[i8; 3]>,
    res: f64,
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn crossb(a: &[BigInt; 3], b: &[BigInt; 3]) -> [BigInt; 3] {
    [
        &a[1] * &b[2] - &a[2] * &b[1],
        &a[2] * &b[0] - &a[0] * &b[2],
        &a[0] * &b[1] - &a[1] * &b[0],
    ]
}
fn subb(a: &[BigInt; 3], b: &[BigInt; 3]) -> [BigInt; 3] {
    [&a[0] - &b[0], &a[1] - &b[1], &a[2] - &b[2]]
}
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn unit(k: usize) -> [f64; 3] {
    let mut u = [0.0; 3];
    u[k] = 1.0;
    u
}

impl<'a> WRef<'a> {
    pub fn new(ex: &'a Exact, t: &[[f32; 3]; 3], origin: [f64; 3], s: f64, res: u32) -> WRef<'a> {
        let w = t.map(|p| p.map(|c| c as f64));
        let g = w.map(|p| [0, 1, 2].map(|k| (p[k] - origin[k]) / s));
        let e = [sub(g[1], g[0]), sub(g[2], g[1]), sub(g[0], g[2])];
        let mut axes = vec![
            unit(0),
            unit(1),
            unit(2),
            cross(sub(g[1], g[0]), sub(g[2], g[0])),
        ];
        for ei in e {
            for k in 0..3 {
                axes.push(cross(ei, unit(k)));
            }
        }
        WRef {
            ex,
            g,
            axes,
            w,
            wb: std::cell::OnceCell::new(),
            orient: std::cell::OnceCell::new(),
            res: res as f64,
        }
    }

    fn wb(&self) -> &[[BigInt; 3]; 3] {
        self.wb
            .get_or_init(|| self.w.map(|p| p.map(|x| self.ex.big(x))))
    }

    /// Exact signs of the world normal's components.
    fn orient(&self) -> [i8; 3] {
        *self.orient.get_or_init(|| {
            // f64 of the f32 values: each component within 5·2⁻⁵³ of the sum of its products
            let (d1, d2) = (sub(self.w[1], self.w[0]), sub(self.w[2], self.w[0]));
            let n = cross(d1, d2);
            let m = [0, 1, 2].map(|k| {
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                (d1[i] * d2[j]).abs() + (d1[j] * d2[i]).abs()
            });
            if (0..3).all(|k| n[k].abs() > 1e-9 * m[k]) {
                return n.map(sgn);
            }
            let wb = self.wb();
            let n = crossb(&subb(&wb[1], &wb[0]), &subb(&wb[2], &wb[0]));
            [sgn_big(&n[0]), sgn_big(&n[1]), sgn_big(&n[2])]
        })
    }

    fn exact_axis(&self, a: usize) -> [BigInt; 3] {
        let z = || BigInt::zero();
        let ub = |k: usize| {
            let mut u = [z(), z(), z()];
            u[k] = BigInt::from(1);
            u
        };
        match a {
            0..=2 => ub(a),
            3 => {
                let wb = self.wb();
                crossb(&subb(&wb[1], &wb[0]), &subb(&wb[2], &wb[0]))
            }
            _ => {
                let (i, k) = ((a - 4) / 3, (a - 4) % 3);
                let wb = self.wb();
                crossb(&subb(&wb[(i + 1) % 3], &wb[i]), &ub(k))
            }
        }
    }

    /// Exact signs of axis `a`'s components (positive scale: world and grid agree).
    fn axis_signs(&self, a: usize) -> [i8; 3] {
        match a {
            0..=2 => unit(a).map(sgn),
            3 => self.orient(),
            // ± differences of two f32 values: their f64 signs are exact
            _ => {
                let (i, k) = ((a - 4) / 3, (a - 4) % 3);
                let e = sub(self.w[(i + 1) % 3], self.w[i]);
                cross(e, unit(k)).map(sgn)
            }
        }
    }

    /// `sign(L_a · (q − v_j))` for the grid corner `q` (multiples of ½), exactly.
    fn sgn(&self, a: usize, q: [f64; 3], j: usize) -> i8 {
        let l = self.axes[a];
        let v = self.g[j];
        let mut f = 0.0;
        let mut m = 0.0;
        let mut c = 0.0;
        for k in 0..3 {
            let d = q[k] - v[k];
            f += l[k] * d;
            m += (l[k] * d).abs();
            c += l[k].abs() + d.abs() + 1.0;
        }
        // the approximate grid coordinates are within ~4·2⁻⁵³·(R + 2) of the exact ones
        let margin = 1e-9 * m + 1e-12 * (self.res + 2.0) * c;
        if f > margin {
            return 1;
        }
        if f < -margin {
            return -1;
        }
        let l = self.exact_axis(a);
        let mut s = BigInt::zero();
        for k in 0..3 {
            s += &l[k] * (self.ex.corner(k, q[k]) - &self.wb()[j][k]);
        }
        sgn_big(&s)
    }

    fn degenerate(&self) -> bool {
        self.orient() == [0; 3]
    }

    fn conservative(&self, p: [i32; 3]) -> bool {
        let pf = p.map(|c| c as f64);
        for a in [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12] {
            let ls = self.axis_signs(a);
            if ls == [0; 3] {
                continue;
            }
            let lo = [0, 1, 2].map(|k| pf[k] + if ls[k] < 0 { 1.0 } else { 0.0 });
            let hi = [0, 1, 2].map(|k| pf[k] + if ls[k] > 0 { 1.0 } else { 0.0 });
            let s1 = (0..3).map(|j| self.sgn(a, lo, j)).min().unwrap();
            let s2 = (0..3).map(|j| -self.sgn(a, hi, j)).min().unwrap();
            if s1 > 0 || s2 > 0 {
                return false;
            }
        }
        true
    }

    fn thin(&self, p: [i32; 3]) -> bool {
        let pf = p.map(|c| c as f64);
        // closed bounding box: some vertex ≤ p+1 and some ≥ p on every axis
        for k in 0..3 {
            if (0..3).all(|j| self.sgn(k, unit(k).map(|u| u * (pf[k] + 1.0)), j) < 0) {
                return false;
            }
            if (0..3).all(|j| self.sgn(k, unit(k).map(|u| u * pf[k]), j) > 0) {
                return false;
            }
        }
        let c = pf.map(|x| x + 0.5);
        let diamond: Vec<[f64; 3]> = (0..6)
            .map(|i| {
                let mut q = c;
                q[i / 2] += if i % 2 == 0 { -0.5 } else { 0.5 };
                q
            })
            .collect();
        let s: Vec<i8> = diamond.iter().map(|&q| self.sgn(3, q, 0)).collect();
        if *s.iter().min().unwrap() > 0 || *s.iter().max().unwrap() < 0 {
            return false;
        }
        for k in 0..3 {
            let o = self.orient()[k];
            if o == 0 {
                continue;
            }
            for i in 0..3 {
                let a = 4 + 3 * i + k;
                let best = diamond
                    .iter()
                    .map(|&q| -o * self.sgn(a, q, i))
                    .max()
                    .unwrap();
                if best < 0 {
                    return false;
                }
            }
        }
        true
    }

    pub fn overlaps(&self, mode: Mode, p: [i32; 3]) -> bool {
        !self.degenerate()
            && match mode {
                Mode::Conservative => self.conservative(p),
                Mode::Thin => self.thin(p),
            }
    }

    /// Voxels that may overlap: the approximate closed box widened by one.
    pub fn candidates(&self) -> ([i32; 3], [i32; 3]) {
        let lo = [0, 1, 2].map(|k| {
            let m = self.g.iter().map(|v| v[k]).fold(f64::INFINITY, f64::min);
            (m.ceil() as i32 - 2).max(0)
        });
        let hi = [0, 1, 2].map(|k| {
            let m = self
                .g
                .iter()
                .map(|v| v[k])
                .fold(f64::NEG_INFINITY, f64::max);
            (m.floor() as i32 + 1).min(self.res as i32 - 1)
        });
        (lo, hi)
    }
}

/// Mismatches of `got` against the reference over `got` and its 26-neighbours:
/// (missed, added, checked).
pub fn compare(
    tris: &[Triangle],
    grid: &Grid,
    mode: Mode,
    got: &HashSet<[i32; 3]>,
) -> (Vec<[i32; 3]>, Vec<[i32; 3]>, usize) {
    let ex = Exact::new(grid.origin, grid.voxel_size);
    let refs: Vec<WRef> = tris
        .iter()
        .map(|t| WRef::new(&ex, &t.v, grid.origin, grid.voxel_size, grid.resolution))
        .collect();
    let mut by_voxel: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
    for (i, r) in refs.iter().enumerate() {
        let (lo, hi) = r.candidates();
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    by_voxel.entry([x, y, z]).or_default().push(i as u32);
                }
            }
        }
    }
    let r = grid.resolution as i32;
    let mut check = HashSet::new();
    for p in got {
        for d in 0..27 {
            let q = [p[0] + d % 3 - 1, p[1] + d / 3 % 3 - 1, p[2] + d / 9 - 1];
            if q.iter().all(|&c| c >= 0 && c < r) {
                check.insert(q);
            }
        }
    }
    let (mut missed, mut added) = (Vec::new(), Vec::new());
    for q in &check {
        let want = by_voxel
            .get(q)
            .is_some_and(|ts| ts.iter().any(|&i| refs[i as usize].overlaps(mode, *q)));
        match (want, got.contains(q)) {
            (true, false) => missed.push(*q),
            (false, true) => added.push(*q),
            _ => {}
        }
    }
    missed.sort();
    added.sort();
    (missed, added, check.len())
}

/// `count` triangles placed where their f32 grid coordinates on `grid` meet voxel corners,
/// edges and faces (kinds `i % 4`: a vertex on a corner, an edge along a voxel edge's line, a
/// face in a voxel face plane, slivers near integers everywhere) with world values within a
/// few f32 ulps of them: the exact coordinates miss or touch by less than an ulp, either side.
pub fn near_ties(grid: &Grid, rng: &mut Rng, count: usize) -> Vec<Triangle> {
    // an f32 world value within a few ulps of the world position of grid coordinate c
    let near = |c: f64, k: usize, rng: &mut Rng| -> f32 {
        let w = (grid.origin[k] + c * grid.voxel_size) as f32;
        let step = ((rng.next_u64() % 7) as i32) - 3;
        f32::from_bits((w.to_bits() as i32 + step) as u32)
    };
    let mut tris = Vec::new();
    for i in 0..count {
        let base = [0, 1, 2].map(|_| 20.0 + (rng.next_u64() % 200) as f64);
        let kind = i % 4;
        let v: [[f32; 3]; 3] = [0, 1, 2].map(|j| {
            [0, 1, 2].map(|k| {
                let on_grid = match kind {
                    // a vertex on a corner
                    0 => j == 0,
                    // an edge along a voxel edge's line (two coordinates on integers)
                    1 => j < 2 && k < 2,
                    // a face in a voxel face plane (one coordinate)
                    2 => k == 2,
                    // slivers: everything near integers
                    _ => true,
                };
                let c = if on_grid {
                    base[k]
                        + if kind == 3 {
                            (j as f64) * ((rng.next_u64() % 3) as f64)
                        } else {
                            0.0
                        }
                } else {
                    base[k] + (rng.f64() * 2.5 - 0.5) * (1.0 + (j as f64))
                };
                if on_grid {
                    near(c, k, rng)
                } else {
                    (grid.origin[k] + c * grid.voxel_size) as f32
                }
            })
        });
        tris.push(Triangle::new(v));
    }
    tris
}
