// The viewer's Web Worker: fetches a node's payloads by HTTP range requests and decodes them
// (voxlod-reader.mjs), off the main thread. Replies with what the GPU takes as is:
// - voxels: the interleaved 12-byte records (pos_mask, normal, colour) of every voxel, the
//   colour replaced by the material's colour for `color=material`;
// - source triangles: positions relative to the leaf chunk's minimum corner, normals, colours
//   and indices (FORMAT.md 14.4).

import {
  decodeVoxelPayload, decodeMaterialPayload, decodeSourcePayload, octDecode,
  CHANNEL_MATERIAL,
} from './voxlod-reader.mjs';
import { fetchRange } from './fetch-range.mjs';

/** crates/render faces.rs `material_color`: grey for 0, golden-angle hues otherwise. */
export function materialColor(id) {
  if (id === 0) return 0xff808080;
  const h = ((id * 0.618033988749895) % 1) * 6;
  const v = id % 2 === 0 ? 1 : 0.75;
  const x = 1 - Math.abs((h % 2) - 1);
  const rgb = [[1, x, 0], [x, 1, 0], [0, 1, x], [0, x, 1], [x, 0, 1], [1, 0, x]][Math.min(Math.floor(h), 5)];
  const q = rgb.map((c) => Math.round(c * v * 255));
  return (q[0] | (q[1] << 8) | (q[2] << 16) | (255 << 24)) >>> 0;
}

async function voxels(msg) {
  const e = msg.entry;
  const mat = msg.material ? e.channels[CHANNEL_MATERIAL] : null;
  // the material payload directly follows the voxel payload (14.2): one request for both
  const end = mat ? mat.offset + mat.size : e.payloadOffset + e.payloadSize;
  const { bytes, fetched } = await fetchRange(msg.url, e.payloadOffset, end - e.payloadOffset);
  const v = decodeVoxelPayload(bytes.subarray(0, e.payloadSize), e);
  const n = e.voxelCount;
  const rec = new Uint32Array(3 * n);
  let colors = v.color;
  if (msg.material) {
    if (!mat) throw new Error(`node ${e.index} has no material payload`);
    const ids = decodeMaterialPayload(bytes.subarray(mat.offset - e.payloadOffset), mat, n);
    colors = new Uint32Array(n);
    const cache = new Map();
    for (let j = 0; j < n; j++) {
      let c = cache.get(ids[j]);
      if (c === undefined) cache.set(ids[j], (c = materialColor(ids[j])));
      colors[j] = c;
    }
  }
  for (let j = 0; j < n; j++) {
    rec[3 * j] = v.pos[j];
    rec[3 * j + 1] = v.normal[j];
    rec[3 * j + 2] = colors[j];
  }
  return { reply: { rec, fetched }, transfer: [rec.buffer] };
}

async function source(msg) {
  const ce = msg.entry.channels[2];
  const { bytes, fetched } = await fetchRange(msg.url, ce.offset, ce.size);
  const m = decodeSourcePayload(bytes, ce);
  const s = msg.voxelSize;
  const nv = m.positions.length / 3;
  const pos = new Float32Array(3 * nv);
  for (let k = 0; k < 3 * nv; k++) pos[k] = s * (m.positions[k] / 128 - 128);
  const nrm = new Float32Array(3 * nv);
  if (m.normals) {
    for (let j = 0; j < nv; j++) {
      const d = octDecode(m.normals[2 * j], m.normals[2 * j + 1]);
      nrm.set(d, 3 * j);
    }
  }
  let positions = pos;
  let normals = nrm;
  let colors;
  let indices;
  if (msg.material) {
    // one colour per triangle: vertices unshared
    const t = m.triangles.length / 3;
    positions = new Float32Array(9 * t);
    normals = new Float32Array(9 * t);
    colors = new Uint32Array(3 * t);
    indices = new Uint32Array(3 * t);
    for (let k = 0; k < 3 * t; k++) {
      const v = m.triangles[k];
      positions.set(pos.subarray(3 * v, 3 * v + 3), 3 * k);
      normals.set(nrm.subarray(3 * v, 3 * v + 3), 3 * k);
      colors[k] = materialColor(m.materials ? m.materials[Math.floor(k / 3)] : 0);
      indices[k] = k;
    }
  } else {
    colors = new Uint32Array(nv);
    for (let j = 0; j < nv; j++) {
      colors[j] = m.colors
        ? (m.colors[4 * j] | (m.colors[4 * j + 1] << 8) | (m.colors[4 * j + 2] << 16) | (m.colors[4 * j + 3] << 24)) >>> 0
        : 0xffffffff;
    }
    indices = m.triangles;
  }
  return {
    reply: { positions, normals, colors, indices, fetched },
    transfer: [positions.buffer, normals.buffer, colors.buffer, indices.buffer],
  };
}

self.onmessage = async (ev) => {
  const msg = ev.data;
  try {
    const { reply, transfer } = msg.kind === 'source' ? await source(msg) : await voxels(msg);
    self.postMessage({ id: msg.id, ok: true, ...reply }, transfer);
  } catch (e) {
    self.postMessage({ id: msg.id, ok: false, error: String(e && e.message ? e.message : e), fetched: e.fetched ?? 0 });
  }
};
