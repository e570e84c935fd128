//! The overlap decisions against an exact reference, in both modes.
//!
//! The reference is written from the definitions, not from the factored form of `overlap.rs`:
//! * conservative: the closed triangle against the closed box `[p, p+1]³` by Akenine-Möller's
//!   13 separating axes (3 box normals, the triangle normal, 9 edge × axis products), each axis
//!   as two-sided interval overlap;
//! * thin: the definition in `overlap.rs`'s docs: closed bounding box, the plane against the 6
//!   vertices of the diamond inscribed in the voxel, and per projection of nonzero area the
//!   inner half-plane of each edge against the diamond's vertices.
//!
//! Every sign is that of a polynomial in the f32 vertex coordinates and the (half-)integer
//! corner coordinates. It is taken from f64 only when the f64 value exceeds `1e-9` times the
//! sum of the magnitudes of its terms (a million times f64's rounding error of these short
//! expressions); otherwise it is computed in big-integer arithmetic (every coordinate times
//! 2¹⁵⁰, which makes every f32 and half-integer an integer): exact.
//!
//! The voxel set of `voxelize_triangle` (and of `ChunkVoxelizer`) must equal the reference's
//! over the triangle's bounding box widened by one voxel: on random and adversarial triangles
//! (vertices nudged one ulp across voxel corners, edges and faces; planes rounded through a
//! corner; slivers; axis-aligned; huge and tiny coordinates) and on real meshes.

use crate::common;
use crate::grid;

use common::adversarial::{adversarial, nudge};
use common::{shared_meshes, Rng};
use num_bigint::BigInt;
use num_traits::{Float, Signed, Zero};
use std::cell::OnceCell;
use std::collections::HashSet;
use voxlod_geom::Triangle;
use voxlod_voxelize::{voxelize_triangle, ChunkVoxelizer, Mode, TriSetup};

/// `x·2¹⁵⁰` exactly, for an f32 value or a half-integer `x`.
fn big(x: f64) -> BigInt {
    if x == 0.0 {
        return BigInt::zero();
    }
    let (m, e, s) = x.integer_decode();
    let tz = m.trailing_zeros() as i32;
    let sh = e as i32 + tz + 150;
    assert!(sh >= 0, "{x} is not an f32 value");
    let b = BigInt::from(m >> tz) << (sh as usize);
    if s < 0 {
        -b
    } else {
        b
    }
}

fn sign_big(b: &BigInt) -> i8 {
    if b.is_zero() {
        0
    } else if b.is_positive() {
        1
    } else {
        -1
    }
}

/// One separating axis `L`: its f64 value, the magnitudes of its components' terms (for the
/// f64 margin) and a recipe for the exact components.
#[derive(Clone, Copy)]
enum AxisKind {
    /// Box normal `e_k`.
    Unit(usize),
    /// Triangle normal `(v1 − v0) × (v2 − v0)`.
    Normal,
    /// `(v_{i+1} − v_i) × e_k`.
    EdgeUnit(usize, usize),
}

struct Axis {
    kind: AxisKind,
    l: [f64; 3],
    mag: [f64; 3],
}

