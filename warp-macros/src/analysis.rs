//! Facts about a lowered function that emitters use.

use crate::ir::*;

/// For each variable, the component of the thread index it is known to hold (an immutable
/// copy of `tid()` or of such a copy), if any.
pub fn tid_components(f: &Function) -> Vec<Option<u8>> {
    let mut comp = vec![None; f.vars.len()];
    // Immutable variables have exactly one (defining) assignment, which precedes every use in
    // statement order, so one walk in order settles them.
    walk_stmts(&f.body, &mut |s| {
        if let StmtKind::Assign {
            dst,
            op,
            define: true,
        } = &s.kind
        {
            if f.vars[*dst].mutable {
                return;
            }
            comp[*dst] = match op {
                Op::Tid(k) => Some(*k),
                Op::Copy(v) => comp[*v],
                _ => None,
            };
        }
    });
    comp
}

/// Is an access `array[index]` indexed exactly by the thread index, dimension by dimension?
/// Then the launch can check it once for the whole grid instead of once per thread.
pub fn is_tid_access(f: &Function, tid: &[Option<u8>], array: VarId, index: &[VarId]) -> bool {
    let is_param = f.params.iter().any(|p| p.var == array);
    // In a tiled kernel `tid()` is the block's index: the launch's cover check says nothing
    // about the accesses it indexes.
    f.tiled.is_none()
        && is_param
        && f.tid_ndim == Some(index.len() as u8)
        && index
            .iter()
            .enumerate()
            .all(|(d, v)| tid[*v] == Some(d as u8))
}

/// The parameters accessed through [`is_tid_access`] accesses.
pub fn tid_accessed_params(f: &Function, tid: &[Option<u8>]) -> Vec<VarId> {
    let mut out = Vec::new();
    walk_stmts(&f.body, &mut |s| {
        let access = match &s.kind {
            StmtKind::Assign {
                op: Op::Load { array, index },
                ..
            } => Some((*array, index)),
            StmtKind::Store { array, index, .. } => Some((*array, index)),
            _ => None,
        };
        if let Some((a, idx)) = access {
            if is_tid_access(f, tid, a, idx) && !out.contains(&a) {
                out.push(a);
            }
        }
    });
    out
}

/// Indices of the array parameters a kernel may write: stored to, updated atomically, or
/// passed to a func (which may store).
pub fn written_params(f: &Function) -> Vec<usize> {
    let mut w: Vec<VarId> = Vec::new();
    walk_stmts(&f.body, &mut |s| match &s.kind {
        StmtKind::Store { array, .. } => w.push(*array),
        StmtKind::Assign {
            op: Op::Builtin { builtin, args },
            ..
        } if builtin.writes_array() => w.push(args[0]),
        StmtKind::Assign {
            op: Op::Func { args, .. },
            ..
        } => w.extend(args.iter().copied()),
        _ => {}
    });
    f.params
        .iter()
        .enumerate()
        .filter(|(_, p)| matches!(p.ty, crate::types::Ty::Array(..)) && w.contains(&p.var))
        .map(|(k, _)| k)
        .collect()
}

/// The array parameters accessed only through [`is_tid_access`] accesses (loads, stores; no
/// other access, no atomic, no func argument): in a launch whose arrays cover the grid, each
/// element of such an array is touched by one thread only, so its gradient can be
/// accumulated without atomics.
pub fn tid_only_params(f: &Function, tid: &[Option<u8>]) -> Vec<VarId> {
    let mut other: Vec<VarId> = Vec::new();
    walk_stmts(&f.body, &mut |s| match &s.kind {
        StmtKind::Assign {
            op: Op::Load { array, index },
            ..
        }
        | StmtKind::Store { array, index, .. }
            if !is_tid_access(f, tid, *array, index) =>
        {
            other.push(*array)
        }
        StmtKind::Assign {
            op: Op::Load { .. },
            ..
        }
        | StmtKind::Store { .. } => {}
        StmtKind::Assign { op, .. } => op.for_each_read(&mut |v| other.push(v)),
        _ => {}
    });
    tid_accessed_params(f, tid)
        .into_iter()
        .filter(|a| !other.contains(a))
        .collect()
}

/// The 1-D array parameters that `body` accesses (loads and stores) at exactly `var`, a loop
/// variable. For a loop over `lo..hi`, one check that `lo..hi` lies inside such an array
/// before the loop makes every one of those accesses in bounds.
pub fn loop_indexed_params(f: &Function, body: &Block, var: VarId) -> Vec<VarId> {
    let mut out = Vec::new();
    walk_stmts(body, &mut |s| {
        let access = match &s.kind {
            StmtKind::Assign {
                op: Op::Load { array, index },
                ..
            } => Some((*array, index)),
            StmtKind::Store { array, index, .. } => Some((*array, index)),
            _ => None,
        };
        if let Some((a, idx)) = access {
            let is_param = f.params.iter().any(|p| p.var == a);
            if is_param && idx.as_slice() == [var] && !out.contains(&a) {
                out.push(a);
            }
        }
    });
    out
}

