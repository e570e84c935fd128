// A reader of voxlod octree files (docs/FORMAT.md), written from that document alone: the
// header, the node index, the channel directory and the manifest, and every node's voxels,
// materials and source triangles, with the document's checks. Plain ES module: it runs in
// browsers (the viewer and its Web Worker) and in node (its tests). Bytes come from a
// `readRange(offset, length)` function returning a Promise of a Uint8Array, so the same code
// reads a local file or an HTTP server by range requests.

import { decompress as zstdDecompress } from './vendor/fzstd.mjs';

export const HEADER_SIZE = 128;
export const INDEX_ENTRY_SIZE = 64;
export const CHANNEL_MATERIAL = 1;
export const CHANNEL_SOURCE_TRIANGLES = 2;
export const MAX_VOXELS = 256 * 256 * 256;

/** A file that breaks a rule of FORMAT.md. */
export class FormatError extends Error {
  constructor(message) {
    super(message);
    this.name = 'FormatError';
  }
}

function fail(message) {
  throw new FormatError(message);
}

// ---------------------------------------------------------------------------------------------
// CRC-32/IEEE (zlib's crc32): reflected polynomial 0xEDB88320.

const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    t[n] = c >>> 0;
  }
  return t;
})();

/** CRC-32 of `bytes` (a Uint8Array). */
export function crc32(bytes) {
  let c = 0xffffffff;
  for (let i = 0; i < bytes.length; i++) c = CRC_TABLE[(c ^ bytes[i]) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

// ---------------------------------------------------------------------------------------------
// Little-endian fields.

function view(u8) {
  return new DataView(u8.buffer, u8.byteOffset, u8.byteLength);
}

/** A u64 as a Number; larger than 2^53 is refused (no file of that size is readable here). */
function u64(dv, at, what) {
  const v = dv.getBigUint64(at, true);
  if (v > BigInt(Number.MAX_SAFE_INTEGER)) fail(`${what} ${v} is too large`);
  return Number(v);
}

// ---------------------------------------------------------------------------------------------
// Header (section 3).

const MAGIC = [0x56, 0x4f, 0x58, 0x4c, 0x4f, 0x44, 0x00, 0x01];

/**
 * Parses and checks the 128-byte header (section 11's order: magic, version, header_size,
 * header CRC, then the fields). `fileSize` (if known) is checked against the layout.
 */
export function parseHeader(u8, fileSize) {
  if (u8.length < HEADER_SIZE) fail(`the file is ${u8.length} bytes, shorter than the 128-byte header`);
  for (let i = 0; i < 8; i++) {
    if (u8[i] !== MAGIC[i]) fail('not a voxlod file (bad magic; an unfinished file has a zero header)');
  }
  const dv = view(u8);
  const version = dv.getUint32(8, true);
  if (version !== 1 && version !== 2) fail(`format version ${version} is not supported`);
  if (dv.getUint32(12, true) !== HEADER_SIZE) fail('header_size is not 128');
  if (crc32(u8.subarray(0, 124)) !== dv.getUint32(124, true)) fail('header CRC mismatch');
  const h = {
    version,
    resolution: dv.getUint32(16, true),
    levels: dv.getUint32(20, true),
    mode: dv.getUint32(24, true),
    flags: dv.getUint32(28, true),
    origin: [dv.getFloat64(32, true), dv.getFloat64(40, true), dv.getFloat64(48, true)],
    voxelSize: dv.getFloat64(56, true),
    nodeCount: u64(dv, 64, 'node_count'),
    indexOffset: u64(dv, 72, 'index_offset'),
    indexSize: u64(dv, 80, 'index_size'),
    manifestOffset: u64(dv, 88, 'manifest_offset'),
    manifestSize: u64(dv, 96, 'manifest_size'),
    totalVoxels: u64(dv, 104, 'total_voxels'),
    indexCrc: dv.getUint32(112, true),
    manifestCrc: dv.getUint32(116, true),
    channelsCrc: dv.getUint32(120, true),
  };
  const r = h.resolution;
  if (r < 256 || r > 2 ** 31 || (r & (r - 1)) !== 0) fail(`resolution ${r} is not a power of two in [256, 2^31]`);
  if (h.levels !== Math.log2(r) - 7) fail(`levels ${h.levels} does not match resolution ${r}`);
  if (h.mode > 1) fail(`mode ${h.mode} is neither 0 nor 1`);
  if (h.flags !== 0) fail('flags are reserved and not 0');
  if (!h.origin.every(Number.isFinite)) fail('origin is not finite');
  if (!(Number.isFinite(h.voxelSize) && h.voxelSize > 0)) fail('voxel_size is not a finite positive number');
  if (version === 1 && h.channelsCrc !== 0) fail('reserved header word 120 is not 0');
  if (h.indexOffset < HEADER_SIZE || h.indexOffset % 8 !== 0) fail('index_offset is below 128 or not a multiple of 8');
  if (h.indexSize !== h.nodeCount * INDEX_ENTRY_SIZE) fail('index_size is not node_count · 64');
  const indexEnd = h.indexOffset + h.indexSize;
  if (version === 1 ? h.manifestOffset !== indexEnd : h.manifestOffset < indexEnd + 8) {
    fail('the manifest does not follow the index');
  }
  h.fileSize = h.manifestOffset + h.manifestSize;
  if (fileSize !== undefined && fileSize !== h.fileSize) {
    fail(`the file is ${fileSize} bytes but its header says ${h.fileSize}`);
  }
  return h;
}

// ---------------------------------------------------------------------------------------------
// Node index (section 4), channel directory (14.1), manifest (9, 11.2).

/** The level-0 Morton code of (x, y, z) as a BigInt (bit b of x → 3b, y → 3b+1, z → 3b+2). */
function morton(x, y, z) {
  let m = 0n;
  for (let b = 0; b < 32; b++) {
    m |= BigInt((x >>> b) & 1) << BigInt(3 * b);
    m |= BigInt((y >>> b) & 1) << BigInt(3 * b + 1);
    m |= BigInt((z >>> b) & 1) << BigInt(3 * b + 2);
  }
  return m;
}

/** The index order key of section 4, as [end, level]. */
function orderKey(e) {
  return [(morton(e.x, e.y, e.z) + 1n) << BigInt(3 * e.level), e.level];
}

/** Deepest `[`/`{` nesting outside strings (the manifest rule (3) of 11.2). */
function jsonDepth(text) {
  let depth = 0;
  let max = 0;
  let inString = false;
  for (let i = 0; i < text.length; i++) {
    const c = text[i];
    if (inString) {
      if (c === '\\') i++;
      else if (c === '"') inString = false;
    } else if (c === '"') inString = true;
    else if (c === '[' || c === '{') max = Math.max(max, ++depth);
    else if (c === ']' || c === '}') depth--;
  }
  return max;
}

/**
 * Parses the bytes from `index_offset` to the end of the file: the node index, the channel
 * directory (version 2) and the manifest, with the checks of section 11 (CRCs, the manifest
 * rules, and per entry: level, position, count, child mask, payload placement, bounds, order,
 * then the totals and the tree invariants).
 */
export function parseTail(u8, h) {
  if (u8.length !== h.fileSize - h.indexOffset) fail('the index and manifest are cut short');
  const index = u8.subarray(0, h.indexSize);
  if (crc32(index) !== h.indexCrc) fail('index CRC mismatch');
  const dir = u8.subarray(h.indexSize, h.manifestOffset - h.indexOffset);
  const manifestBytes = u8.subarray(h.manifestOffset - h.indexOffset);
  const channels = h.version === 2 ? parseChannelDirectory(dir, h) : [];
  if (crc32(manifestBytes) !== h.manifestCrc) fail('manifest CRC mismatch');
  const manifest = parseManifest(manifestBytes);

  const dv = view(index);
  const nodes = [];
  let expect = HEADER_SIZE;
  let total = 0;
  let prevKey = null;
  for (let i = 0; i < h.nodeCount; i++) {
    const at = i * INDEX_ENTRY_SIZE;
    const e = {
      index: i,
      level: dv.getUint32(at, true),
      x: dv.getUint32(at + 4, true),
      y: dv.getUint32(at + 8, true),
      z: dv.getUint32(at + 12, true),
      voxelCount: dv.getUint32(at + 16, true),
      childMask: dv.getUint32(at + 20, true),
      payloadOffset: u64(dv, at + 24, 'payload_offset'),
      payloadSize: u64(dv, at + 32, 'payload_size'),
      payloadCrc: dv.getUint32(at + 40, true),
      blockCrc: dv.getUint32(at + 44, true),
      boundsMin: [index[at + 48], index[at + 49], index[at + 50]],
      boundsMax: [index[at + 52], index[at + 53], index[at + 54]],
      channels: {},
    };
    const where = `node ${i} (level ${e.level}, ${e.x},${e.y},${e.z})`;
    if (e.level >= h.levels) fail(`${where}: level beyond the file's ${h.levels} levels`);
    const side = (h.resolution / 256) >>> e.level;
    if (e.x >= side || e.y >= side || e.z >= side) fail(`${where}: position outside its level's grid`);
    if (e.voxelCount < 1 || e.voxelCount > MAX_VOXELS) fail(`${where}: voxel count ${e.voxelCount}`);
    if (e.childMask > 0xff || (e.level === 0 && e.childMask !== 0)) fail(`${where}: bad child mask`);
    if (e.payloadSize < 1 || e.payloadOffset !== expect) fail(`${where}: payload not right after the previous one`);
    expect = e.payloadOffset + e.payloadSize;
    for (const c of channels) {
      const ce = c.entries[i];
      if (ce.size === 0) continue;
      if (ce.offset !== expect) fail(`${where}: channel ${c.id} payload not right after the previous one`);
      expect = ce.offset + ce.size;
      e.channels[c.id] = ce;
      if (c.id === CHANNEL_MATERIAL && !(ce.count >= 1 && ce.count <= Math.min(e.voxelCount, 65536))) {
        fail(`${where}: material table length ${ce.count}`);
      }
      if (c.id === CHANNEL_SOURCE_TRIANGLES && e.level !== 0) fail(`${where}: source triangles above level 0`);
    }
    if (expect > h.indexOffset) fail(`${where}: payload runs into the index`);
    if (index[at + 51] !== 0 || index[at + 55] !== 0) fail(`${where}: bounds' 4th bytes are not 0`);
    for (let a = 0; a < 3; a++) if (e.boundsMin[a] > e.boundsMax[a]) fail(`${where}: bounds min above max`);
    if (dv.getUint32(at + 56, true) !== 0 || dv.getUint32(at + 60, true) !== 0) fail(`${where}: reserved words not 0`);
    const key = orderKey(e);
    if (prevKey && !(key[0] > prevKey[0] || (key[0] === prevKey[0] && key[1] > prevKey[1]))) {
      fail(`${where}: entries not in index order`);
    }
    prevKey = key;
    total += e.voxelCount;
    nodes.push(e);
  }
  if (total !== h.totalVoxels) fail(`the entries hold ${total} voxels, the header says ${h.totalVoxels}`);
  if (h.indexOffset - expect >= 8) fail('more than 7 bytes of padding before the index');
  return { nodes, channels: channels.map((c) => c.id), manifest, tree: buildTree(nodes, h) };
}

/** Checks and reads the channel directory (14.1): per channel its id and per-node entries. */
function parseChannelDirectory(dir, h) {
  if (crc32(dir) !== h.channelsCrc) fail('channel directory CRC mismatch');
  if (dir.length < 8) fail('the channel directory is cut short');
  const dv = view(dir);
  const count = dv.getUint32(0, true);
  if (count < 1 || count > 16) fail(`channel count ${count} is not in [1, 16]`);
  if (dv.getUint32(4, true) !== 0) fail('channel directory reserved word is not 0');
  if (dir.length < 8 + 16 * count) fail('the channel directory is cut short');
  const out = [];
  let at = 8 + 16 * count;
  let prevId = 0;
  for (let k = 0; k < count; k++) {
    const d = 8 + 16 * k;
    const id = dv.getUint32(d, true);
    const entrySize = dv.getUint32(d + 4, true);
    if (k > 0 && id <= prevId) fail('channel ids are not increasing');
    prevId = id;
    if (entrySize < 24 || entrySize % 8 !== 0) fail(`channel ${id}: entry size ${entrySize}`);
    if (dv.getUint32(d + 8, true) !== 0 || dv.getUint32(d + 12, true) !== 0) fail(`channel ${id}: reserved not 0`);
    if (at + h.nodeCount * entrySize > dir.length) fail('the channel directory is cut short');
    const entries = [];
    for (let i = 0; i < h.nodeCount; i++, at += entrySize) {
      const ce = {
        offset: u64(dv, at, 'channel payload_offset'),
        size: u64(dv, at + 8, 'channel payload_size'),
        crc: dv.getUint32(at + 16, true),
        count: dv.getUint32(at + 20, true),
      };
      if (ce.size === 0 && (ce.offset !== 0 || ce.crc !== 0 || ce.count !== 0)) {
        fail(`channel ${id}: node ${i} has no payload but a non-zero entry`);
      }
      entries.push(ce);
    }
    out.push({ id, entries });
  }
  if (at !== dir.length) fail('the channel directory has a wrong size');
  return out;
}

/** The manifest's JSON object, with the rules of 11.2. */
export function parseManifest(bytes) {
  if (bytes.length === 0) fail('the manifest is empty');
  let text;
  try {
    text = new TextDecoder('utf-8', { fatal: true }).decode(bytes);
  } catch {
    fail('the manifest is not UTF-8');
  }
  if (jsonDepth(text) > 64) fail('the manifest nests deeper than 64');
  let v;
  try {
    v = JSON.parse(text);
  } catch (e) {
    fail(`the manifest is not JSON: ${e.message}`);
  }
  if (v === null || typeof v !== 'object' || Array.isArray(v)) fail('the manifest is not a JSON object');
  return v;
}

/** Children and parents by position; checks child masks and that every parent is stored. */
function buildTree(nodes, h) {
  const byKey = new Map();
  const key = (l, x, y, z) => `${l}/${x}/${y}/${z}`;
  nodes.forEach((e, i) => byKey.set(key(e.level, e.x, e.y, e.z), i));
  const children = nodes.map(() => []);
  let root = -1;
  for (const e of nodes) {
    if (e.level === h.levels - 1) {
      root = e.index;
    } else {
      const p = byKey.get(key(e.level + 1, e.x >>> 1, e.y >>> 1, e.z >>> 1));
      if (p === undefined) fail(`node ${e.index} has no parent`);
    }
    if (e.level > 0) {
      let mask = 0;
      for (let o = 0; o < 8; o++) {
        const c = byKey.get(key(e.level - 1, 2 * e.x + (o & 1), 2 * e.y + ((o >> 1) & 1), 2 * e.z + (o >> 2)));
        if (c !== undefined) {
          mask |= 1 << o;
          children[e.index].push(c);
        }
      }
      if (mask !== e.childMask) fail(`node ${e.index}: child mask differs from the stored children`);
    }
  }
  if (nodes.length > 0 && root !== nodes.length - 1) fail('the root is not the last entry');
  return { root, children };
}

// ---------------------------------------------------------------------------------------------
// zstd frames (section 5, 11.2): one frame with a content size, nothing after it.

/** The content size a zstd frame declares, after checking it is one whole frame of `u8`. */
export function frameContentSize(u8) {
  if (u8.length < 6 || u8[0] !== 0x28 || u8[1] !== 0xb5 || u8[2] !== 0x2f || u8[3] !== 0xfd) {
    fail('the payload is not a zstd frame (bad magic)');
  }
  const fhd = u8[4];
  const fcsFlag = fhd >> 6;
  const single = (fhd >> 5) & 1;
  const checksum = (fhd >> 2) & 1;
  if ((fhd >> 3) & 1) fail('the zstd frame header has its reserved bit set');
  const didSize = [0, 1, 2, 4][fhd & 3];
  const fcsSize = [single ? 1 : 0, 2, 4, 8][fcsFlag];
  if (fcsSize === 0) fail('the zstd frame has no content size');
  let at = 5 + (single ? 0 : 1) + didSize;
  if (at + fcsSize > u8.length) fail('the zstd frame header is cut short');
  const dv = view(u8);
  let size;
  if (fcsSize === 1) size = u8[at];
  else if (fcsSize === 2) size = dv.getUint16(at, true) + 256;
  else if (fcsSize === 4) size = dv.getUint32(at, true);
  else size = u64(dv, at, 'zstd content size');
  at += fcsSize;
  for (;;) {
    if (at + 3 > u8.length) fail('the zstd frame is cut short');
    const bh = u8[at] | (u8[at + 1] << 8) | (u8[at + 2] << 16);
    at += 3;
    const type = (bh >> 1) & 3;
    if (type === 3) fail('the zstd frame has a reserved block type');
    at += type === 1 ? 1 : bh >>> 3;
    if (at > u8.length) fail('the zstd frame is cut short');
    if (bh & 1) break;
  }
  if (checksum) at += 4;
  if (at !== u8.length) fail('the payload is not exactly one zstd frame (bytes after it)');
  return size;
}

/** Decompresses one checked frame of exactly `expected` bytes. */
function inflate(payload, expected, declared) {
  const size = declared ?? frameContentSize(payload);
  if (size !== expected) fail(`the zstd frame declares ${size} bytes, not ${expected}`);
  let out;
  try {
    out = zstdDecompress(payload);
  } catch (e) {
    fail(`zstd: ${e.message}`);
  }
  if (out.length !== expected) fail(`the payload decompresses to ${out.length} bytes, not ${expected}`);
  return out;
}

// ---------------------------------------------------------------------------------------------
// Voxels (sections 5 and 6).

/** Every third bit of a 24-bit Morton code, from bit 0: one axis of morton8. */
function compact3(v) {
  v &= 0x249249;
  v = (v ^ (v >>> 2)) & 0x0c30c3;
  v = (v ^ (v >>> 4)) & 0x00f00f;
  v = (v ^ (v >>> 8)) & 0xff;
  return v;
}

/** morton8(x, y, z) of section 5.1 (for tests). */
export function morton8(x, y, z) {
  let m = 0;
  for (let b = 0; b < 8; b++) {
    m |= ((x >> b) & 1) << (3 * b);
    m |= ((y >> b) & 1) << (3 * b + 1);
    m |= ((z >> b) & 1) << (3 * b + 2);
  }
  return m;
}

/**
 * Decodes a node's voxel block (12n bytes as decompressed) into the three words of each
 * voxel record (section 6): `pos` (x | y<<8 | z<<16 | face mask<<24), `normal`, `color`.
 * Checks the rules of 5.2; `entry` gives the bounds to compare.
 */
export function decodeBlock(block, n, entry) {
  if (block.length !== 12 * n) fail(`the block is ${block.length} bytes, not 12·${n}`);
  const pos = new Uint32Array(n);
  const normal = new Uint32Array(n);
  const color = new Uint32Array(n);
  // positions: 4 planes, no delta
  const p0 = 0;
  let m = 0;
  const lo = [255, 255, 255];
  const hi = [0, 0, 0];
  for (let j = 0; j < n; j++) {
    const w = (block[p0 + j] | (block[p0 + n + j] << 8) | (block[p0 + 2 * n + j] << 16) | (block[p0 + 3 * n + j] << 24)) >>> 0;
    if (w >>> 30) fail(`voxel ${j}: bits 30–31 of the position word are set`);
    const d = w & 0xffffff;
    if (j > 0 && d === 0) fail(`voxel ${j}: a Morton delta of 0`);
    m += d;
    if (m >= 1 << 24) fail(`voxel ${j}: the Morton code reaches 2^24`);
    const x = compact3(m);
    const y = compact3(m >>> 1);
    const z = compact3(m >>> 2);
    if (x < lo[0]) lo[0] = x;
    if (y < lo[1]) lo[1] = y;
    if (z < lo[2]) lo[2] = z;
    if (x > hi[0]) hi[0] = x;
    if (y > hi[1]) hi[1] = y;
    if (z > hi[2]) hi[2] = z;
    pos[j] = (x | (y << 8) | (z << 16) | (((w >>> 24) & 0x3f) << 24)) >>> 0;
  }
  // normals and colours: 4 planes each, byte deltas within a plane
  for (const [a, out] of [[1, normal], [2, color]]) {
    for (let b = 0; b < 4; b++) {
      const base = 4 * n * a + n * b;
      let acc = 0;
      const shift = 8 * b;
      for (let j = 0; j < n; j++) {
        acc = (acc + block[base + j]) & 0xff;
        out[j] = (out[j] | (acc << shift)) >>> 0;
      }
    }
  }
  for (let j = 0; j < n; j++) {
    const w = normal[j];
    if (w >>> 30) fail(`voxel ${j}: bits 30–31 of the normal word are set`);
    if ((w & 0x3ff) === 0x200 || ((w >>> 10) & 0x3ff) === 0x200 || ((w >>> 20) & 0x3ff) === 0x200) {
      fail(`voxel ${j}: a normal component is −512`);
    }
  }
  if (entry) {
    for (let a = 0; a < 3; a++) {
      if (lo[a] !== entry.boundsMin[a] || hi[a] !== entry.boundsMax[a]) {
        fail("the decoded positions' bounds differ from the index entry's");
      }
    }
  }
  return { pos, normal, color };
}

/** A node's voxels from its voxel payload (CRCs, frame rules, decompression, decoding). */
export function decodeVoxelPayload(payload, entry) {
  if (payload.length !== entry.payloadSize) fail(`node ${entry.index}: payload cut short`);
  if (crc32(payload) !== entry.payloadCrc) fail(`node ${entry.index}: payload CRC mismatch`);
  const block = inflate(payload, 12 * entry.voxelCount);
  if (crc32(block) !== entry.blockCrc) fail(`node ${entry.index}: block CRC mismatch`);
  return decodeBlock(block, entry.voxelCount, entry);
}

/** Sign-extended 10-bit components of a packed normal, each in [−511, 511]. */
export function unpackNormal(w) {
  return [(w << 22) >> 22, (w << 12) >> 22, (w << 2) >> 22];
}

// ---------------------------------------------------------------------------------------------
// Material channel (14.3).

/** Per-voxel material ids (Uint32Array of n) from a node's material payload. */
export function decodeMaterialPayload(payload, ce, n) {
  if (crc32(payload) !== ce.crc) fail('material payload CRC mismatch');
  const t = ce.count;
  const block = inflate(payload, 4 * t + 2 * n);
  const dv = view(block);
  const table = new Uint32Array(t);
  for (let k = 0; k < t; k++) {
    table[k] = dv.getUint32(4 * k, true);
    if (k > 0 && table[k] <= table[k - 1]) fail('the material table is not strictly increasing');
  }
  const used = new Uint8Array(t);
  const out = new Uint32Array(n);
  for (let j = 0; j < n; j++) {
    const i = block[4 * t + j] | (block[4 * t + n + j] << 8);
    if (i >= t) fail(`voxel ${j}: material index ${i} beyond the table of ${t}`);
    used[i] = 1;
    out[j] = table[i];
  }
  if (used.some((u) => !u)) fail('a material table entry is used by no voxel');
  return out;
}

// ---------------------------------------------------------------------------------------------
// Source triangles (14.4).

export const ATTR_NORMALS = 1;
export const ATTR_COLORS = 2;
export const ATTR_MATERIALS = 4;

function sourceBlockSize(v, t, attrs) {
  const perVertex = 6 + (attrs & ATTR_NORMALS ? 4 : 0) + (attrs & ATTR_COLORS ? 4 : 0);
  const perTriangle = 12 + (attrs & ATTR_MATERIALS ? 2 : 0);
  return 16 + v * perVertex + t * perTriangle;
}

/** Reads `count` values of `k` bytes stored as byte planes from `at`. */
function planes(block, at, count, k) {
  const out = k === 2 ? new Uint16Array(count) : new Uint32Array(count);
  for (let b = 0; b < k; b++) {
    const base = at + b * count;
    const s = 8 * b;
    for (let j = 0; j < count; j++) out[j] |= block[base + j] << s;
  }
  return out;
}

/**
 * A leaf's source triangles from its payload in channel 2: `positions` (3 u16 codes per
 * vertex, x y z), `normals` (2 octahedral u16 codes per vertex) or null, `colors` (RGBA8 per
 * vertex) or null, `triangles` (3 vertex indices each), `materials` (u16 per triangle) or null.
 */
export function decodeSourcePayload(payload, ce) {
  if (crc32(payload) !== ce.crc) fail('source triangle payload CRC mismatch');
  const t = ce.count;
  if (t < 1 || t > 2 ** 26) fail(`source triangle count ${t}`);
  const declared = frameContentSize(payload);
  if (declared > sourceBlockSize(3 * t, t, 7)) fail('the source triangle frame declares too many bytes');
  const block = inflate(payload, declared, declared);
  if (block.length < 16) fail('the source triangle block is cut short');
  const dv = view(block);
  const v = dv.getUint32(0, true);
  const attrs = dv.getUint32(8, true);
  if (dv.getUint32(4, true) !== t) fail('the source triangle count differs from the entry');
  if (attrs & ~7) fail('unknown source triangle attribute bits');
  if (dv.getUint32(12, true) !== 0) fail('source triangle reserved word is not 0');
  if (v < 1 || v > 3 * t) fail(`source vertex count ${v}`);
  if (block.length !== sourceBlockSize(v, t, attrs)) fail('the source triangle block has a wrong size');
  let at = 16;
  const positions = new Uint16Array(3 * v);
  for (let a = 0; a < 3; a++) {
    const c = planes(block, at, v, 2);
    for (let j = 0; j < v; j++) positions[3 * j + a] = c[j];
    at += 2 * v;
  }
  let normals = null;
  if (attrs & ATTR_NORMALS) {
    normals = new Uint16Array(2 * v);
    for (let a = 0; a < 2; a++) {
      const c = planes(block, at, v, 2);
      for (let j = 0; j < v; j++) normals[2 * j + a] = c[j];
      at += 2 * v;
    }
  }
  let colors = null;
  if (attrs & ATTR_COLORS) {
    colors = new Uint8Array(4 * v);
    for (let c = 0; c < 4; c++) for (let j = 0; j < v; j++) colors[4 * j + c] = block[at + c * v + j];
    at += 4 * v;
  }
  const codes = planes(block, at, 3 * t, 4);
  at += 12 * t;
  const triangles = new Uint32Array(3 * t);
  let next = 0;
  for (let k = 0; k < 3 * t; k++) {
    const c = codes[k];
    if (c > next) fail(`source triangle index code ${c} above ${next}`);
    if (c === 0) triangles[k] = next++;
    else triangles[k] = next - c;
    if (next > v) fail('more source vertices used than stored');
  }
  if (next !== v) fail('not every source vertex is used');
  const materials = attrs & ATTR_MATERIALS ? planes(block, at, t, 2) : null;
  return { positions, normals, colors, triangles, materials };
}

/** The unit direction of octahedral normal codes (a, b). */
export function octDecode(a, b) {
  let u = (a / 65535) * 2 - 1;
  let v = (b / 65535) * 2 - 1;
  const w = 1 - Math.abs(u) - Math.abs(v);
  if (w < 0) {
    const su = u >= 0 ? 1 : -1;
    const sv = v >= 0 ? 1 : -1;
    [u, v] = [(1 - Math.abs(v)) * su, (1 - Math.abs(u)) * sv];
  }
  const l = Math.hypot(u, v, w);
  return [u / l, v / l, w / l];
}

// ---------------------------------------------------------------------------------------------
// Geometry (section 7).

/** Edge of a voxel of `level`. */
export function voxelSizeAt(h, level) {
  return h.voxelSize * 2 ** level;
}

/** World box of node `e`'s voxels: from its bounds_min voxel's minimum corner to bounds_max's maximum. */
export function nodeBounds(h, e) {
  const s = voxelSizeAt(h, e.level);
  const p = [e.x, e.y, e.z];
  return {
    min: [0, 1, 2].map((a) => h.origin[a] + s * (256 * p[a] + e.boundsMin[a])),
    max: [0, 1, 2].map((a) => h.origin[a] + s * (256 * p[a] + e.boundsMax[a] + 1)),
  };
}

// ---------------------------------------------------------------------------------------------
// A whole file.

/** An open file: header, nodes, tree, manifest; node data read on demand through `readRange`. */
export class VoxlodFile {
  constructor(readRange, header, tail) {
    this.readRange = readRange;
    this.header = header;
    this.nodes = tail.nodes;
    this.channels = tail.channels;
    this.manifest = tail.manifest;
    this.root = tail.tree.root;
    this.children = tail.tree.children;
  }

  /** Opens a file: two reads, the header and everything from the index to the end. */
  static async open(readRange, fileSize) {
    const head = await readRange(0, HEADER_SIZE);
    const h = parseHeader(head, fileSize);
    const tail = await readRange(h.indexOffset, h.fileSize - h.indexOffset);
    return new VoxlodFile(readRange, h, parseTail(tail, h));
  }

  hasMaterials() {
    return this.channels.includes(CHANNEL_MATERIAL);
  }

  hasSourceTriangles() {
    return this.channels.includes(CHANNEL_SOURCE_TRIANGLES);
  }

  async readVoxels(i) {
    const e = this.nodes[i];
    return decodeVoxelPayload(await this.readRange(e.payloadOffset, e.payloadSize), e);
  }

  /** Per-voxel material ids, or null without the material channel. */
  async readMaterials(i) {
    const ce = this.nodes[i].channels[CHANNEL_MATERIAL];
    if (!ce) return null;
    return decodeMaterialPayload(await this.readRange(ce.offset, ce.size), ce, this.nodes[i].voxelCount);
  }

  /** The leaf's source triangles, or null where it has none. */
  async readSourceTriangles(i) {
    const ce = this.nodes[i].channels[CHANNEL_SOURCE_TRIANGLES];
    if (!ce) return null;
    return decodeSourcePayload(await this.readRange(ce.offset, ce.size), ce);
  }
}
