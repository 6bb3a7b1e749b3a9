//! Assertions: `assert!(cond)`, `assert!(cond, "message")`, `debug_assert!(..)`, and Warp's
//! test expectations as statements (`expect_eq(a, b);`, `expect_neq`, `expect_near(a, b, tol)`).
//!
//! Each becomes the statements computing its condition and a `StmtKind::Assert` holding the
//! message, which the back ends turn into a fault (`FaultKind::AssertionFailed`) when the
//! condition is false. A `debug_assert!` is wrapped in `if debug { .. }` (`Op::DebugMode`), so
//! that its condition is not computed while the runtime's debug mode is off. The message is
//! fixed at compile time: a string literal without format arguments (a GPU fault record holds
//! no text, only the line and column by which the host finds it), or the condition's source
//! text, as Rust's `assert!` prints it.

use super::{err, Lowerer, R};
use crate::builtins;
use crate::ir::*;
use crate::types::BOOL;
use proc_macro2::{Delimiter, LineColumn, Span, TokenStream, TokenTree};
use syn::spanned::Spanned;
use syn::Expr;

/// The expectations, statements whose row is their check.
pub(super) const EXPECTATIONS: &[&str] = &["expect_eq", "expect_neq", "expect_near"];

/// The source text of `node` as written (as Rust's `assert!` prints its condition): each
/// token's text, with one space where the source has a gap between two tokens (a line break
/// counts as one). Without token positions (code a macro made), the tokens as printed.
fn source_text(node: &impl quote::ToTokens) -> String {
    /// Appends `text`, which spans `start..end` in the source.
    fn put(
        start: LineColumn,
        end: LineColumn,
        text: &str,
        out: &mut String,
        last: &mut Option<LineColumn>,
    ) -> Option<()> {
        if start.line == 0 {
            return None;
        }
        if last.is_some_and(|l| l != start) {
            out.push(' ');
        }
        out.push_str(text);
        *last = Some(end);
        Some(())
    }
    fn walk(ts: TokenStream, out: &mut String, last: &mut Option<LineColumn>) -> Option<()> {
        for tt in ts {
            match tt {
                TokenTree::Group(g) => {
                    let (open, close) = match g.delimiter() {
                        Delimiter::Parenthesis => ("(", ")"),
                        Delimiter::Bracket => ("[", "]"),
                        Delimiter::Brace => ("{", "}"),
                        Delimiter::None => ("", ""),
                    };
                    // The delimiters are one column wide at the group's ends (the compiler's
                    // `span_open` is the whole group's span on stable).
                    let (start, end) = (g.span().start(), g.span().end());
                    let after_open = LineColumn {
                        column: start.column + 1,
                        ..start
                    };
                    let before_close = LineColumn {
                        column: end.column.saturating_sub(1),
                        ..end
                    };
                    if !open.is_empty() {
                        put(start, after_open, open, out, last)?;
                    }
                    walk(g.stream(), out, last)?;
                    if !close.is_empty() {
                        put(before_close, end, close, out, last)?;
                    }
                }
                t => put(t.span().start(), t.span().end(), &t.to_string(), out, last)?,
            }
        }
        Some(())
    }
    let tokens = node.to_token_stream();
    let mut out = String::new();
    match walk(tokens.clone(), &mut out, &mut None) {
        Some(()) => out,
        None => tokens.to_string(),
    }
}

/// The message literal's text with `{{` and `}}` unescaped; a lone brace (a format argument,
/// `{}` or `{x}`) is refused at the literal.
fn plain_message(lit: &syn::LitStr) -> R<String> {
    let (s, mut out) = (lit.value(), String::new());
    let mut chars = s.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '{' | '}' if chars.peek() == Some(&c) => {
                chars.next();
                out.push(c);
            }
            '{' | '}' => {
                return err(
                    lit.span(),
                    "format arguments are not supported in a kernel's assertion message: the \
                     message is a plain string literal (write `{{` and `}}` for braces)",
                )
            }
            c => out.push(c),
        }
    }
    Ok(out)
}

