//! The `voxlod` Python package (`python/`, maturin + PyO3): its pytest suite
//! (`python/tests/test_reader.py`, which builds files with this binary and compares every
//! node the package decodes with `scripts/voxlod_read.py`, the independent reader) run here, so
//! `cargo test` covers it. Needs `pip install ./python pytest` (`.ci/run` does it): under
//! `CI=true` a missing package is a failure, elsewhere the test says it skipped.

use std::process::Command;

use super::{BIN, REPO};

#[test]
fn python_package_passes_its_tests() {
    if !voxlod_testkit::python_ready("python_package") {
        return;
    }
    let probe = Command::new("python3")
        .args(["-c", "import voxlod, pytest; print(voxlod.__file__)"])
        .output()
        .expect("running python3");
    if !probe.status.success() {
        let why = String::from_utf8_lossy(&probe.stderr);
        assert!(
            !voxlod_testkit::under_ci(),
            "python_package: CI=true but the voxlod package or pytest is not installed \
             (python3 -m pip install ./python pytest): {why}"
        );
        voxlod_testkit::skipped(
            "python_package",
            &format!(
                "the voxlod package or pytest is not installed \
                 (python3 -m pip install ./python pytest): {}",
                why.trim()
            ),
        );
        return;
    }
    let o = Command::new("python3")
        .args([
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "python/tests",
        ])
        .current_dir(REPO)
        .env("VOXLOD_BIN", BIN)
        .output()
        .expect("running pytest");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "pytest python/tests failed:\n{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // every test ran: none skipped (a skip would hide a missing mesh or reader)
    let last = out
        .lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .unwrap_or("");
    assert!(
        last.contains(" passed") && !last.contains("skipped"),
        "pytest's summary: {last}"
    );
}
