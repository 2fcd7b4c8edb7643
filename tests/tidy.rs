//! House rules every crate of the workspace follows, checked on the source
//! tree (as rust-analyzer's tidy tests do): each crate root and each module
//! opens with a `//!` doc; each dependency is declared through the root's
//! `[workspace.dependencies]` (`dep.workspace = true`), so every version is
//! set once; no test passes without testing (no `#[ignore]`, and a test
//! that cannot run fails, except behind a named opt-out that CI never sets).
//! Also the architecture's boundaries: the wire and the master's
//! core build without an async runtime, QUIC, TLS or a web server. Sources,
//! docs and help texts describe the code, not its history (no tracker
//! numbers, numbered work periods or "wave"), and no module outside the
//! tests is over [`MAX_MODULE_LINES`] lines.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The workspace root and its manifest.
fn workspace() -> (PathBuf, toml::Table) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let manifest = read(&root.join("Cargo.toml"))
        .parse()
        .expect("root Cargo.toml");
    (root, manifest)
}

/// The workspace root and its member crates' directories (the root package included).
fn crate_dirs() -> Vec<PathBuf> {
    let (root, manifest) = workspace();
    let members = manifest["workspace"]["members"]
        .as_array()
        .expect("workspace.members is a list");
    let mut dirs = vec![root.clone()];
    dirs.extend(
        members
            .iter()
            .map(|m| root.join(m.as_str().expect("member path"))),
    );
    dirs
}

/// The directories of a crate that hold Rust modules (its own, not those of
/// crates nested below it).
const SOURCE_DIRS: [&str; 4] = ["src", "tests", "examples", "benches"];

