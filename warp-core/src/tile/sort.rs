//! `tile_sort(&mut keys, &mut values)`: a 1-D key tile sorted ascending, the value tile of the
//! same length permuted with it.
//!
//! **The order** both backends give, bit for bit: elements are ordered by `(key, index)`, the
//! index being the element's position before the sort, so equal keys keep their order (a
//! stable sort) and the result is unique. Keys compare by value (`<`), except that every NaN
//! is greater than every number and NaNs tie with each other (so they come last, in their
//! original order); `-0.0` and `+0.0` tie (IEEE equality), so they too keep their order.
//! Because `(key, index)` is a strict total order, any correct sort gives the same permutation:
//! the CUDA library (wp_tile_sort.h) runs a bitonic network under it, this module Rust's sort.
//!
//! The generated code sorts in two steps that both backends share: [`sort_perm`] gives the
//! sorting permutation (`p[r]`: the index of the `r`-th smallest element), and [`permute`]
//! applies it to the values and then to the keys. (A statement of the kernel IR sets one
//! variable, and a sort sets two.)

use super::Tile1;

/// The key types of `tile_sort` (Warp's: 32- and 64-bit integers and floats), with the order of
/// the module docs.
pub trait SortKey: Copy {
    /// Whether `self` comes strictly before `o` (NaN after every number; NaNs tie).
    fn sort_lt(self, o: Self) -> bool;
}

macro_rules! int_key {
    ($($t:ty),*) => {$(
        impl SortKey for $t {
            #[inline(always)]
            fn sort_lt(self, o: Self) -> bool {
                self < o
            }
        }
    )*};
}
int_key!(i32, u32, i64, u64);

macro_rules! float_key {
    ($($t:ty),*) => {$(
        impl SortKey for $t {
            #[inline(always)]
            fn sort_lt(self, o: Self) -> bool {
                // A NaN is never before anything; a number is before a NaN; else `<` (which
                // makes -0 and +0 tie).
                !self.is_nan() && (o.is_nan() || self < o)
            }
        }
    )*};
}
float_key!(f32, f64);

/// The sorting permutation of `keys` in the module's order: element `r` is the index (before
/// the sort) of the element that ends at position `r`.
pub fn sort_perm<K: SortKey, const N: usize>(keys: &Tile1<K, N>) -> Tile1<i32, N> {
    let mut p: [i32; N] = std::array::from_fn(|i| i as i32);
    // Unstable is enough (and allocates nothing): the index breaks every tie, so the order is
    // strict and total and the result is the stable sort's.
    p.sort_unstable_by(|&a, &b| {
        let (ka, kb) = (keys.data[a as usize], keys.data[b as usize]);
        if ka.sort_lt(kb) {
            std::cmp::Ordering::Less
        } else if kb.sort_lt(ka) {
            std::cmp::Ordering::Greater
        } else {
            a.cmp(&b)
        }
    });
    Tile1 { data: p }
}

/// `t` permuted by `p` (from [`sort_perm`]): element `r` is `t[p[r]]`. An entry of `p` outside
/// the tile (never one of `sort_perm`'s) keeps element `r` rather than panicking.
pub fn permute<T: Copy, const N: usize>(t: &Tile1<T, N>, p: &Tile1<i32, N>) -> Tile1<T, N> {
    Tile1 {
        data: std::array::from_fn(|r| {
            usize::try_from(p.data[r])
                .ok()
                .and_then(|i| t.data.get(i).copied())
                .unwrap_or(t.data[r])
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Keys with duplicates, both zeros and NaNs: the order is the stable sort by value with
    /// NaNs last, and the values follow their keys.
    #[test]
    fn stable_with_nan_last_and_zeros_tied() {
        let keys = Tile1 {
            data: [3.0f32, f32::NAN, -0.0, 1.0, 0.0, 3.0, -f32::NAN, -2.0, 1.0],
        };
        let p = sort_perm(&keys);
        assert_eq!(p.data, [7, 2, 4, 3, 8, 0, 5, 1, 6]);
        let vals = Tile1 {
            data: std::array::from_fn::<u8, 9, _>(|i| i as u8 * 10),
        };
        assert_eq!(permute(&vals, &p).data, [70, 20, 40, 30, 80, 0, 50, 10, 60]);
        let k = permute(&keys, &p).data;
        // -0 before +0 here because -0 came first; the bits say so.
        assert_eq!(k[1].to_bits(), (-0.0f32).to_bits());
        assert_eq!(k[2].to_bits(), 0.0f32.to_bits());
        assert!(k[7].is_nan() && k[8].is_nan());
    }

    #[test]
    fn integer_keys_with_extremes() {
        let keys = Tile1 {
            data: [u64::MAX, 0, 5, u64::MAX, 1],
        };
        assert_eq!(sort_perm(&keys).data, [1, 4, 2, 0, 3]);
        let keys = Tile1 {
            data: [i32::MIN, 7, i32::MAX, -1, 7],
        };
        assert_eq!(sort_perm(&keys).data, [0, 3, 1, 4, 2]);
    }

    #[test]
    fn permute_of_a_bad_entry_keeps_the_element() {
        let t = Tile1 { data: [1, 2, 3] };
        let p = Tile1 { data: [2, -1, 9] };
        assert_eq!(permute(&t, &p).data, [3, 2, 3]);
    }
}
