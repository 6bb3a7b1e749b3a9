//! The element types of the primitives and what the backends share: the traits that say
//! which types each primitive takes and how a backend computes with them, and the length of
//! a call (`Extent`).
//!
//! A leaf: it imports nothing of the runtime above `error`, so that the backends (`cpu/`,
//! `cuda/`) can use it without importing `array` (the seam's one-way layering).

use crate::error::Error;

mod sealed {
    pub trait Sealed {}
}

/// What the backends compute with for a scan or reduction element (see [`ScanElement`](super::ScanElement)).
#[doc(hidden)]
pub trait ScanOps: bytemuck::Pod + Send + Sync + sealed::Sealed {
    /// The type's name in the CUDA library (`wp::i32`, ...).
    #[doc(hidden)]
    const CUDA: &'static str;
    /// 0.
    #[doc(hidden)]
    const ZERO: Self;
    /// The identity of `min`: the largest value (+inf for floats).
    #[doc(hidden)]
    const MIN_IDENTITY: Self;
    /// The identity of `max`: the smallest value (-inf for floats).
    #[doc(hidden)]
    const MAX_IDENTITY: Self;
    /// `self + other`, wrapping for integers.
    #[doc(hidden)]
    fn add(self, other: Self) -> Self;
    /// The smaller of the two; NaN loses (the GPU's `op_min`).
    #[doc(hidden)]
    fn min_of(self, other: Self) -> Self;
    /// The larger of the two; NaN loses (the GPU's `op_max`).
    #[doc(hidden)]
    fn max_of(self, other: Self) -> Self;
}

macro_rules! scan_ints {
    ($($t:ident),*) => {$(
        impl sealed::Sealed for $t {}
        impl ScanOps for $t {
            const CUDA: &'static str = stringify!($t);
            const ZERO: Self = 0;
            const MIN_IDENTITY: Self = $t::MAX;
            const MAX_IDENTITY: Self = $t::MIN;
            #[inline(always)]
            fn add(self, other: Self) -> Self {
                self.wrapping_add(other)
            }
            #[inline(always)]
            fn min_of(self, other: Self) -> Self {
                if other < self { other } else { self }
            }
            #[inline(always)]
            fn max_of(self, other: Self) -> Self {
                if other > self { other } else { self }
            }
        }
    )*};
}
scan_ints!(i32, u32, i64, u64);

macro_rules! scan_floats {
    ($($t:ident),*) => {$(
        impl sealed::Sealed for $t {}
        impl ScanOps for $t {
            const CUDA: &'static str = stringify!($t);
            const ZERO: Self = 0.0;
            const MIN_IDENTITY: Self = $t::INFINITY;
            const MAX_IDENTITY: Self = $t::NEG_INFINITY;
            #[inline(always)]
            fn add(self, other: Self) -> Self {
                self + other
            }
            // The same expressions as `op_min`/`op_max` in wp_primitives.h, so that both
            // backends treat NaN and signed zeros alike element by element.
            #[inline(always)]
            fn min_of(self, other: Self) -> Self {
                if other < self || self.is_nan() { other } else { self }
            }
            #[inline(always)]
            fn max_of(self, other: Self) -> Self {
                if other > self || self.is_nan() { other } else { self }
            }
        }
    )*};
}
scan_floats!(f32, f64);

/// What the backends sort by (see [`SortKey`](super::SortKey)).
#[doc(hidden)]
pub trait SortKeyOps: bytemuck::Pod + Send + Sync + sealed::Sealed {
    /// The type's name in the CUDA library.
    #[doc(hidden)]
    const CUDA: &'static str;
    /// Whether a sort may use fewer than 32 key bits (not for floats, whose low bits alone
    /// have no order).
    #[doc(hidden)]
    const PARTIAL_BITS: bool;
    /// The order-preserving unsigned image (`radix_key` in wp_primitives.h).
    #[doc(hidden)]
    fn to_radix(self) -> u32;
    /// The key back from its image.
    #[doc(hidden)]
    fn from_radix(bits: u32) -> Self;
}

impl SortKeyOps for u32 {
    const CUDA: &'static str = "u32";
    const PARTIAL_BITS: bool = true;
    #[inline(always)]
    fn to_radix(self) -> u32 {
        self
    }
    #[inline(always)]
    fn from_radix(bits: u32) -> Self {
        bits
    }
}

impl SortKeyOps for i32 {
    const CUDA: &'static str = "i32";
    const PARTIAL_BITS: bool = true;
    #[inline(always)]
    fn to_radix(self) -> u32 {
        (self as u32) ^ 0x8000_0000
    }
    #[inline(always)]
    fn from_radix(bits: u32) -> Self {
        (bits ^ 0x8000_0000) as i32
    }
}

impl SortKeyOps for f32 {
    const CUDA: &'static str = "f32";
    const PARTIAL_BITS: bool = false;
    #[inline(always)]
    fn to_radix(self) -> u32 {
        let b = self.to_bits();
        if b & 0x8000_0000 != 0 {
            !b
        } else {
            b | 0x8000_0000
        }
    }
    #[inline(always)]
    fn from_radix(bits: u32) -> Self {
        f32::from_bits(if bits & 0x8000_0000 != 0 {
            bits & 0x7fff_ffff
        } else {
            !bits
        })
    }
}

/// A 32-bit value the backends move with its key (see [`SortValue`](super::SortValue)).
#[doc(hidden)]
pub trait SortValueOps: bytemuck::Pod + Send + Sync + sealed::Sealed {}
impl SortValueOps for u32 {}
impl SortValueOps for i32 {}
impl SortValueOps for f32 {}

/// The length of a primitive call, as the backends receive it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Extent {
    /// Exactly this many elements.
    Host(usize),
    /// As many as the `i32` at address `count` (a 1-element array on the backend's device)
    /// says, which must lie in `0..=capacity`; `limit` names the array that sets the capacity
    /// (for the message of a bad count).
    Device {
        count: u64,
        capacity: usize,
        limit: &'static str,
    },
}

/// The error of a device count outside `0..=capacity`, where a backend can report one before
/// anything is written (the CPU; a GPU records a fault instead).
#[cold]
pub(crate) fn bad_count(func: &str, count: i32, capacity: usize, limit: &str) -> Error {
    Error::invalid(format!(
        "{func}: the `count` array holds {count}, outside 0..={capacity} (`{limit}` has \
         {capacity} elements)"
    ))
}
