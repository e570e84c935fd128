"""Read voxlod level-of-detail voxel octree files into numpy arrays.

A ``.voxlod`` file (written by ``voxlod build``, specified in docs/FORMAT.md) holds an octree
of chunks of 256³ voxels over a grid of ``R = 256·2^k`` leaf voxels per axis: level 0 holds the
full-resolution leaves, level ``levels - 1`` the single root chunk. This package is the Rust
reader of the ``voxlod-format`` crate compiled for Python: every checksum and structural check
of ``voxlod inspect`` and ``voxlod verify`` applies, and a file that fails one raises
:class:`VoxlodError` with the same message the command line prints.

    >>> import voxlod
    >>> r = voxlod.Reader("bunny.voxlod")
    >>> r.levels, r.resolution, r.voxel_size
    >>> nodes = r.nodes()                    # numpy structured array, one row per node
    >>> root = nodes[-1]                     # index order is a post-order: the root is last
    >>> v = r.decode(root["level"], root["x"], root["y"], root["z"])
    >>> v["pos"], v["face_mask"], v["normal"], v["color"]      # (N,3) (N,) (N,3) (N,4)
    >>> lv = r.level(0)                      # a whole level as one set of arrays
    >>> lv["pos"], lv["node"]                # (N,3) absolute positions, (N,) rows of nodes()
    >>> world = r.world(root["level"], v["pos"])               # minimum corners, (N,3) f64
    >>> r.verify()["ok"]

Coordinates: ``pos`` is in voxels of the node's level, counted from the grid origin (a level-l
voxel is ``2^l`` leaf voxels wide); :meth:`Reader.world` turns them into world units.
"""

import json
import os

import numpy as np

from ._voxlod import CHUNK, VoxlodError, __version__
from ._voxlod import Reader as _Reader

__all__ = [
    "Reader",
    "VoxlodError",
    "VoxlodFileNotFoundError",
    "CHUNK",
    "NODE_DTYPE",
    "FACE_BITS",
    "__version__",
]


class VoxlodFileNotFoundError(VoxlodError, FileNotFoundError):
    """The file to open does not exist: both a :class:`VoxlodError` and the built-in
    ``FileNotFoundError`` (an ``OSError`` with ``errno.ENOENT``), so either ``except`` catches
    it. Its message names the file, as every :class:`VoxlodError` does."""

#: One row of :meth:`Reader.nodes`.
NODE_DTYPE = np.dtype(
    [
        ("level", "<u4"),
        ("x", "<u4"),
        ("y", "<u4"),
        ("z", "<u4"),
        ("voxels", "<u4"),
        ("child_mask", "u1"),
        ("payload_offset", "<u8"),
        ("payload_size", "<u8"),
        ("bounds_min", "u1", (3,)),
        ("bounds_max", "u1", (3,)),
        ("source_triangles", "<u4"),
    ]
)

#: The face-mask bits (docs/FORMAT.md section 6): bit ``i`` set means the face on that side
#: of the voxel faces outward.
FACE_BITS = {"+x": 1, "-x": 2, "+y": 4, "-y": 8, "+z": 16, "-z": 32}


