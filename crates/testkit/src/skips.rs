//! What the tests skipped, said where it is seen: at the end of the test binary's output.
//!
//! The test runner captures what a passing test prints, so a test that skips its real-mesh part
//! (no `../shared` beside the clone) would pass with "0 ignored" and its "SKIPPED" line unseen.
//! [`skipped`] records each skip, and the first one registers an exit handler (`atexit`, which
//! runs after the runner's `test result:` line) that prints how many tests skipped what:
//!
//! ```text
//! test result: ok. 40 passed; 0 failed; 0 ignored; 0 measured; 0 filtered out; finished in 3.1s
//!
//! SKIPPED in 2 tests (their checks did not all run; under CI=true this is a failure):
//!     octree::real_meshes_build_with_stable_counts: ../shared/data/meshes is not beside this clone
//!     shard::merge_equals_single_build_on_the_npm_bunny: ../shared/data/meshes is not beside this clone
//! ```
//!
//! Whether a skip is allowed is the caller's rule (under `CI=true` the shared meshes and the
//! Python modules must be there: [`crate::shared_meshes`] fails instead of calling this).

use std::collections::BTreeMap;
use std::io::Write;
use std::sync::{Mutex, Once};

static SKIPS: Mutex<BTreeMap<String, String>> = Mutex::new(BTreeMap::new());
static AT_EXIT: Once = Once::new();

extern "C" {
    fn atexit(f: extern "C" fn()) -> std::os::raw::c_int;
}

/// Records that `test` skipped part or all of its checks because of `why`: prints
/// "`test`: SKIPPED: `why`" now (shown with `--nocapture`), and the test binary ends with a
/// list of every test that skipped something (the first reason of each, on one line: the last
/// line of a multi-line `why`, such as a Python traceback's error).
pub fn skipped(test: &str, why: &str) {
    eprintln!("{test}: SKIPPED: {why}");
    let why = why.trim().lines().last().unwrap_or_default().trim();
    SKIPS
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .entry(test.to_string())
        .or_insert_with(|| why.to_string());
    AT_EXIT.call_once(|| {
        // SAFETY: `atexit` is the C library's; `report` is a plain `extern "C" fn` that does
        // not unwind (it catches nothing it could panic on: try_lock, write errors ignored).
        let registered = unsafe { atexit(report) } == 0;
        if !registered {
            eprintln!("{test}: the list of skipped tests could not be registered");
        }
    });
}

/// The tests recorded so far and their reasons.
pub fn recorded() -> Vec<(String, String)> {
    let skips = SKIPS.lock().unwrap_or_else(|e| e.into_inner());
    skips.iter().map(|(t, w)| (t.clone(), w.clone())).collect()
}

/// The closing report for `skips` (test, reason), or `None` when nothing was skipped.
pub fn report_text(skips: &[(String, String)]) -> Option<String> {
    if skips.is_empty() {
        return None;
    }
    let n = skips.len();
    let mut s = format!(
        "SKIPPED in {n} test{} (their checks did not all run; under CI=true this is a \
         failure):\n",
        if n == 1 { "" } else { "s" }
    );
    for (test, why) in skips {
        s.push_str(&format!("    {test}: {why}\n"));
    }
    Some(s)
}

extern "C" fn report() {
    // The runner's threads are done when the process exits; a lock still held would mean a
    // test thread died holding it, and then no report is better than a hang.
    let Ok(skips) = SKIPS.try_lock() else { return };
    let list: Vec<_> = skips.iter().map(|(t, w)| (t.clone(), w.clone())).collect();
    if let Some(text) = report_text(&list) {
        let mut out = std::io::stdout().lock();
        let _ = out.write_all(text.as_bytes());
        let _ = out.flush();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_lists_each_test_once() {
        assert_eq!(report_text(&[]), None);
        let one = report_text(&[("a::b".into(), "no mesh".into())]).unwrap();
        assert!(one.contains("SKIPPED in 1 test (") && one.contains("    a::b: no mesh\n"));
        let two = report_text(&[("a".into(), "x".into()), ("b".into(), "y".into())]).unwrap();
        assert!(two.contains("SKIPPED in 2 tests ("), "{two}");
    }

    /// Runs only as the child of `the_binary_ends_with_the_list`: records a skip.
    #[test]
    fn child_that_skips() {
        if std::env::var_os("VOXLOD_TESTKIT_SKIP_CHILD").is_some() {
            skipped("skips::tests::child_that_skips", "made up for the test");
            skipped(
                "skips::tests::child_that_skips",
                "a second reason is not listed",
            );
            skipped(
                "another::test",
                "Traceback (most recent call last):\n  x\nmade up too\n",
            );
        }
    }

    /// The report comes after the runner's summary line, in the same output, whether or not
    /// output is captured.
    #[test]
    fn the_binary_ends_with_the_list() {
        let exe = std::env::current_exe().unwrap();
        let o = std::process::Command::new(exe)
            .args([
                "skips::tests::child_that_skips",
                "--exact",
                "--test-threads=1",
            ])
            .env("VOXLOD_TESTKIT_SKIP_CHILD", "1")
            .output()
            .unwrap();
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{out}");
        let summary = out.find("test result: ok. 1 passed").expect(&out);
        let list = out.find("SKIPPED in 2 tests").expect(&out);
        assert!(summary < list, "the list must follow the summary:\n{out}");
        assert!(out.contains("    skips::tests::child_that_skips: made up for the test\n"));
        assert!(out.contains("    another::test: made up too\n"));
        assert!(!out.contains("second reason"), "{out}");
    }
}
