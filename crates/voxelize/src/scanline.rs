//! The projected scanline voxelizer: Zhang, Garcia, Xu, Shao & Yang, "Efficient Voxelization
//! Using Projected Optimal Scanline" (section 4), as a second way to enumerate the voxels of
//! [`TriSetup`]'s overlap tests, and the paper's integer-only variant (ILV) as an approximation.
//!
//! # The exact method ([`scan`], `--voxelizer scanline`)
//!
//! In swizzled coordinates (depth axis z, `n_z > 0`) the triangle is cut into **slices**, the
//! slabs `x ∈ [i, i+1]` of the outer axis (the paper slices along the dominant axis; slicing
//! along x instead makes the voxels come out in the chunk voxelizer's column order, x, then y,
//! then z, with no sort). Inside a slice every **scanline** is a line of voxels, and the voxels
//! of a convex triangle along a line of voxels form an interval: the marked voxels are the
//! lattice points of a convex polytope (the 13 separating-axis conditions are half-spaces in
//! `p`). So only the ends of each interval are decided, through the three predicates of
//! [`TriSetup`] (`column_inside`, `column_depth`, `side_inside`, exact once the overlap tests
//! are); the voxels between the ends follow from convexity, and the columns of a run (3.) from
//! a floating-point bound with a margin far above its rounding:
//!
//! 1. The **columns** of the slice, the y-interval where `column_inside(i, y)` holds: its ends
//!    are computed in floating point from the three dominant-projection edges (rounded
//!    outwards), then settled with the predicate, stepping in while it fails and out while it
//!    holds.
//! 2. Per column, the depth scanline `column_depth(i, y, ..)` (the predicate returns the
//!    interval itself).
//! 3. The other two projections (`side_inside`) only cut columns near the triangle's edges.
//!    The **optimal scanline interval** of the slice is the run of columns `[ra, rb]` where they
//!    cannot cut. The depth band of those columns lies in the parallelogram `Q` between the
//!    lines `z = f(y) − 1` and `z = g(y)` over `[ra, rb]` (its ends are `⌈f⌉ − 1 ≥ f − 1` and
//!    `⌊g⌋ ≤ g` for the plane's linear `f`, `g`), and each side constraint is linear: the run
//!    is where all six hold with a margin of `RUN_MARGIN` (10⁻⁶ voxel times the constraint
//!    normal's length) at `Q`'s corners, evaluated in f64. That margin is some 10⁴ times the
//!    rounding error of the evaluation for grid coordinates below 2²⁰, so the constraints hold
//!    on all of `Q` in exact arithmetic too (a projection of nearly zero area, where an exact
//!    edge normal could differ in sign from the f64 one, has its constraints tight on the band
//!    and never gets a run; a run is only looked for where `RUN_MARGIN` is at least 100 times
//!    the exact predicates' own f64 rounding bound, `TriSetup::side_slack`, and never for a
//!    triangle that the overlap tests decide exactly throughout). In the run, every voxel of a depth scanline is marked with no
//!    further test. As a check through the predicates, `side_inside` must hold at both ends
//!    of the depth scanlines of the run's first and last columns; otherwise (it should not
//!    happen) the slice is settled column by column.
//! 4. Outside the run (a few columns at each end of the slice) the depth scanline is settled
//!    at both ends with `side_inside`, stepping inwards (the depth interval is a hard bound).
//!
//! Triangles whose window spans fewer than `SMALL` (32) columns in x or y, where a slice's
//! setup costs more than it saves, go to [`TriSetup::scan`] (the same voxels; [`scan_slices`]
//! runs the slices on any triangle).
//!
//! This is the paper's super-cover rule (SLV): every voxel a scanline's interval touches,
//! ties included, so the set **equals** the conservative set of the overlap tests, and in thin
//! mode the 6-separating set of the same predicates ("the same number of voxels as the
//! SAT-based method", section 6). Where the paper saves the per-voxel tests of a scanline's
//! interior by stepping a line voxelization (RLV) along it, this saves them by certifying the
//! whole run at once; the per-voxel work left is one `column_depth` per column and the emit.
//!
//! # The integer-only approximation ([`scan_ilv`], `--voxelizer scanline-ilv`)
//!
//! Algorithm 1 of the paper with integer-only line voxelization (ILV): the vertices are
//! snapped to their voxels, the three edges voxelized as 6-connected integer lines, the
//! triangle sliced along its dominant axis, and every slice filled with ILV scanlines between
//! the two edge paths, their ends picked by the integer scanning condition (equations 8–9) so
//! that consecutive scanlines are at most the optimal interval `d̂ = (|ΔX| + |ΔY|) / |Δ|`
//! apart. It is **approximate**: the vertices move to their voxels' centres (up to 0.87 voxel),
//! which shifts the surface. Against the exact conservative set (npm bunny and a 48k-triangle
//! dragon at 512³, `tests/scanline.rs`, which asserts below 15 %) it misses 12–13 % of the
//! voxels and adds 13–14 % others: the counts differ by under 1 %, which is the paper's
//! "error" (Table 3), but the sets do not. Conservative mode only, and no faster here than the
//! exact method (measured: docs/journal/benchmarks-notebook.md, "Projected scanline
//! voxelizer").

