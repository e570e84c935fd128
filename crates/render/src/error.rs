//! The crate's error type: every message says what failed and where.

use std::path::PathBuf;

/// Everything that can go wrong exporting or rendering.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// Reading the octree failed (the message names the file and node).
    #[error(transparent)]
    Format(#[from] voxlod_format::FormatError),
    /// An option is out of range (level not in the file, zero image size, ...).
    #[error("{0}")]
    Option(String),
    /// Writing an output file failed.
    #[error("{}: {op}: {source}", path.display())]
    Io {
        /// The output file.
        path: PathBuf,
        /// What was being done.
        op: &'static str,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// No GPU adapter (for CPU-only machines install Mesa's lavapipe: mesa-vulkan-drivers).
    #[error("no graphics adapter found ({0}); on a machine without a GPU install Mesa's lavapipe (apt-get install mesa-vulkan-drivers libvulkan1)")]
    NoAdapter(String),
    /// The device could not be created or reported an error.
    #[error("GPU ({adapter}): {reason}")]
    Gpu {
        /// Adapter name.
        adapter: String,
        /// What went wrong.
        reason: String,
    },
    /// Encoding the JPEG failed.
    #[error("{}: writing JPEG: {reason}", path.display())]
    Jpeg {
        /// The output file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// Encoding the PNG failed.
    #[error("{}: writing PNG: {reason}", path.display())]
    Png {
        /// The output file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

impl RenderError {
    /// `Io` for `op` on `path`, as a `map_err` argument.
    pub(crate) fn io(
        op: &'static str,
        path: &std::path::Path,
    ) -> impl FnOnce(std::io::Error) -> RenderError {
        let path = path.to_path_buf();
        move |source| RenderError::Io { path, op, source }
    }
}
