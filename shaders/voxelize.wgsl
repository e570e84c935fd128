// Shared routines of the GPU hybrid voxelizer: Rauwendaal & Bailey, "Hybrid Computational
// Voxelization Using the Graphics Pipeline", JCGT 2(1) 2013, sections 3.1-3.6 and the Appendix
// (Figures 17 and 18).
//
// This file is appended to classify.wgsl (compute) and raster.wgsl (render); those declare the
// bindings used here: params, tris, occ, base, accum, counter. `real` is f64 when the adapter
// has SHADER_F64 and f32 otherwise; the host prepends the alias and the constants UNIT (the
// unit roundoff of `real`, 2^-53 or 2^-24) and TINY (absolute slack for underflow).
//
// Every formula mirrors crates/voxelize (overlap.rs, clip.rs) operation by operation. The overlap
// decisions are filtered as on the CPU (overlap.rs, `TriSetup::new`): each value is compared with
// the same forward error bound, computed with `real`'s unit roundoff. A value inside its band is
// not trusted: the decision counts as outside (so the triangle marks a subset of its exact set)
// and the triangle is *listed* (`note_uncertain`): its index goes to a list in `counter`, which
// the host reads after marking; the host decides the listed triangles exactly on the CPU, sets
// their voxels' bits before compaction and adds their attributes itself. In the accumulation
// phase the host overwrites the listed triangles with degenerate ones (skipped). A triangle
// whose normal component has an uncertain sign is listed before it marks anything.
//
// Certified triangles (f64 only; the host sets TRI_EXACT_* in the triangle's flags,
// crates/gpu/src/fallback.rs `exact_flags`): when every coordinate is a multiple of 2^-q and
// (max |v| + 2)·2^q < 2^24,
// every product and sum of the normal and of the edge functions is an integer multiple of
// 2^-2q (2^-2q-1 in thin mode) below 2^53, so f64 computes them without rounding and f >= 0
// decides; below 2^14 the same holds for the depth predicates (multiples
// of 2^-3q-1 below 2^53; a fused multiply-add rounds an exact value, so it changes nothing).
// A face in an axis plane z = c (two normal components exactly 0) gets its depth range from
// integer comparisons with c instead of the plane predicates: voxel z meets the plane iff
// z <= c <= z + 1 (the box and the diamond alike). Ties count as inside, as the CPU's exact
// predicates decide them (the closed box counts).
//
// World coordinates (issue 32 §1): the host feeds f32 grid coordinates `Grid::to_grid` of the
// input's world positions and flags a triangle TRI_ROUNDED when some coordinate is not exactly
// the image of its world value (crates/gpu/src/fallback.rs `world_flags`). The decisions must be
// those of the exact image (crates/voxelize/src/world.rs), so for such a triangle every band is
// widened by what the rounding can move its value (world.rs `Perturbation`: each coordinate
// within eta = 2^-23 M of the exact one, M its largest magnitude; `perturbation` below), the
// certificates are off (the host sets no TRI_EXACT_* flags), and the two discontinuous
// decisions that a rounding onto an integer can flip are listed: a bounding box end on an
// integer and an axis-plane face on an integer (to_grid is monotone and keeps integers, so a
// coordinate off an integer is on the same side of every integer as its exact image). A zero
// coordinate difference must be a zero of the world values (else TRI_TIES_BROKEN, listed): then
// a normal component whose products are all 0 is 0 in the world too.
const MODE_CONSERVATIVE: u32 = 0u;
const MODE_THIN: u32 = 1u;
const PHASE_MARK: u32 = 0u;
const PHASE_ACCUMULATE: u32 = 1u;
const TRI_HAS_NORMALS: u32 = 1u;
// flags in counter[3]: a decision's value inside its error band / a normal component's sign
// uncertain (then the triangle's whole setup is in doubt)
const UNCERTAIN_DECISION: u32 = 1u;
const UNCERTAIN_NORMAL: u32 = 2u;
// Triangle flags set by the host (crates/gpu/src/fallback.rs `exact_flags`, f64 only)
const TRI_EXACT_EDGES: u32 = 256u;
const TRI_EXACT_DEPTH: u32 = 512u;
// the grid coordinates are not all the exact images of the world ones / a zero difference of
// them is not one of the world values (crates/gpu/src/fallback.rs `world_flags`)
const TRI_ROUNDED: u32 = 1024u;
const TRI_TIES_BROKEN: u32 = 2048u;
// counter[4]: listed triangles (append attempts; more than LIST_CAP = overflow);
// counter[LIST_FLAGS..]: one bit per triangle of the batch (listed); counter[LIST_AT..]: the
// listed triangles' indices in the chunk's stream (params.tri_base + batch index).
// crates/gpu/src/voxelizer.rs has the same constants.
const LIST_COUNT: u32 = 4u;
const LIST_FLAGS: u32 = 8u;
const LIST_AT: u32 = 2056u; // LIST_FLAGS + 65536 / 32
const LIST_CAP: u32 = 65536u;
const CHUNK: i32 = 256;
// accumulator words per voxel slot: 16 fixed-point sums of three u32 words each
const SLOT_WORDS: u32 = 48u;
// word offset of fixed-point sum k in a slot
fn sum_at(off: u32, k: u32) -> u32 {
    return off + 3u * k;
}

