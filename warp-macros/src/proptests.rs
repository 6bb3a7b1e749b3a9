//! Property tests of the front end: malformed kernels and funcs fed to the macros' entries
//! (`expand::kernel`, `expand::func`, over `proc_macro2` token streams, as the proc macros
//! call them). Whatever the input, the expansion must come back, within a time bound, either
//! as code or as `compile_error!` tokens (a `syn::Error` with a span and a message): never a
//! panic (which rustc reports as an internal "proc macro panicked" with no useful span), never
//! a hang.
//!
//! Inputs: random token soups built from Rust fragments inside a kernel body, valid kernels
//! truncated at a random character or with one token replaced, expression trees over
//! mistyped operands and unknown builtins, literals of every suffix and magnitude (out of
//! range ones must be errors), and deeply nested expressions.
//!
//! `PROPTEST_CASES` sets the number of cases per property (proptest's own variable); the
//! default here is modest so that `cargo test -p warp-macros` stays quick in a debug build.

use crate::expand;
use proc_macro2::TokenStream;
use proptest::prelude::*;
use proptest::test_runner::Config;
use std::str::FromStr;
use std::sync::mpsc;
use std::time::Duration;

/// The most one expansion may take before the property calls it a hang. Debug builds of the
/// emitters are slow on large inputs, but no input here is large: ten seconds is a hang.
const TIME_LIMIT: Duration = Duration::from_secs(10);

/// The stack an expansion runs on: rustc runs proc macros on a thread with (at least) this
/// much, so recursion depth is judged against what a real build has, not the test harness's
/// 2 MiB threads.
const MACRO_STACK: usize = 8 << 20;

/// Cases per property unless `PROPTEST_CASES` says otherwise.
fn config(default_cases: u32) -> Config {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default_cases);
    Config {
        cases,
        // No regression files for a proc-macro crate's unit tests: a failing seed is printed
        // and belongs in a plain #[test] below.
        failure_persistence: None,
        ..Config::default()
    }
}

/// Which macro an input goes to.
#[derive(Clone, Copy, Debug)]
enum Entry {
    Kernel,
    Func,
}

/// What an expansion came to.
#[derive(Debug)]
enum Outcome {
    /// Code without errors.
    Accepted,
    /// The messages of its `compile_error!`s.
    Rejected(Vec<String>),
}

/// Expands `source` (a whole `fn` item) with `entry`, on a thread of its own with rustc's
/// stack, and fails on a panic or when it takes longer than [`TIME_LIMIT`]. `None` when the
/// source is not even a token stream (unbalanced delimiters, a bad character): rustc's lexer
/// rejects that before any macro runs.
fn expand(entry: Entry, attr: &str, source: &str) -> Result<Option<Outcome>, TestCaseError> {
    if TokenStream::from_str(source).is_err() || TokenStream::from_str(attr).is_err() {
        return Ok(None);
    }
    let (attr, source) = (attr.to_string(), source.to_string());
    let (tx, rx) = mpsc::channel();
    let name = format!("{entry:?} {source}");
    std::thread::Builder::new()
        .stack_size(MACRO_STACK)
        .spawn(move || {
            // Token streams are not Send: parse them on this thread.
            let attr = TokenStream::from_str(&attr).unwrap();
            let item = TokenStream::from_str(&source).unwrap();
            let out = std::panic::catch_unwind(move || {
                match entry {
                    Entry::Kernel => expand::kernel(attr, item),
                    Entry::Func => expand::func(attr, item),
                }
                .to_string()
            });
            let _ = tx.send(out.map_err(|p| panic_message(&p)));
        })
        .expect("spawn an expansion thread");
    match rx.recv_timeout(TIME_LIMIT) {
        Ok(Ok(out)) => Ok(Some(outcome(&out))),
        Ok(Err(msg)) => Err(TestCaseError::fail(format!(
            "the front end panicked ({msg}) on:\n{name}"
        ))),
        Err(_) => Err(TestCaseError::fail(format!(
            "the front end took over {TIME_LIMIT:?} (or died) on:\n{name}"
        ))),
    }
}

fn panic_message(p: &Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<String>()
        .cloned()
        .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "a non-string panic".into())
}

/// Reads the `compile_error!` messages out of an expansion. `syn::Error::to_compile_error`
/// writes `:: core :: compile_error ! { "message" }`.
fn outcome(out: &str) -> Outcome {
    let mut messages = Vec::new();
    let mut rest = out;
    while let Some(at) = rest.find("compile_error ! {") {
        rest = &rest[at + "compile_error ! {".len()..];
        let end = rest.find('}').unwrap_or(rest.len());
        messages.push(rest[..end].trim().to_string());
    }
    if messages.is_empty() {
        Outcome::Accepted
    } else {
        Outcome::Rejected(messages)
    }
}

