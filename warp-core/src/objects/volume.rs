//! Warp's sparse volumes (NanoVDB grids), kernel side: [`VolumeView`] (what a `Volume<T>`
//! kernel parameter is on the CPU, and field for field what `wp::volume_t<T>` is on CUDA), the
//! lookup from a voxel to its value, and the `volume_*` builtins with their adjoints, with the
//! meaning they have in Warp 1.19 (docs/book/src/nanovdb.md, sections 4 and 5).
//!
//! # The invariant that makes lookups unchecked
//!
//! A view is made only by [`VolumeView::from_info`], from the [`GridInfo`] that
//! [`validate`](super::nanovdb::validate) returned for the very bytes the view addresses.
//! `validate` proved that the root's tile table lies inside the grid and that every child
//! offset (root tile -> upper node, upper table -> lower node, lower table -> leaf) lands
//! exactly on the start of a node of the next level, inside the grid. A lookup only ever
//! follows such offsets and reads fixed fields of the nodes it lands on, so it does **no
//! bounds checks**. The only mutation a kernel can make, [`volume_store`], writes leaf values,
//! never a mask, an offset or a key, so the structure stays valid for the whole launch.
//!
//! # Values and concurrency
//!
//! Values are read and written through relaxed atomics of the value's width
//! (`AtomicU32`/`AtomicU64`, a vector component by component), so concurrent
//! [`volume_store`]s and reads are not data races (a relaxed load compiles to a plain load).
//! The gradient grid ([`VolumeView::grad`], when non-zero) is a buffer of the grid's size:
//! every value location (leaf value, internal table value, root tile value, root background)
//! has a twin at the same byte offset, and the adjoints add into the twin of each location
//! they read with an atomic add (a compare-exchange loop on the bits). Nothing reads its
//! other bytes (the walk is the grid's), so it starts as zeros.
//!
//! # Sampling, exactly (the CUDA mirror reproduces every step)
//!
//! Positions are in index space, an integer being a voxel centre. A position with a NaN or
//! infinite coordinate is a fault ([`FaultKind::NonFinite`], `what` = `"volume sample
//! position"`), in every mode. Mode 0 is CLOSEST, any other value LINEAR.
//!
//! - **Integer coordinates.** A voxel coordinate is computed in `i64` from an integral `f32`
//!   `c` (rounded or floored): `clamp(c, -2^40, 2^40)` then converted (exact), plus the corner
//!   offset. A coordinate outside the `i32` range is unallocated space: the root background
//!   (level 4), whatever the tree holds.
//! - **CLOSEST**: `c = round(uvw)` per axis, halves away from zero (`-0.5 -> -1`, `2.5 -> 3`);
//!   the value of voxel `c` ([`VolumeView::locate`]).
//! - **LINEAR**: `b = floor(uvw)`, `f = uvw - b`, `wx = [1 - f.x, f.x]` (likewise `wy`, `wz`),
//!   all `f32`. Corners `c = 0..8` in the order `o = (c>>2 & 1, c>>1 & 1, c & 1)`, i.e.
//!   (0,0,0), (0,0,1), (0,1,0), (0,1,1), (1,0,0), ... Per corner, in `f32`:
//!   `w = (wx[o.x] * wy[o.y]) * wz[o.z]`, and with `s = 2*o - 1` (±1):
//!   `gw = [(s.x * wy[o.y]) * wz[o.z], (s.y * wx[o.x]) * wz[o.z], (s.z * wx[o.x]) * wy[o.y]]`.
//!   Then in the value's scalar precision `S` (f32 for `f32`/`Vec3`, f64 for `f64`/`DVec3`;
//!   `w` and `gw` converted to `S`), starting from zero, per corner value `v`:
//!   `val = val + w * v` (componentwise), and for the gradient `G = G + outer(v, gw)`
//!   (scalar: `G_a = G_a + v * gw_a`; vector: `G[c][a] = G[c][a] + v_c * gw_a`, row `c` =
//!   component, column `a` = axis: `Mat3::from_cols(dv/du, dv/dv, dv/dw)`). Corners are read
//!   as stored (tile, inactive and background values alike: no active-mask test). An
//!   integral `uvw` still blends with the `+1` neighbour at weight 0, so the gradient there
//!   is the positive-side cell's.
//! - **Position adjoint** (LINEAR only; CLOSEST gives zero): per corner,
//!   `d = dot(v, adj_ret)` (vector: `(v.x*a.x + v.y*a.y) + v.z*a.z`) in `S`,
//!   `t = f32(d * gw_a)` per axis; for `sample_grad` also `r_a = mul(v, adj_grad)_a`
//!   (scalar: `v * AG_a`; vector: `(v.x*AG[x][a] + v.y*AG[y][a]) + v.z*AG[z][a]`) and, with
//!   the weight Hessian's off-diagonal `hxy = (s.x*s.y)*wz[o.z]`, `hxz = (s.x*s.z)*wy[o.y]`,
//!   `hyz = (s.y*s.z)*wx[o.x]` (f32, converted to `S`):
//!   `h = f32([r_y*hxy + r_z*hxz, r_x*hxy + r_z*hyz, r_x*hxz + r_y*hyz])`. A local `f32`
//!   sum starts at zero and adds `t` (then `h`) per corner, in corner order; the caller's
//!   `adj_uvw` gets the sum added once at the end.
//! - **Value adjoint** (when `grad != 0`; also in CLOSEST, where the one voxel gets
//!   `adj_ret`): per corner, `a = w * adj_ret`, for `sample_grad` plus
//!   `rmul(adj_grad, gw)` (scalar: `(AG_x*gw_x + AG_y*gw_y) + AG_z*gw_z`; vector: per
//!   component `c`, `(AG[c][x]*gw_x + AG[c][y]*gw_y) + AG[c][z]*gw_z`), atomically added into
//!   the gradient grid at the corner's byte offset.
//! - **Transforms** use the grid's `f32` map copies (`matF` row-major, `invMatF`, `vecF`):
//!   `index_to_world(p)_r = ((p.x*M[r][0] + p.y*M[r][1]) + p.z*M[r][2]) + t_r`,
//!   `world_to_index(p)`: `s = p - t`, then `((s.x*Mi[r][0] + s.y*Mi[r][1]) + s.z*Mi[r][2])`;
//!   the `_dir` forms drop `t`. Adjoints add `Mᵀ adj` (`(a.x*M[0][c] + a.y*M[1][c]) +
//!   a.z*M[2][c]`), resp. `Miᵀ adj`, for positions and directions alike (Warp's own `f32`
//!   overloads add `M adj`, which is wrong unless `M` is symmetric).
//! - **Index variants** ([`volume_sample_index`], ...): the same taps, each reading
//!   `data[idx - 1]` for a level-0 hit with `idx > 0` and `bg` otherwise, `idx` as
//!   [`VolumeView::voxel_index`] computes it; their adjoints give the position's gradient only
//!   (the data's and the background's are not propagated yet).
//!
//! The grid type of a view always matches `T` (the runtime checks that before it makes one),
//! so Warp's "wrong type gives 0" case cannot arise here.

use core::marker::PhantomData;
use std::cell::UnsafeCell;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering::Relaxed};

use glam::{DMat3, DVec3, Mat3, Vec3};

use super::nanovdb::{
    GridInfo, GridType, Layout, GRID_DATA, LOWER_CHILD_MASK, MAP, UPPER_CHILD_MASK,
};
use crate::adjoint::Adjoint;
use crate::builtins::atomic::AtomicElement;
use crate::{ArrayView, Fault, FaultKind, GradView, KResult};

/// Sampling mode 0: the value of the voxel nearest to the position.
pub const CLOSEST: i32 = 0;
/// Sampling mode 1: trilinear interpolation of the 8 voxels around the position (any mode
/// other than [`CLOSEST`] samples this way).
pub const LINEAR: i32 = 1;

/// What a non-finite sample position is called in its fault.
const POSITION: &str = "volume sample position";

/// Offset of the leaf's value mask (8 little-endian u64 words).
const LEAF_MASK: u64 = super::nanovdb::LEAF_VALUE_MASK as u64;
/// Offset of an index leaf's `mPrefixSum` (its `mOffset` is at the value table, 80).
pub(crate) const INDEX_PREFIX_SUM: u64 = 88;
/// Voxels in a leaf.
const LEAF_VOXELS: u64 = 512;

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
    impl Sealed for i32 {}
    impl Sealed for glam::Vec3 {}
    impl Sealed for glam::DVec3 {}
    impl Sealed for super::VoxelIndex {}
}

/// What a volume can hold: a value type ([`VolumeValue`]) or, for index grids, the marker
/// [`VoxelIndex`]. Sealed.
pub trait VolumeGrid: Copy + Send + Sync + core::fmt::Debug + 'static + sealed::Sealed {
    /// The NanoVDB grid-type codes a view of this type may address.
    const GRID_TYPES: &'static [u32];
}

/// The element type of index grids (`Index` 19, `OnIndex` 20), whose leaves hold indices
/// into a separate array instead of values: a view of one supports the index variants
/// ([`volume_sample_index`], [`volume_lookup_index`], ...) and the transforms, nothing else.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VoxelIndex;

impl VolumeGrid for VoxelIndex {
    const GRID_TYPES: &'static [u32] = &[19, 20];
}

/// A value type of a grid: `f32` (Float), `f64` (Double), `i32` (Int32), `Vec3` (Vec3f),
/// `DVec3` (Vec3d). Sealed.
///
/// # Safety (of every method taking an address)
/// `p` must address a live, writable value of this type inside a grid (or its gradient
/// twin), aligned to the value's scalar, accessed by other threads only through these
/// methods for the duration of the call.
pub trait VolumeValue: VolumeGrid {
    /// Bytes of one value in the grid.
    const SIZE: u32;
    /// The zero value.
    fn zero() -> Self;
    /// A relaxed atomic load of the value at `p` (component by component).
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn load(p: *mut u8) -> Self;
    /// A relaxed atomic store of `v` at `p` (component by component).
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn store(p: *mut u8, v: Self);
    /// `*p += v`, atomically per component (a gradient accumulation); a no-op for `i32`,
    /// which has no gradient.
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn grad_add(p: *mut u8, v: Self);
}

macro_rules! scalar_value {
    ($t:ty, $code:expr, $atomic:ty, $bits:ty, gradient: $grad:literal) => {
        impl VolumeGrid for $t {
            const GRID_TYPES: &'static [u32] = &[$code];
        }
        impl VolumeValue for $t {
            const SIZE: u32 = core::mem::size_of::<$t>() as u32;
            #[inline(always)]
            fn zero() -> Self {
                0 as $t
            }
            #[inline(always)]
            unsafe fn load(p: *mut u8) -> Self {
                // SAFETY: the trait's contract (a live, aligned, writable value).
                let bits = unsafe { <$atomic>::from_ptr(p.cast::<$bits>()) }.load(Relaxed);
                <$t>::from_ne_bytes(bits.to_ne_bytes())
            }
            #[inline(always)]
            unsafe fn store(p: *mut u8, v: Self) {
                let bits = <$bits>::from_ne_bytes(v.to_ne_bytes());
                // SAFETY: the trait's contract.
                unsafe { <$atomic>::from_ptr(p.cast::<$bits>()) }.store(bits, Relaxed);
            }
            #[inline(always)]
            unsafe fn grad_add(p: *mut u8, v: Self) {
                // Integers have no gradient: nothing (a `ty` fragment cannot be matched
                // against `i32` in a macro arm, hence the flag).
                if $grad {
                    // SAFETY: the trait's contract; the float add is a CAS loop on the bits.
                    unsafe { <$t as AtomicElement>::atomic_add(p.cast::<$t>(), v) };
                }
            }
        }
    };
}
scalar_value!(f32, 1, AtomicU32, u32, gradient: true);
scalar_value!(f64, 2, AtomicU64, u64, gradient: true);
scalar_value!(i32, 4, AtomicU32, u32, gradient: false);

macro_rules! vector_value {
    ($v:ty, $s:ty, $code:expr) => {
        impl VolumeGrid for $v {
            const GRID_TYPES: &'static [u32] = &[$code];
        }
        impl VolumeValue for $v {
            const SIZE: u32 = 3 * core::mem::size_of::<$s>() as u32;
            #[inline(always)]
            fn zero() -> Self {
                <$v>::ZERO
            }
            #[inline(always)]
            unsafe fn load(p: *mut u8) -> Self {
                let s = core::mem::size_of::<$s>();
                // SAFETY: the trait's contract: three consecutive scalars.
                unsafe {
                    <$v>::new(
                        <$s>::load(p),
                        <$s>::load(p.add(s)),
                        <$s>::load(p.add(2 * s)),
                    )
                }
            }
            #[inline(always)]
            unsafe fn store(p: *mut u8, v: Self) {
                let s = core::mem::size_of::<$s>();
                // SAFETY: the trait's contract.
                unsafe {
                    <$s>::store(p, v.x);
                    <$s>::store(p.add(s), v.y);
                    <$s>::store(p.add(2 * s), v.z);
                }
            }
            #[inline(always)]
            unsafe fn grad_add(p: *mut u8, v: Self) {
                let s = core::mem::size_of::<$s>();
                // SAFETY: the trait's contract.
                unsafe {
                    <$s>::grad_add(p, v.x);
                    <$s>::grad_add(p.add(s), v.y);
                    <$s>::grad_add(p.add(2 * s), v.z);
                }
            }
        }
    };
}
vector_value!(Vec3, f32, 6);
vector_value!(DVec3, f64, 7);

/// The float scalar of a sampled value: `f32` or `f64`. Sealed.
pub trait VolumeScalar:
    Copy + core::ops::Add<Output = Self> + core::ops::Mul<Output = Self> + sealed::Sealed + 'static
{
    /// `w` converted (exactly, for `f64`).
    fn from_f32(w: f32) -> Self;
    /// `self` rounded to `f32`.
    fn to_f32(self) -> f32;
}
impl VolumeScalar for f32 {
    #[inline(always)]
    fn from_f32(w: f32) -> Self {
        w
    }
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }
}
impl VolumeScalar for f64 {
    #[inline(always)]
    fn from_f32(w: f32) -> Self {
        w as f64
    }
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self as f32
    }
}

