#!/usr/bin/env python3
"""A second, independent reader for voxlod files, written from docs/FORMAT.md alone.

It exists to prove the format document is complete: nothing here was taken from the Rust
code. It reads a file with positioned reads (no memory map, so a file truncated while it is
open is an error, not SIGBUS: FORMAT.md 11.1), checks the header, index and manifest (section
11), applies the manifest and zstd frame rules of section 11.2 (the same as the Rust reader
and `voxlod verify`), lists the nodes and decodes a node's voxels (section 5.2) into numpy
arrays. Every allocation is bounded by the file size or the spec's 12·n bytes per node, and
every error names the file.

Needs numpy and zstandard (`pip install numpy zstandard`); CRC-32 comes from zlib.

Usage:
    voxlod_read.py FILE                      # header and a table of the nodes
    voxlod_read.py FILE --json               # the same as JSON
    voxlod_read.py FILE --node L X Y Z       # decode one node, print its first voxels
    voxlod_read.py FILE --node L X Y Z --raw OUT
        # write the node's voxels as plain 12-byte records (pos_mask, normal, color; u32 LE)
    voxlod_read.py FILE --check              # decode every node (all checks of 5.2;
                                             # and every material payload, 14.3)
    voxlod_read.py FILE --node L X Y Z --materials OUT
        # write the node's per-voxel material ids (u32 LE, voxel order; section 14.3)
    voxlod_read.py FILE --node 0 X Y Z --source OUT
        # write the leaf's source triangles as JSON (codes as stored; section 14.4)

As a library:
    f = VoxlodFile("bunny.voxlod")
    f.header["resolution"], len(f.nodes)
    v = f.decode(f.nodes[-1])                # the root: dict of numpy arrays
    v["pos"], v["mask"], v["normal"], v["color"]
    f.materials(f.nodes[-1])                 # per-voxel material ids, or None (section 14)
    f.source(f.nodes[0])                     # a leaf's source triangles, or None (14.4)
"""

import argparse
import json
import os
import stat
import struct
import sys
import zlib

import numpy as np
import zstandard

MAGIC = b"VOXLOD\x00\x01"
HEADER_SIZE = 128
ENTRY_SIZE = 64
MAX_VOXELS = 256**3
MAX_MANIFEST_DEPTH = 64  # FORMAT.md 11.2
ZSTD_MAGIC = 0xFD2FB528
SKIPPABLE_MAGIC = 0x184D2A50  # ..0x184D2A5F
# Section 14: optional channels (version 2).
CHANNEL_MATERIAL = 1
CHANNEL_TRIANGLES = 2
MAX_SOURCE_TRIANGLES = 1 << 26
MAX_CHANNELS = 16
MAX_MATERIAL_TABLE = 65536

# Section 3: the header, little-endian.
HEADER_STRUCT = struct.Struct("<8sIIIIII3ddQQQQQQIIII")
assert HEADER_STRUCT.size == HEADER_SIZE

# Section 4: one index entry.
ENTRY_DTYPE = np.dtype(
    [
        ("level", "<u4"),
        ("x", "<u4"),
        ("y", "<u4"),
        ("z", "<u4"),
        ("voxel_count", "<u4"),
        ("child_mask", "<u4"),
        ("payload_offset", "<u8"),
        ("payload_size", "<u8"),
        ("payload_crc32", "<u4"),
        ("block_crc32", "<u4"),
        ("bounds_min", "u1", (4,)),
        ("bounds_max", "u1", (4,)),
        ("reserved", "<u4", (2,)),
    ]
)
assert ENTRY_DTYPE.itemsize == ENTRY_SIZE


class FormatError(Exception):
    """The file is not a valid voxlod file (version 1 or 2); the message says where."""


def crc32(data):
    return zlib.crc32(data) & 0xFFFFFFFF


def morton_key(x, y, z):
    """Interleave bits: bit b of x -> 3b, of y -> 3b+1, of z -> 3b+2 (any width)."""
    code = 0
    b = 0
    while (x | y | z) >> b:
        code |= ((x >> b) & 1) << (3 * b)
        code |= ((y >> b) & 1) << (3 * b + 1)
        code |= ((z >> b) & 1) << (3 * b + 2)
        b += 1
    return code


def order_key(level, x, y, z):
    """Section 4: entries are sorted by ((morton + 1) << 3*level, level)."""
    return ((morton_key(x, y, z) + 1) << (3 * level), level)


