// WebGL2 drawing of voxels from the voxel buffers, as the native renderer does it
// (docs/VIEWER.md, "How voxels are drawn"): each resident node keeps its voxels' 12-byte records
// as decoded (nothing per face), in an RGB32UI texture the vertex shader reads (vertex
// pulling: 18 vertices per voxel, one draw per node; on SwiftShader twice as fast as the same
// with instanced attributes). Slot s = (gl_VertexID mod 18) / 6 is axis s, whose face on the
// eye's side is drawn if the face mask has it (two-sided: either bit of the axis, the back lit
// as its front), else the slot collapses to a point outside the clip volume. Source triangles
// of close-up leaves are indexed triangle lists in the same camera and light. Occlusion tests
// are node boxes drawn inside ANY_SAMPLES_PASSED_CONSERVATIVE queries.

const VOXEL_VS = `#version 300 es
precision highp float;
precision highp int;
uniform highp usampler2D u_voxels;     // per texel: pos_mask, normal, colour (FORMAT.md section 6)
uniform int u_width;                   // texels per row of u_voxels
uniform mat4 u_viewProj;
uniform vec3 u_eye;       // relative to the origin
uniform vec4 u_node;      // xyz: the node's minimum corner relative to the origin; w: voxel edge
uniform int u_twoSided;
out vec3 v_normal;
out vec4 v_color;

float snorm10(uint w, uint shift) {
  return float(int(w << (22u - shift)) >> 22);
}

void main() {
  gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
  v_normal = vec3(0.0, 0.0, 1.0);
  v_color = vec4(0.0);
  int voxel = gl_VertexID / 18;
  int slot = gl_VertexID - 18 * voxel;
  int axis = slot / 6;
  uvec3 words = texelFetch(u_voxels, ivec2(voxel % u_width, voxel / u_width), 0).xyz;
  float edge = u_node.w;
  vec3 lo = u_node.xyz + vec3(float(words.x & 255u), float((words.x >> 8u) & 255u), float((words.x >> 16u) & 255u)) * edge;
  int dir;
  if (u_eye[axis] > lo[axis] + edge) {
    dir = 2 * axis;
  } else if (u_eye[axis] < lo[axis]) {
    dir = 2 * axis + 1;
  } else {
    return;
  }
  uint mask = (words.x >> 24u) & 63u;
  bool own = ((mask >> uint(dir)) & 1u) == 1u;
  bool either = ((mask >> uint(2 * axis)) & 3u) != 0u;
  if (!own && !(u_twoSided == 1 && either)) return;
  vec2 corners[6] = vec2[6](vec2(0.0, 0.0), vec2(1.0, 0.0), vec2(1.0, 1.0),
                            vec2(0.0, 0.0), vec2(1.0, 1.0), vec2(0.0, 1.0));
  bool neg = (dir & 1) == 1;
  vec2 uv = corners[slot % 6];
  if (neg) uv = uv.yx;
  vec3 p = vec3(0.0);
  p[axis] = neg ? 0.0 : 1.0;
  p[(axis + 1) % 3] = uv.x;
  p[(axis + 2) % 3] = uv.y;
  vec3 n = vec3(snorm10(words.y, 0u), snorm10(words.y, 10u), snorm10(words.y, 20u));
  if (dot(n, n) == 0.0) {
    n = vec3(0.0);
    n[axis] = neg ? -1.0 : 1.0;
  }
  if (!own) n = -n;
  gl_Position = u_viewProj * vec4(lo + p * edge, 1.0);
  v_normal = n;
  v_color = vec4(float(words.z & 255u), float((words.z >> 8u) & 255u), float((words.z >> 16u) & 255u), float(words.z >> 24u)) / 255.0;
}`;

const SHADE_FS = `#version 300 es
precision highp float;
in vec3 v_normal;
in vec4 v_color;
uniform vec3 u_light;
out vec4 color;
void main() {
  vec3 n = normalize(v_normal);
  float shade = 0.22 + 0.78 * max(dot(n, u_light), 0.0);
  color = vec4(v_color.rgb * shade, 1.0);
}`;

// an occlusion test: the 36 vertices of a box (two triangles per side) from gl_VertexID
const BOX_VS = `#version 300 es
precision highp float;
uniform mat4 u_viewProj;
uniform vec3 u_min;
uniform vec3 u_max;
void main() {
  int side = gl_VertexID / 6;
  int axis = side / 2;
  vec2 corners[6] = vec2[6](vec2(0.0, 0.0), vec2(1.0, 0.0), vec2(1.0, 1.0),
                            vec2(0.0, 0.0), vec2(1.0, 1.0), vec2(0.0, 1.0));
  vec2 uv = corners[gl_VertexID % 6];
  vec3 t = vec3(0.0);
  t[axis] = float(side % 2);
  t[(axis + 1) % 3] = uv.x;
  t[(axis + 2) % 3] = uv.y;
  gl_Position = u_viewProj * vec4(mix(u_min, u_max, t), 1.0);
}`;