struct Params {
    // chunk origin, grid voxels
    origin: vec3<i32>,
    mode: u32,
    tri_count: u32,
    // triangles whose dominant 2D projected area (voxels²) is below this are voxelized in the
    // classification pass; the others are deferred to the fragment pass
    cutoff: f32,
    phase: u32,
    slot_lo: u32,
    slot_hi: u32,
    groups_x: u32,
    // index of the batch's first triangle in the chunk's stream of (finite) triangles
    tri_base: u32,
    _pad1: u32,
};

// voxlod_geom::Triangle, 88 bytes
struct Tri {
    v: array<f32, 9>,
    n: array<f32, 9>,
    c: array<u32, 3>,
    flags: u32,
};

// A deferred (large) triangle: its dilated dominant projection in chunk-local voxel units.
struct Deferred {
    a: vec2<f32>,
    b: vec2<f32>,
    c: vec2<f32>,
    tri: u32,
    _pad: u32,
    // the triangle's column range in the chunk (chunk-local, swizzled): fragments of the
    // dilated triangle outside it are discarded before the setup (the dilated vertices of a
    // sliver lie far away, Hertel's miters)
    lo: vec2<i32>,
    hi: vec2<i32>,
};

// Per-triangle setup (paper 3.1.2), swizzled so that the dominant axis is z.
struct Setup {
    ok: bool,
    axis: u32,
    v0: vec3<real>,
    v1: vec3<real>,
    v2: vec3<real>,
    // swizzled normal (v1-v0)x(v2-v0), made n.z > 0
    n: vec3<real>,
    // |n_z| / 2: the projected area in voxels²
    area2d: real,
    // inward edge normals per projection (XY on (x,y), YZ on (y,z), ZX on (z,x)) and distances
    xy0: vec2<real>, xy1: vec2<real>, xy2: vec2<real>, dxy: vec3<real>,
    yz0: vec2<real>, yz1: vec2<real>, yz2: vec2<real>, dyz: vec3<real>,
    zx0: vec2<real>, zx1: vec2<real>, zx2: vec2<real>, dzx: vec3<real>,
    d_lo: real,
    d_hi: real,
    // error bounds of the edge functions (same numbering as dxy, dyz, dzx) and of the depth
    // predicates (overlap.rs `be`, `bp`)
    bxy: vec3<real>,
    byz: vec3<real>,
    bzx: vec3<real>,
    bp: real,
    // a face in the axis plane z = plane_z (swizzled): the depth range is exact integer arithmetic
    axis_face: bool,
    plane_z: real,
    // swizzled voxel range: closed bounding box clamped to the chunk
    lo: vec3<i32>,
    hi: vec3<i32>,
    // TRI_ROUNDED: how far each grid coordinate may be from its exact image (else 0)
    eta: real,
};

fn sgn(x: real) -> real {
    if x > real(0.0) { return real(1.0); }
    if x < real(0.0) { return real(-1.0); }
    return real(0.0);
}

fn swizzle_r(p: vec3<real>, axis: u32) -> vec3<real> {
    if axis == 0u { return p.yzx; }
    if axis == 1u { return p.zxy; }
    return p;
}

fn swizzle_i(p: vec3<i32>, axis: u32) -> vec3<i32> {
    if axis == 0u { return p.yzx; }
    if axis == 1u { return p.zxy; }
    return p;
}

fn unswizzle_i(p: vec3<i32>, axis: u32) -> vec3<i32> {
    if axis == 0u { return p.zxy; }
    if axis == 1u { return p.yzx; }
    return p;
}

fn unswizzle_r(p: vec3<real>, axis: u32) -> vec3<real> {
    if axis == 0u { return p.zxy; }
    if axis == 1u { return p.yzx; }
    return p;
}