def _spread8(v):
    """Spread the 8 bits of each element to every third bit (vectorised morton8 part)."""
    v = v.astype(np.uint32)
    out = np.zeros_like(v)
    for b in range(8):
        out |= ((v >> b) & 1) << (3 * b)
    return out


def _compact8(m):
    """Inverse of _spread8: collect every third bit starting at bit 0."""
    out = np.zeros_like(m)
    for b in range(8):
        out |= ((m >> (3 * b)) & 1) << b
    return out


def morton8(x, y, z):
    return _spread8(x) | (_spread8(y) << 1) | (_spread8(z) << 2)


def _sign_extend10(v):
    v = v.astype(np.int32)
    return np.where(v >= 512, v - 1024, v)


def json_depth(raw):
    """Deepest nesting of [ and { outside JSON strings (FORMAT.md 11.2), by a byte scan, so
    that no parser recurses on a hostile manifest."""
    depth = deepest = 0
    in_string = escaped = False
    for b in raw:
        if in_string:
            if escaped:
                escaped = False
            elif b == 0x5C:  # backslash
                escaped = True
            elif b == 0x22:  # quote
                in_string = False
        elif b == 0x22:
            in_string = True
        elif b in (0x5B, 0x7B):
            depth += 1
            deepest = max(deepest, depth)
        elif b in (0x5D, 0x7D):
            depth = max(depth - 1, 0)
    return deepest


def check_manifest(raw):
    """FORMAT.md 11.2, the manifest rules in order: not empty, UTF-8, nesting depth at most
    64, one JSON value, an object. Returns the parsed object."""
    if not raw:
        raise FormatError("bad manifest: it is empty (a manifest is a JSON object)")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise FormatError(f"bad manifest: it is not valid UTF-8 (at byte {e.start})") from None
    depth = json_depth(raw)
    if depth > MAX_MANIFEST_DEPTH:
        raise FormatError(f"bad manifest: its JSON nests {depth} levels deep, more than the "
                          f"{MAX_MANIFEST_DEPTH} allowed")
    try:
        value = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as e:
        raise FormatError(f"bad manifest: it is not valid JSON: {e}") from None
    if not isinstance(value, dict):
        raise FormatError("bad manifest: its JSON is not an object")
    return value


def check_frame(payload, n, want=None, formula=None):
    """FORMAT.md 11.2, the payload rules in order: the zstd magic (not a skippable frame), a
    content size in the frame header, equal to 12·n (or `want` bytes, for a channel payload,
    14.2); the rest (one frame, no trailing bytes) is checked while decompressing."""
    if want is None:
        want, formula = 12 * n, f"12·{n}"
    if len(payload) < 4:
        raise FormatError(f"the payload is {len(payload)} bytes, too short for a zstd frame")
    magic = struct.unpack_from("<I", payload)[0]
    if magic & 0xFFFFFFF0 == SKIPPABLE_MAGIC:
        raise FormatError("the payload starts with a skippable zstd frame")
    if magic != ZSTD_MAGIC:
        raise FormatError("the payload does not start with the zstd magic (28 b5 2f fd)")
    try:
        size = zstandard.get_frame_parameters(payload).content_size
    except zstandard.ZstdError:
        raise FormatError("the zstd frame header is corrupt or cut short") from None
    if size == getattr(zstandard, "CONTENTSIZE_UNKNOWN", 2**64 - 1):
        raise FormatError(f"the zstd frame header has no content size (it must say {formula})")
    if size != want:
        raise FormatError(f"the zstd frame header's content size is {size} bytes, "
                          f"expected {formula} = {want}")


