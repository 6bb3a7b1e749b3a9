//! Atomic builtins on array elements: real CPU atomics.
//!
//! `atomic_add`, `atomic_sub`, `atomic_min` and `atomic_max` read-modify-write one element of
//! an [`ArrayView`] atomically and return the element's old value, like Warp's builtins of the
//! same names (and CUDA's `atomicAdd` family underneath them).
//!
//! * Integers (`i32`, `u32`, `i64`, `u64`) use the std atomic types' `fetch_*` operations on
//!   the element itself (`Atomic*::from_ptr`); `add`/`sub` wrap, as in CUDA.
//! * Floats (`f32`, `f64`, `f16`) use a compare-exchange loop on the bit pattern through
//!   `AtomicU32`/`AtomicU64`/`AtomicU16`. `min`/`max` use IEEE `fmin`/`fmax` semantics (a NaN operand
//!   loses to the other), the same as the [`min`](super::min)/[`max`](super::max) builtins.
//!   `sub` is `add` of the negated value, which is the same IEEE result.
//! * Float vectors (`Vec2/3/4`, `DVec2/3/4`) are updated componentwise, `x` first, each
//!   component atomic on its own. The vector as a whole is **not** updated atomically, exactly
//!   as in Warp/CUDA: another thread may observe (or interleave with) a partially updated
//!   vector, and the returned "old" vector is assembled from the per-component old values.
//!
//! Memory ordering is `Relaxed` throughout. That matches CUDA's `atomicAdd` (relaxed, device
//! scope) and is sufficient: an atomic builtin only promises that concurrent updates of the
//! same element are not lost, never an ordering with other memory accesses of the launch, and
//! a kernel launch is a synchronisation point — the executor joins every worker thread before
//! the launch returns, which makes all effects (atomic or not) visible to the host afterwards.
//!
//! Bounds are checked by [`ArrayView::ptr_at`]; an out-of-bounds index returns its fault and
//! touches no memory.

use std::sync::atomic::{AtomicI32, AtomicI64, AtomicU16, AtomicU32, AtomicU64, Ordering::Relaxed};

use half::{bf16, f16};

use glam::{DVec2, DVec3, DVec4, Vec2, Vec3, Vec4};

use crate::fault::KResult;
use crate::index::KernelIndex;
use crate::view::ArrayView;

/// An element type the atomic builtins accept: `i32`, `u32`, `i64`, `u64`, `f32`, `f64`, `f16`, `bf16`,
/// `Vec2/3/4`, `DVec2/3/4`.
///
/// Each operation stores the new value and returns the old one.
///
/// # Safety (of every method)
/// `p` must point to a live, properly aligned `Self` that, for the duration of the call, is
/// accessed by other threads only through these atomic operations (the concurrency contract
/// of [`ArrayView`]: concurrent non-atomic writes to the same element are a race).
pub trait AtomicElement: Copy {
    /// `*p = *p + v` (wrapping for integers); returns the old value.
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn atomic_add(p: *mut Self, v: Self) -> Self;
    /// `*p = *p - v` (wrapping for integers); returns the old value.
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn atomic_sub(p: *mut Self, v: Self) -> Self;
    /// `*p = min(*p, v)` (IEEE `fmin` for floats); returns the old value.
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn atomic_min(p: *mut Self, v: Self) -> Self;
    /// `*p = max(*p, v)` (IEEE `fmax` for floats); returns the old value.
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn atomic_max(p: *mut Self, v: Self) -> Self;
}

/// Atomically adds `value` to `arr[idx]` and returns the old value.
#[inline(always)]
pub fn atomic_add<T: AtomicElement, const N: usize, I: KernelIndex<N>>(
    arr: &ArrayView<T, N>,
    idx: I,
    value: T,
) -> KResult<T> {
    let p = arr.ptr_at(idx)?;
    // SAFETY: `ptr_at` checked the index, so `p` addresses a live, aligned element of the
    // view's allocation (`ArrayView::new`'s contract); concurrent access to it from other
    // kernel threads is atomic per the view's concurrency contract.
    Ok(unsafe { T::atomic_add(p, value) })
}

