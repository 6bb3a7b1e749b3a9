//! Tiles on the CPU: block-wide values that generated code of tiled kernels computes with.
//!
//! A tile is a plain value, `Tile1<T, N0>` (`[T; N0]`) or `Tile2<T, N0, N1>` (`[[T; N1]; N0]`,
//! row-major), `Copy` where `T` is; `Tile3<T, N0, N1, N2>` and `Tile4<T, N0, N1, N2, N3>` are the
//! same pattern one and two levels deeper. Its shape is part of its type, so an operation on
//! tiles of mismatched shapes does not compile (see `docs/design/tiles.md`, §2.1, layer 3).
//! Ranks 3 and 4 have the rank-generic operations (constructors, element access, loads and
//! stores, elementwise operators and maps, reductions, reshapes, atomic adds); the operations
//! that are matrix algebra (matmul, transpose, linear algebra, FFTs, views) stay rank 1-2.
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

pub use atomic::{atomic_add1, atomic_add2, atomic_add3, atomic_add4};
pub use convert::{diag_add, reshape, reshape11, reshape12, reshape21, reshape22};
pub use fft::{fft, ifft};
pub use linalg::{
    cholesky, cholesky_solve1, cholesky_solve2, lower_solve1, lower_solve2, upper_solve1,
    upper_solve2,
};
pub use load::{load1, load2, load3, load4, store1, store2, store3, store4};
pub use matmul::{matmul, matmul_acc, Fma, MatmulElem};
pub use reduce::{argmax, argmin, max, min, reduce, sum, try_reduce};
pub use scan::{scan_exclusive, scan_inclusive, scan_max_inclusive, scan_min_inclusive};
pub use shape::{broadcast11, broadcast12, broadcast22, transpose};
pub use sort::{permute, sort_perm, SortKey};
pub use view::{view11, view21, view22, window1, window2};

/// Implemented by each `#[func]` whose parameters and result are scalars (not `bool`): the
/// func takes the elements `Args` (a tuple, one per parameter) and returns `Ret`. The kernel
/// macro cannot see a func's signature, so `tile_map(func, ..)` and `tile_reduce(func, t)` call
/// the func through this trait, with the elements it chose: a func that does not fit is one
/// error at the func's path (this message), not a type error in generated code.
#[diagnostic::on_unimplemented(
    message = "`tile_map` / `tile_reduce` cannot apply `{Self}` to elements `{Args}` giving `{Ret}`",
    label = "not a #[func] taking `{Args}` and returning `{Ret}`",
    note = "`tile_map(f, a..)` takes a #[func] of scalars with one parameter per tile, of the tiles' element types",
    note = "`tile_reduce(f, t)` takes a #[func] of two elements of `t`'s type returning that type",
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

/// A rank-3 tile of shape `(N0, N1, N2)`, stored row-major (the last axis fastest).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tile3<T, const N0: usize, const N1: usize, const N2: usize> {
    /// The elements, `data[i][j][k]`.
    pub data: [[[T; N2]; N1]; N0],
}

/// A rank-4 tile of shape `(N0, N1, N2, N3)`, stored row-major (the last axis fastest).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tile4<T, const N0: usize, const N1: usize, const N2: usize, const N3: usize> {
    /// The elements, `data[i][j][k][l]`.
    pub data: [[[[T; N3]; N2]; N1]; N0],
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

impl<T, const N0: usize, const N1: usize, const N2: usize> Tile for Tile3<T, N0, N1, N2> {
    type Elem = T;
    const RANK: usize = 3;
    const SHAPE: [usize; 4] = [N0, N1, N2, 1];
    const SIZE: usize = N0 * N1 * N2;
    #[inline(always)]
    fn as_flat(&self) -> &[T] {
        self.data.as_flattened().as_flattened()
    }
    #[inline(always)]
    fn as_flat_mut(&mut self) -> &mut [T] {
        self.data.as_flattened_mut().as_flattened_mut()
    }
}

impl<T, const N0: usize, const N1: usize, const N2: usize, const N3: usize> Tile
    for Tile4<T, N0, N1, N2, N3>
{
    type Elem = T;
    const RANK: usize = 4;
    const SHAPE: [usize; 4] = [N0, N1, N2, N3];
    const SIZE: usize = N0 * N1 * N2 * N3;
    #[inline(always)]
    fn as_flat(&self) -> &[T] {
        self.data.as_flattened().as_flattened().as_flattened()
    }
    #[inline(always)]
    fn as_flat_mut(&mut self) -> &mut [T] {
        self.data
            .as_flattened_mut()
            .as_flattened_mut()
            .as_flattened_mut()
    }
}

/// A tile type that can be built element by element in row-major order: what the
/// rank-generic operations (the N-D loads, the reshape between any two ranks) construct their
/// results with, since [`Tile`] itself only reads and writes an existing tile.
pub trait TileFromFn: Tile + Sized {
    /// The tile whose row-major element `k` is `f(k)`, for `k` in `0..SIZE` ascending.
    fn from_flat_fn(f: impl FnMut(usize) -> Self::Elem) -> Self;
}

impl<T, const N0: usize> TileFromFn for Tile1<T, N0> {
    #[inline(always)]
    fn from_flat_fn(f: impl FnMut(usize) -> T) -> Self {
        Tile1 {
            data: std::array::from_fn(f),
        }
    }
}

