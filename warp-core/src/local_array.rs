//! Fixed-size local arrays (`[f32; 8]` in a kernel or func) and the lanes of vectors,
//! quaternions and matrices (`v[i]`, `m[(i, j)]`): what generated code calls to read and write
//! their elements at run-time indices, checked against the length. An index outside it is a
//! [`FaultKind::LocalIndex`] fault naming the function, the index, the length and the source
//! line (wp_core.h's `local_get`/`local_set`/`col_get`/`col_set` raise the same fault on a
//! GPU).
//!
//! A local array is a Rust array: a `Copy` value, whose adjoint (forward-mode tangent too) is
//! an array of the elements' adjoints ([`Adjoint`] below); a vector's adjoint is a vector, so
//! the adjoint of lane `i` is lane `i` of the adjoint ([`at_mut`]).

use crate::adjoint::Adjoint;
use crate::fault::{Fault, FaultKind, KResult};
use crate::index::IndexInt;
use crate::spatial::{DSpatialMatrix, DSpatialVector, SpatialMatrix, SpatialVector};
use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
    UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
};

#[cold]
#[inline(never)]
fn out_of_range(kernel: &'static str, index: i128, len: usize, line: u32) -> Box<Fault> {
    let index = i64::try_from(index).unwrap_or(if index < 0 { i64::MIN } else { i64::MAX });
    Fault::new(kernel, FaultKind::LocalIndex { index, len, line })
}

/// A value whose elements a kernel indexes at run time: a local array's elements, a vector's or
/// quaternion's lanes (glam's x, y, z, w order), a spatial vector's six lanes, a spatial
/// matrix's rows. glam's matrices are [`Columns`] instead, so that a single index of one
/// (whose meaning glam and Warp disagree on) does not compile.
pub trait Lanes: Copy {
    /// An element.
    type Lane: Copy;
    /// The elements, in index order.
    fn lanes(&self) -> &[Self::Lane];
    /// The elements, in index order, to write.
    fn lanes_mut(&mut self) -> &mut [Self::Lane];
}

impl<T: Copy, const N: usize> Lanes for [T; N] {
    type Lane = T;
    #[inline(always)]
    fn lanes(&self) -> &[T] {
        self
    }
    #[inline(always)]
    fn lanes_mut(&mut self) -> &mut [T] {
        self
    }
}

/// The lanes of a `Pod` value laid out as `[$s; $n]` (glam's vectors and quaternions, whose
/// memory is x, y, z, w; warp-core's spatial types).
macro_rules! pod_lanes {
    ($($t:ty => [$s:ty; $n:literal]),* $(,)?) => {$(
        impl Lanes for $t {
            type Lane = $s;
            #[inline(always)]
            fn lanes(&self) -> &[$s] {
                bytemuck::cast_ref::<$t, [$s; $n]>(self)
            }
            #[inline(always)]
            fn lanes_mut(&mut self) -> &mut [$s] {
                bytemuck::cast_mut::<$t, [$s; $n]>(self)
            }
        }
    )*};
}
pod_lanes!(
    Vec2 => [f32; 2], Vec3 => [f32; 3], Vec4 => [f32; 4],
    DVec2 => [f64; 2], DVec3 => [f64; 3], DVec4 => [f64; 4],
    IVec2 => [i32; 2], IVec3 => [i32; 3], IVec4 => [i32; 4],
    UVec2 => [u32; 2], UVec3 => [u32; 3], UVec4 => [u32; 4],
    Quat => [f32; 4], DQuat => [f64; 4],
    SpatialVector => [f32; 6], DSpatialVector => [f64; 6],
    SpatialMatrix => [SpatialVector; 6], DSpatialMatrix => [DSpatialVector; 6],
);

/// A glam matrix as its columns (its memory, column-major): a kernel's `m[(i, j)]` is lane `i`
/// of column `j`.
pub trait Columns: Copy {
    /// A column.
    type Col: Copy;
    /// The columns, in order.
    fn cols(&self) -> &[Self::Col];
    /// The columns, in order, to write.
    fn cols_mut(&mut self) -> &mut [Self::Col];
}

macro_rules! pod_columns {
    ($($t:ty => [$c:ty; $n:literal]),* $(,)?) => {$(
        impl Columns for $t {
            type Col = $c;
            #[inline(always)]
            fn cols(&self) -> &[$c] {
                bytemuck::cast_ref::<$t, [$c; $n]>(self)
            }
            #[inline(always)]
            fn cols_mut(&mut self) -> &mut [$c] {
                bytemuck::cast_mut::<$t, [$c; $n]>(self)
            }
        }
    )*};
}
pod_columns!(
    Mat2 => [Vec2; 2], Mat3 => [Vec3; 3], Mat4 => [Vec4; 4],
    DMat2 => [DVec2; 2], DMat3 => [DVec3; 3], DMat4 => [DVec4; 4],
);

/// `s[i]`, or a fault of `kernel` at `line` when `i` is outside the slice.
#[inline(always)]
fn get_in<T: Copy, I: IndexInt>(s: &[T], i: I, kernel: &'static str, line: u32) -> KResult<T> {
    match s.get(i.as_usize()) {
        Some(v) => Ok(*v),
        None => Err(out_of_range(kernel, i.widen(), s.len(), line)),
    }
}