/// Atomically subtracts `value` from `arr[idx]` and returns the old value.
#[inline(always)]
pub fn atomic_sub<T: AtomicElement, const N: usize, I: KernelIndex<N>>(
    arr: &ArrayView<T, N>,
    idx: I,
    value: T,
) -> KResult<T> {
    let p = arr.ptr_at(idx)?;
    // SAFETY: as in `atomic_add`: in-bounds, aligned, live, atomically shared.
    Ok(unsafe { T::atomic_sub(p, value) })
}

/// Atomically sets `arr[idx]` to `min(arr[idx], value)` and returns the old value.
#[inline(always)]
pub fn atomic_min<T: AtomicElement, const N: usize, I: KernelIndex<N>>(
    arr: &ArrayView<T, N>,
    idx: I,
    value: T,
) -> KResult<T> {
    let p = arr.ptr_at(idx)?;
    // SAFETY: as in `atomic_add`: in-bounds, aligned, live, atomically shared.
    Ok(unsafe { T::atomic_min(p, value) })
}

/// Atomically sets `arr[idx]` to `max(arr[idx], value)` and returns the old value.
#[inline(always)]
pub fn atomic_max<T: AtomicElement, const N: usize, I: KernelIndex<N>>(
    arr: &ArrayView<T, N>,
    idx: I,
    value: T,
) -> KResult<T> {
    let p = arr.ptr_at(idx)?;
    // SAFETY: as in `atomic_add`: in-bounds, aligned, live, atomically shared.
    Ok(unsafe { T::atomic_max(p, value) })
}

// ------------------------------------------------------------------------------------------
// Integers: native fetch_* operations.
// ------------------------------------------------------------------------------------------

macro_rules! atomic_int {
    ($($t:ty => $a:ty),*) => {$(
        impl AtomicElement for $t {
            #[inline(always)]
            unsafe fn atomic_add(p: *mut Self, v: Self) -> Self {
                // SAFETY: the caller guarantees `p` is live and aligned for `Self` and only
                // accessed atomically; `from_ptr` needs the atomic type's alignment, which
                // is checked in debug builds (it equals the integer's on 64-bit targets).
                unsafe { atomic_ref::<$t, $a>(p) }.fetch_add(v, Relaxed)
            }
            #[inline(always)]
            unsafe fn atomic_sub(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_add`.
                unsafe { atomic_ref::<$t, $a>(p) }.fetch_sub(v, Relaxed)
            }
            #[inline(always)]
            unsafe fn atomic_min(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_add`.
                unsafe { atomic_ref::<$t, $a>(p) }.fetch_min(v, Relaxed)
            }
            #[inline(always)]
            unsafe fn atomic_max(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_add`.
                unsafe { atomic_ref::<$t, $a>(p) }.fetch_max(v, Relaxed)
            }
        }
    )*};
}
atomic_int!(i32 => AtomicI32, u32 => AtomicU32, i64 => AtomicI64, u64 => AtomicU64);

/// Views the value at `p` as the atomic type `A` of the same size.
///
/// # Safety
/// `p` must be live, aligned for `A`, and accessed only atomically while the reference lives.
#[inline(always)]
unsafe fn atomic_ref<'a, T, A>(p: *mut T) -> &'a A
where
    A: FromPtr<T>,
{
    debug_assert_eq!(size_of::<T>(), size_of::<A>());
    debug_assert!(p.cast::<A>().is_aligned(), "misaligned atomic element");
    // SAFETY: forwarded to the caller.
    unsafe { A::from_ptr(p) }
}

/// `Atomic*::from_ptr`, generically.
trait FromPtr<T> {
    /// # Safety
    /// As `AtomicI32::from_ptr`.
    unsafe fn from_ptr<'a>(p: *mut T) -> &'a Self;
}
macro_rules! from_ptr {
    ($($t:ty => $a:ty),*) => {$(
        impl FromPtr<$t> for $a {
            #[inline(always)]
            unsafe fn from_ptr<'a>(p: *mut $t) -> &'a Self {
                // SAFETY: forwarded to the caller (live, aligned, atomic-only access).
                unsafe { <$a>::from_ptr(p.cast()) }
            }
        }
    )*};
}
from_ptr!(i32 => AtomicI32, u32 => AtomicU32, i64 => AtomicI64, u64 => AtomicU64);
from_ptr!(f32 => AtomicU32, f64 => AtomicU64, f16 => AtomicU16, bf16 => AtomicU16);

// ------------------------------------------------------------------------------------------
// Floats: compare-exchange loop on the bit pattern.
// ------------------------------------------------------------------------------------------

macro_rules! atomic_float {
    ($($t:ident => $a:ty),*) => {$(
        impl AtomicElement for $t {
            #[inline(always)]
            unsafe fn atomic_add(p: *mut Self, v: Self) -> Self {
                // SAFETY: as `atomic_rmw` requires, forwarded from the caller.
                unsafe { float_rmw(p, |x: $t| x + v) }
            }
            #[inline(always)]
            unsafe fn atomic_sub(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_add`.
                unsafe { float_rmw(p, |x: $t| x - v) }
            }
            #[inline(always)]
            unsafe fn atomic_min(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_add`.
                unsafe { float_rmw(p, |x: $t| $t::min(x, v)) }
            }
            #[inline(always)]
            unsafe fn atomic_max(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_add`.
                unsafe { float_rmw(p, |x: $t| $t::max(x, v)) }
            }
        }
    )*};
}
atomic_float!(f32 => AtomicU32, f64 => AtomicU64);

