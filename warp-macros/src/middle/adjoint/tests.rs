use super::*;
use syn::parse_quote;

use crate::test_support::kernel;

fn name(f: &Function, v: VarId) -> String {
    f.vars[v].name.clone().unwrap_or_else(|| format!("t{v}"))
}

/// Every block (a statement list), depth first.
fn blocks(b: &[AStmt]) -> Vec<&[AStmt]> {
    let mut out = vec![b];
    for s in b {
        match &s.kind {
            AKind::If { then, els, .. } => {
                out.extend(blocks(then));
                out.extend(blocks(els));
            }
            AKind::Loop { body, .. } | AKind::RevLoop { body } | AKind::Scope(body) => {
                out.extend(blocks(body))
            }
            _ => {}
        }
    }
    out
}

/// Every statement, depth first.
fn all(b: &[AStmt]) -> Vec<&AStmt> {
    blocks(b).into_iter().flatten().collect()
}

/// How the adjoint touches array gradients, one line per statement (`fast`/`slow`: in the
/// branch of an `if __FAST`; `reg`: the adjoint of a variable the pass added, numbered from
/// `first_new`), sorted.
fn gradient_updates(a: &Adjoint, first_new: VarId) -> Vec<String> {
    fn walk(a: &Adjoint, first_new: VarId, b: &[AStmt], ctx: &str, out: &mut Vec<String>) {
        let n = |v: &VarId| name(&a.f, *v);
        let adj = |g: &GradSrc| match g {
            GradSrc::Adj { var, .. } if *var >= first_new => "reg".to_string(),
            GradSrc::Seed => "seed".into(),
            g => format!("{g:?}"),
        };
        for s in b {
            match &s.kind {
                AKind::If { cond, then, els } => {
                    let (t, e) = match cond {
                        Cond::Fast => ("fast ", "slow "),
                        _ => (ctx, ctx),
                    };
                    walk(a, first_new, then, t, out);
                    walk(a, first_new, els, e, out);
                }
                AKind::Loop { body, .. } | AKind::RevLoop { body } | AKind::Scope(body) => {
                    walk(a, first_new, body, ctx, out)
                }
                AKind::GradAccum {
                    array, from, own, ..
                } => {
                    let how = if *own { "own" } else { "atomic" };
                    out.push(format!("{ctx}{how} {} += {}", n(array), adj(from)));
                }
                AKind::GradClearOwn { array, .. } => out.push(format!("{ctx}clear {}", n(array))),
                AKind::Accum { to, from } => match (to, from) {
                    (AdjOf::Var { var, .. }, g) if *var >= first_new => {
                        out.push(format!("{ctx}reg += {}", adj(g)))
                    }
                    (_, GradSrc::Take { array, .. }) => out.push(format!("{ctx}take {}", n(array))),
                    (_, GradSrc::Get { array, .. }) => out.push(format!("{ctx}get {}", n(array))),
                    _ => {}
                },
                _ => {}
            }
        }
    }
    let mut out = Vec::new();
    walk(a, first_new, &a.body, "", &mut out);
    out.sort();
    out
}

#[test]
fn thread_owned_arrays_follow_the_policy() {
    let f = kernel(parse_quote! {
        fn k(x: Array<f32>, y: Array<f32>, z: Array<f32>, j: i32) {
            let i = tid();
            y[i] = x[i] * z[j];
        }
    });
    let first_new = f.vars.len();
    // z is read at another index: atomic on every target. The CPU updates x's gradient as
    // its only user under __FAST, and takes y's.
    let a = build(&f, Policy::CPU).unwrap();
    let expect = [
        "atomic z += seed",
        "fast own x += seed",
        "slow atomic x += seed",
        "take y",
    ];
    assert_eq!(gradient_updates(&a, first_new), expect);
    assert_eq!(a.f.vars.len(), first_new);
    // CUDA gathers x's in a register (the adjoint of a variable of the pass), added at the
    // end, and only reads y's, cleared at the end.
    let a = build(&f, Policy::CUDA).unwrap();
    let expect = [
        "atomic z += seed",
        "fast clear y",
        "fast get y",
        "fast own x += reg",
        "fast reg += seed",
        "slow atomic x += seed",
        "slow take y",
    ];
    assert_eq!(gradient_updates(&a, first_new), expect);
    assert_eq!(a.f.vars.len(), first_new + 1);
    assert!(a.adjs.contains(&first_new));
}

