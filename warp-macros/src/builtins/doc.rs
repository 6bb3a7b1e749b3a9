//! docs/book/src/builtins.md held to the builtin table (the page's "How this page is kept true" says
//! what is generated and what is checked, and why).
//!
//! Generated: the section "The builtin table" (from [`BUILTINS`]) and the Summary counts
//! (from the page's own group tables), and the two counts README.md quotes. Without
//! `WARP_LANG_BLESS=1` a stale one fails the test; with it the test rewrites it.
//! Checked, in both directions: the names in the group tables against the table's rows.

use super::{Builtin, Draw, Emit, Grad, Pos, Tangent, BUILTINS};
use crate::types::{Scalar, Ty};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Warp builtins that are language constructs here, not rows of the builtin table: the group
/// tables may call them supported (or different), and the check knows them by this list.
const CONSTRUCTS: &[&str] = &[
    // Operators and assignments.
    "add",
    "sub",
    "mul",
    "div",
    "floordiv",
    "neg",
    "unot",
    "invert",
    "bit_and",
    "bit_or",
    "bit_xor",
    "lshift",
    "rshift",
    "copy",
    "assign",
    "array_store",
    "assign_inplace",
    "assign_copy",
    "add_inplace",
    "sub_inplace",
    "bit_and_inplace",
    "bit_or_inplace",
    "bit_xor_inplace",
    "transform_add_inplace",
    "transform_sub_inplace",
    "transform_set_translation",
    "transform_set_rotation",
    "transform_set_translation_copy",
    "transform_set_rotation_copy",
    // glam's constructors and constants.
    "vector",
    "matrix",
    "matrix_from_cols",
    "matrix_from_rows",
    "identity",
    "quaternion",
    "quat_identity",
    "transform_identity",
    // Control flow, loops, indexing and views.
    "where",
    "range",
    "reversed",
    "iter_next",
    "extract",
    "index",
    "len",
    "view",
    "slice",
    // A fixed-size local array (`front::lower::local_arrays`): Rust's `[0.0f32; N]`.
    "zeros",
    // A tuple (`ir::Op::Tuple`): Rust's `(a, b)`.
    "tuple",
    // Calls and macros the front end lowers by name (`front::lower`): the thread index,
    // print!, and Warp's builtins that are other operations here.
    "tid",
    "print",
    "printf",
    "sample_cdf",
    "div_approx",
    "inverse_approx",
    // A `for` loop over a query (`front::lower::query`) is Warp's `*_query_next` loop.
    "hash_grid_query_next",
    "bvh_query_next",
    "mesh_query_aabb_next",
    // The volume rows typed by the parameter's `Volume<T>` are Warp's per-type spellings.
    "volume_sample_f",
    "volume_sample_v",
    "volume_sample_i",
    "volume_sample_grad_f",
    "volume_lookup_f",
    "volume_lookup_v",
    "volume_lookup_i",
    "volume_store_f",
    "volume_store_v",
    "volume_store_i",
];

const BLESS: &str = "WARP_LANG_BLESS";

fn repo_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(name)
}

