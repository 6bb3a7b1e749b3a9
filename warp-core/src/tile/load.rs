//! Loads and stores of tiles against array views (`tile_load`, `tile_store`).
//!
//! Offsets are signed, one per axis of the array: element `(i, j)` of the tile is array
//! element `(o0 + i, o1 + j)`. A coordinate outside the array on any axis (negative, or at
//! least the extent) reads as `T`'s zero (all bits zero, C++'s `T{}`), and a store to it is
//! skipped: Warp's `bounds_check=True` semantics, where only `c >= shape` is checked, extended
//! to negative coordinates. Neither is a fault. Every in-bounds store goes through the view's
//! checked [`ArrayView::store`], so the runtime's race check sees every store; a load of a tile
//! wholly inside the view is checked once for the tile and read row by row (the same elements
//! and the same outcome: the per-element check is against the shape only), otherwise each
//! in-bounds element through [`ArrayView::load`]. Elements are visited in row-major order, so the
//! first fault (if any) is that of the first element in that order.

use bytemuck::Zeroable;

use super::{Tile, Tile1, Tile2, Tile3, Tile4, TileFromFn};
use crate::fault::KResult;
use crate::index::IndexInt;
use crate::view::ArrayView;

/// Coordinate `o + i` as an index below `extent`, or `None` when it lies outside `0..extent`.
#[inline(always)]
pub(super) fn coord<O: IndexInt>(o: O, i: usize, extent: usize) -> Option<usize> {
    let c = o.widen() + i as i128;
    if c >= 0 && c < extent as i128 {
        Some(c as usize)
    } else {
        None
    }
}

/// The array coordinates of row-major element `k` of a tile of shape `X::SHAPE` at the
/// (widened) offsets `o`, or `None` when any axis falls outside `0..extent` of `shape`: the
/// rank-generic form of [`coord`] on every axis, for the tiles of rank 3 and 4.
#[inline(always)]
pub(super) fn coords_nd<X: Tile, const R: usize>(
    k: usize,
    o: [i128; R],
    shape: [usize; R],
) -> Option<[usize; R]> {
    let mut c = [0usize; R];
    let mut rest = k;
    // The last axis varies fastest: peel the tile coordinates off from the right.
    for ax in (0..R).rev() {
        let n = X::SHAPE[ax];
        let v = o[ax] + (rest % n) as i128;
        rest /= n;
        if v < 0 || v >= shape[ax] as i128 {
            return None;
        }
        c[ax] = v as usize;
    }
    Some(c)
}

/// A tile of rank `R` (3 or 4) read from an `R`-D array at offsets `o`: each element through
/// the checked [`ArrayView::load`] in row-major order (so the first fault is the first
/// element's in that order), zero outside the array. No contiguous fast path: the rank-3 and
/// rank-4 tiles are the uncommon case, and this keeps one obviously-checked path.
#[inline]
fn load_nd<X, const R: usize>(a: &ArrayView<X::Elem, R>, o: [i128; R]) -> KResult<X>
where
    X: TileFromFn<Elem: Copy + Zeroable>,
    [usize; R]: crate::index::KernelIndex<R>,
{
    const { assert!(X::RANK == R, "a tile's rank is its array's") };
    let shape = a.shape();
    let mut t = X::from_flat_fn(|_| Zeroable::zeroed());
    for (k, d) in t.as_flat_mut().iter_mut().enumerate() {
        if let Some(c) = coords_nd::<X, R>(k, o, shape) {
            *d = a.load(c)?;
        }
    }
    Ok(t)
}

