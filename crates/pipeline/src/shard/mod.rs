//! Sharded builds (`voxlod plan`, `map`, `build --plan --shard`, `merge`): the plan file and its
//! split, the map tasks' outputs, the shard file, the merge, and the input's content checksum a shard checks.

pub(crate) mod content_hash;
pub(crate) mod map_part;
pub(crate) mod merge;
pub(crate) mod plan_file;
pub(crate) mod shard_file;
pub(crate) mod split;