/// Expands and requires a clear result: `Ok` either way, and an error's messages non-empty.
fn check(entry: Entry, source: &str) -> Result<Option<Outcome>, TestCaseError> {
    let out = expand(entry, "", source)?;
    if let Some(Outcome::Rejected(msgs)) = &out {
        for m in msgs {
            // A message is a string literal: more than its quotes.
            prop_assert!(
                m.len() > 2,
                "an empty error message for:\n{source}\n{msgs:?}"
            );
        }
    }
    Ok(out)
}

/// Expands and requires a rejection (for inputs that are nonsense by the language's rules).
fn check_rejected(entry: Entry, source: &str) -> Result<Vec<String>, TestCaseError> {
    match check(entry, source)? {
        Some(Outcome::Rejected(msgs)) => Ok(msgs),
        Some(Outcome::Accepted) => Err(TestCaseError::fail(format!(
            "accepted what must be an error:\n{source}"
        ))),
        None => Err(TestCaseError::fail(format!(
            "not a token stream:\n{source}"
        ))),
    }
}

/// The kernel every body is put in: parameters of several types to refer to.
fn kernel_with_body(body: &str) -> String {
    format!(
        "fn k(a: Array<f32>, b: Array<Vec3, 2>, m: Array<Mat33>, n: Array<i32>, x: f32, \
         y: f64, h: f16, u: u8, v: Vec3, q: Quat) {{ let i = tid(); {body} }}"
    )
}

// ---------------------------------------------------------------------------------------------
// Generators

/// Pieces of Rust (and of the kernel language) that token soups are made of.
const ATOMS: &[&str] = &[
    "let",
    "mut",
    "if",
    "else",
    "for",
    "in",
    "while",
    "loop",
    "break",
    "continue",
    "return",
    "fn",
    "as",
    "match",
    "struct",
    "unsafe",
    "move",
    "ref",
    "self",
    "Self",
    "crate",
    "super",
    "impl",
    "where",
    "dyn",
    "async",
    "await",
    "const",
    "static",
    "type",
    "use",
    "mod",
    "true",
    "false",
    "a",
    "b",
    "m",
    "n",
    "x",
    "y",
    "h",
    "u",
    "v",
    "q",
    "i",
    "j",
    "tid",
    "wp",
    "f32",
    "f64",
    "f16",
    "i32",
    "u8",
    "u32",
    "i64",
    "usize",
    "bool",
    "Vec3",
    "Mat33",
    "Mat3",
    "Quat",
    "Array",
    "Transform",
    "sin",
    "cos",
    "sqrt",
    "dot",
    "cross",
    "min",
    "max",
    "atomic_add",
    "randf",
    "rand_init",
    "hash_grid_query",
    "mesh_query_point",
    "len",
    "shape",
    "view",
    "row",
    "not_a_builtin",
    "printf",
    "print",
    "print!",
    "println!",
    "vec!",
    "format!",
    "=",
    "==",
    "!=",
    "+",
    "-",
    "*",
    "/",
    "%",
    "+=",
    "-=",
    "*=",
    "/=",
    "%=",
    "<",
    ">",
    "<=",
    ">=",
    "<<",
    ">>",
    "&",
    "&&",
    "|",
    "||",
    "^",
    "!",
    "?",
    "..",
    "..=",
    "::",
    ".",
    ",",
    ":",
    ";",
    "->",
    "=>",
    "#",
    "@",
    "$",
    "~",
    "_",
    "'a",
    "0",
    "1",
    "2",
    "-1",
    "0.5",
    "1.0",
    "1e39",
    "1e39f32",
    "1e309",
    "3.4e38",
    "3.5e38",
    "65504.0",
    "65520.0f16",
    "255u8",
    "256u8",
    "2147483648",
    "-2147483649",
    "4294967296u32",
    "0x7fffffff",
    "0xffffffffffffffffffff",
    "1_000",
    "1e-50f32",
    "0.0",
    "f32::MAX",
    "f32::INFINITY",
    "\"s\"",
    "'c'",
    "b'x'",
    "b\"s\"",
    "1u128",
    "1i128",
    "1usize",
    "1isize",
    "1f8",
    "1x",
    "std",
    "String",
    "Vec",
    "Box",
    "None",
    "Some",
    "Ok",
    "Err",
];

