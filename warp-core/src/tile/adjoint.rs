//! Reverse-mode adjoints of the tile operations (CPU), for the adjoint of a tiled kernel.
//!
//! Conventions are [`crate::adjoint`]'s: every function **accumulates** into the adjoints it
//! is given, from `r`, the adjoint of the operation's result. Arguments come in the order the
//! generated code passes them: the operation's inputs (tiles by reference, arrays by
//! reference), then one adjoint per input (an array's [`GradView`], an integer offset's unused
//! adjoint), then `r`, then the block size `bd`.
//!
//! Every result is reproduced bit for bit by `wp_adjoint_tile.h` on the GPU:
//! - elementwise adjoints call the scalar adjoint of the operation on each element (the same
//!   formula as an ordinary kernel's `adj_mul`), each element independently;
//! - where a uniform scalar meets a tile (`t * s`), `s`'s adjoint is the sum of the
//!   elements' contributions in the reductions' order for block size `bd`
//!   ([`reduce::gpu_order`]), added once for the block (by lane 0: the caller's part);
//! - a sum over several elements into one (a broadcast's adjoint, a matmul's) is one chain in
//!   ascending row-major order, starting from zero, computed by one GPU thread; the matmul's
//!   chains are FMAs ([`Fma`]), as its forward.
//!
//! Loads and stores skip what their forward skipped (coordinates outside the array): the
//! adjoint of a zero read of padding is nothing, and a skipped store hands nothing over.

use super::fft::Complex;
use super::load::coord;
use super::load::coords_nd;
use super::matmul::{Fma, MatmulElem};
use super::reduce::{self, gpu_order};
use super::{Tile, Tile1, Tile2, Tile3, Tile4, TileFromFn};
use crate::adjoint::{AdjAdd, AdjCast, AdjDiv, AdjMul, AdjNeg, AdjSub, Adjoint};
use crate::block::{LaneValue, PerLane};
use crate::builtins::Scalar;
use crate::fault::KResult;
use crate::grad::{AdStack, GradElement, GradView};
use crate::index::IndexInt;
use crate::view::ArrayView;

// The linear algebra's and the scans' adjoints live beside their forwards' order of roundings.
pub use super::adjoint_linalg::*;
// `tile_atomic_add`'s adjoint lives beside its forward.
pub use super::atomic::{
    adj_tile_atomic_add1, adj_tile_atomic_add2, adj_tile_atomic_add3, adj_tile_atomic_add4,
};

impl<T: Adjoint, const N0: usize> Adjoint for Tile1<T, N0> {
    #[inline(always)]
    fn adj_zero() -> Self {
        Tile1 {
            data: [T::adj_zero(); N0],
        }
    }
    #[inline(always)]
    fn adj_accum(&mut self, v: Self) {
        for (a, b) in self.data.iter_mut().zip(v.data) {
            a.adj_accum(b);
        }
    }
}

impl<T: Adjoint, const N0: usize, const N1: usize> Adjoint for Tile2<T, N0, N1> {
    #[inline(always)]
    fn adj_zero() -> Self {
        Tile2 {
            data: [[T::adj_zero(); N1]; N0],
        }
    }
    #[inline(always)]
    fn adj_accum(&mut self, v: Self) {
        let flat = v.data.as_flattened();
        for (a, b) in self.data.as_flattened_mut().iter_mut().zip(flat) {
            a.adj_accum(*b);
        }
    }
}

/// The adjoint algebra of the rank-3 and rank-4 tiles, elementwise over the flattening.
macro_rules! nd_adjoint {
    ($tile:ident < $($n:ident),+ >) => {
        impl<T: Adjoint, $(const $n: usize),+> Adjoint for $tile<T, $($n),+> {
            #[inline(always)]
            fn adj_zero() -> Self {
                <Self as TileFromFn>::from_flat_fn(|_| T::adj_zero())
            }
            #[inline(always)]
            fn adj_accum(&mut self, v: Self) {
                for (a, b) in self.as_flat_mut().iter_mut().zip(v.as_flat()) {
                    a.adj_accum(*b);
                }
            }
        }
    };
}
nd_adjoint!(Tile3<N0, N1, N2>);
nd_adjoint!(Tile4<N0, N1, N2, N3>);

// ---- Loads and stores ----------------------------------------------------------------------

/// Adjoint of `t = tile_load(a, o)`: `a.grad[o + i] += r[i]` for every `o + i` inside `a`
/// (atomically: blocks may load overlapping tiles).
pub fn adj_tile_load1<T: GradElement, const N0: usize, O: IndexInt>(
    a: &ArrayView<T, 1>,
    o: O,
    adj_a: &mut GradView<T, 1>,
    _adj_o: &mut O,
    r: &Tile1<T, N0>,
    _bd: usize,
) -> KResult<()> {
    let [n] = a.shape();
    for (i, &g) in r.data.iter().enumerate() {
        if let Some(c) = coord(o, i, n) {
            adj_a.accumulate(c, g)?;
        }
    }
    Ok(())
}