/// A triangle for the reference: f64 vertices (exact), its axes, and lazily the exact ones.
struct Ref {
    v: [[f64; 3]; 3],
    vb: OnceCell<[[BigInt; 3]; 3]>,
    axes: Vec<Axis>,
    exact_axes: OnceCell<Vec<[BigInt; 3]>>,
    /// Sign of the exact normal's components.
    orient: [i8; 3],
    /// Number of signs that needed big integers.
    slow: std::cell::Cell<usize>,
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn cross_mag(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        (a[1] * b[2]).abs() + (a[2] * b[1]).abs(),
        (a[2] * b[0]).abs() + (a[0] * b[2]).abs(),
        (a[0] * b[1]).abs() + (a[1] * b[0]).abs(),
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

impl Ref {
    fn new(t: &[[f32; 3]; 3]) -> Ref {
        let v = t.map(|p| p.map(|c| c as f64));
        let e = [sub(v[1], v[0]), sub(v[2], v[1]), sub(v[0], v[2])];
        let mut axes = Vec::with_capacity(13);
        for k in 0..3 {
            axes.push(Axis {
                kind: AxisKind::Unit(k),
                l: unit(k),
                mag: unit(k),
            });
        }
        let (a, b) = (sub(v[1], v[0]), sub(v[2], v[0]));
        axes.push(Axis {
            kind: AxisKind::Normal,
            l: cross(a, b),
            mag: cross_mag(a, b),
        });
        for (i, ei) in e.iter().enumerate() {
            for k in 0..3 {
                let l = cross(*ei, unit(k));
                axes.push(Axis {
                    kind: AxisKind::EdgeUnit(i, k),
                    l,
                    mag: l.map(f64::abs),
                });
            }
        }
        let mut r = Ref {
            v,
            vb: OnceCell::new(),
            axes,
            exact_axes: OnceCell::new(),
            orient: [0; 3],
            slow: std::cell::Cell::new(0),
        };
        for k in 0..3 {
            let (l, m) = (r.axes[3].l[k], r.axes[3].mag[k]);
            r.orient[k] = if l > 1e-9 * m {
                1
            } else if l < -1e-9 * m {
                -1
            } else {
                r.slow.set(r.slow.get() + 1);
                sign_big(&r.exact_axis(3)[k])
            };
        }
        r
    }

    fn vb(&self) -> &[[BigInt; 3]; 3] {
        self.vb.get_or_init(|| self.v.map(|p| p.map(big)))
    }

    fn exact_axis(&self, a: usize) -> &[BigInt; 3] {
        &self.exact_axes.get_or_init(|| {
            let vb = self.vb();
            let one = big(1.0);
            let ub = |k: usize| {
                let mut u = [BigInt::zero(), BigInt::zero(), BigInt::zero()];
                u[k] = one.clone();
                u
            };
            self.axes
                .iter()
                .map(|ax| match ax.kind {
                    AxisKind::Unit(k) => ub(k),
                    AxisKind::Normal => crossb(&subb(&vb[1], &vb[0]), &subb(&vb[2], &vb[0])),
                    AxisKind::EdgeUnit(i, k) => crossb(&subb(&vb[(i + 1) % 3], &vb[i]), &ub(k)),
                })
                .collect()
        })[a]
    }

    fn degenerate(&self) -> bool {
        self.orient == [0; 3]
    }

    /// `sign(L_a · (q − v_j))`, exact; `q` has (half-)integer coordinates.
    fn sgn(&self, a: usize, q: [f64; 3], j: usize) -> i8 {
        let ax = &self.axes[a];
        let w = self.v[j];
        if let AxisKind::Unit(k) = ax.kind {
            // the sign of a rounded difference is exact
            let d = q[k] - w[k];
            return if d > 0.0 {
                1
            } else if d < 0.0 {
                -1
            } else {
                0
            };
        }
        let mut f = 0.0;
        let mut m = 0.0;
        for k in 0..3 {
            f += ax.l[k] * (q[k] - w[k]);
            m += ax.mag[k] * (q[k].abs() + w[k].abs() + 1.0);
        }
        if f > 1e-9 * m {
            return 1;
        }
        if f < -1e-9 * m {
            return -1;
        }
        self.slow.set(self.slow.get() + 1);
        let l = self.exact_axis(a);
        let vb = &self.vb()[j];
        let mut s = BigInt::zero();
        for k in 0..3 {
            s += &l[k] * (big(q[k]) - &vb[k]);
        }
        sign_big(&s)
    }

    /// Closed triangle ∩ closed box `[p, p+1]³`; `tie` if it touches the box only (an axis
    /// separation is exactly 0).
    fn conservative(&self, p: [i32; 3]) -> (bool, bool) {
        let pf = p.map(|c| c as f64);
        let mut tie = false;
        // the plane first: most boxes are separated by it
        for a in [3, 0, 1, 2, 4, 5, 6, 7, 8, 9, 10, 11, 12] {
            // a zero edge × axis product (the edge is parallel to the axis): no axis; its f64
            // components are ± differences of f32 values, zero iff exactly zero. The normal of a
            // non-degenerate triangle is never zero.
            if self.axes[a].l == [0.0; 3] && !matches!(self.axes[a].kind, AxisKind::Normal) {
                continue;
            }
            // box corners minimizing / maximizing L (exact signs of L's components)
            let ls = self.axis_signs(a);
            let lo = [0, 1, 2].map(|k| pf[k] + if ls[k] < 0 { 1.0 } else { 0.0 });
            let hi = [0, 1, 2].map(|k| pf[k] + if ls[k] > 0 { 1.0 } else { 0.0 });
            // sign(box_lo − tri_hi) = min_j sign(L·(lo − v_j)); sign(tri_lo − box_hi) likewise
            let s1 = (0..3).map(|j| self.sgn(a, lo, j)).min().unwrap();
            let s2 = (0..3).map(|j| -self.sgn(a, hi, j)).min().unwrap();
            if s1 > 0 || s2 > 0 {
                return (false, false);
            }
            if s1 == 0 || s2 == 0 {
                tie = true;
            }
        }
        (true, tie)
    }

    fn axis_signs(&self, a: usize) -> [i8; 3] {
        let ax = &self.axes[a];
        match ax.kind {
            AxisKind::Normal => self.orient,
            // components are ± a difference of two f32 values: its f64 sign is exact
            _ => ax.l.map(|c| {
                if c > 0.0 {
                    1
                } else if c < 0.0 {
                    -1
                } else {
                    0
                }
            }),
        }
    }

    /// The thin definition (`overlap.rs` docs); `tie` if a deciding value is exactly 0.
    fn thin(&self, p: [i32; 3]) -> (bool, bool) {
        let pf = p.map(|c| c as f64);
        let mut tie = false;
        // closed bounding box
        for k in 0..3 {
            let lo = self.v.iter().map(|w| w[k]).fold(f64::INFINITY, f64::min);
            let hi = self
                .v
                .iter()
                .map(|w| w[k])
                .fold(f64::NEG_INFINITY, f64::max);
            if pf[k] + 1.0 < lo || pf[k] > hi {
                return (false, false);
            }
            tie |= pf[k] + 1.0 == lo || pf[k] == hi;
        }
        let c = pf.map(|x| x + 0.5);
        let diamond: Vec<[f64; 3]> = (0..6)
            .map(|i| {
                let mut q = c;
                q[i / 2] += if i % 2 == 0 { -0.5 } else { 0.5 };
                q
            })
            .collect();
        // the plane against the diamond: min ≤ 0 ≤ max
        let s: Vec<i8> = diamond.iter().map(|&q| self.sgn(3, q, 0)).collect();
        let (mn, mx) = (*s.iter().min().unwrap(), *s.iter().max().unwrap());
        if mn > 0 || mx < 0 {
            return (false, false);
        }
        tie |= mn == 0 || mx == 0;
        // each projection of nonzero area, each edge: its inner half-plane meets the diamond
        // (the inner side of edge i in the plane ⟂ k is where −o_k·(e_i × e_k)·(q − v_i) ≥ 0)
        for k in 0..3 {
            let o = self.orient[k];
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
                    return (false, false);
                }
                tie |= best == 0;
            }
        }
        (true, tie)
    }

