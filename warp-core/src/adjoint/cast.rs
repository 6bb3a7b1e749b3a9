//! Adjoints of `as` casts between scalars.

use super::Adjoint;

/// Adjoint of `x as To`, implemented on `x`'s type for every pair of the 13 scalar types
/// (`bool`, the integers, `f32`, `f64`).
pub trait AdjCast<To>: Adjoint {
    /// Accumulates into `adj_from` the contribution of `x as To` given the adjoint `adj_to` of
    /// its result (see [`adj_cast`]).
    fn adj_cast(adj_from: &mut Self, adj_to: To);
}

/// Adjoint of `x as To`: between `f32` and `f64` (either way, or to the same type),
/// `adj_from += adj_to as From`; a no-op whenever `From` or `To` is an integer or `bool`
/// (the cast, or the value cast, is not differentiable).
#[inline(always)]
pub fn adj_cast<From: AdjCast<To>, To>(adj_from: &mut From, adj_to: To) {
    From::adj_cast(adj_from, adj_to)
}

macro_rules! float_cast {
    ($($f:ident => $t:ident),*) => {$(
        impl AdjCast<$t> for $f {
            #[inline(always)]
            fn adj_cast(adj_from: &mut $f, adj_to: $t) {
                *adj_from += adj_to as $f;
            }
        }
    )*};
}
float_cast!(f32 => f32, f32 => f64, f64 => f32, f64 => f64);

macro_rules! noop_cast {
    (@row $f:ty; [$($t:ty),*]) => {$(
        impl AdjCast<$t> for $f {
            #[inline(always)]
            fn adj_cast(_adj_from: &mut $f, _adj_to: $t) {}
        }
    )*};
    ($to:tt <- $($f:ty),*) => {$(
        noop_cast!(@row $f; $to);
    )*};
}
// Integer or bool to anything.
noop_cast!(
    [bool, i8, i16, i32, i64, isize, u8, u16, u32, u64, usize, f32, f64]
    <- bool, i8, i16, i32, i64, isize, u8, u16, u32, u64, usize
);
// Float to integer or bool.
noop_cast!([bool, i8, i16, i32, i64, isize, u8, u16, u32, u64, usize] <- f32, f64);
