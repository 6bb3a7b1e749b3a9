//! Tiles on the CPU: block-wide values that generated code of tiled kernels computes with.
//!
//! A tile is a plain value, `Tile1<T, N0>` (`[T; N0]`) or `Tile2<T, N0, N1>` (`[[T; N1]; N0]`,
//! row-major), `Copy` where `T` is. Its shape is part of its type, so an operation on tiles of
//! mismatched shapes does not compile (see `docs/design/tiles.md`, §2.1, layer 3). Ranks 3 and 4
//! (`Tile3`, `Tile4`) will follow the same pattern: a nested array and an impl of [`Tile`].
//!
//! On the GPU a block's lanes hold the tile together; here the block is one task that computes
//! the whole value, and the operations whose result depends on how lanes share the work
//! (reductions) take the block size `bd` and reproduce the GPU's order exactly (see the docs
//! of the [`reduce`](mod@reduce) module). Elementwise operations and the FMA matmul
//! ([`matmul`](mod@matmul)) do not depend on `bd`.
//!
//! Files by concept: this module holds the types, their constructors and element access;
//! [`ops`] the elementwise operators and `map`; [`load`] loads and stores against array views;
//! [`reduce`](mod@reduce) the reductions in the GPU's order; [`matmul`](mod@matmul) the FMA
//! matrix product; [`shape`] transposes and broadcasts; [`scan`](mod@scan) the scans in a shared order; [`sort`](mod@sort) the sort's permutation; [`convert`] reshapes and `tile_diag_add`; [`atomic`] the atomic add of a tile; [`linalg`] the Cholesky factor and the triangular solves, in the GPU's order; [`fft`](mod@fft) the FFTs of tiles of complex values (`Vec2`, `DVec2`). [`view`] the windows: `tile_view` and `tile_assign` with the in-place forms. The per-lane side (`tile(x)`, `untile`) is in [`crate::block`].
//!
//! Nothing here allocates or panics on a kernel's data: an index outside a tile is a
//! [`FaultKind::TileIndex`] fault, and an array coordinate outside the array is a zero read or
//! a skipped store (Warp's `bounds_check=True`, extended to negative coordinates).

use bytemuck::Zeroable;

use crate::builtins::Scalar;
use crate::fault::{Fault, FaultKind, KResult};
use crate::index::IndexInt;
use crate::ops::FromLiteral;

pub mod adjoint;
mod adjoint_linalg;
pub mod atomic;
pub mod convert;
pub mod fft;
pub mod linalg;
pub mod load;
pub mod matmul;
pub mod ops;
pub mod reduce;
pub mod scan;
pub mod shape;
pub mod sort;
pub mod view;

pub use atomic::{atomic_add1, atomic_add2};
pub use convert::{diag_add, reshape11, reshape12, reshape21, reshape22};
pub use fft::{fft, ifft};
pub use linalg::{
    cholesky, cholesky_solve1, cholesky_solve2, lower_solve1, lower_solve2, upper_solve1,
    upper_solve2,
};
pub use load::{load1, load2, store1, store2};
pub use matmul::{matmul, matmul_acc, Fma, MatmulElem};
pub use reduce::{argmax, argmin, max, min, reduce, sum};
pub use scan::{scan_exclusive, scan_inclusive, scan_max_inclusive, scan_min_inclusive};
pub use shape::{broadcast11, broadcast12, broadcast22, transpose};
pub use sort::{permute, sort_perm, SortKey};
pub use view::{view11, view21, view22, window1, window2};

/// Implemented by each `#[func]` whose parameters and result are scalars (not `bool`): the
/// func takes the elements `Args` (a tuple, one per parameter) and returns `Ret`. The kernel
/// macro cannot see a func's signature, so `tile_map(func, ..)` calls the func through this
/// trait, with the elements it chose: a func that does not fit is one error at the func's path
/// (this message), not a type error in generated code.
#[diagnostic::on_unimplemented(
    message = "`tile_map` cannot apply `{Self}` to elements `{Args}` giving `{Ret}`",
    label = "not a #[func] taking `{Args}` and returning `{Ret}`",
    note = "`tile_map(f, a..)` takes a #[func] of scalars with one parameter per tile, of the tiles' element types",
    note = "a func returning another type than the first tile's element names it: `let r: Tile<i32, 8> = tile_map(f, a);` or `tile_map::<i32>(f, a)`"
)]
pub trait TileMapFn<Args, Ret> {
    /// The func's CPU code on one set of elements.
    fn call(args: Args) -> KResult<Ret>;
    /// Its replay (an adjoint's forward pass: no prints).
    fn replay(args: Args) -> KResult<Ret>;
    /// Its adjoint at `args` with seed `adj_ret`, accumulating into `adj_args`, on `stack`.
    fn adj(
        args: Args,
        adj_args: &mut Args,
        adj_ret: Ret,
        stack: &mut crate::grad::AdStack,
    ) -> KResult<()>;
}