#[test]
fn loops_push_restore_and_record() {
    let f = kernel(parse_quote! {
        fn k(x: Array<f64>, out: Array<f64>) {
            let mut p: f64 = 1.0;
            for i in 0..N {
                for j in 0..i {
                    if x[j] > 0.0 { p = p * x[j]; }
                }
            }
            out[0] = p;
        }
    });
    let a = build(&f, Policy::CPU).unwrap();
    assert!(a.uses_stack);
    // The loop variables have the type of their bounds (the const's, for the outer one),
    // and are declared after them.
    let pos = |n: &str| a.decls.iter().position(|d| name(&a.f, d.var) == n).unwrap();
    for (var, end) in [("i", None), ("j", Some("i"))] {
        let d = &a.decls[pos(var)];
        let Some(TypeOf::Var(e)) = &d.def else {
            panic!("{var}: {:?}", d.def)
        };
        if let Some(end) = end {
            assert_eq!(name(&a.f, *e), end);
        }
        assert!(a
            .decls
            .iter()
            .position(|d| d.var == *e)
            .is_none_or(|k| k < pos(var)));
    }
    // Each reversed `for` iteration ends by restoring its variable.
    let stmts = all(&a.body);
    let rev_loops: Vec<&Vec<AStmt>> = stmts
        .iter()
        .filter_map(|s| match &s.kind {
            AKind::RevLoop { body } => Some(body),
            _ => None,
        })
        .collect();
    assert_eq!(rev_loops.len(), 2);
    for b in rev_loops {
        assert!(matches!(b.last().map(|s| &s.kind), Some(AKind::Pop { .. })));
    }
    // The `if` inside the loops copies its decision into a declared variable of the pass,
    // branches on it and pushes it; the sweep branches on the popped decision.
    let recorded = stmts
        .windows(3)
        .find_map(|w| match (&w[0].kind, &w[1].kind, &w[2].kind) {
            (
                AKind::Assign { dst, .. },
                AKind::If {
                    cond: Cond::Var(c), ..
                },
                AKind::Push { var, .. },
            ) if dst == c && c == var => Some(*c),
            _ => None,
        });
    let c = recorded.expect("a recorded decision");
    assert!(c >= f.vars.len() && a.decls.iter().any(|d| d.var == c));
    assert!(stmts.iter().any(|s| matches!(
        &s.kind,
        AKind::If {
            cond: Cond::Popped,
            ..
        }
    )));
}

#[test]
fn atomics_replay_as_zero() {
    let f = kernel(parse_quote! {
        fn k(x: Array<f32>, sum: Array<f32>) {
            let i = tid();
            atomic_sub(sum, 0, x[i] * 2.0);
        }
    });
    let a = build(&f, Policy::CUDA).unwrap();
    let stmts = all(&a.body);
    assert!(stmts.iter().any(|s| matches!(
        &s.kind,
        AKind::Assign {
            value: Value::Zero { .. },
            ..
        }
    )));
    // The seed is the gradient at the index; sub negates it into the value's adjoint.
    let seeded = blocks(&a.body)
        .into_iter()
        .flat_map(|b| b.windows(2))
        .any(|w| {
            matches!(
                (&w[0].kind, &w[1].kind),
                (
                    AKind::Seed(GradSrc::Get { .. }),
                    AKind::AdjCall { func, grads, .. },
                ) if func == "adj_neg" && matches!(grads[..], [GradArg::Adj(_)])
            )
        });
    assert!(seeded);
    // Nothing is pushed: a kernel without loops or calls needs no stack.
    assert!(!a.uses_stack);
}

#[test]
fn atomic_extremes_compare_with_the_array_after_the_launch() {
    let f = kernel(parse_quote! {
        fn k(x: Array<f32>, m: Array<f32>) {
            let i = tid();
            atomic_max(m, 0, x[i]);
        }
    });
    let a = build(&f, Policy::CPU).unwrap();
    let stmts = all(&a.body);
    // A variable of the pass holds the array's value, read in the sweep.
    let cur = stmts.iter().find_map(|s| match &s.kind {
        AKind::Assign {
            dst,
            value: Value::Op(Op::Load { .. }),
        } if *dst >= f.vars.len() => Some(*dst),
        _ => None,
    });
    let cur = cur.expect("the array's value is read in the sweep");
    assert!(a.decls.iter().any(|d| d.var == cur));
    assert!(!a.adjs.contains(&cur));
    assert!(stmts.iter().any(|s| matches!(
        &s.kind,
        AKind::AdjCall { func, values, .. }
            if func == "adj_atomic_extreme" && values[0] == Arg::Value(cur)
    )));
}

/// The adjoint calls of `a`, in order.
fn adj_calls(a: &Adjoint) -> Vec<String> {
    let calls = all(&a.body).into_iter().filter_map(|s| match &s.kind {
        AKind::AdjCall { func, .. } => Some(func.clone()),
        _ => None,
    });
    calls.collect()
}

