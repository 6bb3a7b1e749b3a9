//! `tile_atomic_add`: a tile added into an array atomically, element by element, as Warp's
//! (the result is the tile of the values each element held before; elements outside the array
//! are skipped and read zero, like a store and a load).

use super::adjoint::gather_grad;
use super::load::{coord, coords_nd};
use super::{Tile1, Tile2, Tile3, Tile4, TileFromFn};
use crate::adjoint::Adjoint;
use crate::builtins::atomic::{atomic_add, AtomicElement};
use crate::fault::KResult;
use crate::grad::{GradElement, GradView};
use crate::index::IndexInt;
use crate::view::ArrayView;
use bytemuck::Zeroable;

/// `tile_atomic_add(a, t, o)` into a 1-D array: `a[o + i] += t[i]` atomically where
/// `o + i` is inside the array; returns the old values (zero outside).
#[inline]
pub fn atomic_add1<T: AtomicElement + Zeroable, const N0: usize, O: IndexInt>(
    a: &ArrayView<T, 1>,
    o: O,
    t: &Tile1<T, N0>,
) -> KResult<Tile1<T, N0>> {
    let [n] = a.shape();
    let mut old = Tile1 {
        data: [T::zeroed(); N0],
    };
    for (i, (&v, d)) in t.data.iter().zip(old.data.iter_mut()).enumerate() {
        if let Some(c) = coord(o, i, n) {
            *d = atomic_add(a, c, v)?;
        }
    }
    Ok(old)
}

/// `tile_atomic_add(a, t, (o0, o1))` into a 2-D array.
#[inline]
pub fn atomic_add2<
    T: AtomicElement + Zeroable,
    const N0: usize,
    const N1: usize,
    O0: IndexInt,
    O1: IndexInt,
>(
    a: &ArrayView<T, 2>,
    o0: O0,
    o1: O1,
    t: &Tile2<T, N0, N1>,
) -> KResult<Tile2<T, N0, N1>> {
    let [n0, n1] = a.shape();
    let mut old = Tile2 {
        data: [[T::zeroed(); N1]; N0],
    };
    for (i, (row, orow)) in t.data.iter().zip(old.data.iter_mut()).enumerate() {
        let Some(c0) = coord(o0, i, n0) else { continue };
        for (j, (&v, d)) in row.iter().zip(orow.iter_mut()).enumerate() {
            if let Some(c1) = coord(o1, j, n1) {
                *d = atomic_add(a, (c0, c1), v)?;
            }
        }
    }
    Ok(old)
}

/// `tile_atomic_add` of a rank-`R` tile (3 or 4) into an `R`-D array at the widened offsets
/// `o`: element by element in row-major order, skipping (and reading zero for) the elements
/// outside the array.
fn atomic_add_nd<X, const R: usize>(a: &ArrayView<X::Elem, R>, o: [i128; R], t: &X) -> KResult<X>
where
    X: TileFromFn<Elem: AtomicElement + Zeroable>,
    [usize; R]: crate::index::KernelIndex<R>,
{
    const { assert!(X::RANK == R, "a tile's rank is its array's") };
    let shape = a.shape();
    let mut old = X::from_flat_fn(|_| Zeroable::zeroed());
    for (k, (d, &v)) in old.as_flat_mut().iter_mut().zip(t.as_flat()).enumerate() {
        if let Some(c) = coords_nd::<X, R>(k, o, shape) {
            *d = atomic_add(a, c, v)?;
        }
    }
    Ok(old)
}

/// `tile_atomic_add(a, t, (o0, o1, o2))` into a 3-D array.
#[inline]
pub fn atomic_add3<T, const N0: usize, const N1: usize, const N2: usize, O0, O1, O2>(
    a: &ArrayView<T, 3>,
    o0: O0,
    o1: O1,
    o2: O2,
    t: &Tile3<T, N0, N1, N2>,
) -> KResult<Tile3<T, N0, N1, N2>>
where
    T: AtomicElement + Zeroable,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
{
    atomic_add_nd(a, [o0.widen(), o1.widen(), o2.widen()], t)
}

/// `tile_atomic_add(a, t, (o0, o1, o2, o3))` into a 4-D array.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn atomic_add4<
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
    t: &Tile4<T, N0, N1, N2, N3>,
) -> KResult<Tile4<T, N0, N1, N2, N3>>
where
    T: AtomicElement + Zeroable,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
    O3: IndexInt,
{
    atomic_add_nd(a, [o0.widen(), o1.widen(), o2.widen(), o3.widen()], t)
}

// ---- Adjoints ------------------------------------------------------------------------------

/// Adjoint of `old = tile_atomic_add(a, t, o)` (Warp's `adj_tile_atomic_add`): the update
/// added `t[i]` to `a[o + i]`, so `t`'s adjoint gets `a.grad[o + i]` for every `o + i` inside
/// the array (read, not cleared: the element's earlier value keeps its gradient too, as for
/// the scalar `atomic_add`); elements outside get nothing. `r`, the adjoint of the old values,
/// goes nowhere: Warp drops it, and the kernel cannot read them (the adjoint's replay does not
/// redo the atomic). Arguments in [`super::adjoint`]'s order.
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_atomic_add1<T, const N0: usize, O: IndexInt>(
    a: &ArrayView<T, 1>,
    _t: &Tile1<T, N0>,
    o: O,
    adj_a: &mut GradView<T, 1>,
    adj_t: &mut Tile1<T, N0>,
    _adj_o: &mut O,
    _r: &Tile1<T, N0>,
    _bd: usize,
) -> KResult<()>
where
    T: GradElement + Adjoint,
{
    gather_grad(a, [o.widen()], adj_a, adj_t, false)
}

/// Adjoint of `old = tile_atomic_add(a, t, (o0, o1))`, as [`adj_tile_atomic_add1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_atomic_add2<T, const N0: usize, const N1: usize, O0, O1>(
    a: &ArrayView<T, 2>,
    _t: &Tile2<T, N0, N1>,
    o0: O0,
    o1: O1,
    adj_a: &mut GradView<T, 2>,
    adj_t: &mut Tile2<T, N0, N1>,
    _adj_o0: &mut O0,
    _adj_o1: &mut O1,
    _r: &Tile2<T, N0, N1>,
    _bd: usize,
) -> KResult<()>
where
    T: GradElement + Adjoint,
    O0: IndexInt,
    O1: IndexInt,
{
    gather_grad(a, [o0.widen(), o1.widen()], adj_a, adj_t, false)
}

/// Adjoint of `old = tile_atomic_add(a, t, (o0, o1, o2))`, as [`adj_tile_atomic_add1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_atomic_add3<T, const N0: usize, const N1: usize, const N2: usize, O0, O1, O2>(
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
    _r: &Tile3<T, N0, N1, N2>,
    _bd: usize,
) -> KResult<()>
where
    T: GradElement + Adjoint,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
{
    gather_grad(a, [o0.widen(), o1.widen(), o2.widen()], adj_a, adj_t, false)
}

/// Adjoint of `old = tile_atomic_add(a, t, (o0, o1, o2, o3))`, as [`adj_tile_atomic_add1`].
#[allow(clippy::too_many_arguments)]
pub fn adj_tile_atomic_add4<
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
    _r: &Tile4<T, N0, N1, N2, N3>,
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
    gather_grad(a, o, adj_a, adj_t, false)
}
