//! What every stage of one run shares ([`BuildContext`]), and what the run builds
//! ([`Scope`]): the whole octree, one shard of a plan, or the plan itself. Stages ask the
//! scope instead of looking at the output's kind or the plan.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use serde::Serialize;
use voxlod_ingest::MeshSource;

use crate::error::StageError;
use crate::files::output::{OutputGuard, OutputKind};
use crate::files::work::WorkDir;
use crate::memory::MemoryPlan;
use crate::progress::Bar;
use crate::settings::BuildSettings;
use crate::shard::plan_file::ShardScope;

/// What a run builds.
#[derive(Clone, Debug)]
pub(crate) enum Scope {
    /// The whole octree (`build`).
    Whole,
    /// One shard of a plan (`build --plan --shard`): its subtrees only, into a shard file.
    Shard(Box<ShardScope>),
    /// A plan (`plan`): the ingest and count passes only; no bins, no voxels.
    Plan,
}

impl Scope {
    /// True if leaf chunk `c` is built by this run (a shard keeps its own subtrees' chunks).
    pub(crate) fn keeps(&self, c: [u32; 3]) -> bool {
        match self {
            Scope::Shard(s) => s.contains_chunk(c),
            Scope::Whole | Scope::Plan => true,
        }
    }

    /// True if the run builds only some of the leaf chunks (those it [`keeps`](Self::keeps)).
    pub(crate) fn drops_chunks(&self) -> bool {
        matches!(self, Scope::Shard(_))
    }

    /// True if the run writes chunk bins (a plan only counts).
    pub(crate) fn writes_bins(&self) -> bool {
        !matches!(self, Scope::Plan)
    }

    /// The shard, for a sharded build.
    pub(crate) fn shard(&self) -> Option<&ShardScope> {
        match self {
            Scope::Shard(s) => Some(s),
            Scope::Whole | Scope::Plan => None,
        }
    }

    /// The kind of file the run writes.
    pub(crate) fn output_kind(&self) -> OutputKind {
        match self {
            Scope::Whole => OutputKind::Octree,
            Scope::Shard(_) => OutputKind::Shard,
            Scope::Plan => OutputKind::Plan,
        }
    }
}

/// The stages of a build, by the names the summary, the JSON output and the docs use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Stage {
    /// Reading the input (and, when it cannot be read again cheaply, the spool).
    Ingest,
    /// Binning the triangles by leaf chunk.
    Tile,
    /// The source triangles of each leaf chunk (`--source-geometry`).
    Source,
    /// Decoding (and tiling) the textures before the voxelizers start.
    Textures,
    /// Voxelizing the leaf chunks.
    Voxelize,
    /// The levels above the leaves and the output file.
    LodWrite,
}

impl Stage {
    /// The stage's name in the summary and the JSON output.
    pub(crate) const fn name(self) -> &'static str {
        match self {
            Stage::Ingest => "ingest",
            Stage::Tile => "tile",
            Stage::Source => "source",
            Stage::Textures => "textures",
            Stage::Voxelize => "voxelize",
            Stage::LodWrite => "lod+write",
        }
    }
}

/// Wall-clock seconds and peak memory per stage.
#[derive(Clone, Debug, Serialize)]
pub struct StageTime {
    /// Stage name: `ingest`, `tile`, `voxelize` or `lod+write`.
    pub stage: &'static str,
    /// Wall time of the stage, seconds.
    pub seconds: f64,
    /// Peak resident memory of the process at the end of the stage (bytes; monotone).
    pub peak_rss: u64,
    /// True if the stage's result was taken from an interrupted earlier run.
    pub resumed: bool,
}

/// What every stage of one build shares.
pub(crate) struct BuildContext<'a> {
    /// The build's settings.
    pub settings: &'a BuildSettings,
    /// What the run builds.
    pub scope: &'a Scope,
    /// The input mesh, opened.
    pub source: &'a MeshSource,
    /// The input's path as given.
    pub input: &'a Path,
    /// The locked output (written to its staged name, renamed at the end).
    pub output: &'a OutputGuard,
    /// The worker threads.
    pub pool: &'a rayon::ThreadPool,
    /// The work folder with the intermediates and the markers.
    pub work: &'a WorkDir,
    /// How the memory budget is split.
    pub memory: MemoryPlan,
    /// Show progress on stderr.
    pub progress: bool,
    /// Time and peak memory of each stage, in the order they ran.
    pub times: Vec<StageTime>,
    /// Warnings for the summary.
    pub warnings: Vec<String>,
    /// Set by Ctrl-C; checked between batches.
    pub interrupt: &'static AtomicBool,
}

impl BuildContext<'_> {
    /// The error to stop with once an interrupt was requested.
    pub(crate) fn interrupted(&self) -> StageError {
        StageError::Interrupted {
            work: self.work.path().to_path_buf(),
        }
    }

    /// `Err(Interrupted)` once an interrupt was requested.
    pub(crate) fn check_interrupt(&self) -> Result<(), StageError> {
        if self.interrupt.load(Ordering::SeqCst) {
            return Err(self.interrupted());
        }
        Ok(())
    }

    /// Chunk `i` of `total` is in a stage's log (leaf or source log): shows it on `bar`, and
    /// requests an interrupt once [`crate::interrupt_after_chunks`] chunks are logged (the
    /// resume tests' hook).
    pub(crate) fn chunk_logged(&self, bar: &Bar, i: usize, total: usize) {
        bar.set(i as u64 + 1, total as u64);
        if crate::system::interrupt_after().is_some_and(|n| i as u64 + 1 >= n) {
            self.interrupt.store(true, Ordering::SeqCst);
        }
    }

    /// Records a stage's time, started at `t`; `resumed` if its artifact came from the work
    /// folder.
    pub(crate) fn stage_done(&mut self, stage: Stage, t: Instant, resumed: bool) {
        self.times.push(StageTime {
            stage: stage.name(),
            seconds: t.elapsed().as_secs_f64(),
            peak_rss: crate::system::peak_rss(),
            resumed,
        });
    }
}
