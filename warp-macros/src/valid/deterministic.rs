//! `#[kernel(deterministic)]`: what such a kernel may not do, and its per-thread record limit.
//!
//! A deterministic kernel's float `atomic_add`/`atomic_sub` are recorded and added into their
//! elements after the launch in a fixed order (docs/book/src/deterministic.md), so:
//! - the old value such a call returns does not exist: reading it is an error at the call;
//! - `atomic_exch`/`atomic_cas` on floats keep whichever write came last, an order no
//!   recording fixes: an error at the call;
//! - a tiled kernel's lanes are not supported yet: an error;
//! - `bsr_add_block` (a float atomic add into a sparse matrix's values) is not recorded yet:
//!   an error at the call.
//!
//! Integer atomics are exact whatever the order (their final values are deterministic
//! already; the old values they return are not, and stay the user's to use), and float
//! `atomic_min`/`atomic_max` are order-independent: both are left as they are.

use crate::analysis::float_accumulation;
use crate::ir::{Block, Function, Op, StmtKind, VarId};

/// The per-thread record limit when a float accumulation sits in a loop and the kernel does
/// not say `max_records = N`: the number of calls a thread makes is then not known at compile
/// time.
pub const DEFAULT_MAX_RECORDS: u32 = 64;

/// Checks a deterministic kernel and returns its per-thread record limit: `explicit` if
/// given, else the number of float accumulation calls when none is in a loop (each runs at
/// most once per thread), else the larger of that number and [`DEFAULT_MAX_RECORDS`].
pub fn check(f: &Function, explicit: Option<u32>) -> Result<u32, Vec<syn::Error>> {
    let mut reads: Vec<VarId> = Vec::new();
    crate::ir::walk_stmts(&f.body, &mut |s| {
        s.kind.for_each_read(&mut |v| reads.push(v))
    });
    let mut errors = Vec::new();
    let mut sites = 0u32;
    let mut in_loop = false;
    walk(&f.body, false, &mut |s_kind, span, looped| {
        let StmtKind::Assign {
            dst,
            op: Op::Builtin { builtin, args },
            ..
        } = s_kind
        else {
            return;
        };
        if float_accumulation(f, builtin, args) {
            sites = sites.saturating_add(1);
            in_loop |= looped;
            if reads.contains(dst) {
                errors.push(syn::Error::new(
                    span,
                    format!(
                        "a deterministic kernel cannot use the old value `{}` returns: its \
                         float accumulations are recorded and added after the launch, so there \
                         is none",
                        builtin.name
                    ),
                ));
            }
        } else if matches!(builtin.name, "atomic_exch" | "atomic_cas")
            && crate::analysis::float_elements(f, args[0])
        {
            errors.push(syn::Error::new(
                span,
                format!(
                    "`{}` on floats keeps whichever thread wrote last, which no order of a \
                     deterministic kernel fixes",
                    builtin.name
                ),
            ));
        } else if builtin.name == "bsr_add_block" {
            // Its adds go into a matrix's values, which the recording of float
            // accumulations (arrays' elements) does not reach yet.
            errors.push(syn::Error::new(
                span,
                "`bsr_add_block` is not ordered in a deterministic kernel yet: sum the blocks \
                 with `Bsr::from_triplets` (ordered sums), or write each block from one \
                 thread with `bsr_set_block`",
            ));
        }
    });
    if !errors.is_empty() {
        return Err(errors);
    }
    Ok(match explicit {
        Some(n) => n,
        None if in_loop => sites.max(DEFAULT_MAX_RECORDS),
        // A kernel without accumulations records nothing; 1 keeps the limit meaningful.
        None => sites.max(1),
    })
}

/// The arrays whose elements a deterministic kernel's adjoint records gradient accumulations
/// into (the reads of arrays it neither stores into nor passes to a func:
/// `analysis::stored_or_passed`), and whether one such read sits in a loop.
fn recorded_reads(f: &Function) -> (Vec<VarId>, u32, bool) {
    let excluded = crate::analysis::stored_or_passed(f);
    let (mut arrays, mut sites, mut in_loop) = (Vec::new(), 0u32, false);
    walk(&f.body, false, &mut |s_kind, _, looped| {
        if let StmtKind::Assign {
            op: Op::Load { array, .. },
            ..
        } = s_kind
        {
            if !excluded.contains(array) {
                sites = sites.saturating_add(1);
                in_loop |= looped;
                if !arrays.contains(array) {
                    arrays.push(*array);
                }
            }
        }
    });
    (arrays, sites, in_loop)
}

/// The per-thread limit of a deterministic kernel's recorded gradient accumulations in its
/// adjoint (each recorded read's reverse makes one): the number of such reads when none is in
/// a loop, else the larger of that number and the forward's limit `forward`.
pub fn adjoint_limit(f: &Function, forward: u32) -> u32 {
    let (_, sites, in_loop) = recorded_reads(f);
    match in_loop {
        true => sites.max(forward),
        false => sites.max(1),
    }
}

/// The arrays whose elements a deterministic kernel records accumulations into, forward
/// (float `atomic_add`/`atomic_sub`) or in its adjoint (gradients of recorded reads): a GPU's
/// record slots are sized for the widest of their elements.
pub fn recorded_arrays(f: &Function) -> Vec<VarId> {
    let mut out = recorded_reads(f).0;
    walk(&f.body, false, &mut |s_kind, _, _| {
        if let StmtKind::Assign {
            op: Op::Builtin { builtin, args },
            ..
        } = s_kind
        {
            if float_accumulation(f, builtin, args) && !out.contains(&args[0]) {
                out.push(args[0]);
            }
        }
    });
    out
}

/// Calls `visit` on every statement with its span and whether it sits in a loop.
fn walk(block: &Block, looped: bool, visit: &mut dyn FnMut(&StmtKind, proc_macro2::Span, bool)) {
    for s in block {
        visit(&s.kind, s.span, looped);
        match &s.kind {
            StmtKind::If { then, els, .. } => {
                walk(then, looped, visit);
                walk(els, looped, visit);
            }
            StmtKind::For { body, .. } | StmtKind::Loop { body } => walk(body, true, visit),
            _ => {}
        }
    }
}