/// Adjoint of `t = tile_load(a, (o0, o1))`, as [`adj_tile_load1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_load2<T: GradElement, const N0: usize, const N1: usize, O0, O1>(
    a: &ArrayView<T, 2>,
    o0: O0,
    o1: O1,
    adj_a: &mut GradView<T, 2>,
    _adj_o0: &mut O0,
    _adj_o1: &mut O1,
    r: &Tile2<T, N0, N1>,
    _bd: usize,
) -> KResult<()>
where
    O0: IndexInt,
    O1: IndexInt,
{
    let [n0, n1] = a.shape();
    for (i, row) in r.data.iter().enumerate() {
        let Some(c0) = coord(o0, i, n0) else { continue };
        for (j, &g) in row.iter().enumerate() {
            if let Some(c1) = coord(o1, j, n1) {
                adj_a.accumulate((c0, c1), g)?;
            }
        }
    }
    Ok(())
}

/// Adjoint of `tile_store(a, t, o)`: the gradient of each element written hands over to
/// `t`'s adjoint and is cleared there (the write replaced the element), as an ordinary store's.
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_store1<T: GradElement + Adjoint, const N0: usize, O: IndexInt>(
    a: &ArrayView<T, 1>,
    _t: &Tile1<T, N0>,
    o: O,
    adj_a: &mut GradView<T, 1>,
    adj_t: &mut Tile1<T, N0>,
    _adj_o: &mut O,
    _r: &(),
    _bd: usize,
) -> KResult<()> {
    let [n] = a.shape();
    for (i, d) in adj_t.data.iter_mut().enumerate() {
        if let Some(c) = coord(o, i, n) {
            d.adj_accum(adj_a.take(c, T::adj_zero())?);
        }
    }
    Ok(())
}

/// Adjoint of `tile_store(a, t, (o0, o1))`, as [`adj_tile_store1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_store2<T, const N0: usize, const N1: usize, O0, O1>(
    a: &ArrayView<T, 2>,
    _t: &Tile2<T, N0, N1>,
    o0: O0,
    o1: O1,
    adj_a: &mut GradView<T, 2>,
    adj_t: &mut Tile2<T, N0, N1>,
    _adj_o0: &mut O0,
    _adj_o1: &mut O1,
    _r: &(),
    _bd: usize,
) -> KResult<()>
where
    T: GradElement + Adjoint,
    O0: IndexInt,
    O1: IndexInt,
{
    let [n0, n1] = a.shape();
    for (i, row) in adj_t.data.iter_mut().enumerate() {
        let Some(c0) = coord(o0, i, n0) else { continue };
        for (j, d) in row.iter_mut().enumerate() {
            if let Some(c1) = coord(o1, j, n1) {
                d.adj_accum(adj_a.take((c0, c1), T::adj_zero())?);
            }
        }
    }
    Ok(())
}

/// The adjoint of a rank-3 or rank-4 `tile_load` at the widened offsets `o`:
/// `a.grad[c] += r[k]` for every element `k` whose coordinates `c` lie inside the array.
fn adj_load_nd<X, const R: usize>(
    a: &ArrayView<X::Elem, R>,
    o: [i128; R],
    adj_a: &mut GradView<X::Elem, R>,
    r: &X,
) -> KResult<()>
where
    X: Tile<Elem: GradElement>,
    [usize; R]: crate::index::KernelIndex<R>,
{
    let shape = a.shape();
    for (k, &g) in r.as_flat().iter().enumerate() {
        if let Some(c) = coords_nd::<X, R>(k, o, shape) {
            adj_a.accumulate(c, g)?;
        }
    }
    Ok(())
}

/// Each element `k` of `adj_t` whose coordinates `c` lie inside the array gathers `a.grad[c]`:
/// taken (cleared) for a `tile_store` of rank 3 or 4, whose write overwrote that element; read
/// and kept for `tile_atomic_add` of any rank, whose add left the element's earlier value in
/// the sum (`tile::atomic`'s adjoints).
pub(super) fn gather_grad<X, const R: usize>(
    a: &ArrayView<X::Elem, R>,
    o: [i128; R],
    adj_a: &GradView<X::Elem, R>,
    adj_t: &mut X,
    clear: bool,
) -> KResult<()>
where
    X: Tile<Elem: GradElement + Adjoint>,
    [usize; R]: crate::index::KernelIndex<R>,
{
    let shape = a.shape();
    let zero = <X::Elem as Adjoint>::adj_zero;
    for (k, d) in adj_t.as_flat_mut().iter_mut().enumerate() {
        if let Some(c) = coords_nd::<X, R>(k, o, shape) {
            d.adj_accum(if clear {
                adj_a.take(c, zero())?
            } else {
                adj_a.get(c, zero())?
            });
        }
    }
    Ok(())
}

/// Adjoint of `t = tile_load(a, (o0, o1, o2))`, as [`adj_tile_load1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_load3<T, const N0: usize, const N1: usize, const N2: usize, O0, O1, O2>(
    a: &ArrayView<T, 3>,
    o0: O0,
    o1: O1,
    o2: O2,
    adj_a: &mut GradView<T, 3>,
    _adj_o0: &mut O0,
    _adj_o1: &mut O1,
    _adj_o2: &mut O2,
    r: &Tile3<T, N0, N1, N2>,
    _bd: usize,
) -> KResult<()>
where
    T: GradElement,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
{
    adj_load_nd(a, [o0.widen(), o1.widen(), o2.widen()], adj_a, r)
}

/// Adjoint of `t = tile_load(a, (o0, o1, o2, o3))`, as [`adj_tile_load1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_load4<
    T,
    const N0: usize,
    const N1: usize,
    const N2: usize,
    const N3: usize,
    O0,
    O1,
    O2,
    O3,
