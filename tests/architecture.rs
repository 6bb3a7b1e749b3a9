//! ARCHITECTURE.md's invariants that a test can check, checked against the workspace's source
//! text: no import cycles between the files of a crate, warp-runtime's layers, the workspace's
//! crate graph, the size limit of the compiler's files, where warp-core allocates, and the parts
//! of the builtin and host-object recipes that the sources show.
//!
//! Nothing here builds or runs the crates: the sources are read as text by a small Rust lexer
//! and an item-level reader (modules, `use` trees, paths in code, item names), which is all a
//! file-level import graph needs. Paths resolve the way rustc resolves them, through `use`
//! bindings and glob imports to the file that *defines* the name, so a re-export
//! (`pub use child::X` in a `mod.rs`) is no import of its own: the file that uses `X` depends on
//! the file that defines it. Test code (`#[cfg(test)]` items and the files they declare) is left
//! out: a test module importing its parent is no cycle.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

// -------------------------------------------------------------------------------------------
// The workspace
// -------------------------------------------------------------------------------------------

/// The crates whose modules are read: (package name, crate root relative to the workspace).
const CRATES: &[(&str, &str)] = &[
    ("warp-core", "warp-core/src/lib.rs"),
    ("warp-macros", "warp-macros/src/lib.rs"),
    ("warp-runtime", "warp-runtime/src/lib.rs"),
    ("warp-cuda", "warp-cuda/src/lib.rs"),
    ("warp-report", "warp-report/src/lib.rs"),
    ("warp-lang", "src/lib.rs"),
];

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read_rel(rel: &str) -> Option<String> {
    std::fs::read_to_string(workspace().join(rel)).ok()
}

fn read_required(rel: &str) -> String {
    read_rel(rel).unwrap_or_else(|| panic!("cannot read {rel} (relative to the workspace)"))
}

/// Every file under `dir` (relative to the workspace) whose name ends with `ext`, as workspace
/// paths with `/` separators, sorted.
fn files_under(dir: &str, ext: &str) -> Vec<String> {
    fn walk(abs: &Path, rel: &str, ext: &str, out: &mut Vec<String>) {
        let Ok(entries) = std::fs::read_dir(abs) else {
            return;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let rel = format!("{rel}/{name}");
            let path = e.path();
            if path.is_dir() {
                walk(&path, &rel, ext, out);
            } else if name.ends_with(ext) {
                out.push(rel);
            }
        }
    }
    let mut out = Vec::new();
    walk(&workspace().join(dir), dir, ext, &mut out);
    out.sort();
    out
}

fn load_crate(root: &str) -> Crate {
    Crate::load(root, &read_rel)
}

// -------------------------------------------------------------------------------------------
// A Rust lexer: tokens without comments; string and char literals as one token each
// -------------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Ident,
    Punct,
    Lit,
    Lifetime,
}

#[derive(Clone, Debug)]
struct Tok {
    kind: Kind,
    text: String,
    line: usize,
}

impl Tok {
    fn is(&self, s: &str) -> bool {
        self.kind != Kind::Lit && self.text == s
    }
    fn ident(&self) -> bool {
        self.kind == Kind::Ident
    }
    /// The value of a plain string literal (`"wp::foo"` -> `wp::foo`), escapes left as written.
    fn str_value(&self) -> Option<&str> {
        (self.kind == Kind::Lit)
            .then(|| self.text.strip_prefix('"')?.strip_suffix('"'))
            .flatten()
    }
}

fn is_ident_start(c: char) -> bool {
    c == '_' || c.is_alphabetic()
}

fn is_ident_char(c: char) -> bool {
    c == '_' || c.is_alphanumeric()
}

fn lex(src: &str) -> Vec<Tok> {
    let c: Vec<char> = src.chars().collect();
    let n = c.len();
    let at = |i: usize| c.get(i).copied().unwrap_or('\0');
    let mut out = Vec::new();
    let mut line = 1;
    let mut i = 0;
    while i < n {
        let ch = c[i];
        let start = i;
        let start_line = line;
        if ch == '\n' {
            line += 1;
            i += 1;
            continue;
        }
        if ch.is_whitespace() {
            i += 1;
            continue;
        }
        if ch == '/' && at(i + 1) == '/' {
            while i < n && c[i] != '\n' {
                i += 1;
            }
            continue;
        }
        if ch == '/' && at(i + 1) == '*' {
            let mut depth = 0;
            while i < n {
                if c[i] == '/' && at(i + 1) == '*' {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && at(i + 1) == '/' {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if c[i] == '\n' {
                        line += 1;
                    }
                    i += 1;
                }
            }
            continue;
        }
        // Raw strings: r"..", r#".."#, br"..", cr"..".
        let mut j = i;
        if matches!(ch, 'b' | 'c') && at(i + 1) == 'r' {
            j += 1;
        }
        if at(j) == 'r'
            && (at(j + 1) == '"' || (at(j + 1) == '#' && matches!(at(j + 2), '#' | '"')))
        {
            let mut hashes = 0;
            j += 1;
            while at(j) == '#' {
                hashes += 1;
                j += 1;
            }
            j += 1; // the opening quote
            loop {
                if j >= n {
                    break;
                }
                if c[j] == '"' && (0..hashes).all(|h| at(j + 1 + h) == '#') {
                    j += 1 + hashes;
                    break;
                }
                if c[j] == '\n' {
                    line += 1;
                }
                j += 1;
            }
            let text: String = c[start..j.min(n)].iter().collect();
            out.push(Tok {
                kind: Kind::Lit,
                text,
                line: start_line,
            });
            i = j;
            continue;
        }
        // Strings and byte strings: "..", b"..", c"..".
        let q = if matches!(ch, 'b' | 'c') && at(i + 1) == '"' {
            i + 1
        } else {
            i
        };
        if at(q) == '"' {
            let mut j = q + 1;
            while j < n && c[j] != '"' {
                if c[j] == '\\' {
                    j += 1;
                }
                if at(j) == '\n' {
                    line += 1;
                }
                j += 1;
            }
            let text: String = c[q..(j + 1).min(n)].iter().collect();
            out.push(Tok {
                kind: Kind::Lit,
                text,
                line: start_line,
            });
            i = j + 1;
            continue;
        }
        // Chars, byte chars and lifetimes.
        let q = if ch == 'b' && at(i + 1) == '\'' {
            i + 1
        } else {
            i
        };
        if at(q) == '\'' {
            if at(q + 1) == '\\' {
                let mut j = q + 2;
                while j < n && c[j] != '\'' {
                    j += 1;
                }
                out.push(Tok {
                    kind: Kind::Lit,
                    text: "'c'".into(),
                    line,
                });
                i = j + 1;
            } else if at(q + 2) == '\'' {
                out.push(Tok {
                    kind: Kind::Lit,
                    text: "'c'".into(),
                    line,
                });
                i = q + 3;
            } else {
                let mut j = q + 1;
                while j < n && is_ident_char(c[j]) {
                    j += 1;
                }
                let text: String = c[q..j].iter().collect();
                out.push(Tok {
                    kind: Kind::Lifetime,
                    text,
                    line,
                });
                i = j;
            }
            continue;
        }
        // Raw identifiers and identifiers.
        if ch == 'r' && at(i + 1) == '#' && is_ident_start(at(i + 2)) {
            let mut j = i + 2;
            while j < n && is_ident_char(c[j]) {
                j += 1;
            }
            let text: String = c[i + 2..j].iter().collect();
            out.push(Tok {
                kind: Kind::Ident,
                text,
                line,
            });
            i = j;
            continue;
        }
        if is_ident_start(ch) {
            let mut j = i;
            while j < n && is_ident_char(c[j]) {
                j += 1;
            }
            let text: String = c[i..j].iter().collect();
            out.push(Tok {
                kind: Kind::Ident,
                text,
                line,
            });
            i = j;
            continue;
        }
        if ch.is_ascii_digit() {
            let mut j = i;
            // Digits, suffixes, a fraction (`1.5`, not the range `0..n` or a field `t.0`), and
            // an exponent's sign (`1e-3`, not in hex).
            loop {
                let fraction = at(j) == '.' && at(j + 1).is_ascii_digit();
                let exponent = matches!(at(j), '+' | '-')
                    && matches!(at(j - 1), 'e' | 'E')
                    && !c[i..j].contains(&'x');
                if (j < n && is_ident_char(c[j])) || fraction || exponent {
                    j += 1;
                } else {
                    break;
                }
            }
            let text: String = c[i..j].iter().collect();
            out.push(Tok {
                kind: Kind::Lit,
                text,
                line,
            });
            i = j;
            continue;
        }
        if ch == ':' && at(i + 1) == ':' {
            out.push(Tok {
                kind: Kind::Punct,
                text: "::".into(),
                line,
            });
            i += 2;
            continue;
        }
        out.push(Tok {
            kind: Kind::Punct,
            text: ch.to_string(),
            line,
        });
        i += 1;
    }
    out
}

/// The index of the bracket that closes the one at `open` (`(`, `[` or `{`).
fn matching(t: &[Tok], open: usize) -> usize {
    let mut depth = 0usize;
    for (k, tok) in t.iter().enumerate().skip(open) {
        if tok.kind != Kind::Punct {
            continue;
        }
        match tok.text.as_str() {
            "(" | "[" | "{" => depth += 1,
            ")" | "]" | "}" => {
                depth -= 1;
                if depth == 0 {
                    return k;
                }
            }
            _ => {}
        }
    }
    t.len()
}

/// The end (exclusive) of the item starting at `i`: after its `;` or its closing `}` (and a
/// `;` right after it), whichever comes first at the item's own level.
fn item_end(t: &[Tok], i: usize, end: usize) -> usize {
    let mut depth = 0usize;
    let mut k = i;
    while k < end {
        if t[k].kind == Kind::Punct {
            match t[k].text.as_str() {
                "(" | "[" | "{" => depth += 1,
                ")" | "]" => depth = depth.saturating_sub(1),
                "}" => {
                    depth = depth.saturating_sub(1);
                    if depth == 0 {
                        return if k + 1 < end && t[k + 1].is(";") {
                            k + 2
                        } else {
                            k + 1
                        };
                    }
                }
                ";" if depth == 0 => return k + 1,
                _ => {}
            }
        }
        k += 1;
    }
    end
}

/// Whether an attribute's tokens (inside `#[..]`) make its item test-only: `cfg(test)`,
/// `cfg(all(test, ..))`, `test`.
fn is_test_attr(attr: &[Tok]) -> bool {
    match attr.first() {
        Some(a) if a.is("test") => attr.len() == 1,
        Some(a) if a.is("cfg") => {
            attr.iter().any(|t| t.is("test")) && !attr.iter().any(|t| t.is("not") || t.is("any"))
        }
        _ => false,
    }
}

// -------------------------------------------------------------------------------------------
// A crate's modules, the paths they name, and their resolution to files
// -------------------------------------------------------------------------------------------

#[derive(Default, Debug)]
struct Module {
    parent: Option<usize>,
    /// The file the module's text is in (workspace-relative).
    file: String,
    children: BTreeMap<String, usize>,
    /// Names of items defined in the module (fn, struct, enum, trait, type, const, static,
    /// macro_rules, union).
    defs: BTreeSet<String>,
    /// `use` bindings: name -> the paths it stands for (cfg alternatives may give several),
    /// as written in this module.
    bindings: BTreeMap<String, Vec<Vec<String>>>,
    /// Glob imports (`use a::b::*`), as written in this module.
    globs: Vec<Vec<String>>,
}

/// A path a module names: in a `use` or in code. `reexport`: a `pub use` binding, which is an
/// import of its file only if the file's own code names it.
#[derive(Debug)]
struct Reference {
    module: usize,
    segs: Vec<String>,
    line: usize,
    reexport: bool,
}

/// What a path leads to: a module, or an item defined in a module.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Found {
    Module(usize),
    Item(usize),
}

