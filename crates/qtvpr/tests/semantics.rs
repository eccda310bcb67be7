//! `docs/semantics.md`'s table of where each section lives, held to the tree: every
//! section of the document is a row, the module a row names exists and its module
//! documentation opens with "semantics §N:" (its home), no other module of the core
//! claims that section so, and every "semantics §N" cited in the repository's code and
//! documents names a section that exists.

use std::fs;
use std::path::{Path, PathBuf};

/// The repository's root.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn semantics() -> String {
    fs::read_to_string(root().join("docs/semantics.md")).unwrap()
}

/// The numbers of the document's sections: its `## N. Title` headings.
fn sections(text: &str) -> Vec<u32> {
    text.lines()
        .filter_map(|l| l.strip_prefix("## ")?.split_once(". ")?.0.parse().ok())
        .collect()
}

/// The rows of the table between the `sections` markers: (§, the file of its home,
/// relative to `crates/qtvpr/src/`).
fn table(text: &str) -> Vec<(u32, String)> {
    let rows = text.split("<!-- sections:start -->").nth(1).unwrap();
    let rows = rows.split("<!-- sections:end -->").next().unwrap();
    rows.lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            let section = cells.get(1)?.parse().ok()?;
            // The first code span of the third cell.
            let file = cells.get(3)?.split('`').nth(1)?;
            Some((section, file.to_string()))
        })
        .collect()
}

/// Every file under `dir` whose name ends with one of `extensions`, recursively.
fn files(dir: &Path, extensions: &[&str], out: &mut Vec<PathBuf>) {
    for entry in fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() {
            if !name.starts_with('.') && name != "target" {
                files(&path, extensions, out);
            }
        } else if extensions.iter().any(|e| name.ends_with(e)) {
            out.push(path);
        }
    }
}

/// The section a module claims as its home: `N` of a first line `//! semantics §N: ...`.
fn home(path: &Path) -> Option<u32> {
    let first = fs::read_to_string(path).ok()?.lines().next()?.to_string();
    first.strip_prefix("//! semantics §")?.split_once(':')?.0.parse().ok()
}

#[test]
fn every_section_lives_in_the_module_the_table_names() {
    let text = semantics();
    let (sections, table) = (sections(&text), table(&text));
    assert_eq!(
        sections,
        (1..=sections.len() as u32).collect::<Vec<_>>(),
        "numbered in order"
    );
    assert_eq!(
        table.iter().map(|r| r.0).collect::<Vec<_>>(),
        sections,
        "one row per section, in order"
    );
    let src = root().join("crates/qtvpr/src");
    for (section, file) in &table {
        let path = src.join(file);
        assert!(path.is_file(), "§{section}: {file} does not exist");
        assert_eq!(
            home(&path),
            Some(*section),
            "§{section}: {file} does not open with `//! semantics §{section}:`"
        );
    }
    // No other module claims a section as its home.
    let mut all = Vec::new();
    files(&src, &[".rs"], &mut all);
    for path in all {
        if let Some(section) = home(&path) {
            let file = path.strip_prefix(&src).unwrap().to_string_lossy().replace('\\', "/");
            assert!(
                table.contains(&(section, file.clone())),
                "{file} claims semantics §{section}, whose home the table says is elsewhere"
            );
        }
    }
}

#[test]
fn every_section_cited_exists() {
    let sections = sections(&semantics());
    let mut all = Vec::new();
    for dir in [
        "crates", "py", "docs", "tests", "benches", "scripts", "include", "ros", "examples",
    ] {
        files(
            &root().join(dir),
            &[".rs", ".py", ".pyi", ".md", ".h", ".c", ".cpp", ".msg"],
            &mut all,
        );
    }
    all.extend(["README.md", "ARCHITECTURE.md", "CONTRIBUTING.md"].map(|f| root().join(f)));
    let mut cited = 0;
    for path in all {
        let text = fs::read_to_string(&path).unwrap_or_default();
        for at in text.match_indices("semantics §").map(|(i, _)| i + "semantics §".len()) {
            // "semantics §N" with a letter is the notation, not a citation.
            let digits: String = text[at..].chars().take_while(char::is_ascii_digit).collect();
            let Ok(n) = digits.parse::<u32>() else {
                continue;
            };
            assert!(
                sections.contains(&n),
                "{} cites semantics §{n}, which does not exist",
                path.display()
            );
            cited += 1;
        }
    }
    assert!(cited > 100, "only {cited} citations found: is the walk right?");
}
