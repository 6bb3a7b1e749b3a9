//! Well-formedness: every variable a statement reads is defined before it, in the same block
//! or an enclosing one (a parameter, a defining assignment, a `Declare`, a `for` variable
//! inside its loop); `break` and `continue` are inside a loop (and the adjoint's `ExitIf`).
//!
//! Lowering produces only such IR, with one exception user code can reach: a view
//! (`a.row(i)`, `a.view(lo..hi)`, `a.indexed(idx)`) is a name that lowering resolves into
//! accesses of the viewed array (`front/lower/views.rs`), so its variable is never defined; a
//! view used any other way (passed to a func, printed, copied into an `if` value) is a read of
//! it, reported here. Any other undefined read would be a bug of the front end, and says so.

use crate::ir::*;
use crate::types::Ty;
use proc_macro2::Span;

pub(super) fn check(f: &Function, errors: &mut Vec<syn::Error>) {
    let mut cx = Checker {
        f,
        defined: vec![false; f.vars.len()],
        loops: 0,
        errors,
    };
    for p in &f.params {
        cx.defined[p.var] = true;
    }
    cx.block(&f.body);
}

struct Checker<'a, 'e> {
    f: &'a Function,
    /// Defined at this point of the walk (in scope).
    defined: Vec<bool>,
    /// Loops enclosing the statement.
    loops: usize,
    errors: &'e mut Vec<syn::Error>,
}

impl Checker<'_, '_> {
    fn block(&mut self, b: &Block) {
        // What this block defines goes out of scope at its end.
        let mut introduced = Vec::new();
        for s in b {
            let mut undefined = None;
            s.kind.for_each_read(&mut |v| {
                if !self.defined[v] && undefined.is_none() {
                    undefined = Some(v);
                }
            });
            if let Some(v) = undefined {
                self.undefined(v, s.span);
            }
            match &s.kind {
                StmtKind::Assign {
                    dst, define: true, ..
                }
                | StmtKind::Declare { var: dst }
                    if !self.defined[*dst] =>
                {
                    self.defined[*dst] = true;
                    introduced.push(*dst);
                }
                StmtKind::Assign {
                    dst, define: false, ..
                } if !self.defined[*dst] => self.undefined(*dst, s.span),
                StmtKind::If { then, els, .. } => {
                    self.block(then);
                    self.block(els);
                }
                StmtKind::For { var, body, .. } => {
                    let outer = self.defined[*var];
                    self.defined[*var] = true;
                    self.loop_body(body);
                    self.defined[*var] = outer;
                }
                StmtKind::Loop { body } => self.loop_body(body),
                StmtKind::Break | StmtKind::Continue if self.loops == 0 => {
                    let word = if matches!(s.kind, StmtKind::Break) {
                        "break"
                    } else {
                        "continue"
                    };
                    self.errors.push(syn::Error::new(
                        s.span,
                        format!("`{word}` outside of a loop"),
                    ));
                }
                StmtKind::ExitIf { .. } if self.loops == 0 => self.errors.push(syn::Error::new(
                    s.span,
                    "warp-lang internal error: a loop exit outside of a loop (please report it)",
                )),
                _ => {}
            }
        }
        for v in introduced {
            self.defined[v] = false;
        }
    }

    fn loop_body(&mut self, body: &Block) {
        self.loops += 1;
        self.block(body);
        self.loops -= 1;
    }

    fn undefined(&mut self, v: VarId, span: Span) {
        let is_param = self.f.params.iter().any(|p| p.var == v);
        let msg = if matches!(self.f.vars[v].ty, Ty::Array(..)) && !is_param {
            "a view (`row`, `view`, `indexed`) can be indexed, measured (`len`, `shape`) and \
             viewed again, nothing else yet: pass the array and its index to funcs"
                .to_string()
        } else {
            let name = self.f.vars[v]
                .name
                .clone()
                .unwrap_or_else(|| format!("temporary {v}"));
            format!(
                "warp-lang internal error: `{name}` is used before it is defined (please report \
                 it)"
            )
        };
        self.errors.push(syn::Error::new(span, msg));
    }
}