/// A value type that can be interpolated: `f32`, `f64`, `Vec3`, `DVec3`. The methods are the
/// elementary steps of the module's sampling formulas, each in the order its documentation
/// gives (the CUDA mirror follows them). Sealed.
pub trait VolumeSample: VolumeValue + Adjoint + crate::grad::GradElement {
    /// The scalar precision of the arithmetic (`f32` or `f64`).
    type Scalar: VolumeScalar;
    /// The gradient with respect to the index-space position: `Vec3`/`DVec3` for scalars,
    /// `Mat3`/`DMat3` (column `a` = the derivative along axis `a`) for vectors.
    type Grad: Copy + Adjoint + core::fmt::Debug;
    /// `acc + w * v`, componentwise.
    fn add_scaled(acc: Self, w: Self::Scalar, v: Self) -> Self;
    /// `w * a`, componentwise.
    fn scale(w: Self::Scalar, a: Self) -> Self;
    /// `a + b`, componentwise.
    fn add(a: Self, b: Self) -> Self;
    /// The zero gradient.
    fn grad_zero() -> Self::Grad;
    /// `g + outer(v, gw)`: entry (component `c`, axis `a`) gets `g + v_c * gw_a`.
    fn grad_add_outer(g: Self::Grad, v: Self, gw: [Self::Scalar; 3]) -> Self::Grad;
    /// `dot(v, a)`: scalar `v * a`; vector `(v.x*a.x + v.y*a.y) + v.z*a.z`.
    fn dot(v: Self, a: Self) -> Self::Scalar;
    /// `vᵀ g` per axis `a`: scalar `v * g_a`; vector `(v.x*g[x][a] + v.y*g[y][a]) + v.z*g[z][a]`.
    fn vec_mul_grad(v: Self, g: Self::Grad) -> [Self::Scalar; 3];
    /// `g gw`: scalar `(g_x*gw_x + g_y*gw_y) + g_z*gw_z`; vector, per component `c`,
    /// `(g[c][x]*gw_x + g[c][y]*gw_y) + g[c][z]*gw_z`.
    fn grad_mul_vec(g: Self::Grad, gw: [Self::Scalar; 3]) -> Self;
}

macro_rules! scalar_sample {
    ($t:ty, $g:ty) => {
        impl VolumeSample for $t {
            type Scalar = $t;
            type Grad = $g;
            #[inline(always)]
            fn add_scaled(acc: Self, w: $t, v: Self) -> Self {
                acc + w * v
            }
            #[inline(always)]
            fn scale(w: $t, a: Self) -> Self {
                w * a
            }
            #[inline(always)]
            fn add(a: Self, b: Self) -> Self {
                a + b
            }
            #[inline(always)]
            fn grad_zero() -> $g {
                <$g>::ZERO
            }
            #[inline(always)]
            fn grad_add_outer(g: $g, v: Self, gw: [$t; 3]) -> $g {
                <$g>::new(g.x + v * gw[0], g.y + v * gw[1], g.z + v * gw[2])
            }
            #[inline(always)]
            fn dot(v: Self, a: Self) -> $t {
                v * a
            }
            #[inline(always)]
            fn vec_mul_grad(v: Self, g: $g) -> [$t; 3] {
                [v * g.x, v * g.y, v * g.z]
            }
            #[inline(always)]
            fn grad_mul_vec(g: $g, gw: [$t; 3]) -> Self {
                (g.x * gw[0] + g.y * gw[1]) + g.z * gw[2]
            }
        }
    };
}
scalar_sample!(f32, Vec3);
scalar_sample!(f64, DVec3);

macro_rules! vector_sample {
    ($v:ty, $s:ty, $m:ty) => {
        impl VolumeSample for $v {
            type Scalar = $s;
            type Grad = $m;
            #[inline(always)]
            fn add_scaled(acc: Self, w: $s, v: Self) -> Self {
                <$v>::new(acc.x + w * v.x, acc.y + w * v.y, acc.z + w * v.z)
            }
            #[inline(always)]
            fn scale(w: $s, a: Self) -> Self {
                <$v>::new(w * a.x, w * a.y, w * a.z)
            }
            #[inline(always)]
            fn add(a: Self, b: Self) -> Self {
                <$v>::new(a.x + b.x, a.y + b.y, a.z + b.z)
            }
            #[inline(always)]
            fn grad_zero() -> $m {
                <$m>::ZERO
            }
            #[inline(always)]
            fn grad_add_outer(g: $m, v: Self, gw: [$s; 3]) -> $m {
                // Column `a` is the derivative along axis `a`: component `c` of it gets
                // `v_c * gw_a`.
                let col = |c: <$m as MatCols>::Col, w: $s| {
                    <$v>::new(c.x + v.x * w, c.y + v.y * w, c.z + v.z * w)
                };
                <$m>::from_cols(
                    col(g.x_axis, gw[0]),
                    col(g.y_axis, gw[1]),
                    col(g.z_axis, gw[2]),
                )
            }
            #[inline(always)]
            fn dot(v: Self, a: Self) -> $s {
                (v.x * a.x + v.y * a.y) + v.z * a.z
            }
            #[inline(always)]
            fn vec_mul_grad(v: Self, g: $m) -> [$s; 3] {
                // g[c][a] is column a's component c.
                let r = |c: <$m as MatCols>::Col| (v.x * c.x + v.y * c.y) + v.z * c.z;
                [r(g.x_axis), r(g.y_axis), r(g.z_axis)]
            }
            #[inline(always)]
            fn grad_mul_vec(g: $m, gw: [$s; 3]) -> Self {
                let (a, b, c) = (g.x_axis, g.y_axis, g.z_axis);
                <$v>::new(
                    (a.x * gw[0] + b.x * gw[1]) + c.x * gw[2],
                    (a.y * gw[0] + b.y * gw[1]) + c.y * gw[2],
                    (a.z * gw[0] + b.z * gw[1]) + c.z * gw[2],
                )
            }
        }
    };
}

/// The column type of a glam 3x3 matrix (for the macro above).
trait MatCols {
    type Col;
}
impl MatCols for Mat3 {
    type Col = Vec3;
}
impl MatCols for DMat3 {
    type Col = DVec3;
}
vector_sample!(Vec3, f32, Mat3);
vector_sample!(DVec3, f64, DMat3);

/// A grid as a kernel thread sees it: the addresses of the grid bytes and of their gradient
/// twin, and the offsets a lookup needs, decoded once on the host by
/// [`validate`](super::nanovdb::validate). `#[repr(C)]`, 104 bytes, plain `u64`/`u32`
/// words: `wp::volume_t<T>` in the CUDA library has the same fields in the same order.
///
/// | offset | field | type | meaning |
/// |---|---|---|---|
/// | 0 | `data` | u64 | address of grid byte 0 (32-byte aligned) |
/// | 8 | `grad` | u64 | address of the gradient twin (the grid's size, values at the grid's offsets), 0 = none |
/// | 16 | `size` | u64 | grid bytes (GridData's gridSize) |
/// | 24 | `first_leaf` | u64 | byte offset of leaf 0 from `data` |
/// | 32 | `name` | u64 | CPU only: address of the kernel name's bytes, for faults (0 = none; the device ignores it) |
/// | 40 | `grid_type` | u32 | NanoVDB grid-type code |
/// | 44 | `root` | u32 | byte offset of RootData (child offsets in root tiles are relative to it) |
/// | 48 | `tiles` | u32 | byte offset of root tile 0 (`root + rootSize`) |
/// | 52 | `tile_count` | u32 | root tiles (tableSize) |
/// | 56 | `leaf_count` | u32 | leaves |
/// | 60 | `background` | u32 | byte offset of the root background value (`root + bg`) |
/// | 64 | `tile_size` | u32 | bytes per root tile |
/// | 68 | `tile_value` | u32 | offset of the value in a root tile |
/// | 72 | `stride` | u32 | bytes per internal-node table entry |
/// | 76 | `upper_table` | u32 | offset of the table in an upper node |
/// | 80 | `lower_table` | u32 | offset of the table in a lower node |
/// | 84 | `leaf_table` | u32 | offset of the values in a leaf (index grids: `mOffset`, 80) |
/// | 88 | `leaf_size` | u32 | bytes per leaf |
/// | 92 | `value_size` | u32 | bytes per leaf value; **0 for index grids** (so the level-0 "value offset" is the leaf's `mOffset` field, as in PNanoVDB) |
/// | 96 | `name_len` | u32 | CPU only: bytes of the kernel name |
/// | 100 | `pad` | u32 | zero |
///
/// The node-internal constants (child masks at 4128 in an upper node and 544 in a lower, the
/// leaf value mask at 16, an index leaf's `mPrefixSum` at 88, the map at 296) are the same
/// for every type and are not stored.
#[repr(C)]
pub struct VolumeView<T> {
    data: u64,
    grad: u64,
    size: u64,
    first_leaf: u64,
    name: u64,
    grid_type: u32,
    root: u32,
    tiles: u32,
    tile_count: u32,
    leaf_count: u32,
    background: u32,
    tile_size: u32,
    tile_value: u32,
    stride: u32,
    upper_table: u32,
    lower_table: u32,
    leaf_table: u32,
    leaf_size: u32,
    value_size: u32,
    name_len: u32,
    pad: u32,
    _t: PhantomData<T>,
}

const _: () = assert!(core::mem::size_of::<VolumeView<f32>>() == 104);
const _: () = assert!(core::mem::align_of::<VolumeView<f32>>() == 8);

impl<T> Clone for VolumeView<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for VolumeView<T> {}

// SAFETY: a view is addresses into buffers the runtime keeps alive for the whole launch;
// threads write values only through relaxed atomics (module docs).
unsafe impl<T> Send for VolumeView<T> {}
unsafe impl<T> Sync for VolumeView<T> {}

impl<T> core::fmt::Debug for VolumeView<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("VolumeView")
            .field("data", &format_args!("{:#x}", self.data))
            .field("grad", &format_args!("{:#x}", self.grad))
            .field("size", &self.size)
            .field("grid_type", &self.grid_type)
            .field("tile_count", &self.tile_count)
            .field("leaf_count", &self.leaf_count)
            .finish_non_exhaustive()
    }
}

/// Where a voxel's value lives: its byte offset from the grid start and the level of the
/// tree that holds it (0 leaf, 1 lower-node table, 2 upper-node table, 3 root tile, 4 root
/// background). For index grids a level-0 offset is the leaf's `mOffset` field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VoxelAddress {
    /// Byte offset from the grid's start.
    pub offset: u64,
    /// 0 leaf .. 4 background.
    pub level: u32,
}

/// PNanoVDB's read accessor: the nodes on the path to the last voxel looked up, reused by
/// the next lookup when it falls in the same node. Per-thread, per-sample state (LINEAR's 8
/// taps share one). Invariant: each non-zero node contains `key`.
#[derive(Clone, Copy)]
struct Accessor {
    key: [i32; 3],
    leaf: u64,
    lower: u64,
    upper: u64,
}

impl Accessor {
    #[inline(always)]
    fn new() -> Self {
        Accessor {
            key: [i32::MAX; 3],
            leaf: 0,
            lower: 0,
            upper: 0,
        }
    }
}

/// The 32-byte aligned, writable (never written) zeroed bytes an empty view addresses.
#[repr(C, align(32))]
struct EmptyGrid(UnsafeCell<[u8; 1024]>);
// SAFETY: nothing ever writes the bytes (an empty view has no leaf and no gradient), so
// sharing them is sharing immutable memory; the cell only places them in writable memory,
// which the atomic loads require.
unsafe impl Sync for EmptyGrid {}
static EMPTY_GRID: EmptyGrid = EmptyGrid(UnsafeCell::new([0; 1024]));

#[inline(always)]
fn leaf_voxel(ijk: [i32; 3]) -> u64 {
    ((((ijk[0] & 7) << 6) | ((ijk[1] & 7) << 3) | (ijk[2] & 7)) as u32) as u64
}

#[inline(always)]
fn lower_slot(ijk: [i32; 3]) -> u64 {
    ((((ijk[0] & 127) >> 3) << 8) | (((ijk[1] & 127) >> 3) << 4) | ((ijk[2] & 127) >> 3)) as u64
}

#[inline(always)]
fn upper_slot(ijk: [i32; 3]) -> u64 {
    ((((ijk[0] & 4095) >> 7) << 10) | (((ijk[1] & 4095) >> 7) << 5) | ((ijk[2] & 4095) >> 7)) as u64
}

