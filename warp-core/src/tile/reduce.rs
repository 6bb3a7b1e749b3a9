//! Whole-tile reductions in the GPU's order: `tile_sum`, `tile_min`, `tile_max`,
//! `tile_reduce(op)`, `tile_argmin`, `tile_argmax`. Each returns a `Tile1<_, 1>`.
//!
//! # The order (the CUDA library must match it bit for bit)
//!
//! Let `x[0..S]` be the tile's elements in row-major order, `bd` the block size (its lanes
//! `0..bd`), and `op(a, b)` the combining operation. A *partial* is either a value or *empty*;
//! `combine(a, b)` is `op(a, b)` when both are values and otherwise the one that is not empty
//! (empty when both are). Then:
//!
//! 1. **Per lane.** Lane `l` owns the elements `e = l, l + bd, l + 2·bd, ..` below `S`. If it
//!    owns none (`l >= S`), its partial is empty. Otherwise it starts from its first element
//!    and folds the rest in increasing `e`: `p = x[l]; p = op(p, x[l + bd]); ..`.
//! 2. **Per warp.** Lanes are grouped into warps of 32 (`w = l / 32`; a lane `>= bd` does not
//!    exist and its partial is empty). Within a warp, for `offset = 16, 8, 4, 2, 1` in that
//!    order, every lane `i` (its position in the warp) with `i + offset < 32` sets
//!    `p[i] = combine(p[i], p[i + offset])` from the values before the step, as
//!    `__shfl_down_sync` delivers them (own value on the left). The warp's result is `p[0]`.
//! 3. **Across warps.** Lane 0 of the block folds the warps' results in warp order:
//!    `r = combine(combine(r0, r1), r2) ..` (empty warps, whose lanes own no element, are
//!    skipped by `combine`).
//!
//! An empty partial is never an operand of `op`, so no identity is needed (`tile_reduce` takes
//! any user operation) and an empty lane never changes a result. For `sum` this is the same as
//! giving empty lanes the identity `0` for every input except the sign of a zero: adding `+0`
//! would turn a sum of `-0.0`s into `+0.0`, while here it stays `-0.0`, as sequential
//! summation gives. The CUDA side knows which partials are empty from the lane index alone
//! (lane `l` owns an element iff `l < min(bd, S)`, a prefix of the lanes), so it needs no flag.
//!
//! For `bd == 1` this is sequential left-to-right summation. `sum` adds with IEEE `+` (floats)
//! or wrapping `+` (integers), `min`/`max` use the builtins' `min`/`max` (a NaN operand loses
//! to a number, as `fminf`/`fmaxf`). `bd` outside `1..=1024` is clamped into it: launches
//! never have such a block size (`launch_tiled` refuses them).
//!
//! `argmin`/`argmax` reduce `(value, index)` pairs under a total order: numbers before NaN,
//! then the value (smaller for `argmin`, larger for `argmax`), then the smaller index. The
//! minimum of a total order does not depend on the order of combination, so these agree with
//! Warp's "first index of the extremum" for every `bd`; a tile of only NaNs gives index 0.

use super::{Tile, Tile1};
use crate::builtins::{MinMax, Scalar};
use crate::fault::KResult;

/// The largest block size (CUDA's limit on threads per block).
pub const MAX_BLOCK_DIM: usize = 1024;

/// The width of a warp.
const WARP: usize = 32;

/// `combine` of the module docs: `op` on two values, else the one present.
#[inline(always)]
fn combine<E: Copy>(a: Option<E>, b: Option<E>, op: &impl Fn(E, E) -> E) -> Option<E> {
    match (a, b) {
        (Some(a), Some(b)) => Some(op(a, b)),
        (a, None) => a,
        (None, b) => b,
    }
}

/// Reduces the `size` values `elem(0..size)` with `op` in the GPU's order for block size `bd`
/// (see the module docs); `None` only when `size == 0`.
pub fn gpu_order<E: Copy>(
    size: usize,
    bd: usize,
    elem: impl Fn(usize) -> E,
    op: impl Fn(E, E) -> E,
) -> Option<E> {
    let bd = bd.clamp(1, MAX_BLOCK_DIM);
    // Lanes 0..active own at least one element; the others' partials are empty.
    let active = size.min(bd);
    let mut result = None;
    for w in 0..active.div_ceil(WARP) {
        let mut p: [Option<E>; WARP] = [None; WARP];
        for (i, slot) in p.iter_mut().enumerate() {
            let l = w * WARP + i;
            if l >= active {
                break;
            }
            let mut acc = elem(l);
            let mut e = l + bd;
            while e < size {
                acc = op(acc, elem(e));
                e += bd;
            }
            *slot = Some(acc);
        }
        let mut offset = WARP / 2;
        while offset > 0 {
            // Lanes below `offset` read lanes at or above it, which this step does not write,
            // so updating in place reads the values from before the step; the lanes at or above
            // `offset` no longer feed lane 0.
            for i in 0..offset {
                p[i] = combine(p[i], p[i + offset], &op);
            }
            offset /= 2;
        }
        result = combine(result, p[0], &op);
    }
    result
}