impl Lowerer {
    /// `assert!(cond)`, `assert_eq!(a, b)` and `assert_ne!(a, b)`, each with an optional
    /// message literal, and their `debug_` forms (`name`), checked only in debug mode. The
    /// comparisons are the checks of `expect_eq`/`expect_neq` (numbers, vectors, quaternions,
    /// matrices; the same type on both sides), with Rust's message
    /// (``assertion `left == right` failed: a == b``, the operands as written: a GPU fault
    /// record cannot carry their values).
    pub(super) fn assert_macro(&mut self, mac: &syn::Macro, name: &str) -> R<()> {
        let span = mac.span();
        let debug = name.starts_with("debug_");
        // The comparison's operator and expectation, or `None` for `assert!`.
        let cmp = match name.trim_start_matches("debug_") {
            "assert_eq" => Some(("==", "expect_eq")),
            "assert_ne" => Some(("!=", "expect_neq")),
            _ => None,
        };
        let parsed: syn::punctuated::Punctuated<Expr, syn::Token![,]> =
            mac.parse_body_with(syn::punctuated::Punctuated::parse_terminated)?;
        let args: Vec<&Expr> = parsed.iter().collect();
        let (values, usage) = match cmp {
            None => (1, "cond"),
            Some(_) => (2, "a, b"),
        };
        if args.len() < values {
            return err(
                span,
                match cmp {
                    None => format!("{name}! needs a condition: `{name}!(x > 0.0)`"),
                    Some(_) => format!("{name}! needs two values: `{name}!(a, b)`"),
                },
            );
        }
        let message = match (args.get(values), cmp) {
            (None, None) => format!("assertion failed: {}", source_text(args[0])),
            (None, Some((op, _))) => format!(
                "assertion `left {op} right` failed: {} {op} {}",
                source_text(args[0]),
                source_text(args[1])
            ),
            (
                Some(Expr::Lit(syn::ExprLit {
                    lit: syn::Lit::Str(s),
                    ..
                })),
                _,
            ) => plain_message(s)?,
            (Some(other), _) => {
                return err(
                    other.span(),
                    format!(
                        "the message of {name}! in a kernel is a string literal: \
                         `{name}!({usage}, \"message\")`"
                    ),
                )
            }
        };
        if let Some(extra) = args.get(values + 1) {
            return err(
                extra.span(),
                format!(
                    "format arguments are not supported in a kernel's {name}!: the message is \
                     a plain string literal"
                ),
            );
        }
        let check = move |cx: &mut Self| match cmp {
            None => cx.assertion(args[0], message, span),
            Some((_, expectation)) => cx.expected(expectation, &args[..2], message, span),
        };
        if !debug {
            return check(self);
        }
        let on = self.def(Op::DebugMode, BOOL, span);
        let (then, ()) = self.in_block(check)?;
        self.push(
            StmtKind::If {
                cond: on,
                then,
                els: Vec::new(),
            },
            span,
        );
        Ok(())
    }

    /// The condition's statements and the assertion on it.
    fn assertion(&mut self, cond: &Expr, message: String, span: Span) -> R<()> {
        let c = self.expr(cond, Some(&BOOL))?;
        match self.ty(c) {
            t if t == BOOL || t.is_deferred() => {}
            t => {
                return err(
                    cond.span(),
                    format!("mismatched types: an assertion's condition is a `bool`, found `{t}`"),
                )
            }
        }
        self.push(StmtKind::Assert { cond: c, message }, span);
        Ok(())
    }

    /// `expect_eq(a, b);` and the other expectations (`name`), as statements: the row's check,
    /// then the assertion on it, whose message is the call as written.
    pub(super) fn expectation(&mut self, c: &syn::ExprCall, name: &str) -> R<()> {
        let args: Vec<&Expr> = c.args.iter().collect();
        let message = format!("expectation failed: {}", source_text(c));
        self.expected(name, &args, message, c.span())
    }

    /// Expectation `name`'s check of `args` and the assertion on it with `message`.
    fn expected(&mut self, name: &str, args: &[&Expr], message: String, span: Span) -> R<()> {
        let b = builtins::lookup(name).expect("an expectation has a row");
        let ok = self.builtin_call(b, args, None, span)?;
        self.push(StmtKind::Assert { cond: ok, message }, span);
        Ok(())
    }
}