/// Every `.rs` file of every member crate and of the fuzz targets' own
/// workspace, sorted.
fn rust_files() -> Vec<PathBuf> {
    fn walk(dir: &Path, files: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return; // a crate without this directory
        };
        for entry in entries {
            let path = entry.expect("a readable directory entry").path();
            if path.is_dir() {
                walk(&path, files);
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }
    let mut files = Vec::new();
    let fuzz = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    for dir in crate_dirs().into_iter().chain([fuzz]) {
        for sub in SOURCE_DIRS {
            walk(&dir.join(sub), &mut files);
        }
    }
    files.sort();
    files
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Whether a module's first line that is neither blank nor an inner
/// attribute (`#![...]`) is a `//!` doc comment.
fn has_module_doc(source: &str) -> bool {
    source
        .lines()
        .map(str::trim_start)
        .find(|line| !line.is_empty() && !line.starts_with("#!["))
        .is_some_and(|line| line.starts_with("//!"))
}

/// What in a source file lets a test pass without testing: an `#[ignore]`
/// attribute, or a `SKIPPED` message outside a file that fails under CI and
/// names its opt-out (`VTFARM_ALLOW_NO_...`). Each finding as `line: text`.
fn passes_on_a_skip(source: &str) -> Vec<String> {
    let gated = source.contains("std::env::var(\"CI\")") && source.contains("\"VTFARM_ALLOW_NO_");
    source
        .lines()
        .enumerate()
        .filter(|(_, line)| {
            let code = line.trim_start();
            let ignored = code.starts_with("#[ignore");
            let skipped = !code.starts_with("//") && line.contains("SKIPPED") && !gated;
            ignored || skipped
        })
        .map(|(i, line)| format!("{}: {}", i + 1, line.trim()))
        .collect()
}

/// The dependencies of a member's manifest not declared as `workspace = true`,
/// as `section: name`.
fn dependencies_outside_the_workspace_table(manifest: &str) -> Vec<String> {
    let manifest: toml::Table = manifest.parse().expect("manifest is TOML");
    let mut sections: Vec<(String, &toml::Table)> = Vec::new();
    for kind in ["dependencies", "dev-dependencies", "build-dependencies"] {
        if let Some(table) = manifest.get(kind).and_then(|t| t.as_table()) {
            sections.push((kind.to_owned(), table));
        }
        let targets = manifest.get("target").and_then(|t| t.as_table());
        for (target, spec) in targets.into_iter().flatten() {
            if let Some(table) = spec.get(kind).and_then(|t| t.as_table()) {
                sections.push((format!("target.{target}.{kind}"), table));
            }
        }
    }
    let mut outside = Vec::new();
    for (section, table) in sections {
        for (name, spec) in table {
            let from_workspace = spec
                .get("workspace")
                .and_then(|w| w.as_bool())
                .unwrap_or(false);
            if !from_workspace {
                outside.push(format!("{section}: {name}"));
            }
        }
    }
    outside
}

/// The longest a module may be (tests aside): a longer one mixes concerns
/// that a reader has to hold apart.
const MAX_MODULE_LINES: usize = 1500;

/// A module over [`MAX_MODULE_LINES`] lines outside the tests (a `tests/`
/// directory or a `tests.rs` module), as `path: N lines`.
fn oversized_module(path: &Path, source: &str) -> Option<String> {
    let in_tests = path.components().any(|c| c.as_os_str() == "tests")
        || path.file_name().is_some_and(|n| n == "tests.rs");
    let lines = source.lines().count();
    (!in_tests && lines > MAX_MODULE_LINES).then(|| format!("{}: {lines} lines", path.display()))
}

/// Words of a development log rather than a description: a tracker number
/// ("issue 13", "issues 26 and 27"), a numbered work period ("session 14"),
/// the tracker as a source ("the issue compares"), or "wave". Each finding
/// as `line: text`.
fn development_log_words(text: &str) -> Vec<String> {
    let numbered = [
        "issue", "issues", "session", "sessions", "sprint", "sprints",
    ];
    let mut found = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let lower = line.to_lowercase();
        let words: Vec<&str> = (lower.split(|c: char| !c.is_alphanumeric()))
            .filter(|w| !w.is_empty())
            .collect();
        let logged = words.iter().enumerate().any(|(k, word)| {
            let next = words.get(k + 1).copied().unwrap_or("");
            (numbered.contains(word)
                && next.chars().all(|c| c.is_ascii_digit())
                && !next.is_empty())
                || (["the", "this", "last", "next"].contains(word) && next == "issue")
                || ["wave", "waves"].contains(word)
        });
        if logged {
            found.push(format!("{}: {}", i + 1, line.trim()));
        }
    }
    found
}

/// Every text file of the repository a reader meets besides the Rust
/// sources: docs, scripts, configurations, the dashboard's pages, sorted.
fn text_files() -> Vec<PathBuf> {
    // `vendor`: third-party code kept as its authors wrote it.
    const SKIPPED_DIRS: [&str; 5] = ["target", ".git", "node_modules", "shared", "vendor"];
    const TEXT: [&str; 11] = [
        "md", "sh", "toml", "yml", "yaml", "html", "js", "css", "txt", "py", "json",
    ];
    fn walk(dir: &Path, files: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for entry in entries {
            let path = entry.expect("a readable directory entry").path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if path.is_dir() {
                if !SKIPPED_DIRS.contains(&name) {
                    walk(&path, files);
                }
            } else if name == "Dockerfile"
                || path
                    .extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| TEXT.contains(&e))
            {
                files.push(path);
            }
        }
    }
    let mut files = Vec::new();
    walk(Path::new(env!("CARGO_MANIFEST_DIR")), &mut files);
    files.retain(|p| p.file_name().is_none_or(|n| n != "Cargo.lock"));
    files.sort();
    files
}

#[test]
fn every_module_has_a_module_doc() {
    let missing: Vec<String> = rust_files()
        .into_iter()
        .filter(|path| !has_module_doc(&read(path)))
        .map(|path| path.display().to_string())
        .collect();
    assert!(
        missing.is_empty(),
        "modules without a `//!` doc saying what they are for:\n{}",
        missing.join("\n")
    );
}

#[test]
fn no_test_passes_on_a_skip() {
    // This file names what it looks for.
    let this_file = Path::new(env!("CARGO_MANIFEST_DIR")).join(file!());
    let mut found = Vec::new();
    for path in rust_files().into_iter().filter(|p| *p != this_file) {
        for finding in passes_on_a_skip(&read(&path)) {
            found.push(format!("{}:{finding}", path.display()));
        }
    }
    assert!(
        found.is_empty(),
        "tests that pass without testing (a test that cannot run must fail; an opt-out \
         needs a VTFARM_ALLOW_NO_* variable and must fail under CI):\n{}",
        found.join("\n")
    );
}