    fn overlaps(&self, mode: Mode, p: [i32; 3]) -> (bool, bool) {
        match mode {
            Mode::Conservative => self.conservative(p),
            Mode::Thin => self.thin(p),
        }
    }
}

/// Mismatches of one comparison.
#[derive(Default, Debug, Clone, Copy)]
struct Tally {
    triangles: usize,
    voxels: usize,
    missed: usize,
    added: usize,
    ties: usize,
    slow: usize,
}

impl Tally {
    fn add(&mut self, o: Tally) {
        self.triangles += o.triangles;
        self.voxels += o.voxels;
        self.missed += o.missed;
        self.added += o.added;
        self.ties += o.ties;
        self.slow += o.slow;
    }
}

fn bbox(t: &[[f32; 3]; 3]) -> ([i32; 3], [i32; 3]) {
    let mut lo = [0; 3];
    let mut hi = [0; 3];
    for k in 0..3 {
        let mn = t.iter().map(|p| p[k] as f64).fold(f64::INFINITY, f64::min);
        let mx = t
            .iter()
            .map(|p| p[k] as f64)
            .fold(f64::NEG_INFINITY, f64::max);
        lo[k] = mn.floor() as i32 - 2;
        hi[k] = mx.floor() as i32 + 1;
    }
    (lo, hi)
}