>(
    a: &ArrayView<T, 4>,
    o0: O0,
    o1: O1,
    o2: O2,
    o3: O3,
    adj_a: &mut GradView<T, 4>,
    _adj_o0: &mut O0,
    _adj_o1: &mut O1,
    _adj_o2: &mut O2,
    _adj_o3: &mut O3,
    r: &Tile4<T, N0, N1, N2, N3>,
    _bd: usize,
) -> KResult<()>
where
    T: GradElement,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
    O3: IndexInt,
{
    adj_load_nd(
        a,
        [o0.widen(), o1.widen(), o2.widen(), o3.widen()],
        adj_a,
        r,
    )
}

/// Adjoint of `tile_store(a, t, (o0, o1, o2))`, as [`adj_tile_store1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_store3<T, const N0: usize, const N1: usize, const N2: usize, O0, O1, O2>(
    a: &ArrayView<T, 3>,
    _t: &Tile3<T, N0, N1, N2>,
    o0: O0,
    o1: O1,
    o2: O2,
    adj_a: &mut GradView<T, 3>,
    adj_t: &mut Tile3<T, N0, N1, N2>,
    _adj_o0: &mut O0,
    _adj_o1: &mut O1,
    _adj_o2: &mut O2,
    _r: &(),
    _bd: usize,
) -> KResult<()>
where
    T: GradElement + Adjoint,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
{
    gather_grad(a, [o0.widen(), o1.widen(), o2.widen()], adj_a, adj_t, true)
}

/// Adjoint of `tile_store(a, t, (o0, o1, o2, o3))`, as [`adj_tile_store1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_store4<
    T,
    const N0: usize,
    const N1: usize,
    const N2: usize,
    const N3: usize,
    O0,
    O1,
    O2,
    O3,
>(
    a: &ArrayView<T, 4>,
    _t: &Tile4<T, N0, N1, N2, N3>,
    o0: O0,
    o1: O1,
    o2: O2,
    o3: O3,
    adj_a: &mut GradView<T, 4>,
    adj_t: &mut Tile4<T, N0, N1, N2, N3>,
    _adj_o0: &mut O0,
    _adj_o1: &mut O1,
    _adj_o2: &mut O2,
    _adj_o3: &mut O3,
    _r: &(),
    _bd: usize,
) -> KResult<()>
where
    T: GradElement + Adjoint,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
    O3: IndexInt,
{
    let o = [o0.widen(), o1.widen(), o2.widen(), o3.widen()];
    gather_grad(a, o, adj_a, adj_t, true)
}

// ---- Elementwise ---------------------------------------------------------------------------

/// The sum of `c(0..n)` in the reductions' order for block size `bd` (zero for none):
/// what a uniform scalar operand's adjoint receives from a whole tile.
fn block_total<T: Scalar>(n: usize, bd: usize, c: impl Fn(usize) -> T) -> T {
    gpu_order(n, bd, c, Scalar::s_add).unwrap_or(T::ZERO)
}

/// The sum of the contributions `c` in the reductions' order for block size `bd`: the adjoint
/// of a scalar constant of `tile_map` (`tile_map(f, t, s)`), whose elements' contributions the
/// generated code collects, as `t * s` gives `s` its adjoint.
pub fn block_sum<T: Scalar>(c: &[T], bd: usize) -> T {
    block_total(c.len(), bd, |e| c[e])
}

macro_rules! elementwise {
    ($tr:ident, $f:ident, $tt:ident, $ts:ident, $st:ident, $what:literal) => {
        #[doc = concat!("Adjoint of `a ", $what, " b` on two tiles of one shape: element by element, the scalar rule.")]
        pub fn $tt<X>(a: &X, b: &X, adj_a: &mut X, adj_b: &mut X, r: &X, _bd: usize)
        where
            X: Tile,
            X::Elem: $tr<X::Elem, Output = X::Elem> + Copy,
        {
            let (a, b, r) = (a.as_flat(), b.as_flat(), r.as_flat());
            let aa = adj_a.as_flat_mut();
            for e in 0..aa.len() {
                crate::adjoint::$f(a[e], b[e], &mut aa[e], &mut adj_b.as_flat_mut()[e], r[e]);
            }
        }

        #[doc = concat!("Adjoint of `t ", $what, " s` (tile with a uniform scalar, the elements' own or, for a tile of vectors, their components'): the tile's adjoint element by element; `s`'s, the sum of the elements' contributions in the reductions' order (see the module docs).")]
        pub fn $ts<X, S>(a: &X, s: S, adj_a: &mut X, adj_s: &mut S, r: &X, bd: usize)
        where
            X: Tile,
            X::Elem: $tr<S, Output = X::Elem> + Adjoint,
            S: Adjoint + Scalar,
        {
            let (a, r) = (a.as_flat(), r.as_flat());
            let mut unused = S::adj_zero();
            for (e, d) in adj_a.as_flat_mut().iter_mut().enumerate() {
                crate::adjoint::$f(a[e], s, d, &mut unused, r[e]);
            }
            // Each element's contribution to `s` (a vector's components in lane order, as the
            // scalar rule adds them), computed again on its own, then their block total.
            let contribution = |e: usize| {
                let (mut g, mut unused) = (S::adj_zero(), X::Elem::adj_zero());
                crate::adjoint::$f(a[e], s, &mut unused, &mut g, r[e]);
                g
            };
            adj_s.adj_accum(block_total(a.len(), bd, contribution));
        }

        #[doc = concat!("Adjoint of `s ", $what, " t` (a uniform scalar with a tile), as the tile-scalar form.")]
        pub fn $st<X, S>(s: S, b: &X, adj_s: &mut S, adj_b: &mut X, r: &X, bd: usize)
        where
            X: Tile,
            X::Elem: Adjoint,
            S: $tr<X::Elem, Output = X::Elem> + Adjoint + Scalar,
        {
            let (b, r) = (b.as_flat(), r.as_flat());
            let mut unused = S::adj_zero();
            for (e, d) in adj_b.as_flat_mut().iter_mut().enumerate() {
                crate::adjoint::$f(s, b[e], &mut unused, d, r[e]);
            }
            let contribution = |e: usize| {
                let (mut g, mut unused) = (S::adj_zero(), X::Elem::adj_zero());
                crate::adjoint::$f(s, b[e], &mut g, &mut unused, r[e]);
                g
            };
            adj_s.adj_accum(block_total(b.len(), bd, contribution));
        }
    };
}
elementwise!(
    AdjAdd,
    adj_add,
    adj_tile_add_tt,
    adj_tile_add_ts,
    adj_tile_add_st,
    "+"
);
elementwise!(
    AdjSub,
    adj_sub,
    adj_tile_sub_tt,
    adj_tile_sub_ts,
    adj_tile_sub_st,
    "-"
);
elementwise!(
    AdjMul,
    adj_mul,
    adj_tile_mul_tt,
    adj_tile_mul_ts,
    adj_tile_mul_st,
    "*"
);
elementwise!(
    AdjDiv,
    adj_div,
    adj_tile_div_tt,
    adj_tile_div_ts,
    adj_tile_div_st,
    "/"
);

