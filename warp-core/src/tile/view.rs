//! Windows of tiles: `tile_view` (a sub-tile read out of a tile) and the in-place forms that
//! write a tile into a window of another (`tile_assign`, `tile_add_inplace`,
//! `tile_sub_inplace`, `tile_bit_and_inplace`, `tile_bit_or_inplace`, `tile_bit_xor_inplace`).
//!
//! A window of shape `(M, N)` at offset `(o0, o1)` of a tile of shape `(A, B)` covers the
//! elements `(o0 + i, o1 + j)`. It must lie wholly inside the tile: otherwise the operation is
//! a [`FaultKind::TileIndex`](crate::fault::FaultKind::TileIndex) fault (nothing is read or
//! written), whose index is the first coordinate of the window outside the tile on each axis
//! (the offset where it is out of range, else the window's last coordinate). Warp checks only
//! constant offsets and leaves a run-time offset out of range to a debug-build assertion; a
//! fault here is never a read or write outside the tile.
//!
//! A view is a copy here (tiles are values): writing the view does not write the tile it came
//! from (Warp's view aliases its parent's shared memory); `tile_assign` is how a window is
//! written. A view may drop leading axes (Warp's `tile_view(t, (i,))` of a 2-D tile is row `i`):
//! its dims are aligned with the parent's trailing ones, and the dropped axes have extent 1.

use super::{index_fault, Tile, Tile1, Tile2};
use crate::builtins::Scalar;
use crate::fault::KResult;
use crate::index::IndexInt;

/// The start of a window of extent `m` at offset `o` on an axis of extent `n`, or `Err` with
/// the coordinate to report (see the module docs).
#[inline(always)]
fn window_start(w: i128, m: usize, n: usize) -> Result<usize, i128> {
    if w < 0 || w >= n as i128 {
        return Err(w);
    }
    let last = w + m as i128 - 1;
    if last >= n as i128 {
        return Err(last);
    }
    Ok(w as usize)
}

/// The window's starts on a parent of shape `P::SHAPE`, for a window of `shape` (the parent's
/// rank; 1 on dropped axes), or the fault.
#[inline(always)]
fn starts<P: Tile>(
    offs: [i128; 2],
    shape: [usize; 2],
    kernel: &'static str,
) -> KResult<[usize; 2]> {
    let mut out = [0usize; 2];
    let mut bad = None;
    for k in 0..P::RANK {
        match window_start(offs[k], shape[k], P::SHAPE[k]) {
            Ok(s) => out[k] = s,
            Err(c) => {
                let mut idx = [0i128; 4];
                for (a, slot) in idx.iter_mut().enumerate().take(P::RANK) {
                    *slot = if a == k { c } else { offs[a] };
                }
                bad.get_or_insert(idx);
            }
        }
    }
    match bad {
        Some(idx) => index_fault::<_, P>(kernel, idx),
        None => Ok(out),
    }
}

/// `tile_view(t, o)` of a 1-D tile: `M` elements from `o`.
#[inline]
pub fn view11<T: Copy, const A: usize, const M: usize, O: IndexInt>(
    t: &Tile1<T, A>,
    o: O,
    kernel: &'static str,
) -> KResult<Tile1<T, M>> {
    const { assert!(M <= A, "tile_view: the view is larger than the tile") };
    let [s, _] = starts::<Tile1<T, A>>([o.widen(), 0], [M, 1], kernel)?;
    Ok(Tile1 {
        data: std::array::from_fn(|i| t.data[s + i]),
    })
}

/// `tile_view(t, (i,))` of a 2-D tile (no shape): row `i`, Warp's rank-dropping view.
#[inline]
pub fn view21<T: Copy, const A: usize, const B: usize, const N: usize, O: IndexInt>(
    t: &Tile2<T, A, B>,
    o: O,
    kernel: &'static str,
) -> KResult<Tile1<T, N>> {
    const { assert!(N == B, "tile_view: a row of the tile") };
    let [s, _] = starts::<Tile2<T, A, B>>([o.widen(), 0], [1, B], kernel)?;
    Ok(Tile1 {
        data: std::array::from_fn(|j| t.data[s][j]),
    })
}

