//! One integration-test binary per crate: each crate's tests live in `tests/all/` as modules of
//! `tests/all/main.rs` (the e2e suite in the repository's `tests/e2e/main.rs`), so a CI run
//! links one test binary per crate instead of one per file and runs all of a crate's tests in
//! parallel threads of one process. Cargo compiles only the files `main.rs` declares, so a test
//! file dropped into the folder without its `mod` line would silently never run;
//! [`assert_every_file_is_a_module`] is the test that catches that.

use std::collections::BTreeSet;
use std::path::Path;

/// The module names `main_rs` declares with `mod NAME;` or `pub mod NAME;` (attributes such as
/// `#[path]` on the line before are allowed; inline `mod NAME { … }` blocks are not files).
pub fn declared_modules(main_rs: &str) -> BTreeSet<String> {
    main_rs
        .lines()
        .map(str::trim)
        .filter_map(|l| l.strip_prefix("pub ").unwrap_or(l).strip_prefix("mod "))
        .filter_map(|rest| rest.strip_suffix(';'))
        .map(|name| name.trim().to_string())
        .collect()
}

/// The modules the folder `dir` holds: every `NAME.rs` except `main.rs`, and every
/// sub-folder with a `mod.rs`.
pub fn module_files(dir: &Path) -> BTreeSet<String> {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    let mut names = BTreeSet::new();
    for entry in entries {
        let path = entry
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .path();
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default();
        let is_module = if path.is_dir() {
            path.join("mod.rs").is_file()
        } else {
            path.extension().is_some_and(|x| x == "rs") && stem != "main"
        };
        if is_module {
            names.insert(stem.to_string());
        }
    }
    names
}

/// Panics, naming the files, when a module file in `dir` (the folder of a test binary's
/// `main.rs`, whose text is `main_rs`) is not declared by `main.rs`, i.e. would never be
/// compiled or run.
pub fn assert_every_file_is_a_module(dir: &Path, main_rs: &str) {
    let declared = declared_modules(main_rs);
    let missing: Vec<_> = module_files(dir).difference(&declared).cloned().collect();
    assert!(
        missing.is_empty(),
        "{}: {missing:?} not declared in main.rs, so never compiled or run: add `mod NAME;` \
         for each (one test binary per crate; docs/ARCHITECTURE.md, \"Tests\")",
        dir.display()
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_declared_and_undeclared_modules() {
        let dir = tempfile_dir();
        for f in ["main.rs", "a.rs", "b.rs", "notes.txt"] {
            std::fs::write(dir.join(f), "").unwrap();
        }
        std::fs::create_dir(dir.join("common")).unwrap();
        std::fs::write(dir.join("common/mod.rs"), "").unwrap();
        std::fs::create_dir(dir.join("data")).unwrap();
        let files: Vec<_> = module_files(&dir).into_iter().collect();
        assert_eq!(files, ["a", "b", "common"]);
        let main = "//! x\nmod a;\n#[path = \"common/mod.rs\"]\npub mod common;\nmod inline {}\n";
        let declared: Vec<_> = declared_modules(main).into_iter().collect();
        assert_eq!(declared, ["a", "common"]);
        let err = std::panic::catch_unwind(|| assert_every_file_is_a_module(&dir, main));
        let msg = *err.unwrap_err().downcast::<String>().unwrap();
        assert!(msg.contains("[\"b\"]"), "{msg}");
        assert_every_file_is_a_module(&dir, &format!("{main}mod b;\n"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A fresh folder under the system's temporary directory (the kit has no dependencies).
    fn tempfile_dir() -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("voxlod-testkit-suite-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }
}
