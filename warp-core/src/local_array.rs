//! Fixed-size local arrays (`[f32; 8]` in a kernel or func): what generated code calls to read
//! and write their elements at dynamic indices, checked against the length. An index outside
//! it is a [`FaultKind::LocalIndex`] fault naming the function, the index, the length and the
//! source line (wp_core.h's `local_get`/`local_set` raise the same fault on a GPU).
//!
//! A local array is a Rust array: a `Copy` value, whose adjoint (forward-mode tangent too) is
//! an array of the elements' adjoints ([`Adjoint`] below).

use crate::adjoint::Adjoint;
use crate::fault::{Fault, FaultKind, KResult};
use crate::index::IndexInt;

#[cold]
#[inline(never)]
fn out_of_range(kernel: &'static str, index: i128, len: usize, line: u32) -> Box<Fault> {
    let index = i64::try_from(index).unwrap_or(if index < 0 { i64::MIN } else { i64::MAX });
    Fault::new(kernel, FaultKind::LocalIndex { index, len, line })
}

/// `a[i]`, or a fault of `kernel` at `line` when `i` is outside `0..N`.
#[inline(always)]
pub fn get<T: Copy, const N: usize, I: IndexInt>(
    a: &[T; N],
    i: I,
    kernel: &'static str,
    line: u32,
) -> KResult<T> {
    match a.get(i.as_usize()) {
        Some(v) => Ok(*v),
        None => Err(out_of_range(kernel, i.widen(), N, line)),
    }
}

/// `a[i] = v`, or a fault of `kernel` at `line` when `i` is outside `0..N` (nothing written).
#[inline(always)]
pub fn set<T: Copy, const N: usize, I: IndexInt>(
    a: &mut [T; N],
    i: I,
    v: T,
    kernel: &'static str,
    line: u32,
) -> KResult<()> {
    match a.get_mut(i.as_usize()) {
        Some(slot) => {
            *slot = v;
            Ok(())
        }
        None => Err(out_of_range(kernel, i.widen(), N, line)),
    }
}

/// The element of an adjoint at an index that the replay already checked (a reverse sweep
/// names an element only at an index its forward access used). Element 0 for any other index
/// (a warp-lang compiler bug), so the access stays in bounds without a panic; `N` is at least
/// 1 (the macro refuses empty local arrays).
#[inline(always)]
pub fn at_mut<T, const N: usize, I: IndexInt>(a: &mut [T; N], i: I) -> &mut T {
    let i = i.as_usize();
    &mut a[if i < N { i } else { 0 }]
}

/// The sum of the elements, from zero in index order (the adjoint of a repeat `[v; N]`).
pub fn sum<T: Adjoint, const N: usize>(a: &[T; N]) -> T {
    let mut s = T::adj_zero();
    for v in a {
        s.adj_accum(*v);
    }
    s
}

/// A local array's adjoint: the elements' adjoints, accumulated element by element.
impl<T: Adjoint, const N: usize> Adjoint for [T; N] {
    #[inline(always)]
    fn adj_zero() -> Self {
        [T::adj_zero(); N]
    }
    #[inline(always)]
    fn adj_accum(&mut self, v: Self) {
        for (a, v) in self.iter_mut().zip(v) {
            a.adj_accum(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_and_writes_are_checked() {
        let mut a = [1.0f32, 2.0, 3.0];
        assert_eq!(get(&a, 2u32, "k", 7).unwrap(), 3.0);
        set(&mut a, 0i64, 5.0, "k", 8).unwrap();
        assert_eq!(a, [5.0, 2.0, 3.0]);
        let f = get(&a, 3usize, "k", 9).unwrap_err();
        assert_eq!(
            f.kind,
            FaultKind::LocalIndex {
                index: 3,
                len: 3,
                line: 9
            }
        );
        assert_eq!(
            f.to_string(),
            "kernel `k`: index 3 is out of bounds for a local array of length 3 (line 9)"
        );
        // A negative index is shown as given, and nothing is written.
        let f = set(&mut a, -1i32, 0.0, "k", 4).unwrap_err();
        assert!(matches!(
            f.kind,
            FaultKind::LocalIndex {
                index: -1,
                len: 3,
                line: 4
            }
        ));
        assert_eq!(a, [5.0, 2.0, 3.0]);
    }

    #[test]
    fn adjoints_are_elementwise() {
        let mut g: [glam::Vec2; 2] = Adjoint::adj_zero();
        g.adj_accum([glam::Vec2::ONE, glam::Vec2::X]);
        g.adj_accum([glam::Vec2::Y, glam::Vec2::X]);
        assert_eq!(g, [glam::Vec2::new(1.0, 2.0), glam::Vec2::new(2.0, 0.0)]);
        assert_eq!(sum(&[1.0f64, 2.0, 4.0]), 7.0);
        // Integer elements have no adjoint.
        assert_eq!(sum(&[1i32, 2]), 0);
        *at_mut(&mut g, 1u8) = glam::Vec2::ZERO;
        *at_mut(&mut g, 7u8) += glam::Vec2::ONE;
        assert_eq!(g, [glam::Vec2::new(2.0, 3.0), glam::Vec2::ZERO]);
    }
}