/// Compares `voxelize_triangle` with the reference over the bounding box widened by one voxel
/// (voxel `i` meets `[min, max]` iff `ceil(min) − 1 ≤ i ≤ floor(max)`); `set` collects the
/// reference's voxels.
fn compare_triangle(
    t: &[[f32; 3]; 3],
    mode: Mode,
    set: Option<&mut HashSet<[i32; 3]>>,
    what: &str,
) -> Tally {
    let r = Ref::new(t);
    let mut got = HashSet::new();
    let (lo, hi) = bbox(t);
    voxelize_triangle(t, lo, hi, mode, &mut |p| {
        assert!(got.insert(p), "{what}: {p:?} emitted twice");
    });
    let mut tally = Tally {
        triangles: 1,
        ..Tally::default()
    };
    if r.degenerate() {
        assert!(
            got.is_empty(),
            "{what}: a degenerate triangle {t:?} marked {got:?}"
        );
        assert!(TriSetup::new(t, mode).is_none());
        return tally;
    }
    let mut set = set;
    for x in lo[0]..=hi[0] {
        for y in lo[1]..=hi[1] {
            for z in lo[2]..=hi[2] {
                let p = [x, y, z];
                let (want, tie) = r.overlaps(mode, p);
                let have = got.contains(&p);
                if want {
                    tally.voxels += 1;
                    tally.ties += tie as usize;
                    if let Some(s) = set.as_deref_mut() {
                        s.insert(p);
                    }
                }
                if want && !have {
                    tally.missed += 1;
                    eprintln!("{what} {mode}: MISSED {p:?} of {t:?} (tie {tie})");
                }
                if have && !want {
                    tally.added += 1;
                    eprintln!("{what} {mode}: ADDED {p:?} of {t:?}");
                }
            }
        }
    }
    tally.slow = r.slow.get();
    tally
}

// ---------------------------------------------------------------- made-up triangles

fn run_made_up(name: &str, offset: f64, count: usize, seed: u64) -> [Tally; 2] {
    let mut out = [Tally::default(); 2];
    for (mi, mode) in [Mode::Conservative, Mode::Thin].into_iter().enumerate() {
        let mut rng = Rng(seed);
        for i in 0..count {
            let t = adversarial(&mut rng, i, offset);
            out[mi].add(compare_triangle(&t, mode, None, name));
        }
        eprintln!("{name} {mode}: {:?}", out[mi]);
    }
    out
}

fn assert_clean(name: &str, t: &[Tally]) {
    for x in t {
        assert_eq!((x.missed, x.added), (0, 0), "{name}: {x:?}");
    }
}

#[test]
fn adversarial_triangles_near_the_origin() {
    let t = run_made_up("near 0", 0.0, 6000, 1);
    assert_clean("near 0", &t);
    // the categories do produce ties and near-ties (the exact path is exercised)
    assert!(t[0].ties > 1000 && t[0].slow > 1000, "{t:?}");
    assert!(t[1].ties > 100 && t[1].slow > 1000, "{t:?}");
}

