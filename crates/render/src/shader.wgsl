// Voxels as the Chajdas renderer draws them, from the voxel buffers: one instance per voxel
// (its three words as the file stores them, FORMAT.md section 6), 18 vertices per instance.
// Vertex slot s = vertex_index / 6 is axis s; of that axis the face on the eye's side is drawn
// (at most three faces per voxel) if the face mask allows it, else the slot collapses to a
// point outside the clip volume. Shaded by the voxel's normal (the face direction where the
// normal is zero) under one directional light.

struct Uniforms {
    view_proj: mat4x4<f32>,
    light_dir: vec4<f32>,   // towards the light, unit length
    eye: vec4<f32>,         // the eye relative to the origin
};
@group(0) @binding(0) var<uniform> u: Uniforms;

// Per node: its minimum corner relative to the origin and the voxel edge; flags bit 0:
// two-sided (an axis with either face-mask bit draws its eye-side face).
struct Node {
    min_edge: vec4<f32>,
    flags: vec4<u32>,
};
@group(1) @binding(0) var<uniform> node: Node;

struct VOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) color: vec4<f32>,
};

fn snorm10(w: u32, shift: u32) -> f32 {
    return f32(bitcast<i32>(w << (22u - shift)) >> 22u);
}

@vertex
fn vs(@builtin(vertex_index) vi: u32, @location(0) words: vec3<u32>) -> VOut {
    var out: VOut;
    // a collapsed slot: all its vertices at one point outside the clip volume
    out.clip = vec4<f32>(2.0, 2.0, 2.0, 1.0);
    out.normal = vec3<f32>(0.0, 0.0, 1.0);
    out.color = vec4<f32>(0.0);

    let axis = vi / 6u;
    let edge = node.min_edge.w;
    var lo = node.min_edge.xyz
        + vec3<f32>(f32(words.x & 255u), f32((words.x >> 8u) & 255u), f32((words.x >> 16u) & 255u)) * edge;
    var eye = u.eye.xyz;
    var dir: u32;
    if (eye[axis] > lo[axis] + edge) {
        dir = 2u * axis;        // +axis
    } else if (eye[axis] < lo[axis]) {
        dir = 2u * axis + 1u;   // -axis
    } else {
        return out;             // the eye is inside the voxel's slab: no face of this axis
    }
    let mask = (words.x >> 24u) & 63u;
    let own = ((mask >> dir) & 1u) == 1u;
    let either = ((mask >> (2u * axis)) & 3u) != 0u;
    let two_sided = (node.flags.x & 1u) == 1u;
    if (!own && !(two_sided && either)) {
        return out;
    }

    var corners = array<vec2<f32>, 6>(
        vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 0.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 1.0), vec2<f32>(0.0, 1.0));
    let neg = (dir & 1u) == 1u;
    var uv = corners[vi % 6u];
    if (neg) {
        uv = uv.yx; // reversed winding, so every face is counter-clockwise from outside
    }
    var p = vec3<f32>(0.0);
    p[axis] = select(1.0, 0.0, neg);
    p[(axis + 1u) % 3u] = uv.x;
    p[(axis + 2u) % 3u] = uv.y;

    var n = vec3<f32>(snorm10(words.y, 0u), snorm10(words.y, 10u), snorm10(words.y, 20u));
    if (dot(n, n) == 0.0) {
        n = vec3<f32>(0.0);
        n[axis] = select(1.0, -1.0, neg);
    }
    if (!own) {
        // the back of an open surface: lit as its front would be from this side
        n = -n;
    }
    out.clip = u.view_proj * vec4<f32>(lo + p * edge, 1.0);
    out.normal = n;
    out.color = unpack4x8unorm(words.z);
    return out;
}

@fragment
fn fs(in: VOut) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    // a normal facing away from the light still gets the ambient term
    let diffuse = max(dot(n, u.light_dir.xyz), 0.0);
    let shade = 0.22 + 0.78 * diffuse;
    return vec4<f32>(in.color.rgb * shade, 1.0);
}
