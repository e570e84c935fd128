// Tests of the reader module (voxlod-reader.mjs): FORMAT.md's worked examples, corrupted
// inputs, and, when VOXLOD_WEB_REF names a folder of reference dumps written by the Rust
// reader (tests/e2e/web.rs writes them and runs this file), every node of several files:
// voxels, face masks, normals, colours, materials and source triangles.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import {
  crc32, morton8, decodeBlock, decodeMaterialPayload, decodeSourcePayload, frameContentSize,
  unpackNormal, FormatError, VoxlodFile,
} from '../voxlod-reader.mjs';

const hex = (s) => Uint8Array.from(s.trim().split(/\s+/).map((b) => parseInt(b, 16)));

/** One zstd frame holding `bytes` as a single raw block (content size in the header). */
function rawFrame(bytes) {
  const n = bytes.length;
  const head = [0x28, 0xb5, 0x2f, 0xfd, 0xa0, n & 0xff, (n >> 8) & 0xff, (n >> 16) & 0xff, (n >> 24) & 0xff];
  const bh = 1 | (n << 3);
  return Uint8Array.from([...head, bh & 0xff, (bh >> 8) & 0xff, (bh >> 16) & 0xff, ...bytes]);
}

test('CRC-32 check value', () => {
  assert.equal(crc32(new TextEncoder().encode('123456789')), 0xcbf43926);
});

test('one voxel: the worked example of section 12', () => {
  assert.equal(morton8(3, 200, 17), 0x48440d);
  const block = hex('0D 44 48 09 33 9D 09 00 C8 96 64 FF');
  const v = decodeBlock(block, 1, { boundsMin: [3, 200, 17], boundsMax: [3, 200, 17] });
  assert.equal(v.pos[0], 0x0911c803);
  assert.equal(v.normal[0], 0x00099d33);
  assert.equal(v.color[0], 0xff6496c8);
  assert.deepEqual(unpackNormal(v.normal[0]), [307, -409, 0]);
});

test('two voxels: shuffle and plane deltas', () => {
  const block = hex('01 01 00 00 00 00 29 26  FF 01 01 FB 00 07 00 00  44 11 33 00 22 00 11 00');
  const v = decodeBlock(block, 2, { boundsMin: [0, 0, 0], boundsMax: [1, 1, 0] });
  assert.deepEqual([...v.pos], [0x29000001, 0x26000100]);
  assert.deepEqual([...v.normal], [0x000001ff, 0x0007fc00]);
  assert.deepEqual([...v.color], [0x11223344, 0x11223355]);
  // the bounds are checked
  assert.throws(() => decodeBlock(block, 2, { boundsMin: [0, 0, 0], boundsMax: [1, 1, 1] }), FormatError);
  // a zero Morton delta after the first voxel
  const zero = Uint8Array.from(block);
  zero[1] = 0;
  assert.throws(() => decodeBlock(zero, 2), /delta of 0/);
  // a normal component of −512
  const bad = Uint8Array.from(block);
  bad[8] = 0x00;
  bad[10] = 0x02; // byte 1 of voxel 0's normal: 0x200
  assert.throws(() => decodeBlock(bad, 2), /−512/);
});

test('material block: the example of section 14.3', () => {
  const block = hex('02 00 00 00  07 00 00 00  2C 01 00 00   01 01 02 01 00   00 00 00 00 00');
  const payload = rawFrame(block);
  const ce = { crc: crc32(payload), count: 3 };
  assert.deepEqual([...decodeMaterialPayload(payload, ce, 5)], [7, 7, 300, 7, 2]);
  assert.throws(() => decodeMaterialPayload(payload, { ...ce, crc: ce.crc ^ 1 }, 5), /CRC/);
  assert.throws(() => decodeMaterialPayload(payload, ce, 4), /declares/);
  // an unused table entry
  const unused = hex('02 00 00 00  07 00 00 00  2C 01 00 00   01 01 01 01 00   00 00 00 00 00');
  const p2 = rawFrame(unused);
  assert.throws(() => decodeMaterialPayload(p2, { crc: crc32(p2), count: 3 }, 5), /used by no voxel/);
});

test('source triangles: the example of section 14.4', () => {
  // two triangles (0,1,2), (2,1,3) over four vertices, positions only
  const v = 4;
  const t = 2;
  const head = [v, 0, 0, 0, t, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0];
  const xs = [0x00, 0x00, 0x00, 0xff, 0x00, 0x40, 0x00, 0xff]; // codes 0, 16384, 0, 65535
  const ys = [1, 2, 3, 4, 0, 0, 0, 0];
  const zs = [5, 6, 7, 8, 0, 0, 0, 0];
  const codes = [0, 0, 0, 1, 2, 0];
  const idx = [...codes, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0];
  const payload = rawFrame(Uint8Array.from([...head, ...xs, ...ys, ...zs, ...idx]));
  const m = decodeSourcePayload(payload, { crc: crc32(payload), count: t });
  assert.deepEqual([...m.triangles], [0, 1, 2, 2, 1, 3]);
  assert.deepEqual([0, 1, 2, 3].map((j) => m.positions[3 * j]), [0, 16384, 0, 65535]);
  assert.deepEqual([0, 1, 2, 3].map((j) => m.positions[3 * j + 1]), [1, 2, 3, 4]);
  assert.equal(m.normals, null);
  // a code above the vertices used so far
  const bad = [...head, ...xs, ...ys, ...zs, 0, 0, 0, 4, 2, 0, ...idx.slice(6)];
  const p2 = rawFrame(Uint8Array.from(bad));
  assert.throws(() => decodeSourcePayload(p2, { crc: crc32(p2), count: t }), /index code/);
});