/// A source file as read: its tokens, and the token ranges that are test-only.
struct SourceFile {
    toks: Vec<Tok>,
    /// Token ranges `[a, b)` of `#[cfg(test)]` items (left out of every check).
    test_ranges: Vec<(usize, usize)>,
    /// Identifiers its non-test code names outside `use` items.
    code_idents: BTreeSet<String>,
}

struct Crate {
    modules: Vec<Module>,
    refs: Vec<Reference>,
    files: BTreeMap<String, SourceFile>,
    /// Files declared only by `#[cfg(test)] mod x;`: test code.
    test_files: BTreeSet<String>,
    /// `mod x;` declarations whose file is missing (the reader would miss code).
    missing: Vec<String>,
}

/// One leaf of a `use` tree: the full path, the name it binds (None for `_`), whether a glob.
struct UseLeaf {
    segs: Vec<String>,
    binding: Option<String>,
    glob: bool,
}

fn use_tree(t: &[Tok], a: usize, b: usize, prefix: &[String], out: &mut Vec<UseLeaf>) {
    let mut segs = prefix.to_vec();
    let mut k = a;
    if k < b && t[k].is("::") {
        segs.push(String::new()); // an extern path: `use ::std::..`
        k += 1;
    }
    while k < b {
        let tok = &t[k];
        if tok.is("{") {
            let close = matching(t, k).min(b);
            let mut s = k + 1;
            let mut depth = 0;
            for e in k + 1..=close {
                let at_end = e == close;
                if !at_end && (t[e].is("{") || t[e].is("(")) {
                    depth += 1;
                } else if !at_end && (t[e].is("}") || t[e].is(")")) {
                    depth -= 1;
                }
                if at_end || (depth == 0 && t[e].is(",")) {
                    if s < e {
                        use_tree(t, s, e, &segs, out);
                    }
                    s = e + 1;
                }
            }
            return;
        }
        if tok.is("*") {
            out.push(UseLeaf {
                segs,
                binding: None,
                glob: true,
            });
            return;
        }
        if tok.ident() && tok.text != "as" {
            segs.push(tok.text.clone());
            k += 1;
            if k < b && t[k].is("::") {
                k += 1;
                continue;
            }
            let mut binding = Some(tok.text.clone());
            if k + 1 < b && t[k].is("as") {
                binding = (t[k + 1].text != "_").then(|| t[k + 1].text.clone());
            }
            if segs.last().map(String::as_str) == Some("self") {
                segs.pop();
                if binding.as_deref() == Some("self") {
                    binding = segs.last().cloned();
                }
            }
            out.push(UseLeaf {
                segs,
                binding,
                glob: false,
            });
            return;
        }
        k += 1;
    }
}

const ITEM_KEYWORDS: &[&str] = &[
    "fn", "struct", "enum", "union", "trait", "type", "const", "static",
];
const QUALIFIERS: &[&str] = &["unsafe", "async", "extern", "default", "auto", "const"];

impl Crate {
    /// Reads the crate whose root file is `root`, following `mod` declarations through `read`.
    fn load(root: &str, read: &dyn Fn(&str) -> Option<String>) -> Crate {
        let mut c = Crate {
            modules: vec![Module {
                file: root.to_string(),
                ..Module::default()
            }],
            refs: Vec::new(),
            files: BTreeMap::new(),
            test_files: BTreeSet::new(),
            missing: Vec::new(),
        };
        let dir = root.rsplit_once('/').map_or("", |(d, _)| d).to_string();
        c.load_file(root, 0, &dir, read);
        c
    }

    fn load_file(
        &mut self,
        file: &str,
        m: usize,
        dir: &str,
        read: &dyn Fn(&str) -> Option<String>,
    ) {
        let Some(text) = read(file) else {
            self.missing.push(file.to_string());
            return;
        };
        let toks = lex(&text);
        self.files.insert(
            file.to_string(),
            SourceFile {
                toks: Vec::new(),
                test_ranges: Vec::new(),
                code_idents: BTreeSet::new(),
            },
        );
        let mut pending = Vec::new();
        let n = toks.len();
        self.items(&toks, 0, n, m, dir, file, &mut pending, read);
        self.files.get_mut(file).unwrap().toks = toks;
        for (child, child_file, child_dir) in pending {
            self.load_file(&child_file, child, &child_dir, read);
        }
    }

    fn new_module(&mut self, parent: usize, name: &str, file: &str) -> usize {
        let id = self.modules.len();
        self.modules.push(Module {
            parent: Some(parent),
            file: file.to_string(),
            ..Module::default()
        });
        self.modules[parent].children.insert(name.to_string(), id);
        id
    }

    /// Reads the items of module `m` in tokens `[i, end)`. `dir` is where its child modules'
    /// files are; files to read are queued on `pending`.
    #[allow(clippy::too_many_arguments)]
    fn items(
        &mut self,
        t: &[Tok],
        mut i: usize,
        end: usize,
        m: usize,
        dir: &str,
        file: &str,
        pending: &mut Vec<(usize, String, String)>,
        read: &dyn Fn(&str) -> Option<String>,
    ) {
        while i < end {
            let item_start = i;
            let mut test_only = false;
            let mut path_attr = None;
            while i + 1 < end && t[i].is("#") {
                let inner = t[i + 1].is("!");
                let open = if inner { i + 2 } else { i + 1 };
                if open >= end || !t[open].is("[") {
                    break;
                }
                let close = matching(t, open);
                let attr = &t[open + 1..close];
                if is_test_attr(attr) {
                    if inner {
                        // `#![cfg(test)]`: the whole module is test code.
                        self.files.get_mut(file).unwrap().test_ranges.push((i, end));
                        return;
                    }
                    test_only = true;
                }
                if attr.len() == 3 && attr[0].is("path") && attr[1].is("=") {
                    path_attr = attr[2].str_value().map(str::to_string);
                }
                i = close + 1;
            }
            if i >= end {
                break;
            }
            let stop = item_end(t, i, end);
            let mut j = i;
            let mut public = false;
            if t[j].is("pub") {
                public = true;
                j += 1;
                if j < end && t[j].is("(") {
                    j = matching(t, j) + 1;
                }
            }
            if test_only {
                self.files
                    .get_mut(file)
                    .unwrap()
                    .test_ranges
                    .push((item_start, stop));
                if t[j].is("mod") && t[j + 2].is(";") {
                    let name = &t[j + 1].text;
                    let f = path_attr.map_or_else(
                        || child_file(dir, name, read),
                        |p| format!("{}/{p}", file.rsplit_once('/').map_or("", |(d, _)| d)),
                    );
                    self.test_files.insert(f);
                    self.test_files.insert(format!("{dir}/{name}/"));
                }
                i = stop;
                continue;
            }
            match t[j].text.as_str() {
                "use" if t[j].kind == Kind::Ident => {
                    let mut leaves = Vec::new();
                    use_tree(t, j + 1, stop - 1, &[], &mut leaves);
                    for leaf in leaves {
                        if leaf.glob {
                            self.modules[m].globs.push(leaf.segs.clone());
                        } else if let Some(b) = &leaf.binding {
                            self.modules[m]
                                .bindings
                                .entry(b.clone())
                                .or_default()
                                .push(leaf.segs.clone());
                        }
                        // A public glob (`pub use math::*`) only hands names on: the files that
                        // use them import the files that define them.
                        if !(public && leaf.glob) {
                            self.refs.push(Reference {
                                module: m,
                                segs: leaf.segs,
                                line: t[j].line,
                                reexport: public,
                            });
                        }
                    }
                }
                "mod" if t[j + 1].ident() => {
                    let name = t[j + 1].text.clone();
                    if t[j + 2].is(";") {
                        let f = match path_attr {
                            Some(p) => {
                                format!("{}/{p}", file.rsplit_once('/').map_or("", |(d, _)| d))
                            }
                            None => child_file(dir, &name, read),
                        };
                        let child_dir = match f.strip_suffix("/mod.rs") {
                            Some(d) => d.to_string(),
                            None => format!("{dir}/{name}"),
                        };
                        let child = self.new_module(m, &name, &f);
                        pending.push((child, f, child_dir));
                    } else if t[j + 2].is("{") {
                        let close = matching(t, j + 2);
                        let child = self.new_module(m, &name, file);
                        self.items(
                            t,
                            j + 3,
                            close,
                            child,
                            &format!("{dir}/{name}"),
                            file,
                            pending,
                            read,
                        );
                    }
                }
                "macro_rules" if t[j + 1].is("!") => {
                    self.modules[m].defs.insert(t[j + 2].text.clone());
                    self.scan_code(t, j + 3, stop, m, file);
                }
                "extern" if t[j + 1].is("crate") => {}
                _ => {
                    let mut k = j;
                    while k < stop
                        && (QUALIFIERS.contains(&t[k].text.as_str()) && !t[k + 1].ident()
                            || QUALIFIERS.contains(&t[k].text.as_str())
                                && ITEM_KEYWORDS.contains(&t[k + 1].text.as_str())
                            || t[k].kind == Kind::Lit)
                    {
                        k += 1;
                    }
                    if ITEM_KEYWORDS.contains(&t[k].text.as_str()) && t[k].kind == Kind::Ident {
                        let mut name = k + 1;
                        if t[name].is("mut") {
                            name += 1;
                        }
                        if t[name].ident() {
                            self.modules[m].defs.insert(t[name].text.clone());
                        }
                    } else if t[k].ident() && t[k + 1].is("!") {
                        // An item-level macro call (`thread_local!`, a table): the items it
                        // spells out by name are this module's ...
                        for w in t[k..stop].windows(2) {
                            if ITEM_KEYWORDS.contains(&w[0].text.as_str()) && w[1].ident() {
                                self.modules[m].defs.insert(w[1].text.clone());
                            }
                        }
                        // ... and so are the functions a macro of this file makes under names
                        // its call passes (`fn $name` in `atomic_bits_fn!(atomic_and: ..)`).
                        if defines_fn_by_argument(t, &t[k].text) {
                            for w in t[k + 2..stop].windows(3) {
                                let head =
                                    w[0].is("(") || w[0].is(",") || w[0].is("[") || w[0].is("{");
                                let tail =
                                    [":", ",", ")", "]", "}", ";"].iter().any(|p| w[2].is(p));
                                if head
                                    && tail
                                    && w[1].ident()
                                    && w[1].text.chars().all(|c| {
                                        c == '_' || c.is_ascii_lowercase() || c.is_ascii_digit()
                                    })
                                {
                                    self.modules[m].defs.insert(w[1].text.clone());
                                }
                            }
                        }
                    }
                    self.scan_code(t, j, stop, m, file);
                }
            }
            i = stop;
        }
    }