#[test]
fn adversarial_triangles_at_moderate_and_huge_coordinates() {
    // 2^20: f32 spacing 1/8; 2^23 − 8: spacing 1/2; 300.0: spacing 2^-15; negative side too
    for (name, o, seed) in [
        ("at 300", 300.0, 2),
        ("at -77", -77.0, 3),
        ("at 2^20", (1u64 << 20) as f64, 4),
        ("at 2^23", ((1u64 << 23) - 8) as f64, 5),
    ] {
        let t = run_made_up(name, o, 2000, seed);
        assert_clean(name, &t);
    }
}

#[test]
fn tiny_and_subnormal_coordinates() {
    let mut rng = Rng(6);
    let mut tally = [Tally::default(); 2];
    for i in 0..3000 {
        // around the grid corner 0 (and 1): scale 1e-30 or subnormal f32
        let s = if i % 2 == 0 { 1e-30 } else { 1e-40 };
        let c = if i % 3 == 0 { 1.0 } else { 0.0 };
        let t: [[f32; 3]; 3] = [0, 1, 2].map(|_| rng.point(-1.0, 1.0).map(|x| (c + x * s) as f32));
        for (mi, mode) in [Mode::Conservative, Mode::Thin].into_iter().enumerate() {
            tally[mi].add(compare_triangle(&t, mode, None, "tiny"));
        }
    }
    // tiny triangles with one large coordinate: a vertex far out along an axis
    for _ in 0..1000 {
        let mut t: [[f32; 3]; 3] =
            [0, 1, 2].map(|_| rng.point(-1.0, 1.0).map(|x| (x * 1e-20) as f32));
        let k = rng.int(0, 2) as usize;
        t[0][k] = rng.range(-3.0, 3.0) as f32;
        for (mi, mode) in [Mode::Conservative, Mode::Thin].into_iter().enumerate() {
            tally[mi].add(compare_triangle(&t, mode, None, "tiny+long"));
        }
    }
    eprintln!("tiny: {tally:?}");
    assert_clean("tiny", &tally);
}

/// The composed decision of the public methods for voxel `p` (original coordinates).
fn decided(s: &TriSetup, p: [i32; 3]) -> bool {
    let q = s.swizzle(p);
    (0..3).all(|k| q[k] >= s.bmin[k] && q[k] <= s.bmax[k])
        && s.column_inside(q[0], q[1])
        && s.column_depth(q[0], q[1], q[2], q[2])
            .is_some_and(|(a, b)| a == q[2] && b == q[2])
        && s.side_inside(q)
}

#[test]
fn exact_signs_and_degenerate_triangles() {
    // exactly collinear
    for t in [
        [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]],
        [
            [1e9, 3.0, -7.0],
            [1e9 + 64.0, 3.0 + 64.0, -7.0 + 128.0],
            [1e9 - 128.0, 3.0 - 128.0, -7.0 - 256.0],
        ],
        [[1e-30, 0.0, 5.0], [1e-30, 0.0, 5.0], [3.0, 1.0, 2.0]],
    ] {
        let r = Ref::new(&t);
        assert!(r.degenerate());
        assert!(TriSetup::new(&t, Mode::Thin).is_none(), "{t:?}");
    }
    // triangles too large to enumerate, with huge and tiny coordinates mixed on one axis (their
    // f64 differences round, so f64 signs of the normal can be wrong): the decisions at voxels
    // around the vertices and along the edges, where they are close
    let mut rng = Rng(9);
    let mut checked = [0usize; 2];
    for _ in 0..3000 {
        let mut coord = || -> f32 {
            match rng.int(0, 5) {
                0 => (rng.range(-1.0, 1.0) * 1e9) as f32,
                1 => (rng.range(-1.0, 1.0) * 1e-30) as f32,
                2 => {
                    let c = rng.int(-3, 3) as f32;
                    nudge(&mut rng, c)
                }
                3 => rng.range(-1e4, 1e4) as f32,
                _ => rng.int(-3, 3) as f32,
            }
        };
        let mut t = [[0.0f32; 3]; 3];
        for v in &mut t {
            for c in v.iter_mut() {
                *c = coord();
            }
        }
        let r = Ref::new(&t);
        for (mi, mode) in [Mode::Conservative, Mode::Thin].into_iter().enumerate() {
            let Some(s) = TriSetup::new(&t, mode) else {
                assert!(r.degenerate(), "{t:?}");
                continue;
            };
            assert!(!r.degenerate());
            let mut pts = Vec::new();
            for i in 0..3 {
                for f in [0.0, 0.25, 0.5, 0.75] {
                    let (a, b) = (t[i], t[(i + 1) % 3]);
                    pts.push([0, 1, 2].map(|k| a[k] as f64 + f * (b[k] as f64 - a[k] as f64)));
                }
            }
            for q in pts {
                let c = q.map(|x| x.floor().clamp(-2e9, 2e9) as i32);
                for d in 0..27 {
                    let p = [c[0] + d % 3 - 1, c[1] + d / 3 % 3 - 1, c[2] + d / 9 - 1];
                    assert_eq!(decided(&s, p), r.overlaps(mode, p).0, "{t:?} {mode} {p:?}");
                    checked[mi] += 1;
                }
            }
        }
    }
    eprintln!("huge/tiny mixed: {checked:?} voxels checked");
    // non-finite input is still rejected
    assert!(TriSetup::new(
        &[[f32::NAN, 0.0, 0.0], [1.0; 3], [0.0, 1.0, 0.0]],
        Mode::Thin
    )
    .is_none());
}

