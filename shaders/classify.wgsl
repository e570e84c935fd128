// Classification pass and voxel compaction of the GPU hybrid voxelizer (Rauwendaal & Bailey,
// JCGT 2013, section 3.4.2 and Figure 15; voxel lists with an atomic counter, section 3.5).
//
// `classify`: one invocation per triangle. Triangles whose dominant projected area is below the
// cutoff are voxelized right here (triangle-parallel, section 3.2); the others are appended to
// the deferred list with their dilated 2D triangle (Hertel et al. 2009, section 3.3.2) and the
// indirect draw arguments of the fragment pass are bumped.
// `compact`: one invocation per occupancy word; gives every word the first slot of its voxels.
// The routines shared with the fragment pass are in voxelize.wgsl, appended by the host.

@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> tris: array<Tri>;
@group(0) @binding(2) var<storage, read_write> occ: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> deferred: array<Deferred>;
// [0..4]: draw_indirect arguments of the fragment pass (vertex_count, instance_count,
// first_vertex, first_instance); [4..7]: dispatch_workgroups_indirect arguments of the sweep
// pass (deferred triangles, strips, 1)
@group(0) @binding(4) var<storage, read_write> draw_args: array<atomic<u32>, 8>;
@group(0) @binding(5) var<storage, read_write> base: array<u32>;
@group(0) @binding(6) var<storage, read_write> accum: array<atomic<u32>>;
// [0]: number of occupied voxels; [1], [2]: triangles voxelized here / deferred (mark phase);
// [3..]: the uncertainty flags and the list of uncertain triangles of voxelize.wgsl
@group(0) @binding(7) var<storage, read_write> counter: array<atomic<u32>>;

// Half the pixel diagonal (paper: l = sqrt(2)/2 in voxel space) plus a margin for the
// rasterizer's sub-pixel snapping and f32 rounding; extra fragments are culled by the tests.
const DILATION: f32 = 0.7071068 + 0.01;
// Columns one invocation may sweep. Lavapipe (llvmpipe) ends any shader invocation after 65535
// loop iterations in total, so a triangle with more columns than this is deferred even when it
// is under the cutoff, and the sweep pass gives each invocation at most STRIP rows of one column
// line; a column costs at most a few hundred iterations (three voxels, each clipped).
const INLINE_COLUMNS: i32 = 64;
const STRIP: i32 = 64;
const STRIPS: u32 = 4u; // 256 / STRIP

@compute @workgroup_size(64)
fn classify(@builtin(global_invocation_id) gid: vec3<u32>) {
    let ti = gid.y * params.groups_x * 64u + gid.x;
    if ti == 0u {
        atomicStore(&draw_args[1], 1u);
        atomicStore(&draw_args[5], STRIPS);
        atomicStore(&draw_args[6], 1u);
    }
    if ti >= params.tri_count {
        return;
    }
    let s = setup(ti);
    if !s.ok {
        return;
    }
    let columns = (s.hi.x - s.lo.x + 1) * (s.hi.y - s.lo.y + 1);
    if f32(s.area2d) < params.cutoff && columns <= INLINE_COLUMNS {
        if params.phase == PHASE_MARK {
            atomicAdd(&counter[1], 1u);
        }
        voxelize_triangle(s, ti);
        return;
    }
    if params.phase == PHASE_MARK {
        atomicAdd(&counter[2], 1u);
    }
    let slot = atomicAdd(&draw_args[0], 3u) / 3u;
    atomicAdd(&draw_args[4], 1u);
    deferred[slot] = dilate(s, ti);
}

// Hertel's dilation of the dominant projection: each edge line moved outward by DILATION, the
// new vertices at the intersections of adjacent moved lines. Chunk-local f32 coordinates.
fn dilate(s: Setup, ti: u32) -> Deferred {
    let o = vec2<real>(swizzle_i(params.origin, s.axis).xy);
    var q: array<vec2<f32>, 3>;
    q[0] = vec2<f32>(s.v0.xy - o);
    q[1] = vec2<f32>(s.v1.xy - o);
    q[2] = vec2<f32>(s.v2.xy - o);
    // orientation of the projected triangle (the swizzled normal's z before the sign fix is
    // not kept; recompute in 2D)
    let e01 = q[1] - q[0];
    let e02 = q[2] - q[0];
    let orient = select(-1.0, 1.0, e01.x * e02.y - e01.y * e02.x > 0.0);
    // TRI_ROUNDED: the exact image's edges are within eta·sqrt(2) of these
    let dilation = DILATION + f32(real(1.5) * s.eta);
    // outward unit normals of edges i -> i+1
    var m: array<vec2<f32>, 3>;
    for (var i = 0u; i < 3u; i++) {
        let e = q[(i + 1u) % 3u] - q[i];
        m[i] = orient * normalize(vec2<f32>(e.y, -e.x));
    }
    var r: array<vec2<f32>, 3>;
    for (var i = 0u; i < 3u; i++) {
        let a = m[(i + 2u) % 3u];
        let b = m[i];
        let det = a.x * b.y - a.y * b.x;
        // solve a·y = l, b·y = l
        let y = dilation * vec2<f32>(b.y - a.y, a.x - b.x) / det;
        r[i] = q[i] + y;
    }
    var d: Deferred;
    d.a = r[0];
    d.b = r[1];
    d.c = r[2];
    d.tri = ti;
    d._pad = 0u;
    let oi = swizzle_i(params.origin, s.axis).xy;
    d.lo = s.lo.xy - oi;
    d.hi = s.hi.xy - oi;
    return d;
}

// Triangle-parallel voxelization of the deferred triangles without the rasterizer (the
// triangle-only scheme): workgroup (t, k) sweeps rows [64k, 64k+63] of deferred triangle t's
// column range, one invocation per column line x.
@compute @workgroup_size(256)
fn sweep(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let d = deferred[wid.x];
    let s = setup(d.tri);
    let px = s.lo.x + i32(lid.x);
    let y0 = s.lo.y + i32(wid.y) * STRIP;
    if !s.ok || px > s.hi.x || y0 > s.hi.y {
        return;
    }
    let y1 = min(s.hi.y, y0 + STRIP - 1);
    for (var py = y0; py <= y1; py++) {
        column(s, d.tri, px, py);
    }
}

@compute @workgroup_size(64)
fn compact(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x;
    if w >= arrayLength(&occ) {
        return;
    }
    let bits = atomicLoad(&occ[w]);
    if bits != 0u {
        base[w] = atomicAdd(&counter[0], countOneBits(bits));
    }
}