use crate::overlap::TriSetup;
use crate::Mode;
use std::cell::RefCell;

/// Relative slack of the floating-point column ends: an end is rounded outwards by this much
/// of the magnitudes involved (f64 rounding is ~1e-16 of them), so the estimate holds the exact
/// interval; the predicates then settle it.
const REL_SLACK: f64 = 1e-9;

/// Side constraints must be slack by this many voxels (times the constraint's normal length) at
/// the corners of the band's parallelogram for a run; far above the f64 rounding of that
/// evaluation (~1e-10 for coordinates below 2^20), so a run never reaches a tie.
const RUN_MARGIN: f64 = 1e-6;

/// Shortest column range of a slice for which a run is worth finding.
const MIN_RUN: i32 = 3;

/// Triangles whose window spans fewer columns than this in x or y go to [`TriSetup::scan`]
/// (the same voxels): on them the slice setup costs more than it saves (measured:
/// docs/journal/benchmarks-notebook.md, "Projected scanline voxelizer").
const SMALL: i32 = 32;

/// A dominant-projection edge `a·x + b·y + c ≥ 0` as a bound on the columns y of slice x:
/// `y ≥ −(c + a·x)/b` if `lower` (`b > 0`), else `y ≤` (`b < 0`); `inv_b = 0` for `b = 0`
/// (the edge does not depend on y).
#[derive(Clone, Copy, Debug)]
struct ColumnBound {
    a: f64,
    c: f64,
    inv_b: f64,
    lower: bool,
}

/// A side constraint evaluated on a line bounding the depth band, as a linear function of the
/// column: `h(x, y) = α·y + β0 + β1·x`, which must reach `mu`.
#[derive(Clone, Copy, Debug)]
struct RunBound {
    alpha: f64,
    inv_alpha: f64,
    beta0: f64,
    beta1: f64,
    mu: f64,
}

/// Per-triangle setup of the slice loop.
struct Slices {
    cols: [ColumnBound; 3],
    run: [RunBound; 12],
}