/// `s[i] = v`, or a fault of `kernel` at `line` when `i` is outside the slice (nothing
/// written).
#[inline(always)]
fn set_in<T: Copy, I: IndexInt>(
    s: &mut [T],
    i: I,
    v: T,
    kernel: &'static str,
    line: u32,
) -> KResult<()> {
    let n = s.len();
    match s.get_mut(i.as_usize()) {
        Some(slot) => {
            *slot = v;
            Ok(())
        }
        None => Err(out_of_range(kernel, i.widen(), n, line)),
    }
}

/// Element 0 for an index outside the slice (see [`at_mut`]); the slice is never empty.
#[inline(always)]
fn at_in<T, I: IndexInt>(s: &mut [T], i: I) -> &mut T {
    let i = i.as_usize();
    let k = if i < s.len() { i } else { 0 };
    &mut s[k]
}

/// `a[i]`, or a fault of `kernel` at `line` when `i` is outside `0..len`.
#[inline(always)]
pub fn get<A: Lanes, I: IndexInt>(
    a: &A,
    i: I,
    kernel: &'static str,
    line: u32,
) -> KResult<A::Lane> {
    get_in(a.lanes(), i, kernel, line)
}

/// `a[i] = v`, or a fault of `kernel` at `line` when `i` is outside `0..len` (nothing
/// written).
#[inline(always)]
pub fn set<A: Lanes, I: IndexInt>(
    a: &mut A,
    i: I,
    v: A::Lane,
    kernel: &'static str,
    line: u32,
) -> KResult<()> {
    set_in(a.lanes_mut(), i, v, kernel, line)
}

/// The element of an adjoint at an index that the replay already checked (a reverse sweep
/// names an element only at an index its forward access used). Element 0 for any other index
/// (a warp-lang compiler bug), so the access stays in bounds without a panic; every [`Lanes`]
/// value has at least one element (the macro refuses empty local arrays).
#[inline(always)]
pub fn at_mut<A: Lanes, I: IndexInt>(a: &mut A, i: I) -> &mut A::Lane {
    at_in(a.lanes_mut(), i)
}

/// Column `j` of a glam matrix, or a fault of `kernel` at `line` when `j` is outside it.
#[inline(always)]
pub fn col_get<M: Columns, I: IndexInt>(
    m: &M,
    j: I,
    kernel: &'static str,
    line: u32,
) -> KResult<M::Col> {
    get_in(m.cols(), j, kernel, line)
}

/// Column `j` of a glam matrix set to `v`, or a fault of `kernel` at `line` when `j` is
/// outside it (nothing written).
#[inline(always)]
pub fn col_set<M: Columns, I: IndexInt>(
    m: &mut M,
    j: I,
    v: M::Col,
    kernel: &'static str,
    line: u32,
) -> KResult<()> {
    set_in(m.cols_mut(), j, v, kernel, line)
}

/// Column `j` of a matrix adjoint at a checked index ([`at_mut`]'s rule).
#[inline(always)]
pub fn col_at_mut<M: Columns, I: IndexInt>(m: &mut M, j: I) -> &mut M::Col {
    at_in(m.cols_mut(), j)
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
            "kernel `k`: index 3 is out of bounds for a local array or vector of length 3 (line 9)"
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

    #[test]
    fn lanes_follow_glam() {
        // Lanes in glam's order (x, y, z, w; a quaternion's scalar last), columns of a
        // column-major matrix; every access checked.
        let mut v = glam::Vec4::new(1.0, 2.0, 3.0, 4.0);
        assert_eq!(get(&v, 3i32, "k", 1).unwrap(), v.w);
        set(&mut v, 1u8, 9.0, "k", 1).unwrap();
        assert_eq!(v, glam::Vec4::new(1.0, 9.0, 3.0, 4.0));
        let f = get(&v, -1i64, "k", 5).unwrap_err();
        assert!(matches!(
            f.kind,
            FaultKind::LocalIndex {
                index: -1,
                len: 4,
                line: 5
            }
        ));
        let q = glam::DQuat::from_xyzw(0.5, 0.25, 0.125, 2.0);
        assert_eq!(get(&q, 3usize, "k", 1).unwrap(), q.w);
        let mut m = glam::Mat3::from_cols_array(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
        assert_eq!(col_get(&m, 1u32, "k", 1).unwrap(), m.y_axis);
        assert_eq!(col_get(&m, 2u32, "k", 1).unwrap()[0], m.col(2)[0]);
        col_set(&mut m, 0i32, glam::Vec3::ZERO, "k", 1).unwrap();
        assert_eq!(m.x_axis, glam::Vec3::ZERO);
        let f = col_set(&mut m, 3i32, glam::Vec3::ONE, "k", 2).unwrap_err();
        assert!(matches!(
            f.kind,
            FaultKind::LocalIndex {
                index: 3,
                len: 3,
                line: 2
            }
        ));
        assert_eq!(m.z_axis, glam::Vec3::new(7.0, 8.0, 9.0));
        *col_at_mut(&mut m, 5u8) = glam::Vec3::ONE;
        assert_eq!(m.x_axis, glam::Vec3::ONE);
        // A spatial matrix's elements are its rows.
        let sm = SpatialMatrix::IDENTITY;
        assert_eq!(
            get(&get(&sm, 2u8, "k", 1).unwrap(), 2u8, "k", 1).unwrap(),
            1.0
        );
        let mut sv = SpatialVector::ZERO;
        set(&mut sv, 5i32, 3.0, "k", 1).unwrap();
        assert_eq!(sv[5], 3.0);
        assert!(set(&mut sv, 6i32, 3.0, "k", 1).is_err());
    }
}