class VoxlodFile:
    """A validated, memory-mapped voxlod file. `header` is a dict, `nodes` a numpy
    structured array of index entries (ENTRY_DTYPE), `manifest` the parsed JSON."""

    def __init__(self, path):
        self.path = str(path)
        try:
            self._fh = open(path, "rb")
        except OSError as e:
            raise FormatError(f"{path}: cannot open: {e.strerror}") from None
        try:
            st = os.fstat(self._fh.fileno())
            if not stat.S_ISREG(st.st_mode):
                raise FormatError("not a regular file")
            self.size = st.st_size
            self.header = self._read_header()
            self.nodes = self._read_index()
            self.channels = self._read_channels()
            self.manifest = self._read_manifest()
            self._check_nodes()
        except FormatError as e:
            self._fh.close()
            raise FormatError(f"{self.path}: {e}") from None
        self._dctx = zstandard.ZstdDecompressor()

    def _read(self, offset, size, what):
        """`size` bytes at `offset` by positioned reads; the callers bound `size` by the
        file size checked at open (or by 12·n)."""
        parts = []
        got = 0
        while got < size:
            b = os.pread(self._fh.fileno(), size - got, offset + got)
            if not b:
                raise FormatError(f"the file ends before its {what} [{offset}, +{size}): "
                                  "it was truncated after it was opened")
            parts.append(b)
            got += len(b)
        return b"".join(parts)

    # -- section 3 -------------------------------------------------------------------------
    def _read_header(self):
        if self.size < HEADER_SIZE:
            raise FormatError(f"file is {self.size} bytes, shorter than the 128-byte header")
        m = self._read(0, HEADER_SIZE, "header")
        f = HEADER_STRUCT.unpack_from(m, 0)
        (magic, version, header_size, resolution, levels, mode, flags, ox, oy, oz, voxel_size,
         node_count, index_offset, index_size, manifest_offset, manifest_size, total_voxels,
         index_crc, manifest_crc, reserved, header_crc) = f
        if magic != MAGIC:
            raise FormatError(f"bad magic {magic!r} (an unfinished file has a zero header)")
        if version not in (1, 2):
            raise FormatError(f"unsupported version {version}")
        if header_size != HEADER_SIZE:
            raise FormatError(f"header_size {header_size} != 128")
        if crc32(m[0:124]) != header_crc:
            raise FormatError("header CRC mismatch")
        if resolution < 256 or resolution > 2**31 or resolution & (resolution - 1):
            raise FormatError(f"resolution {resolution} is not a power of two in [256, 2^31]")
        if levels != resolution.bit_length() - 1 - 7:
            raise FormatError(f"levels {levels} != log2({resolution}) - 7")
        if mode not in (0, 1):
            raise FormatError(f"unknown mode {mode}")
        # version 2: the word at 120 is the channel directory's CRC (section 14.1)
        if flags != 0 or (version == 1 and reserved != 0):
            raise FormatError("reserved header fields are not zero")
        origin = (ox, oy, oz)
        if not all(np.isfinite(origin)):
            raise FormatError("origin is not finite")
        if not (np.isfinite(voxel_size) and voxel_size > 0):
            raise FormatError(f"voxel_size {voxel_size} is not finite and > 0")
        if index_offset < HEADER_SIZE or index_offset % 8:
            raise FormatError(f"index_offset {index_offset} is < 128 or not a multiple of 8")
        if index_size != node_count * ENTRY_SIZE:
            raise FormatError(f"index_size {index_size} != node_count {node_count} * 64")
        index_end = index_offset + index_size
        if version == 1 and manifest_offset != index_end:
            raise FormatError("manifest does not directly follow the index")
        if version == 2 and not index_end + 8 <= manifest_offset <= self.size:
            raise FormatError("no room for the channel directory between index and manifest")
        if manifest_offset + manifest_size != self.size:
            raise FormatError(
                f"file is {self.size} bytes but the manifest ends at "
                f"{manifest_offset + manifest_size} (truncated or extended)"
            )
        return {
            "version": version,
            "resolution": resolution,
            "levels": levels,
            "mode": mode,
            "mode_name": ("conservative", "thin")[mode],
            "origin": origin,
            "voxel_size": voxel_size,
            "node_count": node_count,
            "index_offset": index_offset,
            "index_size": index_size,
            "manifest_offset": manifest_offset,
            "manifest_size": manifest_size,
            "total_voxels": total_voxels,
            "index_crc32": index_crc,
            "manifest_crc32": manifest_crc,
            "channels_crc32": reserved,
        }

    # -- section 4 -------------------------------------------------------------------------
    def _read_index(self):
        h = self.header
        raw = self._read(h["index_offset"], h["index_size"], "node index")
        if crc32(raw) != h["index_crc32"]:
            raise FormatError("index CRC mismatch")
        return np.frombuffer(raw, dtype=ENTRY_DTYPE, count=h["node_count"])

    # -- section 14 ------------------------------------------------------------------------
    def _read_channels(self):
        """The channel directory of a version 2 file: {id: array of (offset, size, crc, count)
        per node}, in directory order; {} for version 1."""
        h = self.header
        if h["version"] == 1:
            return {}
        start = h["index_offset"] + h["index_size"]
        raw = self._read(start, h["manifest_offset"] - start, "channel directory")
        if crc32(raw) != h["channels_crc32"]:
            raise FormatError("channel directory CRC mismatch")
        count, res = struct.unpack_from("<II", raw, 0)
        if not 1 <= count <= MAX_CHANNELS or res:
            raise FormatError(f"channel directory head invalid ({count} channels)")
        if len(raw) < 8 + 16 * count:
            raise FormatError("channel directory too short for its descriptors")
        nodes = h["node_count"]
        descs = [struct.unpack_from("<IIII", raw, 8 + 16 * k) for k in range(count)]
        want = 8 + 16 * count + sum(nodes * d[1] for d in descs)
        out = {}
        prev = None
        at = 8 + 16 * count
        for cid, entry_size, fl, rs in descs:
            if prev is not None and cid <= prev:
                raise FormatError("channel ids not strictly increasing")
            if entry_size < 24 or entry_size % 8 or fl or rs:
                raise FormatError(f"channel {cid}: bad descriptor")
            prev = cid
            if want != len(raw):
                raise FormatError("channel directory size does not match its tables")
            table = [struct.unpack_from("<QQII", raw, at + i * entry_size) for i in range(nodes)]
            at += nodes * entry_size
            out[cid] = table
        if want != len(raw):
            raise FormatError("channel directory size does not match its tables")
        return out

    def _read_manifest(self):
        h = self.header
        raw = self._read(h["manifest_offset"], h["manifest_size"], "manifest")
        if crc32(raw) != h["manifest_crc32"]:
            raise FormatError("manifest CRC mismatch")
        return check_manifest(raw)

    def _check_nodes(self):
        h = self.header
        chunks0 = h["resolution"] // 256
        expected_offset = HEADER_SIZE
        prev_key = None
        present = set()
        total = 0
        for i, e in enumerate(self.nodes):
            lvl, x, y, z = int(e["level"]), int(e["x"]), int(e["y"]), int(e["z"])
            name = f"node {i} (level {lvl}, {x},{y},{z})"
            if lvl >= h["levels"]:
                raise FormatError(f"{name}: level >= levels {h['levels']}")
            per_axis = chunks0 >> lvl
            if max(x, y, z) >= per_axis:
                raise FormatError(f"{name}: position outside the {per_axis}^3 chunk grid")
            n = int(e["voxel_count"])
            if not 1 <= n <= MAX_VOXELS:
                raise FormatError(f"{name}: voxel_count {n} outside [1, 256^3]")
            cm = int(e["child_mask"])
            if cm >> 8 or (lvl == 0 and cm):
                raise FormatError(f"{name}: bad child_mask {cm:#x}")
            off, sz = int(e["payload_offset"]), int(e["payload_size"])
            if off != expected_offset or sz < 1 or off + sz > h["index_offset"]:
                raise FormatError(f"{name}: payload [{off}, +{sz}) not contiguous/inside")
            expected_offset = off + sz
            # section 14.2: the node's channel payloads follow, in directory order
            for cid, table in self.channels.items():
                coff, csz, ccrc, ccount = table[i]
                if csz == 0:
                    if coff or ccrc or ccount:
                        raise FormatError(f"{name}: channel {cid}: empty entry with non-zero fields")
                    if cid == CHANNEL_MATERIAL:
                        raise FormatError(f"{name}: no material payload")
                    continue
                if coff != expected_offset or coff + csz > h["index_offset"]:
                    raise FormatError(f"{name}: channel {cid} payload not contiguous/inside")
                if cid == CHANNEL_MATERIAL and not 1 <= ccount <= min(n, MAX_MATERIAL_TABLE):
                    raise FormatError(f"{name}: material table of {ccount} entries")
                if cid == CHANNEL_TRIANGLES and (lvl or not 1 <= ccount <= MAX_SOURCE_TRIANGLES):
                    raise FormatError(f"{name}: source triangles ({ccount}) at level {lvl}")
                expected_offset = coff + csz
            bmin, bmax = e["bounds_min"], e["bounds_max"]
            if bmin[3] or bmax[3] or any(bmin[a] > bmax[a] for a in range(3)):
                raise FormatError(f"{name}: bad bounds")
            if e["reserved"].any():
                raise FormatError(f"{name}: reserved fields not zero")
            key = order_key(lvl, x, y, z)
            if prev_key is not None and key <= prev_key:
                raise FormatError(f"{name}: out of order")
            prev_key = key
            present.add((lvl, x, y, z))
            total += n
        if total != h["total_voxels"]:
            raise FormatError(f"sum of voxel counts {total} != total_voxels {h['total_voxels']}")
        pad_len = h["index_offset"] - expected_offset
        if pad_len >= 8 or any(self._read(expected_offset, pad_len, "padding")):
            raise FormatError("padding before the index is not 0-7 zero bytes")
        root_level = h["levels"] - 1
        for e in self.nodes:
            lvl, x, y, z = int(e["level"]), int(e["x"]), int(e["y"]), int(e["z"])
            mask = 0
            if lvl > 0:
                for c in range(8):
                    child = (lvl - 1, 2 * x + (c & 1), 2 * y + (c >> 1 & 1), 2 * z + (c >> 2))
                    if child in present:
                        mask |= 1 << c
            if mask != int(e["child_mask"]):
                raise FormatError(f"node (level {lvl}, {x},{y},{z}): child_mask mismatch")
            if lvl < root_level and (lvl + 1, x >> 1, y >> 1, z >> 1) not in present:
                raise FormatError(f"node (level {lvl}, {x},{y},{z}): parent missing")

    # -- lookup ----------------------------------------------------------------------------
    def find(self, level, x, y, z):
        """Index of node (level, x, y, z), or None. A linear search is enough here."""
        hits = np.nonzero(
            (self.nodes["level"] == level)
            & (self.nodes["x"] == x)
            & (self.nodes["y"] == y)
            & (self.nodes["z"] == z)
        )[0]
        return int(hits[0]) if len(hits) else None

    # -- section 5 -------------------------------------------------------------------------
    def decode(self, entry):
        """Decode one node's voxels. Returns a dict of numpy arrays (n = voxel_count):
        pos (n,3) u8 chunk positions, mask (n,) u8 face masks, normal (n,3) i16 quantized
        components in [-511, 511], color (n,4) u8 RGBA, and the plain 12-byte records
        `records` (n,3) u32 = (pos_mask, normal, color) as in section 6."""
        n = int(entry["voxel_count"])
        off, sz = int(entry["payload_offset"]), int(entry["payload_size"])
        name = f"node (level {int(entry['level'])}, {int(entry['x'])},{int(entry['y'])},{int(entry['z'])})"
        try:
            payload = self._read(off, sz, "payload")
            if crc32(payload) != int(entry["payload_crc32"]):
                raise FormatError("payload CRC mismatch")
            check_frame(payload, n)
            # check_frame bounded the output to 12·n bytes (the frame's content size)
            block = self._decompress(payload)
        except FormatError as e:
            raise FormatError(f"{self.path}: {name}: {e}") from None
        name = f"{self.path}: {name}"
        if len(block) != 12 * n:
            raise FormatError(f"{name}: block is {len(block)} bytes, expected {12 * n}")
        if crc32(block) != int(entry["block_crc32"]):
            raise FormatError(f"{name}: block CRC mismatch")

        planes = np.frombuffer(block, dtype=np.uint8).reshape(3, 4, n)
        # Undo the plane delta (normals and colours only): prefix sums modulo 256.
        nc = np.cumsum(planes[1:].astype(np.uint64), axis=2) % 256
        words = np.empty((3, n), dtype=np.uint32)
        for a in range(3):
            src = planes[a].astype(np.uint32) if a == 0 else nc[a - 1].astype(np.uint32)
            words[a] = src[0] | (src[1] << 8) | (src[2] << 16) | (src[3] << 24)
        p = words[0]
        if (p >> 30).any():
            raise FormatError(f"{name}: position word bits 30-31 set")
        if (words[1] >> 30).any():
            raise FormatError(f"{name}: normal word bits 30-31 set")
        # section 6: components are in [-511, 511]; the field value 0x200 (-512) is invalid
        if any(((words[1] >> s) & 0x3FF == 0x200).any() for s in (0, 10, 20)):
            raise FormatError(f"{name}: a normal component is -512")
        delta = (p & 0xFFFFFF).astype(np.uint64)
        if n > 1 and (delta[1:] == 0).any():
            raise FormatError(f"{name}: zero Morton delta (voxels not strictly increasing)")
        m = np.cumsum(delta)
        if m[-1] >= 1 << 24:
            raise FormatError(f"{name}: running Morton code reaches 2^24")
        m = m.astype(np.uint32)
        pos = np.stack([_compact8(m), _compact8(m >> 1), _compact8(m >> 2)], axis=1).astype(np.uint8)
        mask = ((p >> 24) & 0x3F).astype(np.uint8)
        if not (np.array_equal(pos.min(axis=0), entry["bounds_min"][:3])
                and np.array_equal(pos.max(axis=0), entry["bounds_max"][:3])):
            raise FormatError(f"{name}: decoded bounds differ from the index entry")
        nw = words[1]
        normal = np.stack(
            [_sign_extend10(nw & 0x3FF), _sign_extend10((nw >> 10) & 0x3FF),
             _sign_extend10((nw >> 20) & 0x3FF)], axis=1).astype(np.int16)
        color = np.stack([(words[2] >> (8 * c)) & 0xFF for c in range(4)], axis=1).astype(np.uint8)
        pos_mask = (pos[:, 0].astype(np.uint32) | (pos[:, 1].astype(np.uint32) << 8)
                    | (pos[:, 2].astype(np.uint32) << 16) | (mask.astype(np.uint32) << 24))
        records = np.stack([pos_mask, nw, words[2]], axis=1)
        return {"pos": pos, "mask": mask, "normal": normal, "color": color, "records": records}

    def _decompress(self, payload):
        """One zstd frame, checked by check_frame before: the whole payload, nothing after it."""
        try:
            dobj = self._dctx.decompressobj()
            block = dobj.decompress(payload)
            if not dobj.eof or dobj.unused_data:
                raise FormatError("the zstd frame is cut short or followed by more bytes")
        except zstandard.ZstdError as e:
            raise FormatError(f"zstd: {e}") from None
        return block

    def materials(self, entry):
        """Section 14.3: the per-voxel material ids of a node (n,) u32 in voxel order, or
        None if the file has no material channel."""
        if CHANNEL_MATERIAL not in self.channels:
            return None
        i = self.find(int(entry["level"]), int(entry["x"]), int(entry["y"]), int(entry["z"]))
        off, sz, crc, t = self.channels[CHANNEL_MATERIAL][i]
        n = int(entry["voxel_count"])
        name = f"{self.path}: node (level {int(entry['level'])}, {int(entry['x'])},{int(entry['y'])},{int(entry['z'])}): material payload"
        try:
            payload = self._read(off, sz, "material payload")
            if crc32(payload) != crc:
                raise FormatError("payload CRC mismatch")
            want = 4 * t + 2 * n
            check_frame(payload, n, want, f"4·{t} + 2·{n}")
            block = self._decompress(payload)
            if len(block) != want:
                raise FormatError(f"block is {len(block)} bytes, expected {want}")
        except FormatError as e:
            raise FormatError(f"{name}: {e}") from None
        table = np.frombuffer(block, dtype="<u4", count=t)
        if t > 1 and (np.diff(table.astype(np.int64)) <= 0).any():
            raise FormatError(f"{name}: table not strictly increasing")
        planes = np.frombuffer(block, dtype=np.uint8, offset=4 * t).reshape(2, n)
        idx = planes[0].astype(np.uint32) | (planes[1].astype(np.uint32) << 8)
        if (idx >= t).any():
            raise FormatError(f"{name}: an index is past the table")
        if len(np.unique(idx)) != t:
            raise FormatError(f"{name}: a table entry is used by no voxel")
        return table[idx].astype(np.uint32)

    def source(self, entry):
        """Section 14.4: a leaf's source triangles as a dict of numpy arrays ("codes" (V,3)
        u16, "positions" (V,3) f64 voxels in the chunk's frame, "normal_codes" (V,2) u16 and
        "normals" (V,3) f64 or None, "colors" (V,4) u8 or None, "triangles" (T,3) u32,
        "materials" (T,) u16 or None), or None if the node has no payload in the channel."""
        if CHANNEL_TRIANGLES not in self.channels:
            return None
        i = self.find(int(entry["level"]), int(entry["x"]), int(entry["y"]), int(entry["z"]))
        off, sz, crc, t = self.channels[CHANNEL_TRIANGLES][i]
        if sz == 0:
            return None
        name = (f"{self.path}: node (level {int(entry['level'])}, {int(entry['x'])},"
                f"{int(entry['y'])},{int(entry['z'])}): source triangles")
        try:
            return self._source_block(self._read(off, sz, "source payload"), crc, t)
        except FormatError as e:
            raise FormatError(f"{name}: {e}") from None

    def _source_block(self, payload, crc, t):
        if crc32(payload) != crc:
            raise FormatError("payload CRC mismatch")
        if not 1 <= t <= MAX_SOURCE_TRIANGLES:
            raise FormatError(f"entry count {t} outside [1, 2^26]")
        bound = 16 + 3 * t * 14 + 14 * t
        try:
            size = zstandard.get_frame_parameters(payload).content_size
        except zstandard.ZstdError:
            size = None
        if size is not None and size <= bound:
            check_frame(payload, 0, size, f"at most {bound}")
        else:
            check_frame(payload, 0, bound, f"at most {bound}")
        block = self._decompress(payload)
        if len(block) < 16:
            raise FormatError("block shorter than its 16-byte head")
        v, bt, attrs, res = struct.unpack_from("<IIII", block, 0)
        if bt != t or attrs & ~7 or res:
            raise FormatError(f"head says {bt} triangles, attributes {attrs:#x}, reserved {res:#x}")
        if not 1 <= v <= 3 * t:
            raise FormatError(f"{v} vertices for {t} triangles")
        normals, colors, mats = attrs & 1, attrs & 2, attrs & 4
        want = 16 + v * (6 + 4 * bool(normals) + 4 * bool(colors)) + t * (12 + 2 * bool(mats))
        if len(block) != want:
            raise FormatError(f"block is {len(block)} bytes, expected {want}")
        at = [16]

        def planes(count, width):
            raw = np.frombuffer(block, dtype=np.uint8, count=count * width, offset=at[0])
            at[0] += count * width
            raw = raw.reshape(width, count).astype(np.uint32)
            return sum(raw[b] << np.uint32(8 * b) for b in range(width)).astype(np.uint32)

        out = {}
        codes = np.stack([planes(v, 2) for _ in range(3)], axis=1).astype(np.uint16)
        out["codes"] = codes
        out["positions"] = codes.astype(np.float64) / 128.0 - 128.0
        out["normal_codes"] = out["normals"] = out["colors"] = out["materials"] = None
        if normals:
            nc = np.stack([planes(v, 2), planes(v, 2)], axis=1).astype(np.uint16)
            out["normal_codes"] = nc
            out["normals"] = oct_decode(nc)
        if colors:
            out["colors"] = np.stack([planes(v, 1) for _ in range(4)], axis=1).astype(np.uint8)
        idx_codes = planes(3 * t, 4)
        if mats:
            out["materials"] = planes(t, 2).astype(np.uint16)
        tris = np.empty(3 * t, dtype=np.uint32)
        nxt = 0
        for k, c in enumerate(idx_codes.tolist()):
            if c > nxt:
                raise FormatError(f"index code {c} at {k} reaches before the first vertex")
            tris[k] = nxt - c
            nxt += c == 0
        if nxt != v:
            raise FormatError(f"{v} vertices but the triangles use {nxt}")
        out["triangles"] = tris.reshape(t, 3)
        return out

    def world_min_corner(self, entry, pos):
        """Section 7: world coordinates of the voxels' minimum corners (n,3) f64."""
        lvl = int(entry["level"])
        edge = self.header["voxel_size"] * (1 << lvl)
        p = np.array([int(entry["x"]), int(entry["y"]), int(entry["z"])], dtype=np.float64)
        return np.asarray(self.header["origin"]) + edge * (256.0 * p + pos.astype(np.float64))