impl<T: VolumeGrid> VolumeView<T> {
    /// A view of the validated grid at `data`, with its gradient twin at `grad` (0 for none).
    ///
    /// # Safety
    /// - `info` is what [`validate`](super::nanovdb::validate) returned for the `info.size`
    ///   bytes at `data`, and `T::GRID_TYPES` contains `info.grid_type` (the runtime checks
    ///   this and reports an error before calling).
    /// - `data` is 32-byte aligned, and those bytes stay alive, writable, and structurally
    ///   unchanged (only values may change, through the builtins) while any copy of the view
    ///   is used.
    /// - `grad` is 0, or the 32-byte aligned address of `info.size` writable bytes that stay
    ///   alive while any copy of the view is used (the adjoints add at the grid's value
    ///   offsets; nothing else reads or writes them).
    pub unsafe fn from_info(info: &GridInfo, data: u64, grad: u64) -> Self {
        debug_assert!(T::GRID_TYPES.contains(&info.grid_type.code()));
        debug_assert!(data.is_multiple_of(32) && grad.is_multiple_of(32));
        debug_assert!(info.root + info.layout.root_size as u64 <= u32::MAX as u64);
        Self::from_layout(
            info.grid_type,
            &info.layout,
            data,
            grad,
            info.size,
            info.first_leaf,
            info.root as u32,
            info.tile_count,
            info.leaf_count,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn from_layout(
        grid_type: GridType,
        l: &Layout,
        data: u64,
        grad: u64,
        size: u64,
        first_leaf: u64,
        root: u32,
        tile_count: u32,
        leaf_count: u32,
    ) -> Self {
        VolumeView {
            data,
            grad,
            size,
            first_leaf,
            name: 0,
            grid_type: grid_type.code(),
            root,
            tiles: root + l.root_size as u32,
            tile_count,
            leaf_count,
            background: root + l.background as u32,
            tile_size: l.tile_size as u32,
            tile_value: l.tile_value as u32,
            stride: l.stride as u32,
            upper_table: l.up_table as u32,
            lower_table: l.lo_table as u32,
            leaf_table: l.leaf_table as u32,
            leaf_size: l.leaf_size as u32,
            value_size: if grid_type.is_index() {
                0
            } else {
                l.value_size as u32
            },
            name_len: 0,
            pad: 0,
            _t: PhantomData,
        }
    }

    /// An empty grid of `T`'s (first) grid type: every lookup is the background, zero; no
    /// gradient; an all-zero map. What an adjoint's placeholder for a volume holds.
    pub fn empty() -> Self {
        let grid_type = GridType::from_code(T::GRID_TYPES[0]);
        let layout = Layout::of(grid_type).expect("every volume type has a layout");
        let root = (GRID_DATA + super::nanovdb::TREE_DATA) as u32;
        Self::from_layout(
            grid_type,
            &layout,
            EMPTY_GRID.0.get() as u64,
            0,
            (root as usize + layout.root_size) as u64,
            0,
            root,
            0,
            0,
        )
    }

    /// The view with `kernel` as the kernel name its faults carry (the runtime sets it when
    /// it makes the view for a launch).
    pub fn with_kernel_name(mut self, kernel: &'static str) -> Self {
        self.name = kernel.as_ptr() as u64;
        self.name_len = kernel.len() as u32;
        self
    }

    /// The kernel name faults carry (`"?"` when none was set).
    pub fn kernel_name(&self) -> &'static str {
        if self.name == 0 {
            return "?";
        }
        // SAFETY: `name`/`name_len` are private and only ever set together from a
        // `&'static str` (`with_kernel_name`).
        unsafe {
            core::str::from_utf8_unchecked(core::slice::from_raw_parts(
                self.name as *const u8,
                self.name_len as usize,
            ))
        }
    }

    /// The grid type.
    pub fn grid_type(&self) -> GridType {
        GridType::from_code(self.grid_type)
    }

    /// The address of grid byte 0.
    pub fn data(&self) -> u64 {
        self.data
    }

    /// The address of the gradient grid (0 for none).
    pub fn grad(&self) -> u64 {
        self.grad
    }

    /// Grid bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// Leaves in the grid.
    pub fn leaf_count(&self) -> u32 {
        self.leaf_count
    }

    /// Root tiles.
    pub fn tile_count(&self) -> u32 {
        self.tile_count
    }

    #[inline(always)]
    fn u64_at(&self, off: u64) -> u64 {
        // SAFETY: `off` is a node field proven inside the grid (module invariant); node
        // fields of 8 bytes are 8-aligned in a 32-aligned grid.
        unsafe { ((self.data + off) as *const u64).read() }
    }

    #[inline(always)]
    fn child_bit(&self, mask: u64, n: u64) -> bool {
        (self.u64_at(mask + ((n >> 6) << 3)) >> (n & 63)) & 1 != 0
    }

    /// Where the value of voxel `ijk` lives (docs/book/src/nanovdb.md, section 4; no active-mask
    /// test), without a cache.
    #[inline]
    pub fn locate(&self, ijk: [i32; 3]) -> VoxelAddress {
        self.locate_cached(ijk, &mut Accessor::new())
    }

    /// [`Self::locate`] for a voxel coordinate computed in `i64`: outside the `i32` range it
    /// is the root background.
    #[inline(always)]
    fn locate_wide(&self, c: [i64; 3], acc: &mut Accessor) -> VoxelAddress {
        let inside = |x: i64| x >= i32::MIN as i64 && x <= i32::MAX as i64;
        if inside(c[0]) && inside(c[1]) && inside(c[2]) {
            self.locate_cached([c[0] as i32, c[1] as i32, c[2] as i32], acc)
        } else {
            VoxelAddress {
                offset: self.background as u64,
                level: 4,
            }
        }
    }

    #[inline(always)]
    fn locate_cached(&self, ijk: [i32; 3], acc: &mut Accessor) -> VoxelAddress {
        let dirty = (ijk[0] ^ acc.key[0]) | (ijk[1] ^ acc.key[1]) | (ijk[2] ^ acc.key[2]);
        if acc.leaf != 0 {
            if dirty & !7 == 0 {
                return self.in_leaf(acc.leaf, ijk);
            }
            acc.leaf = 0;
        }
        if acc.lower != 0 {
            if dirty & !127 == 0 {
                return self.in_lower(acc.lower, ijk, acc);
            }
            acc.lower = 0;
        }
        if acc.upper != 0 {
            if dirty & !4095 == 0 {
                return self.in_upper(acc.upper, ijk, acc);
            }
            acc.upper = 0;
        }
        self.in_root(ijk, acc)
    }

    #[inline(always)]
    fn in_root(&self, ijk: [i32; 3], acc: &mut Accessor) -> VoxelAddress {
        let key = super::nanovdb::root_key(ijk);
        let mut tile = self.tiles as u64;
        for _ in 0..self.tile_count {
            if self.u64_at(tile) == key {
                let child = self.u64_at(tile + 8);
                if child == 0 {
                    return VoxelAddress {
                        offset: tile + self.tile_value as u64,
                        level: 3,
                    };
                }
                let upper = (self.root as u64).wrapping_add(child);
                acc.upper = upper;
                acc.key = ijk;
                return self.in_upper(upper, ijk, acc);
            }
            tile += self.tile_size as u64;
        }
        VoxelAddress {
            offset: self.background as u64,
            level: 4,
        }
    }

    #[inline(always)]
    fn in_upper(&self, upper: u64, ijk: [i32; 3], acc: &mut Accessor) -> VoxelAddress {
        let n = upper_slot(ijk);
        let entry = upper + self.upper_table as u64 + n * self.stride as u64;
        if self.child_bit(upper + UPPER_CHILD_MASK as u64, n) {
            let lower = upper.wrapping_add(self.u64_at(entry));
            acc.lower = lower;
            acc.key = ijk;
            self.in_lower(lower, ijk, acc)
        } else {
            VoxelAddress {
                offset: entry,
                level: 2,
            }
        }
    }

    #[inline(always)]
    fn in_lower(&self, lower: u64, ijk: [i32; 3], acc: &mut Accessor) -> VoxelAddress {
        let n = lower_slot(ijk);
        let entry = lower + self.lower_table as u64 + n * self.stride as u64;
        if self.child_bit(lower + LOWER_CHILD_MASK as u64, n) {
            let leaf = lower.wrapping_add(self.u64_at(entry));
            acc.leaf = leaf;
            acc.key = ijk;
            self.in_leaf(leaf, ijk)
        } else {
            VoxelAddress {
                offset: entry,
                level: 1,
            }
        }
    }

    #[inline(always)]
    fn in_leaf(&self, leaf: u64, ijk: [i32; 3]) -> VoxelAddress {
        VoxelAddress {
            offset: leaf + self.leaf_table as u64 + leaf_voxel(ijk) * self.value_size as u64,
            level: 0,
        }
    }

    /// Warp's voxel index of a lookup's result (`get_grid_voxel_index`): 0 unless `at` is a
    /// leaf (level 0); in a leaf, voxel `n = (i&7)<<6 | (j&7)<<3 | (k&7)` has, for an `Index`
    /// grid, `mOffset + n`; for `OnIndex`, 0 when the voxel is inactive, else `mOffset` plus
    /// the active voxels before it (a popcount in its mask word plus the 9-bit field of
    /// `mPrefixSum` for the earlier words); for a value grid `leafId * 512 + n + 1`, with
    /// `leafId` the leaf's position in the leaf array.
    #[inline]
    pub fn voxel_index(&self, at: VoxelAddress, ijk: [i32; 3]) -> u64 {
        if at.level != 0 {
            return 0;
        }
        let n = leaf_voxel(ijk);
        match self.grid_type {
            19 => self.u64_at(at.offset).wrapping_add(n),
            20 => {
                let leaf = at.offset - self.leaf_table as u64;
                let (w, b) = (n >> 6, n & 63);
                let word = self.u64_at(leaf + LEAF_MASK + 8 * w);
                if (word >> b) & 1 == 0 {
                    return 0;
                }
                let mut sum = (word & ((1u64 << b) - 1)).count_ones() as u64;
                if w > 0 {
                    sum += (self.u64_at(leaf + INDEX_PREFIX_SUM) >> (9 * (w - 1))) & 511;
                }
                self.u64_at(at.offset).wrapping_add(sum)
            }
            _ => {
                let leaf = at.offset - self.leaf_table as u64 - n * self.value_size as u64;
                let id = (leaf - self.first_leaf) / self.leaf_size as u64;
                id * LEAF_VOXELS + n + 1
            }
        }
    }

    /// The grid's `f32` map: `matF` (row-major), `invMatF`, `vecF`.
    #[inline(always)]
    fn map_f32(&self) -> ([f32; 9], [f32; 9], [f32; 3]) {
        let at = |k: usize| {
            // SAFETY: the map lies inside GridData (a validated grid is at least 736 bytes;
            // the empty view's bytes are 1024), f32s at 4-aligned offsets.
            unsafe { ((self.data as usize + MAP + 4 * k) as *const f32).read() }
        };
        (
            core::array::from_fn(at),
            core::array::from_fn(|k| at(9 + k)),
            [at(18), at(19), at(20)],
        )
    }

    #[cold]
    #[inline(never)]
    fn non_finite(&self, uvw: Vec3) -> Box<Fault> {
        Fault::new(
            self.kernel_name(),
            FaultKind::NonFinite {
                what: POSITION,
                values: vec![uvw.x as f64, uvw.y as f64, uvw.z as f64],
            },
        )
    }

    #[inline(always)]
    fn check_position(&self, uvw: Vec3) -> KResult<()> {
        if uvw.x.is_finite() && uvw.y.is_finite() && uvw.z.is_finite() {
            Ok(())
        } else {
            Err(self.non_finite(uvw))
        }
    }
}

impl<T: VolumeValue> VolumeView<T> {
    /// The value at `at` (a relaxed atomic load).
    #[inline(always)]
    pub fn value_at(&self, at: VoxelAddress) -> T {
        // SAFETY: `at` came from a lookup of this view: a value location inside the grid,
        // aligned to the value's scalar (module invariant, `from_info`).
        unsafe { T::load((self.data + at.offset) as *mut u8) }
    }

