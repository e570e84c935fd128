// The camera and the level-of-detail cut of `voxlod render`, in f64 as the Rust code computes
// them (crates/render/src/camera.rs and cut.rs), so that a URL with render's parameters shows
// the same picture: the model framed by its robust bounds from a view direction, and the
// nodes refined while their voxels project to more than `error` pixels, frustum culled.

import { nodeBounds, voxelSizeAt } from './voxlod-reader.mjs';

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const len = (a) => Math.sqrt(dot(a, a));
const norm = (a) => scale(a, 1 / len(a));
export const vec = { sub, add, scale, dot, cross, len, norm };

/** What the user asks for, with `render`'s defaults. */
export function defaultView() {
  return { width: 1024, height: 768, direction: [0.55, 0.35, 1], up: [0, 1, 0], fovYDeg: 35, zoom: 1, target: null };
}

/** Shot.frame: frames `bounds` ({min, max}) from `view`; throws on bad parameters. */
export function frameShot(bounds, view) {
  if (!(view.width >= 1 && view.height >= 1 && view.width <= 16384 && view.height <= 16384)) {
    throw new Error(`image size ${view.width}x${view.height} must be 1..=16384 on each side`);
  }
  if (!(view.fovYDeg > 1 && view.fovYDeg < 170)) throw new Error(`field of view ${view.fovYDeg}° must be in (1, 170)`);
  if (!(Number.isFinite(view.zoom) && view.zoom > 0)) throw new Error(`zoom ${view.zoom} must be positive`);
  let dir = view.direction;
  if (!(dir.every(Number.isFinite) && len(dir) > 0)) throw new Error(`view direction ${dir} is not a direction`);
  dir = norm(dir);
  let up = view.up;
  if (!(up.every(Number.isFinite) && len(up) > 0)) throw new Error(`up vector ${up} is not a direction`);
  up = norm(up);
  if (len(cross(up, dir)) < 1e-6) up = Math.abs(dir[2]) < 0.9 ? [0, 0, 1] : [1, 0, 0];
  up = norm(sub(up, scale(dir, dot(up, dir))));
  const lo = bounds.min;
  const hi = bounds.max;
  let centre = scale(add(lo, hi), 0.5);
  const radius = Math.max(len(sub(hi, lo)) * 0.5, 1e-9);
  let cover = radius;
  if (view.target) {
    const t = view.target;
    if (!t.every(Number.isFinite)) throw new Error(`target ${t} is not a point`);
    const far = [0, 1, 2].map((a) => Math.max(Math.abs(t[a] - lo[a]), Math.abs(t[a] - hi[a])));
    centre = t;
    cover = Math.max(len(far), radius);
  }
  const fovY = (view.fovYDeg * Math.PI) / 180;
  const aspect = view.width / view.height;
  const fovX = 2 * Math.atan(Math.tan(fovY * 0.5) * aspect);
  const half = 0.5 * Math.min(fovY, fovX);
  const dist = radius / Math.sin(half) / view.zoom;
  return {
    eye: add(centre, scale(dir, dist)),
    target: centre,
    up,
    fovY,
    near: Math.max(dist - cover * 1.01, cover * 1e-4),
    far: dist + cover * 1.01,
    width: view.width,
    height: view.height,
  };
}

/** Row-major 4×4 product. */
function mul(a, b) {
  const out = new Array(16).fill(0);
  for (let r = 0; r < 4; r++) {
    for (let c = 0; c < 4; c++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[4 * r + k] * b[4 * k + c];
      out[4 * r + c] = s;
    }
  }
  return out;
}

/** glam's look_at_rh, row-major, for an eye and target relative to `origin`. */
function lookAt(eye, target, up) {
  const f = norm(sub(target, eye));
  const s = norm(cross(f, up));
  const u = cross(s, f);
  return [s[0], s[1], s[2], -dot(s, eye), u[0], u[1], u[2], -dot(u, eye), -f[0], -f[1], -f[2], dot(f, eye), 0, 0, 0, 1];
}

/**
 * World (relative to `origin`) → clip matrix, row-major. `gl` false: wgpu's depth range
 * [0, 1] (glam's perspective_rh, for the frustum test exactly as the Rust cut does it);
 * true: OpenGL's [−1, 1] (for drawing in WebGL2).
 */
export function viewProj(shot, origin, gl = false) {
  const view = lookAt(sub(shot.eye, origin), sub(shot.target, origin), shot.up);
  const h = 1 / Math.tan(0.5 * shot.fovY);
  const w = h / (shot.width / shot.height);
  const n = shot.near;
  const f = shot.far;
  const proj = gl
    ? [w, 0, 0, 0, 0, h, 0, 0, 0, 0, (f + n) / (n - f), (2 * f * n) / (n - f), 0, 0, -1, 0]
    : [w, 0, 0, 0, 0, h, 0, 0, 0, 0, f / (n - f), (f * n) / (n - f), 0, 0, -1, 0];
  return mul(proj, view);
}

/** Column-major Float32Array of a row-major matrix (a WebGL uniform). */
export function columnMajor(m) {
  const out = new Float32Array(16);
  for (let r = 0; r < 4; r++) for (let c = 0; c < 4; c++) out[4 * c + r] = m[4 * r + c];
  return out;
}

function pixelsAtUnitDepth(shot) {
  const ty = Math.tan(0.5 * shot.fovY);
  const tx = (ty * shot.width) / shot.height;
  return (shot.height / (2 * ty)) * Math.sqrt(1 + tx * tx + ty * ty);
}