/// `tile_view(t, (o0, o1))` of a 2-D tile: the `(M, N)` window at `(o0, o1)`.
#[inline]
pub fn view22<T, const A: usize, const B: usize, const M: usize, const N: usize, O0, O1>(
    t: &Tile2<T, A, B>,
    o0: O0,
    o1: O1,
    kernel: &'static str,
) -> KResult<Tile2<T, M, N>>
where
    T: Copy,
    O0: IndexInt,
    O1: IndexInt,
{
    const {
        assert!(
            M <= A && N <= B,
            "tile_view: the view is larger than the tile"
        )
    };
    let [s0, s1] = starts::<Tile2<T, A, B>>([o0.widen(), o1.widen()], [M, N], kernel)?;
    Ok(Tile2 {
        data: std::array::from_fn(|i| std::array::from_fn(|j| t.data[s0 + i][s1 + j])),
    })
}

/// `dst` with `f(dst[o + i], src[i])` in the window of `src`'s shape at `o` (1-D).
#[inline]
pub fn window1<T: Copy, const A: usize, const M: usize, O: IndexInt>(
    dst: &Tile1<T, A>,
    src: &Tile1<T, M>,
    o: O,
    kernel: &'static str,
    f: impl Fn(T, T) -> T,
) -> KResult<Tile1<T, A>> {
    const {
        assert!(
            M <= A,
            "tile_assign: the source is larger than the destination"
        )
    };
    let [s, _] = starts::<Tile1<T, A>>([o.widen(), 0], [M, 1], kernel)?;
    let mut out = *dst;
    for (d, &x) in out.data[s..s + M].iter_mut().zip(&src.data) {
        *d = f(*d, x);
    }
    Ok(out)
}

/// `dst` with `f(dst[o0 + i][o1 + j], src[i][j])` in the window of `src`'s shape (2-D).
#[inline]
pub fn window2<T, const A: usize, const B: usize, const M: usize, const N: usize, O0, O1>(
    dst: &Tile2<T, A, B>,
    src: &Tile2<T, M, N>,
    o0: O0,
    o1: O1,
    kernel: &'static str,
    f: impl Fn(T, T) -> T,
) -> KResult<Tile2<T, A, B>>
where
    T: Copy,
    O0: IndexInt,
    O1: IndexInt,
{
    const {
        assert!(
            M <= A && N <= B,
            "tile_assign: the source is larger than the destination"
        )
    };
    let [s0, s1] = starts::<Tile2<T, A, B>>([o0.widen(), o1.widen()], [M, N], kernel)?;
    let mut out = *dst;
    for (row, srow) in out.data[s0..s0 + M].iter_mut().zip(&src.data) {
        for (d, &x) in row[s1..s1 + N].iter_mut().zip(srow) {
            *d = f(*d, x);
        }
    }
    Ok(out)
}

/// The elements of a window of shape `shape` at `offs` in a tile of type `P`: pairs of the
/// parent's row-major index and the window's, in the window's row-major order; or the fault.
/// (The adjoints' walk over a window, for every rank the views take.)
pub(crate) fn window_pairs<P: Tile>(
    offs: [i128; 2],
    shape: [usize; 2],
    kernel: &'static str,
) -> KResult<impl Iterator<Item = (usize, usize)>> {
    let [s0, s1] = starts::<P>(offs, shape, kernel)?;
    // A 1-D parent has one row: its columns are axis 0.
    let (rows, cols, start, stride) = match P::RANK {
        1 => (1, shape[0], s0, 0),
        _ => (shape[0], shape[1], s0 * P::SHAPE[1] + s1, P::SHAPE[1]),
    };
    Ok((0..rows).flat_map(move |i| (0..cols).map(move |j| (start + i * stride + j, i * cols + j))))
}

/// The element functions of the in-place forms, by name: what `window1`/`window2` apply.
pub mod op {
    use super::Scalar;