/// A tile of rank `R` written into an `R`-D array at offsets `o`: each element inside the
/// array through the checked [`ArrayView::store`] (the race check sees each), row-major; the
/// rest is skipped.
#[inline]
fn store_nd<X, const R: usize>(a: &ArrayView<X::Elem, R>, o: [i128; R], t: &X) -> KResult<()>
where
    X: Tile<Elem: Copy>,
    [usize; R]: crate::index::KernelIndex<R>,
{
    const { assert!(X::RANK == R, "a tile's rank is its array's") };
    let shape = a.shape();
    for (k, &v) in t.as_flat().iter().enumerate() {
        if let Some(c) = coords_nd::<X, R>(k, o, shape) {
            a.store(c, v)?;
        }
    }
    Ok(())
}

/// The first coordinate of an axis the whole tile lies inside: `o` and `o + n - 1` both in
/// `0..extent` (`n >= 1`), so every coordinate of the tile on that axis is.
#[inline(always)]
fn inside<O: IndexInt>(o: O, n: usize, extent: usize) -> Option<usize> {
    let c = coord(o, 0, extent)?;
    coord(o, n - 1, extent).map(|_| c)
}

/// A rank-1 tile read from `a` at offset `o` (`tile_load(a, o)`): element `i` is `a[o + i]`,
/// or zero where `o + i` is outside the array.
#[inline]
pub fn load1<T: Copy + Zeroable, const N0: usize, O: IndexInt>(
    a: &ArrayView<T, 1>,
    o: O,
) -> KResult<Tile1<T, N0>> {
    let [n] = a.shape();
    let mut t = Tile1 {
        data: [T::zeroed(); N0],
    };
    // The fast path: the whole tile inside the array (one check), then no check per element.
    // Not weaker than the checked path: `ArrayView::load` checks an index only against the
    // shape, which the tile-wide check already proves for every element, and loads are not
    // logged (the race check sees stores only).
    if N0 > 0 {
        if let Some(c) = inside(o, N0, n) {
            let [s] = a.strides();
            // SAFETY: c..c + N0 are in bounds (checked above), so each pointer is live and aligned
            // (`ArrayView::new`'s contract); with stride 1 they are one run of N0 elements.
            unsafe {
                let p = a.ptr_unchecked(c);
                if s == 1 {
                    std::ptr::copy_nonoverlapping(p, t.data.as_mut_ptr(), N0);
                } else {
                    for (i, d) in t.data.iter_mut().enumerate() {
                        *d = p.offset(i as isize * s).read();
                    }
                }
            }
            return Ok(t);
        }
    }
    for (i, d) in t.data.iter_mut().enumerate() {
        if let Some(c) = coord(o, i, n) {
            *d = a.load(c)?;
        }
    }
    Ok(t)
}

/// A rank-2 tile read from `a` at offsets `(o0, o1)` (`tile_load(a, (o0, o1))`): element
/// `(i, j)` is `a[o0 + i, o1 + j]`, or zero where that is outside the array on either axis.
#[inline]
pub fn load2<T: Copy + Zeroable, const N0: usize, const N1: usize, O0: IndexInt, O1: IndexInt>(
    a: &ArrayView<T, 2>,
    o0: O0,
    o1: O1,
) -> KResult<Tile2<T, N0, N1>> {
    let [n0, n1] = a.shape();
    let mut t = Tile2 {
        data: [[T::zeroed(); N1]; N0],
    };
    // The fast path, as `load1`'s: the whole tile inside (one check per axis), then rows read
    // directly, as one copy each when the innermost stride is 1.
    if N0 > 0 && N1 > 0 {
        if let (Some(c0), Some(c1)) = (inside(o0, N0, n0), inside(o1, N1, n1)) {
            let [s0, s1] = a.strides();
            // SAFETY: every (c0 + i, c1 + j) of the tile is in bounds (checked above), so each
            // pointer is live and aligned (`ArrayView::new`'s contract); with s1 == 1 a row is
            // one run of N1 elements.
            unsafe {
                let p = a.ptr_unchecked((c0, c1));
                for (i, row) in t.data.iter_mut().enumerate() {
                    let r = p.offset(i as isize * s0);
                    if s1 == 1 {
                        std::ptr::copy_nonoverlapping(r, row.as_mut_ptr(), N1);
                    } else {
                        for (j, d) in row.iter_mut().enumerate() {
                            *d = r.offset(j as isize * s1).read();
                        }
                    }
                }
            }
            return Ok(t);
        }
    }
    for (i, row) in t.data.iter_mut().enumerate() {
        let Some(c0) = coord(o0, i, n0) else { continue };
        for (j, d) in row.iter_mut().enumerate() {
            if let Some(c1) = coord(o1, j, n1) {
                *d = a.load((c0, c1))?;
            }
        }
    }
    Ok(t)
}