    /// Adds `v` into the gradient twin of the value at `at` (a no-op without a gradient grid).
    #[inline(always)]
    fn grad_add_at(&self, at: VoxelAddress, v: T) {
        if self.grad != 0 {
            // SAFETY: the twin has the grid's size (`from_info`) and `at` is a value location
            // of the grid, so the value's bytes lie inside the twin.
            unsafe { T::grad_add((self.grad + at.offset) as *mut u8, v) }
        }
    }
}

/// An integral `f32` as an `i64` voxel coordinate: clamped to ±2^40 first (exact; far
/// outside the `i32` range, so anything clamped is background).
#[inline(always)]
fn wide(c: f32) -> i64 {
    c.clamp(-1_099_511_627_776.0, 1_099_511_627_776.0) as i64
}

/// The LINEAR weights of one corner: `w`, `gw` (module docs), and the Hessian's
/// off-diagonal `[hxy, hxz, hyz]`.
struct Corner {
    offset: [i64; 3],
    w: f32,
    gw: [f32; 3],
    h: [f32; 3],
}

/// The LINEAR cell of `uvw`: its base voxel and the 8 corners' weights, in corner order.
#[inline(always)]
fn cell(uvw: Vec3) -> ([i64; 3], [Corner; 8]) {
    let b = [uvw.x.floor(), uvw.y.floor(), uvw.z.floor()];
    let f = [uvw.x - b[0], uvw.y - b[1], uvw.z - b[2]];
    let wx = [1.0 - f[0], f[0]];
    let wy = [1.0 - f[1], f[1]];
    let wz = [1.0 - f[2], f[2]];
    let corners = core::array::from_fn(|c| {
        let o = [(c >> 2) & 1, (c >> 1) & 1, c & 1];
        let s = o.map(|x| if x == 1 { 1.0f32 } else { -1.0 });
        let (x, y, z) = (wx[o[0]], wy[o[1]], wz[o[2]]);
        Corner {
            offset: o.map(|x| x as i64),
            w: (x * y) * z,
            gw: [(s[0] * y) * z, (s[1] * x) * z, (s[2] * x) * y],
            h: [(s[0] * s[1]) * z, (s[0] * s[2]) * y, (s[1] * s[2]) * x],
        }
    });
    (b.map(wide), corners)
}

/// The nearest voxel (halves away from zero), in `i64`.
#[inline(always)]
fn closest(uvw: Vec3) -> [i64; 3] {
    [uvw.x.round(), uvw.y.round(), uvw.z.round()].map(wide)
}

#[inline(always)]
fn corner_of(base: [i64; 3], c: &Corner) -> [i64; 3] {
    [
        base[0] + c.offset[0],
        base[1] + c.offset[1],
        base[2] + c.offset[2],
    ]
}

#[inline(always)]
fn widen<S: VolumeScalar>(v: [f32; 3]) -> [S; 3] {
    v.map(S::from_f32)
}

/// The 8 LINEAR taps of `uvw`: calls `tap(corner weights, address, voxel)` in corner order
/// (the voxel is meaningful only for in-range corners, where the address is not level 4
/// from the range rule; it is clamped into `i32` otherwise).
#[inline(always)]
fn for_taps<G: VolumeGrid>(
    v: &VolumeView<G>,
    uvw: Vec3,
    mut tap: impl FnMut(&Corner, VoxelAddress, [i32; 3]),
) {
    let (base, corners) = cell(uvw);
    let mut acc = Accessor::new();
    for c in &corners {
        let p = corner_of(base, c);
        let at = v.locate_wide(p, &mut acc);
        let ijk = p.map(|x| x.clamp(i32::MIN as i64, i32::MAX as i64) as i32);
        tap(c, at, ijk);
    }
}

/// The voxel nearest to `uvw` and its address.
#[inline(always)]
fn closest_tap<G: VolumeGrid>(v: &VolumeView<G>, uvw: Vec3) -> (VoxelAddress, [i32; 3]) {
    let p = closest(uvw);
    let at = v.locate_wide(p, &mut Accessor::new());
    (
        at,
        p.map(|x| x.clamp(i32::MIN as i64, i32::MAX as i64) as i32),
    )
}

/// Where the values of an index variant come from: `data[idx - 1]` for a level-0 hit with
/// `idx > 0`, `bg` otherwise.
#[inline(always)]
fn index_value<G: VolumeGrid, T: VolumeSample>(
    v: &VolumeView<G>,
    at: VoxelAddress,
    ijk: [i32; 3],
    data: &ArrayView<T, 1>,
    bg: T,
) -> KResult<T> {
    let idx = v.voxel_index(at, ijk);
    if idx > 0 {
        data.load(idx - 1)
    } else {
        Ok(bg)
    }
}

/// The adjoint of [`index_value`]: `a` into the data's gradient at the voxel's index, or into
/// the background's adjoint where the voxel has none (Warp's rule, CLOSEST included).
fn index_value_adj<G: VolumeGrid, T: VolumeSample>(
    v: &VolumeView<G>,
    at: VoxelAddress,
    ijk: [i32; 3],
    adj_data: &GradView<T, 1>,
    adj_bg: &mut T,
    a: T,
) -> KResult<()> {
    let idx = v.voxel_index(at, ijk);
    if idx > 0 {
        adj_data.accumulate(idx - 1, a)
    } else {
        adj_bg.adj_accum(a);
        Ok(())
    }
}

/// The LINEAR sum and gradient over values given by `read` (module docs).
#[inline(always)]
fn linear<G: VolumeGrid, T: VolumeSample>(
    v: &VolumeView<G>,
    uvw: Vec3,
    with_grad: bool,
    mut read: impl FnMut(VoxelAddress, [i32; 3]) -> KResult<T>,
) -> KResult<(T, T::Grad)> {
    let mut val = T::zero();
    let mut grad = T::grad_zero();
    let mut err = None;
    for_taps(v, uvw, |c, at, ijk| {
        if err.is_some() {
            return;
        }
        match read(at, ijk) {
            Ok(x) => {
                val = T::add_scaled(val, T::Scalar::from_f32(c.w), x);
                if with_grad {
                    grad = T::grad_add_outer(grad, x, widen(c.gw));
                }
            }
            Err(e) => err = Some(e),
        }
    });
    match err {
        Some(e) => Err(e),
        None => Ok((val, grad)),
    }
}

/// The position adjoint of LINEAR over values given by `read` (module docs), and the value
/// adjoint of each tap handed to `value_adj(address, ijk, adjoint)`.
#[inline(always)]
fn adj_linear<G: VolumeGrid, T: VolumeSample>(
    v: &VolumeView<G>,
    uvw: Vec3,
    adj_ret: T,
    adj_grad: Option<T::Grad>,
    mut read: impl FnMut(VoxelAddress, [i32; 3]) -> KResult<T>,
    mut value_adj: impl FnMut(VoxelAddress, [i32; 3], T) -> KResult<()>,
) -> KResult<Vec3> {
    let mut g = [0.0f32; 3];
    let mut err = None;
    for_taps(v, uvw, |c, at, ijk| {
        if err.is_some() {
            return;
        }
        let x = match read(at, ijk) {
            Ok(x) => x,
            Err(e) => {
                err = Some(e);
                return;
            }
        };
        let gw: [T::Scalar; 3] = widen(c.gw);
        let d = T::dot(x, adj_ret);
        for a in 0..3 {
            g[a] += (d * gw[a]).to_f32();
        }
        let mut a = T::scale(T::Scalar::from_f32(c.w), adj_ret);
        if let Some(ag) = adj_grad {
            let r = T::vec_mul_grad(x, ag);
            let [hxy, hxz, hyz]: [T::Scalar; 3] = widen(c.h);
            let h = [
                r[1] * hxy + r[2] * hxz,
                r[0] * hxy + r[2] * hyz,
                r[0] * hxz + r[1] * hyz,
            ];
            for a in 0..3 {
                g[a] += h[a].to_f32();
            }
            a = T::add(a, T::grad_mul_vec(ag, gw));
        }
        if let Err(e) = value_adj(at, ijk, a) {
            err = Some(e);
        }
    });
    match err {
        Some(e) => Err(e),
        None => Ok(Vec3::new(g[0], g[1], g[2])),
    }
}

// ---------------------------------------------------------------------------------------
// The builtins.

/// Warp's `volume_sample`: the grid sampled at index-space `uvw`, CLOSEST (mode 0) or
/// LINEAR (any other mode). A non-finite coordinate is a fault.
#[inline]
pub fn volume_sample<T: VolumeSample>(v: VolumeView<T>, uvw: Vec3, mode: i32) -> KResult<T> {
    v.check_position(uvw)?;
    if mode == CLOSEST {
        let (at, _) = closest_tap(&v, uvw);
        return Ok(v.value_at(at));
    }
    Ok(linear(&v, uvw, false, |at, _| Ok(v.value_at(at)))?.0)
}

/// Warp's `volume_sample_grad`: the sample and its gradient with respect to `uvw` (index
/// space; zero in CLOSEST mode).
#[inline]
pub fn volume_sample_grad<T: VolumeSample>(
    v: VolumeView<T>,
    uvw: Vec3,
    mode: i32,
) -> KResult<(T, T::Grad)> {
    v.check_position(uvw)?;
    if mode == CLOSEST {
        let (at, _) = closest_tap(&v, uvw);
        return Ok((v.value_at(at), T::grad_zero()));
    }
    linear(&v, uvw, true, |at, _| Ok(v.value_at(at)))
}

/// Warp's `volume_lookup`: the value of voxel `(i, j, k)` as stored (tile, inactive and
/// background values alike).
#[inline]
pub fn volume_lookup<T: VolumeValue>(v: VolumeView<T>, i: i32, j: i32, k: i32) -> KResult<T> {
    Ok(v.value_at(v.locate([i, j, k])))
}

/// Warp's `volume_store`: writes `value` at voxel `(i, j, k)` when the voxel is in a leaf
/// (active or not); a silent no-op elsewhere (tiles and the background are never written).
#[inline]
pub fn volume_store<T: VolumeValue>(
    v: VolumeView<T>,
    i: i32,
    j: i32,
    k: i32,
    value: T,
) -> KResult<()> {
    let at = v.locate([i, j, k]);
    if at.level == 0 {
        // SAFETY: a leaf value location of this grid (module invariant).
        unsafe { T::store((v.data + at.offset) as *mut u8, value) };
    }
    Ok(())
}

/// `M p + t` per row, in the module's order.
#[inline(always)]
fn affine(m: &[f32; 9], p: Vec3, t: [f32; 3]) -> Vec3 {
    Vec3::new(
        ((p.x * m[0] + p.y * m[1]) + p.z * m[2]) + t[0],
        ((p.x * m[3] + p.y * m[4]) + p.z * m[5]) + t[1],
        ((p.x * m[6] + p.y * m[7]) + p.z * m[8]) + t[2],
    )
}

/// `M p` per row.
#[inline(always)]
fn linear_map(m: &[f32; 9], p: Vec3) -> Vec3 {
    Vec3::new(
        (p.x * m[0] + p.y * m[1]) + p.z * m[2],
        (p.x * m[3] + p.y * m[4]) + p.z * m[5],
        (p.x * m[6] + p.y * m[7]) + p.z * m[8],
    )
}

/// `Mᵀ a` per column.
#[inline(always)]
fn transposed(m: &[f32; 9], a: Vec3) -> Vec3 {
    Vec3::new(
        (a.x * m[0] + a.y * m[3]) + a.z * m[6],
        (a.x * m[1] + a.y * m[4]) + a.z * m[7],
        (a.x * m[2] + a.y * m[5]) + a.z * m[8],
    )
}

/// Warp's `volume_index_to_world`: `M uvw + t` with the grid's `f32` map.
#[inline]
pub fn volume_index_to_world<G: VolumeGrid>(v: VolumeView<G>, uvw: Vec3) -> KResult<Vec3> {
    let (m, _, t) = v.map_f32();
    Ok(affine(&m, uvw, t))
}

/// Warp's `volume_world_to_index`: `M⁻¹ (xyz - t)` with the grid's `f32` map.
#[inline]
pub fn volume_world_to_index<G: VolumeGrid>(v: VolumeView<G>, xyz: Vec3) -> KResult<Vec3> {
    let (_, mi, t) = v.map_f32();
    Ok(linear_map(
        &mi,
        Vec3::new(xyz.x - t[0], xyz.y - t[1], xyz.z - t[2]),
    ))
}

/// Warp's `volume_index_to_world_dir`: `M uvw`.
#[inline]
pub fn volume_index_to_world_dir<G: VolumeGrid>(v: VolumeView<G>, uvw: Vec3) -> KResult<Vec3> {
    let (m, _, _) = v.map_f32();
    Ok(linear_map(&m, uvw))
}

/// Warp's `volume_world_to_index_dir`: `M⁻¹ xyz`.
#[inline]
pub fn volume_world_to_index_dir<G: VolumeGrid>(v: VolumeView<G>, xyz: Vec3) -> KResult<Vec3> {
    let (_, mi, _) = v.map_f32();
    Ok(linear_map(&mi, xyz))
}

/// Warp's `volume_sample_index`: [`volume_sample`] with the values taken from `data` by voxel
/// index (`data[idx - 1]`, `bg` where the voxel has none), on any grid (index grids and value
/// grids alike). An index beyond `data` is the array's out-of-bounds fault.
#[inline]
pub fn volume_sample_index<G: VolumeGrid, T: VolumeSample>(
    v: VolumeView<G>,
    uvw: Vec3,
    mode: i32,
    data: &ArrayView<T, 1>,
    bg: T,
) -> KResult<T> {
    v.check_position(uvw)?;
    if mode == CLOSEST {
        let (at, ijk) = closest_tap(&v, uvw);
        return index_value(&v, at, ijk, data, bg);
    }
    Ok(linear(&v, uvw, false, |at, ijk| index_value(&v, at, ijk, data, bg))?.0)
}

/// Warp's `volume_sample_grad_index`: [`volume_sample_grad`] with the values of
/// [`volume_sample_index`].
#[inline]
pub fn volume_sample_grad_index<G: VolumeGrid, T: VolumeSample>(
    v: VolumeView<G>,
    uvw: Vec3,
    mode: i32,
    data: &ArrayView<T, 1>,
    bg: T,
) -> KResult<(T, T::Grad)> {
    v.check_position(uvw)?;
    if mode == CLOSEST {
        let (at, ijk) = closest_tap(&v, uvw);
        return Ok((index_value(&v, at, ijk, data, bg)?, T::grad_zero()));
    }
    linear(&v, uvw, true, |at, ijk| index_value(&v, at, ijk, data, bg))
}

/// Warp's `volume_lookup_index`: the voxel's index into a value array (`idx - 1`), or -1
/// where it has none (not in a leaf; an inactive voxel of an `OnIndex` grid).
#[inline]
pub fn volume_lookup_index<G: VolumeGrid>(
    v: VolumeView<G>,
    i: i32,
    j: i32,
    k: i32,
) -> KResult<i32> {
    let at = v.locate([i, j, k]);
    Ok((v.voxel_index(at, [i, j, k]) as i32).wrapping_sub(1))
}

// ---------------------------------------------------------------------------------------
// The adjoints.

// Volumes carry no gradient as values (a gradient grid travels inside the view): the
// placeholder is an empty grid.
no_gradient!(where [T: VolumeGrid] VolumeView<T> = VolumeView::empty());

/// Adjoint of [`volume_sample`]: the position's (LINEAR), and with a gradient grid the
/// values' (module docs).
#[inline]
pub fn adj_volume_sample<T: VolumeSample>(
    v: VolumeView<T>,
    uvw: Vec3,
    mode: i32,
    _adj_v: &mut VolumeView<T>,
    adj_uvw: &mut Vec3,
    _adj_mode: &mut i32,
    adj_ret: T,
) -> KResult<()> {
    v.check_position(uvw)?;
    if mode == CLOSEST {
        let (at, _) = closest_tap(&v, uvw);
        v.grad_add_at(at, adj_ret);
        return Ok(());
    }
    let g = adj_linear(
        &v,
        uvw,
        adj_ret,
        None,
        |at, _| Ok(v.value_at(at)),
        |at, _, a| {
            v.grad_add_at(at, a);
            Ok(())
        },
    )?;
    *adj_uvw += g;
    Ok(())
}

/// Adjoint of [`volume_sample_grad`]: the position's (LINEAR, with the gradient's
/// second-derivative term), and with a gradient grid the values'.
#[inline]
pub fn adj_volume_sample_grad<T: VolumeSample>(
    v: VolumeView<T>,
    uvw: Vec3,
    mode: i32,
    _adj_v: &mut VolumeView<T>,
    adj_uvw: &mut Vec3,
    _adj_mode: &mut i32,
    adj_ret: (T, T::Grad),
) -> KResult<()> {
    v.check_position(uvw)?;
    if mode == CLOSEST {
        let (at, _) = closest_tap(&v, uvw);
        v.grad_add_at(at, adj_ret.0);
        return Ok(());
    }
    let g = adj_linear(
        &v,
        uvw,
        adj_ret.0,
        Some(adj_ret.1),
        |at, _| Ok(v.value_at(at)),
        |at, _, a| {
            v.grad_add_at(at, a);
            Ok(())
        },
    )?;
    *adj_uvw += g;
    Ok(())
}

/// Adjoint of [`volume_lookup`]: with a gradient grid, `adj_ret` added at the voxel's value
/// location (the indices have none).
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn adj_volume_lookup<T: VolumeValue + Adjoint>(
    v: VolumeView<T>,
    i: i32,
    j: i32,
    k: i32,
    _adj_v: &mut VolumeView<T>,
    _adj_i: &mut i32,
    _adj_j: &mut i32,
    _adj_k: &mut i32,
    adj_ret: T,
) -> KResult<()> {
    if v.grad != 0 {
        v.grad_add_at(v.locate([i, j, k]), adj_ret);
    }
    Ok(())
}

/// Adjoint of [`volume_index_to_world`]: `adj_uvw += Mᵀ adj_ret`.
#[inline]
pub fn adj_volume_index_to_world<G: VolumeGrid>(
    v: VolumeView<G>,
    _uvw: Vec3,
    _adj_v: &mut VolumeView<G>,
    adj_uvw: &mut Vec3,
    adj_ret: Vec3,
) -> KResult<()> {
    let (m, _, _) = v.map_f32();
    *adj_uvw += transposed(&m, adj_ret);
    Ok(())
}

/// Adjoint of [`volume_world_to_index`]: `adj_xyz += M⁻ᵀ adj_ret`.
#[inline]
pub fn adj_volume_world_to_index<G: VolumeGrid>(
    v: VolumeView<G>,
    _xyz: Vec3,
    _adj_v: &mut VolumeView<G>,
    adj_xyz: &mut Vec3,
    adj_ret: Vec3,
) -> KResult<()> {
    let (_, mi, _) = v.map_f32();
    *adj_xyz += transposed(&mi, adj_ret);
    Ok(())
}

/// Adjoint of [`volume_index_to_world_dir`]: `adj_uvw += Mᵀ adj_ret`.
#[inline]
pub fn adj_volume_index_to_world_dir<G: VolumeGrid>(
    v: VolumeView<G>,
    uvw: Vec3,
    adj_v: &mut VolumeView<G>,
    adj_uvw: &mut Vec3,
    adj_ret: Vec3,
) -> KResult<()> {
    adj_volume_index_to_world(v, uvw, adj_v, adj_uvw, adj_ret)
}

/// Adjoint of [`volume_world_to_index_dir`]: `adj_xyz += M⁻ᵀ adj_ret`.
#[inline]
pub fn adj_volume_world_to_index_dir<G: VolumeGrid>(
    v: VolumeView<G>,
    xyz: Vec3,
    adj_v: &mut VolumeView<G>,
    adj_xyz: &mut Vec3,
    adj_ret: Vec3,
) -> KResult<()> {
    adj_volume_world_to_index(v, xyz, adj_v, adj_xyz, adj_ret)
}

/// Adjoint of [`volume_sample_index`]: the position's (LINEAR; CLOSEST gives zero), and each
/// tap's weight times `adj_ret` into the data's gradient at its index, or into `adj_bg` where
/// the voxel has none (Warp's rule; CLOSEST's one tap with weight 1).
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn adj_volume_sample_index<G: VolumeGrid, T: VolumeSample>(
    v: VolumeView<G>,
    uvw: Vec3,
    mode: i32,
    data: &ArrayView<T, 1>,
    bg: T,
    _adj_v: &mut VolumeView<G>,
    adj_uvw: &mut Vec3,
    _adj_mode: &mut i32,
    adj_data: &mut GradView<T, 1>,
    adj_bg: &mut T,
    adj_ret: T,
) -> KResult<()> {
    v.check_position(uvw)?;
    if mode == CLOSEST {
        let (at, ijk) = closest_tap(&v, uvw);
        return index_value_adj(&v, at, ijk, adj_data, adj_bg, adj_ret);
    }
    let g = adj_linear(
        &v,
        uvw,
        adj_ret,
        None,
        |at, ijk| index_value(&v, at, ijk, data, bg),
        |at, ijk, a| index_value_adj(&v, at, ijk, adj_data, adj_bg, a),
    )?;
    *adj_uvw += g;
    Ok(())
}

/// Adjoint of [`volume_sample_grad_index`]: the position's (LINEAR, with the
/// second-derivative term; CLOSEST gives zero) and, as [`adj_volume_sample_index`], the data's
/// and the background's (each tap's value adjoint, the gradient term included).
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn adj_volume_sample_grad_index<G: VolumeGrid, T: VolumeSample>(
    v: VolumeView<G>,
    uvw: Vec3,
    mode: i32,
    data: &ArrayView<T, 1>,
    bg: T,
    _adj_v: &mut VolumeView<G>,
    adj_uvw: &mut Vec3,
    _adj_mode: &mut i32,
    adj_data: &mut GradView<T, 1>,
    adj_bg: &mut T,
    adj_ret: (T, T::Grad),
) -> KResult<()> {
    v.check_position(uvw)?;
    if mode == CLOSEST {
        let (at, ijk) = closest_tap(&v, uvw);
        return index_value_adj(&v, at, ijk, adj_data, adj_bg, adj_ret.0);
    }
    let g = adj_linear(
        &v,
        uvw,
        adj_ret.0,
        Some(adj_ret.1),
        |at, ijk| index_value(&v, at, ijk, data, bg),
        |at, ijk, a| index_value_adj(&v, at, ijk, adj_data, adj_bg, a),
    )?;
    *adj_uvw += g;
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::collections::HashSet;

    use super::*;
    use crate::objects::nanovdb::{build_from_tiles, build_from_voxels, validate, BuildKind, Map};

    /// 32 bytes, 32-aligned: grid buffers are vectors of these.
    #[repr(C, align(32))]
    #[derive(Clone, Copy)]
    struct A32([u8; 32]);

    /// A validated grid in an aligned buffer, with an optional gradient twin. The buffers are
    /// only touched through the raw addresses once made (the views write through them).
    struct Grid {
        _data: Vec<A32>,
        _grad: Vec<A32>,
        data: *mut u8,
        grad: *mut u8,
        info: GridInfo,
    }

    fn aligned(bytes: &[u8]) -> Vec<A32> {
        let mut v = vec![A32([0; 32]); bytes.len().div_ceil(32)];
        for (k, b) in bytes.iter().enumerate() {
            v[k / 32].0[k % 32] = *b;
        }
        v
    }

    impl Grid {
        /// `bytes` validated; `twin` (the same structure with zero values) as the gradient.
        fn new(bytes: Vec<u8>, twin: Option<Vec<u8>>) -> Grid {
            let info = validate(&bytes).expect("valid grid");
            let mut data = aligned(&bytes);
            let mut grad = twin.map(|t| aligned(&t)).unwrap_or_default();
            let g = if grad.is_empty() {
                core::ptr::null_mut()
            } else {
                grad.as_mut_ptr().cast()
            };
            Grid {
                data: data.as_mut_ptr().cast(),
                grad: g,
                _data: data,
                _grad: grad,
                info,
            }
        }

        fn view<T: VolumeGrid>(&self) -> VolumeView<T> {
            // SAFETY: validated, aligned, alive as long as `self`; the twin has the grid's
            // structure (built from the same tiles).
            unsafe { VolumeView::from_info(&self.info, self.data as u64, self.grad as u64) }
        }

        fn grad_at<T: VolumeValue>(&self, off: u64) -> T {
            // SAFETY: a value location of the twin.
            unsafe { T::load(self.grad.add(off as usize)) }
        }

        fn put<T: VolumeValue>(&self, off: u64, v: T) {
            // SAFETY: a value location of the grid.
            unsafe { T::store(self.data.add(off as usize), v) }
        }
    }

    trait Bytes: VolumeValue {
        const TYPE: GridType;
        fn le(self) -> Vec<u8>;
    }
    impl Bytes for f32 {
        const TYPE: GridType = GridType::Float;
        fn le(self) -> Vec<u8> {
            self.to_le_bytes().to_vec()
        }
    }
    impl Bytes for f64 {
        const TYPE: GridType = GridType::Double;
        fn le(self) -> Vec<u8> {
            self.to_le_bytes().to_vec()
        }
    }
    impl Bytes for i32 {
        const TYPE: GridType = GridType::Int32;
        fn le(self) -> Vec<u8> {
            self.to_le_bytes().to_vec()
        }
    }
    impl Bytes for Vec3 {
        const TYPE: GridType = GridType::Vec3f;
        fn le(self) -> Vec<u8> {
            self.to_array()
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect()
        }
    }
    impl Bytes for DVec3 {
        const TYPE: GridType = GridType::Vec3d;
        fn le(self) -> Vec<u8> {
            self.to_array()
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect()
        }
    }

    /// A value grid of `T` with a leaf per tile, background `bg`, every leaf voxel set to
    /// `f(voxel)` through `volume_store`, and (when `grad`) a gradient twin.
    fn value_grid<T: Bytes>(
        tiles: &[[i32; 3]],
        bg: T,
        map: &Map,
        grad: bool,
        f: impl Fn([i32; 3]) -> T,
    ) -> Grid {
        let build = |b: T| {
            build_from_tiles(
                BuildKind::Value {
                    grid_type: T::TYPE,
                    background: &b.le(),
                },
                tiles,
                map,
            )
            .expect("built")
        };
        let g = Grid::new(build(bg), grad.then(|| build(T::zero())));
        let v = g.view::<T>();
        for_voxels(tiles, |p| volume_store(v, p[0], p[1], p[2], f(p)).unwrap());
        g
    }

    fn leaf_of(p: [i32; 3]) -> [i32; 3] {
        p.map(|x| x & !7)
    }

    /// Every voxel of every tile's leaf (once per distinct leaf).
    fn for_voxels(tiles: &[[i32; 3]], mut f: impl FnMut([i32; 3])) {
        let leaves: HashSet<[i32; 3]> = tiles.iter().map(|&t| leaf_of(t)).collect();
        for o in leaves {
            for n in 0..512 {
                f([o[0] + (n >> 6), o[1] + ((n >> 3) & 7), o[2] + (n & 7)]);
            }
        }
    }

    /// The tiles of the inclusive box `lo..=hi`.
    fn box_tiles(lo: [i32; 3], hi: [i32; 3]) -> Vec<[i32; 3]> {
        let mut t = vec![];
        let (lo, hi) = (leaf_of(lo), leaf_of(hi));
        let mut x = lo[0] as i64;
        while x <= hi[0] as i64 {
            let mut y = lo[1] as i64;
            while y <= hi[1] as i64 {
                let mut z = lo[2] as i64;
                while z <= hi[2] as i64 {
                    t.push([x as i32, y as i32, z as i32]);
                    z += 8;
                }
                y += 8;
            }
            x += 8;
        }
        t
    }

    /// The value grid's reference: `f` in allocated leaves, `bg` elsewhere.
    struct Dense<'a, T> {
        leaves: HashSet<[i32; 3]>,
        bg: T,
        f: &'a dyn Fn([i32; 3]) -> T,
    }

