//! The user documentation held to two rules: every chapter of the book (docs/book) is compiled
//! (its Rust blocks are doctests through `mod book` in src/lib.rs) and listed in its
//! SUMMARY.md, and no user-facing page names a path that exists only in the developers'
//! workspace (a reader cannot follow it).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The markdown files under `dir`, recursively, relative to `dir`.
fn markdown_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let p = e.expect("dir entry").path();
            if p.is_dir() {
                todo.push(p);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p.strip_prefix(dir).expect("under dir").to_path_buf());
            }
        }
    }
    out.sort();
    out
}

/// The `.rs` files under `dir`, recursively.
fn rust_under(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let p = e.expect("dir entry").path();
        if p.is_dir() {
            rust_under(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The book's chapters: every markdown file of docs/book/src but SUMMARY.md (mdBook's table of
/// contents, which holds no code).
fn chapters() -> Vec<String> {
    let src = root().join("docs/book/src");
    markdown_under(&src)
        .into_iter()
        .map(|p| p.to_string_lossy().replace('\\', "/"))
        .filter(|p| p != "SUMMARY.md")
        .collect()
}

/// The files `mod book` of src/lib.rs includes as doctest pages (paths relative to src/).
fn included_in_lib() -> BTreeSet<String> {
    let lib = read(&root().join("src/lib.rs"));
    let start = lib
        .find("#[cfg(doctest)]\nmod book {")
        .expect("src/lib.rs has `#[cfg(doctest)] mod book { .. }`");
    let body = &lib[start..];
    let body = &body[..body.find("\n}\n").expect("mod book's closing brace")];
    body.split("include_str!(\"")
        .skip(1)
        .map(|s| s[..s.find('"').expect("closing quote")].to_string())
        .collect()
}

#[test]
fn every_chapter_is_a_doctest() {
    let included = included_in_lib();
    let missing: Vec<String> = chapters()
        .into_iter()
        .filter(|c| !included.contains(&format!("../docs/book/src/{c}")))
        .collect();
    assert!(
        missing.is_empty(),
        "chapters whose Rust blocks no test compiles: {missing:?}; add each to `mod book` in \
         src/lib.rs (`#[doc = include_str!(\"../docs/book/src/NAME.md\")] struct Name;`)"
    );
    // The README's example is compiled the same way.
    assert!(
        included.contains("../README.md"),
        "README.md is not in `mod book` of src/lib.rs: its example would go uncompiled"
    );
    // And nothing listed there is gone (include_str! would fail the build, but say why).
    for f in &included {
        assert!(
            root().join("src").join(f).is_file(),
            "mod book includes {f}, which is not there"
        );
    }
}

#[test]
fn every_chapter_is_in_the_summary() {
    let summary = read(&root().join("docs/book/src/SUMMARY.md"));
    let linked: BTreeSet<String> = summary
        .split("](")
        .skip(1)
        .map(|s| s[..s.find(')').expect("link's closing parenthesis")].to_string())
        .collect();
    let chapters: BTreeSet<String> = chapters().into_iter().collect();
    let unlisted: Vec<&String> = chapters.difference(&linked).collect();
    let dangling: Vec<&String> = linked.difference(&chapters).collect();
    assert!(
        unlisted.is_empty() && dangling.is_empty(),
        "docs/book/src/SUMMARY.md: chapters not listed {unlisted:?}, links to no chapter {dangling:?}"
    );
}

/// Paths that exist only in the developers' workspace: the shared tools and design notes beside
/// the repository, the machines' home and work directories, the GPU bundling scripts.
const PRIVATE: &[&str] = &[
    "../shared",
    "shared/tools",
    "shared/DESIGN",
    "DESIGN.md",
    "/work/",
    "/root/",
    "gpu-bundle",
    "warp-bundle",
];

/// Where `text` names a private path: (line number, pattern, line).
fn private_paths(text: &str) -> Vec<(usize, &'static str, String)> {
    let mut hits = Vec::new();
    for (n, line) in text.lines().enumerate() {
        for p in PRIVATE {
            if line.contains(p) {
                hits.push((n + 1, *p, line.trim().to_string()));
            }
        }
    }
    hits
}

#[test]
fn private_paths_are_found() {
    // The check itself: a line naming the shared tools is caught, a plain one is not.
    assert_eq!(
        private_paths("ok\nReproduce: `../shared/tools/gpu-bundle --benches gpu`\n")
            .iter()
            .map(|h| h.0)
            .collect::<BTreeSet<_>>(),
        BTreeSet::from([2])
    );
    assert!(private_paths("cargo bench --bench gpu\nsee ARCHITECTURE.md").is_empty());
}

#[test]
fn user_documentation_names_no_private_path() {
    let root = root();
    // The pages a user reads: the README, the book, ARCHITECTURE.md (rendered as rustdoc by
    // src/docs.rs), and the rustdoc of every library crate (all its source: `///` and `//!`
    // lines, and the strings a `#[doc]` may hold, are read alike).
    let mut files = vec![root.join("README.md"), root.join("ARCHITECTURE.md")];
    let book = root.join("docs/book");
    files.push(book.join("book.toml"));
    files.extend(
        markdown_under(&book.join("src"))
            .into_iter()
            .map(|p| book.join("src").join(p)),
    );
    let mut rust = Vec::new();
    for dir in [
        "src",
        "warp-core/src",
        "warp-macros/src",
        "warp-runtime/src",
        "warp-cuda/src",
        "warp-report/src",
    ] {
        rust_under(&root.join(dir), &mut rust);
    }
    rust.sort();
    files.extend(rust);
    let mut found = Vec::new();
    for f in &files {
        for (line, pattern, text) in private_paths(&read(f)) {
            let rel = f.strip_prefix(&root).unwrap_or(f).display().to_string();
            found.push(format!("{rel}:{line}: `{pattern}` in: {text}"));
        }
    }
    assert!(
        found.is_empty(),
        "user documentation names paths that exist only in the developers' workspace:\n{}",
        found.join("\n")
    );
}