/// Writes rank-1 tile `t` into `a` at offset `o` (`tile_store(a, o, t)`): `a[o + i] = t[i]`
/// for every `o + i` inside the array; the other elements are skipped.
#[inline]
pub fn store1<T: Copy, const N0: usize, O: IndexInt>(
    a: &ArrayView<T, 1>,
    o: O,
    t: &Tile1<T, N0>,
) -> KResult<()> {
    let [n] = a.shape();
    for (i, &v) in t.data.iter().enumerate() {
        if let Some(c) = coord(o, i, n) {
            a.store(c, v)?;
        }
    }
    Ok(())
}

/// Writes rank-2 tile `t` into `a` at offsets `(o0, o1)` (`tile_store(a, (o0, o1), t)`):
/// `a[o0 + i, o1 + j] = t[i, j]` wherever that is inside the array; the rest is skipped.
#[inline]
pub fn store2<T: Copy, const N0: usize, const N1: usize, O0: IndexInt, O1: IndexInt>(
    a: &ArrayView<T, 2>,
    o0: O0,
    o1: O1,
    t: &Tile2<T, N0, N1>,
) -> KResult<()> {
    let [n0, n1] = a.shape();
    for (i, row) in t.data.iter().enumerate() {
        let Some(c0) = coord(o0, i, n0) else { continue };
        for (j, &v) in row.iter().enumerate() {
            if let Some(c1) = coord(o1, j, n1) {
                a.store((c0, c1), v)?;
            }
        }
    }
    Ok(())
}

/// A rank-3 tile read from `a` at offsets `(o0, o1, o2)` (`tile_load(a, (o0, o1, o2))`):
/// element `(i, j, k)` is `a[o0 + i, o1 + j, o2 + k]`, or zero where that is outside the array
/// on any axis.
#[inline]
pub fn load3<T, const N0: usize, const N1: usize, const N2: usize, O0, O1, O2>(
    a: &ArrayView<T, 3>,
    o0: O0,
    o1: O1,
    o2: O2,
) -> KResult<Tile3<T, N0, N1, N2>>
where
    T: Copy + Zeroable,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
{
    load_nd(a, [o0.widen(), o1.widen(), o2.widen()])
}

/// A rank-4 tile read from `a` at offsets `(o0, o1, o2, o3)`, as [`load3`].
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn load4<
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
) -> KResult<Tile4<T, N0, N1, N2, N3>>
where
    T: Copy + Zeroable,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
    O3: IndexInt,
{
    load_nd(a, [o0.widen(), o1.widen(), o2.widen(), o3.widen()])
}

/// Writes rank-3 tile `t` into `a` at offsets `(o0, o1, o2)` (`tile_store(a, (o0, o1, o2),
/// t)`): `a[o0 + i, o1 + j, o2 + k] = t[i, j, k]` wherever that is inside the array; the rest
/// is skipped.
#[inline]
pub fn store3<T, const N0: usize, const N1: usize, const N2: usize, O0, O1, O2>(
    a: &ArrayView<T, 3>,
    o0: O0,
    o1: O1,
    o2: O2,
    t: &Tile3<T, N0, N1, N2>,
) -> KResult<()>
where
    T: Copy,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
{
    store_nd(a, [o0.widen(), o1.widen(), o2.widen()], t)
}