    impl<'a, T: Copy> Dense<'a, T> {
        fn new(tiles: &[[i32; 3]], bg: T, f: &'a dyn Fn([i32; 3]) -> T) -> Self {
            Dense {
                leaves: tiles.iter().map(|&t| leaf_of(t)).collect(),
                bg,
                f,
            }
        }
        fn at(&self, p: [i64; 3]) -> T {
            if p.iter()
                .any(|&x| x < i32::MIN as i64 || x > i32::MAX as i64)
            {
                return self.bg;
            }
            let p = p.map(|x| x as i32);
            if self.leaves.contains(&leaf_of(p)) {
                (self.f)(p)
            } else {
                self.bg
            }
        }
    }

    /// The trilinear interpolation of `d` at `uvw`, in f64 (the exact-arithmetic reference).
    fn trilinear(d: &Dense<'_, f32>, uvw: Vec3) -> f64 {
        let b = uvw.to_array().map(|x| x.floor() as f64);
        let f = [0, 1, 2].map(|a| uvw[a] as f64 - b[a]);
        let mut s = 0.0;
        for c in 0..8 {
            let o = [(c >> 2) & 1, (c >> 1) & 1, c & 1];
            let w: f64 = (0..3)
                .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
                .product();
            let p = [0, 1, 2].map(|a| b[a] as i64 + o[a] as i64);
            s += w * d.at(p) as f64;
        }
        s
    }