/// Adjoint of `-t`.
pub fn adj_tile_neg<X>(a: &X, adj_a: &mut X, r: &X, _bd: usize)
where
    X: Tile,
    X::Elem: AdjNeg + Copy,
{
    let (a, r) = (a.as_flat(), r.as_flat());
    for (e, d) in adj_a.as_flat_mut().iter_mut().enumerate() {
        crate::adjoint::adj_neg(a[e], d, r[e]);
    }
}

/// Adjoint of `tile_map(f, a)`: `adj` (the scalar adjoint of `f`) on each element.
pub fn adj_tile_map1<X: Tile, Y: Tile>(
    a: &X,
    adj_a: &mut X,
    r: &Y,
    adj: impl Fn(X::Elem, &mut X::Elem, Y::Elem),
) where
    X::Elem: Copy,
    Y::Elem: Copy,
{
    let (a, r) = (a.as_flat(), r.as_flat());
    for (e, d) in adj_a.as_flat_mut().iter_mut().enumerate() {
        adj(a[e], d, r[e]);
    }
}

/// Adjoint of `tile_map(f, a, b)`: `adj` (the scalar adjoint of `f`) on each pair of elements.
pub fn adj_tile_map2<X: Tile, Y: Tile, Z: Tile>(
    a: &X,
    b: &Y,
    adj_a: &mut X,
    adj_b: &mut Y,
    r: &Z,
    adj: impl Fn(X::Elem, Y::Elem, &mut X::Elem, &mut Y::Elem, Z::Elem),
) where
    X::Elem: Copy,
    Y::Elem: Copy,
    Z::Elem: Copy,
{
    let (a, b, r) = (a.as_flat(), b.as_flat(), r.as_flat());
    let ab = adj_b.as_flat_mut();
    for (e, d) in adj_a.as_flat_mut().iter_mut().enumerate() {
        adj(a[e], b[e], d, &mut ab[e], r[e]);
    }
}

/// Adjoint of `tile_map(func, a)` of a user func: `adj` (the func's adjoint, which may fault
/// and uses the caller's adjoint stack) on each element in row-major order.
pub fn adj_tile_map_func1<X: Tile, Y: Tile>(
    a: &X,
    adj_a: &mut X,
    r: &Y,
    mut adj: impl FnMut(X::Elem, &mut X::Elem, Y::Elem) -> KResult<()>,
) -> KResult<()>
where
    X::Elem: Copy,
    Y::Elem: Copy,
{
    let (a, r) = (a.as_flat(), r.as_flat());
    for (e, d) in adj_a.as_flat_mut().iter_mut().enumerate() {
        adj(a[e], d, r[e])?;
    }
    Ok(())
}

/// Adjoint of `tile_map(func, a, b)` of a user func: `adj` on each pair of elements.
pub fn adj_tile_map_func2<X: Tile, Y: Tile, Z: Tile>(
    a: &X,
    b: &Y,
    adj_a: &mut X,
    adj_b: &mut Y,
    r: &Z,
    mut adj: impl FnMut(X::Elem, Y::Elem, &mut X::Elem, &mut Y::Elem, Z::Elem) -> KResult<()>,
) -> KResult<()>
where
    X::Elem: Copy,
    Y::Elem: Copy,
    Z::Elem: Copy,
{
    let (a, b, r) = (a.as_flat(), b.as_flat(), r.as_flat());
    let ab = adj_b.as_flat_mut();
    for (e, d) in adj_a.as_flat_mut().iter_mut().enumerate() {
        adj(a[e], b[e], d, &mut ab[e], r[e])?;
    }
    Ok(())
}

