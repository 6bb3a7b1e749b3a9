//! Scans of rank-1 tiles (`tile_scan_inclusive`, `tile_scan_exclusive`, and the inclusive
//! `max`/`min` scans) in an order the CUDA library follows exactly, so that float scans give
//! the same bits on both backends for a block size `bd`.
//!
//! The order, for `S` elements and `C = ceil(S / bd)`:
//! 1. lane `l` owns the contiguous chunk `[l C, min((l + 1) C, S))` and runs through it from its
//!    first element: `r = x[first]`, then `r = op(r, x[e])` (the chunk's running values), ending
//!    at the chunk's total;
//! 2. the chunks' prefixes, in lane order: `p[1] = total[0]`, `p[l + 1] = op(p[l], total[l])`
//!    (one thread on the GPU);
//! 3. an inclusive result is `r` in chunk 0 and `op(p[l], r)` in chunk `l > 0`; an exclusive
//!    one is the inclusive result of the element before (the identity, zero, at element 0).
//!
//! Sums use the builtins' `+` (IEEE for floats, wrapping for integers); max and min the
//! builtins' (a NaN loses to a number).

use super::reduce::MAX_BLOCK_DIM;
use super::Tile1;
use crate::builtins::{MinMax, Scalar};

/// The inclusive scan of `t` with `op` in the module's order for block size `bd`.
pub fn scan_with<T: Copy, const N: usize>(
    t: &Tile1<T, N>,
    bd: usize,
    op: impl Fn(T, T) -> T,
) -> Tile1<T, N> {
    let bd = bd.clamp(1, MAX_BLOCK_DIM);
    let chunk = N.div_ceil(bd).max(1);
    let mut out = *t;
    let mut prefix: Option<T> = None;
    for start in (0..N).step_by(chunk) {
        let end = (start + chunk).min(N);
        let mut r = t.data[start];
        for e in start..end {
            if e > start {
                r = op(r, t.data[e]);
            }
            out.data[e] = match prefix {
                Some(p) => op(p, r),
                None => r,
            };
        }
        // `r` is the chunk's total.
        prefix = Some(match prefix {
            Some(p) => op(p, r),
            None => r,
        });
    }
    out
}

/// `tile_scan_inclusive(t)`: running sums.
pub fn scan_inclusive<T: Scalar, const N: usize>(t: &Tile1<T, N>, bd: usize) -> Tile1<T, N> {
    scan_with(t, bd, Scalar::s_add)
}

/// `tile_scan_exclusive(t)`: the running sums before each element (zero first).
pub fn scan_exclusive<T: Scalar, const N: usize>(t: &Tile1<T, N>, bd: usize) -> Tile1<T, N> {
    let inc = scan_inclusive(t, bd);
    let mut out = inc;
    out.data[0] = T::ZERO;
    out.data[1..].copy_from_slice(&inc.data[..N - 1]);
    out
}

/// `tile_scan_max_inclusive(t)`: running maxima.
pub fn scan_max_inclusive<T: MinMax, const N: usize>(t: &Tile1<T, N>, bd: usize) -> Tile1<T, N> {
    scan_with(t, bd, MinMax::w_max)
}

/// `tile_scan_min_inclusive(t)`: running minima.
pub fn scan_min_inclusive<T: MinMax, const N: usize>(t: &Tile1<T, N>, bd: usize) -> Tile1<T, N> {
    scan_with(t, bd, MinMax::w_min)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integer_scans_are_prefix_sums_for_every_block_size() {
        let t = Tile1 {
            data: std::array::from_fn::<i32, 37, _>(|i| (i as i32 * 7) % 11 - 5),
        };
        let mut acc = 0;
        let want: Vec<i32> = t
            .data
            .iter()
            .map(|&v| {
                acc += v;
                acc
            })
            .collect();
        for bd in [1, 2, 5, 32, 37, 64, 1024] {
            assert_eq!(scan_inclusive(&t, bd).data.to_vec(), want, "bd {bd}");
            let ex = scan_exclusive(&t, bd).data;
            assert_eq!(ex[0], 0);
            assert_eq!(&ex[1..], &want[..36], "bd {bd}");
        }
        let m = scan_max_inclusive(&t, 4).data;
        let mut hi = i32::MIN;
        for (k, &v) in t.data.iter().enumerate() {
            hi = hi.max(v);
            assert_eq!(m[k], hi);
        }
    }

    #[test]
    fn float_order_depends_on_the_block_size_as_documented() {
        // 1e8 then ones: sequentially each one vanishes (f32's spacing at 1e8 is 8); chunked,
        // the second chunk's ones add up first.
        let t = Tile1 {
            data: std::array::from_fn::<f32, 16, _>(|i| if i == 0 { 1e8 } else { 1.0 }),
        };
        assert_eq!(scan_inclusive(&t, 1).data[15], 1e8);
        // bd 2: chunks [0, 8) and [8, 16); the second's total, 8, is added to 1e8 once.
        assert_eq!(scan_inclusive(&t, 2).data[15], 1e8 + 8.0);
    }
}