#[test]
fn every_dependency_comes_from_the_workspace_table() {
    let mut outside = Vec::new();
    for dir in crate_dirs() {
        let path = dir.join("Cargo.toml");
        for dependency in dependencies_outside_the_workspace_table(&read(&path)) {
            outside.push(format!("{}: {dependency}", path.display()));
        }
    }
    assert!(
        outside.is_empty(),
        "dependencies not declared with `workspace = true` (put the version in the root's \
         [workspace.dependencies]):\n{}",
        outside.join("\n")
    );
}

/// The crates a workspace crate builds on, through the workspace crates it
/// depends on as well (normal dependencies only: what a build of the crate
/// links): the workspace crates by package name, and the third-party ones.
fn dependency_closure(crate_dir: &Path) -> (BTreeSet<String>, BTreeSet<String>) {
    let (root, manifest) = workspace();
    let shared = manifest["workspace"]["dependencies"]
        .as_table()
        .expect("workspace.dependencies is a table");
    let path_of = |name: &str| {
        let spec = shared.get(name)?.as_table()?;
        Some(root.join(spec.get("path")?.as_str()?))
    };
    let (mut seen, mut workspace_crates, mut external, mut todo) = (
        BTreeSet::new(),
        BTreeSet::new(),
        BTreeSet::new(),
        vec![crate_dir.to_owned()],
    );
    while let Some(dir) = todo.pop() {
        if !seen.insert(dir.clone()) {
            continue;
        }
        let manifest: toml::Table = read(&dir.join("Cargo.toml"))
            .parse()
            .expect("manifest is TOML");
        let Some(dependencies) = manifest.get("dependencies").and_then(|d| d.as_table()) else {
            continue;
        };
        for name in dependencies.keys() {
            match path_of(name) {
                Some(path) => {
                    workspace_crates.insert(name.clone());
                    todo.push(path);
                }
                None => {
                    external.insert(name.clone());
                }
            }
        }
    }
    (workspace_crates, external)
}

/// The third-party crates a workspace crate builds on (see [`dependency_closure`]).
fn external_dependencies(crate_dir: &Path) -> BTreeSet<String> {
    dependency_closure(crate_dir).1
}

/// Architecture invariants: the wire knows nothing of QUIC, and the
/// master's core does no I/O, so neither links a runtime, QUIC, TLS or a
/// web server (`fuzz/` builds the wire alone).
#[test]
fn the_wire_and_the_master_core_build_without_the_transport() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let forbidden = ["tokio", "quinn", "rustls", "rcgen", "axum"];
    for dir in ["proto", "crates/master-core"] {
        let external = external_dependencies(&root.join(dir));
        let found: Vec<_> = forbidden
            .iter()
            .filter(|f| external.contains(**f))
            .collect();
        assert!(found.is_empty(), "{dir} builds on {found:?}");
    }
    // The check sees through workspace crates: the transport has them all.
    let transport = external_dependencies(&root.join("transport"));
    assert!(
        transport.contains("quinn") && transport.contains("tokio"),
        "{transport:?}"
    );
}

/// Architecture invariants: the master server runs no worker and holds no
/// client (the embedded farm, `vtfarm-embedded`, joins master and workers;
/// the submitter is `vtfarm-submit`), and the submitter knows the wire and
/// the transport, nothing of the master's or a worker's insides.
#[test]
fn the_master_runs_no_worker_and_the_submitter_knows_only_the_wire() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let (master, _) = dependency_closure(&root.join("master"));
    let found: Vec<_> = ["vtfarm-worker", "vtfarm-submit", "vtfarm-embedded"]
        .into_iter()
        .filter(|c| master.contains(*c))
        .collect();
    assert!(found.is_empty(), "the master builds on {found:?}");
    let (submit, _) = dependency_closure(&root.join("crates/submit"));
    let found: Vec<_> = ["vtfarm-master", "vtfarm-master-core", "vtfarm-worker"]
        .into_iter()
        .filter(|c| submit.contains(*c))
        .collect();
    assert!(found.is_empty(), "the submitter builds on {found:?}");
    // The check sees through workspace crates: the embedded farm has both ends.
    let (embedded, _) = dependency_closure(&root.join("crates/embedded"));
    assert!(
        [
            "vtfarm-master",
            "vtfarm-worker",
            "vtfarm-master-core",
            "vtfarm-proto"
        ]
        .iter()
        .all(|c| embedded.contains(*c)),
        "{embedded:?}"
    );
}