// ---- Reductions ----------------------------------------------------------------------------

/// Adjoint of `tile_sum(t)` (and `tile_reduce(add, t)`): every element gets the result's
/// adjoint.
pub fn adj_tile_sum<X: Tile>(_t: &X, adj_t: &mut X, r: &Tile1<X::Elem, 1>, _bd: usize)
where
    X::Elem: Adjoint,
{
    for d in adj_t.as_flat_mut() {
        d.adj_accum(r.data[0]);
    }
}

/// Adjoint of `tile_min(t)`: the element `tile_argmin` picks (the first smallest for block
/// size `bd`) gets the result's adjoint.
pub fn adj_tile_min<X: Tile>(t: &X, adj_t: &mut X, r: &Tile1<X::Elem, 1>, bd: usize)
where
    X::Elem: Adjoint + Scalar,
{
    let i = reduce::argmin(t, bd).data[0] as usize;
    adj_t.as_flat_mut()[i].adj_accum(r.data[0]);
}

/// Adjoint of `tile_max(t)`, as [`adj_tile_min`] with `tile_argmax`.
pub fn adj_tile_max<X: Tile>(t: &X, adj_t: &mut X, r: &Tile1<X::Elem, 1>, bd: usize)
where
    X::Elem: Adjoint + Scalar,
{
    let i = reduce::argmax(t, bd).data[0] as usize;
    adj_t.as_flat_mut()[i].adj_accum(r.data[0]);
}

// ---- FFTs ----------------------------------------------------------------------------------

/// Adjoint of `tile_fft(&mut t)`: the unnormalised inverse transform of the seed (Warp's rule;
/// with real and imaginary parts as independent reals, the forward DFT's matrix `F` has the
/// adjoint `conj(F)ᵀ = conj(F)`, the inverse's). The transform is in place, so `adj_t` is the
/// slot `r` was copied from: the adjoint of `t` before the transform *replaces* the seed (the
/// statements before it, which add to that adjoint, run after this in the sweep).
pub fn adj_tile_fft<C: Complex, const M: usize, const N: usize>(
    _t: &Tile2<C, M, N>,
    adj_t: &mut Tile2<C, M, N>,
    r: &Tile2<C, M, N>,
    _bd: usize,
) {
    *adj_t = super::fft::ifft(r);
}

/// Adjoint of `tile_ifft(&mut t)`: the forward transform of the seed, in place as
/// [`adj_tile_fft`].
pub fn adj_tile_ifft<C: Complex, const M: usize, const N: usize>(
    _t: &Tile2<C, M, N>,
    adj_t: &mut Tile2<C, M, N>,
    r: &Tile2<C, M, N>,
    _bd: usize,
) {
    *adj_t = super::fft::fft(r);
}

// ---- Conversions ---------------------------------------------------------------------------

/// Adjoint of `tile_full(x)`: `x` (a uniform value) gets the sum of the seed in the reductions'
/// order, added once for the block (the caller's part, as for `t * s`). Warp drops this
/// gradient (its `tile_full` is not differentiable); a zero would be a wrong one.
pub fn adj_tile_full<X: Tile>(_x: X::Elem, adj_x: &mut X::Elem, r: &X, bd: usize)
where
    X::Elem: Adjoint + Scalar,
{
    let r = r.as_flat();
    adj_x.adj_accum(block_total(r.len(), bd, |e| r[e]));
}

/// Adjoint of `tile_astype::<U>(t)`: each element's seed converted back as the adjoint of
/// `x as U` ([`adj_cast`](crate::adjoint::adj_cast)): between floats `adj_t[e] += r[e] as T`,
/// nothing where either side is an integer (Warp's rule).
pub fn adj_tile_astype<X: Tile, Y: Tile>(_t: &X, adj_t: &mut X, r: &Y, _bd: usize)
where
    X::Elem: AdjCast<Y::Elem>,
    Y::Elem: Copy,
{
    for (d, g) in adj_t.as_flat_mut().iter_mut().zip(r.as_flat()) {
        crate::adjoint::adj_cast(d, *g);
    }
}

// ---- Shapes --------------------------------------------------------------------------------

/// Adjoint of `tile_reshape(a)` and `tile_squeeze(a)`: the same elements in row-major order,
/// so `adj_a[k] += r[k]` over the flattenings.
pub fn adj_tile_reshape<X: Tile, Y: Tile<Elem = X::Elem>>(_a: &X, adj_a: &mut X, r: &Y, _bd: usize)
where
    X::Elem: Adjoint,
{
    for (d, g) in adj_a.as_flat_mut().iter_mut().zip(r.as_flat()) {
        d.adj_accum(*g);
    }
}

/// Adjoint of `tile_diag_add(a, d)`: `adj_a += r`, and `adj_d[i] += r[i][i]`.
pub fn adj_tile_diag_add<T: Adjoint, const N: usize, const M: usize>(
    _a: &Tile2<T, N, M>,
    _d: &Tile1<T, N>,
    adj_a: &mut Tile2<T, N, M>,
    adj_d: &mut Tile1<T, N>,
    r: &Tile2<T, N, M>,
    _bd: usize,
) {
    for (i, row) in adj_a.data.iter_mut().enumerate() {
        for (j, g) in row.iter_mut().enumerate() {
            g.adj_accum(r.data[i][j]);
        }
        adj_d.data[i].adj_accum(r.data[i][i]);
    }
}