/// A float whose bit pattern lives in an unsigned atomic.
trait FloatBits: Copy {
    type Atomic: FromPtr<Self>;
    fn cas_loop(a: &Self::Atomic, f: impl Fn(Self) -> Self) -> Self;
}
macro_rules! float_bits {
    ($($t:ident => $a:ty),*) => {$(
        impl FloatBits for $t {
            type Atomic = $a;
            #[inline(always)]
            fn cas_loop(a: &$a, f: impl Fn($t) -> $t) -> $t {
                let mut cur = a.load(Relaxed);
                loop {
                    let new = f($t::from_bits(cur)).to_bits();
                    match a.compare_exchange_weak(cur, new, Relaxed, Relaxed) {
                        Ok(old) => return $t::from_bits(old),
                        Err(actual) => cur = actual,
                    }
                }
            }
        }
    )*};
}
float_bits!(f32 => AtomicU32, f64 => AtomicU64, f16 => AtomicU16, bf16 => AtomicU16);

/// `f16` and `bf16`: a compare-exchange loop on the 16-bit pattern (`AtomicU16`), each new
/// value one 16-bit float operation (computed in `f32`, rounded once), `min`/`max` the
/// builtins.
macro_rules! atomic_half {
    ($($t:ident),*) => {$(
impl AtomicElement for $t {
    #[inline(always)]
    unsafe fn atomic_add(p: *mut Self, v: Self) -> Self {
        // SAFETY: as `atomic_rmw` requires, forwarded from the caller.
        unsafe { float_rmw(p, |x: $t| x + v) }
    }
    #[inline(always)]
    unsafe fn atomic_sub(p: *mut Self, v: Self) -> Self {
        // SAFETY: as in `atomic_add`.
        unsafe { float_rmw(p, |x: $t| x - v) }
    }
    #[inline(always)]
    unsafe fn atomic_min(p: *mut Self, v: Self) -> Self {
        // SAFETY: as in `atomic_add`.
        unsafe { float_rmw(p, |x: $t| super::min(x, v)) }
    }
    #[inline(always)]
    unsafe fn atomic_max(p: *mut Self, v: Self) -> Self {
        // SAFETY: as in `atomic_add`.
        unsafe { float_rmw(p, |x: $t| super::max(x, v)) }
    }
}
    )*};
}
atomic_half!(f16, bf16);

/// `*p = f(*p)` atomically via compare-exchange on the bits; returns the old value.
///
/// # Safety
/// `p` must be live, aligned (float and same-size unsigned atomic alignments agree on every
/// supported target; checked in debug builds), and accessed only atomically meanwhile.
#[inline(always)]
unsafe fn float_rmw<F: FloatBits>(p: *mut F, f: impl Fn(F) -> F) -> F {
    // SAFETY: forwarded to the caller.
    let a = unsafe { atomic_ref::<F, F::Atomic>(p) };
    F::cas_loop(a, f)
}

// ------------------------------------------------------------------------------------------
// Float vectors: componentwise, each component atomic on its own.
// ------------------------------------------------------------------------------------------

