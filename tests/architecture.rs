//! The folder layout is the architecture: data flows one way through the crate's top-level
//! modules, and this test holds the code to it by reading every `crate::` path in `src/`.
//!
//! ```text
//! values, progress → noise → io → scene → accel → field → backend → render → dist → cli / viewer / study / scene_file
//! ```
//!
//! A module may use the modules before it in the flow, never one after it; only the top tier
//! (the command line, and the scene file that composes everything) may use its siblings. A new
//! top-level module fails the test until it is given its place here.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Each top-level module's place in the flow; a module may use only lower places (and, at the
/// top, its own).
const FLOW: &[(&str, u32)] = &[
    ("values", 0),
    ("progress", 0),
    ("noise", 1),
    ("io", 2),
    ("scene", 3),
    ("accel", 4),
    ("field", 5),
    ("backend", 6),
    ("render", 7),
    ("dist", 8),
    ("cli", 9),
    ("scene_file", 9),
    ("viewer", 9),
    ("study", 9),
];
const TOP: u32 = 9;

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The top-level module a file belongs to (`None` for the crate roots).
fn module_of(src: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(src).unwrap();
    let first = rel
        .components()
        .next()?
        .as_os_str()
        .to_string_lossy()
        .into_owned();
    let name = first.strip_suffix(".rs").unwrap_or(&first).to_owned();
    (name != "lib" && name != "main").then_some(name)
}

/// The top-level modules named by `crate::<module>` paths in `code`, outside comments and
/// string literals (doc links in comments do not make a dependency).
fn crate_paths(code: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for line in code.lines() {
        let code = line.split("//").next().unwrap_or("");
        // Drop string literals (paths in messages are not uses).
        let mut stripped = String::new();
        let mut in_string = false;
        let mut escaped = false;
        for c in code.chars() {
            match (in_string, escaped, c) {
                (true, false, '\\') => escaped = true,
                (true, false, '"') => in_string = false,
                (true, _, _) => escaped = false,
                (false, _, '"') => in_string = true,
                (false, _, c) => stripped.push(c),
            }
        }
        let mut rest = stripped.as_str();
        while let Some(i) = rest.find("crate::") {
            let preceded_by_ident = rest[..i]
                .chars()
                .next_back()
                .is_some_and(|c| c.is_alphanumeric() || c == '_');
            let after = &rest[i + "crate::".len()..];
            let name: String = after
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !preceded_by_ident && !name.is_empty() {
                out.insert(name);
            }
            rest = after;
        }
    }
    out
}

#[test]
fn modules_use_only_what_comes_before_them_in_the_data_flow() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let place: BTreeMap<&str, u32> = FLOW.iter().copied().collect();
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut problems = Vec::new();
    let mut edges: BTreeSet<(String, String)> = BTreeSet::new();
    for file in &files {
        let Some(module) = module_of(&src, file) else {
            continue;
        };
        let Some(&own) = place.get(module.as_str()) else {
            problems.push(format!(
                "{}: top-level module '{module}' has no place in the flow (tests/architecture.rs)",
                file.display()
            ));
            continue;
        };
        let code = std::fs::read_to_string(file).unwrap();
        for used in crate_paths(&code) {
            if used == module {
                continue;
            }
            let Some(&theirs) = place.get(used.as_str()) else {
                problems.push(format!(
                    "{}: uses unknown module crate::{used}",
                    file.display()
                ));
                continue;
            };
            edges.insert((module.clone(), used.clone()));
            let allowed = theirs < own || (theirs == TOP && own == TOP);
            if !allowed {
                problems.push(format!(
                    "{}: '{module}' uses crate::{used}, which comes after it (or beside it) in the flow",
                    file.display()
                ));
            }
        }
    }
    // No cycle among the modules, the top tier included.
    for (a, b) in &edges {
        if edges.contains(&(b.clone(), a.clone())) && a < b {
            problems.push(format!("'{a}' and '{b}' use each other"));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn the_reader_sees_paths_and_ignores_comments_and_strings() {
    let code = "use crate::values::Bounds;\n// crate::render::x in a comment\nlet s = \"crate::cli\"; crate::io::read(x); notcrate::scene::y;\n";
    let found: Vec<String> = crate_paths(code).into_iter().collect();
    assert_eq!(found, ["io", "values"]);
}