/// A `loop` that `front::lower::query` made of `for j in query(object, ..) { .. }` over a row
/// whose items its `next` checks against a bound (`Iterate::bound`): the object, the loop
/// variable `j` and the bound's CUDA function. Matched on the lowering's shape: the state's
/// `next`, its `done` and the `break`, then the item. `None` for any other loop, for a
/// mutable `j` or object (an assignment could move either), and for a loop without a
/// variable.
pub fn bounded_query_loop(f: &Function, body: &Block) -> Option<(VarId, VarId, &'static str)> {
    let [first, _, _, item_stmt, ..] = body.as_slice() else {
        return None;
    };
    let StmtKind::Assign {
        op: Op::Builtin {
            builtin: next,
            args,
        },
        ..
    } = &first.kind
    else {
        return None;
    };
    let it = crate::builtins::BUILTINS
        .iter()
        .filter_map(|b| b.iterate)
        .find(|it| it.next == next.name)?;
    let bound = it.bound?;
    let StmtKind::Assign {
        dst: j,
        op: Op::Builtin { builtin: item, .. },
        define: true,
    } = &item_stmt.kind
    else {
        return None;
    };
    let object = *args.first()?;
    (item.name == it.item && !f.vars[*j].mutable && !f.vars[object].mutable)
        .then_some((object, *j, bound))
}

/// Whether `array` is an array of floats or float vectors (the array's element type: a
/// value's type may be one the macro cannot see).
pub fn float_elements(f: &Function, array: VarId) -> bool {
    matches!(f.ty(array), crate::types::Ty::Array(e, _)
        if e.scalar().is_some_and(|s| s.is_float()))
}

/// Whether a call of `builtin` on `args` is a float accumulation, what a deterministic kernel
/// records: `atomic_add` or `atomic_sub` into an array of floats or float vectors.
pub fn float_accumulation(
    f: &Function,
    builtin: &crate::builtins::Builtin,
    args: &[VarId],
) -> bool {
    matches!(builtin.name, "atomic_add" | "atomic_sub") && float_elements(f, args[0])
}

/// Whether `f` makes a float accumulation ([`float_accumulation`]) anywhere: a func that
/// does cannot be called from a deterministic kernel (its calls are not recorded).
pub fn has_float_accumulation(f: &Function) -> bool {
    let mut found = false;
    walk_stmts(&f.body, &mut |s| {
        if let StmtKind::Assign {
            op: Op::Builtin { builtin, args },
            ..
        } = &s.kind
        {
            found |= float_accumulation(f, builtin, args);
        }
    });
    found
}

/// The arrays `f` stores into with a plain store or passes to a func (which may store into
/// them). A deterministic kernel's adjoint records its gradient accumulations into the other
/// arrays only: the adjoint of a store takes (reads and clears) the element's gradient during
/// the launch, and must see every accumulation into it made before, which a recorded one,
/// added after the launch, is not.
pub fn stored_or_passed(f: &Function) -> Vec<VarId> {
    let mut out = Vec::new();
    walk_stmts(&f.body, &mut |s| match &s.kind {
        StmtKind::Store { array, .. } => out.push(*array),
        StmtKind::Assign {
            op: Op::Func { args, .. },
            ..
        } => out.extend(
            args.iter()
                .filter(|v| matches!(f.ty(**v), crate::types::Ty::Array(..))),
        ),
        _ => {}
    });
    out
}

/// Why an adjoint of `f` cannot be generated because of an atomic: one without an adjoint
/// (`atomic_cas`, `atomic_exch`, `atomic_and/or/xor`) on float elements (the gradient it
/// carries would be lost), or any atomic whose returned old value is used (the adjoint's
/// replay does not redo atomics, so it would not have that value: `let slot =
/// atomic_add(count, 0, 1); out[slot] = ..` would send every gradient to `out[0]`). Updates
/// whose result is unused, the common case of accumulations, flags and counters, are fine.
pub fn atomic_without_adjoint(f: &Function) -> Option<String> {
    let mut reads: Vec<VarId> = Vec::new();
    walk_stmts(&f.body, &mut |s| {
        s.kind.for_each_read(&mut |v| reads.push(v))
    });
    let mut why = None;
    walk_stmts(&f.body, &mut |s| {
        if why.is_some() {
            return;
        }
        if let StmtKind::Assign {
            dst,
            op: Op::Builtin { builtin, args },
            ..
        } = &s.kind
        {
            if builtin.grad == crate::builtins::Grad::Effect {
                // A store into an object: the stored value's gradient would be lost.
                let float_value = f
                    .ty(args[args.len() - 1])
                    .scalar()
                    .is_some_and(|s| s.is_float());
                if float_value {
                    why = Some(format!(
                        "stores a float with `{}`, which has no adjoint yet",
                        builtin.name
                    ));
                }
                return;
            }
            if !builtin.is_atomic() {
                return;
            }
            if builtin.grad == crate::builtins::Grad::AtomicNone && float_elements(f, args[0]) {
                why = Some(format!(
                    "uses `{}` on floats, which has no adjoint (as in Warp)",
                    builtin.name
                ));
            } else if reads.contains(dst) {
                why = Some(format!(
                    "uses the old value `{}` returns, which the adjoint's replay cannot recompute",
                    builtin.name
                ));
            }
        }
    });
    why
}

#[cfg(test)]
mod tests {
    use super::*;
    use syn::parse_quote;

    #[test]
    fn tid_accesses_are_found() {
        let item: syn::ItemFn = parse_quote! {
            fn k(a: Array<f32>, b: Array<f32>, c: Array<f32>) {
                let i = tid();
                let j = i;
                let mut m = i;
                m += 0;
                a[j] = b[i] + c[m] + c[0];
            }
        };
        let f = crate::front::lower::lower_fn(&item, FnKind::Kernel).unwrap();
        let tid = tid_components(&f);
        let params: Vec<String> = tid_accessed_params(&f, &tid)
            .iter()
            .map(|v| f.vars[*v].name.clone().unwrap())
            .collect();
        assert_eq!(
            params,
            vec!["b", "a"],
            "c is indexed by a mutable copy and by a constant"
        );
    }
}