macro_rules! atomic_vec {
    ($($v:ident: $s:ident x $n:literal),*) => {$(
        // The component pointer arithmetic below relies on the vector being exactly `n`
        // contiguous components starting at offset 0 (glam guarantees this, `bytemuck::Pod`).
        const _: () = assert!(size_of::<$v>() == $n * size_of::<$s>());
        const _: () = assert!(align_of::<$v>() >= align_of::<$s>());

        impl AtomicElement for $v {
            #[inline(always)]
            unsafe fn atomic_add(p: *mut Self, v: Self) -> Self {
                // SAFETY: forwarded from the caller; see `vec_rmw`.
                unsafe { vec_rmw::<$s, $n>(p.cast(), v.to_array(), <$s as AtomicElement>::atomic_add) }.into()
            }
            #[inline(always)]
            unsafe fn atomic_sub(p: *mut Self, v: Self) -> Self {
                // SAFETY: forwarded from the caller; see `vec_rmw`.
                unsafe { vec_rmw::<$s, $n>(p.cast(), v.to_array(), <$s as AtomicElement>::atomic_sub) }.into()
            }
            #[inline(always)]
            unsafe fn atomic_min(p: *mut Self, v: Self) -> Self {
                // SAFETY: forwarded from the caller; see `vec_rmw`.
                unsafe { vec_rmw::<$s, $n>(p.cast(), v.to_array(), <$s as AtomicElement>::atomic_min) }.into()
            }
            #[inline(always)]
            unsafe fn atomic_max(p: *mut Self, v: Self) -> Self {
                // SAFETY: forwarded from the caller; see `vec_rmw`.
                unsafe { vec_rmw::<$s, $n>(p.cast(), v.to_array(), <$s as AtomicElement>::atomic_max) }.into()
            }
        }
    )*};
}
atomic_vec!(
    Vec2: f32 x 2, Vec3: f32 x 3, Vec4: f32 x 4,
    DVec2: f64 x 2, DVec3: f64 x 3, DVec4: f64 x 4
);

/// Applies the scalar atomic `op` to each of the `N` components at `p`, in order; returns the
/// per-component old values.
///
/// # Safety
/// `p` must point to `N` live contiguous components of a vector that is accessed only
/// atomically meanwhile, aligned for `S` (every glam vector is at least as aligned as its
/// component, e.g. `Vec3` is 4-byte aligned, so per-component `f32` atomics are fine).
#[inline(always)]
unsafe fn vec_rmw<S: AtomicElement, const N: usize>(
    p: *mut S,
    v: [S; N],
    op: unsafe fn(*mut S, S) -> S,
) -> [S; N] {
    debug_assert!(p.is_aligned(), "misaligned vector component");
    core::array::from_fn(|i| {
        // SAFETY: component `i < N` lies inside the vector (size asserted at compile time),
        // is aligned for `S` (vector alignment ≥ component alignment, size a multiple of
        // it), and the caller's liveness and atomic-only guarantees cover it.
        unsafe { op(p.add(i), v[i]) }
    })
}

