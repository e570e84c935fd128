//! The licence the manifests state has its files: the workspace's `license` expression (SPDX)
//! names only licences whose text is in the repository root, every crate and the Python
//! package state that same expression, and the README's "Licence" section links each file.

use std::path::Path;

use super::REPO;

fn read(rel: &str) -> String {
    std::fs::read_to_string(Path::new(REPO).join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The value of `key = "…"` on a line of a TOML file (the manifests keep it on one line).
fn value<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    text.lines().find_map(|l| {
        let rest = l.trim().strip_prefix(key)?.trim_start().strip_prefix('=')?;
        let rest = rest.trim();
        // `license = { text = "…" }` (pyproject) or `license = "…"`
        let rest = rest.strip_prefix("{ text =").map_or(rest, str::trim);
        Some(rest.trim_start_matches('"').split('"').next().unwrap_or(""))
    })
}

#[test]
fn the_stated_licence_has_its_files() {
    let root = read("Cargo.toml");
    let expr = value(&root, "license").expect("the workspace states a licence");
    assert_eq!(expr, "MIT OR Apache-2.0");
    // each licence of the expression: its file, and the text in it
    let files = [
        (
            "MIT",
            "LICENSE-MIT",
            "Permission is hereby granted, free of charge",
        ),
        (
            "Apache-2.0",
            "LICENSE-APACHE",
            "Apache License\n                           Version 2.0",
        ),
    ];
    let ids: Vec<&str> = expr.split(" OR ").collect();
    assert_eq!(ids.len(), files.len(), "{expr}");
    let readme = read("README.md");
    let section = &readme[readme.find("## Licence").expect("a Licence section")..];
    for (id, file, text) in files {
        assert!(ids.contains(&id), "{id} not in {expr}");
        assert!(read(file).contains(text), "{file} is not the {id} text");
        assert!(
            section.contains(&format!("({file})")),
            "the README does not link {file}"
        );
    }
    // every crate inherits it; the Python package states the same
    for entry in std::fs::read_dir(Path::new(REPO).join("crates")).unwrap() {
        let manifest = entry.unwrap().path().join("Cargo.toml");
        let text = std::fs::read_to_string(&manifest).unwrap();
        assert!(
            text.lines().any(|l| l.trim() == "license.workspace = true"),
            "{} does not inherit the workspace licence",
            manifest.display()
        );
    }
    assert_eq!(value(&read("python/Cargo.toml"), "license"), Some(expr));
    assert_eq!(value(&read("python/pyproject.toml"), "license"), Some(expr));
}