/// Backward through `tile_atomic_add`: the value tile's adjoint gathers the array's gradient
/// (`adj_tile_atomic_add<rank>`), and the replay does not redo the atomic.
#[test]
fn tile_atomic_add_has_an_adjoint_and_is_not_replayed() {
    let f = kernel(parse_quote! {
        fn k(x: Array<f64, 2>, acc: Array<f64, 2>) {
            let t: Tile<f64, 4, 3> = tile_load(x, (0, 0));
            tile_atomic_add(acc, t * t, (1, -1));
        }
    });
    let a = build(&f, Policy::CUDA).unwrap();
    let calls = adj_calls(&a);
    assert!(
        calls.iter().any(|c| c == "adj_tile_atomic_add2"),
        "{calls:?}"
    );
    let redone = all(&a.body).into_iter().any(|s| {
        matches!(&s.kind, AKind::Assign { value: Value::Op(Op::Builtin { builtin, .. }), .. }
            if builtin.name == "tile_atomic_add")
    });
    assert!(!redone, "the replay redoes the atomic");
}

/// Backward through both forms of the f16 matmul: `adj_tile_matmul` for each.
#[test]
fn f16_matmul_has_an_adjoint() {
    let f = kernel(parse_quote! {
        fn k(a: Array<f16, 2>, b: Array<f16, 2>, p: Array<f16, 2>, c: Array<f32, 2>) {
            let ta: Tile<f16, 16, 16> = tile_load(a, (0, 0));
            let tb: Tile<f16, 16, 8> = tile_load(b, (0, 0));
            tile_store(p, tile_matmul(ta, tb), (0, 0));
            let mut acc = tile_zeros::<f32, 16, 8>();
            tile_matmul(ta, tb, &mut acc);
            tile_store(c, acc, (0, 0));
        }
    });
    let a = build(&f, Policy::CUDA).unwrap();
    let calls = adj_calls(&a);
    let n = calls.iter().filter(|c| *c == "adj_tile_matmul").count();
    assert_eq!(n, 2, "{calls:?}");
}

/// A local array is one variable: an element store in a loop pushes the whole array before it
/// and pops it after its reverse, whose seed is the element's adjoint (then cleared); a read
/// accumulates into the element's adjoint; a literal seeds its elements' values, a repeat the
/// sum of its adjoint's elements.
#[test]
fn local_array_element_stores_overwrite_the_array() {
    let f = kernel(parse_quote! {
        fn k(x: Array<f64>, y: Array<f64>) {
            let i = tid();
            let t = x[i];
            let mut a = [t; 3];
            let b = [t, 2.0, t * t];
            for j in 0..3 {
                a[j] = a[(j + 1) % 3] * b[j];
            }
            y[i] = a[0];
        }
    });
    let a = build(&f, Policy::CPU).unwrap();
    let arr = (0..a.f.vars.len())
        .find(|v| a.f.vars[*v].name.as_deref() == Some("a"))
        .unwrap();
    let stmts = all(&a.body);
    let pos = |p: &dyn Fn(&AKind) -> bool| stmts.iter().position(|s| p(&s.kind));
    let push = pos(&|k| matches!(k, AKind::Push { var, .. } if *var == arr)).unwrap();
    let set = pos(&|k| matches!(k, AKind::SetElem { var, .. } if *var == arr)).unwrap();
    assert!(push < set, "the array is pushed before its element store");
    let count = |p: &dyn Fn(&AKind) -> bool| stmts.iter().filter(|s| p(&s.kind)).count();
    // Its definition (a `mut` variable) and the store in the loop each push it once; the
    // reverse pops it as often.
    assert_eq!(
        count(&|k| matches!(k, AKind::Push { var, .. } if *var == arr)),
        2
    );
    assert_eq!(
        count(&|k| matches!(k, AKind::Pop { var } if *var == arr)),
        2
    );
    assert_eq!(
        count(&|k| matches!(k, AKind::Seed(GradSrc::AdjElem { var, .. }) if *var == arr)),
        1
    );
    assert_eq!(
        count(&|k| matches!(k, AKind::ClearAdjElem { var, .. } if *var == arr)),
        1
    );
    // Reads of `a` and `b` at an index: into the element's adjoint.
    let elem_accums = count(&|k| {
        matches!(
            k,
            AKind::Accum {
                to: AdjOf::Elem { .. },
                ..
            }
        )
    });
    assert_eq!(elem_accums, 3);
    // `[t; 3]`: the sum of the adjoint's elements into `t`.
    assert_eq!(
        count(&|k| matches!(
            k,
            AKind::Accum {
                from: GradSrc::ElemSum,
                ..
            }
        )),
        1
    );
    let lanes: Vec<usize> = stmts
        .iter()
        .filter_map(|s| match &s.kind {
            AKind::Accum {
                from: GradSrc::SeedElem(k),
                ..
            } => Some(*k),
            _ => None,
        })
        .collect();
    // Every element of the literal is a float variable (the `2.0` too).
    assert_eq!(lanes, [0, 1, 2]);
    assert!(a.adjs.contains(&arr), "the array has an adjoint");
}