    /// A deterministic xorshift generator.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
        /// Uniform in `[lo, hi)`.
        fn f32(&mut self, lo: f32, hi: f32) -> f32 {
            lo + (hi - lo) * ((self.next() >> 40) as f32 / (1u64 << 24) as f32)
        }
        fn i32(&mut self, lo: i32, hi: i32) -> i32 {
            lo + (self.next() % (hi - lo) as u64) as i32
        }
    }

    fn hash(p: [i32; 3]) -> f32 {
        let h = (p[0].wrapping_mul(73_856_093) ^ p[1].wrapping_mul(19_349_663))
            ^ p[2].wrapping_mul(83_492_791);
        (h & 0xFFFF) as f32 - 30_000.0
    }

    const BG: f32 = -7.25;

    fn unit() -> Map {
        Map::uniform(1.0, [0.0; 3])
    }

    /// Tiles on both sides of each boundary the lookups must cross, negative ones, and the
    /// ends of the i32 range.
    fn boundary_tiles() -> Vec<[i32; 3]> {
        vec![
            [0, 0, 0],
            [8, 0, 0],
            [120, 0, 0],
            [128, 0, 0],
            [4088, 0, 0],
            [4096, 0, 0],
            [-1, 0, 0],
            [-9, 0, 0],
            [-4097, 0, 0],
            [-4096, 0, 0],
            [0, -1, -1],
            [5, 300, 9],
            [i32::MAX, i32::MAX, i32::MAX],
            [i32::MIN, 0, i32::MIN],
            [2_147_483_520, 0, 0],
        ]
    }

    #[test]
    fn lookup_matches_dense_reference_everywhere() {
        let tiles = boundary_tiles();
        let g = value_grid(&tiles, BG, &unit(), false, hash);
        let v = g.view::<f32>();
        let d = Dense::new(&tiles, BG, &hash);
        let mut n = 0;
        // Every voxel of every leaf and a shell of one voxel around it (wrapping at the
        // ends of the range, which names real voxels too).
        for t in &tiles {
            let o = leaf_of(*t);
            for x in -1..9 {
                for y in -1..9 {
                    for z in -1..9 {
                        let p = [
                            o[0].wrapping_add(x),
                            o[1].wrapping_add(y),
                            o[2].wrapping_add(z),
                        ];
                        let want = d.at(p.map(|c| c as i64));
                        assert_eq!(volume_lookup(v, p[0], p[1], p[2]).unwrap(), want, "{p:?}");
                        n += 1;
                    }
                }
            }
        }
        assert_eq!(n, tiles.len() * 1000);
        // The levels: a leaf, a lower table entry (same lower, no leaf), an upper table
        // entry (same upper, no lower), the background (no upper).
        let level = |p: [i32; 3]| v.locate(p).level;
        assert_eq!(level([7, 7, 7]), 0);
        assert_eq!(level([-1, 0, 0]), 0); // local 7 of the leaf at -8
        assert_eq!(level([16, 0, 0]), 1);
        assert_eq!(level([0, 1000, 0]), 2);
        assert_eq!(level([8192, 0, 0]), 4);
        assert_eq!(level([-4097, 0, 0]), 0);
        assert_eq!(level([-4105, 0, 0]), 1);
        for p in [[16, 0, 0], [0, 1000, 0], [8192, 0, 0], [-8193, 5, 5]] {
            assert_eq!(volume_lookup(v, p[0], p[1], p[2]).unwrap(), BG);
        }
    }

    #[test]
    fn root_value_tile_is_level_3() {
        // A tile whose child is 0 holds a value for its whole 4096^3 region: made here by
        // clearing the child offset of the only tile (the upper node becomes unreachable,
        // every other offset stays in range).
        let g = value_grid(&[[0, 0, 0]], BG, &unit(), false, |_| 1.0);
        let v = g.view::<f32>();
        // SAFETY: the child field of root tile 0 (8-aligned, inside the grid).
        unsafe { (g.data.add(v.tiles as usize + 8) as *mut u64).write(0) };
        let at = v.locate([5, 5, 5]);
        assert_eq!(at.level, 3);
        assert_eq!(at.offset, v.tiles as u64 + v.tile_value as u64);
        g.put(at.offset, 2.5f32);
        assert_eq!(volume_lookup(v, 4095, 0, 0).unwrap(), 2.5);
        assert_eq!(volume_lookup(v, 4096, 0, 0).unwrap(), BG);
    }

    #[test]
    fn store_writes_leaves_only() {
        let tiles = [[0, 0, 0]];
        let g = value_grid(&tiles, BG, &unit(), false, |_| 0.0);
        let v = g.view::<f32>();
        volume_store(v, 3, 4, 5, 9.5).unwrap();
        assert_eq!(volume_lookup(v, 3, 4, 5).unwrap(), 9.5);
        // Outside the leaves: a lower table entry, an upper one, the background.
        for p in [[8, 0, 0], [0, 200, 0], [-5000, 0, 0]] {
            volume_store(v, p[0], p[1], p[2], 1.0).unwrap();
            assert_eq!(volume_lookup(v, p[0], p[1], p[2]).unwrap(), BG);
        }
        // The background stayed the background everywhere.
        assert_eq!(volume_lookup(v, 9, 0, 0).unwrap(), BG);
    }

    #[test]
    fn closest_rounds_halves_away_from_zero() {
        let tiles = box_tiles([-16, -8, -8], [15, 7, 7]);
        let f = |p: [i32; 3]| (p[0] * 100 + p[1] * 10 + p[2]) as f32;
        let g = value_grid(&tiles, BG, &unit(), false, f);
        let v = g.view::<f32>();
        let s = |x: f32, y: f32, z: f32| volume_sample(v, Vec3::new(x, y, z), CLOSEST).unwrap();
        assert_eq!(s(0.5, 0.0, 0.0), 100.0);
        assert_eq!(s(-0.5, 0.0, 0.0), -100.0);
        assert_eq!(s(2.5, -2.5, 0.0), f([3, -3, 0]));
        assert_eq!(s(-2.5, 2.5, 0.5), f([-3, 3, 1]));
        assert_eq!(s(0.49, -0.49, 1.51), f([0, 0, 2]));
        assert_eq!(s(-8.5, 0.0, 0.0), f([-9, 0, 0]));
        // Past the allocation: the background.
        assert_eq!(s(15.5, 0.0, 0.0), BG);
        // The grad variant: the value, a zero gradient.
        let (val, grad) = volume_sample_grad(v, Vec3::new(2.5, 0.0, 0.0), CLOSEST).unwrap();
        assert_eq!((val, grad), (f([3, 0, 0]), Vec3::ZERO));
    }

    #[test]
    fn linear_reproduces_a_trilinear_function_across_boundaries() {
        // v = a + b i + c j + d k + e ijk is trilinear, so trilinear interpolation reproduces
        // it: the only error is f32 rounding (the stored values, the weights, the 8-term
        // sum), bounded by 16 ulp of the largest corner value (module docs' formula: 0.5
        // ulp storing, 3 roundings per weight, 8 in the sum).
        let f64f = |p: [f64; 3]| {
            0.5 + 0.25 * p[0] - 0.125 * p[1] + 0.0625 * p[2] + 0.01 * p[0] * p[1] * p[2]
        };
        let f = move |p: [i32; 3]| f64f(p.map(|x| x as f64)) as f32;
        let mut tiles = box_tiles([-16, -16, -16], [15, 15, 15]);
        for (lo, hi) in [
            ([120, 0, 0], [135, 7, 7]),
            ([4088, 0, 0], [4103, 7, 7]),
            ([-4104, 0, 0], [-4089, 7, 7]),
        ] {
            tiles.extend(box_tiles(lo, hi));
        }
        let g = value_grid(&tiles, BG, &unit(), false, f);
        let v = g.view::<f32>();
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        let check = |uvw: Vec3| {
            let got = volume_sample(v, uvw, LINEAR).unwrap() as f64;
            let want = f64f(uvw.to_array().map(|x| x as f64));
            let b = uvw.to_array().map(|x| x.floor() as i32);
            let vmax = (0..8)
                .map(|c| f([b[0] + (c >> 2 & 1), b[1] + (c >> 1 & 1), b[2] + (c & 1)]).abs())
                .fold(0.0f32, f32::max) as f64;
            let tol = 16.0 * f32::EPSILON as f64 * vmax.max(1.0);
            assert!(
                (got - want).abs() <= tol,
                "{uvw}: {got} vs {want} (tol {tol})"
            );
        };
        for _ in 0..4000 {
            check(Vec3::new(
                rng.f32(-16.0, 15.0),
                rng.f32(-16.0, 15.0),
                rng.f32(-16.0, 15.0),
            ));
        }
        for x in [
            7.5, -0.5, -8.5, 127.5, 4095.5, -4096.5, 127.0, -4097.0, 4095.25,
        ] {
            for _ in 0..50 {
                let (y, z) = (rng.f32(0.0, 6.99), rng.f32(0.0, 6.99));
                check(Vec3::new(x, y, z));
                check(Vec3::new(x.clamp(-16.0, 14.99), x.clamp(-16.0, 14.99), z));
            }
        }
        // On a voxel: exactly the voxel's value (weight 1, the rest 0).
        for p in [[3, -4, 5], [-16, -16, -16], [127, 2, 3], [-4097, 1, 1]] {
            let uvw = Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32);
            assert_eq!(volume_sample(v, uvw, LINEAR).unwrap(), f(p));
        }
    }

    #[test]
    fn linear_mixes_with_background_at_the_allocation_edge() {
        // Against the f64 trilinear interpolation of the dense reference, corners outside
        // the leaves reading the background; tolerance as above.
        let tiles = vec![[0, 0, 0], [8, 8, 0], [-8, 0, -8], [0, 120, 0], [0, 128, 0]];
        let g = value_grid(&tiles, BG, &unit(), false, hash);
        let v = g.view::<f32>();
        let d = Dense::new(&tiles, BG, &hash);
        let mut rng = Rng(7);
        for k in 0..6000 {
            let uvw = if k % 2 == 0 {
                Vec3::new(
                    rng.f32(-10.0, 18.0),
                    rng.f32(-2.0, 18.0),
                    rng.f32(-10.0, 10.0),
                )
            } else {
                Vec3::new(
                    rng.f32(-1.0, 9.0),
                    rng.f32(118.0, 138.0),
                    rng.f32(-1.0, 9.0),
                )
            };
            let got = volume_sample(v, uvw, LINEAR).unwrap() as f64;
            let want = trilinear(&d, uvw);
            let tol = 16.0 * f32::EPSILON as f64 * 65536.0;
            assert!((got - want).abs() <= tol, "{uvw}: {got} vs {want}");
        }
    }

    #[test]
    fn sample_grad_matches_warps_check_and_the_analytic_gradient() {
        let f = |p: [i32; 3]| (p[0] * p[1] * p[2]) as f32;
        let tiles = box_tiles([-8, -8, -8], [15, 15, 15]);
        let g = value_grid(&tiles, BG, &unit(), false, f);
        let v = g.view::<f32>();
        // Warp's test: at (1.5, 2, 3) the value 9 and the gradient (jk, ik, ij) = (6, 4.5, 3),
        // the y derivative from the positive side (exact: every weight and product is a
        // short binary fraction).
        let (val, grad) = volume_sample_grad(v, Vec3::new(1.5, 2.0, 3.0), LINEAR).unwrap();
        assert_eq!(val, 9.0);
        assert_eq!(grad, Vec3::new(6.0, 4.5, 3.0));
        // Inside cells the interpolant of ijk is ijk itself, so the gradient is
        // (uv.., ...) exactly up to f32 rounding (values below 3375; tolerance 64 ulp of it).
        let mut rng = Rng(99);
        for _ in 0..2000 {
            let p = Vec3::new(
                rng.f32(-7.0, 14.0),
                rng.f32(-7.0, 14.0),
                rng.f32(-7.0, 14.0),
            );
            let (val, grad) = volume_sample_grad(v, p, LINEAR).unwrap();
            assert_eq!(
                val,
                volume_sample(v, p, LINEAR).unwrap(),
                "same taps, same sum"
            );
            let want = Vec3::new(p.y * p.z, p.x * p.z, p.x * p.y);
            assert!(
                (grad - want).abs().max_element() <= 64.0 * f32::EPSILON * 400.0,
                "{p}"
            );
        }
    }

    /// The central difference of `f` along axis `a` at `p` with step `h`.
    fn central(f: impl Fn(Vec3) -> f64, p: Vec3, a: usize, h: f32) -> f64 {
        let mut lo = p;
        let mut hi = p;
        lo[a] -= h;
        hi[a] += h;
        (f(hi) - f(lo)) / (hi[a] as f64 - lo[a] as f64)
    }

    /// A point whose fractional parts keep `p ± 0.25` in its cell.
    fn in_cell(rng: &mut Rng, lo: f32, hi: f32) -> Vec3 {
        let c = |rng: &mut Rng| rng.i32(lo as i32, hi as i32) as f32 + rng.f32(0.3, 0.7);
        Vec3::new(c(rng), c(rng), c(rng))
    }

    #[test]
    fn sample_grad_matches_central_differences() {
        // Along an axis, inside a cell, the interpolant is linear: a central difference with
        // h = 0.25 (staying in the cell) equals the gradient up to the samples' rounding
        // (f64 grid: weights are f32, so about 1e-7 relative; tolerance 1e-5 * |v|max / h).
        let f = |p: [i32; 3]| hash(p) as f64 / 1000.0;
        let tiles = box_tiles([-8, -8, -8], [15, 15, 15]);
        let g = value_grid(&tiles, BG as f64, &unit(), false, f);
        let v = g.view::<f64>();
        let mut rng = Rng(5);
        for _ in 0..500 {
            let p = in_cell(&mut rng, -10.0, 17.0);
            let (_, grad) = volume_sample_grad(v, p, LINEAR).unwrap();
            for a in 0..3 {
                let fd = central(|q| volume_sample(v, q, LINEAR).unwrap(), p, a, 0.25);
                assert!(
                    (grad[a] - fd).abs() <= 1e-5 * 40.0 / 0.25,
                    "{p} {a}: {} vs {fd}",
                    grad[a]
                );
            }
        }
    }

    #[test]
    fn position_adjoints_match_the_gradient_and_central_differences() {
        let f = |p: [i32; 3]| hash(p) / 1000.0;
        let tiles = box_tiles([-8, -8, -8], [15, 15, 15]);
        let g = value_grid(&tiles, BG, &unit(), false, f);
        let v = g.view::<f32>();
        let mut rng = Rng(11);
        let mut adj_v = VolumeView::<f32>::empty();
        for _ in 0..500 {
            let p = in_cell(&mut rng, -10.0, 17.0);
            // adj_ret = 1: the gradient itself, bit for bit (the same products, summed in
            // the same order from zero, for an f32 grid).
            let (_, grad) = volume_sample_grad(v, p, LINEAR).unwrap();
            let mut adj = Vec3::ZERO;
            adj_volume_sample(v, p, LINEAR, &mut adj_v, &mut adj, &mut 0, 1.0).unwrap();
            assert_eq!(adj, grad);
            // Accumulates.
            adj_volume_sample(v, p, LINEAR, &mut adj_v, &mut adj, &mut 0, 2.0).unwrap();
            assert!((adj - 3.0 * grad).abs().max_element() <= 1e-5);
            // sample_grad's adjoint: the gradient of L = s*val + dot(ag, grad), the
            // second-derivative term included, against central differences (f32 samples of
            // values below 40: tolerance 64 ulp of 40 over h).
            let (s, ag) = (0.75f32, Vec3::new(0.5, -1.25, 2.0));
            let loss = |q: Vec3| {
                let (val, gr) = volume_sample_grad(v, q, LINEAR).unwrap();
                s as f64 * val as f64 + ag.dot(gr) as f64
            };
            let mut adj = Vec3::ZERO;
            adj_volume_sample_grad(v, p, LINEAR, &mut adj_v, &mut adj, &mut 0, (s, ag)).unwrap();
            for a in 0..3 {
                let fd = central(loss, p, a, 0.25);
                let tol = 64.0 * f32::EPSILON as f64 * 40.0 / 0.25 * 4.0;
                assert!(
                    (adj[a] as f64 - fd).abs() <= tol,
                    "{p} {a}: {} vs {fd}",
                    adj[a]
                );
            }
            // CLOSEST: no position gradient.
            let mut adj = Vec3::ZERO;
            adj_volume_sample(v, p, CLOSEST, &mut adj_v, &mut adj, &mut 0, 1.0).unwrap();
            adj_volume_sample_grad(v, p, CLOSEST, &mut adj_v, &mut adj, &mut 0, (1.0, ag)).unwrap();
            assert_eq!(adj, Vec3::ZERO);
        }
    }

    #[test]
    fn value_adjoints_land_where_the_values_were_read() {
        // Leaf values, a lower-table value and the root background: each corner's weight
        // (times adj_ret, plus the gradient term) goes to the twin of its location; checked
        // against central differences of the sample in the stored value (h = 1/8: the
        // sample is linear in each value; tolerance: rounding of samples below 40).
        let f = |p: [i32; 3]| hash(p) / 1000.0;
        let tiles = [[0, 0, 0], [8, 0, 0]];
        let g = value_grid(&tiles, BG, &unit(), true, f);
        let v = g.view::<f32>();
        let mut adj_v = VolumeView::<f32>::empty();
        // Corners: x in {14, 15} (leaf 8) / {15, 16} (16 is a lower table entry); y in
        // {-1, 0} (-1 is another upper: the background); z in {3, 4}.
        for p in [Vec3::new(14.3, 0.6, 3.2), Vec3::new(15.3, -0.4, 3.7)] {
            let (s, ag) = (1.5f32, Vec3::new(0.25, -0.5, 2.0));
            let mut adj = Vec3::ZERO;
            adj_volume_sample_grad(v, p, LINEAR, &mut adj_v, &mut adj, &mut 0, (s, ag)).unwrap();
            let loss = || {
                let (val, gr) = volume_sample_grad(v, p, LINEAR).unwrap();
                s as f64 * val as f64 + ag.dot(gr) as f64
            };
            let b = p.to_array().map(|x| x.floor() as i32);
            let mut seen = HashSet::new();
            for c in 0..8 {
                let q = [b[0] + (c >> 2 & 1), b[1] + (c >> 1 & 1), b[2] + (c & 1)];
                let at = v.locate(q);
                if !seen.insert(at.offset) {
                    continue; // the background twin collects several corners
                }
                let old: f32 = v.value_at(at);
                let h = 0.125f32;
                g.put(at.offset, old + h);
                let up = loss();
                g.put(at.offset, old - h);
                let down = loss();
                g.put(at.offset, old);
                let fd = (up - down) / (2.0 * h as f64);
                let got: f32 = g.grad_at(at.offset);
                assert!(
                    (got as f64 - fd).abs() <= 1e-4,
                    "{p} {q:?} level {}: {got} vs {fd}",
                    at.level
                );
                // Reset for the next point.
                // SAFETY: the twin's value location.
                unsafe { f32::store(g.grad.add(at.offset as usize), 0.0) };
            }
            assert!(seen.len() >= 4, "the points reach several locations");
        }
        // CLOSEST and lookup: adj_ret lands on the one voxel.
        let p = Vec3::new(2.4, 3.5, 4.6);
        let mut sink = Vec3::ZERO;
        adj_volume_sample(v, p, CLOSEST, &mut adj_v, &mut sink, &mut 0, 2.0).unwrap();
        adj_volume_lookup(v, 2, 4, 5, &mut adj_v, &mut 0, &mut 0, &mut 0, 0.5).unwrap();
        assert_eq!(g.grad_at::<f32>(v.locate([2, 4, 5]).offset), 2.5);
    }

    #[test]
    fn concurrent_value_adjoints_add_up_exactly() {
        // 8 threads x 1000 adjoints at the centre of a cell: each corner gets 1/8 per call,
        // exact in f32, so the atomic sums are exact: 1000 each.
        let g = value_grid(&[[0, 0, 0]], BG, &unit(), true, |_| 1.0);
        let v = g.view::<f32>();
        std::thread::scope(|s| {
            for _ in 0..8 {
                s.spawn(move || {
                    let mut adj_v = VolumeView::<f32>::empty();
                    let mut sink = Vec3::ZERO;
                    for _ in 0..1000 {
                        let p = Vec3::new(2.5, 3.5, 4.5);
                        adj_volume_sample(v, p, LINEAR, &mut adj_v, &mut sink, &mut 0, 1.0)
                            .unwrap();
                    }
                });
            }
        });
        for c in 0..8 {
            let q = [2 + (c >> 2 & 1), 3 + (c >> 1 & 1), 4 + (c & 1)];
            assert_eq!(g.grad_at::<f32>(v.locate(q).offset), 1000.0, "{q:?}");
        }
    }

    #[test]
    fn concurrent_stores_are_all_seen() {
        let tiles = box_tiles([0, 0, 0], [15, 15, 15]);
        let g = value_grid(&tiles, BG, &unit(), false, |_| 0.0);
        let v = g.view::<f32>();
        let tiles = &tiles;
        std::thread::scope(|s| {
            for t in 0..4 {
                s.spawn(move || {
                    for_voxels(tiles, |p| {
                        if (p[0] + p[1] + p[2]) % 4 == t {
                            volume_store(v, p[0], p[1], p[2], hash(p)).unwrap();
                        }
                        // Reads race with the other threads' stores, which is allowed.
                        let _ = volume_lookup(v, p[2], p[1], p[0]).unwrap();
                    });
                });
            }
        });
        for_voxels(tiles, |p| {
            assert_eq!(volume_lookup(v, p[0], p[1], p[2]).unwrap(), hash(p))
        });
    }

    #[test]
    fn non_finite_positions_fault_and_huge_ones_are_background() {
        let g = value_grid(&[[0, 0, 0]], BG, &unit(), true, |_| 1.0);
        let v = g.view::<f32>().with_kernel_name("k");
        for bad in [
            Vec3::new(f32::NAN, 0.0, 0.0),
            Vec3::new(0.0, f32::INFINITY, 0.0),
            Vec3::new(0.0, 0.0, f32::NEG_INFINITY),
        ] {
            for mode in [CLOSEST, LINEAR, 7] {
                let e = volume_sample(v, bad, mode).unwrap_err();
                assert_eq!(e.kernel, "k");
                match &e.kind {
                    FaultKind::NonFinite { what, values } => {
                        assert_eq!(*what, "volume sample position");
                        assert_eq!(values.len(), 3);
                        for a in 0..3 {
                            assert!(values[a].to_bits() == (bad[a] as f64).to_bits());
                        }
                    }
                    k => panic!("{k:?}"),
                }
                assert!(e.to_string().contains("not finite"), "{e}");
                assert!(volume_sample_grad(v, bad, mode).is_err());
                let mut adj = Vec3::ZERO;
                let mut av = VolumeView::empty();
                assert!(adj_volume_sample(v, bad, mode, &mut av, &mut adj, &mut 0, 1.0).is_err());
            }
        }
        assert_eq!(VolumeView::<f32>::empty().kernel_name(), "?");
        // Finite but outside the i32 index range: the background, in both modes (the
        // corners beyond the range too), and its gradient goes to the background's twin.
        for p in [
            Vec3::new(1e10, 0.0, 0.0),
            Vec3::new(0.0, -3e38, 0.0),
            Vec3::new(2_147_483_648.0, 1.0, 1.0),
            Vec3::new(-2_147_483_904.0, 1.0, 1.0),
        ] {
            for mode in [CLOSEST, LINEAR] {
                assert_eq!(volume_sample(v, p, mode).unwrap(), BG, "{p}");
            }
            let mut adj = Vec3::ZERO;
            let mut av = VolumeView::empty();
            adj_volume_sample(v, p, LINEAR, &mut av, &mut adj, &mut 0, 1.0).unwrap();
            assert_eq!(adj, Vec3::ZERO);
        }
        assert_eq!(g.grad_at::<f32>(v.background as u64), 4.0);
    }

    #[test]
    fn the_ends_of_the_index_range() {
        // Leaves at the top and bottom of the i32 range, sampled where f32 can name a voxel.
        let f = |p: [i32; 3]| (p[1] * 8 + p[2]) as f32;
        let tiles = [
            [2_147_483_520, 0, 0],
            [i32::MIN, 0, 0],
            [i32::MAX - 7, 0, 0],
        ];
        let g = value_grid(&tiles, BG, &unit(), false, f);
        let v = g.view::<f32>();
        let top = Vec3::new(2_147_483_520.0, 2.0, 3.0);
        assert_eq!(volume_sample(v, top, CLOSEST).unwrap(), f([0, 2, 3]));
        assert_eq!(volume_sample(v, top, LINEAR).unwrap(), f([0, 2, 3]));
        let bottom = Vec3::new(-2_147_483_648.0, 1.5, 3.0);
        assert_eq!(
            volume_sample(v, bottom, LINEAR).unwrap(),
            0.5 * (f([0, 1, 3]) + f([0, 2, 3]))
        );
        // Lookups at the very ends.
        assert_eq!(volume_lookup(v, i32::MAX, 7, 7).unwrap(), f([0, 7, 7]));
        assert_eq!(volume_lookup(v, i32::MIN, 1, 1).unwrap(), f([0, 1, 1]));
        assert_eq!(volume_lookup(v, i32::MAX, 8, 7).unwrap(), BG);
    }

    #[test]
    fn transforms_use_the_map_and_their_adjoints_its_transpose() {
        // Warp's anisotropic, non-symmetric example; the stored voxel size is the row sums.
        let map = Map {
            mat: [[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 3.0]],
            translation: [0.5, -1.0, 2.0],
        };
        let g = value_grid(&[[0, 0, 0]], BG, &map, false, |_| 0.0);
        let v = g.view::<f32>();
        let vs: [f64; 3] = core::array::from_fn(|k| {
            // SAFETY: GridData's voxelSize, inside the grid.
            unsafe { (g.data.add(608 + 8 * k) as *const f64).read() }
        });
        assert_eq!(vs, [3.0, 1.0, 3.0]);
        let p = Vec3::new(1.0, 2.0, 3.0);
        let w = volume_index_to_world(v, p).unwrap();
        assert_eq!(w, Vec3::new(1.0 + 4.0 + 0.5, 2.0 - 1.0, 9.0 + 2.0));
        assert_eq!(volume_world_to_index(v, w).unwrap(), p);
        assert_eq!(
            volume_index_to_world_dir(v, p).unwrap(),
            Vec3::new(5.0, 2.0, 9.0)
        );
        assert_eq!(
            volume_world_to_index_dir(v, Vec3::new(5.0, 2.0, 9.0)).unwrap(),
            p
        );
        // Adjoints: Mᵀ adj. Warp's f32 overloads would give M adj = (21, 10, 300) here.
        let mut av = VolumeView::empty();
        let a = Vec3::new(1.0, 10.0, 100.0);
        for adj_fn in [
            adj_volume_index_to_world::<f32>,
            adj_volume_index_to_world_dir::<f32>,
        ] {
            let mut adj = Vec3::ZERO;
            adj_fn(v, p, &mut av, &mut adj, a).unwrap();
            assert_eq!(adj, Vec3::new(1.0, 12.0, 300.0));
        }
        // M⁻ᵀ adj, against central differences of dot(a, world_to_index(x)) (linear: exact
        // up to f32 rounding of values below 200).
        for adj_fn in [
            adj_volume_world_to_index::<f32>,
            adj_volume_world_to_index_dir::<f32>,
        ] {
            let mut adj = Vec3::ZERO;
            adj_fn(v, w, &mut av, &mut adj, a).unwrap();
            for k in 0..3 {
                let fd = central(
                    |q| a.dot(volume_world_to_index(v, q).unwrap()) as f64,
                    w,
                    k,
                    0.5,
                );
                assert!((adj[k] as f64 - fd).abs() < 1e-3, "{k}: {} vs {fd}", adj[k]);
            }
            // invMatF = [[1, -2, 0], [0, 1, 0], [0, 0, f32(1/3)]].
            assert_eq!(adj, Vec3::new(1.0, 8.0, 100.0 * (1.0f64 / 3.0) as f32));
        }
        for k in 0..3 {
            let mut adj = Vec3::ZERO;
            adj_volume_index_to_world(v, p, &mut av, &mut adj, a).unwrap();
            let fd = central(
                |q| a.dot(volume_index_to_world(v, q).unwrap()) as f64,
                p,
                k,
                0.5,
            );
            assert!((adj[k] as f64 - fd).abs() < 1e-3);
        }
    }

    /// An `ArrayView` over `v` (kept alive by the caller).
    fn array<T: Copy>(v: &mut [T]) -> ArrayView<T, 1> {
        // SAFETY: the slice outlives every use in the tests.
        unsafe { ArrayView::new(v.as_mut_ptr(), [v.len()], [1], "k", "data") }
    }

    #[test]
    fn index_variants_on_an_index_grid() {
        let tiles = vec![[0, 0, 0], [8, 0, 0], [-8, 0, 0], [0, 128, 0], [4096, 0, 0]];
        let bytes = build_from_tiles(BuildKind::Index, &tiles, &unit()).unwrap();
        let g = Grid::new(bytes, None);
        let v = g.view::<VoxelIndex>();
        assert_eq!(v.grid_type(), GridType::Index);
        // Indices: every voxel of leaf L has L*512 + n, and they cover 0..5*512 once.
        let mut seen = vec![false; tiles.len() * 512];
        for_voxels(&tiles, |p| {
            let i = volume_lookup_index(v, p[0], p[1], p[2]).unwrap();
            assert!(!std::mem::replace(&mut seen[i as usize], true));
            assert_eq!(
                i as u32 % 512,
                ((p[0] & 7) << 6 | (p[1] & 7) << 3 | (p[2] & 7)) as u32
            );
        });
        assert!(seen.iter().all(|&s| s));
        assert_eq!(volume_lookup_index(v, 16, 0, 0).unwrap(), -1);
        assert_eq!(volume_lookup_index(v, 0, 0, -1).unwrap(), -1);
        // Values by index: sampling reproduces the dense reference (data[idx] = f(voxel)).
        let f = |p: [i32; 3]| hash(p) / 100.0;
        let mut data = vec![0.0f32; tiles.len() * 512];
        for_voxels(&tiles, |p| {
            data[volume_lookup_index(v, p[0], p[1], p[2]).unwrap() as usize] = f(p)
        });
        let d = Dense::new(&tiles, BG, &f);
        let av = array(&mut data);
        let mut rng = Rng(3);
        for _ in 0..3000 {
            let uvw = Vec3::new(
                rng.f32(-10.0, 18.0),
                rng.f32(-2.0, 10.0),
                rng.f32(-2.0, 10.0),
            );
            let got = volume_sample_index(v, uvw, LINEAR, &av, BG).unwrap() as f64;
            assert!((got - trilinear(&d, uvw)).abs() <= 16.0 * f32::EPSILON as f64 * 700.0);
            let c = uvw.to_array().map(|x| x.round() as i64);
            assert_eq!(
                volume_sample_index(v, uvw, CLOSEST, &av, BG).unwrap(),
                d.at(c)
            );
            let (val, _) = volume_sample_grad_index(v, uvw, LINEAR, &av, BG).unwrap();
            assert_eq!(val as f64, got);
        }
        // A value array too short: the array's fault.
        let mut short = vec![0.0f32; 10];
        let e = volume_sample_index(v, Vec3::new(5.0, 5.0, 5.0), CLOSEST, &array(&mut short), BG)
            .unwrap_err();
        assert!(
            matches!(e.kind, FaultKind::OutOfBounds { arg: "data", .. }),
            "{e}"
        );
    }

    #[test]
    fn index_variants_on_an_on_index_grid() {
        // Sparse active voxels: inactive ones (even in allocated leaves) have no index.
        let mut rng = Rng(17);
        let mut voxels: Vec<[i32; 3]> = (0..600)
            .map(|_| [rng.i32(-20, 20), rng.i32(-20, 20), rng.i32(-3, 3)])
            .collect();
        voxels.push([-4097, 5, 5]);
        voxels.push([i32::MAX, 0, 0]);
        let active: HashSet<[i32; 3]> = voxels.iter().copied().collect();
        let bytes = build_from_voxels(&voxels, &unit()).unwrap();
        let g = Grid::new(bytes, None);
        let v = g.view::<VoxelIndex>();
        assert_eq!(v.grid_type(), GridType::OnIndex);
        let mut seen = vec![false; active.len()];
        for_voxels(&voxels, |p| {
            let i = volume_lookup_index(v, p[0], p[1], p[2]).unwrap();
            if active.contains(&p) {
                assert!(!std::mem::replace(&mut seen[i as usize], true), "{p:?}");
            } else {
                assert_eq!(i, -1, "{p:?}");
            }
        });
        assert!(seen.iter().all(|&s| s));
        // Sampling: data at active voxels, the background at inactive ones.
        let f = |p: [i32; 3]| hash(p) / 100.0;
        let mut data = vec![0.0f32; active.len()];
        for p in &active {
            data[volume_lookup_index(v, p[0], p[1], p[2]).unwrap() as usize] = f(*p);
        }
        let fa = |p: [i32; 3]| if active.contains(&p) { f(p) } else { BG };
        let d = Dense::new(&voxels, BG, &fa);
        let av = array(&mut data);
        for _ in 0..3000 {
            let uvw = Vec3::new(
                rng.f32(-22.0, 22.0),
                rng.f32(-22.0, 22.0),
                rng.f32(-5.0, 5.0),
            );
            let got = volume_sample_index(v, uvw, LINEAR, &av, BG).unwrap() as f64;
            assert!((got - trilinear(&d, uvw)).abs() <= 16.0 * f32::EPSILON as f64 * 700.0);
        }
        // Position adjoint: the gradient (f32 data: bit for bit), and central differences.
        let mut avv = VolumeView::empty();
        for _ in 0..300 {
            let p = in_cell(&mut rng, -18.0, 18.0);
            let (_, grad) = volume_sample_grad_index(v, p, LINEAR, &av, BG).unwrap();
            let mut adj = Vec3::ZERO;
            let (mut gd, mut gbg) = (GradView::none(), 0.0);
            adj_volume_sample_index(
                v, p, LINEAR, &av, BG, &mut avv, &mut adj, &mut 0, &mut gd, &mut gbg, 1.0,
            )
            .unwrap();
            assert_eq!(adj, grad);
            let ag = Vec3::new(1.0, -0.5, 0.25);
            let loss = |q: Vec3| {
                let (val, gr) = volume_sample_grad_index(v, q, LINEAR, &av, BG).unwrap();
                val as f64 + ag.dot(gr) as f64
            };
            let mut adj = Vec3::ZERO;
            adj_volume_sample_grad_index(
                v,
                p,
                LINEAR,
                &av,
                BG,
                &mut avv,
                &mut adj,
                &mut 0,
                &mut gd,
                &mut gbg,
                (1.0, ag),
            )
            .unwrap();
            for a in 0..3 {
                let fd = central(loss, p, a, 0.25);
                assert!(
                    (adj[a] as f64 - fd).abs() <= 64.0 * f32::EPSILON as f64 * 700.0 / 0.25 * 4.0
                );
            }
        }
        // Value adjoints: every tap's weight lands on its voxel's data entry or on the
        // background, so with a seed of 1 they sum to 1 (Warp's check); CLOSEST puts the whole
        // seed on one of them.
        for mode in [LINEAR, CLOSEST] {
            for _ in 0..200 {
                let p = Vec3::new(
                    rng.f32(-22.0, 22.0),
                    rng.f32(-22.0, 22.0),
                    rng.f32(-5.0, 5.0),
                );
                let mut gdata = vec![0.0f32; data.len()];
                let mut gd = GradView::new(array(&mut gdata));
                let (mut adj, mut gbg) = (Vec3::ZERO, 0.0f32);
                adj_volume_sample_index(
                    v, p, mode, &av, BG, &mut avv, &mut adj, &mut 0, &mut gd, &mut gbg, 1.0,
                )
                .unwrap();
                let total: f64 = gdata.iter().map(|x| *x as f64).sum::<f64>() + gbg as f64;
                // Eight f32 weights, each within an ulp of its product: 1e-6.
                assert!((total - 1.0).abs() <= 1e-6, "{mode}: {total} at {p}");
                if mode == CLOSEST {
                    let ones = gdata.iter().filter(|x| **x == 1.0).count() + (gbg == 1.0) as usize;
                    assert_eq!(ones, 1, "at {p}");
                }
            }
        }
    }

    #[test]
    fn index_variants_on_a_value_grid() {
        // Value grids index their leaves' voxels as Index grids do: leafId*512 + n (+1).
        let tiles = vec![[0, 0, 0], [8, 0, 0], [0, 0, -8]];
        let g = value_grid(&tiles, BG, &unit(), false, |_| 0.0);
        let v = g.view::<f32>();
        let mut seen = HashSet::new();
        for_voxels(&tiles, |p| {
            let i = volume_lookup_index(v, p[0], p[1], p[2]).unwrap();
            let at = v.locate(p);
            let leaf = at.offset - v.leaf_table as u64 - 4 * leaf_voxel(p);
            let id = (leaf - v.first_leaf) / v.leaf_size as u64;
            assert_eq!(i as u64, id * 512 + leaf_voxel(p));
            assert!(seen.insert(i));
        });
        assert_eq!(volume_lookup_index(v, 100, 0, 0).unwrap(), -1);
        let mut data: Vec<f32> = (0..tiles.len() * 512).map(|k| k as f32).collect();
        let av = array(&mut data);
        let i = volume_lookup_index(v, 9, 1, 2).unwrap();
        assert_eq!(
            volume_sample_index(v, Vec3::new(9.0, 1.0, 2.0), CLOSEST, &av, BG).unwrap(),
            i as f32
        );
        assert_eq!(
            volume_sample_index(v, Vec3::new(99.0, 1.0, 2.0), CLOSEST, &av, BG).unwrap(),
            BG
        );
    }

    #[test]
    fn vec3_grids() {
        // (i+2j+3k, 4i+5j+6k, 7i+8j+9k): linear, so LINEAR reproduces it and the gradient
        // is the matrix (rows = components); exact here (small integers and halves).
        let m = Mat3::from_cols(
            Vec3::new(1.0, 4.0, 7.0),
            Vec3::new(2.0, 5.0, 8.0),
            Vec3::new(3.0, 6.0, 9.0),
        );
        let f = move |p: [i32; 3]| m * Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32);
        let tiles = box_tiles([-8, -8, -8], [7, 7, 7]);
        let bg = Vec3::new(1.0, 2.0, 3.0);
        let g = value_grid(&tiles, bg, &unit(), true, f);
        let v = g.view::<Vec3>();
        let p = Vec3::new(1.5, -2.5, 0.25);
        assert_eq!(volume_sample(v, p, LINEAR).unwrap(), m * p);
        let (val, grad) = volume_sample_grad(v, p, LINEAR).unwrap();
        assert_eq!((val, grad), (m * p, m));
        assert_eq!(volume_sample(v, p, CLOSEST).unwrap(), f([2, -3, 0]));
        assert_eq!(volume_lookup(v, 100, 0, 0).unwrap(), bg);
        // Position adjoint = gradientᵀ adj_ret; and with adj_grad, central differences of
        // L = dot(a, val) + sum(AG ∘ grad) (the value is linear: the Hessian term is zero
        // here, so also check on a non-linear field below).
        let a = Vec3::new(0.5, -1.0, 2.0);
        let mut adj = Vec3::ZERO;
        let mut av = VolumeView::empty();
        adj_volume_sample(v, p, LINEAR, &mut av, &mut adj, &mut 0, a).unwrap();
        assert_eq!(adj, m.transpose() * a);
        // The value gradient of a corner: w * a per component.
        let w: f32 = 0.5 * 0.5 * 0.75;
        assert_eq!(g.grad_at::<Vec3>(v.locate([1, -3, 0]).offset), w * a);

        let h = |p: [i32; 3]| {
            Vec3::new(hash(p), hash([p[1], p[2], p[0]]), hash([p[2], p[0], p[1]])) / 1000.0
        };
        let g2 = value_grid(&tiles, bg, &unit(), false, h);
        let v2 = g2.view::<Vec3>();
        let ag = Mat3::from_cols(
            Vec3::new(1.0, 0.5, -0.25),
            Vec3::new(0.0, 2.0, 1.0),
            Vec3::new(-1.0, 0.0, 0.5),
        );
        let mut rng = Rng(23);
        for _ in 0..300 {
            let p = in_cell(&mut rng, -8.0, 6.0);
            let loss = |q: Vec3| {
                let (val, gr) = volume_sample_grad(v2, q, LINEAR).unwrap();
                let s: f32 = (0..3).map(|c| ag.col(c).dot(gr.col(c))).sum();
                a.dot(val) as f64 + s as f64
            };
            let (_, gr) = volume_sample_grad(v2, p, LINEAR).unwrap();
            let mut adj = Vec3::ZERO;
            adj_volume_sample_grad(v2, p, LINEAR, &mut av, &mut adj, &mut 0, (a, ag)).unwrap();
            for k in 0..3 {
                let fd = central(loss, p, k, 0.25);
                assert!(
                    (adj[k] as f64 - fd).abs() <= 2e-3,
                    "{p} {k}: {} vs {fd}",
                    adj[k]
                );
                // The gradient's column k is the central difference of the value.
                let fdv = [0, 1, 2].map(|c| {
                    central(
                        |q| volume_sample(v2, q, LINEAR).unwrap()[c] as f64,
                        p,
                        k,
                        0.25,
                    )
                });
                for (c, fd) in fdv.into_iter().enumerate() {
                    assert!((gr.col(k)[c] as f64 - fd).abs() <= 2e-3);
                }
            }
        }
    }

    #[test]
    fn f64_and_dvec3_grids() {
        let f = |p: [i32; 3]| {
            0.1 * p[0] as f64 + 0.2 * p[1] as f64 - 0.3 * p[2] as f64
                + 1e-3 * (p[0] * p[1] * p[2]) as f64
        };
        let tiles = box_tiles([-8, -8, -8], [7, 7, 7]);
        let g = value_grid(&tiles, -1.0f64, &unit(), true, f);
        let v = g.view::<f64>();
        assert_eq!(volume_lookup(v, 1, 2, 3).unwrap(), f([1, 2, 3]));
        assert_eq!(volume_lookup(v, 9, 2, 3).unwrap(), -1.0);
        // Trilinear reproduced up to the f32 weights (about 4 ulp of f32 relative).
        let mut rng = Rng(31);
        for _ in 0..1000 {
            let p = Vec3::new(rng.f32(-8.0, 6.9), rng.f32(-8.0, 6.9), rng.f32(-8.0, 6.9));
            let q = p.to_array().map(|x| x as f64);
            let want = 0.1 * q[0] + 0.2 * q[1] - 0.3 * q[2] + 1e-3 * q[0] * q[1] * q[2];
            let got = volume_sample(v, p, LINEAR).unwrap();
            assert!(
                (got - want).abs() <= 8.0 * f32::EPSILON as f64 * 4.0,
                "{p}: {got} vs {want}"
            );
        }
        let mut av = VolumeView::empty();
        adj_volume_lookup(v, 1, 2, 3, &mut av, &mut 0, &mut 0, &mut 0, 0.5).unwrap();
        assert_eq!(g.grad_at::<f64>(v.locate([1, 2, 3]).offset), 0.5);

        let fv = |p: [i32; 3]| DVec3::new(p[0] as f64, 2.0 * p[1] as f64, -(p[2] as f64));
        let g = value_grid(&tiles, DVec3::ZERO, &unit(), true, fv);
        let v = g.view::<DVec3>();
        let p = Vec3::new(0.5, 1.25, -3.75);
        assert_eq!(
            volume_sample(v, p, LINEAR).unwrap(),
            DVec3::new(0.5, 2.5, 3.75)
        );
        let (_, grad) = volume_sample_grad(v, p, LINEAR).unwrap();
        assert_eq!(grad, DMat3::from_diagonal(DVec3::new(1.0, 2.0, -1.0)));
        let mut adj = Vec3::ZERO;
        let mut av = VolumeView::empty();
        adj_volume_sample(v, p, LINEAR, &mut av, &mut adj, &mut 0, DVec3::ONE).unwrap();
        assert_eq!(adj, Vec3::new(1.0, 2.0, -1.0));
        volume_store(v, 0, 0, 0, DVec3::splat(9.0)).unwrap();
        assert_eq!(volume_lookup(v, 0, 0, 0).unwrap(), DVec3::splat(9.0));
    }

    #[test]
    fn i32_grids_look_up_and_store() {
        let tiles = [[0, 0, 0], [-8, -8, -8]];
        let f = |p: [i32; 3]| p[0] * 10000 + p[1] * 100 + p[2];
        let g = value_grid(&tiles, -1i32, &unit(), false, f);
        let v = g.view::<i32>();
        for_voxels(&tiles, |p| {
            assert_eq!(volume_lookup(v, p[0], p[1], p[2]).unwrap(), f(p))
        });
        assert_eq!(volume_lookup(v, 8, 0, 0).unwrap(), -1);
        volume_store(v, -1, -2, -3, i32::MIN).unwrap();
        assert_eq!(volume_lookup(v, -1, -2, -3).unwrap(), i32::MIN);
        let mut av = VolumeView::empty();
        adj_volume_lookup(v, 0, 0, 0, &mut av, &mut 0, &mut 0, &mut 0, 5).unwrap();
    }

    #[test]
    fn the_empty_view_is_an_empty_grid() {
        let v = VolumeView::<f32>::empty();
        assert_eq!(
            volume_sample(v, Vec3::new(1.5, 2.0, 3.0), LINEAR).unwrap(),
            0.0
        );
        assert_eq!(volume_lookup(v, 0, 0, 0).unwrap(), 0.0);
        volume_store(v, 0, 0, 0, 1.0).unwrap();
        assert_eq!(volume_index_to_world(v, Vec3::ONE).unwrap(), Vec3::ZERO);
        assert_eq!(
            volume_lookup_index(VolumeView::<VoxelIndex>::empty(), 0, 0, 0).unwrap(),
            -1
        );
        assert_eq!(
            volume_sample(VolumeView::<DVec3>::empty(), Vec3::ONE, LINEAR).unwrap(),
            DVec3::ZERO
        );
    }

    /// The module docs' LINEAR formulas written out directly for a scalar grid, in `S`:
    /// `(value, gradient, position adjoint of sample_grad for (s, ag))`.
    fn spec_linear<S: VolumeSample<Scalar = S> + VolumeScalar>(
        v: VolumeView<S>,
        uvw: Vec3,
        s: S,
        ag: [S; 3],
    ) -> (S, [S; 3], [f32; 3]) {
        let b = [uvw.x.floor(), uvw.y.floor(), uvw.z.floor()];
        let f = [uvw.x - b[0], uvw.y - b[1], uvw.z - b[2]];
        let (wx, wy, wz) = ([1.0 - f[0], f[0]], [1.0 - f[1], f[1]], [1.0 - f[2], f[2]]);
        let mut val = S::zero();
        let mut grad = [S::zero(); 3];
        let mut adj = [0.0f32; 3];
        for c in 0..8 {
            let o = [(c >> 2) & 1, (c >> 1) & 1, c & 1];
            let sg = o.map(|x| if x == 1 { 1.0f32 } else { -1.0 });
            let x: S = v.value_at(v.locate([0, 1, 2].map(|a| b[a] as i32 + o[a] as i32)));
            let w = S::from_f32((wx[o[0]] * wy[o[1]]) * wz[o[2]]);
            let gw = [
                (sg[0] * wy[o[1]]) * wz[o[2]],
                (sg[1] * wx[o[0]]) * wz[o[2]],
                (sg[2] * wx[o[0]]) * wy[o[1]],
            ]
            .map(S::from_f32);
            let h = [
                (sg[0] * sg[1]) * wz[o[2]],
                (sg[0] * sg[2]) * wy[o[1]],
                (sg[1] * sg[2]) * wx[o[0]],
            ]
            .map(S::from_f32);
            val = val + w * x;
            for a in 0..3 {
                grad[a] = grad[a] + x * gw[a];
            }
            let d = x * s;
            let r = [x * ag[0], x * ag[1], x * ag[2]];
            let hv = [
                r[1] * h[0] + r[2] * h[1],
                r[0] * h[0] + r[2] * h[2],
                r[0] * h[1] + r[1] * h[2],
            ];
            for a in 0..3 {
                adj[a] += (d * gw[a]).to_f32();
                adj[a] += hv[a].to_f32();
            }
        }
        (val, grad, adj)
    }

    #[test]
    fn linear_follows_the_documented_order_bit_for_bit() {
        // Values with full mantissas, so any change of the order of operations shows in the
        // last bits (the CUDA mirror must match these bit for bit).
        let f = |p: [i32; 3]| hash(p) / 7.0 + 0.1;
        let tiles = box_tiles([-8, -8, -8], [7, 7, 7]);
        let g32 = value_grid(&tiles, BG, &unit(), false, f);
        let g64 = value_grid(&tiles, BG as f64 / 3.0, &unit(), false, |p| {
            f(p) as f64 / 3.0
        });
        let (v32, v64) = (g32.view::<f32>(), g64.view::<f64>());
        let mut rng = Rng(1234);
        let mut av32 = VolumeView::empty();
        let mut av64 = VolumeView::empty();
        for _ in 0..2000 {
            let p = Vec3::new(rng.f32(-9.0, 8.0), rng.f32(-9.0, 8.0), rng.f32(-9.0, 8.0));
            let (s, ag) = (
                rng.f32(-2.0, 2.0),
                [rng.f32(-2.0, 2.0), rng.f32(-2.0, 2.0), rng.f32(-2.0, 2.0)],
            );
            let (val, grad, adj) = spec_linear(v32, p, s, ag);
            assert_eq!(
                volume_sample(v32, p, LINEAR).unwrap().to_bits(),
                val.to_bits()
            );
            let (gv, gg) = volume_sample_grad(v32, p, LINEAR).unwrap();
            assert_eq!(
                (gv.to_bits(), gg.to_array().map(f32::to_bits)),
                (val.to_bits(), grad.map(f32::to_bits))
            );
            let mut got = Vec3::ZERO;
            adj_volume_sample_grad(
                v32,
                p,
                LINEAR,
                &mut av32,
                &mut got,
                &mut 0,
                (s, Vec3::from(ag)),
            )
            .unwrap();
            assert_eq!(
                got.to_array().map(f32::to_bits),
                adj.map(f32::to_bits),
                "{p}"
            );

            let ag64 = ag.map(|x| x as f64);
            let (val, grad, adj) = spec_linear(v64, p, s as f64, ag64);
            assert_eq!(
                volume_sample(v64, p, LINEAR).unwrap().to_bits(),
                val.to_bits()
            );
            let (gv, gg) = volume_sample_grad(v64, p, LINEAR).unwrap();
            assert_eq!(
                (gv.to_bits(), gg.to_array().map(f64::to_bits)),
                (val.to_bits(), grad.map(f64::to_bits))
            );
            let mut got = Vec3::ZERO;
            adj_volume_sample_grad(
                v64,
                p,
                LINEAR,
                &mut av64,
                &mut got,
                &mut 0,
                (s as f64, DVec3::from(ag64)),
            )
            .unwrap();
            assert_eq!(
                got.to_array().map(f32::to_bits),
                adj.map(f32::to_bits),
                "{p}"
            );
        }
    }

    #[test]
    fn the_accessor_cache_gives_the_uncached_addresses() {
        // Random walks with short and long jumps through a grid with many nodes: every cached
        // lookup must equal the uncached one.
        let mut tiles = box_tiles([-24, -24, -24], [23, 23, 23]);
        tiles.extend(box_tiles([120, 120, 0], [135, 135, 7]));
        tiles.extend([[4096, 0, 0], [-4097, 0, 0], [0, 5000, 0]]);
        let g = value_grid(&tiles, BG, &unit(), false, hash);
        let v = g.view::<f32>();
        let mut rng = Rng(41);
        let mut acc = Accessor::new();
        let mut p = [0i32; 3];
        for _ in 0..200_000 {
            let r = rng.next();
            let step = match r % 7 {
                0 => 4096,
                1 => 128,
                2 | 3 => 8,
                _ => 1,
            };
            let a = (r >> 8) as usize % 3;
            p[a] += if r >> 16 & 1 == 0 { step } else { -step };
            if r.is_multiple_of(997) {
                p = [rng.i32(-30, 140), rng.i32(-30, 140), rng.i32(-30, 30)];
            }
            assert_eq!(v.locate_cached(p, &mut acc), v.locate(p), "{p:?}");
        }
    }
}