impl Slices {
    fn new(s: &TriSetup) -> Slices {
        let cols = [0, 1, 2].map(|i| {
            let [a, b] = s.ne[0][i];
            ColumnBound {
                a,
                c: s.de[0][i],
                inv_b: if b != 0.0 { 1.0 / b } else { 0.0 },
                lower: b > 0.0,
            }
        });
        // the depth band's bounding lines z = (d − n_x x − n_y y) / n_z + off: below, d_lo and
        // −1 (the lower end is ⌈f⌉ − 1 ≥ f − 1); above, d_hi and 0 (the upper end is ⌊g⌋ ≤ g)
        let n = s.n;
        let (gx, gy) = (-n[0] / n[2], -n[1] / n[2]);
        // with world coordinates ([`TriSetup::with_world`]) the exact depth range and side
        // functions may differ from these by the perturbation of the f32 grid coordinates: the
        // lines move out by it and each margin grows by it
        let (de, dp) = s.perturbation_band();
        let dz = 2.0 * dp / n[2];
        let lines = [s.d_lo / n[2] - 1.0 - dz, s.d_hi / n[2] + dz];
        let mut run = [RunBound {
            alpha: 0.0,
            inv_alpha: 0.0,
            beta0: 0.0,
            beta1: 0.0,
            mu: 0.0,
        }; 12];
        let mut k = 0;
        for z0 in lines {
            // z = z0 + gx·x + gy·y
            for i in 0..3 {
                // YZ: A·y + B·z + C
                let [a, b] = s.ne[1][i];
                let c = s.de[1][i];
                run[k] = RunBound {
                    alpha: a + b * gy,
                    inv_alpha: 1.0 / (a + b * gy),
                    beta0: c + b * z0,
                    beta1: b * gx,
                    mu: RUN_MARGIN * (a.abs() + b.abs()) + 2.0 * de,
                };
                k += 1;
                // ZX: A·z + B·x + C
                let [a, b] = s.ne[2][i];
                let c = s.de[2][i];
                run[k] = RunBound {
                    alpha: a * gy,
                    inv_alpha: 1.0 / (a * gy),
                    beta0: c + a * z0,
                    beta1: b + a * gx,
                    mu: RUN_MARGIN * (a.abs() + b.abs()) + 2.0 * de,
                };
                k += 1;
            }
        }
        Slices { cols, run }
    }

    /// The columns of slice `x` in `[ylo, yhi]` that can pass the dominant-projection tests,
    /// rounded outwards (a superset of the exact ones; possibly empty).
    #[inline]
    fn columns(&self, x: f64, ylo: i32, yhi: i32) -> (i32, i32) {
        let (mut a, mut b) = (ylo as f64, yhi as f64);
        for e in &self.cols {
            let ax = e.a * x;
            if e.inv_b == 0.0 {
                // a column-independent edge: all or nothing (up to rounding: leave near-ties
                // to the predicate)
                if ax + e.c < -REL_SLACK * (ax.abs() + e.c.abs()) {
                    return (1, 0);
                }
                continue;
            }
            let t = (-e.c - ax) * e.inv_b;
            let slack = REL_SLACK * (1.0 + (e.c.abs() + ax.abs()) * e.inv_b.abs());
            if slack.is_nan() || slack >= 0.25 {
                continue; // ill-conditioned: no bound from this edge
            }
            if e.lower {
                a = a.max((t - slack).ceil());
            } else {
                b = b.min((t + slack).floor());
            }
        }
        if a > b {
            return (1, 0);
        }
        (a as i32, b as i32)
    }

    /// The run of slice `x` within `[ya, yb]`: the columns on which every side constraint is
    /// slack by its margin on the band's bounding lines.
    #[inline]
    fn run(&self, x: f64, ya: i32, yb: i32) -> (i32, i32) {
        let (mut a, mut b) = (ya as f64, yb as f64);
        for r in &self.run {
            // α·y ≥ μ − β
            let rhs = r.mu - (r.beta0 + r.beta1 * x);
            let q = rhs * r.inv_alpha;
            if r.alpha > 0.0 && q.is_finite() {
                a = a.max(q.ceil());
            } else if r.alpha < 0.0 && q.is_finite() {
                b = b.min(q.floor());
            } else if r.alpha != 0.0 || rhs > 0.0 || rhs.is_nan() {
                // a bound out of range (or not a number): no run in this slice
                return (1, 0);
            }
            if a > b {
                return (1, 0);
            }
        }
        (a as i32, b as i32)
    }
}

