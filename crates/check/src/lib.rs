//! Checking voxlod octree files, for regression tests and for anyone who receives one.
//!
//! - [`verify`] checks everything a file promises: the container (checksums, layout, index
//!   order, child masks — what [`Reader::open`](voxlod_format::Reader::open) validates), every
//!   node's payload (checksums, size, Morton order, bounds), that each parent's voxels equal
//!   the OR-merge of its children recomputed by `voxlod_lod` (Chajdas et al. 2014, section 4:
//!   sort-and-compact), that children lie inside their parents, and the level-0 face masks
//!   (`face_mask(normal) | border_caps(pos)`). It collects every failure, naming the node.
//! - [`diff`] compares two files chunk by chunk: nodes identical, added, removed or changed,
//!   and for changed ones the voxel-set difference (added, removed, IoU) and the largest
//!   normal angle and colour difference on common voxels, judged against a [`Tolerance`].
//!
//! ```
//! use voxlod_format::voxel::{border_caps, face_mask, pack_color, pack_normal, Voxel};
//! use voxlod_format::{encode_node, FileSpec, Writer, MODE_THIN};
//!
//! let dir = tempfile::tempdir().unwrap();
//! let write = |name: &str, red: u8| {
//!     let path = dir.path().join(name);
//!     let n = pack_normal([0.0, 1.0, 0.0]);
//!     let p = [5, 6, 7];
//!     let v = Voxel::new(p, face_mask(n) | border_caps(p), n, pack_color([red, 0, 0, 255]));
//!     let mut w = Writer::create(&path, FileSpec::new(256, MODE_THIN, [0.0; 3], 1.0)).unwrap();
//!     w.write_node(0, [0, 0, 0], 0, &encode_node(&[v], 3).unwrap()).unwrap();
//!     w.finish(&serde_json::json!({})).unwrap();
//!     path
//! };
//! let (a, b) = (write("a.voxlod", 200), write("b.voxlod", 190));
//!
//! let report = voxlod_check::verify(&a);
//! assert!(report.ok(), "{:?}", report.problems);
//!
//! let d = voxlod_check::diff(&a, &b, &voxlod_check::Tolerance::default()).unwrap();
//! assert_eq!(d.changed.len(), 1);
//! assert_eq!(d.changed[0].max_color_diff, 10);
//! assert!(!d.within_tolerance());
//! let loose = voxlod_check::Tolerance { max_color: 10, ..Default::default() };
//! assert!(voxlod_check::diff(&a, &b, &loose).unwrap().within_tolerance());
//! ```

mod diff;
mod source;
mod verify;

pub use diff::{diff, ChangedNode, DiffError, DiffReport, FieldDiff, NodeId, Tolerance};
pub use verify::{verify, Problem, VerifyReport};