/// A rank-1 tile of `N0` elements.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tile1<T, const N0: usize> {
    /// The elements.
    pub data: [T; N0],
}

/// A rank-2 tile of `N0` rows and `N1` columns, stored row-major.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tile2<T, const N0: usize, const N1: usize> {
    /// The rows.
    pub data: [[T; N1]; N0],
}

/// What every tile type shares: its element type, shape, and its elements in row-major order.
///
/// The reductions are written once over this trait.
pub trait Tile {
    /// The element type.
    type Elem;
    /// The number of dimensions, 1..=4.
    const RANK: usize;
    /// The shape; entries past [`Tile::RANK`] are 1.
    const SHAPE: [usize; 4];
    /// The number of elements (the product of the shape).
    const SIZE: usize;
    /// The elements in row-major order (the flattening the reductions' order is defined on).
    fn as_flat(&self) -> &[Self::Elem];
    /// The elements in row-major order, mutable.
    fn as_flat_mut(&mut self) -> &mut [Self::Elem];
}

impl<T, const N0: usize> Tile for Tile1<T, N0> {
    type Elem = T;
    const RANK: usize = 1;
    const SHAPE: [usize; 4] = [N0, 1, 1, 1];
    const SIZE: usize = N0;
    #[inline(always)]
    fn as_flat(&self) -> &[T] {
        &self.data
    }
    #[inline(always)]
    fn as_flat_mut(&mut self) -> &mut [T] {
        &mut self.data
    }
}

impl<T, const N0: usize, const N1: usize> Tile for Tile2<T, N0, N1> {
    type Elem = T;
    const RANK: usize = 2;
    const SHAPE: [usize; 4] = [N0, N1, 1, 1];
    const SIZE: usize = N0 * N1;
    #[inline(always)]
    fn as_flat(&self) -> &[T] {
        self.data.as_flattened()
    }
    #[inline(always)]
    fn as_flat_mut(&mut self) -> &mut [T] {
        self.data.as_flattened_mut()
    }
}

/// The fault of an index outside a tile.
#[cold]
#[inline(never)]
fn index_fault<T, X: Tile>(kernel: &'static str, index: [i128; 4]) -> KResult<T> {
    Err(Fault::new(
        kernel,
        FaultKind::TileIndex {
            index: index.map(|i| i.clamp(i64::MIN.into(), i64::MAX.into()) as i64),
            shape: X::SHAPE.map(|n| u32::try_from(n).unwrap_or(u32::MAX)),
            rank: X::RANK as u8,
        },
    ))
}

/// `i` as an index below `n`, or `None` (negative values are out of range too).
#[inline(always)]
fn in_range<I: IndexInt>(i: I, n: usize) -> Option<usize> {
    let w = i.widen();
    if w >= 0 && w < n as i128 {
        Some(w as usize)
    } else {
        None
    }
}

impl<T: Copy, const N0: usize> Tile1<T, N0> {
    /// A tile with every element `v`.
    #[inline(always)]
    pub fn splat(v: T) -> Self {
        Tile1 { data: [v; N0] }
    }

    /// Element `i` (`t[i]`, Warp's `tile_extract`); an index outside `0..N0` is a
    /// [`FaultKind::TileIndex`] fault of `kernel`.
    #[inline(always)]
    pub fn extract<I: IndexInt>(&self, i: I, kernel: &'static str) -> KResult<T> {
        match in_range(i, N0) {
            Some(i) => Ok(self.data[i]),
            None => index_fault::<T, Self>(kernel, [i.widen(), 0, 0, 0]),
        }
    }
}

impl<T: Copy + Zeroable, const N0: usize> Tile1<T, N0> {
    /// The tile of zeros (`tile_zeros`): every element all bits zero, which is `0` for the
    /// scalars and the zero vector for the vector elements (`Vec2`, `DVec2`).
    #[inline(always)]
    pub fn zeros() -> Self {
        Self::splat(T::zeroed())
    }
}

impl<T: Scalar, const N0: usize> Tile1<T, N0> {
    /// The tile of ones (`tile_ones`).
    #[inline(always)]
    pub fn ones() -> Self {
        Self::splat(T::ONE)
    }
}