/// Adjoint of `tile_transpose(a)`: `adj_a[i][j] += r[j][i]`.
pub fn adj_tile_transpose<T: Adjoint, const M: usize, const N: usize>(
    _a: &Tile2<T, M, N>,
    adj_a: &mut Tile2<T, M, N>,
    r: &Tile2<T, N, M>,
    _bd: usize,
) {
    for (i, row) in adj_a.data.iter_mut().enumerate() {
        for (j, d) in row.iter_mut().enumerate() {
            d.adj_accum(r.data[j][i]);
        }
    }
}

/// The adjoint of a broadcast from shape `(s0, s1)` to `(m, n)` (each source dim equal to the
/// target's or 1, `src` and `dst` row-major): each source element's adjoint gains the sum, in
/// ascending row-major order from zero, of the target elements it was copied to.
fn unbroadcast<T: Adjoint + Scalar>(src: &mut [T], s: [usize; 2], dst: &[T], t: [usize; 2]) {
    for p in 0..s[0] {
        for q in 0..s[1] {
            let rows = if s[0] == t[0] { p..p + 1 } else { 0..t[0] };
            let cols = if s[1] == t[1] { q..q + 1 } else { 0..t[1] };
            let mut acc = T::ZERO;
            for i in rows {
                for j in cols.clone() {
                    acc = acc.s_add(dst[i * t[1] + j]);
                }
            }
            src[p * s[1] + q].adj_accum(acc);
        }
    }
}

/// Adjoint of `tile_broadcast` from a rank-1 tile to a rank-1 tile.
pub fn adj_tile_broadcast11<T: Adjoint + Scalar, const S: usize, const N: usize>(
    _a: &Tile1<T, S>,
    adj_a: &mut Tile1<T, S>,
    r: &Tile1<T, N>,
    _bd: usize,
) {
    unbroadcast(&mut adj_a.data, [1, S], &r.data, [1, N]);
}

/// Adjoint of `tile_broadcast` from a rank-1 tile (aligned with the last axis) to a rank-2.
pub fn adj_tile_broadcast12<T: Adjoint + Scalar, const S: usize, const M: usize, const N: usize>(
    _a: &Tile1<T, S>,
    adj_a: &mut Tile1<T, S>,
    r: &Tile2<T, M, N>,
    _bd: usize,
) {
    unbroadcast(&mut adj_a.data, [1, S], r.data.as_flattened(), [M, N]);
}

/// Adjoint of `tile_broadcast` from a rank-2 tile to a rank-2 tile.
pub fn adj_tile_broadcast22<T, const S0: usize, const S1: usize, const M: usize, const N: usize>(
    _a: &Tile2<T, S0, S1>,
    adj_a: &mut Tile2<T, S0, S1>,
    r: &Tile2<T, M, N>,
    _bd: usize,
) where
    T: Adjoint + Scalar,
{
    let src = adj_a.data.as_flattened_mut();
    unbroadcast(src, [S0, S1], r.data.as_flattened(), [M, N]);
}

// ---- Matmul --------------------------------------------------------------------------------

/// Adjoint of `c = tile_matmul(a, b)` and of `tile_matmul(a, b, &mut c)`: `adj_a += r bᵀ` and
/// `adj_b += aᵀ r`, each element one FMA chain from zero in ascending order (over `r`'s
/// columns for `adj_a`, its rows for `adj_b`), then added to the adjoint. `adj_a` is complete
/// before `adj_b` starts.
///
/// The chains run in the operands' accumulator type ([`MatmulElem::Acc`]), as the forward's:
/// f32 and f64 in themselves (each term `r · b` one FMA, bit for bit the plain chain); f16
/// operands widened exactly to f32, so each product is exact and each chain an f32 one, rounded
/// once to f16 at the end and added to the f16 adjoint (the adjoint of an f16 tile is an f16
/// tile, as Warp's). `r` is the result's adjoint: f16 for the returning f16 form, the f32
/// accumulator's for the accumulating one (`R = f32`, whose accumulator is the same f32).
pub fn adj_tile_matmul<T, R, const M: usize, const K: usize, const N: usize>(
    a: &Tile2<T, M, K>,
    b: &Tile2<T, K, N>,
    adj_a: &mut Tile2<T, M, K>,
    adj_b: &mut Tile2<T, K, N>,
    r: &Tile2<R, M, N>,
    _bd: usize,
) where
    T: MatmulElem + Adjoint,
    R: MatmulElem<Acc = T::Acc>,
{
    let zero = <T::Acc as Scalar>::ZERO;
    for i in 0..M {
        for k in 0..K {
            let mut acc = zero;
            for j in 0..N {
                acc = r.data[i][j].widen().fma(b.data[k][j].widen(), acc);
            }
            adj_a.data[i][k].adj_accum(T::narrow(acc));
        }
    }
    for k in 0..K {
        for j in 0..N {
            let mut acc = zero;
            for i in 0..M {
                acc = a.data[i][k].widen().fma(r.data[i][j].widen(), acc);
            }
            adj_b.data[k][j].adj_accum(T::narrow(acc));
        }
    }
}

// ---- Threads and elements ------------------------------------------------------------------