#[test]
fn public_decisions_compose_to_scan() {
    // column_inside ∧ column_depth ∧ side_inside is the scan, also outside the bounding box
    let mut rng = Rng(7);
    for i in 0..400 {
        let t = adversarial(&mut rng, i, 10.0);
        for mode in [Mode::Conservative, Mode::Thin] {
            let Some(s) = TriSetup::new(&t, mode) else {
                continue;
            };
            let mut scanned = HashSet::new();
            let lo = s.bmin.map(|c| c - 2);
            let hi = s.bmax.map(|c| c + 2);
            s.scan(lo, hi, |p, _| {
                scanned.insert(p);
            });
            let r = Ref::new(&t);
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    let depth = s.column_depth(x, y, lo[2], hi[2]);
                    for z in lo[2]..=hi[2] {
                        let p = [x, y, z];
                        let in_box = (0..3).all(|k| p[k] >= s.bmin[k] && p[k] <= s.bmax[k]);
                        let composed = in_box
                            && s.column_inside(x, y)
                            && depth.is_some_and(|(a, b)| a <= z && z <= b)
                            && s.side_inside(p);
                        assert_eq!(composed, scanned.contains(&p), "{t:?} {mode} {p:?}");
                        assert_eq!(
                            composed,
                            r.overlaps(mode, s.unswizzle(p)).0,
                            "{t:?} {mode} {p:?}"
                        );
                    }
                    // the depth range alone (no bounding box) is exactly the plane test
                    if let Some((a, b)) = depth {
                        assert!(lo[2] <= a && a <= b && b <= hi[2]);
                    }
                }
            }
        }
    }
}

#[test]
fn chunk_voxelizer_sets_equal_the_reference() {
    // many triangles into one chunk (the interior-voxel shortcut, clipping to the chunk)
    let mut rng = Rng(8);
    let tris: Vec<[[f32; 3]; 3]> = (0..3000)
        .map(|i| adversarial(&mut rng, i, 250.0 + (i % 7) as f64))
        .collect();
    for mode in [Mode::Conservative, Mode::Thin] {
        let mut want = HashSet::new();
        let mut tally = Tally::default();
        for t in &tris {
            tally.add(compare_triangle(t, mode, Some(&mut want), "chunk"));
        }
        assert_eq!((tally.missed, tally.added), (0, 0));
        let origins: Vec<[u32; 3]> = (0..8)
            .map(|i| [i & 1, i >> 1 & 1, i >> 2].map(|c| c * 256))
            .collect();
        let got = chunk_sets(&tris, mode, &origins);
        let want: HashSet<[i32; 3]> = want
            .into_iter()
            .filter(|p| p.iter().all(|&c| (0..512).contains(&c)))
            .collect();
        let missed = want.difference(&got).count();
        let added = got.difference(&want).count();
        eprintln!(
            "chunk {mode}: {} voxels, missed {missed}, added {added}",
            want.len()
        );
        assert_eq!((missed, added), (0, 0));
    }
}

