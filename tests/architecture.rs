//! The folder layout is the architecture: data flows one way through the crate's top-level
//! modules, and this test holds the code to it by reading every `crate::` path in `src/`.
//!
//! ```text
//! values, progress → noise → io → scene → accel → field → backend → render → dist → cli / viewer / study / scene_file
//! ```
//!
//! A module may use the modules before it in the flow, never one after it; only the top tier
//! (the command line, and the scene file that composes everything) may use its siblings. A new
//! top-level module fails the test until it is given its place here. Inside a folder, the
//! modules use each other without loops, so each can be read before the ones that use it.

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

/// A file's module path: `src/render/session.rs` is `render::session`, `src/io/vtk/mod.rs` is
/// `io::vtk` (empty for the crate roots).
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut path: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if path
        .last()
        .is_some_and(|l| l == "mod" || l == "lib" || l == "main")
    {
        path.pop();
    }
    path
}

/// The code of `text` without comments and string literals.
fn code_only(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let code = line.split("//").next().unwrap_or("");
        let (mut in_string, mut escaped) = (false, false);
        for c in code.chars() {
            match (in_string, escaped, c) {
                (true, false, '\\') => escaped = true,
                (true, false, '"') => in_string = false,
                (true, _, _) => escaped = false,
                (false, _, '"') => in_string = true,
                (false, _, c) => out.push(c),
            }
        }
        out.push('\n');
    }
    out
}

/// The paths `code` names from `crate::` or `super::` (each brace group's entries apart),
/// as absolute paths for a file whose module is `own` (a `mod.rs`'s own is its folder).
fn used_paths(code: &str, own: &[String]) -> Vec<Vec<String>> {
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect()
    };
    let mut out = Vec::new();
    let bytes = code.as_bytes();
    let mut i = 0;
    while i < code.len() {
        // Bytes, not str: `i` steps through non-ASCII text (a string's α) a byte at a time.
        let starts = |word: &str| bytes[i..].starts_with(word.as_bytes());
        let preceded = i > 0
            && (bytes[i - 1].is_ascii_alphanumeric()
                || bytes[i - 1] == b'_'
                || bytes[i - 1] == b':');
        if preceded || !(starts("crate::") || starts("super::")) {
            i += 1;
            continue;
        }
        let mut base: Vec<String> = Vec::new();
        let mut rest = &code[i..];
        if rest.starts_with("crate::") {
            rest = &rest["crate::".len()..];
        } else {
            base = own.to_vec();
            while rest.starts_with("super::") {
                base.pop();
                rest = &rest["super::".len()..];
            }
        }
        // One path, or a brace group of entries (their first segments).
        let mut path = base.clone();
        loop {
            if let Some(group) = rest.strip_prefix('{') {
                let end = group.find('}').unwrap_or(group.len());
                for entry in group[..end].split(',') {
                    let name = ident(entry.trim());
                    if !name.is_empty() && name != "self" {
                        let mut p = path.clone();
                        p.push(name);
                        out.push(p);
                    }
                }
                break;
            }
            let name = ident(rest);
            if name.is_empty() {
                break;
            }
            rest = &rest[name.len()..];
            path.push(name);
            match rest.strip_prefix("::") {
                Some(r) => rest = r,
                None => break,
            }
        }
        out.push(path);
        i += 1;
    }
    out
}