impl<T: Scalar + FromLiteral, const N0: usize> Tile1<T, N0> {
    /// Evenly spaced values (`tile_arange`): element `i` is `start + T(i) * step`, computed as
    /// Warp's `tile.h` does (`start + linear * step`: one multiplication, then one addition,
    /// each rounded; no accumulation, no fused multiply-add). Integer arithmetic wraps.
    ///
    /// Warp's `tile_arange(start, stop, step)` derives the length from `stop`; here the length
    /// is the type's `N0`, which the front end computes from literal or const bounds.
    #[inline(always)]
    pub fn arange(start: T, step: T) -> Self {
        Tile1 {
            data: std::array::from_fn(|i| start.s_add(T::from_i64(i as i64).s_mul(step))),
        }
    }
}

impl<T: Copy, const N0: usize, const N1: usize> Tile2<T, N0, N1> {
    /// A tile with every element `v`.
    #[inline(always)]
    pub fn splat(v: T) -> Self {
        Tile2 {
            data: [[v; N1]; N0],
        }
    }

    /// Element `(i, j)` (`t[(i, j)]`, Warp's `tile_extract`); an index outside the shape on
    /// either axis is a [`FaultKind::TileIndex`] fault of `kernel`.
    #[inline(always)]
    pub fn extract<I: IndexInt, J: IndexInt>(
        &self,
        i: I,
        j: J,
        kernel: &'static str,
    ) -> KResult<T> {
        match (in_range(i, N0), in_range(j, N1)) {
            (Some(i), Some(j)) => Ok(self.data[i][j]),
            _ => index_fault::<T, Self>(kernel, [i.widen(), j.widen(), 0, 0]),
        }
    }
}

impl<T: Copy + Zeroable, const N0: usize, const N1: usize> Tile2<T, N0, N1> {
    /// The tile of zeros (`tile_zeros`): every element all bits zero, which is `0` for the
    /// scalars and the zero vector for the vector elements (`Vec2`, `DVec2`).
    #[inline(always)]
    pub fn zeros() -> Self {
        Self::splat(T::zeroed())
    }
}

impl<T: Scalar, const N0: usize, const N1: usize> Tile2<T, N0, N1> {
    /// The tile of ones (`tile_ones`).
    #[inline(always)]
    pub fn ones() -> Self {
        Self::splat(T::ONE)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constructors_and_extract() {
        let z = Tile2::<f32, 2, 3>::zeros();
        assert_eq!(z.data, [[0.0; 3]; 2]);
        let o = Tile1::<i32, 4>::ones();
        assert_eq!(o.data, [1; 4]);
        let a = Tile1::<f32, 5>::arange(1.0, 0.5);
        assert_eq!(a.data, [1.0, 1.5, 2.0, 2.5, 3.0]);
        let ai = Tile1::<i32, 3>::arange(10, -4);
        assert_eq!(ai.data, [10, 6, 2]);
        // Wrapping, as CUDA's integers do.
        let w = Tile1::<u8, 3>::arange(250, 3);
        assert_eq!(w.data, [250, 253, 0]);
        assert_eq!(a.extract(4usize, "k").unwrap(), 3.0);
        let t = Tile2::<i32, 2, 3> {
            data: [[1, 2, 3], [4, 5, 6]],
        };
        assert_eq!(t.extract(1, 2, "k").unwrap(), 6);
        assert_eq!(t.as_flat(), &[1, 2, 3, 4, 5, 6]);
        let t2 = t; // Copy
        assert_eq!(t2, t);
    }

    #[test]
    fn arange_is_start_plus_index_times_step() {
        // 0.1 is not exact: element i is 0.1 + (i * 0.1), each rounded once, which differs
        // from accumulating the step.
        let a = Tile1::<f32, 64>::arange(0.1, 0.1);
        let mut acc = 0.1f32;
        let mut differs = false;
        for (i, &v) in a.data.iter().enumerate() {
            assert_eq!(v.to_bits(), (0.1f32 + (i as f32) * 0.1f32).to_bits());
            differs |= v != acc;
            acc += 0.1;
        }
        assert!(differs);
    }

    #[test]
    fn extract_out_of_range_faults() {
        let a = Tile1::<f32, 4>::zeros();
        for bad in [4i64, -1, i64::MAX, i64::MIN] {
            let e = a.extract(bad, "kern").unwrap_err();
            assert_eq!(e.kernel, "kern");
            assert_eq!(
                e.kind,
                FaultKind::TileIndex {
                    index: [bad, 0, 0, 0],
                    shape: [4, 1, 1, 1],
                    rank: 1
                }
            );
        }
        let t = Tile2::<f32, 2, 3>::zeros();
        let e = t.extract(1, 3u32, "kern").unwrap_err();
        assert_eq!(
            e.to_string(),
            "kernel `kern`: index [1, 3] is out of bounds for a tile of shape [2, 3]"
        );
        assert!(t.extract(-1, 0, "kern").is_err());
        assert!(t.extract(2usize, 0usize, "kern").is_err());
    }
}
