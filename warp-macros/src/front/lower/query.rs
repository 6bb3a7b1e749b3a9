//! Lowering of a `for` loop over a host object's query (`for j in hash_grid_query(grid, p, r)
//! { .. }`, Warp's `while wp.hash_grid_query_next(query, j)`), into existing IR:
//!
//! ```text
//! q = hash_grid_query(grid, p, r)        the query row: the state before the first candidate
//! loop {
//!     q = hash_grid_query_next(grid, q)  a pure function of the object and the state,
//!                                        written back (the RNG draws' shape, `rng.rs`),
//!                                        directly: the adjoint pushes the state (40
//!                                        bytes for the hash grid) once per iteration
//!     d = hash_grid_query_done(q)
//!     if d { break }
//!     j = hash_grid_query_point(q)       the loop variable
//!     body
//! }
//! ```
//!
//! The steps are the query row's [`Iterate`](crate::builtins::Iterate) fact, so a new query
//! (BVH, mesh) is rows only. No new statement: both emitters print the calls and the `loop`;
//! the adjoint pass pushes the state and the loop variable where the loop overwrites them,
//! records the trip count and the `if`, and the reverse sweep gives the body's reads
//! (`x[j]`) their gradients; the steps themselves have zero gradient. `continue` goes on to
//! the next candidate, `break` ends the query.
//!
//! A query's result is iterated where it is made: elsewhere (`let q = hash_grid_query(..)`) it
//! is a compile error saying so (`calls.rs`).

use super::*;

impl Lowerer {
    /// The query row that `e` calls (`hash_grid_query(..)`, `wp::hash_grid_query(..)`), if any.
    pub(super) fn query_call(e: &Expr) -> Option<(&syn::ExprCall, &'static Builtin)> {
        let Expr::Call(c) = strip(e) else {
            return None;
        };
        let Expr::Path(fp) = strip(&c.func) else {
            return None;
        };
        let segs: Vec<String> = fp
            .path
            .segments
            .iter()
            .map(|s| s.ident.to_string())
            .collect();
        let prefix_ok =
            segs.len() == 1 || (segs.len() == 2 && crate::paths::names_facade(&segs[0]));
        let b = builtins::lookup_user(segs.last()?)?;
        (prefix_ok && b.iterate.is_some()).then_some((c, b))
    }

    /// `for pat in query(args) { body }`: see the module docs.
    pub(super) fn query_loop(
        &mut self,
        f: &syn::ExprForLoop,
        call: &syn::ExprCall,
        row: &'static Builtin,
    ) -> R<()> {
        let span = call.span();
        let it = row.iterate.expect("a query row");
        let step = |name: &str| builtins::lookup(name).expect("the query's steps are rows");
        let (next, done, item) = (step(it.next), step(it.done), step(it.item));
        let args: Vec<&Expr> = call.args.iter().collect();
        // The state before the first candidate; the loop writes it back, so it is mutable.
        let q = self.builtin_call(row, &args, None, span)?;
        self.vars[q].mutable = true;
        // The object the query reads (its first argument), which every step of `next` reads.
        let object = match self.blocks.last().and_then(|b| b.last()) {
            Some(Stmt {
                kind:
                    StmtKind::Assign {
                        dst,
                        op: Op::Builtin { args, .. },
                        ..
                    },
                ..
            }) if *dst == q => args[0],
            _ => unreachable!("builtin_call defines its result last"),
        };
        let (name, mutable) = match &*f.pat {
            Pat::Ident(pi) if pi.subpat.is_none() && pi.by_ref.is_none() => {
                (Some(pi.ident.to_string()), pi.mutability.is_some())
            }
            Pat::Wild(_) => (None, false),
            p => return err(p.span(), "loop variables must be plain names"),
        };
        let item_ty = match item.ret {
            Pos::Fixed(s) => Ty::Scalar(s),
            _ => unreachable!("a query's items are scalars (indices)"),
        };
        let pat_span = f.pat.span();
        let (body, _) = self.loop_body(|cx| {
            // Into the state itself, not through a temporary: the adjoint pushes what a loop
            // overwrites, and a temporary would double the state's bytes per iteration.
            cx.push(
                StmtKind::Assign {
                    dst: q,
                    op: Op::Builtin {
                        builtin: next,
                        args: vec![object, q],
                    },
                    define: false,
                },
                span,
            );
            let d = cx.def(
                Op::Builtin {
                    builtin: done,
                    args: vec![q],
                },
                BOOL,
                span,
            );
            cx.push(
                StmtKind::If {
                    cond: d,
                    then: vec![Stmt {
                        kind: StmtKind::Break,
                        span,
                    }],
                    els: vec![],
                },
                span,
            );
            if let Some(n) = &name {
                let j = cx.new_var(Some(n.clone()), item_ty.clone(), mutable);
                cx.push(
                    StmtKind::Assign {
                        dst: j,
                        op: Op::Builtin {
                            builtin: item,
                            args: vec![q],
                        },
                        define: true,
                    },
                    pat_span,
                );
                cx.scopes.last_mut().expect("scope").insert(n.clone(), j);
            }
            cx.block_stmts(&f.body.stmts, None, false)
        })?;
        self.push(StmtKind::Loop { body }, f.span());
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::builtins::lookup;
    use crate::ir::*;
    use syn::parse_quote;

    fn lower(item: syn::ItemFn) -> Result<Function, String> {
        crate::front::lower::lower_fn(&item, FnKind::Kernel).map_err(|es| {
            es.iter()
                .map(|e| e.to_string())
                .collect::<Vec<_>>()
                .join("\n")
        })
    }

    fn builtins_in(b: &Block) -> Vec<&'static str> {
        let mut out = Vec::new();
        walk_stmts(b, &mut |s| {
            if let StmtKind::Assign {
                op: Op::Builtin { builtin, .. },
                ..
            } = &s.kind
            {
                out.push(builtin.name);
            }
        });
        out
    }