/// Adjoint of `x = t[i]` in one lane: `adj_t[i] += r` (the forward checked `i`; an index
/// outside the tile is the same fault here).
pub fn adj_tile_extract1<T: Adjoint, const N0: usize, I: IndexInt>(
    t: &Tile1<T, N0>,
    i: I,
    adj_t: &mut Tile1<T, N0>,
    _adj_i: &mut I,
    r: T,
    kernel: &'static str,
) -> KResult<()> {
    t.extract(i, kernel)?;
    let i = i.widen() as usize;
    adj_t.data[i].adj_accum(r);
    Ok(())
}

/// Adjoint of `x = t[(i, j)]` in one lane, as [`adj_tile_extract1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_extract2<T: Adjoint, const N0: usize, const N1: usize, I, J>(
    t: &Tile2<T, N0, N1>,
    i: I,
    j: J,
    adj_t: &mut Tile2<T, N0, N1>,
    _adj_i: &mut I,
    _adj_j: &mut J,
    r: T,
    kernel: &'static str,
) -> KResult<()>
where
    I: IndexInt,
    J: IndexInt,
{
    t.extract(i, j, kernel)?;
    let (i, j) = (i.widen() as usize, j.widen() as usize);
    adj_t.data[i][j].adj_accum(r);
    Ok(())
}

/// Adjoint of `x = t[(i, j, k)]` in one lane, as [`adj_tile_extract1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_extract3<T: Adjoint, const N0: usize, const N1: usize, const N2: usize, I, J, K>(
    t: &Tile3<T, N0, N1, N2>,
    i: I,
    j: J,
    k: K,
    adj_t: &mut Tile3<T, N0, N1, N2>,
    _adj_i: &mut I,
    _adj_j: &mut J,
    _adj_k: &mut K,
    r: T,
    kernel: &'static str,
) -> KResult<()>
where
    I: IndexInt,
    J: IndexInt,
    K: IndexInt,
{
    t.extract(i, j, k, kernel)?;
    let (i, j, k) = (i.widen() as usize, j.widen() as usize, k.widen() as usize);
    adj_t.data[i][j][k].adj_accum(r);
    Ok(())
}

/// Adjoint of `x = t[(i, j, k, l)]` in one lane, as [`adj_tile_extract1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_extract4<
    T: Adjoint,
    const N0: usize,
    const N1: usize,
    const N2: usize,
    const N3: usize,
    I,
    J,
    K,
    L,
>(
    t: &Tile4<T, N0, N1, N2, N3>,
    i: I,
    j: J,
    k: K,
    l: L,
    adj_t: &mut Tile4<T, N0, N1, N2, N3>,
    _adj_i: &mut I,
    _adj_j: &mut J,
    _adj_k: &mut K,
    _adj_l: &mut L,
    r: T,
    kernel: &'static str,
) -> KResult<()>
where
    I: IndexInt,
    J: IndexInt,
    K: IndexInt,
    L: IndexInt,
{
    t.extract(i, j, k, l, kernel)?;
    let [i, j, k, l] = [i.widen(), j.widen(), k.widen(), l.widen()].map(|x| x as usize);
    adj_t.data[i][j][k][l].adj_accum(r);
    Ok(())
}

/// Adjoint of `t = tile(x)`: lane `l`'s `x` gains element `l` of `t`'s adjoint `r`.
pub fn adj_tile_lanes<T: LaneValue + Adjoint, const N: usize>(
    adj_x: &mut PerLane<T>,
    r: &Tile1<T, N>,
    bd: usize,
) {
    for (l, &g) in r.data.iter().enumerate().take(bd) {
        adj_x[l].adj_accum(g);
    }
}

/// Adjoint of `x = untile(t)`: element `l` of `t`'s adjoint gains lane `l`'s adjoint of `x`.
pub fn adj_untile<T: LaneValue + Adjoint, const N: usize>(
    adj_t: &mut Tile1<T, N>,
    adj_x: &PerLane<T>,
    bd: usize,
) {
    for (l, d) in adj_t.data.iter_mut().enumerate().take(bd) {
        d.adj_accum(adj_x[l]);
    }
}

/// Pushes tile `t` on the lanes' adjoint stacks (a reassigned tile whose old value the reverse
/// sweep needs): element `e` on lane `e % bd`'s stack, in ascending `e`, as each GPU thread
/// pushes the elements it owns on its own stack (`adstack_push_tile`), so a lane needs the same
/// stack capacity on both backends.
pub fn push_tile<X: Tile>(t: &X, lanes: &mut [AdStack], line: u32) -> KResult<()>
where
    X::Elem: Copy,
{
    let bd = lanes.len();
    for (e, v) in t.as_flat().iter().enumerate() {
        lanes[e % bd].push(*v, line)?;
    }
    Ok(())
}

/// Pops what [`push_tile`] pushed into `t`.
pub fn pop_tile<X: Tile>(t: &mut X, lanes: &mut [AdStack])
where
    X::Elem: Copy,
{
    let bd = lanes.len();
    for (e, v) in t.as_flat_mut().iter_mut().enumerate().rev() {
        *v = lanes[e % bd].pop();
    }
}

// ---- Windows: views and the in-place forms -------------------------------------------------