/// A token soup: atoms and bracketed groups of soups, `depth` levels deep at most.
fn soup(depth: u32) -> BoxedStrategy<String> {
    let atom = proptest::sample::select(ATOMS).prop_map(str::to_string);
    let leaf = proptest::collection::vec(atom, 0..12).prop_map(|v| v.join(" "));
    leaf.prop_recursive(depth, 48, 6, |inner| {
        prop_oneof![
            proptest::collection::vec(inner.clone(), 1..5).prop_map(|v| v.join(" ")),
            inner.clone().prop_map(|s| format!("( {s} )")),
            inner.clone().prop_map(|s| format!("[ {s} ]")),
            inner.clone().prop_map(|s| format!("{{ {s} }}")),
            (inner.clone(), inner).prop_map(|(a, b)| format!("{a} ; {b}")),
        ]
    })
    .boxed()
}

/// Kernels and funcs that expand without error: the seeds of truncation and mutation.
const VALID: &[&str] = &[
    "fn k(a: Array<f32>, s: f32) { let i = tid(); a[i] = a[i] * s + 1.0; }",
    "fn k(b: Array<Vec3, 2>, v: Vec3) { let (i, j) = tid(); b[(i, j)] = cross(b[(i, j)], v) * 2.0; }",
    "fn k(n: Array<i32>, c: Array<i32>) { let i = tid(); if n[i] % 2 == 0 { atomic_add(c, 0, 1); } else { n[i] = -n[i]; } }",
    "fn k(a: Array<f32>) { let i = tid(); let mut s = 0.0; for j in 0..10 { if j == 3 { continue; } s += a[i] * j as f32; } a[i] = s; }",
    "fn k(m: Array<Mat33>, out: Array<f32>) { let i = tid(); let t = m[i].transpose() * m[i]; out[i] = t.determinant(); }",
    "fn k(a: Array<f64>, seed: u32) { let i = tid(); let mut st = rand_init(seed, i as u32); a[i] = randf(&mut st) as f64; }",
    "fn k(a: Array<f32>) { let i = tid(); let mut x = a[i]; while x > 1.0 { x = x * 0.5; } a[i] = x.sqrt(); }",
    "fn f(x: f32, y: f32) -> f32 { if x > y { return x - y; } let z = x * y; z.sin() }",
    "fn f(v: Vec3) -> f32 { let w = v * 2.0; w.x + w.y * w.z }",
    "fn k(a: Array<u8>, h: Array<f16>) { let i = tid(); a[i] = a[i].wrapping_add(1); h[i] = h[i] * f16::from_f32(2.0); }",
];

fn entry_of(src: &str) -> Entry {
    if src.starts_with("fn f") {
        Entry::Func
    } else {
        Entry::Kernel
    }
}

/// Expressions over the kernel's parameters, any types, any operators, builtins known and
/// unknown: mostly type errors, all of which must be reported, not panic.
fn expr(depth: u32) -> BoxedStrategy<String> {
    let leaf = proptest::sample::select(
        &[
            "a[i]",
            "b[(i, i)]",
            "m[i]",
            "n[i]",
            "x",
            "y",
            "h",
            "u",
            "v",
            "q",
            "i",
            "1",
            "-1",
            "2.5",
            "1e39",
            "256",
            "true",
            "a",
            "b",
            "tid()",
            "zz",
            "Vec3::ZERO",
            "Mat33::IDENTITY",
            "f32::MAX",
            "()",
            "a[-1]",
            "a[i][i]",
            "v.w",
            "v.x",
            "q.x",
            "m[i].x_axis",
        ][..],
    )
    .prop_map(str::to_string);
    leaf.prop_recursive(depth, 64, 3, |inner| {
        let binop = proptest::sample::select(
            &[
                "+", "-", "*", "/", "%", "==", "<", "&&", "||", "&", "|", "^", "<<", ">>",
            ][..],
        );
        let call = proptest::sample::select(
            &[
                "sin",
                "sqrt",
                "dot",
                "cross",
                "min",
                "max",
                "abs",
                "clamp",
                "lerp",
                "atomic_add",
                "length",
                "transpose",
                "not_a_builtin",
                "randf",
                "svd3",
                "floor",
                "select",
                "vec3",
                "Vec3::new",
                "mat33",
            ][..],
        );
        let method = proptest::sample::select(
            &[
                "sin",
                "abs",
                "dot",
                "length",
                "transpose",
                "x",
                "len",
                "foo",
                "powf",
                "min",
            ][..],
        );
        let cast = proptest::sample::select(
            &[
                "f32", "f64", "f16", "i32", "u8", "u64", "bool", "Vec3", "usize",
            ][..],
        );
        prop_oneof![
            (inner.clone(), binop, inner.clone()).prop_map(|(l, o, r)| format!("({l} {o} {r})")),
            inner.clone().prop_map(|e| format!("-{e}")),
            inner.clone().prop_map(|e| format!("!{e}")),
            (call, proptest::collection::vec(inner.clone(), 0..4))
                .prop_map(|(f, args)| format!("{f}({})", args.join(", "))),
            (
                inner.clone(),
                method,
                proptest::collection::vec(inner.clone(), 0..2)
            )
                .prop_map(|(r, m, args)| format!("{r}.{m}({})", args.join(", "))),
            (inner.clone(), cast).prop_map(|(e, t)| format!("({e} as {t})")),
            (inner.clone(), inner.clone(), inner)
                .prop_map(|(c, t, e)| format!("(if {c} {{ {t} }} else {{ {e} }})")),
        ]
    })
    .boxed()
}