// ------------------------------------------------------------------------------------------
// Tests
// ------------------------------------------------------------------------------------------

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fault::FaultKind;

    fn view<T: Copy>(data: &mut [T]) -> ArrayView<T, 1> {
        // SAFETY: every in-bounds index addresses an element of `data`, which outlives the
        // view in each test.
        unsafe { ArrayView::new(data.as_mut_ptr(), [data.len()], [1], "test", "a") }
    }

    const THREADS: usize = 8;
    const PER_THREAD: usize = 1250; // 10_000 in all

    #[test]
    fn concurrent_add_is_exact() {
        let mut f = vec![0.0f32; 4];
        let mut i = vec![0i32; 4];
        let mut d = vec![0.0f64; 2];
        let mut u = vec![0u64; 2];
        let mut v3 = vec![Vec3::ZERO; 2];
        let mut dv4 = vec![DVec4::ZERO; 2];
        let (fv, iv, dv, uv, v3v, dv4v) = (
            view(&mut f),
            view(&mut i),
            view(&mut d),
            view(&mut u),
            view(&mut v3),
            view(&mut dv4),
        );
        std::thread::scope(|s| {
            for _ in 0..THREADS {
                s.spawn(|| {
                    for _ in 0..PER_THREAD {
                        atomic_add(&fv, 2, 1.0f32).unwrap();
                        atomic_add(&iv, 1i64, 1i32).unwrap();
                        atomic_sub(&iv, 3u8, 2i32).unwrap();
                        atomic_add(&dv, 0, 0.5f64).unwrap();
                        atomic_add(&uv, 1, 3u64).unwrap();
                        atomic_add(&v3v, 1, Vec3::new(1.0, 2.0, -1.0)).unwrap();
                        atomic_sub(&dv4v, 0, DVec4::new(1.0, 0.5, 0.25, 2.0)).unwrap();
                    }
                });
            }
        });
        let n = THREADS * PER_THREAD;
        assert_eq!(f, [0.0, 0.0, 10_000.0, 0.0]);
        assert_eq!(i, [0, 10_000, 0, -20_000]);
        assert_eq!(d, [5_000.0, 0.0]);
        assert_eq!(u, [0, 3 * n as u64]);
        assert_eq!(v3, [Vec3::ZERO, Vec3::new(10_000.0, 20_000.0, -10_000.0)]);
        assert_eq!(
            dv4,
            [
                DVec4::new(-10_000.0, -5_000.0, -2_500.0, -20_000.0),
                DVec4::ZERO
            ]
        );
    }

    #[test]
    fn returns_old_value_and_wraps() {
        let mut i = vec![i32::MAX];
        let iv = view(&mut i);
        assert_eq!(atomic_add(&iv, 0, 1).unwrap(), i32::MAX);
        assert_eq!(iv.load(0).unwrap(), i32::MIN);
        assert_eq!(atomic_sub(&iv, 0, 1).unwrap(), i32::MIN);
        assert_eq!(iv.load(0).unwrap(), i32::MAX);

        let mut u = vec![0u32];
        let uv = view(&mut u);
        assert_eq!(atomic_sub(&uv, 0, 1).unwrap(), 0);
        assert_eq!(uv.load(0).unwrap(), u32::MAX);

        let mut f = vec![1.5f32];
        let fv = view(&mut f);
        assert_eq!(atomic_sub(&fv, 0, 0.25).unwrap(), 1.5);
        assert_eq!(fv.load(0).unwrap(), 1.25);

        let mut v = vec![Vec2::new(1.0, 2.0)];
        let vv = view(&mut v);
        assert_eq!(atomic_add(&vv, 0, Vec2::ONE).unwrap(), Vec2::new(1.0, 2.0));
        assert_eq!(vv.load(0).unwrap(), Vec2::new(2.0, 3.0));
    }

    #[test]
    fn min_max_ints_concurrent() {
        let mut i = vec![0i32, 0];
        let mut u = vec![u64::MAX, 0];
        let (iv, uv) = (view(&mut i), view(&mut u));
        std::thread::scope(|s| {
            for t in 0..THREADS {
                let (iv, uv) = (&iv, &uv);
                s.spawn(move || {
                    for k in 0..PER_THREAD {
                        let x = (t * PER_THREAD + k) as i32;
                        atomic_min(iv, 0, -x).unwrap();
                        atomic_max(iv, 1, x).unwrap();
                        atomic_min(uv, 0, x as u64 + 7).unwrap();
                        atomic_max(uv, 1, x as u64).unwrap();
                    }
                });
            }
        });
        let top = (THREADS * PER_THREAD - 1) as i32;
        assert_eq!(i, [-top, top]);
        assert_eq!(u, [7, top as u64]);

        let mut j = vec![5i64];
        let jv = view(&mut j);
        assert_eq!(atomic_min(&jv, 0, 9).unwrap(), 5);
        assert_eq!(atomic_min(&jv, 0, -9).unwrap(), 5);
        assert_eq!(atomic_max(&jv, 0, 3).unwrap(), -9);
        assert_eq!(jv.load(0).unwrap(), 3);
    }

    #[test]
    fn min_max_floats() {
        let mut f = vec![0.0f32, 0.0];
        let fv = view(&mut f);
        std::thread::scope(|s| {
            for t in 0..THREADS {
                let fv = &fv;
                s.spawn(move || {
                    for k in 0..PER_THREAD {
                        let x = (t * PER_THREAD + k) as f32 * 0.5;
                        atomic_min(fv, 0, -x).unwrap();
                        atomic_max(fv, 1, x).unwrap();
                    }
                });
            }
        });
        let top = (THREADS * PER_THREAD - 1) as f32 * 0.5;
        assert_eq!(f, [-top, top]);

        // IEEE fmin/fmax: a NaN operand loses, whichever side it is on.
        let mut d = vec![f64::NAN, 1.0];
        let dv = view(&mut d);
        assert!(atomic_min(&dv, 0, 2.0).unwrap().is_nan());
        assert_eq!(dv.load(0).unwrap(), 2.0);
        assert_eq!(atomic_max(&dv, 1, f64::NAN).unwrap(), 1.0);
        assert_eq!(dv.load(1).unwrap(), 1.0);
        assert_eq!(atomic_max(&dv, 1, 4.0).unwrap(), 1.0);
        assert_eq!(dv.load(1).unwrap(), 4.0);

        let mut v = vec![Vec4::new(1.0, f32::NAN, 3.0, -1.0)];
        let vv = view(&mut v);
        atomic_min(&vv, 0, Vec4::new(2.0, 5.0, f32::NAN, -2.0)).unwrap();
        assert_eq!(vv.load(0).unwrap(), Vec4::new(1.0, 5.0, 3.0, -2.0));
        let old = atomic_max(&vv, 0, Vec4::splat(2.0)).unwrap();
        assert_eq!(old, Vec4::new(1.0, 5.0, 3.0, -2.0));
        assert_eq!(vv.load(0).unwrap(), Vec4::new(2.0, 5.0, 3.0, 2.0));

        let mut w = vec![DVec3::new(1.0, 2.0, 3.0)];
        let wv = view(&mut w);
        atomic_max(&wv, 0, DVec3::splat(2.0)).unwrap();
        assert_eq!(wv.load(0).unwrap(), DVec3::new(2.0, 2.0, 3.0));
    }

    #[test]
    fn out_of_bounds_faults() {
        let mut f = vec![0.0f32; 3];
        let fv = view(&mut f);
        let err = atomic_add(&fv, 3, 1.0).unwrap_err();
        assert_eq!(err.kernel, "test");
        assert_eq!(
            err.kind,
            FaultKind::OutOfBounds {
                arg: "a",
                index: vec![3],
                shape: vec![3]
            }
        );
        let err = atomic_min(&fv, -1i32, 1.0).unwrap_err();
        assert!(matches!(err.kind, FaultKind::OutOfBounds { arg: "a", .. }));

        let mut v = vec![Vec3::ZERO; 2];
        let vv = view(&mut v);
        let err = atomic_max(&vv, 2u64, Vec3::ONE).unwrap_err();
        assert!(matches!(err.kind, FaultKind::OutOfBounds { arg: "a", .. }));
        assert!(err.to_string().contains("`a`"));
        assert_eq!(f, [0.0; 3]);
        assert_eq!(v, [Vec3::ZERO; 2]);
    }
}

