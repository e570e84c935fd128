//! Progress of the stages on stderr: an indicatif bar when stderr is a terminal, otherwise
//! (piped, logged, under CI) a plain line every few seconds and one when the stage ends, like
//! PotreeConverter's log: stage, percent, count, rate. Nothing when progress is off.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressState, ProgressStyle};

/// Seconds between two plain progress lines of one stage.
const PLAIN_EVERY: Duration = Duration::from_secs(5);

/// The progress display of one stage or task: a bar on a terminal, plain lines otherwise,
/// nothing when not shown. Update it with [`Bar::set`] and end it with [`Bar::finish`].
pub struct Bar {
    bar: ProgressBar,
    plain: Option<Plain>,
}

/// The plain-line reporter of one stage.
struct Plain {
    name: String,
    unit: Unit,
    start: Instant,
    /// When the last line was printed, and the last (done, total) seen.
    last: Mutex<(Instant, u64, u64)>,
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum Unit {
    Bytes,
    Items(&'static str),
}

/// What a stage of the given name counts (the pipeline's stage names).
fn item_name(stage: &str) -> &'static str {
    match stage {
        "count" | "scatter" => "triangles",
        "voxelize" | "lod+write" => "chunks",
        _ => "items",
    }
}

/// `x` with three significant digits and a k/M/G suffix: `4.93M`, `812k`, `12.3`, `0.50`.
pub(crate) fn round_count(x: f64) -> String {
    if !x.is_finite() {
        return "-".into();
    }
    let (v, suffix) = match x.abs() {
        a if a >= 1e9 => (x / 1e9, "G"),
        a if a >= 1e6 => (x / 1e6, "M"),
        a if a >= 1e3 => (x / 1e3, "k"),
        _ => (x, ""),
    };
    let digits = match v.abs() {
        a if a >= 99.95 => 0,
        a if a >= 9.995 => 1,
        _ => 2,
    };
    format!("{v:.digits$}{suffix}")
}

/// A count of whole items: exact below a thousand (`46`, not `46.0`), else as [`round_count`]
/// (`1.23k`, `4.93M`).
fn round_items(n: u64) -> String {
    if n < 1000 {
        n.to_string()
    } else {
        round_count(n as f64)
    }
}

/// Bytes as `1.25 GiB`, `310 MiB`: binary units, three significant digits.
fn round_bytes(x: f64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = x.max(0.0);
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    let digits = if u == 0 || v >= 99.95 {
        0
    } else if v >= 9.995 {
        1
    } else {
        2
    };
    format!("{v:.digits$} {}", UNITS[u])
}

impl Unit {
    fn rate(self, per_sec: f64) -> String {
        match self {
            Unit::Bytes => format!("{}/s", round_bytes(per_sec)),
            Unit::Items(name) => format!("{} {name}/s", round_count(per_sec)),
        }
    }
}

impl Plain {
    /// One progress line: `voxelize   42% 1.23k/2.90k chunks, 235 chunks/s, 7.1s`.
    fn line(&self, done: u64, total: u64, elapsed: Duration, finished: bool) -> String {
        let secs = elapsed.as_secs_f64();
        let rate = if secs > 0.0 {
            done as f64 / secs
        } else {
            f64::NAN
        };
        let pct = if total > 0 {
            (100.0 * done as f64 / total as f64).min(100.0)
        } else {
            100.0
        };
        let amount = match self.unit {
            Unit::Bytes => format!("{}/{}", round_bytes(done as f64), round_bytes(total as f64)),
            Unit::Items(name) => format!("{}/{} {name}", round_items(done), round_items(total)),
        };
        format!(
            "{:>10} {:>3.0}% {amount}, {}, {secs:.1}s{}",
            self.name,
            pct.floor(),
            self.unit.rate(rate),
            if finished { " (done)" } else { "" }
        )
    }
}

impl Bar {
    fn new(show: bool, name: &str, total: u64, unit: Unit) -> Bar {
        let terminal = std::io::stderr().is_terminal();
        let bar = if show && terminal {
            ProgressBar::new(total)
        } else {
            ProgressBar::hidden()
        };
        let template = match unit {
            Unit::Bytes => "{prefix:>10} [{bar:40}] {bytes}/{total_bytes} {rate} eta {eta}",
            Unit::Items(_) => "{prefix:>10} [{bar:40}] {human_pos}/{human_len} {rate} eta {eta}",
        };
        let style = ProgressStyle::with_template(template)
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .with_key(
                "rate",
                move |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                    let _ = w.write_str(&unit.rate(s.per_sec()));
                },
            )
            .progress_chars("=> ");
        bar.set_style(style);
        bar.set_prefix(name.to_string());
        let now = Instant::now();
        let plain = (show && !terminal).then(|| Plain {
            name: name.to_string(),
            unit,
            start: now,
            last: Mutex::new((now, 0, total)),
        });
        Bar { bar, plain }
    }

