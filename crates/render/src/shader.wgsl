// Voxel faces as the Chajdas renderer draws them: one instance per active face of a voxel
// cube, expanded from vertex_index into two triangles (6 vertices), shaded by the voxel's
// normal (the face direction where the normal is zero) under one directional light.

struct Uniforms {
    view_proj: mat4x4<f32>,
    light_dir: vec4<f32>,   // towards the light, unit length
};
@group(0) @binding(0) var<uniform> u: Uniforms;

struct Face {
    @location(0) min_corner: vec3<f32>,  // relative to the model's centre
    @location(1) edge: f32,
    @location(2) dir: u32,               // face-mask bit: 0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z
    @location(3) normal: u32,            // 10:10:10 snorm
    @location(4) color: u32,             // RGBA8, R in the low byte
};

struct VOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) color: vec4<f32>,
};

fn snorm10(w: u32, shift: u32) -> f32 {
    return f32(bitcast<i32>(w << (22u - shift)) >> 22u);
}

@vertex
fn vs(@builtin(vertex_index) vi: u32, f: Face) -> VOut {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 0.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 1.0), vec2<f32>(0.0, 1.0));
    let axis = f.dir >> 1u;
    let neg = (f.dir & 1u) == 1u;
    var uv = corners[vi % 6u];
    if (neg) {
        uv = uv.yx; // reversed winding, so every face is counter-clockwise from outside
    }
    var p = vec3<f32>(0.0);
    p[axis] = select(1.0, 0.0, neg);
    p[(axis + 1u) % 3u] = uv.x;
    p[(axis + 2u) % 3u] = uv.y;

    var n = vec3<f32>(snorm10(f.normal, 0u), snorm10(f.normal, 10u), snorm10(f.normal, 20u));
    if (dot(n, n) == 0.0) {
        n = vec3<f32>(0.0);
        n[axis] = select(1.0, -1.0, neg);
    }
    var out: VOut;
    out.clip = u.view_proj * vec4<f32>(f.min_corner + p * f.edge, 1.0);
    out.normal = n;
    out.color = unpack4x8unorm(f.color);
    return out;
}

@fragment
fn fs(in: VOut) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    // two-sided: a normal facing away from the light still gets the ambient term
    let diffuse = max(dot(n, u.light_dir.xyz), 0.0);
    let shade = 0.22 + 0.78 * diffuse;
    return vec4<f32>(in.color.rgb * shade, 1.0);
}
