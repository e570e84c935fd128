// Fragment-parallel pass of the GPU hybrid voxelizer (Rauwendaal & Bailey, JCGT 2013, section
// 3.3): the deferred triangles, already swizzled to their dominant axis and dilated by the
// classification pass, are rasterized into a viewport of the chunk's 256×256 columns; each
// fragment runs the remaining overlap tests of its column (dominant plane, depth range, the
// other two projections) exactly as the triangle-parallel routine does. Wgpu has no geometry
// shader, so the vertex shader fetches the stored dilated vertices by vertex_index.
// The shared routines are in voxelize.wgsl, appended by the host.

@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> tris: array<Tri>;
@group(0) @binding(2) var<storage, read_write> occ: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read> deferred: array<Deferred>;
@group(0) @binding(5) var<storage, read> base: array<u32>;
@group(0) @binding(6) var<storage, read_write> accum: array<atomic<u32>>;
// [3..]: the uncertainty flags and the list of uncertain triangles of voxelize.wgsl ([0..3]
// belong to the classification pass)
@group(0) @binding(7) var<storage, read_write> counter: array<atomic<u32>>;

struct VsOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) @interpolate(flat) slot: u32,
};

@vertex
fn vs(@builtin(vertex_index) vi: u32) -> VsOut {
    let slot = vi / 3u;
    let d = deferred[slot];
    let k = vi % 3u;
    var q = d.a;
    if k == 1u {
        q = d.b;
    } else if k == 2u {
        q = d.c;
    }
    var out: VsOut;
    // chunk-local column (u, v) -> pixel (u, v): x right, y down in framebuffer coordinates
    out.pos = vec4<f32>(q.x / 128.0 - 1.0, 1.0 - q.y / 128.0, 0.5, 1.0);
    out.slot = slot;
    return out;
}

@fragment
fn fs(in: VsOut) -> @location(0) vec4<f32> {
    let d = deferred[in.slot];
    let q = vec2<i32>(floor(in.pos.xy));
    if any(q < d.lo) || any(q > d.hi) {
        return vec4<f32>(0.0);
    }
    let s = setup(d.tri);
    let o = swizzle_i(params.origin, s.axis);
    if s.ok {
        column(s, d.tri, q.x + o.x, q.y + o.y);
    }
    return vec4<f32>(0.0);
}
