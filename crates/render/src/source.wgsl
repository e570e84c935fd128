// Source triangles of the leaves whose voxels are coarser than the pixel error:
// an indexed triangle list in the same camera, depth buffer and light as the voxel faces
// (shader.wgsl). A vertex without a stored normal (zero) is shaded with the face normal,
// from the screen-space derivatives of the position, turned towards the eye.

struct Uniforms {
    view_proj: mat4x4<f32>,
    light_dir: vec4<f32>,   // towards the light, unit length
    eye: vec4<f32>,         // the eye, relative to the same origin as the positions
};
@group(0) @binding(0) var<uniform> u: Uniforms;

struct Vertex {
    @location(0) pos: vec3<f32>,     // relative to the picture's origin
    @location(1) normal: vec3<f32>,  // unit, or zero: use the face normal
    @location(2) color: u32,         // RGBA8, R in the low byte
};

struct VOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
};

@vertex
fn vs(v: Vertex) -> VOut {
    var out: VOut;
    out.clip = u.view_proj * vec4<f32>(v.pos, 1.0);
    out.pos = v.pos;
    out.normal = v.normal;
    out.color = unpack4x8unorm(v.color);
    return out;
}

@fragment
fn fs(in: VOut) -> @location(0) vec4<f32> {
    // derivatives in uniform control flow, used where the vertex has no normal
    let face = cross(dpdx(in.pos), dpdy(in.pos));
    var n = in.normal;
    if (dot(n, n) < 1e-12) {
        n = face;
        if (dot(n, u.eye.xyz - in.pos) < 0.0) {
            n = -n;
        }
    }
    n = normalize(n);
    // the voxel faces' rule: ambient plus diffuse from one directional light
    let diffuse = max(dot(n, u.light_dir.xyz), 0.0);
    let shade = 0.22 + 0.78 * diffuse;
    return vec4<f32>(in.color.rgb * shade, 1.0);
}