/// Settles the interval of `[lo, hi]` where `m` holds, an interval by assumption, from the
/// estimate `[a, b]` (which should contain it): steps in from each end while `m` fails, then
/// out while it holds beyond. `None` if `m` holds nowhere in `[a, b]`.
#[inline]
fn settle(mut a: i32, mut b: i32, lo: i32, hi: i32, m: impl Fn(i32) -> bool) -> Option<(i32, i32)> {
    a = a.max(lo);
    b = b.min(hi);
    while a <= b && !m(a) {
        a += 1;
    }
    if a > b {
        return None;
    }
    while a > lo && m(a - 1) {
        a -= 1;
    }
    while !m(b) {
        b -= 1;
    }
    while b < hi && m(b + 1) {
        b += 1;
    }
    Some((a, b))
}

/// A column outside the run: its depth scanline settled at both ends with `side_inside`,
/// stepping inwards (the voxels passing the side tests along it form an interval).
#[inline]
fn settled_column(
    s: &TriSetup,
    x: i32,
    y: i32,
    zl: i32,
    zh: i32,
    emit: &mut impl FnMut([i32; 3], bool),
) {
    let Some((d0, d1)) = s.column_depth(x, y, zl, zh) else {
        return;
    };
    let mut z0 = d0;
    while z0 <= d1 && !s.side_inside([x, y, z0]) {
        z0 += 1;
    }
    if z0 > d1 {
        return;
    }
    let mut z1 = d1;
    while !s.side_inside([x, y, z1]) {
        z1 -= 1;
    }
    for z in z0..=z1 {
        emit([x, y, z], z == z0);
    }
}

/// The projected scanline voxelizer: calls `emit(p, first)` for exactly the voxels that
/// [`TriSetup::scan`] emits for `[lo, hi]` (swizzled, inclusive), in the same order (x, then y,
/// then z) with the same `first` flags (the first voxel of each (x, y) column).
pub fn scan(s: &TriSetup, lo: [i32; 3], hi: [i32; 3], emit: impl FnMut([i32; 3], bool)) {
    let lo = [0, 1, 2].map(|k| lo[k].max(s.bmin[k]));
    let hi = [0, 1, 2].map(|k| hi[k].min(s.bmax[k]));
    if (0..3).any(|k| lo[k] > hi[k]) {
        return;
    }
    if hi[0] - lo[0] + 1 < SMALL || hi[1] - lo[1] + 1 < SMALL {
        // a small triangle: the overlap tests' own column loop (the same voxels) is faster
        return s.scan(lo, hi, emit);
    }
    scan_slices(s, lo, hi, emit);
}

/// The slices of [`scan`] for a triangle of any size (`scan` runs them on triangles spanning
/// at least `SMALL` columns): the same voxels, order and flags as [`TriSetup::scan`].
pub fn scan_slices(s: &TriSetup, lo: [i32; 3], hi: [i32; 3], mut emit: impl FnMut([i32; 3], bool)) {
    let lo = [0, 1, 2].map(|k| lo[k].max(s.bmin[k]));
    let hi = [0, 1, 2].map(|k| hi[k].min(s.bmax[k]));
    if (0..3).any(|k| lo[k] > hi[k]) {
        return;
    }
    let (zl, zh) = (lo[2], hi[2]);
    let sl = Slices::new(s);
    // a run rests on a float margin: only where it is far above the exact predicates' rounding
    // bound (always for grid coordinates below about 2²², never for a triangle decided
    // exactly throughout, e.g. a projection whose f64 orientation was wrong)
    let runs = 100.0 * s.side_slack() <= RUN_MARGIN;

    for x in lo[0]..=hi[0] {
        let xf = x as f64;
        // 1. the slice's columns
        let (ea, eb) = sl.columns(xf, lo[1], hi[1]);
        let Some((ya, yb)) = settle(ea, eb, lo[1], hi[1], |y| s.column_inside(x, y)) else {
            continue;
        };
        // 3. the run where the side tests cannot cut, checked at its ends
        let (mut ra, mut rb) = (1, 0);
        if runs && yb - ya + 1 >= MIN_RUN {
            let (a, b) = sl.run(xf, ya, yb);
            if b - a + 1 >= MIN_RUN {
                let corner = |y: i32| match s.column_depth(x, y, zl, zh) {
                    Some((d0, d1)) => s.side_inside([x, y, d0]) && s.side_inside([x, y, d1]),
                    None => true,
                };
                if corner(a) && corner(b) {
                    (ra, rb) = (a, b);
                }
            }
        }
        if ra > rb {
            for y in ya..=yb {
                settled_column(s, x, y, zl, zh, &mut emit);
            }
            continue;
        }
        for y in ya..ra {
            settled_column(s, x, y, zl, zh, &mut emit);
        }
        // 2. the run: whole depth scanlines
        for y in ra..=rb {
            if let Some((z0, z1)) = s.column_depth(x, y, zl, zh) {
                for z in z0..=z1 {
                    emit([x, y, z], z == z0);
                }
            }
        }
        for y in rb + 1..=yb {
            settled_column(s, x, y, zl, zh, &mut emit);
        }
    }
}

