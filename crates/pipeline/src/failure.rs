//! What becomes of a failed run's work folder, and the error it reports.

use crate::chain_text::chain_text;
use crate::error::StageError;
use crate::files::work::{WorkDir, WorkFile};
use crate::system::interrupted;

/// The error of a failed build, and what becomes of its work folder: kept after an interrupt
/// (to resume) and after a failure to write the output once every chunk is voxelized (to only
/// write the file next time), removed otherwise.
pub(crate) fn failed(e: StageError, work: WorkDir) -> anyhow::Error {
    if matches!(e, StageError::Interrupted { .. }) || interrupted() {
        return StageError::Interrupted {
            work: work.path().to_path_buf(),
        }
        .into();
    }
    let e = anyhow::Error::from(e);
    if work.file(WorkFile::LeavesMarker).exists() && is_output_failure(&e) {
        // Every chunk is voxelized: keep them, so that once the output side is fixed
        // (space, permissions) the same command only writes the file.
        return anyhow::anyhow!(
            "{}; the voxelized chunks are kept in {}: run the same command again to write only the file",
            chain_text(&e),
            work.path().display()
        );
    }
    // A failed build leaves nothing behind (a killed one keeps its folder to resume).
    let _ = work.remove();
    e
}

/// A failure of writing the output (I/O on it, too little space, the final rename), as
/// opposed to bad data: worth keeping the work for.
fn is_output_failure(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.is::<std::io::Error>()
            || matches!(
                c.downcast_ref::<StageError>(),
                Some(
                    StageError::Output(_)
                        | StageError::Io { .. }
                        | StageError::Format(voxlod_format::FormatError::Io { .. })
                )
            )
            || matches!(
                c.downcast_ref::<voxlod_format::FormatError>(),
                Some(voxlod_format::FormatError::Io { .. })
            )
    })
}
