//! The voxlod on-disk octree format. Renderers depend on this crate alone.
//!
//! A file holds one octree of chunks (256³ voxels each) over a grid of `R = 256·2^k` leaf
//! voxels per axis: level 0 holds the leaf chunks, level `k` the single root chunk, and each
//! level-`l+1` chunk is the sort-and-compact merge of its eight level-`l` children (the
//! Chajdas paper's LOD). Each node's voxels are the 12-byte [`Voxel`] records of that paper,
//! stored as one zstd frame after a reversible transform that makes them compress to a few
//! bytes per voxel. Layout: a 128-byte [`Header`], the payloads, the node index (64-byte
//! [`NodeEntry`]s in post-order) and a JSON manifest. `docs/FORMAT.md` specifies every byte.
//!
//! - [`encode_node`] compresses one node (pure; call it from many threads),
//! - [`Writer`] streams compressed nodes to `<path>.tmp` and renames it to `path` when done,
//! - [`Reader`] validates a file and decodes nodes with checksums checked, reading with
//!   positioned reads (no memory map: a file changed while open gives errors, not SIGBUS);
//!   for renderers it walks the tree ([`Reader::depth_first`], [`Reader::level_nodes`]), picks
//!   the nodes to draw for a [`Camera`] ([`Reader::select_by_error`]) and gives conservative
//!   world boxes for culling ([`Reader::node_bounds`]); [`Reader::read_node_into`] decodes into
//!   a caller's buffer, so a streaming loop allocates nothing per node.
//!
//! ```
//! use voxlod_format::voxel::{border_caps, face_mask, pack_color, pack_normal, Voxel};
//! use voxlod_format::{encode_node, FileSpec, Reader, Writer, MODE_CONSERVATIVE};
//!
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("tiny.voxlod");
//! // one 256³ chunk: a single level, the root is the only node
//! let spec = FileSpec::new(256, MODE_CONSERVATIVE, [0.0; 3], 0.01);
//! let voxel = |p: [u8; 3]| {
//!     let n = pack_normal([0.0, 0.0, 1.0]);
//!     Voxel::new(p, face_mask(n) | border_caps(p), n, pack_color([200, 10, 10, 255]))
//! };
//! // voxels sorted by Morton code of their position: (1,0,0) is 1, (0,1,0) is 2
//! let voxels = vec![voxel([1, 0, 0]), voxel([0, 1, 0])];
//!
//! let mut writer = Writer::create(&path, spec).unwrap();
//! writer.write_node(0, [0, 0, 0], 0, &encode_node(&voxels, 3).unwrap()).unwrap();
//! let size = writer.finish(&serde_json::json!({ "tool": "doctest" })).unwrap();
//!
//! let reader = Reader::open(&path).unwrap();
//! assert_eq!(reader.file_size(), size);
//! assert_eq!(reader.nodes().len(), 1);
//! let root = reader.root().unwrap();
//! assert_eq!(reader.read_node(root).unwrap(), voxels);
//! assert_eq!(reader.manifest().unwrap()["tool"], "doctest");
//! // world position of the second voxel's minimum corner: origin + 0.01 · (0, 1, 0)
//! assert_eq!(reader.spec().voxel_min_corner(0, [0, 0, 0], voxels[1].pos()), [0.0, 0.01, 0.0]);
//! ```

mod block;
pub mod channel;
mod error;
mod layout;
mod reader;
pub mod rules;
mod select;
mod spec;
pub mod triangles;
pub mod voxel;
mod writer;

pub use block::{encode_node, EncodedNode};
pub use channel::{encode_materials, EncodedChannel, CHANNEL_MATERIAL, CHANNEL_TRIANGLES};
pub use error::FormatError;
pub use layout::{
    child_pos, order_key, Header, NodeEntry, HEADER_SIZE, MAGIC, NODE_ENTRY_SIZE, VERSION,
    VERSION_CHANNELS,
};
pub use reader::Reader;
pub use select::{Aabb, Camera, DepthFirst};
pub use spec::{
    levels_for_resolution, FileSpec, CHUNK, MAX_NODE_VOXELS, MODE_CONSERVATIVE, MODE_THIN,
};
pub use triangles::{encode_source, SourceMesh};
pub use voxel::Voxel;
pub use writer::{temp_path, Writer};

/// The zstd level used unless the caller picks one. Measured on a synthetic sphere chunk
/// (`examples/measure_compression.rs`): level 9 is only 4–13% smaller than level 3 at 3–5×
/// the compression time, level 19 6–21% smaller at 20–50×. On real octrees level 1 is as small
/// as level 3 (Stanford dragon at 4096³, all 57M voxels re-encoded: 2.000 against 2.001 bytes
/// per voxel) at 60 % of its compression time, and negative levels are 30–50 % larger for
/// little more speed (docs/journal/benchmarks-notebook.md, "LOD + write"), so the
/// default is 1.
pub const DEFAULT_ZSTD_LEVEL: i32 = 1;
