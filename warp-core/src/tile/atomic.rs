//! `tile_atomic_add`: a tile added into an array atomically, element by element, as Warp's
//! (the result is the tile of the values each element held before; elements outside the array
//! are skipped and read zero, like a store and a load).

use super::load::coord;
use super::{Tile1, Tile2};
use crate::builtins::atomic::{atomic_add, AtomicElement};
use crate::fault::KResult;
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