/// The reduction of a non-empty tile (a zero-sized tile does not compile).
#[inline(always)]
fn reduce_tile<X: Tile<Elem: Copy>>(
    t: &X,
    bd: usize,
    op: impl Fn(X::Elem, X::Elem) -> X::Elem,
) -> Tile1<X::Elem, 1> {
    const { assert!(X::SIZE > 0, "a tile has at least one element") };
    let x = t.as_flat();
    let r = gpu_order(x.len(), bd, |e| x[e], op);
    Tile1 {
        data: [r.unwrap_or(x[0])],
    }
}

/// `tile_reduce(op, t)`: `t`'s elements combined with `op` in the GPU's order for block size
/// `bd` (module docs); `op(a, b)` gets the earlier partial as `a`.
pub fn reduce<X: Tile<Elem: Copy>>(
    t: &X,
    bd: usize,
    op: impl Fn(X::Elem, X::Elem) -> X::Elem,
) -> Tile1<X::Elem, 1> {
    reduce_tile(t, bd, op)
}

/// `tile_reduce(func, t)` of a user func, which may fault: `reduce`'s order, stopping at the
/// first call that faults (in that order) with its error, as a scalar call stops the thread.
/// The GPU lets every call run and sets the fault; either way the launch fails.
pub fn try_reduce<X: Tile<Elem: Copy>>(
    t: &X,
    bd: usize,
    op: impl Fn(X::Elem, X::Elem) -> KResult<X::Elem>,
) -> KResult<Tile1<X::Elem, 1>> {
    // `gpu_order` takes an infallible `op`: after the first fault the remaining combinations
    // return their left operand unchanged, without calling the func again.
    let fault = core::cell::Cell::new(None);
    let r = reduce_tile(t, bd, |a, b| {
        let failed = fault.take();
        let ok = failed.is_none();
        fault.set(failed);
        if !ok {
            return a;
        }
        match op(a, b) {
            Ok(v) => v,
            Err(e) => {
                fault.set(Some(e));
                a
            }
        }
    });
    match fault.into_inner() {
        Some(e) => Err(e),
        None => Ok(r),
    }
}

/// `tile_sum(t)`: IEEE `+` for floats, wrapping `+` for integers, in the GPU's order for block
/// size `bd`.
pub fn sum<X: Tile<Elem: Scalar>>(t: &X, bd: usize) -> Tile1<X::Elem, 1> {
    reduce_tile(t, bd, Scalar::s_add)
}

/// `tile_min(t)`: the builtin `min` (a NaN loses to a number) in the GPU's order.
pub fn min<X: Tile<Elem: MinMax>>(t: &X, bd: usize) -> Tile1<X::Elem, 1> {
    reduce_tile(t, bd, MinMax::w_min)
}

/// `tile_max(t)`: the builtin `max` (a NaN loses to a number) in the GPU's order.
pub fn max<X: Tile<Elem: MinMax>>(t: &X, bd: usize) -> Tile1<X::Elem, 1> {
    reduce_tile(t, bd, MinMax::w_max)
}

/// The pair of the two that comes first in the order of the module docs: numbers before NaN
/// (a value unordered with itself), then by `better`, then the smaller index.
#[inline(always)]
fn pick<T: PartialOrd + Copy>(
    a: (T, usize),
    b: (T, usize),
    better: impl Fn(&T, &T) -> bool,
) -> (T, usize) {
    #[allow(clippy::eq_op)] // `v == v` is false exactly for NaN
    let nan = |v: &T| v != v;
    let (an, bn) = (nan(&a.0), nan(&b.0));
    let b_first = if an != bn {
        an
    } else if an || a.0 == b.0 {
        b.1 < a.1
    } else {
        better(&b.0, &a.0)
    };
    if b_first {
        b
    } else {
        a
    }
}

/// The row-major index of the extremum by `better`, as a `Tile1<i32, 1>`.
fn arg_extreme<X: Tile<Elem: Scalar>>(
    t: &X,
    bd: usize,
    better: impl Fn(&X::Elem, &X::Elem) -> bool + Copy,
) -> Tile1<i32, 1> {
    const { assert!(X::SIZE > 0, "a tile has at least one element") };
    let x = t.as_flat();
    let r = gpu_order(x.len(), bd, |e| (x[e], e), |a, b| pick(a, b, better));
    Tile1 {
        data: [r.map_or(0, |(_, i)| i as i32)],
    }
}

/// `tile_argmin(t)`: the row-major index of the smallest element (NaN only if all are), the
/// first on ties.
pub fn argmin<X: Tile<Elem: Scalar>>(t: &X, bd: usize) -> Tile1<i32, 1> {
    arg_extreme(t, bd, |a, b| a < b)
}

/// `tile_argmax(t)`: the row-major index of the largest element (NaN only if all are), the
/// first on ties.
pub fn argmax<X: Tile<Elem: Scalar>>(t: &X, bd: usize) -> Tile1<i32, 1> {
    arg_extreme(t, bd, |a, b| a > b)
}

#[cfg(test)]
#[path = "reduce_tests.rs"]
mod tests;
