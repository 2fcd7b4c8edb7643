//! House rules every crate of the workspace follows, checked on the source
//! tree (as rust-analyzer's tidy tests do): each crate root opens with a `//!`
//! crate doc, and each dependency is declared through the root's
//! `[workspace.dependencies]` (`dep.workspace = true`), so every version is
//! set once. Also the architecture's boundaries: the wire and the master's
//! core build without an async runtime, QUIC, TLS or a web server.

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

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Whether a crate root's first non-blank line is a `//!` doc comment.
fn has_crate_doc(source: &str) -> bool {
    source
        .lines()
        .find(|line| !line.trim().is_empty())
        .is_some_and(|line| line.starts_with("//!"))
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

#[test]
fn every_crate_root_has_a_crate_doc() {
    let mut missing = Vec::new();
    for dir in crate_dirs() {
        for root in ["src/lib.rs", "src/main.rs"] {
            let path = dir.join(root);
            if path.exists() && !has_crate_doc(&read(&path)) {
                missing.push(path.display().to_string());
            }
        }
    }
    assert!(
        missing.is_empty(),
        "crate roots without a `//!` crate doc:\n{}",
        missing.join("\n")
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

/// The third-party crates a workspace crate builds on, through the
/// workspace crates it depends on as well (normal dependencies only: what
/// a build of the crate links).
fn external_dependencies(crate_dir: &Path) -> BTreeSet<String> {
    let (root, manifest) = workspace();
    let shared = manifest["workspace"]["dependencies"]
        .as_table()
        .expect("workspace.dependencies is a table");
    let path_of = |name: &str| {
        let spec = shared.get(name)?.as_table()?;
        Some(root.join(spec.get("path")?.as_str()?))
    };
    let (mut seen, mut external, mut todo) =
        (BTreeSet::new(), BTreeSet::new(), vec![crate_dir.to_owned()]);
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
                Some(path) => todo.push(path),
                None => {
                    external.insert(name.clone());
                }
            }
        }
    }
    external
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

/// The checks themselves catch what they are for.
#[test]
fn the_checks_catch_violations() {
    assert!(has_crate_doc("\n//! A crate.\n\nuse std::fs;\n"));
    assert!(!has_crate_doc("/// An item doc.\npub fn f() {}\n"));
    assert!(!has_crate_doc("use std::fs;\n//! Too late.\n"));
    assert!(!has_crate_doc(""));
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
}