// ------------------------------------------------------------------------------------------
// Compare-and-swap, exchange and bitwise atomics (no adjoint, as in Warp).
// ------------------------------------------------------------------------------------------

/// An element type of `atomic_cas` and `atomic_exch`: `i32`, `u32`, `i64`, `u64`, `f32`,
/// `f64`. Floats compare and swap their bit patterns, as CUDA's `atomicCAS` on the
/// reinterpreted bits does: `-0.0` does not match `0.0`, a NaN matches the same NaN bits.
///
/// # Safety (of every method)
/// As [`AtomicElement`].
pub trait AtomicSwapElement: Copy {
    /// If `*p == compare` (bitwise), `*p = v`; returns the old value either way.
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn atomic_cas(p: *mut Self, compare: Self, v: Self) -> Self;
    /// `*p = v`; returns the old value.
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn atomic_exch(p: *mut Self, v: Self) -> Self;
}

/// An element type of `atomic_and`, `atomic_or`, `atomic_xor`: `i32`, `u32`, `i64`, `u64`.
///
/// # Safety (of every method)
/// As [`AtomicElement`].
pub trait AtomicBitsElement: Copy {
    /// `*p &= v`; returns the old value.
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn atomic_and(p: *mut Self, v: Self) -> Self;
    /// `*p |= v`; returns the old value.
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn atomic_or(p: *mut Self, v: Self) -> Self;
    /// `*p ^= v`; returns the old value.
    ///
    /// # Safety
    /// See the trait documentation.
    unsafe fn atomic_xor(p: *mut Self, v: Self) -> Self;
}