const BOX_FS = `#version 300 es
precision highp float;
out vec4 color;
void main() {
  color = vec4(1.0);
}`;

const SOURCE_VS = `#version 300 es
precision highp float;
layout(location = 0) in vec3 pos;      // relative to the leaf's minimum corner
layout(location = 1) in vec3 normal;   // unit, or zero: the face normal
layout(location = 2) in uvec4 rgba;
uniform mat4 u_viewProj;
uniform vec4 u_node;
out vec3 v_pos;
out vec3 v_normal;
out vec4 v_color;
void main() {
  vec3 p = u_node.xyz + pos;
  gl_Position = u_viewProj * vec4(p, 1.0);
  v_pos = p;
  v_normal = normal;
  v_color = vec4(rgba) / 255.0;
}`;

const SOURCE_FS = `#version 300 es
precision highp float;
in vec3 v_pos;
in vec3 v_normal;
in vec4 v_color;
uniform vec3 u_light;
uniform vec3 u_eye;
out vec4 color;
void main() {
  vec3 face = cross(dFdx(v_pos), dFdy(v_pos));
  vec3 n = v_normal;
  if (dot(n, n) < 1e-12) {
    n = face;
    if (dot(n, u_eye - v_pos) < 0.0) n = -n;
  }
  n = normalize(n);
  float shade = 0.22 + 0.78 * max(dot(n, u_light), 0.0);
  color = vec4(v_color.rgb * shade, 1.0);
}`;

function compile(gl, vs, fs) {
  const prog = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(`shader: ${gl.getShaderInfoLog(s)}`);
    gl.attachShader(prog, s);
  }
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(`program: ${gl.getProgramInfoLog(prog)}`);
  const uniforms = {};
  const count = gl.getProgramParameter(prog, gl.ACTIVE_UNIFORMS);
  for (let i = 0; i < count; i++) {
    const name = gl.getActiveUniform(prog, i).name;
    uniforms[name] = gl.getUniformLocation(prog, name);
  }
  return { prog, uniforms };
}

/** Light from the upper left behind the eye, fixed relative to the camera (draw.rs). */
export function lightDirection(shot) {
  const n = (a) => { const l = Math.hypot(...a); return a.map((c) => c / l); };
  const fwd = n(shot.target.map((t, a) => t - shot.eye[a]));
  const up = shot.up;
  const right = n([fwd[1] * up[2] - fwd[2] * up[1], fwd[2] * up[0] - fwd[0] * up[2], fwd[0] * up[1] - fwd[1] * up[0]]);
  return n([0, 1, 2].map((a) => -fwd[a] * 0.8 + up[a] * 0.7 - right[a] * 0.45));
}

export const BACKGROUND = [236, 238, 242];

/** Texels per row of a node's voxel texture (a node of 256³ voxels fills 4096 × 4096). */
const TEXTURE_WIDTH = 4096;