/// A statement using an expression: where it goes decides its expected type.
fn statement() -> impl Strategy<Value = String> {
    let places = proptest::sample::select(&["a[i]", "b[(i, 0)]", "m[i]", "n[i]", "x"][..]);
    let tys = proptest::sample::select(&["f32", "f64", "i32", "u8", "Vec3", "Mat33", "bool"][..]);
    prop_oneof![
        expr(4).prop_map(|e| format!("let t = {e};")),
        (tys, expr(4)).prop_map(|(t, e)| format!("let t: {t} = {e};")),
        (places.clone(), expr(4)).prop_map(|(p, e)| format!("{p} = {e};")),
        (places, expr(4)).prop_map(|(p, e)| format!("{p} += {e};")),
        (expr(3), expr(3)).prop_map(|(c, e)| format!("if {c} {{ let t = {e}; }}")),
        (expr(3), expr(3)).prop_map(|(r, e)| format!("for j in 0..{r} {{ a[j] = {e}; }}")),
        expr(4).prop_map(|e| format!("{e};")),
    ]
}

/// Numeric literals: every suffix (real and not), magnitudes at and past every type's range.
fn literal() -> impl Strategy<Value = String> {
    let digits = prop_oneof![
        proptest::sample::select(
            &[
                "0",
                "1",
                "127",
                "128",
                "255",
                "256",
                "32767",
                "32768",
                "65535",
                "65536",
                "2147483647",
                "2147483648",
                "4294967295",
                "4294967296",
                "9223372036854775807",
                "9223372036854775808",
                "18446744073709551615",
                "18446744073709551616",
                "170141183460469231731687303715884105727",
                "170141183460469231731687303715884105728",
                "340282366920938463463374607431768211455",
                "340282366920938463463374607431768211456",
                "0x7f",
                "0xff",
                "0x80000000",
                "0b1",
                "0o777",
                "1_000_000",
            ][..]
        )
        .prop_map(str::to_string),
        any::<u64>().prop_map(|v| v.to_string()),
    ];
    let floats = prop_oneof![
        proptest::sample::select(
            &[
                "0.0",
                "1.5",
                "65504.0",
                "65519.0",
                "65520.0",
                "3.4028235e38",
                "3.4028236e38",
                "3.5e38",
                "1e39",
                "1.7976931348623157e308",
                "1.8e308",
                "1e309",
                "1e-50",
                "1e-400",
                "6e-8",
                "1e-46",
                "1.",
            ][..]
        )
        .prop_map(str::to_string),
        (any::<u32>(), -400i32..400).prop_map(|(m, e)| format!("{m}.5e{e}")),
    ];
    let suffix = proptest::sample::select(
        &[
            "", "", "", "f32", "f64", "f16", "i32", "u8", "u32", "i64", "u64", "usize", "i8",
            "u16", "i128", "x", "f",
        ][..],
    );
    (prop_oneof![digits, floats], suffix).prop_map(|(d, s)| format!("{d}{s}"))
}

// ---------------------------------------------------------------------------------------------
// Properties