impl<T, const N0: usize, const N1: usize> TileFromFn for Tile2<T, N0, N1> {
    #[inline(always)]
    fn from_flat_fn(mut f: impl FnMut(usize) -> T) -> Self {
        Tile2 {
            data: std::array::from_fn(|i| std::array::from_fn(|j| f(i * N1 + j))),
        }
    }
}

impl<T, const N0: usize, const N1: usize, const N2: usize> TileFromFn for Tile3<T, N0, N1, N2> {
    #[inline(always)]
    fn from_flat_fn(mut f: impl FnMut(usize) -> T) -> Self {
        // `array::from_fn` fills in index order, so the calls of `f` are row-major.
        Tile3 {
            data: std::array::from_fn(|i| {
                std::array::from_fn(|j| std::array::from_fn(|k| f((i * N1 + j) * N2 + k)))
            }),
        }
    }
}

impl<T, const N0: usize, const N1: usize, const N2: usize, const N3: usize> TileFromFn
    for Tile4<T, N0, N1, N2, N3>
{
    #[inline(always)]
    fn from_flat_fn(mut f: impl FnMut(usize) -> T) -> Self {
        Tile4 {
            data: std::array::from_fn(|i| {
                std::array::from_fn(|j| {
                    std::array::from_fn(|k| {
                        std::array::from_fn(|l| f(((i * N1 + j) * N2 + k) * N3 + l))
                    })
                })
            }),
        }
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

/// The constructors and element access of the rank-3 and rank-4 tiles, one impl block per
/// rank (the same methods as `Tile1`'s and `Tile2`'s, written over [`TileFromFn`]).
macro_rules! nd_tile_basics {
    ($tile:ident < $($n:ident),+ >, $($i:ident : $ti:ident),+) => {
        impl<T: Copy, $(const $n: usize),+> $tile<T, $($n),+> {
            /// A tile with every element `v`.
            #[inline(always)]
            pub fn splat(v: T) -> Self {
                <Self as TileFromFn>::from_flat_fn(|_| v)
            }

            /// The element at the given index (`t[(i, j, ..)]`, Warp's `tile_extract`); an
            /// index outside the shape on any axis is a [`FaultKind::TileIndex`] fault of
            /// `kernel`.
            #[inline(always)]
            pub fn extract<$($ti: IndexInt),+>(&self, $($i: $ti,)+ kernel: &'static str) -> KResult<T> {
                let ns = [$($n),+];
                let wide = [$($i.widen()),+];
                let mut flat = 0usize;
                for (&w, &n) in wide.iter().zip(&ns) {
                    if w < 0 || w >= n as i128 {
                        let mut index = [0i128; 4];
                        index[..ns.len()].copy_from_slice(&wide);
                        return index_fault::<T, Self>(kernel, index);
                    }
                    flat = flat * n + w as usize;
                }
                Ok(self.as_flat()[flat])
            }
        }

        impl<T: Copy + Zeroable, $(const $n: usize),+> $tile<T, $($n),+> {
            /// The tile of zeros (`tile_zeros`): every element all bits zero.
            #[inline(always)]
            pub fn zeros() -> Self {
                Self::splat(T::zeroed())
            }
        }

        impl<T: Scalar, $(const $n: usize),+> $tile<T, $($n),+> {
            /// The tile of ones (`tile_ones`).
            #[inline(always)]
            pub fn ones() -> Self {
                Self::splat(T::ONE)
            }
        }
    };
}

nd_tile_basics!(Tile3<N0, N1, N2>, i: I, j: J, k: K);
nd_tile_basics!(Tile4<N0, N1, N2, N3>, i: I, j: J, k: K, l: L);

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

    #[test]
    fn rank3_and_rank4_layout_and_extract() {
        // Row-major: element (i, j, k) of a (2, 3, 4) tile is flat element (i * 3 + j) * 4 + k.
        let t = Tile3::<i32, 2, 3, 4>::from_flat_fn(|f| f as i32);
        assert_eq!(t.data[1][2][3], 23);
        assert_eq!(t.as_flat().len(), 24);
        assert_eq!(t.extract(1, 0, 2u8, "k").unwrap(), 14);
        let e = t.extract(0, 3, 0, "kern").unwrap_err();
        assert_eq!(
            e.kind,
            FaultKind::TileIndex {
                index: [0, 3, 0, 0],
                shape: [2, 3, 4, 1],
                rank: 3
            }
        );
        assert!(t.extract(-1, 0, 0, "kern").is_err());
        let q = Tile4::<i32, 2, 1, 3, 2>::from_flat_fn(|f| f as i32);
        assert_eq!(q.extract(1, 0, 2, 1, "k").unwrap(), 11);
        assert_eq!(<Tile4<i32, 2, 1, 3, 2> as Tile>::SHAPE, [2, 1, 3, 2]);
        let e = q.extract(0, 0, 0, 2, "kern").unwrap_err();
        assert_eq!(
            e.to_string(),
            "kernel `kern`: index [0, 0, 0, 2] is out of bounds for a tile of shape [2, 1, 3, 2]"
        );
        assert_eq!(Tile3::<f32, 1, 2, 2>::ones().as_flat(), &[1.0; 4]);
        assert_eq!(Tile4::<u8, 1, 1, 1, 2>::zeros().data, [[[[0, 0]]]]);
        assert_eq!(Tile3::<i8, 1, 1, 2>::splat(-3).data, [[[-3, -3]]]);
    }
}