/// One voxel of an ILV path.
pub type P3 = [i64; 3];

/// ILV, the paper's MARKLINEILV: the 6-connected voxel path from `p0` to `p1` (both marked),
/// stepping along the axis whose next facet is nearest, with the integer distances
/// `L_k = (2i + 1)·M_k`, `M_k` the product of the other axes' extents (axes of zero extent are
/// never stepped; the paper's formula would step them forever). Ties go to the lowest axis.
pub fn ilv_line(p0: P3, p1: P3, mut mark: impl FnMut(P3)) {
    let d = [0, 1, 2].map(|k| p1[k] - p0[k]);
    let ad = d.map(|c| c.abs());
    let step = d.map(|c| c.signum());
    let prod = |k: usize| -> i64 {
        (0..3)
            .filter(|&j| j != k && ad[j] != 0)
            .map(|j| ad[j])
            .product()
    };
    let m = [0, 1, 2].map(|k| if ad[k] == 0 { 0 } else { prod(k) });
    let mut l = [0, 1, 2].map(|k| if ad[k] == 0 { i64::MAX } else { m[k] });
    let mut p = p0;
    mark(p);
    let total = ad[0] + ad[1] + ad[2];
    for _ in 0..total {
        let mut k = 0;
        for j in 1..3 {
            if l[j] < l[k] {
                k = j;
            }
        }
        let lmin = l[k];
        p[k] += step[k];
        for lj in &mut l {
            if *lj != i64::MAX {
                *lj -= lmin;
            }
        }
        l[k] = 2 * m[k];
        mark(p);
    }
    debug_assert_eq!(p, p1);
}

/// The integer scanline interval (equations 8–9): from entry `i` of `side`, the furthest next
/// entry whose distance from the scanline through `pa`, `pb` stays within the optimal
/// interval, i.e. `|ΔY·(X' − X_A) − ΔX·(Y' − Y_A)| ≤ |ΔX| + |ΔY|` (`pa` the current end on
/// this side).
fn next_end(side: &[P3], mut i: usize, pa: P3, pb: P3) -> usize {
    let (dx, dy) = (pa[0] - pb[0], pa[1] - pb[1]);
    if dx == 0 && dy == 0 {
        // both ends in one voxel: no line to measure from, take the next entry
        return (i + 1).min(side.len() - 1);
    }
    let w = dx.abs() + dy.abs();
    while i + 1 < side.len() {
        let q = side[i + 1];
        if (dy * (q[0] - pa[0]) - dx * (q[1] - pa[1])).abs() > w {
            break;
        }
        i += 1;
    }
    i
}

thread_local! {
    static ILV_BUF: RefCell<(Vec<P3>, Vec<P3>, Vec<u64>)> = const {
        RefCell::new((Vec::new(), Vec::new(), Vec::new()))
    };
}