class Reader:
    """A voxlod file, opened and validated.

    ``Reader(path)`` reads and checks the header, the node index, the channel directory and the
    manifest (the file is read with positioned reads, never memory-mapped, and holds no more
    than the index in memory); node payloads are read and checked when decoded. Raises
    :class:`VoxlodError` naming the file and the problem if it is not a valid voxlod file, and
    other ``OSError``-like failures (a directory, no permission) as :class:`VoxlodError` too; a
    file that does not exist raises :class:`VoxlodFileNotFoundError`, which is both a
    :class:`VoxlodError` and a ``FileNotFoundError``.

    Attributes: ``path``, ``resolution`` (leaf voxels per axis), ``levels`` (number of levels),
    ``mode`` (``"conservative"`` or ``"thin"``), ``origin`` (world position of the grid's
    minimum corner), ``voxel_size`` (leaf voxel edge in world units), ``format_version``,
    ``total_voxels``, ``file_size``, ``channels`` (optional channel ids), ``has_materials``,
    ``has_source_triangles``, ``manifest`` (the parsed JSON manifest) and ``materials`` (the
    material names, indexed by material id, or ``None``).
    """

    def __init__(self, path):
        try:
            self._r = _Reader(path)
        except FileNotFoundError as e:
            raise VoxlodFileNotFoundError(2, str(e), os.fspath(path)) from None
        self.manifest = json.loads(self._r.manifest_json)
        names = self.manifest.get("materials") if isinstance(self.manifest, dict) else None
        self.materials = list(names) if self._r.has_materials and names is not None else None

    path = property(lambda self: self._r.path, doc="The file's path.")
    resolution = property(lambda self: self._r.resolution, doc="Leaf voxels per axis, R.")
    levels = property(lambda self: self._r.levels, doc="Number of levels (root is levels - 1).")
    mode = property(lambda self: self._r.mode, doc='"conservative" or "thin" voxelization.')
    origin = property(lambda self: self._r.origin, doc="World position of the grid's minimum corner.")
    voxel_size = property(lambda self: self._r.voxel_size, doc="Leaf voxel edge, world units.")
    format_version = property(lambda self: self._r.format_version, doc="Format version (1 or 2).")
    total_voxels = property(lambda self: self._r.total_voxels, doc="Voxels over all nodes.")
    file_size = property(lambda self: self._r.file_size, doc="File size in bytes at open.")
    channels = property(lambda self: self._r.channels, doc="Optional channel ids (FORMAT.md 14).")
    has_materials = property(lambda self: self._r.has_materials, doc="Per-voxel materials stored.")
    has_source_triangles = property(
        lambda self: self._r.has_source_triangles, doc="Leaf source triangles stored."
    )

    def __repr__(self):
        return repr(self._r)

    def nodes(self):
        """The node index as a numpy structured array of :data:`NODE_DTYPE`, in index order
        (a post-order: children before their parent, the root last).

        Fields: ``level``; ``x, y, z`` (the node's position in chunks at its level); ``voxels``
        (voxel count); ``child_mask`` (bit ``dx | dy<<1 | dz<<2`` set for each stored child);
        ``payload_offset``, ``payload_size`` (the compressed payload's bytes in the file);
        ``bounds_min``, ``bounds_max`` (the voxels' bounding box inside the chunk, inclusive);
        ``source_triangles`` (triangles stored beside a leaf, 0 without that channel)."""
        cols = self._r.node_columns()
        out = np.empty(len(cols["level"]), dtype=NODE_DTYPE)
        for name in NODE_DTYPE.names:
            out[name] = cols[name]
        return out

    def decode(self, level, x, y, z):
        """The voxels of node ``(level, x, y, z)``, every checksum checked, as a dict of numpy
        arrays of N rows (N = the node's voxel count), in the file's order (Morton order
        inside the chunk):

        - ``pos`` (N, 3) uint32: voxel coordinates in the grid of that level, i.e.
          ``256·(x, y, z)`` plus the position inside the chunk; :meth:`world` gives world units;
        - ``face_mask`` (N,) uint8: the outward faces, bits as :data:`FACE_BITS`;
        - ``normal`` (N, 3) float32: the averaged surface normal (10 bits per component,
          components in [-1, 1], not renormalized);
        - ``color`` (N, 4) uint8: RGBA;
        - ``material`` (N,) uint32: material ids indexing :attr:`materials`, only when the
          file has the material channel.

        Raises ``ValueError`` for a level the file does not have (a negative one included),
        ``KeyError`` if the file has no such node and :class:`VoxlodError` if the node's data is
        corrupt."""
        return self._r.decode(self._level(level), int(x), int(y), int(z))

    def level(self, level):
        """Every voxel of level ``level`` (0: the leaves, ``levels - 1``: the root) as one set
        of numpy arrays of N rows (N = the voxels of all the level's nodes), every checksum
        checked; the nodes in index order, each node's voxels in the file's order:

        - ``pos`` (N, 3) uint32: voxel coordinates in the grid of that level, absolute (counted
          from the grid origin, as :meth:`decode` gives them; :meth:`world` gives world units);
        - ``face_mask`` (N,) uint8, ``normal`` (N, 3) float32, ``color`` (N, 4) uint8: as in
          :meth:`decode`;
        - ``material`` (N,) uint32: only when the file has the material channel;
        - ``node`` (N,) uint32: the row of :meth:`nodes` each voxel came from.

        Raises ``ValueError`` naming the file for a level it does not have (a negative one
        included) and :class:`VoxlodError` if a node's data is corrupt. The arrays take about
        29 bytes per voxel (33 with materials)."""
        return self._r.level(self._level(level))

    def _level(self, level):
        """``level`` as an int, checked to be one of the file's levels."""
        k = int(level)
        if not 0 <= k < self.levels:
            raise ValueError(
                f"{self.path}: there is no level {k}: the file's levels are 0 (the leaves) "
                f"to {self.levels - 1} (the root)"
            )
        return k

    def source_triangles(self, level, x, y, z):
        """The input triangles stored beside leaf ``(0, x, y, z)`` when the file was built with
        source geometry (FORMAT.md 14.4), or ``None`` (no such channel, or none in this node).

        A dict: ``positions`` (V, 3) float64 in leaf voxels from the grid origin (the same
        units as level 0's ``pos``; each within 1/256 voxel of the input vertex), ``triangles``
        (T, 3) uint32 vertex indices, and ``normals`` (V, 3) float32, ``colors`` (V, 4) uint8,
        ``materials`` (T,) uint16, each ``None`` when the mesh had none. ``ValueError`` for a
        level the file does not have, ``KeyError`` for a node it does not have."""
        return self._r.source_triangles(self._level(level), int(x), int(y), int(z))

    def verify(self):
        """Runs every check of ``voxlod verify`` (every checksum, every tree invariant, each
        parent recomputed from its children by the LOD rule, materials and source triangles
        where stored) and returns the report as a dict: ``ok`` (bool), ``problems`` (list of
        messages, each naming the node), and the counts ``nodes``, ``nodes_decoded``,
        ``voxels``, ``parents_checked``, ``leaf_voxels_checked``, ``materials_checked``,
        ``source_triangles_checked``. Reads the whole file."""
        return self._r.verify()

    def world(self, level, pos):
        """World coordinates (float64) of the minimum corners of voxels at ``pos`` (any shape
        ending in 3, in grid units of ``level`` as :meth:`decode` gives them): ``origin +
        voxel_size·2^level·pos``."""
        edge = self.voxel_size * float(1 << int(level))
        return np.asarray(self.origin, dtype=np.float64) + edge * np.asarray(pos, dtype=np.float64)
