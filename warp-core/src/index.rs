//! Conversion of the index expressions a kernel writes (`a[i]`, `a[(i, j)]`) into checked
//! per-dimension indices.
//!
//! Any integer type may index an array, as in Warp. Indices are widened to `i128` so that a
//! negative `i32` and a huge `u64` are both reported as written, never wrapped.

/// An index into an array of `N` dimensions: one integer for `N = 1`, a tuple of `N` integers
/// otherwise.
pub trait KernelIndex<const N: usize>: Copy {
    /// The index, one entry per dimension, widened losslessly.
    fn components(self) -> [i128; N];
}

macro_rules! index_impls {
    ($($t:ty),*) => {$(
        impl KernelIndex<1> for $t {
            #[inline(always)]
            fn components(self) -> [i128; 1] { [self as i128] }
        }
    )*};
}
index_impls!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);

/// Integers usable inside an index tuple.
pub trait IndexInt: Copy {
    /// The value widened losslessly.
    fn widen(self) -> i128;
}
macro_rules! index_ints {
    ($($t:ty),*) => {$(
        impl IndexInt for $t {
            #[inline(always)]
            fn widen(self) -> i128 { self as i128 }
        }
    )*};
}
index_ints!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);

impl<A: IndexInt> KernelIndex<1> for (A,) {
    #[inline(always)]
    fn components(self) -> [i128; 1] {
        [self.0.widen()]
    }
}
impl<A: IndexInt, B: IndexInt> KernelIndex<2> for (A, B) {
    #[inline(always)]
    fn components(self) -> [i128; 2] {
        [self.0.widen(), self.1.widen()]
    }
}
impl<A: IndexInt, B: IndexInt, C: IndexInt> KernelIndex<3> for (A, B, C) {
    #[inline(always)]
    fn components(self) -> [i128; 3] {
        [self.0.widen(), self.1.widen(), self.2.widen()]
    }
}
impl<A: IndexInt, B: IndexInt, C: IndexInt, D: IndexInt> KernelIndex<4> for (A, B, C, D) {
    #[inline(always)]
    fn components(self) -> [i128; 4] {
        [self.0.widen(), self.1.widen(), self.2.widen(), self.3.widen()]
    }
}
