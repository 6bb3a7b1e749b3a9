//! What adjoint kernels use on the CPU: [`GradView`] (the gradient of an array argument) and
//! [`AdStack`] (the per-thread stack that keeps the values a reverse sweep needs back).

use crate::builtins::atomic::AtomicElement;
use crate::fault::{Fault, FaultKind, KResult};
use crate::index::KernelIndex;
use crate::view::ArrayView;

/// The zero adjoint of `x`'s type (generated adjoint code names types only through values).
#[inline(always)]
pub fn zero_like<T: crate::adjoint::Adjoint>(x: &T) -> T {
    let _ = x;
    T::adj_zero()
}

// `()` (a unit func's result) carries no gradient; the adjoint of such a call still runs.
impl crate::adjoint::Adjoint for () {
    fn adj_zero() -> Self {}
    fn adj_accum(&mut self, _: Self) {}
}

/// The first reason in `reasons` (a kernel's own, then its funcs'), for
/// `KernelInfo::adjoint_error`.
pub const fn first_error(reasons: &[Option<&'static str>]) -> Option<&'static str> {
    let mut k = 0;
    while k < reasons.len() {
        if reasons[k].is_some() {
            return reasons[k];
        }
        k += 1;
    }
    None
}

/// An array element type whose gradients can be accumulated by many threads at once.
///
/// Floats, float vectors, matrices and quaternions add atomically (component by component);
/// integer and bool elements have no gradient, and adding to them does nothing.
pub trait GradElement: Copy {
    /// Atomically `*p += v` (componentwise), or nothing for types without a gradient.
    ///
    /// # Safety
    /// `p` must point to a live, aligned `Self` that other threads touch only through this
    /// function or [`AtomicElement`] operations while the call runs.
    unsafe fn grad_add(p: *mut Self, v: Self);
}

macro_rules! grad_atomic {
    ($($t:ty),*) => {$(
        impl GradElement for $t {
            #[inline(always)]
            unsafe fn grad_add(p: *mut Self, v: Self) {
                // SAFETY: forwarded contract.
                unsafe { <$t as AtomicElement>::atomic_add(p, v) };
            }
        }
    )*};
}
grad_atomic!(
    f32,
    f64,
    half::f16,
    half::bf16,
    glam::Vec2,
    glam::Vec3,
    glam::Vec4,
    glam::DVec2,
    glam::DVec3,
    glam::DVec4
);

macro_rules! grad_lanes {
    ($($t:ty => $s:ty, $n:expr);* $(;)?) => {$(
        impl GradElement for $t {
            #[inline(always)]
            unsafe fn grad_add(p: *mut Self, v: Self) {
                // A matrix or quaternion is `$n` consecutive `$s` lanes (glam's layout).
                let lanes: [$s; $n] = bytemuck::cast(v);
                let base = p as *mut $s;
                for (k, x) in lanes.into_iter().enumerate() {
                    // SAFETY: lane k of a live, aligned element (forwarded contract).
                    unsafe { <$s as AtomicElement>::atomic_add(base.add(k), x) };
                }
            }
        }
    )*};
}
grad_lanes!(
    glam::Mat2 => f32, 4; glam::Mat3 => f32, 9; glam::Mat4 => f32, 16; glam::Quat => f32, 4;
    glam::DMat2 => f64, 4; glam::DMat3 => f64, 9; glam::DMat4 => f64, 16; glam::DQuat => f64, 4;
);

macro_rules! grad_none {
    ($($t:ty),*) => {$(
        impl GradElement for $t {
            #[inline(always)]
            unsafe fn grad_add(_: *mut Self, _: Self) {}
        }
    )*};
}
grad_none!(bool, i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);

/// A struct's array field (`[f32; 4]`, `[Vec3; 2]`): element by element.
impl<T: GradElement, const N: usize> GradElement for [T; N] {
    #[inline(always)]
    unsafe fn grad_add(p: *mut Self, v: Self) {
        let base = p as *mut T;
        for (k, x) in v.into_iter().enumerate() {
            // SAFETY: element k of a live, aligned `[T; N]` (forwarded contract).
            unsafe { T::grad_add(base.add(k), x) };
        }
    }
}
grad_none!(
    glam::IVec2,
    glam::IVec3,
    glam::IVec4,
    glam::UVec2,
    glam::UVec3,
    glam::UVec4
);

/// The gradient of an array argument inside an adjoint kernel: a view of the array's grad,
/// or nothing when the array has none (then accumulating is a no-op and taking gives zero).
#[derive(Clone, Copy, Debug)]
pub struct GradView<T, const N: usize> {
    view: Option<ArrayView<T, N>>,
}

impl<T: Copy + GradElement, const N: usize> GradView<T, N> {
    /// The gradient held in `view` (an array of the same shape as the value).
    pub fn new(view: ArrayView<T, N>) -> Self {
        GradView { view: Some(view) }
    }

    /// No gradient.
    pub fn none() -> Self {
        GradView { view: None }
    }

    /// Whether there is a gradient array.
    pub fn is_some(&self) -> bool {
        self.view.is_some()
    }

    /// The gradient array's view, if there is one (what a deterministic kernel's adjoint
    /// records its accumulations against).
    pub fn view(&self) -> Option<&ArrayView<T, N>> {
        self.view.as_ref()
    }

    /// `grad[idx] += v`, atomically (the adjoint of a read of the value at `idx`).
    #[inline(always)]
    pub fn accumulate<I: KernelIndex<N>>(&self, idx: I, v: T) -> KResult<()> {
        if let Some(view) = &self.view {
            let p = view.ptr_at(idx)?;
            // SAFETY: `ptr_at` checked the index; concurrent gradient updates are atomic.
            unsafe { T::grad_add(p, v) };
        }
        Ok(())
    }

    /// `grad[idx] += v` without an atomic and without a bounds check, for an element no
    /// other thread touches while the call runs.
    ///
    /// Generated adjoints use it for a thread-owned read (an array read at the thread index,
    /// in a launch whose arrays cover the grid): no other thread of the launch touches the
    /// element, and the CPU executor takes this path only while no other adjoint launch runs
    /// in the process (warp-runtime's `cpu/shared_grads.rs`), since a concurrent one may
    /// accumulate into the same gradient (two tapes reading one parameter array).
    ///
    /// # Safety
    /// `idx` must be in bounds, and no other thread may access `grad[idx]` during the call.
    #[inline(always)]
    pub unsafe fn accumulate_own<I: KernelIndex<N>>(&self, idx: I, v: T)
    where
        T: crate::adjoint::Adjoint,
    {
        if let Some(view) = &self.view {
            // SAFETY: forwarded contract.
            unsafe {
                let p = view.ptr_unchecked(idx);
                let mut g = p.read();
                g.adj_accum(v);
                p.write(g);
            }
        }
    }

    /// Returns `grad[idx]` and sets it to `zero` (the adjoint of a write at `idx`: the
    /// gradient flows to the written value, and the overwritten value had none).
    #[inline(always)]
    pub fn take<I: KernelIndex<N>>(&self, idx: I, zero: T) -> KResult<T> {
        match &self.view {
            Some(view) => {
                let g = view.load(idx)?;
                view.store(idx, zero)?;
                Ok(g)
            }
            None => Ok(zero),
        }
    }

    /// `grad[idx]` (the adjoint of an atomic add at `idx`), or `zero` without a gradient.
    #[inline(always)]
    pub fn get<I: KernelIndex<N>>(&self, idx: I, zero: T) -> KResult<T> {
        match &self.view {
            Some(view) => view.load(idx),
            None => Ok(zero),
        }
    }
}

// SAFETY: as for `ArrayView`: the runtime keeps the memory alive for the launch; threads
// update shared elements atomically.
unsafe impl<T: Send, const N: usize> Send for GradView<T, N> {}
unsafe impl<T: Sync, const N: usize> Sync for GradView<T, N> {}

/// A bounded per-thread stack of values for the reverse sweep of an adjoint kernel: what a
/// loop overwrites (loop-carried values, the loop's own variable, values computed inside it)
/// is pushed before it is overwritten and popped when the reverse sweep gets back there.
///
/// Its capacity is fixed for a launch; pushing past it is a fault naming the kernel and the
/// source line of the push, never a wrong gradient.
pub struct AdStack {
    buf: Vec<u8>,
    cap: usize,
    kernel: &'static str,
    /// The lanes' stacks of a tiled kernel's block ([`AdStack::lanes`]), kept for the next
    /// block.
    lanes: Vec<AdStack>,
}

/// The stack's size, capacity and kernel; not the bytes it holds.
impl std::fmt::Debug for AdStack {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AdStack")
            .field("len", &self.buf.len())
            .field("cap", &self.cap)
            .field("kernel", &self.kernel)
            .finish()
    }
}

impl AdStack {
    /// An empty stack of `capacity` bytes for threads of `kernel`.
    pub fn new(capacity: usize, kernel: &'static str) -> Self {
        AdStack {
            buf: Vec::with_capacity(capacity),
            cap: capacity,
            kernel,
            lanes: Vec::new(),
        }
    }

    /// `n` empty stacks of this one's capacity, one per lane of a tiled kernel's block: on the
    /// CPU a block is one task, and each of its lanes keeps its own history, as each CUDA thread
    /// does in its own stack. Made at the first tiled block, reused (emptied) by the next ones.
    pub fn lanes(&mut self, n: usize) -> &mut [AdStack] {
        while self.lanes.len() < n {
            self.lanes.push(AdStack::new(self.cap, self.kernel));
        }
        let lanes = &mut self.lanes[..n];
        lanes.iter_mut().for_each(AdStack::clear);
        lanes
    }

    /// Empties the stack (for the next thread).
    #[inline(always)]
    pub fn clear(&mut self) {
        self.buf.clear();
    }

    /// Its capacity in bytes.
    pub fn capacity(&self) -> usize {
        self.cap
    }

    /// Bytes in use.
    pub fn len(&self) -> usize {
        self.buf.len()
    }

    /// Whether nothing is pushed.
    pub fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    /// Pushes `v`; `line` names the statement in faults.
    #[inline(always)]
    pub fn push<T: Copy>(&mut self, v: T, line: u32) -> KResult<()> {
        let n = std::mem::size_of::<T>();
        if self.buf.len() + n > self.cap {
            return Err(Fault::new(
                self.kernel,
                FaultKind::AdStackOverflow {
                    line,
                    capacity: self.cap,
                },
            ));
        }
        let start = self.buf.len();
        self.buf.resize(start + n, 0);
        // SAFETY: `n` bytes at `start` were just reserved; an unaligned write of a Copy value
        // into them is sound.
        unsafe { std::ptr::write_unaligned(self.buf.as_mut_ptr().add(start) as *mut T, v) };
        Ok(())
    }

    /// Pops the value pushed last, which must have been pushed as a `T`.
    ///
    /// The generated reverse sweep pops exactly what its forward replay pushed, in reverse
    /// order and with the same types; a mismatch is a compiler bug, caught by the length check
    /// (a panic in that case only, never undefined behaviour).
    #[inline(always)]
    pub fn pop<T: Copy>(&mut self) -> T {
        let n = std::mem::size_of::<T>();
        assert!(
            self.buf.len() >= n,
            "adjoint stack underflow in kernel `{}`: a warp-lang compiler bug",
            self.kernel
        );
        let start = self.buf.len() - n;
        // SAFETY: the `n` bytes at `start` hold a `T` written by `push` (types match by
        // construction of the generated code); unaligned read of a Copy value.
        let v = unsafe { std::ptr::read_unaligned(self.buf.as_ptr().add(start) as *const T) };
        self.buf.truncate(start);
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn lane_stacks_are_separate_and_emptied_for_the_next_block() {
        let mut s = AdStack::new(8, "k");
        let lanes = s.lanes(3);
        assert_eq!(lanes.len(), 3);
        lanes[0].push(1u32, 1).unwrap();
        lanes[2].push(2u32, 1).unwrap();
        lanes[2].push(3u32, 1).unwrap();
        // Each lane has the whole capacity.
        assert!(lanes[2].push(4u8, 9).is_err());
        assert_eq!(lanes[2].pop::<u32>(), 3);
        assert_eq!(lanes[0].pop::<u32>(), 1);
        assert!(lanes[1].is_empty());
        let again = s.lanes(2);
        assert!(again.iter().all(AdStack::is_empty));
    }

    #[test]
    fn stack_round_trip_and_overflow() {
        let mut s = AdStack::new(20, "k");
        s.push(1.5f32, 3).unwrap();
        s.push(Vec3::new(1.0, 2.0, 3.0), 4).unwrap();
        assert_eq!(s.len(), 16);
        let e = s.push(7u64, 9).unwrap_err();
        assert_eq!(
            e.kind,
            FaultKind::AdStackOverflow {
                line: 9,
                capacity: 20
            }
        );
        assert_eq!(s.pop::<Vec3>(), Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(s.pop::<f32>(), 1.5);
        assert!(s.is_empty());
    }

    #[test]
    fn grad_view_accumulates_and_takes() {
        let mut g = vec![0.0f32; 3];
        let view = unsafe { ArrayView::new(g.as_mut_ptr(), [3], [1], "k", "x") };
        let gv = GradView::new(view);
        gv.accumulate(1usize, 2.0).unwrap();
        gv.accumulate(1usize, 0.5).unwrap();
        assert!(gv.accumulate(3usize, 1.0).is_err());
        assert_eq!(gv.get(1usize, 0.0).unwrap(), 2.5);
        assert_eq!(gv.take(1usize, 0.0).unwrap(), 2.5);
        assert_eq!(g, vec![0.0, 0.0, 0.0]);
        let none = GradView::<f32, 1>::none();
        none.accumulate(5usize, 1.0).unwrap();
        assert_eq!(none.take(5usize, 0.0).unwrap(), 0.0);
        let mut m = vec![glam::Mat2::ZERO; 1];
        let mv = GradView::new(unsafe { ArrayView::new(m.as_mut_ptr(), [1], [1], "k", "m") });
        mv.accumulate(0usize, glam::Mat2::IDENTITY).unwrap();
        mv.accumulate(0usize, glam::Mat2::IDENTITY).unwrap();
        assert_eq!(m[0], glam::Mat2::IDENTITY * 2.0);
    }
}