/// The window of a view or an in-place form: its offsets on the parent's axes (0 past the
/// ones given) and its shape on them (1 on a dropped leading axis).
fn window_of<P: Tile, W: Tile>(offs: &[i128]) -> ([i128; 2], [usize; 2]) {
    let mut o = [0i128; 2];
    o[..offs.len()].copy_from_slice(offs);
    let mut shape = [1usize; 2];
    // The window's dims are aligned with the parent's trailing ones.
    let drop = P::RANK - W::RANK;
    shape[drop..P::RANK].copy_from_slice(&W::SHAPE[..W::RANK]);
    (o, shape)
}

/// Adjoint of `v = tile_view(t, o..)` (a copy of a window): `adj_t[o + i] += r[i]` (the forward
/// checked the window; one outside the tile is the same fault here).
fn adj_tile_view<P, W>(
    _t: &P,
    offs: &[i128],
    adj_t: &mut P,
    r: &W,
    kernel: &'static str,
) -> KResult<()>
where
    P: Tile,
    W: Tile<Elem = P::Elem>,
    P::Elem: Adjoint,
{
    let (o, shape) = window_of::<P, W>(offs);
    let (a, g) = (adj_t.as_flat_mut(), r.as_flat());
    for (p, w) in super::view::window_pairs::<P>(o, shape, kernel)? {
        a[p].adj_accum(g[w]);
    }
    Ok(())
}

macro_rules! view_adjoints {
    ($($name:ident: ($($o:ident: $O:ident),+)),*) => {$(
        /// Adjoint of `v = tile_view(t, o..)`: `adj_t[o + i] += r[i]` (the offsets one by one, each with
        /// its unused adjoint; then the seed and the block size).
        #[allow(clippy::too_many_arguments)]
        pub fn $name<P, W, $($O),+>(
            t: &P,
            $($o: $O,)+
            adj_t: &mut P,
            $(_: &mut $O,)+
            r: &W,
            _bd: usize,
        ) -> KResult<()>
        where
            P: Tile,
            W: Tile<Elem = P::Elem>,
            P::Elem: Adjoint,
            $($O: IndexInt,)+
        {
            let offs = [$(($o).widen()),+];
            // The replayed forward checked the window, so this fault is never reached; the
            // seed-and-block-size tail of the block adjoints carries no kernel name.
            adj_tile_view(t, &offs, adj_t, r, "tile_view")
        }
    )*};
}
view_adjoints!(adj_tile_view1: (o0: O0), adj_tile_view2: (o0: O0, o1: O1));

/// Adjoint of an in-place window form, `dst = op(dst[o + i], src[i])`, with the seed `r` (the
/// adjoint of `dst` after): `src`'s adjoint gains `g(r[o + i])` where `g` is the form's
/// derivative in `src` (`+r`, `-r`), and, for `tile_assign` (`clear`), `dst`'s adjoint is zero
/// in the window (those elements were replaced: the value before did not reach the result);
/// elsewhere, and everywhere for the adds, it passes through unchanged (one slot holds the
/// adjoint of `dst` before and after).
fn adj_window<P, W>(
    offs: &[i128],
    adj_dst: &mut P,
    adj_src: &mut W,
    r: &P,
    clear: bool,
    negate: bool,
) -> KResult<()>
where
    P: Tile,
    W: Tile<Elem = P::Elem>,
    P::Elem: Adjoint + AdjNeg + Copy,
{
    let (o, shape) = window_of::<P, W>(offs);
    let (ad, asrc, g) = (adj_dst.as_flat_mut(), adj_src.as_flat_mut(), r.as_flat());
    for (p, w) in super::view::window_pairs::<P>(o, shape, "tile_assign")? {
        if negate {
            crate::adjoint::adj_neg(g[p], &mut asrc[w], g[p]);
        } else {
            asrc[w].adj_accum(g[p]);
        }
        if clear {
            ad[p] = P::Elem::adj_zero();
        }
    }
    Ok(())
}

macro_rules! window_adjoints {
    ($($name:ident, $clear:literal, $neg:literal: ($($o:ident: $O:ident),+)),*) => {$(
        /// Adjoint of an in-place window form (`tile_assign`: the window's adjoint to `src`, cleared
        /// in `adj_dst`; the adds: passed through, negated into `src` for the sub); the order:
        /// `dst`, `src`, the offsets, their adjoints, the seed, the block size.
        #[allow(clippy::too_many_arguments)]
        pub fn $name<P, W, $($O),+>(
            _dst: &P,
            _src: &W,
            $($o: $O,)+
            adj_dst: &mut P,
            adj_src: &mut W,
            $(_: &mut $O,)+
            r: &P,
            _bd: usize,
        ) -> KResult<()>
        where
            P: Tile,
            W: Tile<Elem = P::Elem>,
            P::Elem: Adjoint + AdjNeg + Copy,
            $($O: IndexInt,)+
        {
            adj_window(&[$(($o).widen()),+], adj_dst, adj_src, r, $clear, $neg)
        }
    )*};
}
window_adjoints!(
    adj_tile_assign1, true, false: (o0: O0),
    adj_tile_assign2, true, false: (o0: O0, o1: O1),
    adj_tile_add_inplace1, false, false: (o0: O0),
    adj_tile_add_inplace2, false, false: (o0: O0, o1: O1),
    adj_tile_sub_inplace1, false, true: (o0: O0),
    adj_tile_sub_inplace2, false, true: (o0: O0, o1: O1)
);