macro_rules! atomic_swap_bits {
    ($($t:ty => $a:ty),*) => {$(
        impl AtomicSwapElement for $t {
            #[inline(always)]
            unsafe fn atomic_cas(p: *mut Self, compare: Self, v: Self) -> Self {
                // SAFETY: as in `AtomicElement::atomic_add` for integers.
                match unsafe { atomic_ref::<$t, $a>(p) }.compare_exchange(compare, v, Relaxed, Relaxed) {
                    Ok(old) | Err(old) => old,
                }
            }
            #[inline(always)]
            unsafe fn atomic_exch(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_cas`.
                unsafe { atomic_ref::<$t, $a>(p) }.swap(v, Relaxed)
            }
        }
        impl AtomicBitsElement for $t {
            #[inline(always)]
            unsafe fn atomic_and(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_cas`.
                unsafe { atomic_ref::<$t, $a>(p) }.fetch_and(v, Relaxed)
            }
            #[inline(always)]
            unsafe fn atomic_or(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_cas`.
                unsafe { atomic_ref::<$t, $a>(p) }.fetch_or(v, Relaxed)
            }
            #[inline(always)]
            unsafe fn atomic_xor(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_cas`.
                unsafe { atomic_ref::<$t, $a>(p) }.fetch_xor(v, Relaxed)
            }
        }
    )*};
}
atomic_swap_bits!(i32 => AtomicI32, u32 => AtomicU32, i64 => AtomicI64, u64 => AtomicU64);

macro_rules! atomic_swap_float {
    ($($t:ident => $a:ty),*) => {$(
        impl AtomicSwapElement for $t {
            #[inline(always)]
            unsafe fn atomic_cas(p: *mut Self, compare: Self, v: Self) -> Self {
                // SAFETY: as `float_rmw` requires, forwarded from the caller.
                let a = unsafe { atomic_ref::<$t, $a>(p) };
                match a.compare_exchange(compare.to_bits(), v.to_bits(), Relaxed, Relaxed) {
                    Ok(old) | Err(old) => $t::from_bits(old),
                }
            }
            #[inline(always)]
            unsafe fn atomic_exch(p: *mut Self, v: Self) -> Self {
                // SAFETY: as in `atomic_cas`.
                $t::from_bits(unsafe { atomic_ref::<$t, $a>(p) }.swap(v.to_bits(), Relaxed))
            }
        }
    )*};
}
atomic_swap_float!(f32 => AtomicU32, f64 => AtomicU64);

/// Atomically: if `arr[idx] == compare` (bitwise for floats), stores `value`; returns the old
/// value either way.
#[inline(always)]
pub fn atomic_cas<T: AtomicSwapElement, const N: usize, I: KernelIndex<N>>(
    arr: &ArrayView<T, N>,
    idx: I,
    compare: T,
    value: T,
) -> KResult<T> {
    let p = arr.ptr_at(idx)?;
    // SAFETY: as in `atomic_add`: in-bounds, aligned, live, atomically shared.
    Ok(unsafe { T::atomic_cas(p, compare, value) })
}

/// Atomically stores `value` in `arr[idx]` and returns the old value.
#[inline(always)]
pub fn atomic_exch<T: AtomicSwapElement, const N: usize, I: KernelIndex<N>>(
    arr: &ArrayView<T, N>,
    idx: I,
    value: T,
) -> KResult<T> {
    let p = arr.ptr_at(idx)?;
    // SAFETY: as in `atomic_add`: in-bounds, aligned, live, atomically shared.
    Ok(unsafe { T::atomic_exch(p, value) })
}

macro_rules! atomic_bits_fn {
    ($($name:ident: $what:literal),*) => {$(
        #[doc = concat!("Atomically sets `arr[idx] ", $what, " value` and returns the old value.")]
        #[inline(always)]
        pub fn $name<T: AtomicBitsElement, const N: usize, I: KernelIndex<N>>(
            arr: &ArrayView<T, N>,
            idx: I,
            value: T,
        ) -> KResult<T> {
            let p = arr.ptr_at(idx)?;
            // SAFETY: as in `atomic_add`: in-bounds, aligned, live, atomically shared.
            Ok(unsafe { T::$name(p, value) })
        }
    )*};
}
atomic_bits_fn!(atomic_and: "&=", atomic_or: "|=", atomic_xor: "^=");