    /// A stage measured in input bytes; `show` false displays nothing.
    pub fn bytes(show: bool, name: &str, total: u64) -> Bar {
        Self::new(show, name, total, Unit::Bytes)
    }

    /// A pipeline stage measured in items, named after what the stage counts (triangles of
    /// `count` and `scatter`, chunks of `voxelize` and `lod+write`).
    pub fn items(show: bool, name: &str, total: u64) -> Bar {
        Self::counting(show, name, total, item_name(name))
    }

    /// A task `name` measured in items called `what` (e.g. "records"); `show` false displays
    /// nothing.
    pub fn counting(show: bool, name: &str, total: u64, what: &'static str) -> Bar {
        Self::new(show, name, total, Unit::Items(what))
    }

    /// `done` of `total` are done (the total may change while the task runs).
    pub fn set(&self, done: u64, total: u64) {
        if self.bar.length() != Some(total) {
            self.bar.set_length(total);
        }
        self.bar.set_position(done);
        if let Some(p) = &self.plain {
            // a poisoned lock only means another thread panicked while printing: skip lines
            let Ok(mut last) = p.last.lock() else { return };
            let now = Instant::now();
            last.1 = done;
            last.2 = total;
            if now.duration_since(last.0) >= PLAIN_EVERY {
                last.0 = now;
                eprintln!("{}", p.line(done, total, now - p.start, false));
            }
        }
    }

    /// The task has ended: the bar stays at its last state, a plain display prints its last
    /// line.
    pub fn finish(&self) {
        self.bar.finish();
        if let Some(p) = &self.plain {
            let Ok(last) = p.last.lock() else { return };
            eprintln!("{}", p.line(last.1, last.2, p.start.elapsed(), true));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_are_rounded_to_three_digits() {
        let cases = [
            (4_927_235.778_6, "4.93M"),
            (812_400.0, "812k"),
            (12.345, "12.3"),
            (0.5, "0.50"),
            (999.0, "999"),
            (99_960.0, "100k"),
            (2.5e9, "2.50G"),
        ];
        for (x, want) in cases {
            assert_eq!(round_count(x), want, "{x}");
        }
        assert_eq!(round_bytes(1.28 * 1024.0 * 1024.0 * 1024.0), "1.28 GiB");
        assert_eq!(round_bytes(300.0), "300 B");
        assert_eq!(round_bytes(310.0 * 1024.0 * 1024.0), "310 MiB");
    }

    #[test]
    fn a_plain_line_names_stage_percent_count_and_rate() {
        let now = Instant::now();
        let p = Plain {
            name: "voxelize".into(),
            unit: Unit::Items("chunks"),
            start: now,
            last: Mutex::new((now, 0, 0)),
        };
        let l = p.line(1230, 2900, Duration::from_secs(5), false);
        assert_eq!(l, "  voxelize  42% 1.23k/2.90k chunks, 246 chunks/s, 5.0s");
        let l = p.line(2900, 2900, Duration::from_secs(10), true);
        assert!(
            l.ends_with("100% 2.90k/2.90k chunks, 290 chunks/s, 10.0s (done)"),
            "{l}"
        );
        let l = p.line(46, 46, Duration::from_secs(2), true);
        assert!(l.contains(" 46/46 chunks, 23.0 chunks/s"), "{l}");
        assert_eq!(round_items(999), "999");
        assert_eq!(round_items(1230), "1.23k");
        let b = Plain {
            name: "ingest".into(),
            unit: Unit::Bytes,
            start: now,
            last: Mutex::new((now, 0, 0)),
        };
        let l = b.line(512 << 20, 1 << 30, Duration::from_secs(2), false);
        assert_eq!(l, "    ingest  50% 512 MiB/1.00 GiB, 256 MiB/s, 2.0s");
    }
}