/** Nearest view depth of box `b`. */
export function nearestDepth(shot, b) {
  const fwd = norm(sub(shot.target, shot.eye));
  const c = scale(add(b.min, b.max), 0.5);
  const half = scale(sub(b.max, b.min), 0.5);
  return dot(sub(c, shot.eye), fwd) - dot(fwd.map(Math.abs), half);
}

/** Upper bound of the pixels of an edge `edge` anywhere in box `b`. */
export function voxelPixels(shot, b, edge) {
  return (edge * pixelsAtUnitDepth(shot)) / Math.max(nearestDepth(shot, b), shot.near);
}

/** False when `b` lies wholly outside one plane of the view frustum (wgpu clip space). */
export function inFrustum(shot, b, m = viewProj(shot, shot.target)) {
  const clip = [];
  for (let k = 0; k < 8; k++) {
    const p = sub([k & 1 ? b.max[0] : b.min[0], k & 2 ? b.max[1] : b.min[1], k & 4 ? b.max[2] : b.min[2]], shot.target);
    clip.push([0, 1, 2, 3].map((r) => m[4 * r] * p[0] + m[4 * r + 1] * p[1] + m[4 * r + 2] * p[2] + m[4 * r + 3]));
  }
  const planes = [
    (c) => c[3] + c[0], (c) => c[3] - c[0], (c) => c[3] + c[1], (c) => c[3] - c[1], (c) => c[2], (c) => c[3] - c[2],
  ];
  return planes.every((p) => clip.some((c) => p(c) >= 0));
}

/**
 * The per-frame view of the octree for a shot: each node's box, error, whether it is in the
 * frustum and whether it is refined. `file` is a VoxlodFile.
 */
export class CutContext {
  constructor(file, shot, maxError) {
    this.file = file;
    this.shot = shot;
    this.maxError = maxError;
    this.m = viewProj(shot, shot.target);
    this.boxes = file.boxes ?? (file.boxes = file.nodes.map((e) => nodeBounds(file.header, e)));
  }

  error(i) {
    return voxelPixels(this.shot, this.boxes[i], voxelSizeAt(this.file.header, this.file.nodes[i].level));
  }

  visible(i) {
    return inFrustum(this.shot, this.boxes[i], this.m);
  }

  /** cut.rs `refines`: it has children and its error exceeds the threshold (or is NaN). */
  refines(i) {
    const err = this.error(i);
    return this.file.nodes[i].childMask !== 0 && !(err <= this.maxError);
  }

  /** cut.rs `select`: [{index, error, over}] in depth-first order. */
  select() {
    const out = [];
    const f = this.file;
    const stack = f.root >= 0 ? [f.root] : [];
    while (stack.length) {
      const i = stack.pop();
      if (!this.visible(i)) continue;
      if (this.refines(i)) {
        const kids = f.children[i];
        for (let k = kids.length - 1; k >= 0; k--) stack.push(kids[k]);
      } else {
        const error = this.error(i);
        out.push({ index: i, error, over: f.nodes[i].level === 0 && !(error <= this.maxError) });
      }
    }
    return out;
  }
}

/** camera.rs `up_from_shape`: +Z for a model flat in z, else null. */
export function upFromShape(b) {
  const e = [0, 1, 2].map((a) => b.max[a] - b.min[a]);
  return e[2] * 4 < e[0] && e[2] * 4 < e[1] ? [0, 0, 1] : null;
}

/** Voxels sampled for robust bounds: the coarsest level with at least this many. */
export const ROBUST_SAMPLE = 20000;

/** The level robust bounds are computed from (camera.rs), or -1 for an empty file. */
export function robustLevel(file) {
  const per = new Array(file.header.levels).fill(0);
  for (const e of file.nodes) per[e.level] += e.voxelCount;
  for (let l = file.header.levels - 1; l >= 0; l--) if (per[l] >= ROBUST_SAMPLE) return l;
  return per[0] > 0 ? 0 : -1;
}

/** Nearest-rank percentile `q` of a Float64Array (sorted in place). */
function percentile(v, q) {
  const k = Math.round((v.length - 1) * q);
  return v[k];
}

/**
 * camera.rs `robust_bounds` from the decoded voxels of every node of `level` ([[entry,
 * records], ...], records the interleaved words pos, normal, colour of each voxel): per axis
 * the 1st to 99th percentile of voxel centres, widened by one voxel of that level.
 */
export function robustBounds(h, level, nodes) {
  const edge = voxelSizeAt(h, level);
  let total = 0;
  for (const [, rec] of nodes) total += rec.length / 3;
  const axes = [new Float64Array(total), new Float64Array(total), new Float64Array(total)];
  let k = 0;
  for (const [e, rec] of nodes) {
    const p = [e.x, e.y, e.z];
    for (let j = 0; j < rec.length; j += 3, k++) {
      const w = rec[j];
      const v = [w & 255, (w >>> 8) & 255, (w >>> 16) & 255];
      for (let a = 0; a < 3; a++) axes[a][k] = h.origin[a] + edge * (256 * p[a] + v[a]) + 0.5 * edge;
    }
  }
  const min = [];
  const max = [];
  for (let a = 0; a < 3; a++) {
    axes[a].sort();
    min.push(percentile(axes[a], 0.01) - edge);
    max.push(percentile(axes[a], 0.99) + edge);
  }
  return { min, max };
}