export class Renderer {
  constructor(canvas) {
    const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true, alpha: false });
    if (!gl) throw new Error('this browser has no WebGL2');
    this.gl = gl;
    this.voxel = compile(gl, VOXEL_VS, SHADE_FS);
    this.source = compile(gl, SOURCE_VS, SOURCE_FS);
    this.box = compile(gl, BOX_VS, BOX_FS);
    this.queriesOk = typeof gl.ANY_SAMPLES_PASSED_CONSERVATIVE === 'number';
    // voxel draws read no vertex attributes: everything comes from gl_VertexID
    this.empty = gl.createVertexArray();
  }

  /** GPU buffers of a node's voxel records (Uint32Array, 3 words per voxel). */
  uploadVoxels(rec) {
    const gl = this.gl;
    const n = rec.length / 3;
    const width = Math.min(n, TEXTURE_WIDTH);
    const height = Math.ceil(n / width);
    let data = rec;
    if (width * height !== n) {
      data = new Uint32Array(3 * width * height);
      data.set(rec);
    }
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 4);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGB32UI, width, height, 0, gl.RGB_INTEGER, gl.UNSIGNED_INT, data);
    gl.bindTexture(gl.TEXTURE_2D, null);
    return { kind: 'voxels', tex, width, buffers: [], count: n, bytes: 12 * width * height };
  }

  /** GPU buffers of a leaf's source triangles (from the worker). */
  uploadSource(m) {
    const gl = this.gl;
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const buffers = [];
    const attr = (loc, data, size, type, integer) => {
      const b = gl.createBuffer();
      buffers.push(b);
      gl.bindBuffer(gl.ARRAY_BUFFER, b);
      gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
      gl.enableVertexAttribArray(loc);
      if (integer) gl.vertexAttribIPointer(loc, size, type, 0, 0);
      else gl.vertexAttribPointer(loc, size, type, false, 0, 0);
    };
    attr(0, m.positions, 3, gl.FLOAT, false);
    attr(1, m.normals, 3, gl.FLOAT, false);
    attr(2, new Uint8Array(m.colors.buffer, m.colors.byteOffset, m.colors.byteLength), 4, gl.UNSIGNED_BYTE, true);
    const ib = gl.createBuffer();
    buffers.push(ib);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, m.indices, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    const bytes = m.positions.byteLength + m.normals.byteLength + m.colors.byteLength + m.indices.byteLength;
    return { kind: 'source', vao, buffers, count: m.indices.length, bytes };
  }

  free(res) {
    const gl = this.gl;
    if (res.vao) gl.deleteVertexArray(res.vao);
    if (res.tex) gl.deleteTexture(res.tex);
    for (const b of res.buffers) gl.deleteBuffer(b);
  }

  /**
   * Draws one frame. `frame`: {viewProj (Float32Array, column-major), eye, light (relative to
   * the origin), twoSided}; `draws`: [{res, corner: [x, y, z] relative to the origin, edge}]
   * in order; then `tests`: [{min, max, query}], boxes drawn with colour and depth writes off,
   * each inside its occlusion query (a WebGLQuery, ANY_SAMPLES_PASSED_CONSERVATIVE).
   */
  draw(width, height, frame, draws, tests = []) {
    const gl = this.gl;
    gl.viewport(0, 0, width, height);
    gl.clearColor(BACKGROUND[0] / 255, BACKGROUND[1] / 255, BACKGROUND[2] / 255, 1);
    gl.clearDepth(1);
    gl.depthMask(true);
    gl.colorMask(true, true, true, true);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.depthFunc(gl.LESS);
    let current = null;
    for (const d of draws) {
      const p = d.res.kind === 'voxels' ? this.voxel : this.source;
      if (p !== current) {
        current = p;
        gl.useProgram(p.prog);
        gl.uniformMatrix4fv(p.uniforms.u_viewProj, false, frame.viewProj);
        gl.uniform3fv(p.uniforms.u_light, frame.light);
        if (p.uniforms.u_eye) gl.uniform3fv(p.uniforms.u_eye, frame.eye);
        if (p.uniforms.u_twoSided) gl.uniform1i(p.uniforms.u_twoSided, frame.twoSided ? 1 : 0);
      }
      if (d.res.kind === 'voxels') {
        gl.enable(gl.CULL_FACE);
        gl.cullFace(gl.BACK);
        gl.frontFace(gl.CCW);
      } else {
        gl.disable(gl.CULL_FACE);
      }
      gl.uniform4f(p.uniforms.u_node, d.corner[0], d.corner[1], d.corner[2], d.edge ?? 0);
      if (d.res.kind === 'voxels') {
        gl.bindVertexArray(this.empty);
        gl.activeTexture(gl.TEXTURE0);
        gl.bindTexture(gl.TEXTURE_2D, d.res.tex);
        gl.uniform1i(p.uniforms.u_voxels, 0);
        gl.uniform1i(p.uniforms.u_width, d.res.width);
        gl.drawArrays(gl.TRIANGLES, 0, 18 * d.res.count);
      } else {
        gl.bindVertexArray(d.res.vao);
        gl.drawElements(gl.TRIANGLES, d.res.count, gl.UNSIGNED_INT, 0);
      }
    }
    if (tests.length) {
      gl.useProgram(this.box.prog);
      gl.uniformMatrix4fv(this.box.uniforms.u_viewProj, false, frame.viewProj);
      gl.bindVertexArray(this.empty);
      gl.disable(gl.CULL_FACE);
      gl.colorMask(false, false, false, false);
      gl.depthMask(false);
      for (const t of tests) {
        gl.uniform3fv(this.box.uniforms.u_min, t.min);
        gl.uniform3fv(this.box.uniforms.u_max, t.max);
        gl.beginQuery(gl.ANY_SAMPLES_PASSED_CONSERVATIVE, t.query);
        gl.drawArrays(gl.TRIANGLES, 0, 36);
        gl.endQuery(gl.ANY_SAMPLES_PASSED_CONSERVATIVE);
      }
      gl.colorMask(true, true, true, true);
      gl.depthMask(true);
    }
    gl.bindVertexArray(null);
  }
}
