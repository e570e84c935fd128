//! Sharded builds (`voxlod plan`, `build --plan --shard`, `merge`): the plan file and its
//! split, the shard file, the merge, and the input's content checksum a shard checks.

pub(crate) mod content_hash;
pub(crate) mod merge;
pub(crate) mod plan_file;
pub(crate) mod shard_file;
pub(crate) mod split;
