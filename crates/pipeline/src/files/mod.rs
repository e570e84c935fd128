//! The files a run owns besides its intermediates' contents: the output (checked, locked,
//! staged, renamed), the work folder and its markers.

pub(crate) mod markers;
pub(crate) mod output;
pub(crate) mod work;
