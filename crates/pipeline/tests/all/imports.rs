//! The crate's modules import each other in one direction only: the graph of `crate::…` and
//! `super::…` paths between its source files (tests left out) has no circle.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A module by its path below the crate root (`["stages", "tile"]`); the root is empty.
type Module = Vec<String>;

/// Every `.rs` file under `dir` as (module path, text without comments and test modules).
fn modules(dir: &Path, prefix: &[String], out: &mut BTreeMap<Module, String>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        if path.is_dir() {
            let mut p = prefix.to_vec();
            p.push(name);
            modules(&path, &p, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let mut m = prefix.to_vec();
            if !matches!(name.as_str(), "mod" | "lib") {
                m.push(name);
            }
            out.insert(m, strip(&std::fs::read_to_string(&path).unwrap()));
        }
    }
}

/// The text without `//` comments and without the `#[cfg(test)] mod tests` module.
fn strip(text: &str) -> String {
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(i) => &text[..i],
        None => text,
    };
    text.lines()
        .map(|l| l.find("//").map_or(l, |i| &l[..i]))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The paths of a `use` tree's text after `crate::{` or `super::{` (`a::b, c::{d, e}`).
fn expand(prefix: &[String], body: &str, out: &mut Vec<Module>) {
    let (mut depth, mut start) = (0, 0);
    let mut parts = Vec::new();
    for (i, c) in body.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&body[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&body[start..]);
    for part in parts {
        let part = part.trim();
        if part.is_empty() {
            continue;
        }
        let mut p = prefix.to_vec();
        match part.find("::{") {
            Some(i) if part.ends_with('}') => {
                p.extend(part[..i].split("::").map(str::to_string));
                expand(&p, &part[i + 3..part.len() - 1], out);
            }
            _ => {
                let part = part.split(" as ").next().unwrap();
                p.extend(part.split("::").map(str::to_string));
                out.push(p);
            }
        }
    }
}

/// The paths that start with `crate::` or `super::` in `text` (of module `m`), made absolute.
fn paths(m: &Module, text: &str) -> Vec<Module> {
    let mut out = Vec::new();
    let bytes = text.as_bytes();
    for anchor in ["crate::", "super::"] {
        let mut from = 0;
        while let Some(i) = text[from..].find(anchor).map(|i| i + from) {
            from = i + anchor.len();
            if i > 0 && (bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_') {
                continue;
            }
            // `super` inside an inline `mod x { … }` is the file's own module
            let inline = text[..i]
                .split("mod ")
                .skip(1)
                .any(|s| s.split_once(' ').is_some_and(|(_, r)| r.starts_with('{')));
            let mut base: Module = if anchor == "crate::" || inline {
                Vec::new()
            } else {
                m[..m.len().saturating_sub(1)].to_vec()
            };
            if anchor == "super::" && inline {
                base = m.clone();
            }
            let mut rest = &text[from..];
            while let Some(r) = rest.strip_prefix("super::") {
                base.pop();
                rest = r;
            }
            if let Some(group) = rest.strip_prefix('{') {
                let mut depth = 1;
                let end = group
                    .char_indices()
                    .find(|&(_, c)| {
                        depth += match c {
                            '{' => 1,
                            '}' => -1,
                            _ => 0,
                        };
                        depth == 0
                    })
                    .map_or(group.len(), |(i, _)| i);
                expand(&base, &group[..end], &mut out);
            } else {
                let end = rest
                    .find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                    .unwrap_or(rest.len());
                expand(&base, rest[..end].trim_end_matches(':'), &mut out);
            }
        }
    }
    out
}

/// The modules in a circle of `edges`, if any (depth-first search for a back edge).
fn circle(edges: &BTreeMap<Module, BTreeSet<Module>>) -> Option<Vec<Module>> {
    fn visit(
        m: &Module,
        edges: &BTreeMap<Module, BTreeSet<Module>>,
        state: &mut BTreeMap<Module, u8>,
        stack: &mut Vec<Module>,
    ) -> Option<Vec<Module>> {
        state.insert(m.clone(), 1);
        stack.push(m.clone());
        for n in &edges[m] {
            match state.get(n) {
                Some(1) => {
                    let at = stack.iter().position(|s| s == n).unwrap();
                    return Some(stack[at..].to_vec());
                }
                Some(_) => {}
                None => {
                    if let Some(c) = visit(n, edges, state, stack) {
                        return Some(c);
                    }
                }
            }
        }
        stack.pop();
        state.insert(m.clone(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for m in edges.keys() {
        if !state.contains_key(m) {
            if let Some(c) = visit(m, edges, &mut state, &mut Vec::new()) {
                return Some(c);
            }
        }
    }
    None
}

/// No two modules of the crate import each other, directly or through others; `lib.rs` only
/// declares and re-exports.
#[test]
fn no_import_circle_between_modules() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = BTreeMap::new();
    modules(&src, &[], &mut files);
    assert!(files.len() > 20, "{} modules found", files.len());
    let mut edges = BTreeMap::new();
    for (m, text) in &files {
        let mut to = BTreeSet::new();
        for p in paths(m, text) {
            // the longest prefix that is a module file
            let target = (0..=p.len())
                .rev()
                .map(|n| p[..n].to_vec())
                .find(|q| files.contains_key(q))
                .unwrap_or_default();
            if &target != m {
                to.insert(target);
            }
        }
        edges.insert(m.clone(), to);
    }
    let root: Module = Vec::new();
    assert!(
        edges.values().all(|to| !to.contains(&root)),
        "a module imports from lib.rs (import from the defining module instead): {:?}",
        edges
            .iter()
            .filter(|(_, to)| to.contains(&root))
            .map(|(m, _)| m.join("::"))
            .collect::<Vec<_>>()
    );
    if let Some(c) = circle(&edges) {
        let names: Vec<String> = c.iter().map(|m| m.join("::")).collect();
        panic!("import circle: {} -> (back)", names.join(" -> "));
    }
}
