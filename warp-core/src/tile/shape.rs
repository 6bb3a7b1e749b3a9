//! Tiles reshaped without arithmetic: `tile_transpose` and `tile_broadcast` (numpy's rule:
//! shapes aligned on the right, each source dim 1 or the target's).
//!
//! The shapes are const generics. The front end refuses shapes it can tell are wrong and asks
//! rustc to compare the named consts it cannot; the `const` assertions here are the backstop.

use super::{Tile1, Tile2};

/// `tile_transpose(a)`: `out[j][i] = a[i][j]`.
#[inline]
pub fn transpose<T: Copy, const M: usize, const N: usize>(a: &Tile2<T, M, N>) -> Tile2<T, N, M> {
    let mut out = Tile2 {
        data: [[a.data[0][0]; M]; N],
    };
    for (i, row) in a.data.iter().enumerate() {
        for (j, &v) in row.iter().enumerate() {
            out.data[j][i] = v;
        }
    }
    out
}

/// `tile_broadcast` of a rank-1 tile to rank 1: `(1,)` to `(N,)`, or `(N,)` to itself.
#[inline]
pub fn broadcast11<T: Copy, const S: usize, const N: usize>(a: &Tile1<T, S>) -> Tile1<T, N> {
    const {
        assert!(
            S == N || S == 1,
            "tile_broadcast: each source dim is 1 or the target's"
        )
    };
    Tile1 {
        data: std::array::from_fn(|j| a.data[if S == 1 { 0 } else { j }]),
    }
}

/// `tile_broadcast` of a rank-1 tile `(S,)` to `(M, N)`: the row repeated (`S` is `N` or 1).
#[inline]
pub fn broadcast12<T: Copy, const S: usize, const M: usize, const N: usize>(
    a: &Tile1<T, S>,
) -> Tile2<T, M, N> {
    const {
        assert!(
            S == N || S == 1,
            "tile_broadcast: each source dim is 1 or the target's"
        )
    };
    Tile2 {
        data: [std::array::from_fn(|j| a.data[if S == 1 { 0 } else { j }]); M],
    }
}

/// `tile_broadcast` of `(S0, S1)` to `(M, N)` (each source dim 1 or the target's).
#[inline]
pub fn broadcast22<T: Copy, const S0: usize, const S1: usize, const M: usize, const N: usize>(
    a: &Tile2<T, S0, S1>,
) -> Tile2<T, M, N> {
    const {
        assert!(
            (S0 == M || S0 == 1) && (S1 == N || S1 == 1),
            "tile_broadcast: each source dim is 1 or the target's"
        )
    };
    Tile2 {
        data: std::array::from_fn(|i| {
            let r = &a.data[if S0 == 1 { 0 } else { i }];
            std::array::from_fn(|j| r[if S1 == 1 { 0 } else { j }])
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transpose_moves_every_element() {
        let a = Tile2 {
            data: [[1, 2, 3], [4, 5, 6]],
        };
        assert_eq!(transpose(&a).data, [[1, 4], [2, 5], [3, 6]]);
    }

    #[test]
    fn broadcasts_follow_numpys_rule() {
        let one = Tile1 { data: [7.0f32] };
        assert_eq!(broadcast11::<_, 1, 3>(&one).data, [7.0; 3]);
        let row = Tile1 { data: [1, 2, 3] };
        assert_eq!(broadcast12::<_, 3, 2, 3>(&row).data, [[1, 2, 3], [1, 2, 3]]);
        let col = Tile2 { data: [[1], [2]] };
        assert_eq!(
            broadcast22::<_, 2, 1, 2, 3>(&col).data,
            [[1, 1, 1], [2, 2, 2]]
        );
        let r = Tile2 { data: [[1, 2]] };
        assert_eq!(
            broadcast22::<_, 1, 2, 3, 2>(&r).data,
            [[1, 2], [1, 2], [1, 2]]
        );
    }
}