/// Writes rank-4 tile `t` into `a` at offsets `(o0, o1, o2, o3)`, as [`store3`].
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn store4<
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
) -> KResult<()>
where
    T: Copy,
    O0: IndexInt,
    O1: IndexInt,
    O2: IndexInt,
    O3: IndexInt,
{
    store_nd(a, [o0.widen(), o1.widen(), o2.widen(), o3.widen()], t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A view of `data` with the given shape (row-major, contiguous).
    fn view<T: Copy, const N: usize>(data: &mut [T], shape: [usize; N]) -> ArrayView<T, N> {
        let mut strides = [0isize; N];
        let mut s = 1isize;
        for k in (0..N).rev() {
            strides[k] = s;
            s *= shape[k] as isize;
        }
        assert_eq!(s as usize, data.len());
        // SAFETY: `data` outlives the view in every test, and the shape and strides cover it.
        unsafe { ArrayView::new(data.as_mut_ptr(), shape, strides, "k", "a") }
    }

    #[test]
    fn load3_store3_ragged_edges_against_a_scalar_reference() {
        // A (3, 4, 5) array; a (2, 3, 4) tile at offsets that cross every edge (and below 0).
        let (n0, n1, n2) = (3usize, 4usize, 5usize);
        let mut d: Vec<f32> = (0..n0 * n1 * n2).map(|x| x as f32 + 1.0).collect();
        let orig = d.clone();
        let a = view(&mut d, [n0, n1, n2]);
        for (o0, o1, o2) in [
            (0i64, 0i64, 0i64),
            (2, 2, 3),
            (-1, 3, -2),
            (5, 0, 0),
            (1, -3, 4),
        ] {
            let t: Tile3<f32, 2, 3, 4> = load3(&a, o0, o1, o2).unwrap();
            for i in 0..2 {
                for j in 0..3 {
                    for k in 0..4 {
                        let (c0, c1, c2) = (o0 + i as i64, o1 + j as i64, o2 + k as i64);
                        let inside = (0..n0 as i64).contains(&c0)
                            && (0..n1 as i64).contains(&c1)
                            && (0..n2 as i64).contains(&c2);
                        let want = if inside {
                            orig[((c0 as usize) * n1 + c1 as usize) * n2 + c2 as usize]
                        } else {
                            0.0
                        };
                        assert_eq!(
                            t.data[i][j][k], want,
                            "offsets {o0},{o1},{o2} at {i},{j},{k}"
                        );
                    }
                }
            }
        }
        // A store at (2, 3, 3): only (0, 0, 0..2) of the tile lands, at a[2, 3, 3..5].
        let t = Tile3::<f32, 2, 3, 4>::from_flat_fn(|k| -(k as f32) - 1.0);
        store3(&a, 2u32, 3i8, 3usize, &t).unwrap();
        let mut want = orig.clone();
        want[(2 * n1 + 3) * n2 + 3] = -1.0;
        want[(2 * n1 + 3) * n2 + 4] = -2.0;
        assert_eq!(d, want);
    }

    #[test]
    fn load4_store4_round_trip_and_edges() {
        let shape = [2usize, 3, 2, 3];
        let mut d: Vec<i32> = (0..36).collect();
        let a = view(&mut d, shape);
        let t: Tile4<i32, 2, 2, 2, 2> = load4(&a, 1, 2, 0, 1).unwrap();
        // (0, 0, k, l) -> a[1, 2, k, 1 + l]; every i = 1 or j = 1 is outside axis 0 or 1.
        assert_eq!(t.data[0][0], [[31, 32], [34, 35]]);
        assert_eq!(t.data[1], [[[0; 2]; 2]; 2]);
        assert_eq!(t.data[0][1], [[0; 2]; 2]);
        let z = Tile4::<i32, 1, 1, 1, 4>::splat(7);
        store4(&a, 0, 0, 1, -1, &z).unwrap(); // l = 0 at -1 skipped, l = 3 at 2 lands
        let back: Tile4<i32, 1, 1, 1, 3> = load4(&a, 0, 0, 1, 0).unwrap();
        assert_eq!(back.data, [[[[7, 7, 7]]]]);
        assert_eq!(a.load((0usize, 0usize, 0usize, 2usize)).unwrap(), 2);
    }

    #[test]
    fn load1_pads_both_edges_with_zero() {
        let mut d = [1.0f32, 2.0, 3.0, 4.0, 5.0];
        let a = view(&mut d, [5]);
        let t: Tile1<f32, 4> = load1(&a, 0).unwrap();
        assert_eq!(t.data, [1.0, 2.0, 3.0, 4.0]);
        let t: Tile1<f32, 4> = load1(&a, 3i32).unwrap();
        assert_eq!(t.data, [4.0, 5.0, 0.0, 0.0]);
        let t: Tile1<f32, 4> = load1(&a, -2i64).unwrap();
        assert_eq!(t.data, [0.0, 0.0, 1.0, 2.0]);
        let t: Tile1<f32, 3> = load1(&a, i64::MIN).unwrap();
        assert_eq!(t.data, [0.0; 3]);
        let t: Tile1<f32, 3> = load1(&a, u64::MAX).unwrap(); // 2^64 - 1, not -1
        assert_eq!(t.data, [0.0; 3]);
        let t: Tile1<f32, 8> = load1(&a, -1).unwrap(); // wider than the array
        assert_eq!(t.data, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 0.0, 0.0]);
    }

    #[test]
    fn load2_and_store2_ragged_and_negative() {
        let mut d: [i32; 12] = std::array::from_fn(|k| k as i32 + 1); // 3 x 4
        let a = view(&mut d, [3, 4]);
        let t: Tile2<i32, 2, 3> = load2(&a, 2, -1).unwrap();
        assert_eq!(t.data, [[0, 9, 10], [0, 0, 0]]);
        let t: Tile2<i32, 2, 2> = load2(&a, -1, 3).unwrap();
        assert_eq!(t.data, [[0, 0], [4, 0]]);
        let t: Tile2<i32, 2, 2> = load2(&a, 1usize, 1usize).unwrap();
        assert_eq!(t.data, [[6, 7], [10, 11]]);

        let mut o = [0i32; 12];
        let b = view(&mut o, [3, 4]);
        let s = Tile2::<i32, 2, 3> {
            data: [[1, 2, 3], [4, 5, 6]],
        };
        store2(&b, -1, 2, &s).unwrap(); // row -1 skipped; columns 4 skipped
        store2(&b, 2, -2, &s).unwrap(); // row 2 gets column 0 only; row 3 skipped
        assert_eq!(o, [0, 0, 4, 5, 0, 0, 0, 0, 3, 0, 0, 0]);
    }

    #[test]
    fn store1_skips_outside() {
        let mut o = [0u8; 4];
        let b = view(&mut o, [4]);
        store1(&b, -2, &Tile1::<u8, 3> { data: [7, 8, 9] }).unwrap();
        store1(&b, 3, &Tile1::<u8, 3> { data: [1, 2, 3] }).unwrap();
        assert_eq!(o, [9, 0, 0, 1]);
    }

    #[test]
    fn tiles_larger_than_the_array_and_empty_arrays() {
        let mut d = [1.0f64; 4];
        let a = view(&mut d, [2, 2]);
        let t: Tile2<f64, 3, 3> = load2(&a, 0, 0).unwrap();
        assert_eq!(t.data, [[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0; 3]]);
        let e: &mut [f64] = &mut [];
        let z = view(e, [0, 5]);
        let t: Tile2<f64, 2, 2> = load2(&z, 0, 0).unwrap();
        assert_eq!(t.data, [[0.0; 2]; 2]);
        store2(&z, 0, 0, &t).unwrap();
    }

    /// A view with the given strides (elements) over `data`.
    fn strided<T: Copy, const N: usize>(
        data: &mut [T],
        shape: [usize; N],
        strides: [isize; N],
    ) -> ArrayView<T, N> {
        // SAFETY: each caller's shape and strides stay inside `data`, which outlives the view.
        unsafe { ArrayView::new(data.as_mut_ptr(), shape, strides, "k", "a") }
    }

    /// Every element of a tile read through the fully-inside fast path (and through the
    /// per-element path where the tile overhangs), for contiguous rows, padded rows, a strided
    /// innermost axis and reversed rows, is the element the plain definition names.
    #[test]
    fn fast_path_loads_equal_the_definition() {
        let mut d: Vec<i32> = (0..400).collect();
        let base = d.as_mut_ptr();
        for (shape, strides, off) in [
            ([6usize, 10usize], [10isize, 1isize], 0usize),
            ([6, 10], [13, 1], 0),
            ([6, 10], [31, 3], 0),
            ([6, 10], [-20, 1], 100),
        ] {
            // SAFETY: every index below stays inside `d` (offsets 0..=393).
            let a = unsafe { ArrayView::new(base.add(off), shape, strides, "k", "a") };
            let at = |c0: i64, c1: i64| -> i32 {
                if (0..6).contains(&c0) && (0..10).contains(&c1) {
                    (off as isize + c0 as isize * strides[0] + c1 as isize * strides[1]) as i32
                } else {
                    0
                }
            };
            for (o0, o1) in [(0i64, 0i64), (2, 3), (3, 7), (-1, 2), (4, 0), (0, 9)] {
                let t: Tile2<i32, 3, 4> = load2(&a, o0, o1).unwrap();
                for i in 0..3 {
                    for j in 0..4 {
                        assert_eq!(
                            t.data[i][j],
                            at(o0 + i as i64, o1 + j as i64),
                            "{shape:?} {strides:?} at ({o0}, {o1}), element ({i}, {j})"
                        );
                    }
                }
            }
            let r = strided(&mut d[..], [40], [strides[1].abs() * 3]);
            let t: Tile1<i32, 5> = load1(&r, 7).unwrap();
            let s = strides[1].abs() * 3;
            assert_eq!(
                t.data,
                std::array::from_fn(|i| ((7 + i as isize) * s) as i32)
            );
        }
    }

    /// A write log that refuses every write: each store that reaches the view's checked path
    /// reports a race with "thread 7", and counts itself.
    struct RefuseAll(std::sync::atomic::AtomicUsize);

    impl crate::view::WriteLog for RefuseAll {
        fn register(&self, _: usize, _: usize, _: &[usize], _: &[isize]) {}
        fn record(&self, _: usize, _: usize, _: usize) -> Result<(), usize> {
            self.0.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            Err(7)
        }
    }

    #[test]
    fn in_bounds_stores_go_through_the_checked_store() {
        let mut o = [0i32; 6];
        let b = view(&mut o, [2, 3]);
        let log = RefuseAll(Default::default());
        let _active = crate::view::WriteLogActive::new();
        let t = Tile2::<i32, 2, 2>::ones();
        // SAFETY: `o` outlives the view, used only inside the call while `log` lives.
        let r = unsafe { crate::view::with_write_log(&log, 0, || store2(&b, -1, 2, &t)) };
        // Row -1 and column 3 are skipped without reaching the view; the first in-bounds
        // element in row-major order, (0, 2), reaches the log, which refuses it.
        let e = r.unwrap_err();
        assert_eq!(
            e.kind,
            crate::fault::FaultKind::WriteRace {
                arg: "a",
                index: vec![0, 2],
                threads: (7, 0)
            }
        );
        assert_eq!(log.0.load(std::sync::atomic::Ordering::Relaxed), 1);
        assert_eq!(o, [0; 6]);
    }
}