fn read(name: &str) -> String {
    std::fs::read_to_string(repo_file(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// One row of a group table (`| Warp builtin | here | notes |`).
struct Row {
    group: String,
    /// The builtins the row names: the backquoted names of its first cell, before any
    /// parenthesis that says which overloads it is about (none for a row named by prose).
    names: Vec<String>,
    /// How many builtins the Summary counts for it: one per name, and one for a row named by
    /// prose (the scalar conversions: one hidden builtin per type, counted once).
    count: usize,
    here: String,
    notes: String,
}

/// The group tables of the page, and each group's introduction (the text between its heading
/// and its table).
fn group_tables(doc: &str) -> (Vec<Row>, Vec<(String, String)>) {
    let mut rows = Vec::new();
    let mut intros: Vec<(String, String)> = Vec::new();
    let mut in_table = false;
    for line in doc.lines() {
        if let Some(title) = line
            .strip_prefix("## ")
            .or_else(|| line.strip_prefix("### "))
        {
            intros.push((title.to_string(), String::new()));
            in_table = false;
            continue;
        }
        let Some((group, intro)) = intros.last_mut() else {
            continue;
        };
        if line.starts_with("| Warp builtin | here | notes |") {
            in_table = true;
            continue;
        }
        if !line.starts_with('|') {
            if rows.iter().all(|r: &Row| r.group != *group) {
                intro.push_str(line);
                intro.push('\n');
            }
            in_table = false;
            continue;
        }
        if !in_table || line.starts_with("|---") {
            continue;
        }
        let cells = split_cells(line);
        assert_eq!(cells.len(), 3, "a group table row has 3 cells: {line}");
        // A row named by prose (the scalar conversions) quotes examples, not names.
        let by_name = cells[0].starts_with('`');
        let head = cells[0].split(" (").next().unwrap_or_default();
        let names: Vec<String> = head
            .split('`')
            .skip(1)
            .step_by(2)
            .filter(|_| by_name)
            .map(str::to_string)
            .collect();
        let count = if by_name { names.len() } else { 1 };
        let here = cells[1].clone();
        assert!(
            ["supported", "different", "not yet", "not planned"].contains(&here.as_str()),
            "`{here}` is no state a row can be in: {line}"
        );
        rows.push(Row {
            group: group.clone(),
            names,
            count,
            here,
            notes: cells[2].clone(),
        });
    }
    (rows, intros)
}

/// The cells of a markdown table row (`\|` is a `|` inside a cell).
fn split_cells(line: &str) -> Vec<String> {
    let inner = line.trim().trim_start_matches('|').trim_end_matches('|');
    let mut cells = vec![String::new()];
    let mut chars = inner.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '\\' if chars.peek() == Some(&'|') => {
                cells.last_mut().expect("a cell").push_str("\\|");
                chars.next();
            }
            '|' => cells.push(String::new()),
            c => cells.last_mut().expect("a cell").push(c),
        }
    }
    cells.iter().map(|c| c.trim().to_string()).collect()
}

const STATES: [&str; 4] = ["supported", "different", "not yet", "not planned"];

/// Builtins per group and state, in the order of the groups on the page; the last entry is
/// the total.
fn counts(rows: &[Row]) -> Vec<(String, [usize; 4])> {
    let mut out: Vec<(String, [usize; 4])> = Vec::new();
    for r in rows {
        if out.last().is_none_or(|(g, _)| *g != r.group) {
            out.push((r.group.clone(), [0; 4]));
        }
        let k = STATES.iter().position(|s| *s == r.here).expect("a state");
        out.last_mut().expect("a group").1[k] += r.count;
    }
    let mut all = [0; 4];
    for (_, c) in &out {
        for k in 0..4 {
            all[k] += c[k];
        }
    }
    out.push(("all".to_string(), all));
    out
}

fn summary_table(counts: &[(String, [usize; 4])]) -> String {
    let mut t = String::from(
        "| group | supported | different | not yet | not planned |\n|---|---|---|---|---|\n",
    );
    for (group, c) in counts {
        if group == "all" {
            t += &format!(
                "| **all** | **{}** | **{}** | **{}** | **{}** |\n",
                c[0], c[1], c[2], c[3]
            );
        } else {
            t += &format!("| {group} | {} | {} | {} | {} |\n", c[0], c[1], c[2], c[3]);
        }
    }
    t
}

/// A signature position as the generated table writes it (the section's legend).
fn pos(p: &Pos) -> String {
    match p {
        Pos::T => "T".into(),
        Pos::ScalarOfT => "S".into(),
        Pos::ArrayOfT => "Array<T>".into(),
        Pos::Index => "index".into(),
        Pos::Bool => "bool".into(),
        Pos::MatOfT => "Mat(T)".into(),
        Pos::VecOfT => "Vec(T)".into(),
        Pos::QuatOfT => "Quat(S)".into(),
        Pos::IntOfT => "Int(T)".into(),
        Pos::Fixed(s) => s.name().into(),
        Pos::FixedVec(s, n) => Ty::Vector(*s, *n).to_string(),
        Pos::Vec3OfT => "Vec3(S)".into(),
        Pos::XformOfT => "Transform(S)".into(),
        Pos::SVecOfT => "SpatialVector(S)".into(),
        Pos::SMatOfT => "SpatialMatrix(S)".into(),
        Pos::TransposeOfT => "Transpose(T)".into(),
        Pos::AnyVecOfT => "U".into(),
        Pos::OuterOfT => "Mat(T, U)".into(),
        Pos::Mat4OfT => "Mat4(S)".into(),
        Pos::Tuple(ps) => format!("({})", ps.iter().map(pos).collect::<Vec<_>>().join(", ")),
        Pos::Object(k) => k.row().name.into(),
        Pos::VolumeOfT => "Volume<T>".into(),
        Pos::AnyVolume => "Volume<_>".into(),
        Pos::VolumeGradOfT => "Grad(T)".into(),
        Pos::BsrOfT => "Bsr<T>".into(),
        Pos::AnyBsr => "Bsr<_>".into(),
        Pos::Unit => "()".into(),
        Pos::Tile => "Tile<T>".into(),
        Pos::TileShape => "shape".into(),
        Pos::Offsets => "offsets".into(),
        Pos::TileFn => "fn".into(),
    }
}

fn signature(b: &Builtin) -> String {
    let params: Vec<String> = b
        .params
        .iter()
        .enumerate()
        .map(|(i, p)| match (i, b.draw) {
            // A draw takes the generator state by `&mut` and advances it.
            (0, Some(_)) => format!("&mut {}", pos(p)),
            _ => pos(p),
        })
        .collect();
    format!("({}) -> {}", params.join(", "), pos(&b.ret))
}

/// The other ways to write a call of `b`, and what else a call may leave out.
fn spellings(b: &Builtin) -> Vec<String> {
    let mut out = Vec::new();
    let call = |name: &str| {
        if b.params.len() == 1 {
            format!("`x.{name}()`")
        } else {
            format!("`x.{name}(..)`")
        }
    };
    if b.method {
        out.push(call(b.name));
    }
    out.extend(b.aliases.iter().map(|a| call(a)));
    if let Some((class, f)) = b.ctor {
        // Name the constructor on the first glam type of its class.
        let ty = [
            Ty::Quat(Scalar::F32),
            Ty::Matrix(Scalar::F32, 3),
            Ty::Transform(Scalar::F32),
            Ty::SpatialVector(Scalar::F32),
        ]
        .into_iter()
        .find(|t| class.admits(t))
        .expect("a glam type of the constructor's class");
        out.push(format!("`{ty}::{f}(..)`"));
    }
    if let (Some((name, n)), false) = (b.overload, b.internal) {
        let s = if n == 1 { "" } else { "s" };
        out.push(format!("`{name}` with {n} argument{s}"));
    }
    if b.extension {
        out.push("not in Warp".to_string());
    }
    if let Some(lit) = b.default_last {
        out.push(format!("last argument defaults to `{lit}`"));
    }
    if let Some(results) = b.results {
        out.push(format!("`let {results} = {}(..);`", b.name));
    }
    if let Emit::Operator(op) = b.emit {
        out.push(format!("`a {} b`", op.symbol()));
    }
    if let Some(it) = b.iterate {
        let item = super::lookup(it.item).expect("the item row");
        out.push(format!(
            "only as `for j in {}(..)`, `j: {}`",
            b.name,
            pos(&item.ret)
        ));
    }
    match b.draw {
        Some(Draw::Steps(k)) => {
            let s = if k == 1 { "" } else { "s" };
            out.push(format!("advances the state {k} step{s}"));
        }
        Some(Draw::NextState(row)) => out.push(format!("advances the state to `{row}`")),
        None => {}
    }
    out
}

fn builtin_table() -> String {
    let mut t = String::from(concat!(
        "| builtin | signature | `T` is | also | gradient | forward mode |\n",
        "|---|---|---|---|---|---|\n",
    ));
    // The rows user code reaches: by their names, or as an overload by arity of another.
    for b in BUILTINS
        .iter()
        .filter(|b| !b.internal || b.overload.is_some())
    {
        let name = match (b.internal, b.overload) {
            (true, Some((name, n))) => format!("`{name}` ({n} arguments)"),
            _ => format!("`{}`", b.name),
        };
        let classes: Vec<&str> = b.classes.iter().map(|c| c.describe()).collect();
        let grad = match b.grad {
            // Backward through the other tile rows is refused (`middle::adjoint::tiles`).
            Grad::Adjoint | Grad::Atomic if b.is_tile() => {
                crate::middle::adjoint::tile_adjoint(b.name).unwrap_or("not yet")
            }
            Grad::Adjoint => "adjoint",
            Grad::Zero => "zero",
            Grad::Atomic => "atomic",
            Grad::AtomicNone => "none",
            Grad::Effect => "none (a store)",
            Grad::NotYet => "not yet",
        };
        t += &format!(
            "| {name} | `{}` | {} | {} | {grad} | {} |\n",
            signature(b),
            if classes.is_empty() {
                "-".to_string()
            } else {
                classes.join("; ")
            },
            spellings(b).join("; "),
            forward(b),
        );
    }
    t
}

/// The forward-mode column: whether `wp::jvp` differentiates a call (the row's [`Tangent`]).
fn forward(b: &Builtin) -> String {
    match (b.grad, b.emit, b.tangent) {
        (Grad::Zero, ..) => "zero".into(),
        (_, Emit::Operator(op), _) => format!("as `{}`", op.symbol()),
        (_, _, Some(Tangent::Rule(_) | Tangent::Select(_) | Tangent::Atomic)) => "yes".into(),
        (_, _, Some(Tangent::RuleFor(classes, _))) => {
            let of: Vec<&str> = classes.iter().map(|c| c.describe()).collect();
            format!("for {}", of.join("; "))
        }
        (_, _, Some(Tangent::NoRule) | None) => "not yet".into(),
    }
}

/// Replaces what stands between the markers of generated region `name`.
fn regenerate(doc: &str, name: &str, body: &str) -> String {
    let begin = format!("<!-- generated: {name} -->\n");
    let end = format!("<!-- end generated: {name} -->");
    let start = doc
        .find(&begin)
        .unwrap_or_else(|| panic!("docs/book/src/builtins.md has no `{}`", begin.trim()))
        + begin.len();
    let stop = start
        + doc[start..]
            .find(&end)
            .unwrap_or_else(|| panic!("docs/book/src/builtins.md has no `{end}`"));
    format!("{}{body}{}", &doc[..start], &doc[stop..])
}

/// README.md's sentence with the counts of supported and different builtins.
fn readme_with(readme: &str, supported: usize, different: usize) -> String {
    let (before, rest) = readme
        .split_once(" of Warp's builtins supported and ")
        .expect("README.md quotes the supported count: `N of Warp's builtins supported and M`");
    let head = before.trim_end_matches(|c: char| c.is_ascii_digit());
    let tail = rest.trim_start_matches(|c: char| c.is_ascii_digit());
    format!("{head}{supported} of Warp's builtins supported and {different}{tail}")
}

/// Compares a file with what it should be; with `WARP_LANG_BLESS=1`, rewrites it instead.
/// Returns what is stale.
fn check_or_bless(name: &str, have: &str, want: &str) -> Option<String> {
    if have == want {
        return None;
    }
    if std::env::var(BLESS).is_ok_and(|v| v == "1") {
        // Whole or not at all: the other doc test may be reading the file.
        let path = repo_file(name);
        let tmp = path.with_extension("md.bless");
        std::fs::write(&tmp, want).expect("write");
        std::fs::rename(&tmp, &path).expect("rename");
        return None;
    }
    let line = have
        .lines()
        .zip(want.lines())
        .position(|(a, b)| a != b)
        .unwrap_or_else(|| have.lines().count().min(want.lines().count()));
    Some(format!(
        "{name} is stale from line {}: it has\n  {}\nwhere the test computes\n  {}",
        line + 1,
        have.lines().nth(line).unwrap_or("(the end)"),
        want.lines().nth(line).unwrap_or("(the end)"),
    ))
}

#[test]
fn generated_parts_are_current() {
    let doc = read("docs/book/src/builtins.md");
    let (rows, _) = group_tables(&doc);
    let counts = counts(&rows);
    let want = regenerate(&doc, "builtin table", &builtin_table());
    let want = regenerate(&want, "summary", &summary_table(&counts));
    let all = counts.last().expect("the total").1;
    let readme = read("README.md");
    let stale: Vec<String> = [
        check_or_bless("docs/book/src/builtins.md", &doc, &want),
        check_or_bless("README.md", &readme, &readme_with(&readme, all[0], all[1])),
    ]
    .into_iter()
    .flatten()
    .collect();
    assert!(
        stale.is_empty(),
        "{}\nRewrite with {BLESS}=1 cargo test -p warp-macros",
        stale.join("\n")
    );
}

#[test]
fn group_tables_agree_with_the_table() {
    let doc = read("docs/book/src/builtins.md");
    let (rows, intros) = group_tables(&doc);
    let callable: Vec<&Builtin> = BUILTINS.iter().filter(|b| !b.internal).collect();
    let warp_names: BTreeSet<&str> = callable.iter().filter_map(|b| b.warp_name()).collect();
    let available = |r: &Row| r.here == "supported" || r.here == "different";
    let named: BTreeSet<&str> = rows
        .iter()
        .filter(|r| available(r))
        .flat_map(|r| r.names.iter().map(String::as_str))
        .collect();
    let mut problems = Vec::new();
    for b in &callable {
        match b.warp_name() {
            Some(w) if !named.contains(w) => problems.push(format!(
                "`{}` is in the builtin table, but no supported or different row names `{w}`",
                b.name
            )),
            None if !extensions(&doc).contains(&format!("`{}(", b.name)) => problems.push(format!(
                "`{}` is an extension, but \"Extensions\" does not list it",
                b.name
            )),
            _ => {}
        }
    }
    for r in &rows {
        for n in &r.names {
            let known = warp_names.contains(n.as_str()) || CONSTRUCTS.contains(&n.as_str());
            if available(r) && !known {
                problems.push(format!(
                    "{}: `{n}` is called {}, but it is neither a row of the builtin table nor a \
                     construct the check knows (CONSTRUCTS in builtins/doc.rs)",
                    r.group, r.here
                ));
            }
            if !available(r) && warp_names.contains(n.as_str()) {
                problems.push(format!(
                    "{}: `{n}` is called {}, but the builtin table has it",
                    r.group, r.here
                ));
            }
        }
        // The page promises an adjoint for every supported builtin unless the row (or its
        // group) says otherwise: the table's zero-gradient rows must be said to be.
        let rows_of: Vec<&&Builtin> = callable
            .iter()
            .filter(|b| {
                b.warp_name()
                    .is_some_and(|w| r.names.iter().any(|n| n == w))
            })
            .collect();
        let said =
            |text: &str| text.contains("zero gradient") || text.contains("not differentiable");
        let intro = &intros
            .iter()
            .find(|(g, _)| *g == r.group)
            .expect("a group")
            .1;
        if available(r)
            && !rows_of.is_empty()
            && rows_of.iter().all(|b| b.grad == Grad::Zero)
            && !said(&r.notes)
            && !said(intro)
        {
            problems.push(format!(
                "{}: `{}`: zero gradient in the builtin table, but the row does not say so",
                r.group,
                r.names.join("`, `")
            ));
        }
    }
    for c in CONSTRUCTS {
        if !named.contains(c) {
            problems.push(format!(
                "construct `{c}`: no supported or different row names it"
            ));
        }
        if warp_names.contains(c) {
            problems.push(format!("construct `{c}` is a row of the builtin table now"));
        }
    }
    assert!(
        problems.is_empty(),
        "docs/book/src/builtins.md and the builtin table disagree:\n{}",
        problems.join("\n")
    );
}

/// The section "Extensions (not in Warp)".
fn extensions(doc: &str) -> &str {
    let start = doc
        .find("## Extensions (not in Warp)")
        .expect("an Extensions section");
    let rest = &doc[start + 3..];
    &doc[start..start + 3 + rest.find("\n## ").unwrap_or(rest.len())]
}

#[test]
fn the_counts_follow_the_rule() {
    let doc = "## A\n\n| Warp builtin | here | notes |\n|---|---|---|\n\
               | `a`, `b` (vectors) | supported | x \\| y |\n\
               | scalar conversions `f(x)`, `g(x)` | different | one |\n\
               ## B\n\n| Warp builtin | here | notes |\n|---|---|---|\n\
               | `c` | not planned | z |\n";
    let (rows, _) = group_tables(doc);
    assert_eq!(rows[0].names, ["a", "b"]);
    assert_eq!(rows[0].notes, "x \\| y");
    let c = counts(&rows);
    assert_eq!(c[0], ("A".to_string(), [2, 1, 0, 0]));
    assert_eq!(c[2], ("all".to_string(), [2, 1, 0, 1]));
    assert_eq!(
        readme_with("done: 1 of Warp's builtins supported and 2 with", 172, 24),
        "done: 172 of Warp's builtins supported and 24 with"
    );
}