fn vertex(ti: u32, i: u32) -> vec3<real> {
    let b = 3u * i;
    return vec3<real>(real(tris[ti].v[b]), real(tris[ti].v[b + 1u]), real(tris[ti].v[b + 2u]));
}

fn cross_r(a: vec3<real>, b: vec3<real>) -> vec3<real> {
    return vec3<real>(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}

fn dot_r(a: vec3<real>, b: vec3<real>) -> real {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

// (edge normal, edge distance) of one edge in one projection; `a` = projected start vertex.
fn edge_d(nk: vec2<real>, a: vec2<real>, mode: u32) -> real {
    let base = -(nk.x * a.x + nk.y * a.y);
    if mode == MODE_CONSERVATIVE {
        // most interior corner of the unit square
        return base + max(nk.x, real(0.0)) + max(nk.y, real(0.0));
    }
    // most interior vertex of the diamond inscribed in the unit square
    return base + real(0.5) * (nk.x + nk.y) + real(0.5) * max(abs(nk.x), abs(nk.y));
}

// The triangle being voxelized by this invocation (set by `setup`).
var<private> cur_tri: u32;

// Lists the current triangle (mark phase only; in the accumulation phase the host has replaced
// the listed triangles by degenerate ones, and the others meet the same decisions as in
// marking).
fn note_uncertain(kind: u32) {
    if params.phase != PHASE_MARK {
        return;
    }
    if (atomicLoad(&counter[3]) & kind) == 0u {
        atomicOr(&counter[3], kind);
    }
    let ti = cur_tri;
    let w = LIST_FLAGS + (ti >> 5u);
    let bit = 1u << (ti & 31u);
    if (atomicLoad(&counter[w]) & bit) != 0u {
        return;
    }
    let old = atomicOr(&counter[w], bit);
    if (old & bit) == 0u {
        let i = atomicAdd(&counter[LIST_COUNT], 1u);
        if i < LIST_CAP {
            atomicStore(&counter[LIST_AT + i], params.tri_base + ti);
        }
    }
}

// The current triangle's exactness (TRI_EXACT_* flags set by the host): 2 = edge functions,
// normal and depth predicates computed without rounding, 1 = edge functions and normal, 0 = none.
var<private> cur_level: i32;
// Whether the current column met a value inside its band that the level does not settle.
var<private> unc: bool;

// The filtered predicate `exact >= 0` from its computed value f, |f - exact| <= b (overlap.rs
// `at_least_zero`): certain outside [-b, b). Inside, if the triangle's arithmetic is exact for
// this kind of decision (`cur_level >= need`: 1 for edge functions, 2 for depth predicates), f
// is the exact value and f >= 0 decides (ties inside); otherwise the decision counts as outside
// and `unc` is set (the column then lists the triangle). Kept small: llvmpipe runs the code of
// a branch no lane takes too.
fn at_least_zero(f: real, b: real, need: i32) -> bool {
    if f >= b {
        return true;
    }
    if f < -b {
        return false;
    }
    if cur_level >= need {
        return f >= real(0.0);
    }
    unc = true;
    return false;
}

fn max_abs(v: vec3<real>) -> real {
    return max(max(abs(v.x), abs(v.y)), abs(v.z));
}

// Bound of an edge function with inward normal nk (overlap.rs: 8u(|ne0|+|ne1|)(2M+1), plus
// `de` of the perturbation; 0 for a projection of zero area, whose edge functions are exactly 0,
// in the world values too when the ties hold).
fn edge_bound(nk: vec2<real>, big_m: real, de: real) -> real {
    let w = abs(nk.x) + abs(nk.y);
    if w == real(0.0) {
        return real(0.0);
    }
    return real(8.0) * UNIT * w * (real(2.0) * big_m + real(1.0)) + TINY + de;
}

// How far a TRI_ROUNDED triangle's decisions may move between its f32 grid coordinates and
// their exact images (world.rs `Perturbation::of`, the same formulas and the same 1 % room,
// which also covers their rounding here): (eta, dn, de, dp0) for a coordinate, a normal
// component, an edge function, the depth predicates (without the 2.02 eta sum|n_k| part).
fn perturbation(o0: vec3<real>, o1: vec3<real>, o2: vec3<real>) -> vec4<real> {
    let m = max(max(max_abs(o0), max_abs(o1)), max_abs(o2));
    let eta = m * real(1.1920928955078125e-7) + ETA_MIN;
    let ext = max(max(o0, o1), o2) - min(min(o0, o1), o2);
    let e = max(max(ext.x, ext.y), ext.z) + real(2.0) * eta;
    let dn = real(8.0) * eta * (e + eta) * real(1.01);
    let de = real(8.0) * eta * (e + real(1.0)) * real(1.01);
    let dp0 = (real(3.0) * dn * (e + real(2.0)) + real(6.0) * eta * dn) * real(1.01);
    return vec4<real>(eta, dn, de, dp0);
}

fn clamp_i32(x: real) -> i32 {
    return i32(clamp(x, real(-2147483648.0), real(2147483520.0)));
}

// The setup of triangle `ti` in chunk `params.origin` (TriSetup::new plus the chunk clamp).
fn setup(ti: u32) -> Setup {
    var s: Setup;
    s.ok = false;
    cur_tri = ti;
    let fl = tris[ti].flags;
    cur_level = select(select(0, 1, (fl & TRI_EXACT_EDGES) != 0u), 2, (fl & TRI_EXACT_DEPTH) != 0u);
    let o0 = vertex(ti, 0u);
    let o1 = vertex(ti, 1u);
    let o2 = vertex(ti, 2u);
    if (fl & TRI_TIES_BROKEN) != 0u {
        // a zero difference of the grid coordinates is not one of the world values
        note_uncertain(UNCERTAIN_NORMAL);
        return s;
    }
    let rounded = (fl & TRI_ROUNDED) != 0u;
    var pert = vec4<real>(real(0.0));
    if rounded {
        pert = perturbation(o0, o1, o2);
        cur_level = 0;
    }
    s.eta = pert.x;
    let no = cross_r(o1 - o0, o2 - o0);
    // A_k, the magnitude of the two products of n_k; a component with |n_k| <= 5u A_k may have
    // the wrong sign (overlap.rs), which only the CPU's exact orient2d settles
    let ea = o1 - o0;
    let eb = o2 - o0;
    let mag = vec3<real>(
        abs(ea.y * eb.z) + abs(ea.z * eb.y),
        abs(ea.z * eb.x) + abs(ea.x * eb.z),
        abs(ea.x * eb.y) + abs(ea.y * eb.x));
    for (var k = 0u; k < 3u; k++) {
        if mag[k] != real(0.0) && abs(no[k]) <= real(5.0) * UNIT * mag[k] + pert.y && cur_level < 1 {
            // the orientation is in doubt: the host decides the whole triangle
            note_uncertain(UNCERTAIN_NORMAL);
            return s;
        }
    }
    if no.x == real(0.0) && no.y == real(0.0) && no.z == real(0.0) {
        return s;
    }
    let an = abs(no);
    var axis = 2u;
    if an.z >= an.x && an.z >= an.y {
        axis = 2u;
    } else if an.x >= an.y {
        axis = 0u;
    } else {
        axis = 1u;
    }
    s.axis = axis;
    let v0 = swizzle_r(o0, axis);
    let v1 = swizzle_r(o1, axis);
    let v2 = swizzle_r(o2, axis);
    s.v0 = v0;
    s.v1 = v1;
    s.v2 = v2;
    var n = swizzle_r(no, axis);
    let sx = sgn(n.x);
    let sy = sgn(n.y);
    let sz = sgn(n.z);
    let mode = params.mode;
    let e0 = v1 - v0;
    let e1 = v2 - v1;
    let e2 = v0 - v2;
    s.xy0 = vec2<real>(sz * -e0.y, sz * e0.x);
    s.xy1 = vec2<real>(sz * -e1.y, sz * e1.x);
    s.xy2 = vec2<real>(sz * -e2.y, sz * e2.x);
    s.yz0 = vec2<real>(sx * -e0.z, sx * e0.y);
    s.yz1 = vec2<real>(sx * -e1.z, sx * e1.y);
    s.yz2 = vec2<real>(sx * -e2.z, sx * e2.y);
    s.zx0 = vec2<real>(sy * -e0.x, sy * e0.z);
    s.zx1 = vec2<real>(sy * -e1.x, sy * e1.z);
    s.zx2 = vec2<real>(sy * -e2.x, sy * e2.z);
    s.dxy = vec3<real>(edge_d(s.xy0, v0.xy, mode), edge_d(s.xy1, v1.xy, mode), edge_d(s.xy2, v2.xy, mode));
    s.dyz = vec3<real>(edge_d(s.yz0, v0.yz, mode), edge_d(s.yz1, v1.yz, mode), edge_d(s.yz2, v2.yz, mode));
    s.dzx = vec3<real>(edge_d(s.zx0, v0.zx, mode), edge_d(s.zx1, v1.zx, mode), edge_d(s.zx2, v2.zx, mode));
    // M: the largest coordinate magnitude the scan can reach (bounding box, plus the corners)
    let big_m = max(max(max_abs(v0), max_abs(v1)), max_abs(v2)) + real(2.0);
    s.bxy = vec3<real>(edge_bound(s.xy0, big_m, pert.z), edge_bound(s.xy1, big_m, pert.z), edge_bound(s.xy2, big_m, pert.z));
    s.byz = vec3<real>(edge_bound(s.yz0, big_m, pert.z), edge_bound(s.yz1, big_m, pert.z), edge_bound(s.yz2, big_m, pert.z));
    s.bzx = vec3<real>(edge_bound(s.zx0, big_m, pert.z), edge_bound(s.zx1, big_m, pert.z), edge_bound(s.zx2, big_m, pert.z));
    // a face in an axis plane: the two other normal components are exactly 0 (all their
    // products are, and no product of f32 differences underflows in f64)
    let axis_face = EXACT_TIES && ((mag.x == real(0.0) && mag.y == real(0.0))
        || (mag.y == real(0.0) && mag.z == real(0.0))
        || (mag.z == real(0.0) && mag.x == real(0.0)));
    s.axis_face = axis_face;
    if n.z < real(0.0) {
        n = -n;
    }
    s.bp = real(16.0) * UNIT * (mag.x + mag.y + mag.z) * (real(2.0) * big_m + real(2.0)) + TINY
        + pert.w + real(2.02) * pert.x * (abs(n.x) + abs(n.y) + abs(n.z));
    s.n = n;
    s.plane_z = v0.z;
    s.area2d = real(0.5) * n.z;
    let dp = n.x * v0.x + n.y * v0.y + n.z * v0.z;
    if mode == MODE_CONSERVATIVE {
        s.d_lo = dp - max(n.x, real(0.0)) - max(n.y, real(0.0));
        s.d_hi = dp - min(n.x, real(0.0)) - min(n.y, real(0.0));
    } else {
        let c = dp - real(0.5) * n.x - real(0.5) * n.y;
        s.d_lo = c;
        s.d_hi = c;
    }
    let mn = min(min(v0, v1), v2);
    let mx = max(max(v0, v1), v2);
    let bmin = vec3<i32>(clamp_i32(ceil(mn.x) - real(1.0)), clamp_i32(ceil(mn.y) - real(1.0)), clamp_i32(ceil(mn.z) - real(1.0)));
    let bmax = vec3<i32>(clamp_i32(floor(mx.x)), clamp_i32(floor(mx.y)), clamp_i32(floor(mx.z)));
    let clo = swizzle_i(params.origin, axis);
    let chi = clo + vec3<i32>(CHUNK - 1);
    s.lo = max(bmin, clo);
    s.hi = min(bmax, chi);
    if rounded && all(s.lo <= s.hi) {
        // a box end the rounding put on an integer may be one voxel off for the exact image
        // (voxel mn - 1 touches it at mn, voxel mx at mx), and so may an axis-plane face's
        // depth range (z = c on an integer): listed when that voxel layer is in the chunk
        let lo_on = (mn == floor(mn)) & (bmin >= clo);
        let hi_on = (mx == floor(mx)) & (bmax <= chi);
        let face_on = axis_face && s.plane_z == floor(s.plane_z);
        if any(lo_on) || any(hi_on) || face_on {
            note_uncertain(UNCERTAIN_DECISION);
            return s;
        }
    }
    s.ok = all(s.lo <= s.hi);
    return s;
}

// One (x, y) column of the dominant projection (Figure 17/18 lines 15-20, with the corrected
// depth range of overlap.rs): emits every overlapped voxel of the column. Every decision is
// filtered (`at_least_zero`); the depth range is settled as in overlap.rs `depth`. The scanned
// voxels lie in the triangle's closed bounding box, where the bounds hold.
fn column(s: Setup, ti: u32, px: i32, py: i32) {
    unc = false;
    column_scan(s, ti, px, py);
    if unc {
        note_uncertain(UNCERTAIN_DECISION);
    }
}

fn column_scan(s: Setup, ti: u32, px: i32, py: i32) {
    let x = real(px);
    let y = real(py);
    if !(at_least_zero(s.xy0.x * x + s.xy0.y * y + s.dxy.x, s.bxy.x, 1)
        && at_least_zero(s.xy1.x * x + s.xy1.y * y + s.dxy.y, s.bxy.y, 1)
        && at_least_zero(s.xy2.x * x + s.xy2.y * y + s.dxy.z, s.bxy.z, 1)) {
        return;
    }
    let zl = real(s.lo.z);
    let zh = real(s.hi.z);
    var z0 = zl;
    var z1 = zh;
    if s.axis_face {
        // the plane z = c: voxel z meets it iff z <= c <= z + 1
        z0 = max(zl, ceil(s.plane_z) - real(1.0));
        z1 = min(zh, floor(s.plane_z));
    } else {
        depth_range(s, px, py, &z0, &z1);
    }
    side_tests(s, ti, px, py, i32(z0), i32(z1));
}

// The depth range [z0, z1] of column (px, py) within [z0, z1] (in: the clamped range), settled
// by the filtered plane predicates; empty (z0 > z1) if the plane misses the column there.
fn depth_range(s: Setup, px: i32, py: i32, z0p: ptr<function, real>, z1p: ptr<function, real>) {
    let x = real(px);
    let y = real(py);
    let n = s.n;
    let zl = *z0p;
    let zh = *z1p;
    let inv_nz = real(1.0) / n.z;
    let a = -(n.x * x + n.y * y);
    let lo_rhs = a + s.d_lo;
    let hi_rhs = a + s.d_hi;
    // z0 = the first z >= zl whose box (diamond) reaches up to the plane: the division's guess,
    // then settled by the filtered predicate up(z) = n_z (z+1) - lo_rhs >= 0 (monotone in z,
    // also with uncertain values counted as false: the computed value is monotone in z)
    let c0 = ceil(lo_rhs * inv_nz) - real(1.0);
    var z0 = zl;
    if c0 >= zl {
        z0 = min(c0, zh + real(1.0));
    }
    while z0 > zl && at_least_zero(n.z * z0 - lo_rhs, s.bp, 2) {
        z0 -= real(1.0);
    }
    while z0 <= zh && !at_least_zero(n.z * (z0 + real(1.0)) - lo_rhs, s.bp, 2) {
        z0 += real(1.0);
    }
    if z0 > zh {
        *z0p = real(1.0);
        *z1p = real(0.0);
        return;
    }
    // z1 = the last z <= zh whose box reaches down to the plane: down(z) = hi_rhs - n_z z >= 0
    let c1 = floor(hi_rhs * inv_nz);
    var z1 = zh;
    if c1 <= zh {
        z1 = max(c1, z0 - real(1.0));
    }
    while z1 < zh && at_least_zero(hi_rhs - n.z * (z1 + real(1.0)), s.bp, 2) {
        z1 += real(1.0);
    }
    while z1 >= z0 && !at_least_zero(hi_rhs - n.z * z1, s.bp, 2) {
        z1 -= real(1.0);
    }
    *z0p = z0;
    *z1p = z1;
}

// The YZ and ZX edge tests of the voxels z0..=z1 of column (px, py); emits the overlapped ones.
fn side_tests(s: Setup, ti: u32, px: i32, py: i32, iz0: i32, iz1: i32) {
    let x = real(px);
    let y = real(py);
    let czx = vec3<real>(s.zx0.y * x + s.dzx.x, s.zx1.y * x + s.dzx.y, s.zx2.y * x + s.dzx.z);
    let cyz = vec3<real>(s.yz0.x * y + s.dyz.x, s.yz1.x * y + s.dyz.y, s.yz2.x * y + s.dyz.z);
    for (var pz = iz0; pz <= iz1; pz++) {
        let z = real(pz);
        if at_least_zero(s.yz0.y * z + cyz.x, s.byz.x, 1)
            && at_least_zero(s.yz1.y * z + cyz.y, s.byz.y, 1)
            && at_least_zero(s.yz2.y * z + cyz.z, s.byz.z, 1)
            && at_least_zero(s.zx0.x * z + czx.x, s.bzx.x, 1)
            && at_least_zero(s.zx1.x * z + czx.y, s.bzx.y, 1)
            && at_least_zero(s.zx2.x * z + czx.z, s.bzx.z, 1) {
            emit(s, ti, vec3<i32>(px, py, pz));
        }
    }
}

// The triangle-parallel routine: every column of the triangle's range in the chunk. One flat
// loop, not two nested ones: lanes of a SIMD group iterate in lockstep, so nested loops would
// cost max(width) × max(height) over the group's triangles against lavapipe's iteration cap.
fn voxelize_triangle(s: Setup, ti: u32) {
    let w = s.hi.x - s.lo.x + 1;
    let n = w * (s.hi.y - s.lo.y + 1);
    for (var c = 0; c < n; c++) {
        column(s, ti, s.lo.x + c % w, s.lo.y + c / w);
    }
}

// A voxel (swizzled, grid coordinates) the triangle overlaps: mark it, or add its attributes.
fn emit(s: Setup, ti: u32, p: vec3<i32>) {
    let local = unswizzle_i(p, s.axis) - params.origin;
    let idx = (u32(local.z) * 256u + u32(local.y)) * 256u + u32(local.x);
    let word = idx >> 5u;
    let bit = 1u << (idx & 31u);
    if params.phase == PHASE_MARK {
        atomicOr(&occ[word], bit);
        return;
    }
    let bits = atomicLoad(&occ[word]);
    if (bits & bit) == 0u {
        return;
    }
    let slot = base[word] + countOneBits(bits & (bit - 1u));
    if slot < params.slot_lo || slot >= params.slot_hi {
        return;
    }
    accumulate(s, ti, p, (slot - params.slot_lo) * SLOT_WORDS);
}

// ---- clipped area and centroid (clip.rs) ----

var<private> poly: array<vec3<real>, 9>;
var<private> poly_len: u32;

// Keeps the part of `poly` with x[k] >= b (upper false) or x[k] <= b (upper true).
fn clip_plane(k: u32, b: real, upper: bool) {
    var all_in = true;
    for (var i = 0u; i < poly_len; i++) {
        let d = select(poly[i][k] - b, b - poly[i][k], upper);
        if d < real(0.0) {
            all_in = false;
        }
    }
    if all_in {
        return;
    }
    var out: array<vec3<real>, 9>;
    var m = 0u;
    for (var i = 0u; i < poly_len; i++) {
        let a = poly[i];
        let c = poly[select(i + 1u, 0u, i + 1u == poly_len)];
        let da = select(a[k] - b, b - a[k], upper);
        let dc = select(c[k] - b, b - c[k], upper);
        if da >= real(0.0) && m < 9u {
            out[m] = a;
            m++;
        }
        if ((da > real(0.0) && dc < real(0.0)) || (da < real(0.0) && dc > real(0.0))) && m < 9u {
            var pin = a;
            var pout = c;
            var din = da;
            var dout = dc;
            if !(da > real(0.0)) {
                pin = c;
                pout = a;
                din = dc;
                dout = da;
            }
            let t = din / (din - dout);
            var q = vec3<real>(pin.x + t * (pout.x - pin.x), pin.y + t * (pout.y - pin.y), pin.z + t * (pout.z - pin.z));
            q[k] = b;
            out[m] = q;
            m++;
        }
    }
    poly = out;
    poly_len = m;
}

// ---- attributes (chunk.rs) ----

// atomicAdd with the carry out of that addition
fn add_word(i: u32, v: u32) -> u32 {
    let old = atomicAdd(&accum[i], v);
    return select(0u, 1u, old + v < old);
}

// Adds value · 2^64 as a 96-bit two's-complement integer (three u32 words, least significant
// first) with carries between the words: exact integer arithmetic, hence independent of the
// order of the atomics. 2^64 keeps the relative precision of tiny clipped areas; 96 bits hold
// more than 2^20 contributions of 255 · 2 voxels².
fn add_fixed(off: u32, value: real) {
    let x = value * real(18446744073709551616.0);
    let w2 = floor(x * real(5.421010862427522e-20));
    let r = x - w2 * real(18446744073709551616.0);
    let w1 = floor(r * real(2.3283064365386963e-10));
    let w0 = r - w1 * real(4294967296.0);
    let u0 = u32(w0);
    let u1 = u32(w1);
    let u2 = bitcast<u32>(i32(w2));
    var c0 = 0u;
    if u0 != 0u {
        c0 = add_word(off, u0);
    }
    let s1 = u1 + c0;
    var c1 = select(0u, 1u, s1 < u1);
    if s1 != 0u {
        c1 += add_word(off + 1u, s1);
    }
    let s2 = u2 + c1;
    if s2 != 0u {
        atomicAdd(&accum[off + 2u], s2);
    }
}

fn accumulate(s: Setup, ti: u32, p: vec3<i32>, off: u32) {
    // clipped polygon of the swizzled triangle in the voxel, planes x-, x+, y-, y+, z-, z+
    poly[0] = s.v0;
    poly[1] = s.v1;
    poly[2] = s.v2;
    poly_len = 3u;
    let pf = vec3<real>(p);
    clip_plane(0u, pf.x, false);
    clip_plane(0u, pf.x + real(1.0), true);
    clip_plane(1u, pf.y, false);
    clip_plane(1u, pf.y + real(1.0), true);
    clip_plane(2u, pf.z, false);
    clip_plane(2u, pf.z + real(1.0), true);

    let o0 = vertex(ti, 0u);
    let o1 = vertex(ti, 1u);
    let o2 = vertex(ti, 2u);
    var w = real(0.0);
    var q = (o0 + o1 + o2) / real(3.0);
    if poly_len > 0u {
        let p0 = poly[0];
        var a2 = real(0.0);
        var c = vec3<real>(real(0.0));
        for (var i = 1u; i + 1u < poly_len; i++) {
            let u = vec2<real>(poly[i].x - p0.x, poly[i].y - p0.y);
            let v = vec2<real>(poly[i + 1u].x - p0.x, poly[i + 1u].y - p0.y);
            let ai = u.x * v.y - u.y * v.x;
            a2 += ai;
            c += vec3<real>(ai * (p0.x + poly[i].x + poly[i + 1u].x), ai * (p0.y + poly[i].y + poly[i + 1u].y), ai * (p0.z + poly[i].z + poly[i + 1u].z));
        }
        if a2 != real(0.0) {
            let nn = s.n;
            let scale = sqrt(nn.x * nn.x + nn.y * nn.y + nn.z * nn.z) / abs(nn.z);
            let inv = real(1.0) / (real(3.0) * a2);
            w = real(0.5) * abs(a2) * scale;
            q = unswizzle_r(c * inv, s.axis);
        } else {
            let inv = real(1.0) / real(poly_len);
            var m = vec3<real>(real(0.0));
            for (var i = 0u; i < poly_len; i++) {
                m += poly[i] * inv;
            }
            q = unswizzle_r(m, s.axis);
        }
    }

    // barycentrics at q on the unswizzled triangle
    let e1 = o1 - o0;
    let e2 = o2 - o0;
    let n = cross_r(e1, e2);
    let nn = dot_r(n, n);
    let inv_nn = real(1.0) / nn;
    let d = q - o0;
    let l1 = dot_r(cross_r(d, e2), n) * inv_nn;
    let l2 = dot_r(cross_r(e1, d), n) * inv_nn;
    let l0 = real(1.0) - l1 - l2;
    let len_f = sqrt(nn);
    var normal = vec3<real>(n.x / len_f, n.y / len_f, n.z / len_f);
    if (tris[ti].flags & TRI_HAS_NORMALS) != 0u {
        var vn: array<vec3<real>, 3>;
        for (var k = 0u; k < 3u; k++) {
            let b = 3u * k;
            vn[k] = vec3<real>(real(tris[ti].n[b]), real(tris[ti].n[b + 1u]), real(tris[ti].n[b + 2u]));
        }
        let m = vec3<real>(
            l0 * vn[0].x + l1 * vn[1].x + l2 * vn[2].x,
            l0 * vn[0].y + l1 * vn[1].y + l2 * vn[2].y,
            l0 * vn[0].z + l1 * vn[1].z + l2 * vn[2].z);
        let len = sqrt(dot_r(m, m));
        // `len == len` is false for NaN; the upper bound excludes infinity
        if len > real(0.0) && len < real(3.0e38) {
            normal = vec3<real>(m.x / len, m.y / len, m.z / len);
        }
    }
    var colour: array<real, 4>;
    for (var k = 0u; k < 4u; k++) {
        let sh = 8u * k;
        let c0 = real((tris[ti].c[0] >> sh) & 255u);
        let c1 = real((tris[ti].c[1] >> sh) & 255u);
        let c2 = real((tris[ti].c[2] >> sh) & 255u);
        colour[k] = l0 * c0 + l1 * c1 + l2 * c2;
    }

    // weighted sums when w·2^64 rounds to a nonzero integer, unweighted sums otherwise: a voxel
    // whose total weight is zero (touched only on its boundary) falls back to the unweighted
    // mean, as on the CPU
    if floor(w * real(18446744073709551616.0)) > real(0.0) {
        add_fixed(sum_at(off, 0u), w);
        add_fixed(sum_at(off, 1u), w * normal.x);
        add_fixed(sum_at(off, 2u), w * normal.y);
        add_fixed(sum_at(off, 3u), w * normal.z);
        for (var k = 0u; k < 4u; k++) {
            add_fixed(sum_at(off, 4u + k), w * colour[k]);
        }
    } else {
        add_fixed(sum_at(off, 8u), real(1.0));
        add_fixed(sum_at(off, 9u), normal.x);
        add_fixed(sum_at(off, 10u), normal.y);
        add_fixed(sum_at(off, 11u), normal.z);
        for (var k = 0u; k < 4u; k++) {
            add_fixed(sum_at(off, 12u + k), colour[k]);
        }
    }
}