def oct_decode(codes):
    """Section 14.4: unit normals (n,3) f64 of octahedral codes (n,2) u16."""
    u = codes[:, 0].astype(np.float64) / 65535.0 * 2.0 - 1.0
    v = codes[:, 1].astype(np.float64) / 65535.0 * 2.0 - 1.0
    w = 1.0 - np.abs(u) - np.abs(v)
    su, sv = np.where(u < 0, -1.0, 1.0), np.where(v < 0, -1.0, 1.0)
    fold = w < 0
    u2 = np.where(fold, (1.0 - np.abs(v)) * su, u)
    v2 = np.where(fold, (1.0 - np.abs(u)) * sv, v)
    n = np.stack([u2, v2, w], axis=1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def node_dict(e):
    return {
        "level": int(e["level"]),
        "x": int(e["x"]),
        "y": int(e["y"]),
        "z": int(e["z"]),
        "voxel_count": int(e["voxel_count"]),
        "child_mask": int(e["child_mask"]),
        "payload_offset": int(e["payload_offset"]),
        "payload_size": int(e["payload_size"]),
        "bounds_min": [int(v) for v in e["bounds_min"][:3]],
        "bounds_max": [int(v) for v in e["bounds_max"][:3]],
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("file")
    ap.add_argument("--json", action="store_true", help="print JSON")
    ap.add_argument("--node", nargs=4, type=int, metavar=("L", "X", "Y", "Z"))
    ap.add_argument("--raw", metavar="OUT", help="with --node: write the 12-byte records here")
    ap.add_argument("--materials", metavar="OUT",
                    help="with --node: write the per-voxel material ids (u32 LE) here")
    ap.add_argument("--source", metavar="OUT",
                    help="with --node 0 X Y Z: write the leaf's source triangles as JSON here")
    ap.add_argument("--check", action="store_true", help="decode every node")
    args = ap.parse_args(argv)
    try:
        f = VoxlodFile(args.file)
        if args.node:
            i = f.find(*args.node)
            if i is None:
                print(f"no node {tuple(args.node)}", file=sys.stderr)
                return 1
            v = f.decode(f.nodes[i])
            if args.raw:
                with open(args.raw, "wb") as out:
                    out.write(v["records"].astype("<u4").tobytes())
            if args.materials:
                mats = f.materials(f.nodes[i])
                if mats is None:
                    print("the file has no material channel", file=sys.stderr)
                    return 1
                with open(args.materials, "wb") as out:
                    out.write(mats.astype("<u4").tobytes())
            if args.source:
                src = f.source(f.nodes[i])
                if src is None:
                    print("the node has no source triangles", file=sys.stderr)
                    return 1
                doc = {k: (None if a is None else a.tolist()) for k, a in src.items()
                       if k not in ("positions", "normals")}
                with open(args.source, "w") as out:
                    json.dump(doc, out)
            if args.json:
                print(json.dumps({
                    "node": node_dict(f.nodes[i]),
                    "pos": v["pos"].tolist(),
                    "mask": v["mask"].tolist(),
                    "normal": v["normal"].tolist(),
                    "color": v["color"].tolist(),
                }))
            elif not args.raw and not args.materials and not args.source:
                print(f"node {tuple(args.node)}: {len(v['pos'])} voxels")
                for j in range(min(10, len(v["pos"]))):
                    print(f"  pos {tuple(v['pos'][j].tolist())} mask {int(v['mask'][j]):#04x} "
                          f"normal {tuple(v['normal'][j].tolist())} "
                          f"rgba {tuple(v['color'][j].tolist())}")
            return 0
        if args.check:
            for e in f.nodes:
                f.decode(e)
                f.materials(e)
                f.source(e)
        h = f.header
        if args.json:
            out = {k: h[k] for k in ("version", "resolution", "levels", "mode", "mode_name",
                                     "origin", "voxel_size", "node_count", "total_voxels")}
            out["channels"] = list(f.channels)
            out["nodes"] = [node_dict(e) for e in f.nodes]
            out["manifest"] = f.manifest
            print(json.dumps(out))
        else:
            print(f"resolution {h['resolution']}, {h['levels']} levels, mode {h['mode_name']}, "
                  f"origin {h['origin']}, voxel_size {h['voxel_size']}")
            print(f"{h['node_count']} nodes, {h['total_voxels']} voxels"
                  + (" (all decoded)" if args.check else ""))
            for e in f.nodes:
                d = node_dict(e)
                print(f"  level {d['level']} ({d['x']},{d['y']},{d['z']}) "
                      f"{d['voxel_count']} voxels, {d['payload_size']} bytes, "
                      f"children {d['child_mask']:08b}")
            if args.check:
                print(f"{args.file}: ok ({h['node_count']} nodes, {h['levels']} levels, "
                      f"{h['total_voxels']} voxels decoded)")
        return 0
    except FormatError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