    /// Records the paths that code in `[a, b)` names (and the `use` items inside function
    /// bodies), and the identifiers it names.
    fn scan_code(&mut self, t: &[Tok], a: usize, b: usize, m: usize, file: &str) {
        let mut k = a;
        while k < b {
            let tok = &t[k];
            if tok.is("#") && k + 1 < b && t[k + 1].is("[") {
                let close = matching(t, k + 1);
                if is_test_attr(&t[k + 2..close]) {
                    // A test-only statement or nested item: skip it.
                    let stop = item_end(t, close + 1, b);
                    self.files
                        .get_mut(file)
                        .unwrap()
                        .test_ranges
                        .push((k, stop));
                    k = stop;
                    continue;
                }
                k = close + 1;
                continue;
            }
            if tok.is("use")
                && tok.kind == Kind::Ident
                && k > a
                && (t[k - 1].is(";") || t[k - 1].is("{") || t[k - 1].is("}"))
            {
                let stop = item_end(t, k, b);
                let mut leaves = Vec::new();
                use_tree(t, k + 1, stop - 1, &[], &mut leaves);
                for leaf in leaves {
                    self.refs.push(Reference {
                        module: m,
                        segs: leaf.segs,
                        line: tok.line,
                        reexport: false,
                    });
                }
                k = stop;
                continue;
            }
            if tok.ident() {
                self.files
                    .get_mut(file)
                    .unwrap()
                    .code_idents
                    .insert(tok.text.clone());
                let after_sep = k > 0 && (t[k - 1].is("::") || t[k - 1].is("."));
                if !after_sep && k + 2 < b && t[k + 1].is("::") && t[k + 2].ident() {
                    let mut segs = vec![tok.text.clone()];
                    let mut e = k + 1;
                    while e + 1 < b && t[e].is("::") && t[e + 1].ident() {
                        segs.push(t[e + 1].text.clone());
                        e += 2;
                    }
                    self.refs.push(Reference {
                        module: m,
                        segs,
                        line: tok.line,
                        reexport: false,
                    });
                    for s in &t[k..e] {
                        if s.ident() {
                            self.files
                                .get_mut(file)
                                .unwrap()
                                .code_idents
                                .insert(s.text.clone());
                        }
                    }
                    k = e;
                    continue;
                }
            }
            k += 1;
        }
    }

    /// What `segs`, written in module `m`, names in this crate (None: another crate, a local
    /// name, or something this reader does not see).
    fn resolve(&self, m: usize, segs: &[String], depth: u32) -> Option<Found> {
        self.resolve_ns(m, segs, depth, false)
    }

    /// `resolve`, the last segment looked up as an item where `value` (see `walk_ns`).
    fn resolve_ns(&self, m: usize, segs: &[String], depth: u32, value: bool) -> Option<Found> {
        if depth > 24 || segs.is_empty() {
            return None;
        }
        match segs[0].as_str() {
            "" => None,
            "crate" => self.walk_ns(0, &segs[1..], depth, value),
            "self" => self.walk_ns(m, &segs[1..], depth, value),
            "super" => self.walk_ns(self.modules[m].parent?, &segs[1..], depth, value),
            _ => self.walk_ns(m, segs, depth, value),
        }
    }

    fn walk(&self, cur: usize, rest: &[String], depth: u32) -> Option<Found> {
        self.walk_ns(cur, rest, depth, false)
    }

    /// `walk`; with `value`, the last segment is looked up as an item, not a module (Rust's
    /// namespaces: `builtins::noise` is both the module `noise` and the function it re-exports).
    fn walk_ns(&self, cur: usize, rest: &[String], depth: u32, value: bool) -> Option<Found> {
        if depth > 24 {
            return None;
        }
        let Some(s) = rest.first() else {
            return Some(Found::Module(cur));
        };
        let module = &self.modules[cur];
        match s.as_str() {
            "super" => return self.walk(module.parent?, &rest[1..], depth),
            "self" => return self.walk(cur, &rest[1..], depth),
            _ => {}
        }
        if let Some(&child) = module.children.get(s) {
            if !(value && rest.len() == 1) {
                return self.walk_ns(child, &rest[1..], depth, value);
            }
        }
        if module.defs.contains(s) {
            return Some(Found::Item(cur));
        }
        if let Some(targets) = module.bindings.get(s) {
            for target in targets {
                // A binding to itself (`use glam::Vec3` seen from a path `Vec3::X`) is another
                // crate's name.
                if target.len() == 1 && target[0] == *s {
                    continue;
                }
                let mut path = target.clone();
                path.extend_from_slice(&rest[1..]);
                if let Some(f) = self.resolve_ns(cur, &path, depth + 1, value) {
                    return Some(f);
                }
            }
        }
        for glob in &module.globs {
            if let Some(Found::Module(g)) = self.resolve(cur, glob, depth + 1) {
                if g != cur {
                    if let Some(f) = self.walk_ns(g, rest, depth + 1, value) {
                        return Some(f);
                    }
                }
            }
        }
        None
    }

    /// The files of the modules that enclose `file`'s modules (its parent's file, and so on
    /// up to the crate root).
    fn ancestor_files(&self, file: &str) -> BTreeSet<&str> {
        let mut out = BTreeSet::new();
        for m in self.modules.iter().filter(|m| m.file == file) {
            let mut p = m.parent;
            while let Some(id) = p {
                if self.modules[id].file != file {
                    out.insert(self.modules[id].file.as_str());
                }
                p = self.modules[id].parent;
            }
        }
        out
    }

    /// The import graph whose cycles count: `edges` without the arrows from a module up to a
    /// module that encloses it. A child module is part of its parent (it sees the parent's
    /// private items, and a parent split over child files, `impl Lowerer` in `lower/calls.rs`,
    /// uses them by design), so a parent and its child naming each other is no circle; such
    /// an arrow is one that runs back up (`up_arrows`), as `farm-studio look` draws it.
    fn import_graph(&self) -> BTreeMap<(String, String), BTreeSet<String>> {
        let mut edges = self.edges();
        edges.retain(|(a, b), _| !self.ancestor_files(a).contains(b.as_str()));
        edges
    }

    /// The arrows from a module to a module that encloses it (`use super::*`, `crate::X` for an
    /// `X` of lib.rs).
    fn up_arrows(&self) -> BTreeMap<(String, String), BTreeSet<String>> {
        let mut edges = self.edges();
        edges.retain(|(a, b), _| self.ancestor_files(a).contains(b.as_str()));
        edges
    }

    fn file_of(&self, f: Found) -> &str {
        match f {
            Found::Module(m) | Found::Item(m) => &self.modules[m].file,
        }
    }

    /// The file-level import graph: (from, to) -> the names `from` takes from `to`, with lines.
    fn edges(&self) -> BTreeMap<(String, String), BTreeSet<String>> {
        let mut out: BTreeMap<(String, String), BTreeSet<String>> = BTreeMap::new();
        for r in &self.refs {
            let from = &self.modules[r.module].file;
            if r.reexport {
                let name = r.segs.last().cloned().unwrap_or_default();
                let used = self
                    .files
                    .get(from)
                    .is_some_and(|f| f.code_idents.contains(&name));
                if !used {
                    continue;
                }
            }
            let Some(found) = self.resolve(r.module, &r.segs, 0) else {
                continue;
            };
            let to = self.file_of(found);
            if to == from {
                continue;
            }
            let name = match found {
                Found::Module(_) => r.segs.last().cloned().unwrap_or_default(),
                Found::Item(m) => {
                    // The segment that names the item (`Foo` of `x::Foo::new`).
                    let defs = &self.modules[m].defs;
                    r.segs
                        .iter()
                        .rev()
                        .find(|s| defs.contains(*s))
                        .cloned()
                        .unwrap_or_default()
                }
            };
            let name = if name == "self" || name.is_empty() {
                r.segs
                    .iter()
                    .rev()
                    .find(|s| *s != "self")
                    .cloned()
                    .unwrap_or_default()
            } else {
                name
            };
            out.entry((from.clone(), to.to_string()))
                .or_default()
                .insert(format!("{name} (line {})", r.line));
        }
        out
    }
}

/// The file of child module `name` of a module whose children live in `dir`: `dir/name.rs`,
/// else `dir/name/mod.rs`.
fn child_file(dir: &str, name: &str, read: &dyn Fn(&str) -> Option<String>) -> String {
    let flat = format!("{dir}/{name}.rs");
    let nested = format!("{dir}/{name}/mod.rs");
    if read(&flat).is_none() && read(&nested).is_some() {
        nested
    } else {
        flat
    }
}

/// Whether the file's `macro_rules! name` makes a function named by one of its arguments
/// (`fn $name`).
fn defines_fn_by_argument(t: &[Tok], name: &str) -> bool {
    (0..t.len().saturating_sub(3)).any(|k| {
        t[k].is("macro_rules") && t[k + 1].is("!") && t[k + 2].is(name) && {
            let close = matching(t, k + 3);
            t[k + 3..close]
                .windows(2)
                .any(|w| w[0].is("fn") && w[1].is("$"))
        }
    })
}