fn chunk_sets(tris: &[[[f32; 3]; 3]], mode: Mode, origins: &[[u32; 3]]) -> HashSet<[i32; 3]> {
    let tris: Vec<Triangle> = tris.iter().map(|&v| Triangle::new(v)).collect();
    let mut cv = ChunkVoxelizer::new(mode);
    let mut got = HashSet::new();
    for &o in origins {
        cv.begin(o);
        cv.add(&tris);
        for v in cv.finish() {
            let p = v.pos();
            got.insert([0, 1, 2].map(|k| (o[k] + p[k] as u32) as i32));
        }
    }
    got
}

// ---------------------------------------------------------------- real meshes

/// The positions of a mesh's triangles in the grid coordinates the tool uses, at `res`.
fn positions_in_grid(path: &std::path::Path, res: u32) -> Vec<[[f32; 3]; 3]> {
    grid::mesh_in_grid(path, res).iter().map(|t| t.v).collect()
}

fn real_mesh(rel: &str, resolutions: &[u32]) {
    let Some(dir) = shared_meshes() else {
        return;
    };
    for &res in resolutions {
        let tris = positions_in_grid(&dir.join(rel), res);
        for mode in [Mode::Conservative, Mode::Thin] {
            let mut want = HashSet::new();
            let mut tally = Tally::default();
            for t in &tris {
                tally.add(compare_triangle(t, mode, Some(&mut want), rel));
            }
            let n = res / 256;
            let origins: Vec<[u32; 3]> = (0..n * n * n)
                .map(|i| [i % n, i / n % n, i / (n * n)].map(|c| c * 256))
                .collect();
            let got = chunk_sets(&tris, mode, &origins);
            let want: HashSet<[i32; 3]> = want
                .into_iter()
                .filter(|p| p.iter().all(|&c| c >= 0 && c < res as i32))
                .collect();
            let (cm, ca) = (want.difference(&got).count(), got.difference(&want).count());
            eprintln!(
                "{rel} {res}³ {mode}: {} triangles, {} voxels (per-triangle {} incl. ties {}; \
                 exact signs {}); missed {} added {}; chunk voxelizer missed {cm} added {ca}",
                tally.triangles,
                want.len(),
                tally.voxels,
                tally.ties,
                tally.slow,
                tally.missed,
                tally.added
            );
            assert_eq!(
                (tally.missed, tally.added, cm, ca),
                (0, 0, 0, 0),
                "{rel} {res} {mode}"
            );
        }
    }
}

#[test]
fn stanford_bunny_exact() {
    real_mesh("stanford-bunny/bun_zipper.ply", &[256, 512]);
}

#[test]
fn happy_buddha_exact() {
    real_mesh("stanford-happy-buddha/happy_vrip_res3.ply", &[512]);
}

#[test]
fn face_range_map_exact() {
    real_mesh("pymeshlab-face-rangemap/face000.ply", &[256]);
}

#[test]
fn munich_city_exact() {
    // grid-aligned architecture: many exact ties
    real_mesh("sionna-rt-munich/munich_merged.ply", &[256]);
}

// ---------------------------------------------------------------- small triangles

