//! The voxlod build, end to end: ingest → tile → voxelize → LOD → write.
//!
//! Each stage's algorithms are a crate of their own and meet the next only through plain types
//! (`voxlod_geom::Triangle`, on-disk bins, `voxlod_format::Voxel`); this crate runs them in
//! order over explicit on-disk intermediates in a work folder, with a memory plan, progress
//! bars and a summary.
//!
//! Where things are (every import points down this list):
//! - [`entry`](crate::build): the entry points `build`, `build_shard`, `plan`
//!   (`shard/merge.rs` has `merge`), each opening a `runner::Runner` (the one setup: output
//!   guard, work folder, thread pool, memory plan, progress, interrupt) and running the stages
//!   with a `context::BuildContext` whose `Scope` says what the run builds (whole, one shard, a
//!   plan); `failure.rs` decides what becomes of a failed run's work folder.
//! - `stages/`: one folder or file per stage (`ingest`, `tile`, `source`, `voxelize`,
//!   `lod_write`) with its helpers; `resume.rs` reads once what an interrupted run finished.
//! - `shard/`: the plan file and its split, the shard file, the merge, the content checksum.
//! - `files/`: the output guard, the work folder and its markers.
//! - `settings.rs`, `summary.rs`, `memory.rs`, `progress.rs`, `system.rs`, `size.rs`,
//!   `error.rs`, `chain_text.rs`: the pieces everything above uses.
//!
//! ```no_run
//! use voxlod_pipeline::{build, BuildSettings};
//! let settings = BuildSettings { resolution: 1024, ..Default::default() };
//! let summary = build("bunny.ply".as_ref(), "bunny.voxlod".as_ref(), &settings).unwrap();
//! println!("{} voxels at level 0", summary.levels[0].voxels);
//! ```

mod chain_text;
mod context;
mod entry;
mod error;
mod failure;
mod files;
mod memory;
pub mod progress;
mod resume;
mod runner;
mod settings;
mod shard;
mod size;
mod stages;
mod summary;
mod system;

pub use chain_text::chain_text;
pub use entry::{build, build_shard, plan};
pub use error::StageError;
pub use files::output::{
    find_output_leftovers, remove_output_leftovers, OutputGuard, OutputKind, OutputLeftovers,
};
pub use files::work::{find_work_folders, remove_stale_work_folder, WorkFolder, WORK_PREFIX};
pub use memory::MemoryPlan;
pub use settings::{Backend, BuildSettings, Cutoff, GpuMethod, SettingError};
pub use shard::map_part::{map_part, MapMarker, MapSummary, MAP_FORMAT, MAP_VERSION};
pub use shard::merge::{merge, MergeSummary};
pub use shard::plan_file::{
    Balance, Fingerprint, LoadedPlan, PlanGrid, PlanIngest, PlanInput, PlanPart, PlanSummary,
    ShardPlan, ShardRange, ShardScope, PLAN_FORMAT, PLAN_VERSION,
};
pub use size::{format_size, parse_size};
pub use stages::lod_write::octree_writer::{LevelStats, NodeSink, OctreeWriter, StoredPayloads};
pub use stages::voxelize::textures::TextureCacheSummary;
pub use summary::{BuildSummary, SourceSummary, StageTime};
pub use system::{free_disk, interrupt_after_chunks, interrupted, peak_rss, request_interrupt};
