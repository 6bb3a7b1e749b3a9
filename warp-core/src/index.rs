//! Conversion of the index expressions a kernel writes (`a[i]`, `a[(i, j)]`) into checked
//! per-dimension indices.
//!
//! Any integer type may index an array, as in Warp. Indices are widened to `i128` so that a
//! negative `i32` and a huge `u64` are both reported as written, never wrapped.

/// An index into an array of `N` dimensions: one integer for `N = 1`, a tuple of `N` integers
/// otherwise.
pub trait KernelIndex<const N: usize>: Copy {
    /// The index, one entry per dimension, widened losslessly (for fault reports).
    fn components(self) -> [i128; N];
    /// The index as `usize`s for the bounds check: a negative value sign-extends to a huge
    /// one, so the single unsigned comparison `i < extent` rejects it too.
    fn to_usize(self) -> [usize; N];
}

macro_rules! index_impls {
    ($($t:ty),*) => {$(
        impl KernelIndex<1> for $t {
            #[inline(always)]
            fn components(self) -> [i128; 1] { [self as i128] }
            #[inline(always)]
            fn to_usize(self) -> [usize; 1] { [IndexInt::as_usize(self)] }
        }
    )*};
}
index_impls!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);

/// Integers usable inside an index tuple.
pub trait IndexInt: Copy {
    /// The value widened losslessly.
    fn widen(self) -> i128;
    /// The value as `usize`, negative values sign-extended (so they fail a bounds check).
    fn as_usize(self) -> usize;
}
macro_rules! index_ints {
    ($($t:ty),*) => {$(
        impl IndexInt for $t {
            #[inline(always)]
            fn widen(self) -> i128 { self as i128 }
            #[inline(always)]
            #[allow(clippy::cast_possible_wrap)]
            fn as_usize(self) -> usize { self as isize as usize }
        }
    )*};
}
index_ints!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);

/// An index already split into in-range candidates, one `usize` per dimension: what the
/// rank-generic tile loads and stores (`tile::load3`, ..) compute their coordinates as.
impl<const N: usize> KernelIndex<N> for [usize; N] {
    #[inline(always)]
    fn components(self) -> [i128; N] {
        self.map(|c| c as i128)
    }
    #[inline(always)]
    fn to_usize(self) -> [usize; N] {
        self
    }
}

impl<A: IndexInt> KernelIndex<1> for (A,) {
    #[inline(always)]
    fn components(self) -> [i128; 1] {
        [self.0.widen()]
    }
    #[inline(always)]
    fn to_usize(self) -> [usize; 1] {
        [self.0.as_usize()]
    }
}
impl<A: IndexInt, B: IndexInt> KernelIndex<2> for (A, B) {
    #[inline(always)]
    fn components(self) -> [i128; 2] {
        [self.0.widen(), self.1.widen()]
    }
    #[inline(always)]
    fn to_usize(self) -> [usize; 2] {
        [self.0.as_usize(), self.1.as_usize()]
    }
}
impl<A: IndexInt, B: IndexInt, C: IndexInt> KernelIndex<3> for (A, B, C) {
    #[inline(always)]
    fn components(self) -> [i128; 3] {
        [self.0.widen(), self.1.widen(), self.2.widen()]
    }
    #[inline(always)]
    fn to_usize(self) -> [usize; 3] {
        [self.0.as_usize(), self.1.as_usize(), self.2.as_usize()]
    }
}
impl<A: IndexInt, B: IndexInt, C: IndexInt, D: IndexInt> KernelIndex<4> for (A, B, C, D) {
    #[inline(always)]
    fn components(self) -> [i128; 4] {
        [
            self.0.widen(),
            self.1.widen(),
            self.2.widen(),
            self.3.widen(),
        ]
    }
    #[inline(always)]
    fn to_usize(self) -> [usize; 4] {
        [
            self.0.as_usize(),
            self.1.as_usize(),
            self.2.as_usize(),
            self.3.as_usize(),
        ]
    }
}
