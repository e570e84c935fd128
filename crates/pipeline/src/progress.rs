//! Progress bars (indicatif) for the stages; hidden when progress is off.

use indicatif::{ProgressBar, ProgressStyle};

pub(crate) struct Stage(ProgressBar);

impl Stage {
    fn new(show: bool, name: &str, total: u64, template: &str) -> Stage {
        let bar = if show {
            ProgressBar::new(total)
        } else {
            ProgressBar::hidden()
        };
        let style = ProgressStyle::with_template(template)
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
        bar.set_style(style);
        bar.set_prefix(name.to_string());
        Stage(bar)
    }

    /// A stage measured in input bytes.
    pub(crate) fn bytes(show: bool, name: &str, total: u64) -> Stage {
        Self::new(
            show,
            name,
            total,
            "{prefix:>10} [{bar:40}] {bytes}/{total_bytes} {bytes_per_sec} eta {eta}",
        )
    }

    /// A stage measured in items (triangles, chunks).
    pub(crate) fn items(show: bool, name: &str, total: u64) -> Stage {
        Self::new(
            show,
            name,
            total,
            "{prefix:>10} [{bar:40}] {human_pos}/{human_len} {per_sec} eta {eta}",
        )
    }

    pub(crate) fn set(&self, done: u64, total: u64) {
        if self.0.length() != Some(total) {
            self.0.set_length(total);
        }
        self.0.set_position(done);
    }

    pub(crate) fn finish(&self) {
        self.0.finish();
    }
}