/// Whether `e` is a call of an expectation (`expect_eq(..)`, `wp::expect_eq(..)`), and which.
pub(super) fn expectation_call(e: &Expr) -> Option<(&syn::ExprCall, &'static str)> {
    let Expr::Call(c) = e else { return None };
    let Expr::Path(p) = &*c.func else { return None };
    let segs: Vec<String> = p
        .path
        .segments
        .iter()
        .map(|s| s.ident.to_string())
        .collect();
    let prefix_ok = segs.len() == 1 || (segs.len() == 2 && crate::paths::names_facade(&segs[0]));
    let last = segs.last()?;
    let name = EXPECTATIONS.iter().find(|n| *n == last)?;
    prefix_ok.then_some((c, *name))
}

/// The error for an expectation used as a value (`let ok = expect_eq(a, b);`).
pub(super) fn expectation_as_value(span: Span, name: &str) -> syn::Error {
    syn::Error::new(
        span,
        format!(
            "`{name}` is a statement in kernels: `{name}(..);` faults when the expectation \
             fails, and has no value"
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::super::lower_fn;
    use crate::ir::*;

    fn lower(src: &str) -> Result<Function, Vec<String>> {
        let item: syn::ItemFn = syn::parse_str(src).expect("a fn");
        lower_fn(&item, FnKind::Kernel).map_err(|e| e.iter().map(|e| e.to_string()).collect())
    }

    fn messages(f: &Function) -> Vec<String> {
        let mut out = Vec::new();
        walk_stmts(&f.body, &mut |s| {
            if let StmtKind::Assert { message, .. } = &s.kind {
                out.push(message.clone());
            }
        });
        out
    }

    #[test]
    fn messages_are_the_source_text_or_the_literal() {
        let f = lower(
            "fn k(a: Array<f32>, v: Array<Vec3>) {
                let i = tid();
                assert!(a[i]  >  0.0);
                assert!(a[i] < 1.0, \"below {{one}}\");
                expect_near(v[i], vec3(1.0, 2.0,
                    3.0), 0.5);
            }",
        )
        .unwrap();
        assert_eq!(
            messages(&f),
            [
                "assertion failed: a[i] > 0.0",
                "below {one}",
                "expectation failed: expect_near(v[i], vec3(1.0, 2.0, 3.0), 0.5)",
            ]
        );
    }

    #[test]
    fn debug_assert_is_guarded_by_the_debug_mode() {
        let f = lower("fn k(a: Array<f32>) { let i = tid(); debug_assert!(a[i] > 0.0); }").unwrap();
        let StmtKind::If { cond, then, els } = &f.body.last().unwrap().kind else {
            panic!("{:?}", f.body)
        };
        assert!(els.is_empty());
        assert!(f.body.iter().any(|s| matches!(
            &s.kind,
            StmtKind::Assign { dst, op: Op::DebugMode, .. } if dst == cond
        )));
        // The condition is computed inside the guard.
        assert!(matches!(
            then.first().unwrap().kind,
            StmtKind::Assign { .. }
        ));
        assert!(matches!(then.last().unwrap().kind, StmtKind::Assert { .. }));
    }

    #[test]
    fn misuse_is_refused() {
        let cases = [
            (
                "assert!(x > 0.0, \"x = {}\", x);",
                "format arguments are not supported",
            ),
            (
                "assert!(x > 0.0, \"x = {x}\");",
                "format arguments are not supported",
            ),
            ("assert!(x > 0.0, msg);", "is a string literal"),
            (
                "assert!(x);",
                "an assertion's condition is a `bool`, found `f32`",
            ),
            ("assert!();", "needs a condition"),
            ("let ok = expect_eq(x, 1.0);", "`expect_eq` is a statement"),
            ("expect_near(x, 1.0f64, 0.5);", "expect_near"),
        ];
        for (stmt, want) in cases {
            let src = format!("fn k(x: f32) {{ {stmt} }}");
            let errors = lower(&src).err().unwrap_or_default();
            assert!(
                errors.iter().any(|e| e.contains(want)),
                "{stmt}: {errors:?} should contain {want:?}"
            );
        }
    }
}