proptest! {
    #![proptest_config(config(64))]

    /// A random token soup as a kernel body.
    #[test]
    fn token_soup_never_panics(body in soup(3)) {
        check(Entry::Kernel, &kernel_with_body(&body))?;
    }

    /// A random token soup as a func body, a return type and a parameter list.
    #[test]
    fn token_soup_in_func_never_panics(body in soup(2), ret in soup(1), params in soup(1)) {
        check(Entry::Func, &format!("fn f(x: f32) -> f32 {{ {body} }}"))?;
        check(Entry::Func, &format!("fn f(x: f32) -> {ret} {{ x }}"))?;
        check(Entry::Kernel, &format!("fn k({params}) {{ let i = tid(); }}"))?;
    }

    /// A valid kernel cut at any character (most cuts do not lex; those that do must expand).
    #[test]
    fn truncated_kernels_never_panic(src in proptest::sample::select(VALID), cut in any::<proptest::sample::Index>()) {
        let src = &src[..cut.index(src.len() + 1)];
        // Close what the cut left open, so that more cuts lex.
        let mut closed = src.to_string();
        let opens = src.matches('{').count().saturating_sub(src.matches('}').count());
        let parens = src.matches('(').count().saturating_sub(src.matches(')').count());
        closed.push_str(&")".repeat(parens));
        closed.push_str(&"}".repeat(opens));
        check(entry_of(src), src)?;
        check(entry_of(src), &closed)?;
    }

    /// A valid kernel with one whitespace-separated word replaced by an atom.
    #[test]
    fn mutated_kernels_never_panic(
        src in proptest::sample::select(VALID),
        at in any::<proptest::sample::Index>(),
        with in proptest::sample::select(ATOMS),
    ) {
        let mut words: Vec<&str> = src.split(' ').collect();
        let k = at.index(words.len());
        words[k] = with;
        let mutated = words.join(" ");
        check(entry_of(src), &mutated)?;
    }

    /// Statements over the kernel's parameters with random (mostly wrong) types.
    #[test]
    fn mistyped_statements_never_panic(stmts in proptest::collection::vec(statement(), 1..4)) {
        check(Entry::Kernel, &kernel_with_body(&stmts.join(" ")))?;
    }

    /// Literals of every kind in every context: accepted only when in range for the type
    /// they take, else an error.
    #[test]
    fn literals_in_range_or_rejected(lit in literal(), neg in any::<bool>(), ctx in 0usize..6) {
        let lit = if neg { format!("-{lit}") } else { lit };
        let body = match ctx {
            0 => format!("let t = {lit};"),
            1 => format!("a[i] = {lit};"),
            2 => format!("n[i] = {lit};"),
            3 => format!("let t: f64 = {lit};"),
            4 => format!("let t = x * {lit};"),
            _ => format!("let t: u8 = {lit};"),
        };
        let src = kernel_with_body(&body);
        let out = check(Entry::Kernel, &src)?;
        if let (Some(Outcome::Accepted), Some(why)) = (&out, out_of_range(&lit, ctx)) {
            return Err(TestCaseError::fail(format!("accepted {lit} ({why}) in:\n{src}")));
        }
    }

    /// Deep nesting: parentheses, negations, blocks, calls and long operator chains.
    #[test]
    fn deep_nesting_never_panics(depth in 1usize..80, shape in 0usize..5) {
        let e = match shape {
            0 => format!("{}x{}", "(".repeat(depth), ")".repeat(depth)),
            1 => format!("{}x", "-".repeat(depth)),
            2 => format!("{}x{}", "sin(".repeat(depth), ")".repeat(depth)),
            3 => format!("{}x{}", "{ ".repeat(depth), " }".repeat(depth)),
            _ => vec!["x"; depth * 4].join(" + "),
        };
        check(Entry::Kernel, &kernel_with_body(&format!("a[i] = {e};")))?;
        let ifs = format!("{}a[i] = x;{}", "if x > 0.0 { ".repeat(depth), " }".repeat(depth));
        check(Entry::Kernel, &kernel_with_body(&ifs))?;
    }
}

