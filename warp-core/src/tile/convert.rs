//! Tiles made from other tiles without arithmetic across elements: `tile_reshape` (and
//! `tile_squeeze`, a reshape that drops dims of 1) and `tile_diag_add`. (`tile_full` is
//! `Tile1::splat`/`Tile2::splat`; `tile_astype` is `map` with `as`'s meaning.)
//!
//! A reshape keeps the elements in row-major order: element `k` of the flattening of the
//! source is element `k` of the result's. The sizes must agree; the macro checks literal dims
//! at the call, and the `const` assertions here check the rest when rustc instantiates them.

use super::{Tile, Tile1, Tile2, TileFromFn};
use crate::builtins::Scalar;

/// `tile_reshape` between tiles of any ranks (1 to 4) of the same size: what the generated code
/// calls when either side has rank 3 or 4 (`reshape11` .. `reshape22` stay for ranks 1-2).
#[inline]
pub fn reshape<X, Y>(a: &X) -> Y
where
    X: Tile<Elem: Copy>,
    Y: TileFromFn<Elem = X::Elem>,
{
    const { assert!(X::SIZE == Y::SIZE, "tile_reshape: the sizes differ") };
    let flat = a.as_flat();
    Y::from_flat_fn(|k| flat[k])
}

/// `tile_reshape` of `(A,)` to `(M,)`.
#[inline]
pub fn reshape11<T: Copy, const A: usize, const M: usize>(a: &Tile1<T, A>) -> Tile1<T, M> {
    const { assert!(A == M, "tile_reshape: the sizes differ") };
    Tile1 {
        data: std::array::from_fn(|k| a.data[k]),
    }
}

/// `tile_reshape` of `(A,)` to `(M, N)`.
#[inline]
pub fn reshape12<T: Copy, const A: usize, const M: usize, const N: usize>(
    a: &Tile1<T, A>,
) -> Tile2<T, M, N> {
    const { assert!(A == M * N, "tile_reshape: the sizes differ") };
    Tile2 {
        data: std::array::from_fn(|i| std::array::from_fn(|j| a.data[i * N + j])),
    }
}

/// `tile_reshape` of `(A, B)` to `(M,)`.
#[inline]
pub fn reshape21<T: Copy, const A: usize, const B: usize, const M: usize>(
    a: &Tile2<T, A, B>,
) -> Tile1<T, M> {
    const { assert!(A * B == M, "tile_reshape: the sizes differ") };
    let flat = a.data.as_flattened();
    Tile1 {
        data: std::array::from_fn(|k| flat[k]),
    }
}

/// `tile_reshape` of `(A, B)` to `(M, N)`.
#[inline]
pub fn reshape22<T: Copy, const A: usize, const B: usize, const M: usize, const N: usize>(
    a: &Tile2<T, A, B>,
) -> Tile2<T, M, N> {
    const { assert!(A * B == M * N, "tile_reshape: the sizes differ") };
    let flat = a.data.as_flattened();
    Tile2 {
        data: std::array::from_fn(|i| std::array::from_fn(|j| flat[i * N + j])),
    }
}

/// `tile_diag_add(a, d)`: `a` with `d[i]` added to `a[i][i]` (the builtins' `+`, wrapping for
/// integers). Only the diagonal is computed: adding zero elsewhere would turn `-0.0` into
/// `+0.0`.
#[inline]
pub fn diag_add<T: Scalar, const N: usize, const M: usize>(
    a: &Tile2<T, N, M>,
    d: &Tile1<T, N>,
) -> Tile2<T, N, M> {
    const { assert!(N == M, "tile_diag_add: `a` must be square") };
    let mut out = *a;
    for (i, row) in out.data.iter_mut().enumerate() {
        row[i] = row[i].s_add(d.data[i]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reshape_between_ranks_keeps_row_major_order() {
        use super::super::{Tile3, Tile4};
        let a = Tile3::<i32, 2, 3, 2>::from_flat_fn(|k| k as i32);
        let b: Tile2<i32, 6, 2> = reshape(&a);
        assert_eq!(b.data[4], [8, 9]);
        let c: Tile4<i32, 1, 2, 2, 3> = reshape(&b);
        assert_eq!(c.data[0][1][0], [6, 7, 8]);
        let d: Tile1<i32, 12> = reshape(&c);
        assert_eq!(d.data, std::array::from_fn(|k| k as i32));
        let e: Tile3<i32, 2, 3, 2> = reshape(&d);
        assert_eq!(e, a);
    }

    #[test]
    fn reshapes_keep_row_major_order() {
        let a = Tile1 {
            data: std::array::from_fn::<i32, 6, _>(|k| k as i32),
        };
        let b: Tile2<i32, 2, 3> = reshape12(&a);
        assert_eq!(b.data, [[0, 1, 2], [3, 4, 5]]);
        let c: Tile2<i32, 3, 2> = reshape22(&b);
        assert_eq!(c.data, [[0, 1], [2, 3], [4, 5]]);
        let d: Tile1<i32, 6> = reshape21(&c);
        assert_eq!(d, a);
        assert_eq!(reshape11::<i32, 6, 6>(&a), a);
    }

    #[test]
    fn diag_add_touches_only_the_diagonal() {
        let a = Tile2 {
            data: [[-0.0f32, 1.0], [2.0, 3.0]],
        };
        let d = Tile1 { data: [1.0, -3.0] };
        let r = diag_add(&a, &d);
        assert_eq!(r.data, [[1.0, 1.0], [2.0, 0.0]]);
        let z = diag_add(
            &Tile2 {
                data: [[0.0f32, -0.0], [-0.0, 1.0]],
            },
            &Tile1 { data: [0.0; 2] },
        );
        assert_eq!(z.data[0][1].to_bits(), (-0.0f32).to_bits());
        let w = diag_add(&Tile2 { data: [[i32::MAX]] }, &Tile1 { data: [1] });
        assert_eq!(w.data[0][0], i32::MIN);
    }
}