/// Strongly connected components of more than one node (Tarjan).
fn cycles(edges: &BTreeMap<(String, String), BTreeSet<String>>) -> Vec<Vec<String>> {
    let mut nodes: BTreeSet<&str> = BTreeSet::new();
    let mut adj: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for (a, b) in edges.keys() {
        nodes.insert(a);
        nodes.insert(b);
        adj.entry(a).or_default().push(b);
    }
    struct State<'a> {
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        on_stack: BTreeSet<&'a str>,
        stack: Vec<&'a str>,
        next: usize,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(v: &'a str, adj: &BTreeMap<&'a str, Vec<&'a str>>, s: &mut State<'a>) {
        s.index.insert(v, s.next);
        s.low.insert(v, s.next);
        s.next += 1;
        s.stack.push(v);
        s.on_stack.insert(v);
        for &w in adj.get(v).map(Vec::as_slice).unwrap_or(&[]) {
            if !s.index.contains_key(w) {
                visit(w, adj, s);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if s.on_stack.contains(w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                comp.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                s.out.push(comp);
            }
        }
    }
    let mut s = State {
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        on_stack: BTreeSet::new(),
        stack: Vec::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in nodes {
        if !s.index.contains_key(v) {
            visit(v, &adj, &mut s);
        }
    }
    s.out.sort();
    s.out
}

/// Each cycle of `edges`, with the names that tie it (empty: no cycle).
fn describe_cycles(edges: &BTreeMap<(String, String), BTreeSet<String>>) -> String {
    let mut msg = String::new();
    for comp in cycles(edges) {
        let _ = writeln!(msg, "cycle of {} files: {}", comp.len(), comp.join(", "));
        for ((a, b), names) in edges {
            if comp.contains(a) && comp.contains(b) {
                let names: Vec<&str> = names.iter().map(String::as_str).collect();
                let _ = writeln!(msg, "  {a} -> {b}: {}", names.join(", "));
            }
        }
    }
    msg
}

// -------------------------------------------------------------------------------------------
// 1. No import cycles
// -------------------------------------------------------------------------------------------

/// ARCHITECTURE.md: "There are no import cycles". Between the files of each crate (the crates
/// themselves cannot form one: cargo refuses it), a file that imports another (a `use`, or a
/// path in code that resolves to an item the other file defines) never reaches itself again.
#[test]
fn no_import_cycles_between_files() {
    let mut report = String::new();
    for (name, root) in CRATES {
        let c = load_crate(root);
        let cycles = describe_cycles(&c.import_graph());
        if !cycles.is_empty() {
            let _ = write!(report, "{name}:\n{cycles}");
        }
    }
    assert!(
        report.is_empty(),
        "import cycles (file -> file: the names it takes, where):\n{report}"
    );
}

/// Every `.rs` file under a crate's `src/` is read by these checks: a module of the crate, or
/// test code that a `#[cfg(test)] mod` declares. A file the reader misses would escape them.
#[test]
fn every_source_file_is_a_module_these_checks_read() {
    let mut unread = Vec::new();
    for (_, root) in CRATES {
        let c = load_crate(root);
        assert!(
            c.missing.is_empty(),
            "{root}: `mod` declarations without a file: {:?}",
            c.missing
        );
        let src = root.strip_suffix("/lib.rs").unwrap();
        for f in files_under(src, ".rs") {
            let is_test = c
                .test_files
                .iter()
                .any(|t| f == *t || (t.ends_with('/') && f.starts_with(t.as_str())));
            if !c.files.contains_key(&f) && !is_test {
                unread.push(f);
            }
        }
    }
    assert!(
        unread.is_empty(),
        "source files no module declares: {unread:?}"
    );
}

/// The reader itself: re-exports are transparent, test modules and their imports are no
/// edges, and a cycle through `super::` paths in code is found with the names that tie it.
#[test]
fn the_reader_finds_cycles_through_uses_and_paths_but_not_through_reexports() {
    let files: BTreeMap<&str, &str> = BTreeMap::from([
        (
            "x/lib.rs",
            "mod a; mod b; pub mod faces; mod split; pub use a::A;
             // `use crate::b::B;` in a comment is no import
             fn f() -> &'static str { \"crate::b::g()\" }",
        ),
        ("x/a.rs", "pub struct A; pub fn h() { super::b::g(); }"),
        (
            "x/b.rs",
            "use crate::A; pub fn g() {}
             #[cfg(test)] mod tests { use super::*; use crate::a::h; }",
        ),
        // A parent that only re-exports its children, and children that use a sibling through
        // the parent's re-export: no cycle with the parent.
        (
            "x/faces/mod.rs",
            "mod p; mod q; pub use p::P; pub use q::Q;",
        ),
        ("x/faces/p.rs", "pub struct P;"),
        ("x/faces/q.rs", "use super::P; pub struct Q(P);"),
        // A parent split over a child file that uses the parent's items: no cycle either.
        ("x/split.rs", "mod part; pub struct S(part::Part);"),
        (
            "x/split/part.rs",
            "use super::*; pub struct Part; impl S { fn f() {} }",
        ),
    ]);
    let read = |f: &str| files.get(f).map(|s| s.to_string());
    let c = Crate::load("x/lib.rs", &read);
    let edges = c.import_graph();
    let keys: Vec<(&str, &str)> = edges
        .keys()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .collect();
    assert_eq!(
        keys,
        [
            ("x/a.rs", "x/b.rs"),
            ("x/b.rs", "x/a.rs"),
            ("x/faces/q.rs", "x/faces/p.rs"),
            ("x/split.rs", "x/split/part.rs")
        ]
    );
    let up: Vec<(String, String)> = c.up_arrows().into_keys().collect();
    assert_eq!(
        up,
        [("x/split/part.rs".to_string(), "x/split.rs".to_string())]
    );
    let report = describe_cycles(&edges);
    assert!(
        report.contains("cycle of 2 files: x/a.rs, x/b.rs"),
        "{report}"
    );
    assert!(report.contains("x/a.rs -> x/b.rs: g (line 1)"), "{report}");
    assert!(report.contains("x/b.rs -> x/a.rs: A (line 1)"), "{report}");
    assert_eq!(cycles(&edges).len(), 1, "{report}");
}

// -------------------------------------------------------------------------------------------
// 2. Layers: warp-runtime's files, and the workspace's crates
// -------------------------------------------------------------------------------------------

/// warp-runtime's layers, top first (ARCHITECTURE.md: "Imports run one way, each layer
/// importing only layers to its right"): (rank, name, files). A file is a path under
/// `warp-runtime/src/`, a folder ends in `/`, and the longest match places a file. A file
/// imports files of its own row or of a higher rank; two rows of one rank (the backends)
/// import neither each other. `lib.rs`, the crate's face (its re-exports), is in no row: a
/// file that imports an item of lib.rs climbs above every layer.
const RUNTIME_LAYERS: &[(u32, &str, &[&str])] = &[
    // `sparse/` (the `sparse` feature) captures its solver's loop (`graph`); `ops/` (the `ops`
    // feature) launches kernels and their adjoints and replays bodies under tapes; `python/`
    // (the `python` feature) imports `ops/` (its ops.rs) beside the arrays and streams.
    (
        0,
        "entry points",
        &[
            "launch.rs",
            "autograd.rs",
            "checkpoint.rs",
            "python/",
            "sparse/",
            "ops/",
        ],
    ),
    (1, "tape", &["tape.rs"]),
    (2, "graph", &["graph.rs"]),
    // `objects/` sits beside `array`: it imports `array`, `primitives` and `dispatch`.
    (
        3,
        "arrays and what is made of them",
        &["array.rs", "array/", "objects/", "primitives/mod.rs"],
    ),
    (4, "dispatch", &["dispatch.rs"]),
    (5, "capturing", &["capturing.rs"]),
    (6, "the CPU backend", &["cpu/"]),
    (6, "the CUDA backend", &["cuda/"]),
    // The primitives' leaves are what the `Backend` trait's primitives take.
    (
        7,
        "the backend seam",
        &[
            "backend.rs",
            "params.rs",
            "primitives/elements.rs",
            "primitives/plan.rs",
        ],
    ),
    (8, "kernel", &["kernel.rs"]),
    (9, "device", &["device.rs", "launch_id.rs"]),
    (10, "leaves", &["error.rs", "config.rs", "cpp_table.rs"]),
];

/// The imports that climb a layer on purpose (ARCHITECTURE.md states each): (file, the files it
/// may import above its layer, why).
const RUNTIME_LAYER_EXCEPTIONS: &[(&str, &[&str], &str)] = &[
    (
        "cuda/pinned.rs",
        &["array.rs", "array/"],
        "PinnedVec's asynchronous copies are methods of `Array` on the array's `Storage`",
    ),
    (
        "cuda/distributed.rs",
        &["array.rs", "array/"],
        "collectives take `Array`s",
    ),
];

const RUNTIME_SRC: &str = "warp-runtime/src/";

/// The backends' folders ("Only `dispatch.rs` names every backend").
const RUNTIME_BACKENDS: &[&str] = &["cpu/", "cuda/"];

/// Whether `file` is `pattern`, or lies under it where `pattern` is a folder (ends in `/`).
fn path_matches(file: &str, pattern: &str) -> bool {
    if pattern.ends_with('/') {
        file.starts_with(pattern)
    } else {
        file == pattern
    }
}

/// The row of `RUNTIME_LAYERS` that places a warp-runtime file (a path under `RUNTIME_SRC`).
fn runtime_layer(file: &str) -> Option<usize> {
    RUNTIME_LAYERS
        .iter()
        .enumerate()
        .filter_map(|(row, (_, _, files))| {
            files
                .iter()
                .filter(|p| path_matches(file, p))
                .map(|p| (p.len(), row))
                .max()
        })
        .max()
        .map(|(_, row)| row)
}

/// ARCHITECTURE.md's layers of warp-runtime: every import goes down (or stays in its row),
/// but for the stated exceptions; a backend's folder depends on `backend.rs` and below, never
/// on dispatch, array, tape or launch; and only `dispatch.rs` names every backend.
#[test]
fn warp_runtime_imports_follow_its_layers() {
    let c = load_crate("warp-runtime/src/lib.rs");
    let mut problems = Vec::new();
    for file in c.files.keys() {
        let f = file.strip_prefix(RUNTIME_SRC).unwrap();
        if f != "lib.rs" && runtime_layer(f).is_none() {
            problems.push(format!("{file} is in no layer: place it in RUNTIME_LAYERS"));
        }
    }
    let mut backends_named: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    let edges = c.edges();
    for ((from, to), names) in &edges {
        let (a, b) = (
            from.strip_prefix(RUNTIME_SRC).unwrap(),
            to.strip_prefix(RUNTIME_SRC).unwrap(),
        );
        if a == "lib.rs" {
            continue;
        }
        let (Some(ra), rb) = (runtime_layer(a), runtime_layer(b)) else {
            continue;
        };
        if let Some(backend) = RUNTIME_BACKENDS.iter().find(|p| path_matches(b, p)) {
            if !path_matches(a, backend) {
                backends_named.entry(a).or_default().insert(backend);
            }
        }
        let climbs = match rb {
            // lib.rs climbs above every layer; a file in no layer is reported as such above.
            None => b == "lib.rs",
            Some(rb) => {
                let (rank_a, rank_b) = (RUNTIME_LAYERS[ra].0, RUNTIME_LAYERS[rb].0);
                rank_b < rank_a || (rank_b == rank_a && ra != rb)
            }
        };
        let excepted = RUNTIME_LAYER_EXCEPTIONS
            .iter()
            .any(|(f, to, _)| *f == a && to.iter().any(|p| path_matches(b, p)));
        if climbs && !excepted {
            let names: Vec<&str> = names.iter().map(String::as_str).collect();
            problems.push(format!(
                "{a} ({}) imports {b} ({}): {}",
                RUNTIME_LAYERS[ra].1,
                rb.map_or("the crate's face", |rb| RUNTIME_LAYERS[rb].1),
                names.join(", ")
            ));
        }
    }
    for (file, rows) in backends_named {
        if rows.len() > 1 && file != "dispatch.rs" {
            problems.push(format!(
                "{file} names more than one backend: only dispatch.rs does"
            ));
        }
    }
    for (f, to, _) in RUNTIME_LAYER_EXCEPTIONS {
        let used = edges.keys().any(|(a, b)| {
            a.strip_prefix(RUNTIME_SRC) == Some(*f)
                && to.iter().any(|p| {
                    b.strip_prefix(RUNTIME_SRC)
                        .is_some_and(|b| path_matches(b, p))
                })
        });
        if !used {
            problems.push(format!("RUNTIME_LAYER_EXCEPTIONS lets {f} import {to:?}, which it no longer does: remove it"));
        }
    }
    assert!(
        problems.is_empty(),
        "warp-runtime's layers (ARCHITECTURE.md):\n{}",
        problems.join("\n")
    );
}

/// The workspace's crate graph (the library's dependency tables of each Cargo.toml: normal,
/// build, per target): (crate, its manifest, the workspace crates it depends on). warp-core and
/// warp-cuda stand alone (warp-core is the kernel-side vocabulary, warp-cuda the driver
/// layer); warp-macros depends on no workspace crate (the code it generates names
/// `::warp_lang::__private`, which the user's crate resolves); warp-report stands alone;
/// warp-runtime sits on warp-core and warp-cuda, never on the compiler; the facade on all; the
/// examples' crate (`examples/`, package warp-lang-examples) on the facade, warp-report and
/// warp-cuda (the kernel cache's settings).
/// A member is named here by its folder (the workspace's `members` list).
const CRATE_DEPS: &[(&str, &str, &[&str])] = &[
    ("warp-core", "warp-core/Cargo.toml", &[]),
    ("warp-cuda", "warp-cuda/Cargo.toml", &[]),
    ("warp-macros", "warp-macros/Cargo.toml", &[]),
    ("warp-report", "warp-report/Cargo.toml", &[]),
    (
        "warp-runtime",
        "warp-runtime/Cargo.toml",
        &["warp-core", "warp-cuda"],
    ),
    (
        "warp-lang",
        "Cargo.toml",
        &[
            "warp-core",
            "warp-cuda",
            "warp-macros",
            "warp-report",
            "warp-runtime",
        ],
    ),
    (
        "examples",
        "examples/Cargo.toml",
        &["warp-cuda", "warp-lang", "warp-report"],
    ),
];

/// The examples' crate's package name: what its manifest's dependents would name it.
const EXAMPLES_PACKAGE: &str = "warp-lang-examples";

/// The packages a manifest's library depends on: every dependency table but
/// `[dev-dependencies]` (tests and examples may use any crate; a dev-dependency adds nothing to
/// the library's graph).
fn manifest_deps(toml: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut in_deps = false;
    for line in toml.lines() {
        let line = line.split('#').next().unwrap().trim();
        if line.starts_with('[') {
            let header = line.trim_matches(|c| c == '[' || c == ']');
            // `[dependencies]`, `[dev-dependencies]`, `[target.'cfg(unix)'.dependencies]`, and
            // `[dependencies.foo]` (one dependency per table).
            let (table, name) = match header.rsplit_once("dependencies") {
                Some((before, _)) if before.ends_with("dev-") => (false, ""),
                Some((_, rest)) => (true, rest.trim_start_matches('.')),
                None => (false, ""),
            };
            in_deps = table && name.is_empty();
            if table && !name.is_empty() {
                out.insert(name.trim_matches('"').to_string());
            }
            continue;
        }
        if in_deps {
            if let Some(key) = line.split(['=', '.']).next() {
                let key = key.trim().trim_matches('"');
                if !key.is_empty() {
                    out.insert(key.to_string());
                }
            }
        }
    }
    out
}

/// The workspace's crates depend on each other as `CRATE_DEPS` says (one way: no crate below
/// depends on one above it), and `CRATE_DEPS` names every member.
#[test]
fn workspace_crates_form_the_intended_dag() {
    let names: BTreeSet<&str> = CRATE_DEPS
        .iter()
        .map(|(n, _, _)| *n)
        .chain([EXAMPLES_PACKAGE])
        .collect();
    let root = read_required("Cargo.toml");
    let members = root
        .split("members")
        .nth(1)
        .and_then(|s| s.split(']').next())
        .expect("a workspace members list");
    for m in members.split(',').map(|m| {
        m.trim()
            .trim_matches(|c| c == '[' || c == '=' || c == ' ' || c == '"')
    }) {
        if !m.is_empty() {
            assert!(
                names.contains(m),
                "workspace member {m} is not in CRATE_DEPS: state what it may depend on"
            );
        }
    }
    let mut problems = Vec::new();
    for (name, manifest, want) in CRATE_DEPS {
        let got: BTreeSet<String> = manifest_deps(&read_required(manifest))
            .into_iter()
            .filter(|d| names.contains(d.as_str()))
            .collect();
        let want: BTreeSet<String> = want.iter().map(|s| s.to_string()).collect();
        if got != want {
            problems.push(format!(
                "{name} depends on {got:?}; the architecture says {want:?}"
            ));
        }
    }
    // Only the examples use what the examples need: the library's own graph holds neither
    // rerun's SDK (hundreds of crates for the scenes' recordings) nor their command lines.
    let lib = manifest_deps(&root);
    for only_examples in ["rerun", "clap"] {
        if lib.contains(only_examples) {
            problems.push(format!(
                "warp-lang depends on {only_examples}, which only the examples use: it belongs \
                 in examples/Cargo.toml"
            ));
        }
    }
    // The intended graph itself has no cycle.
    let edges: BTreeMap<(String, String), BTreeSet<String>> = CRATE_DEPS
        .iter()
        .flat_map(|(n, _, deps)| {
            deps.iter()
                .map(move |d| ((n.to_string(), d.to_string()), BTreeSet::new()))
        })
        .collect();
    assert!(cycles(&edges).is_empty(), "CRATE_DEPS has a cycle");
    assert!(
        problems.is_empty(),
        "the workspace's crate graph:\n{}",
        problems.join("\n")
    );
}

// -------------------------------------------------------------------------------------------
// 3. File sizes
// -------------------------------------------------------------------------------------------

/// The most lines a warp-macros source file may have (issue 30: the builtin table had grown
/// to 1,770): past it, a file holds more than one concept.
const MACROS_MAX_LINES: usize = 1300;

#[test]
fn no_warp_macros_source_file_is_over_1300_lines() {
    let long: Vec<String> = files_under("warp-macros/src", ".rs")
        .into_iter()
        .filter_map(|f| {
            let n = read_required(&f).lines().count();
            (n > MACROS_MAX_LINES).then(|| format!("{f}: {n} lines"))
        })
        .collect();
    assert!(
        long.is_empty(),
        "warp-macros files over {MACROS_MAX_LINES} lines:\n{}",
        long.join("\n")
    );
}

// -------------------------------------------------------------------------------------------
// 4. Where warp-core allocates
// -------------------------------------------------------------------------------------------

/// Types whose values own heap memory.
const ALLOCATING_TYPES: &[&str] = &[
    "Vec",
    "String",
    "Box",
    "Rc",
    "Arc",
    "HashMap",
    "HashSet",
    "BTreeMap",
    "BTreeSet",
    "VecDeque",
    "BinaryHeap",
    "LinkedList",
    "Cow",
    "CString",
    "OsString",
    "PathBuf",
];
/// Macros that allocate.
const ALLOCATING_MACROS: &[&str] = &["vec", "format"];
/// Methods that return an owned, allocated value.
const ALLOCATING_METHODS: &[&str] = &[
    "to_vec",
    "to_string",
    "to_owned",
    "collect",
    "into_boxed_slice",
    "into_owned",
];

/// One allocating construct in non-test code: file, line, the construct, the enclosing fn
/// (`ITEM_LEVEL` outside any: a type, a field), and whether that fn is `#[cold]`.
#[derive(Debug)]
struct Allocation {
    file: String,
    line: usize,
    what: String,
    function: String,
    cold: bool,
}

/// The "function" of a construct outside every function body: a type alias, a field.
const ITEM_LEVEL: &str = "(item level)";

/// The names of the attributes on the item whose keyword (`fn`) is at `k`.
fn attributes_before(t: &[Tok], mut k: usize) -> Vec<String> {
    let mut out = Vec::new();
    // Back over the qualifiers and visibility: `pub(crate) const unsafe fn`.
    while k > 0 {
        let p = &t[k - 1];
        if p.ident()
            && [
                "pub", "const", "unsafe", "async", "extern", "crate", "super",
            ]
            .contains(&p.text.as_str())
            || p.kind == Kind::Lit
            || p.is("(")
            || p.is(")")
        {
            k -= 1;
        } else {
            break;
        }
    }
    // Back over `#[..]` groups.
    while k > 1 && t[k - 1].is("]") {
        let mut depth = 0;
        let mut open = k - 1;
        loop {
            if t[open].is("]") {
                depth += 1;
            } else if t[open].is("[") {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            if open == 0 {
                return out;
            }
            open -= 1;
        }
        if open == 0 || !t[open - 1].is("#") {
            break;
        }
        out.push(t[open + 1].text.clone());
        k = open - 1;
    }
    out
}

/// The allocating constructs of a crate's non-test code.
fn allocations(c: &Crate) -> Vec<Allocation> {
    let mut out = Vec::new();
    for (file, src) in &c.files {
        let t = &src.toks;
        let in_test = |k: usize| src.test_ranges.iter().any(|&(a, b)| a <= k && k < b);
        // The functions, innermost last: (name, body start, body end).
        let mut fns: Vec<(String, usize, usize, bool)> = Vec::new();
        for k in 0..t.len().saturating_sub(1) {
            if t[k].is("fn") && t[k + 1].ident() {
                let mut b = k + 2;
                while b < t.len() && !t[b].is("{") && !t[b].is(";") {
                    if t[b].is("(") || t[b].is("[") {
                        b = matching(t, b);
                    }
                    b += 1;
                }
                if b < t.len() && t[b].is("{") {
                    let cold = attributes_before(t, k).iter().any(|a| a == "cold");
                    fns.push((t[k + 1].text.clone(), k, matching(t, b), cold));
                }
            }
        }
        for k in 0..t.len() {
            if in_test(k) || t[k].kind != Kind::Ident {
                continue;
            }
            let word = t[k].text.as_str();
            let prev = |s: &str| k > 0 && t[k - 1].is(s);
            let next = |s: &str| t.get(k + 1).is_some_and(|n| n.is(s));
            let what = if ALLOCATING_TYPES.contains(&word) && !prev(".") {
                word.to_string()
            } else if ALLOCATING_MACROS.contains(&word) && next("!") {
                format!("{word}!")
            } else if ALLOCATING_METHODS.contains(&word) && prev(".") {
                format!(".{word}()")
            } else if word == "alloc" && (next("::") || prev("::")) {
                "alloc::".to_string()
            } else {
                continue;
            };
            let (function, cold) = fns
                .iter()
                .filter(|(_, a, b, _)| *a <= k && k <= *b)
                .max_by_key(|(_, a, _, _)| *a)
                .map_or((ITEM_LEVEL.to_string(), false), |(n, _, _, c)| {
                    (n.clone(), *c)
                });
            out.push(Allocation {
                file: file.clone(),
                line: t[k].line,
                what,
                function,
                cold,
            });
        }
    }
    out
}

/// The allocation scanner itself: it finds each construct with its function and whether that
/// is `#[cold]`, and leaves test code, comments and strings alone.
#[test]
fn the_allocation_scanner_finds_constructs_outside_tests() {
    let src = "pub fn fine(x: &[u8]) -> usize { x.len() } // a Vec in a comment
        #[cold]
        #[inline(never)]
        pub(crate) fn fault() -> Box<u8> { Box::new(0) }
        fn hot(x: &[u8]) -> usize { let s = \"vec![in a string]\"; x.to_vec().len() + s.len() }
        #[cfg(test)] mod tests { fn t() { let v: Vec<u8> = vec![]; } }
        pub struct S { names: String }";
    let read = |f: &str| (f == "y/lib.rs").then(|| src.to_string());
    let c = Crate::load("y/lib.rs", &read);
    let found: Vec<(String, String, bool)> = allocations(&c)
        .into_iter()
        .map(|a| (a.function, a.what, a.cold))
        .collect();
    let want = [
        ("fault", "Box", true),
        ("fault", "Box", true),
        ("hot", ".to_vec()", false),
        (ITEM_LEVEL, "String", false),
    ];
    let want: Vec<(String, String, bool)> = want
        .iter()
        .map(|(f, w, c)| (f.to_string(), w.to_string(), *c))
        .collect();
    assert_eq!(found, want);
}

/// Why a part of warp-core may allocate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Why {
    /// Kernel-side code reporting a fault: a `Box<Fault>` with its index and values, built in
    /// a `#[cold]` function (which the test checks), so that the path taken by every access
    /// that does not fault allocates nothing.
    Fault,
    /// Host code: it runs outside kernels (a validator, a builder, a constructor the runtime
    /// calls once per launch chunk).
    Host,
}

/// The parts of warp-core that allocate, each with its reason: a file and its functions
/// (`"*"`: every function of the file; `ITEM_LEVEL`: its types and fields). Every other
/// non-test source of warp-core contains no allocating construct (`ALLOCATING_TYPES`,
/// `ALLOCATING_MACROS`, `ALLOCATING_METHODS`, `alloc::`).
const WARP_CORE_ALLOCATES: &[(&str, &[&str], Why, &str)] = &[
    (
        "warp-core/src/fault.rs",
        &[ITEM_LEVEL, "new", "assertion_failed"],
        Why::Fault,
        "`KResult<T> = Result<T, Box<Fault>>`: a fault is boxed so that `Ok` stays one word, and \
         `FaultKind` holds the index, shape and values it names as `Vec`s; `Fault::new` boxes it \
         (`Fault::assertion_failed`, a failed assertion's, through it)",
    ),
    (
        "warp-core/src/view.rs",
        &["out_of_bounds", "view_out_of_bounds", "log_write"],
        Why::Fault,
        "an array access's faults (out of bounds, a view's bound, a write race) copy the index and \
         shape into the fault",
    ),
    (
        "warp-core/src/local_array.rs",
        &["out_of_range"],
        Why::Fault,
        "an index outside a local array, with the index, the length and the line",
    ),
    (
        "warp-core/src/objects/bvh.rs",
        &["fault"],
        Why::Fault,
        "an out-of-bounds node or primitive index of a BVH",
    ),
    (
        "warp-core/src/objects/hash_grid.rs",
        &["not_a_point"],
        Why::Fault,
        "a hash grid candidate that is not a point index, with the id and the point count",
    ),
    (
        "warp-core/src/objects/bvh.rs",
        &["preorder_escapes"],
        Why::Host,
        "the escape links of a built tree (the vector and its work list): builders call it \
         once per build, on the host, beside the layout it computes them from",
    ),
    (
        "warp-core/src/objects/volume.rs",
        &["non_finite"],
        Why::Fault,
        "a NaN or infinite volume sample position, with its values",
    ),
    (
        "warp-core/src/grad.rs",
        &[ITEM_LEVEL, "new"],
        Why::Host,
        "`AdStack`'s buffer: the CPU backend makes one stack per launch chunk (`AdStack::new`, \
         with its whole capacity); a kernel thread's pushes never grow it (past the capacity a \
         push is a fault)",
    ),
    (
        "warp-core/src/meta.rs",
        &[ITEM_LEVEL],
        Why::Host,
        "`ConstLiteral` (`fn() -> String`) and `StructDefs` (`fn(&mut Vec<..>)`): signatures of \
         the host functions the CUDA source assembler calls, which the macro generates",
    ),
    (
        "warp-core/src/objects/nanovdb.rs",
        &["*"],
        Why::Host,
        "the NanoVDB format's host code: the validator and the map's accessors (errors as \
         `String`) and the CPU builders `build_from_tiles`/`build_from_voxels` (a grid as \
         `Vec<u8>`), kept with the format facts so that they have one home",
    ),
];

/// ARCHITECTURE.md: warp-core allocates only where `WARP_CORE_ALLOCATES` says, and why; its
/// fault constructors are `#[cold]`; and no entry of the list is stale.
#[test]
fn warp_core_allocates_only_where_listed() {
    let c = load_crate("warp-core/src/lib.rs");
    let found = allocations(&c);
    let allowed = |a: &Allocation| {
        WARP_CORE_ALLOCATES.iter().find(|(f, fns, _, _)| {
            *f == a.file && (fns.contains(&"*") || fns.contains(&a.function.as_str()))
        })
    };
    let mut problems = Vec::new();
    for a in &found {
        match allowed(a) {
            None => problems.push(format!(
                "{}:{}: {} in `{}`: warp-core allocates here, which WARP_CORE_ALLOCATES does not list",
                a.file, a.line, a.what, a.function
            )),
            Some((_, _, Why::Fault, _)) if a.function != ITEM_LEVEL && !a.cold => problems.push(format!(
                "{}:{}: {} in `{}`: a fault constructor that allocates must be #[cold]",
                a.file, a.line, a.what, a.function
            )),
            Some(_) => {}
        }
    }
    for (file, fns, _, _) in WARP_CORE_ALLOCATES {
        for f in *fns {
            if !found
                .iter()
                .any(|a| a.file == *file && (*f == "*" || a.function == *f))
            {
                problems.push(format!(
                    "WARP_CORE_ALLOCATES lists `{f}` in {file}, which allocates nothing (any more): \
                     remove it"
                ));
            }
        }
    }
    assert!(
        problems.is_empty(),
        "warp-core's allocation rule:\n{}",
        problems.join("\n")
    );
}

// -------------------------------------------------------------------------------------------
// 5. The recipes: a builtin, a host object
// -------------------------------------------------------------------------------------------
//
// Where today's tables are. Other work moves them (one row per CUDA library section, the
// builtin table split, host objects behind one derive): these constants and the readers
// below them are the lines to adapt.

/// The builtin table: the invocations, anywhere under warp-macros/src, of the macros whose
/// definition makes rows with `Builtin::row` (today `table!` in builtins.rs; each row
/// `"name": classes, (params) -> result, "section", Grad, facts..;`).
const BUILTIN_ROW_CONSTRUCTOR: [&str; 2] = ["Builtin", "row"];
/// The CUDA library's sections: one row per section, `kernel!(..)` for the sections kernels
/// include (see `cuda_sections`); section `s` is `wp_<s>.h`.
const SECTION_ROWS_FILE: &str = "warp-cuda/src/library.rs";
const SECTION_ROW_MACRO: &str = "kernel";
/// The host objects' kinds (`OBJECTS`: `ObjectRow { kind, name, param, rust, cuda, section }`).
const OBJECTS_FILE: &str = "warp-macros/src/types.rs";
/// Or, in that file, a macro with one row per kind (`Name: param|state, "View", "wp::t",
/// "section";`).
const OBJECT_ROWS_MACRO: &str = "object_kinds";
/// The CUDA builtin library's headers.
const CUDA_LIBRARY: &str = "warp-cuda/cuda";

/// A row of the builtin table, as far as the recipe needs it.
#[derive(Debug)]
struct BuiltinRow {
    name: String,
    section: String,
    grad: String,
    /// The names of the builder facts that follow (`method`, `aliases`, `operator`, ..).
    facts: Vec<String>,
    at: String,
}

fn builtin_rows() -> Vec<BuiltinRow> {
    let sources: Vec<(String, Vec<Tok>)> = files_under("warp-macros/src", ".rs")
        .into_iter()
        .map(|f| {
            let t = lex(&read_required(&f));
            (f, t)
        })
        .collect();
    // The table's macros: `macro_rules! NAME { .. Builtin::row(..) .. }`.
    let mut table_macros = BTreeSet::new();
    for (_, t) in &sources {
        for k in 0..t.len().saturating_sub(3) {
            if t[k].is("macro_rules") && t[k + 1].is("!") && t[k + 3].is("{") {
                let body = &t[k + 3..matching(t, k + 3)];
                let [ty, f] = BUILTIN_ROW_CONSTRUCTOR;
                if body
                    .windows(3)
                    .any(|w| w[0].is(ty) && w[1].is("::") && w[2].is(f))
                {
                    table_macros.insert(t[k + 2].text.clone());
                }
            }
        }
    }
    let mut rows = Vec::new();
    for (file, t) in &sources {
        let (file, t) = (file.clone(), t.as_slice());
        for k in 0..t.len().saturating_sub(2) {
            let invocation = table_macros.contains(&t[k].text)
                && t[k + 1].is("!")
                && t[k + 2].is("{")
                && !(k > 0 && t[k - 1].is("!"));
            if !invocation {
                continue;
            }
            let close = matching(t, k + 2);
            let mut a = k + 3;
            while a < close {
                let end = (a..close).find(|&e| t[e].is(";")).unwrap_or(close);
                let row = &t[a..end];
                let name = row.first().and_then(Tok::str_value);
                let arrow = row.windows(2).position(|w| w[0].is("-") && w[1].is(">"));
                if let (Some(name), Some(arrow)) = (name, arrow) {
                    let mut depth = 0i32;
                    let mut top = Vec::new(); // the row's tokens outside brackets, after `->`
                    for tok in &row[arrow + 2..] {
                        match tok.text.as_str() {
                            "(" | "[" if tok.kind == Kind::Punct => depth += 1,
                            ")" | "]" if tok.kind == Kind::Punct => depth -= 1,
                            _ if depth == 0 => top.push(tok),
                            _ => {}
                        }
                    }
                    let sec = top.iter().position(|t| t.kind == Kind::Lit);
                    if let Some(sec) = sec {
                        let rest: Vec<&&Tok> =
                            top[sec + 1..].iter().filter(|t| t.ident()).collect();
                        rows.push(BuiltinRow {
                            name: name.to_string(),
                            section: top[sec].str_value().unwrap_or_default().to_string(),
                            grad: rest.first().map(|t| t.text.clone()).unwrap_or_default(),
                            facts: rest.iter().skip(1).map(|t| t.text.clone()).collect(),
                            at: format!("{file}:{}", row[0].line),
                        });
                    }
                }
                a = end + 1;
            }
        }
    }
    rows
}

/// The CUDA library's sections, each with its adjoint part's header where it has one, from
/// the rows kernels include (`SECTION_ROWS_FILE`: `kernel!("name", Some(header!("wp_adjoint_x.h"))
/// | Some(CONST) | None, ..)`).
fn cuda_sections() -> BTreeMap<String, Option<String>> {
    let t = lex(&read_required(SECTION_ROWS_FILE));
    let header_of = |k: usize| -> Option<String> {
        // `header!("x")`, or a const holding one.
        if t[k].is("header") {
            return t[k + 3].str_value().map(str::to_string);
        }
        let c = (1..t.len()).find(|&c| t[c].is(&t[k].text) && t[c - 1].is("const"))?;
        let h = (c..t.len()).find(|&h| t[h].is("header"))?;
        t[h + 3].str_value().map(str::to_string)
    };
    let mut out = BTreeMap::new();
    for k in 1..t.len().saturating_sub(3) {
        if t[k].is(SECTION_ROW_MACRO) && t[k + 1].is("!") && t[k + 2].is("(") && !t[k - 1].is("!") {
            let Some(name) = t[k + 3].str_value() else {
                continue;
            };
            let part = (t[k + 5].is("Some")).then(|| header_of(k + 7)).flatten();
            out.insert(name.to_string(), part);
        }
    }
    assert!(
        out.len() > 5,
        "read {} section rows in {SECTION_ROWS_FILE}: has the table moved?",
        out.len()
    );
    out
}

/// A CUDA library header and every library header it includes, transitively, as one text.
fn cuda_closure(header: &str) -> String {
    let mut seen = BTreeSet::new();
    let mut todo = vec![header.to_string()];
    let mut text = String::new();
    while let Some(h) = todo.pop() {
        if !seen.insert(h.clone()) {
            continue;
        }
        let Some(src) = read_rel(&format!("{CUDA_LIBRARY}/{h}")) else {
            continue;
        };
        for line in src.lines() {
            if let Some(inc) = line.trim().strip_prefix("#include \"") {
                todo.push(inc.trim_end_matches('"').to_string());
            }
        }
        text.push_str(&src);
        text.push('\n');
    }
    text
}

/// Where C++ `text` names `ident` (as a whole identifier): the byte offsets.
fn cpp_uses(text: &str, ident: &str) -> Vec<usize> {
    text.match_indices(ident)
        .filter(|(i, _)| {
            let before = text[..*i].chars().next_back();
            let after = text[i + ident.len()..].chars().next();
            !before.is_some_and(is_ident_char) && !after.is_some_and(is_ident_char)
        })
        .map(|(i, _)| i)
        .collect()
}

/// Whether C++ `text` names `ident` (as a whole identifier).
fn cpp_names(text: &str, ident: &str) -> bool {
    !cpp_uses(text, ident).is_empty()
}

/// Whether C++ `text` defines `struct name` (a definition or a declaration).
fn cpp_defines_struct(text: &str, name: &str) -> bool {
    cpp_uses(text, name)
        .into_iter()
        .any(|i| text[..i].trim_end().ends_with("struct"))
}

/// The builtin recipe (ARCHITECTURE.md, "A new builtin"), the parts the sources show: every row's
/// section is a section of the CUDA library with its header; the CPU function is
/// `warp_core::builtins::<name>` and the CUDA one `wp::<name>` in its section (or what that
/// includes); a row differentiated by `adj_<name>` (`Grad::Adjoint`) has its section's adjoint
/// part, `warp_core::adjoint::adj_<name>` and `adj_<name>` in that part. Rows the front end
/// writes out (`lowered`) or emits as an operator (`operator`) have no functions of their own.
#[test]
fn builtin_rows_follow_the_recipe() {
    let rows = builtin_rows();
    assert!(
        rows.len() > 100,
        "read {} builtin rows: has the table moved? (BUILTIN_ROW_CONSTRUCTOR)",
        rows.len()
    );
    let sections = cuda_sections();
    let core = load_crate("warp-core/src/lib.rs");
    let in_core = |module: &str, name: &str| {
        let path: Vec<String> = ["crate", module, name]
            .iter()
            .map(|s| s.to_string())
            .collect();
        matches!(core.resolve_ns(0, &path, 0, true), Some(Found::Item(_)))
    };
    let mut problems = Vec::new();
    for r in &rows {
        let header = format!("wp_{}.h", r.section);
        if !sections.contains_key(&r.section) {
            problems.push(format!(
                "{}: `{}`'s section \"{}\" is not in SECTIONS",
                r.at, r.name, r.section
            ));
        }
        if read_rel(&format!("{CUDA_LIBRARY}/{header}")).is_none() {
            problems.push(format!(
                "{}: `{}`'s section has no {CUDA_LIBRARY}/{header}",
                r.at, r.name
            ));
        }
        if r.facts.iter().any(|f| f == "lowered" || f == "operator") {
            continue;
        }
        // Tile rows: the CPU side is warp-core's `tile` and `block` modules (typed generic
        // functions the block printer names), not `builtins`; the CUDA side is `wp::<name>` in
        // wp_tile.h or one of the tile sections the emitter adds for some rows (`tile_linalg`,
        // `tile_mma`); their adjoints are named by the sweep's tile rules
        // (`middle/adjoint/tiles.rs`: `adj_tile_load1`, ..), held to warp-core by
        // tests/cuda_tile_adjoint_host.rs, not by this recipe.
        if r.section == "tile" {
            let tile_headers: String = sections
                .keys()
                .filter(|s| s.starts_with("tile"))
                .map(|s| cuda_closure(&format!("wp_{s}.h")))
                .collect();
            if !cpp_names(&tile_headers, &r.name) {
                problems.push(format!(
                    "{}: no CUDA function wp::{} in the tile sections' headers",
                    r.at, r.name
                ));
            }
            continue;
        }
        if !in_core("builtins", &r.name) {
            problems.push(format!(
                "{}: no CPU function warp_core::builtins::{}",
                r.at, r.name
            ));
        }
        if !cpp_names(&cuda_closure(&header), &r.name) {
            problems.push(format!(
                "{}: no CUDA function wp::{} in {header} or what it includes",
                r.at, r.name
            ));
        }
        if r.grad != "Adjoint" {
            continue;
        }
        let adj = format!("adj_{}", r.name);
        if !in_core("adjoint", &adj) {
            problems.push(format!(
                "{}: `{}` is differentiated by adj_ but warp_core::adjoint::{adj} is missing",
                r.at, r.name
            ));
        }
        match sections.get(&r.section).and_then(Option::as_ref) {
            None => problems.push(format!(
                "{}: `{}` has an adjoint but its section \"{}\" has no adjoint part (ADJOINT_PARTS)",
                r.at, r.name, r.section
            )),
            Some(part) if !cpp_names(&cuda_closure(part), &adj) => {
                problems.push(format!("{}: no CUDA adjoint wp::{adj} in {part} or what it includes", r.at))
            }
            Some(_) => {}
        }
    }
    assert!(
        problems.is_empty(),
        "the builtin recipe:\n{}",
        problems.join("\n")
    );
}

/// A row of `OBJECTS`: (kind's name, whether a kernel parameter, warp-core's view or state
/// type, the C++ type, the section), with where it is.
#[derive(Debug)]
struct ObjectRow {
    name: String,
    param: bool,
    rust: String,
    cuda: String,
    section: String,
    at: String,
}

fn object_rows() -> Vec<ObjectRow> {
    let t = lex(&read_required(OBJECTS_FILE));
    let mut rows = Vec::new();
    for k in 1..t.len().saturating_sub(2) {
        // Today: `ObjectRow { kind, name: "HashGrid", param: true, rust, cuda, section }`.
        if t[k].is("ObjectRow") && t[k + 1].is("{") && !t[k - 1].is("struct") {
            let close = matching(&t, k + 1);
            let field = |name: &str| {
                (k + 2..close)
                    .find(|&f| t[f].is(name) && t[f + 1].is(":"))
                    .map(|f| {
                        t[f + 2]
                            .str_value()
                            .map_or_else(|| t[f + 2].text.clone(), str::to_string)
                    })
                    .unwrap_or_default()
            };
            if field("name").starts_with(|c: char| c.is_ascii_uppercase()) {
                rows.push(ObjectRow {
                    name: field("name"),
                    param: field("param") == "true",
                    rust: field("rust"),
                    cuda: field("cuda"),
                    section: field("section"),
                    at: format!("{OBJECTS_FILE}:{}", t[k].line),
                });
            }
        }
        // One row per kind in a macro (`object_kinds! { HashGrid: param, "HashGridView",
        // "wp::hash_grid_t", "hash_grid"; .. }`): the kind, its role, three strings.
        if t[k].is(OBJECT_ROWS_MACRO) && t[k + 1].is("!") && t[k + 2].is("{") && !t[k - 1].is("!") {
            let close = matching(&t, k + 2);
            let mut a = k + 3;
            while a < close {
                let end = (a..close).find(|&e| t[e].is(";")).unwrap_or(close);
                let row = &t[a..end];
                let strings: Vec<&str> = row.iter().filter_map(Tok::str_value).collect();
                let colon = row.iter().position(|x| x.is(":"));
                if let (Some(c), [rust, cuda, section]) = (colon, strings.as_slice()) {
                    rows.push(ObjectRow {
                        name: row[0].text.clone(), // `Volume(VolumeElem): ..`: the kind
                        param: row[c + 1].is("param"),
                        rust: rust.to_string(),
                        cuda: cuda.to_string(),
                        section: section.to_string(),
                        at: format!("{OBJECTS_FILE}:{}", row[0].line),
                    });
                }
                a = end + 1;
            }
        }
    }
    rows
}

/// The types a crate's non-test code implements `trait_name` for (`impl<..> Trait<..> for
/// Type<..>`, the type's last path segment).
fn impls_of(c: &Crate, trait_name: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for src in c.files.values() {
        let t = &src.toks;
        let in_test = |k: usize| src.test_ranges.iter().any(|&(a, b)| a <= k && k < b);
        for f in 1..t.len().saturating_sub(1) {
            if !t[f].is("for") || in_test(f) {
                continue;
            }
            // The trait: the identifier before `for`, past its generic arguments.
            let mut b = f - 1;
            if t[b].is(">") {
                let mut depth = 0;
                while b > 0 {
                    if t[b].is(">") {
                        depth += 1;
                    } else if t[b].is("<") {
                        depth -= 1;
                        if depth == 0 {
                            break;
                        }
                    }
                    b -= 1;
                }
                b = b.saturating_sub(1);
            }
            if !t[b].is(trait_name) {
                continue;
            }
            let is_impl = (0..b)
                .rev()
                .take_while(|&k| !t[k].is("{") && !t[k].is(";") && !t[k].is("}"))
                .any(|k| t[k].is("impl"));
            if !is_impl {
                continue;
            }
            // The type: the last segment of the path after `for`.
            let mut e = f + 1;
            let mut ty = None;
            while e < t.len() && !t[e].is("<") && !t[e].is("{") && !t[e].is("where") {
                if t[e].ident()
                    && !["mut", "dyn", "crate", "self", "super"].contains(&t[e].text.as_str())
                {
                    ty = Some(t[e].text.clone());
                }
                e += 1;
            }
            out.extend(ty);
        }
    }
    // Impls a macro of the crate writes for the types its calls name (`no_gradient!(HashGridView
    // = ..)` over `impl Adjoint for $t`): a type at the head of an argument.
    let mut makers = BTreeSet::new();
    for src in c.files.values() {
        let t = &src.toks;
        for k in 0..t.len().saturating_sub(3) {
            if t[k].is("macro_rules") && t[k + 1].is("!") && t[k + 3].is("{") {
                let body = &t[k + 3..matching(t, k + 3)];
                let writes = body
                    .windows(3)
                    .any(|w| w[0].is(trait_name) && w[1].is("for") && w[2].is("$"));
                if writes {
                    makers.insert(t[k + 2].text.clone());
                }
            }
        }
    }
    for src in c.files.values() {
        let t = &src.toks;
        let in_test = |k: usize| src.test_ranges.iter().any(|&(a, b)| a <= k && k < b);
        for k in 1..t.len().saturating_sub(2) {
            if !(makers.contains(&t[k].text) && t[k + 1].is("!") && !t[k - 1].is("!")) || in_test(k)
            {
                continue;
            }
            let close = matching(t, k + 2);
            for w in t[k + 2..close].windows(3) {
                let head = w[0].is("(") || w[0].is(",") || w[0].is("]") || w[0].is("{");
                let tail = w[2].is("=") || w[2].is("<") || w[2].is(",") || w[2].is(")");
                if head
                    && tail
                    && w[1].ident()
                    && w[1].text.starts_with(|c: char| c.is_ascii_uppercase())
                {
                    out.insert(w[1].text.clone());
                }
            }
        }
    }
    out
}

/// The host-object recipe (ARCHITECTURE.md, "A new kernel-visible host object"), the parts the
/// sources show, for every kind of `OBJECTS` (objects and their query states): its section is
/// a section of the CUDA library, whose header (or what it includes) defines its C++ type; its
/// view or state is `warp_core::objects::<rust>` with an `Adjoint` impl (a zero placeholder);
/// and for a kind a kernel takes as a parameter: the host type
/// `warp_runtime::objects::<name>` implementing `KernelArg`, builtin rows of its section (a
/// kernel sees it only through them), and its suite tests `tests/suite/<name>.rs`.
#[test]
fn host_objects_follow_the_recipe() {
    let rows = object_rows();
    assert!(
        rows.len() >= 4,
        "read {} OBJECTS rows: has the table moved? (OBJECTS_FILE)",
        rows.len()
    );
    let sections = cuda_sections();
    let builtin_sections: BTreeSet<String> =
        builtin_rows().into_iter().map(|r| r.section).collect();
    let core = load_crate("warp-core/src/lib.rs");
    let runtime = load_crate("warp-runtime/src/lib.rs");
    let core_adjoint = impls_of(&core, "Adjoint");
    // `KernelArg` directly, or through the host-object seam whose blanket impl gives it.
    let kernel_args: BTreeSet<String> = ["KernelArg", "HostObject"]
        .iter()
        .flat_map(|t| impls_of(&runtime, t))
        .collect();
    let item = |c: &Crate, path: &[&str]| {
        let path: Vec<String> = path.iter().map(|s| s.to_string()).collect();
        matches!(c.resolve(0, &path, 0), Some(Found::Item(_)))
    };
    let mut problems = Vec::new();
    for r in &rows {
        let header = format!("wp_{}.h", r.section);
        if !sections.contains_key(&r.section) {
            problems.push(format!(
                "{}: {}'s section \"{}\" is not in SECTIONS",
                r.at, r.name, r.section
            ));
        }
        let cpp = cuda_closure(&header);
        if cpp.is_empty() {
            problems.push(format!(
                "{}: {} has no header {CUDA_LIBRARY}/{header}",
                r.at, r.name
            ));
        }
        let cpp_type = r.cuda.trim_start_matches("wp::");
        if !cpp_defines_struct(&cpp, cpp_type) {
            problems.push(format!(
                "{}: {header} (or what it includes) defines no `struct {cpp_type}`",
                r.at
            ));
        }
        if !item(&core, &["crate", "objects", &r.rust]) {
            problems.push(format!("{}: no warp_core::objects::{}", r.at, r.rust));
        }
        if !core_adjoint.contains(&r.rust) {
            problems.push(format!(
                "{}: warp-core has no `Adjoint` impl for {}",
                r.at, r.rust
            ));
        }
        if !r.param {
            continue;
        }
        if !item(&runtime, &["crate", "objects", &r.name]) {
            problems.push(format!(
                "{}: no host type warp_runtime::objects::{}",
                r.at, r.name
            ));
        }
        if !kernel_args.contains(&r.name) {
            problems.push(format!(
                "{}: warp-runtime has no `KernelArg` (or `HostObject`) impl for {}",
                r.at, r.name
            ));
        }
        if !builtin_sections.contains(&r.section) {
            problems.push(format!(
                "{}: no builtin row of section \"{}\" takes {}",
                r.at, r.section, r.name
            ));
        }
        let suite = format!("tests/suite/{}.rs", snake_case(&r.name));
        if read_rel(&suite).is_none() {
            problems.push(format!("{}: {} has no suite tests {suite}", r.at, r.name));
        }
    }
    assert!(
        problems.is_empty(),
        "the host-object recipe:\n{}",
        problems.join("\n")
    );
}

/// `HashGrid` -> `hash_grid`.
fn snake_case(name: &str) -> String {
    let mut out = String::new();
    for (i, c) in name.chars().enumerate() {
        if c.is_uppercase() && i > 0 {
            out.push('_');
        }
        out.extend(c.to_lowercase());
    }
    out
}

// ---------------------------------------------------------------------------------------------
// ARCHITECTURE.md's `Backend` block against `warp-runtime/src/backend.rs`
// ---------------------------------------------------------------------------------------------

/// The names of the `fn`s between `start` and the brace that closes the item opened on its
/// line (a trait's methods), in order.
fn trait_methods(text: &str, start: &str) -> Vec<String> {
    let Some(at) = text.find(start) else {
        return Vec::new();
    };
    let body = &text[at..];
    let (mut depth, mut end) = (0i32, body.len());
    for (i, c) in body.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => {
                depth -= 1;
                if depth == 0 {
                    end = i;
                    break;
                }
            }
            _ => {}
        }
    }
    body[..end]
        .lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .filter_map(|l| {
            let rest = l.trim_start().strip_prefix("fn ")?;
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            (!name.is_empty()).then_some(name)
        })
        .collect()
}

/// The code block ARCHITECTURE.md shows of the backend seam names every method of the trait,
/// and no other: it was out of date once (review of 2026-11-28), and it is what a second
/// backend's author reads first.
#[test]
fn the_backend_block_names_every_method() {
    let code = read_required("warp-runtime/src/backend.rs");
    let doc = read_required("ARCHITECTURE.md");
    let start = "pub(crate) trait Backend {";
    let in_code = trait_methods(&code, start);
    let in_doc = trait_methods(&doc, start);
    assert!(
        in_code.len() > 5,
        "read {} methods of Backend in backend.rs: has the trait moved?",
        in_code.len()
    );
    let (mut c, mut d) = (in_code.clone(), in_doc.clone());
    c.sort();
    d.sort();
    assert_eq!(
        d, c,
        "ARCHITECTURE.md's `Backend` block names {in_doc:?}, backend.rs has {in_code:?}"
    );
}
