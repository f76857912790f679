//! The layout's promises, read from the sources: no import circle between modules (a module
//! and its own ancestors aside), and in the core every arrow between stages points down the
//! data flow (model → bench → trace → measure → identify → calibration → validate → diagnose →
//! session → report), so a stage never names one that comes after it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

type ModPath = Vec<String>;

/// The core's top-level modules, lowest layer first. A module may use only modules listed
/// before it.
const CORE_LAYERS: &[&str] = &[
    "files",
    "solver",
    "model",
    "plan",
    "trace",
    "bench",
    "hardware",
    "measure",
    "identify",
    "validate",
    "calibration",
    "diagnose",
    "position",
    "session",
    "report",
];

/// Every `.rs` file under `src`, keyed by its module path (`a/b/mod.rs` and `a/b.rs` are
/// `a::b`). Separate test files (`tests.rs`) are left out: tests may reach anywhere.
fn modules(src: &Path) -> BTreeMap<ModPath, PathBuf> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            if path.extension().and_then(|e| e.to_str()) != Some("rs") {
                continue;
            }
            let rel = path.strip_prefix(src).expect("under src").with_extension("");
            let mut parts: ModPath = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
            let last = parts.last().cloned().unwrap_or_default();
            if last == "tests" {
                continue;
            }
            if ["mod", "lib", "main"].contains(&last.as_str()) {
                parts.pop();
            }
            out.insert(parts, path);
        }
    }
    out
}

/// The code of a file without its test module and line comments.
fn code_of(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let text = match text.find("#[cfg(test)]") {
        Some(i) => &text[..i],
        None => &text[..],
    };
    text.lines().map(|l| l.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n")
}

/// The identifiers of a path that starts at byte `at` (`a::b::{c, d}` gives `a, b`).
fn path_at(code: &str, at: usize) -> Vec<String> {
    let mut parts = Vec::new();
    let mut rest = &code[at..];
    loop {
        let ident: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        if ident.is_empty() {
            break;
        }
        rest = &rest[ident.len()..];
        parts.push(ident);
        match rest.strip_prefix("::") {
            Some(r) => rest = r,
            None => break,
        }
    }
    parts
}

/// The modules a file names through `crate::` or `super::` paths.
fn uses(module: &ModPath, is_mod_file: bool, code: &str) -> Vec<ModPath> {
    let mut out = Vec::new();
    for key in ["crate::", "super::"] {
        for (at, _) in code.match_indices(key) {
            let before = code[..at].chars().last();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            let mut parts = path_at(code, at);
            let mut base: ModPath = if parts[0] == "crate" {
                Vec::new()
            } else if is_mod_file {
                module.clone()
            } else {
                module[..module.len().saturating_sub(1)].to_vec()
            };
            parts.remove(0);
            if key == "super::" {
                base.truncate(base.len().saturating_sub(if is_mod_file { 1 } else { 0 }));
                while parts.first().is_some_and(|p| p == "super") {
                    parts.remove(0);
                    base.pop();
                }
            }
            base.extend(parts);
            out.push(base);
        }
    }
    out
}

/// Module-to-module arrows of a crate, each resolved to the longest module path it names.
fn graph(src: &Path) -> BTreeMap<ModPath, BTreeSet<ModPath>> {
    let mods = modules(src);
    let mut edges: BTreeMap<ModPath, BTreeSet<ModPath>> = BTreeMap::new();
    for (module, path) in &mods {
        let is_mod_file = path.file_stem().is_some_and(|s| ["mod", "lib", "main"].contains(&s.to_str().unwrap_or("")));
        let targets = edges.entry(module.clone()).or_default();
        for named in uses(module, is_mod_file, &code_of(path)) {
            let target = (0..=named.len()).rev().map(|k| named[..k].to_vec()).find(|p| mods.contains_key(p));
            if let Some(t) = target.filter(|t| t != module) {
                targets.insert(t);
            }
        }
    }
    edges
}

fn is_ancestor(a: &ModPath, b: &ModPath) -> bool {
    a.len() <= b.len() && b[..a.len()] == a[..] || b.len() <= a.len() && a[..b.len()] == b[..]
}

/// Arrows that close a circle: `a -> b` where `b` reaches `a` again, ancestors aside.
fn circles(edges: &BTreeMap<ModPath, BTreeSet<ModPath>>) -> Vec<String> {
    let next = |m: &ModPath| -> Vec<ModPath> {
        edges.get(m).map(|s| s.iter().filter(|n| !is_ancestor(m, n)).cloned().collect()).unwrap_or_default()
    };
    let reaches = |from: &ModPath, to: &ModPath| {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.clone()];
        while let Some(m) = stack.pop() {
            if &m == to {
                return true;
            }
            if seen.insert(m.clone()) {
                stack.extend(next(&m));
            }
        }
        false
    };
    let mut out = Vec::new();
    for a in edges.keys() {
        for b in next(a) {
            if reaches(&b, a) {
                out.push(format!("{} -> {}", a.join("::"), b.join("::")));
            }
        }
    }
    out
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root").to_path_buf()
}

#[test]
fn no_module_of_the_core_or_the_app_sits_in_an_import_circle() {
    for krate in ["core/src", "app/src"] {
        let found = circles(&graph(&workspace().join(krate)));
        assert!(found.is_empty(), "{krate}: arrows inside an import circle:\n{}", found.join("\n"));
    }
}

#[test]
fn every_arrow_between_core_stages_points_down_the_data_flow() {
    let edges = graph(&workspace().join("core/src"));
    let rank = |m: &str| CORE_LAYERS.iter().position(|l| *l == m);
    let mut wrong = BTreeSet::new();
    for (from, targets) in &edges {
        let Some(top) = from.first() else { continue };
        let from_rank = rank(top).unwrap_or_else(|| panic!("core module `{top}` is missing from CORE_LAYERS"));
        for to in targets.iter().filter_map(|t| t.first()).filter(|t| *t != top) {
            let to_rank = rank(to).unwrap_or_else(|| panic!("core module `{to}` is missing from CORE_LAYERS"));
            if to_rank > from_rank {
                wrong.insert(format!("{} -> {to}", from.join("::")));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "arrows from a lower stage to a higher one:\n{}",
        wrong.into_iter().collect::<Vec<_>>().join("\n")
    );
}

#[test]
fn the_checker_sees_a_circle_and_an_upward_arrow() {
    let m = |s: &str| s.split("::").map(String::from).collect::<ModPath>();
    let mut edges = BTreeMap::new();
    edges.insert(m("a::x"), BTreeSet::from([m("b")]));
    edges.insert(m("b"), BTreeSet::from([m("a::x")]));
    edges.insert(m("a"), BTreeSet::from([m("a::x")]));
    assert_eq!(circles(&edges).len(), 2);
    let used = uses(&m("measure::track::grid"), false, "use super::super::extrema::X; crate::model::phase::P");
    assert_eq!(used, vec![m("model::phase::P"), m("measure::extrema::X")]);
}
