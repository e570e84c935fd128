//! The one error type of the crate. Every message names the file (where there is one) and,
//! for node errors, which node: its index in the node index, level and position.

use std::io;
use std::path::PathBuf;

/// Everything that can go wrong writing or reading a voxlod file.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// An operating-system call on the file failed.
    #[error("{}: {op}: {source}", path.display())]
    Io {
        /// The file (or, for a rename, its destination).
        path: PathBuf,
        /// What was being done, e.g. "creating the temporary file".
        op: &'static str,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
    /// The 128-byte header is missing, not a voxlod header, of another version or corrupt.
    #[error("{}: bad header: {what}", path.display())]
    Header {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The node index (as a whole: its range, checksum or order) is corrupt.
    #[error("{}: bad node index: {what}", path.display())]
    Index {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// One node's index entry or payload is corrupt.
    #[error("{}: node {index} (level {level}, position {pos:?}): {what}", path.display())]
    Node {
        /// The file.
        path: PathBuf,
        /// The node's index in the node index.
        index: usize,
        /// The node's level (0 = leaves).
        level: u32,
        /// The node's position at its level.
        pos: [u32; 3],
        /// What is wrong.
        what: String,
    },
    /// A node index past the end of the index was asked for.
    #[error("{}: no node {index}: the file has {count} nodes", path.display())]
    NoSuchNode {
        /// The file.
        path: PathBuf,
        /// The index asked for.
        index: usize,
        /// Nodes in the file.
        count: usize,
    },
    /// The manifest is corrupt or not JSON.
    #[error("{}: bad manifest: {what}", path.display())]
    Manifest {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The voxels given to [`encode_node`](crate::encode_node) break a rule of the format.
    #[error("invalid node voxels: {what}")]
    Voxels {
        /// What is wrong.
        what: String,
    },
    /// The [`FileSpec`](crate::FileSpec) given to [`Writer::create`](crate::Writer::create) is invalid.
    #[error("{}: invalid file spec: {what}", path.display())]
    Spec {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// [`Writer::write_node`](crate::Writer::write_node) or
    /// [`Writer::finish`](crate::Writer::finish) was called with a node that does not fit the
    /// octree written so far. Nothing was written; the writer is still usable.
    #[error("{}: cannot write node (level {level}, position {pos:?}): {what}", path.display())]
    Tree {
        /// The file.
        path: PathBuf,
        /// The node's level (0 = leaves).
        level: u32,
        /// The node's position at its level.
        pos: [u32; 3],
        /// What is wrong.
        what: String,
    },
    /// An earlier I/O error left the temporary file in an unknown state.
    #[error("{}: the writer failed earlier and cannot continue", path.display())]
    Poisoned {
        /// The file.
        path: PathBuf,
    },
}