    /// `tile_assign`: the source's element.
    #[inline(always)]
    pub fn assign<T>(_d: T, s: T) -> T {
        s
    }
    /// `tile_add_inplace`: the builtins' `+` (wrapping for integers).
    #[inline(always)]
    pub fn add<T: Scalar>(d: T, s: T) -> T {
        d.s_add(s)
    }
    /// `tile_sub_inplace`: the builtins' `-` (wrapping for integers).
    #[inline(always)]
    pub fn sub<T: Scalar>(d: T, s: T) -> T {
        d.s_sub(s)
    }
    /// `tile_bit_and_inplace` (integer tiles).
    #[inline(always)]
    pub fn bit_and<T: std::ops::BitAnd<Output = T>>(d: T, s: T) -> T {
        d & s
    }
    /// `tile_bit_or_inplace` (integer tiles).
    #[inline(always)]
    pub fn bit_or<T: std::ops::BitOr<Output = T>>(d: T, s: T) -> T {
        d | s
    }
    /// `tile_bit_xor_inplace` (integer tiles).
    #[inline(always)]
    pub fn bit_xor<T: std::ops::BitXor<Output = T>>(d: T, s: T) -> T {
        d ^ s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fault::FaultKind;

    fn t44() -> Tile2<i32, 4, 4> {
        Tile2 {
            data: std::array::from_fn(|i| std::array::from_fn(|j| (10 * i + j) as i32)),
        }
    }

    #[test]
    fn views_copy_the_window() {
        let t = t44();
        let v: Tile2<i32, 2, 3> = view22(&t, 1, 1u32, "k").unwrap();
        assert_eq!(v.data, [[11, 12, 13], [21, 22, 23]]);
        let r: Tile1<i32, 4> = view21(&t, 3i64, "k").unwrap();
        assert_eq!(r.data, [30, 31, 32, 33]);
        let a = Tile1 {
            data: [1, 2, 3, 4, 5],
        };
        let w: Tile1<i32, 2> = view11(&a, 3, "k").unwrap();
        assert_eq!(w.data, [4, 5]);
    }

    #[test]
    fn a_window_outside_the_tile_faults() {
        let t = t44();
        let e = view22::<_, 4, 4, 2, 3, _, _>(&t, 1, 2, "k").unwrap_err();
        match e.kind {
            FaultKind::TileIndex { index, shape, rank } => {
                assert_eq!(
                    (rank, &index[..2], &shape[..2]),
                    (2, &[1, 4][..], &[4, 4][..])
                );
            }
            k => panic!("{k:?}"),
        }
        assert!(view22::<_, 4, 4, 1, 1, _, _>(&t, -1, 0, "k").is_err());
        assert!(view21::<_, 4, 4, 4, _>(&t, 4, "k").is_err());
        let s = Tile1 { data: [7, 7] };
        assert!(window1(&Tile1 { data: [0; 3] }, &s, 2, "k", op::assign).is_err());
    }

    #[test]
    fn windows_write_only_their_elements() {
        let t = t44();
        let s = Tile2 {
            data: [[1, 2], [3, 4]],
        };
        let a = window2(&t, &s, 2, 1, "k", op::assign).unwrap();
        assert_eq!(a.data[2][1..3], [1, 2]);
        assert_eq!(a.data[3][1..3], [3, 4]);
        assert_eq!(a.data[3][0], 30);
        let b = window2(&t, &s, 0, 0, "k", op::sub).unwrap();
        assert_eq!(b.data[1][..3], [7, 7, 12]);
        let c = window2(&t, &s, 0, 0, "k", op::bit_xor).unwrap();
        assert_eq!(c.data[0][..3], [1, 3, 2]);
        let w = window1(
            &Tile1 {
                data: [i32::MAX, 0],
            },
            &Tile1 { data: [1] },
            0,
            "k",
            op::add,
        );
        assert_eq!(w.unwrap().data, [i32::MIN, 0]);
    }
}