#[test]
fn no_module_outside_the_tests_is_over_the_limit() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let oversized: Vec<String> = rust_files()
        .into_iter()
        .filter_map(|path| {
            let relative = path.strip_prefix(root).unwrap_or(&path).to_owned();
            oversized_module(&relative, &read(&path))
        })
        .collect();
    assert!(
        oversized.is_empty(),
        "modules over {MAX_MODULE_LINES} lines (split them along their concerns):\n{}",
        oversized.join("\n")
    );
}

#[test]
fn sources_docs_and_help_texts_describe_rather_than_narrate() {
    // This file names what it looks for.
    let this_file = Path::new(env!("CARGO_MANIFEST_DIR")).join(file!());
    let mut found = Vec::new();
    for path in (rust_files().into_iter().chain(text_files())).filter(|p| *p != this_file) {
        for finding in development_log_words(&read(&path)) {
            found.push(format!("{}:{finding}", path.display()));
        }
    }
    assert!(
        found.is_empty(),
        "development-log words (say what the code does and why; its history is in git):\n{}",
        found.join("\n")
    );
}

/// The checks themselves catch what they are for.
#[test]
fn the_checks_catch_violations() {
    assert!(has_module_doc("\n//! A crate.\n\nuse std::fs;\n"));
    assert!(!has_module_doc("/// An item doc.\npub fn f() {}\n"));
    assert!(!has_module_doc("use std::fs;\n//! Too late.\n"));
    assert!(!has_module_doc(""));
    assert!(has_module_doc("#![allow(dead_code)]\n//! A module.\n"));
    assert!(!has_module_doc("#[cfg(test)]\nmod tests;\n"));
    let ignored = "#[test]\n#[ignore]\nfn slow() {}\n";
    assert_eq!(passes_on_a_skip(ignored), ["2: #[ignore]"]);
    let silent = "fn t() {\n    if missing() {\n        eprintln!(\"SKIPPED: no tool\");\n        return;\n    }\n}\n";
    assert_eq!(
        passes_on_a_skip(silent),
        ["3: eprintln!(\"SKIPPED: no tool\");"]
    );
    let gated = format!(
        "const A: &str = \"VTFARM_ALLOW_NO_TOOL\";\nfn g() {{ assert!(std::env::var(\"CI\").is_err()); }}\n{silent}"
    );
    assert!(passes_on_a_skip(&gated).is_empty());
    assert!(passes_on_a_skip("// SKIPPED is said in a comment only\n").is_empty());
    let manifest = r#"
        [package]
        name = "x"
        [dependencies]
        good.workspace = true
        also-good = { workspace = true, optional = true }
        inline = "1"
        table = { version = "0.3", features = ["a"] }
        [dev-dependencies]
        not-shared = { path = "../y" }
        [target.'cfg(unix)'.dependencies]
        unix-only = "2"
    "#;
    assert_eq!(
        dependencies_outside_the_workspace_table(manifest),
        [
            "dependencies: inline",
            "dependencies: table",
            "target.cfg(unix).dependencies: unix-only",
            "dev-dependencies: not-shared",
        ]
    );
    let long = "//! A module.\n".to_owned() + &"fn f() {}\n".repeat(MAX_MODULE_LINES);
    assert_eq!(
        oversized_module(Path::new("crates/x/src/big.rs"), &long).as_deref(),
        Some("crates/x/src/big.rs: 1501 lines")
    );
    assert_eq!(
        oversized_module(Path::new("crates/x/tests/big.rs"), &long),
        None
    );
    assert_eq!(
        oversized_module(Path::new("crates/x/src/tests.rs"), &long),
        None
    );
    let fits = "fn f() {}\n".repeat(MAX_MODULE_LINES);
    assert_eq!(oversized_module(Path::new("src/lib.rs"), &fits), None);
    let log = "// Overflowed in obvhs (issue 13).\n\
               /// Fixed in Session 14's main.\n\
               /// (default: 1, the figure the issue compares)\n\
               // Measured in the last wave.\n\
               // Issues 26 and 27: the fixed costs.\n\
               // A `WorkerSession` per connection; a wavefront; an issue of the queue.\n";
    assert_eq!(
        development_log_words(log),
        [
            "1: // Overflowed in obvhs (issue 13).",
            "2: /// Fixed in Session 14's main.",
            "3: /// (default: 1, the figure the issue compares)",
            "4: // Measured in the last wave.",
            "5: // Issues 26 and 27: the fixed costs.",
        ]
    );
}
