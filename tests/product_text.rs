//! The product speaks of the product: the README, the docs, the shipped assets and every source
//! file refer to what is in the repository, never to a specification outside it, to how the work
//! was organised (issue or stop numbers, notes) or to what the code was before a change.

use std::path::{Path, PathBuf};

/// Text files of the workspace a reader meets: sources, docs, assets, manifests and scripts.
fn product_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if path.is_dir() {
            if !name.starts_with('.') && name != "target" {
                product_files(&path, out);
            }
        } else if ["rs", "md", "ron", "toml", "sh"].iter().any(|e| name.ends_with(&format!(".{e}"))) {
            out.push(path);
        }
    }
}

/// Whether `text` holds `word` with no letter, digit or `_` on either side.
fn has_word(text: &str, word: &str) -> bool {
    let is_word = |c: char| c.is_alphanumeric() || c == '_';
    text.match_indices(word).any(|(i, _)| {
        let before = text[..i].chars().next_back();
        let after = text[i + word.len()..].chars().next();
        !before.is_some_and(is_word) && !after.is_some_and(is_word)
    })
}

/// `lead` followed by optional `#`, spaces or `-`, then a digit: "issue 49", "stop-21", "issue #3".
fn numbered(text: &str, lead: &str) -> bool {
    text.match_indices(lead).any(|(i, _)| {
        let before = text[..i].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            return false;
        }
        let rest = text[i + lead.len()..].trim_start_matches([' ', '#', '-']);
        rest.len() < text.len() - i - lead.len() && rest.starts_with(|c: char| c.is_ascii_digit())
    })
}

/// What a line of a file says that the product should not: `None` when it is clean.
fn problem(line: &str, is_source: bool) -> Option<&'static str> {
    // In a source file only comments are prose; a string may carry a controller's command.
    let prose = if is_source { line.find("//").map_or("", |i| &line[i..]) } else { line };
    let lower = prose.to_lowercase();
    if has_word(line, "SPEC") || line.contains("SPEC.md") || line.contains("shared/seed") {
        Some("a specification outside the repository: name the docs page that explains it")
    } else if numbered(&lower, "issue") || lower.contains("(issue:") {
        Some("an issue: say what the product does, not which work item asked for it")
    } else if numbered(&lower, "stop") {
        Some("a work stop: history goes in commit messages")
    } else if lower.contains("see notes") || lower.contains("before the speed work") || lower.contains("before the fix")
    {
        Some("history narration: state what is, with its figure and command")
    } else {
        None
    }
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("the workspace").to_path_buf()
}

/// Every line of every product file, against `problem`.
fn findings(root: &Path) -> Vec<String> {
    let mut files = Vec::new();
    product_files(root, &mut files);
    let this = Path::new(file!()).file_name().expect("this file's name");
    let mut found = Vec::new();
    for file in files.iter().filter(|f| f.file_name() != Some(this)) {
        let Ok(text) = std::fs::read_to_string(file) else { continue };
        let is_source = file.extension().is_some_and(|e| e == "rs");
        for (n, line) in text.lines().enumerate() {
            if let Some(why) = problem(line, is_source) {
                let shown = file.strip_prefix(root).unwrap_or(file).display();
                found.push(format!("{shown}:{}: {why}\n    {}", n + 1, line.trim()));
            }
        }
    }
    found
}

#[test]
fn the_readme_docs_assets_and_sources_speak_of_the_product() {
    let root = workspace();
    let found = findings(&root);
    assert!(root.join("README.md").exists() && root.join("docs").is_dir(), "the workspace at {}", root.display());
    assert!(found.is_empty(), "{} lines speak of something else:\n{}", found.len(), found.join("\n"));
}

/// The checker on lines it must refuse and lines it must let through.
#[test]
fn the_checker_tells_history_and_outside_references_from_product_text() {
    for bad in [
        "//! The discrepancy workflow (SPEC section 9): replay",
        "/// SPEC §5: 40 nm sweep",
        "The physics are in `../shared/SPEC.md`;",
        "//! compared with the truth (issue: optics, bench, fringes).",
        "(as in issue #12)",
        "// stop-21 code 50.4 M",
        "Not worked on this stop 3.",
        "| 4.98 s (24.5 s before the speed work) |",
    ] {
        assert!(problem(bad, bad.starts_with("//")).is_some(), "not seen: {bad}");
    }
    // (line, from a source file)
    for (good, is_source) in [
        ("let mut spec = r2c.make_output_vec();", true),
        ("        \":WAV:SWE:STOP 1540.0000\",", true),
        ("/// A stop pressed before it was asked for is kept for the next motion.", true),
        ("/// Every issue the verdict raises is listed.", true),
        ("The SPECTRUM of the sweep.", false),
        ("Ctrl-C stops `calibrate` at the segment.", false),
    ] {
        assert!(problem(good, is_source).is_none(), "refused: {good}");
    }
}