/// A triangle within about one voxel of the grid point `p` (so its closed voxel range spans
/// at most two voxels per axis, the chunk voxelizer's small path): vertices on the point, on
/// its grid lines and planes, nudged by ulps across them, a plane through the point rounded to
/// f32, an edge through a grid line, tiny triangles at the point, and general ones.
fn small_adversarial(rng: &mut Rng, kind: usize, p: [f64; 3]) -> [[f32; 3]; 3] {
    let near = |rng: &mut Rng, r: f64| {
        [0, 1, 2].map(|k| match rng.int(0, 3) {
            0 => nudge(rng, p[k] as f32),
            _ => {
                let x = (p[k] + rng.range(-r, r)) as f32;
                nudge(rng, x)
            }
        })
    };
    match kind % 5 {
        0 => [0, 1, 2].map(|_| near(rng, 0.95)),
        // the plane through the point, rounded to f32
        1 => {
            let n = rng.point(-1.0, 1.0);
            let a = common::cross(n, rng.point(-1.0, 1.0));
            let b = common::cross(n, a);
            let s = 0.95 / a.iter().chain(&b).fold(1e-9f64, |m, c| m.max(c.abs()));
            let q = |u: f64, w: f64| [0, 1, 2].map(|k| (p[k] + s * (u * a[k] + w * b[k])) as f32);
            [0, 1, 2].map(|_| q(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5)))
        }
        // an edge through a grid line of the point: two vertices symmetric about it
        2 => {
            let k = rng.int(0, 2) as usize;
            let d = rng.point(-0.45, 0.45);
            let mut a = [0, 1, 2].map(|j| p[j] + d[j]);
            let mut b = [0, 1, 2].map(|j| p[j] - d[j]);
            a[k] = p[k] + rng.range(-0.9, 0.9);
            b[k] = p[k] + rng.range(-0.9, 0.9);
            let c = near(rng, 0.9).map(|c| c as f64);
            [a, b, c].map(|v| v.map(|x| nudge(rng, x as f32)))
        }
        // tiny, at the point
        3 => [0, 1, 2].map(|_| near(rng, 1e-5)),
        _ => [0, 1, 2].map(|_| near(rng, 0.5)),
    }
}

/// The small path of the chunk voxelizer (exact decisions against the octants around one grid
/// point, `crate::small`) against the big-integer reference, conservative mode: the same sets,
/// on triangles built to sit on and an ulp off the point's grid lines and planes; and the same
/// sets as the voxelizer with the small path off.
#[test]
fn small_triangles_sets_equal_the_reference() {
    let mut rng = Rng(0x5a11);
    let tris: Vec<[[f32; 3]; 3]> = (0..6000)
        .map(|i| {
            let p = [0, 1, 2].map(|_| rng.int(2, 250) as f64);
            small_adversarial(&mut rng, i, p)
        })
        .collect();
    let mut want = HashSet::new();
    let mut tally = Tally::default();
    for t in &tris {
        tally.add(compare_triangle(
            t,
            Mode::Conservative,
            Some(&mut want),
            "small",
        ));
    }
    assert_eq!((tally.missed, tally.added), (0, 0), "{tally:?}");
    // ties and near-ties are there: the exact predicates decide
    assert!(tally.ties > 1000 && tally.slow > 1000, "{tally:?}");
    let tris: Vec<Triangle> = tris.iter().map(|&v| Triangle::new(v)).collect();
    let mut sets = Vec::new();
    for small in [true, false] {
        let mut cv = ChunkVoxelizer::new(Mode::Conservative);
        cv.set_small_path(small);
        cv.begin([0; 3]);
        cv.add(&tris);
        let got: HashSet<[i32; 3]> = cv
            .finish()
            .iter()
            .map(|v| v.pos().map(|c| c as i32))
            .collect();
        let small_count = cv.small_triangles();
        eprintln!(
            "small path {small}: {} voxels, {small_count} of {} triangles small",
            got.len(),
            tris.len()
        );
        if small {
            // nearly all of them take the small path (the rest: zero area, uncertain signs,
            // projections of zero area)
            assert!(small_count as usize > tris.len() * 9 / 10, "{small_count}");
        }
        sets.push(got);
    }
    let missed = want.difference(&sets[0]).count();
    let added = sets[0].difference(&want).count();
    assert_eq!((missed, added), (0, 0), "small path against the reference");
    assert_eq!(sets[0], sets[1], "small path on and off");
}