test('zstd frame rules', () => {
  const f = rawFrame(Uint8Array.from([1, 2, 3]));
  assert.equal(frameContentSize(f), 3);
  assert.throws(() => frameContentSize(Uint8Array.from([...f, 0])), /exactly one zstd frame/);
  const skippable = Uint8Array.from([0x50, 0x2a, 0x4d, 0x18, 0, 0, 0, 0, ...f]);
  assert.throws(() => frameContentSize(skippable), /bad magic/);
  const noSize = Uint8Array.from(f);
  noSize[4] = 0x00; // no single segment, no content size
  assert.throws(() => frameContentSize(noSize), /content size/);
});

/** Reads ranges of a local file, as the browser reads them from a server. */
function fileRanges(file) {
  const fd = fs.openSync(file, 'r');
  return async (offset, length) => {
    const b = Buffer.alloc(length);
    const got = fs.readSync(fd, b, 0, length, offset);
    if (got !== length) throw new Error(`short read at ${offset}`);
    return new Uint8Array(b.buffer, b.byteOffset, length);
  };
}

/** A file's bytes as little-endian u32 words. */
function u32s(file) {
  const b = fs.readFileSync(file);
  return new Uint32Array(b.buffer.slice(b.byteOffset, b.byteOffset + b.length));
}

const refDir = process.env.VOXLOD_WEB_REF;
test('every node of the reference files equals the Rust reader\'s', { skip: !refDir && 'VOXLOD_WEB_REF is not set (tests/e2e/web.rs sets it)' }, async () => {
  const refs = JSON.parse(fs.readFileSync(path.join(refDir, 'refs.json'), 'utf8'));
  assert.ok(refs.length >= 2, 'several files');
  const seen = { materials: 0, source: 0, colours: 0 };
  for (const r of refs) {
    const size = fs.statSync(r.file).size;
    const f = await VoxlodFile.open(fileRanges(r.file), size);
    assert.equal(f.nodes.length, r.nodes, r.file);
    assert.deepEqual(f.channels, r.channels, r.file);
    assert.equal(f.root, r.root);
    for (let i = 0; i < f.nodes.length; i++) {
      const want = u32s(path.join(r.dir, `node-${i}.vox`));
      const v = await f.readVoxels(i);
      const n = f.nodes[i].voxelCount;
      assert.equal(want.length, 3 * n, `${r.file} node ${i}`);
      for (let j = 0; j < n; j++) {
        if (v.pos[j] !== want[3 * j] || v.normal[j] !== want[3 * j + 1] || v.color[j] !== want[3 * j + 2]) {
          assert.fail(`${r.file} node ${i} voxel ${j}: ${[v.pos[j], v.normal[j], v.color[j]]} != ${[want[3 * j], want[3 * j + 1], want[3 * j + 2]]}`);
        }
        if ((v.color[j] & 0xffffff) !== 0xffffff) seen.colours++;
      }
      const matFile = path.join(r.dir, `node-${i}.mat`);
      const mats = await f.readMaterials(i);
      if (fs.existsSync(matFile)) {
        const wm = u32s(matFile);
        assert.deepEqual([...mats], [...wm], `${r.file} node ${i} materials`);
        seen.materials++;
      } else {
        assert.equal(mats, null);
      }
      const srcFile = path.join(r.dir, `node-${i}.src.json`);
      const src = await f.readSourceTriangles(i);
      if (fs.existsSync(srcFile)) {
        const ws = JSON.parse(fs.readFileSync(srcFile, 'utf8'));
        assert.deepEqual([...src.positions], ws.positions, `${r.file} node ${i} source positions`);
        assert.deepEqual([...src.triangles], ws.triangles, `${r.file} node ${i} source triangles`);
        assert.deepEqual(src.normals && [...src.normals], ws.normals);
        assert.deepEqual(src.colors && [...src.colors], ws.colors);
        assert.deepEqual(src.materials && [...src.materials], ws.materials);
        seen.source++;
      } else {
        assert.equal(src, null, `${r.file} node ${i}: source triangles the Rust reader does not have`);
      }
    }
  }
  // the files exercise every part
  assert.ok(seen.materials > 0 && seen.source > 0 && seen.colours > 0, JSON.stringify(seen));
});
