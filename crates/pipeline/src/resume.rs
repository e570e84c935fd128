//! What an interrupted run finished, decided once from the work folder's markers: a build
//! started again with the same arguments takes each finished stage's result from its marker
//! instead of running the stage.

use crate::files::markers::{BinsMarker, IngestMarker, LeavesMarker, SourceMarker};
use crate::files::work::WorkDir;

/// The furthest stage an earlier run finished.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Done {
    /// Nothing: every stage runs.
    Fresh,
    /// The ingest stage (its marker; the spool, if it wrote one, is checked by the stage).
    Ingested,
    /// The tile stage: the bins (checked against their layout when opened).
    Tiled,
    /// The voxelize stage: every chunk is in the leaf log; tile and voxelize are skipped.
    Voxelized,
}

/// The markers of a work folder, read once before the stages run. A missing or unreadable
/// marker is `None` (its stage runs again).
#[derive(Clone, Debug, Default)]
pub(crate) struct Resume {
    /// The ingest stage's marker.
    pub ingest: Option<IngestMarker>,
    /// The tile stage's marker (the bins layout).
    pub bins: Option<BinsMarker>,
    /// The voxelize stage's marker.
    pub leaves: Option<LeavesMarker>,
    /// The source-geometry stage's marker.
    pub source: Option<SourceMarker>,
}

impl Resume {
    /// The markers in `work`.
    pub(crate) fn read(work: &WorkDir) -> Resume {
        Resume {
            ingest: work.marker(),
            bins: work.marker(),
            leaves: work.marker(),
            source: work.marker(),
        }
    }

    /// The furthest stage with a marker.
    pub(crate) fn done(&self) -> Done {
        if self.leaves.is_some() {
            Done::Voxelized
        } else if self.bins.is_some() {
            Done::Tiled
        } else if self.ingest.is_some() {
            Done::Ingested
        } else {
            Done::Fresh
        }
    }

    /// True if a stage after ingest finished: the spool and the chunk counts are not needed
    /// again.
    pub(crate) fn past_ingest(&self) -> bool {
        self.done() > Done::Ingested
    }
}