/// Why a literal (as the kernel source spells it, possibly negated) must be rejected in
/// context `ctx` of [`literals_in_range_or_rejected`], when it must; `None` when the model
/// does not know (the front end may then accept or reject).
fn out_of_range(lit: &str, ctx: usize) -> Option<&'static str> {
    let (neg, body) = match lit.strip_prefix('-') {
        Some(b) => (true, b),
        None => (false, lit),
    };
    // Split the suffix off (hex digits include 'f': only decimal literals are modelled).
    if body.starts_with("0x") || body.starts_with("0b") || body.starts_with("0o") {
        return None;
    }
    let split = body
        .find(|c: char| c.is_ascii_alphabetic() && c != 'e')
        .unwrap_or(body.len());
    let (digits, suffix) = body.split_at(split);
    let is_float_lit = digits.contains('.') || digits.contains('e');
    // The type it takes: its suffix, else its context (the kernel's parameter types).
    let ty = match (suffix, ctx) {
        ("", 1 | 4) => "f32",
        ("", 2) => "i32",
        ("", 3) => "f64",
        ("", 5) => "u8",
        ("", _) if is_float_lit => "f32",
        ("", _) => "i32",
        (s, _) => s,
    };
    let v: f64 = digits.replace('_', "").parse().ok()?;
    let v = if neg { -v } else { v };
    match ty {
        "f32" if (v as f32).is_infinite() => Some("past f32::MAX"),
        "f64" if v.is_infinite() => Some("past f64::MAX"),
        "f16" if v.abs() >= 65520.0 => Some("past f16::MAX"),
        _ if is_float_lit => None,
        "i32" if v < i32::MIN as f64 || v > i32::MAX as f64 => Some("outside i32"),
        "u8" if !(0.0..=255.0).contains(&v) => Some("outside u8"),
        "u32" if !(0.0..=u32::MAX as f64).contains(&v) => Some("outside u32"),
        "i64" if v < i64::MIN as f64 || v > i64::MAX as f64 * 1.000001 => Some("outside i64"),
        "u64" if !(0.0..=u64::MAX as f64 * 1.000001).contains(&v) => Some("outside u64"),
        _ => None,
    }
}

// ---------------------------------------------------------------------------------------------
// Regressions: what the properties found, each as a plain test.

/// Float literals past their type's range were accepted and then panicked the emitter
/// (`proc_macro2::Literal::f32_suffixed(inf)`): now an error naming the type.
#[test]
fn float_literals_past_their_type_are_errors() {
    for (body, ty) in [
        ("let t = 1e39;", "f32"),
        ("a[i] = 1e39;", "f32"),
        ("let t = 1e39f32;", "f32"),
        ("let t = x * 3.4028236e38;", "f32"),
        ("let t: f64 = 1e309;", "f64"),
        ("let t = -1e309f64;", "f64"),
        ("let t = 65520.0f16;", "f16"),
        ("let t = h * -70000.0;", "f16"),
        // An integer literal in a float context becomes a float of that type.
        ("let t: f16 = 70000;", "f16"),
        ("let t = h * 65520;", "f16"),
    ] {
        let msgs = check_rejected(Entry::Kernel, &kernel_with_body(body)).unwrap();
        let want = format!("literal out of range for `{ty}`");
        assert!(
            msgs.iter().any(|m| m.contains(&want)),
            "{body}: {msgs:?} should say {want}"
        );
    }
    // The largest finite values are fine.
    for body in [
        "let t = 3.4028235e38;",
        "let t: f64 = 1.7976931348623157e308;",
        "let t = 65504.0f16;",
        "let t = -65519.0f16;",
    ] {
        assert!(
            matches!(
                check(Entry::Kernel, &kernel_with_body(body)).unwrap(),
                Some(Outcome::Accepted)
            ),
            "{body}"
        );
    }
}

/// Integer literals past `i128::MAX` wrapped (`u128::MAX` became -1, an `i32` in range), and
/// negating `2^127` overflowed: both are "integer literal too large" now.
#[test]
fn integer_literals_past_i128_are_errors() {
    for body in [
        "let t = 340282366920938463463374607431768211455;",
        "n[i] = 340282366920938463463374607431768211455;",
        "let t = -170141183460469231731687303715884105728;",
        "let t = 170141183460469231731687303715884105728u64;",
    ] {
        let msgs = check_rejected(Entry::Kernel, &kernel_with_body(body)).unwrap();
        assert!(
            msgs.iter().any(|m| m.contains("integer literal too large")),
            "{body}: {msgs:?}"
        );
    }
}

/// A lone `;` (Rust's empty statement) was "this expression is not supported": it is accepted
/// and does nothing, as in Rust.
#[test]
fn empty_statements_are_accepted() {
    for body in [";", "; ;", "a[i] = 1.0; ;", "if x > 0.0 { ; }"] {
        assert!(
            matches!(
                check(Entry::Kernel, &kernel_with_body(body)).unwrap(),
                Some(Outcome::Accepted)
            ),
            "{body}"
        );
    }
    assert!(matches!(
        check(Entry::Func, "fn f(x: f32) -> f32 { ; x }").unwrap(),
        Some(Outcome::Accepted)
    ));
}