/// The ILV approximation (Algorithm 1 of the paper): calls `emit(p, first)` for each voxel in
/// `[lo, hi]` (swizzled, inclusive) that the integer-only scanlines mark, once each, in the
/// order of [`scan`]. Approximate: see the module docs. Conservative mode only (asserted).
pub fn scan_ilv(s: &TriSetup, lo: [i32; 3], hi: [i32; 3], mut emit: impl FnMut([i32; 3], bool)) {
    assert_eq!(
        s.mode,
        Mode::Conservative,
        "scanline-ilv approximates the conservative set only"
    );
    let lo = [0, 1, 2].map(|k| lo[k].max(s.bmin[k]));
    let hi = [0, 1, 2].map(|k| hi[k].min(s.bmax[k]));
    if (0..3).any(|k| lo[k] > hi[k]) {
        return;
    }
    let lo64 = lo.map(|c| c as i64);
    let hi64 = hi.map(|c| c as i64);
    ILV_BUF.with(|b| {
        let (q1, q2, keys) = &mut *b.borrow_mut();
        q1.clear();
        q2.clear();
        keys.clear();
        let mut mark = |p: P3| {
            if (0..3).all(|k| p[k] >= lo64[k] && p[k] <= hi64[k]) {
                let r = [0, 1, 2].map(|k| (p[k] - lo64[k]) as u64);
                keys.push(r[0] << 42 | r[1] << 21 | r[2]);
            }
        };
        // the vertices' voxels (voxel p is [p, p+1]³), sorted along the dominant axis
        let mut v = s
            .v
            .map(|q| q.map(|c| c.floor().clamp(-(1i64 << 24) as f64, (1i64 << 24) as f64) as i64));
        v.sort_by_key(|p| p[2]);
        let [p0, p1, p2] = v;
        // the edges: Q1 = P0 → P1 → P2, Q2 = P0 → P2 (z non-decreasing along both)
        ilv_line(p0, p1, |p| q1.push(p));
        q1.pop();
        ilv_line(p1, p2, |p| q1.push(p));
        ilv_line(p0, p2, |p| q2.push(p));
        for p in q1.iter().chain(q2.iter()) {
            mark(*p);
        }
        // the slices along the dominant axis, each filled with scanlines between the paths
        let (mut i1, mut i2) = (0usize, 0usize);
        for z in p0[2]..=p2[2] {
            let s1 = i1;
            while i1 < q1.len() && q1[i1][2] == z {
                i1 += 1;
            }
            let s2 = i2;
            while i2 < q2.len() && q2[i2][2] == z {
                i2 += 1;
            }
            if z < lo64[2] || z > hi64[2] || s1 == i1 || s2 == i2 {
                continue;
            }
            let (sa, sb) = (&q1[s1..i1], &q2[s2..i2]);
            let (mut ia, mut ib) = (0, 0);
            loop {
                let (pa, pb) = (sa[ia], sb[ib]);
                ilv_line(pa, pb, &mut mark);
                if ia + 1 == sa.len() && ib + 1 == sb.len() {
                    break;
                }
                ia = next_end(sa, ia, pa, pb);
                ib = next_end(sb, ib, pb, pa);
            }
        }
        keys.sort_unstable();
        keys.dedup();
        let mut col = u64::MAX;
        for &k in keys.iter() {
            let p = [
                lo[0] + (k >> 42) as i32,
                lo[1] + ((k >> 21) & 0x1f_ffff) as i32,
                lo[2] + (k & 0x1f_ffff) as i32,
            ];
            let c = k >> 21;
            emit(p, c != col);
            col = c;
        }
    });
}

/// [`crate::voxelize_triangle`] with a choice of method: calls `emit(voxel)` (grid
/// coordinates) for every voxel in `[bmin, bmax]` that `method` marks, in the order swizzled
/// x, y, z.
pub fn voxelize_triangle_with(
    v: &[[f32; 3]; 3],
    bmin: [i32; 3],
    bmax: [i32; 3],
    mode: Mode,
    method: crate::Method,
    emit: &mut impl FnMut([i32; 3]),
) {
    let Some(s) = TriSetup::new(v, mode) else {
        return;
    };
    let (lo, hi) = (s.swizzle(bmin), s.swizzle(bmax));
    let f = |p, _| emit(s.unswizzle(p));
    match method {
        crate::Method::Sat => s.scan(lo, hi, f),
        crate::Method::Scanline => scan(&s, lo, hi, f),
        crate::Method::ScanlineIlv => scan_ilv(&s, lo, hi, f),
    }
}