    #[test]
    fn a_query_loop_is_a_loop_over_the_steps() {
        let f = lower(parse_quote! {
            fn k(grid: HashGrid, x: Array<Vec3>, out: Array<f32>) {
                let i = tid();
                let mut s = 0.0;
                for j in hash_grid_query(grid, x[i], 0.5) {
                    if j == i { continue; }
                    s += length(x[j] - x[i]);
                }
                out[i] = s;
            }
        })
        .unwrap();
        assert_eq!(
            builtins_in(&f.body),
            [
                "hash_grid_query",
                "hash_grid_query_next",
                "hash_grid_query_done",
                "hash_grid_query_point",
                "length"
            ]
        );
        // The state is one mutable variable, written back inside the loop; `j` is a usize.
        let q = f
            .vars
            .iter()
            .position(|v| v.ty == crate::types::Ty::Object(crate::types::ObjectKind::HashGridQuery))
            .unwrap();
        assert!(f.vars[q].mutable);
        let j = f
            .vars
            .iter()
            .find(|v| v.name.as_deref() == Some("j"))
            .unwrap();
        assert_eq!(j.ty, crate::types::USIZE);
        let Some(StmtKind::Loop { body }) = f
            .body
            .iter()
            .map(|s| &s.kind)
            .find(|k| matches!(k, StmtKind::Loop { .. }))
        else {
            panic!("a loop")
        };
        // `q = next(grid, q)` into the state itself, then `done`, then the `if`.
        assert!(matches!(
            &body[0].kind,
            StmtKind::Assign { dst, define: false, op: Op::Builtin { args, .. } }
                if *dst == q && args[1] == q
        ));
        assert!(
            matches!(&body[2].kind, StmtKind::If { then, .. } if matches!(then[0].kind, StmtKind::Break))
        );
        assert!(lookup("hash_grid_query_next").unwrap().internal);
    }

    #[test]
    fn query_misuse_is_reported() {
        let cases: [(syn::ItemFn, &str); 5] = [
            (
                parse_quote! { fn k(grid: HashGrid) {
                    println!("{:?}", grid);
                } },
                "cannot be printed",
            ),
            (
                parse_quote! { fn k(grid: HashGrid, x: Array<Vec3>) {
                    let q = hash_grid_query(grid, x[0], 1.0);
                } },
                "iterated where it is made",
            ),
            (
                parse_quote! { fn k(grid: Array<Vec3>, x: Array<Vec3>) {
                    for j in hash_grid_query(grid, x[0], 1.0) {}
                } },
                "expected `HashGrid`",
            ),
            (
                parse_quote! { fn k(grid: HashGrid, x: Array<Vec3>) {
                    for (a, b) in hash_grid_query(grid, x[0], 1.0) {}
                } },
                "plain names",
            ),
            (
                parse_quote! { fn k(grid: HashGrid, x: Array<f32>) {
                    let i = hash_grid_point_id(grid, x[0]);
                } },
                "indices are integers",
            ),
        ];
        for (item, want) in cases {
            let e = lower(item).unwrap_err();
            assert!(e.contains(want), "{want}: {e}");
        }
    }
}