#[test]
fn the_modules_of_a_folder_use_each_other_without_loops() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let modules: BTreeSet<Vec<String>> = files.iter().map(|f| module_path(&src, f)).collect();
    // Edges between siblings: a file's use of a module beside its own (or beside one of its
    // ancestors) counts for the sibling it lies in.
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    for file in &files {
        let own = module_path(&src, file);
        let code = code_only(&std::fs::read_to_string(file).unwrap());
        for used in used_paths(&code, &own) {
            // The longest prefix of the path that is a module.
            let Some(target) = (1..=used.len())
                .rev()
                .map(|n| used[..n].to_vec())
                .find(|p| modules.contains(p))
            else {
                continue;
            };
            let common = own.iter().zip(&target).take_while(|(a, b)| a == b).count();
            if common >= own.len() || common >= target.len() {
                continue; // itself, an ancestor or a descendant
            }
            edges
                .entry(own[..=common].to_vec())
                .or_default()
                .insert(target[..=common].to_vec());
        }
    }
    // A loop: a path back to where it started (depth-first from each module).
    let mut loops = BTreeSet::new();
    for start in edges.keys() {
        let mut stack = vec![(start.clone(), vec![start.clone()])];
        let mut seen = BTreeSet::new();
        while let Some((at, trail)) = stack.pop() {
            for next in edges.get(&at).into_iter().flatten() {
                if next == start {
                    let mut names: Vec<String> = trail.iter().map(|m| m.join("::")).collect();
                    let first = names.iter().min().unwrap().clone();
                    let k = names.iter().position(|n| *n == first).unwrap();
                    names.rotate_left(k);
                    loops.insert(names.join(" -> "));
                } else if seen.insert(next.clone()) {
                    let mut t = trail.clone();
                    t.push(next.clone());
                    stack.push((next.clone(), t));
                }
            }
        }
    }
    assert!(
        loops.is_empty(),
        "modules that use each other in a loop (each loops back to its first):\n{}",
        loops.into_iter().collect::<Vec<_>>().join("\n")
    );
}

#[test]
fn the_loop_reader_resolves_super_crate_and_brace_groups() {
    let own: Vec<String> = ["render", "session"].map(String::from).to_vec();
    let code = code_only(
        "use super::{auto::AutoValues, cycles};\nuse crate::io::vtk::read; // super::x\nlet s = \"super::y\"; super::super::cli::run();\n",
    );
    let found: Vec<String> = used_paths(&code, &own)
        .iter()
        .map(|p| p.join("::"))
        .collect();
    assert!(found.contains(&"render::auto".to_owned()), "{found:?}");
    assert!(found.contains(&"render::cycles".to_owned()), "{found:?}");
    assert!(found.contains(&"io::vtk::read".to_owned()), "{found:?}");
    assert!(found.contains(&"cli::run".to_owned()), "{found:?}");
    assert!(
        !found.iter().any(|p| p.ends_with("x") || p.ends_with("y")),
        "{found:?}"
    );
}

/// The integration tests are one binary (`tests/suite.rs`) and Cargo no longer finds them by
/// file: a test file missing from the suite's `mod` list would never run, and pass unseen.
#[test]
fn every_test_file_is_in_the_suite() {
    let tests = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    let suite = std::fs::read_to_string(tests.join("suite.rs")).unwrap();
    let declared: BTreeSet<&str> = suite
        .lines()
        .filter_map(|line| line.strip_prefix("mod ")?.strip_suffix(';'))
        .collect();
    let own_binaries = ["suite", "ash_validation"];
    let cargo = std::fs::read_to_string(tests.join("../Cargo.toml")).unwrap();
    for name in own_binaries {
        assert!(
            cargo.contains(&format!("path = \"tests/{name}.rs\"")),
            "Cargo.toml has no [[test]] for tests/{name}.rs"
        );
    }
    let mut missing = Vec::new();
    for entry in std::fs::read_dir(&tests).unwrap() {
        let path = entry.unwrap().path();
        let name = if path.is_dir() {
            if !path.join("mod.rs").exists() {
                continue; // data
            }
            path.file_name().unwrap().to_string_lossy().into_owned()
        } else if path.extension().is_some_and(|e| e == "rs") {
            path.file_stem().unwrap().to_string_lossy().into_owned()
        } else {
            continue;
        };
        if !declared.contains(name.as_str()) && !own_binaries.contains(&name.as_str()) {
            missing.push(name);
        }
    }
    assert!(
        missing.is_empty(),
        "not in tests/suite.rs (add `mod NAME;` there), so never run: {missing:?}"
    );
}
