//! Reverse-mode differentiation over launches: [`Tape`].
//!
//! While a tape is recording on a thread (`let _rec = tape.record();`), every kernel launch
//! made on that thread is recorded with its arguments (array handles, values). `backward`
//! seeds the loss's gradient with one and runs the recorded launches' adjoints in reverse
//! order: each adjoint replays its thread's forward computation and accumulates into the
//! gradients of the arrays it read (`Array::with_grad`). Gradients accumulate: a second
//! backward without [`Tape::zero`] adds to the first.

use crate::array::{Array, Element};
use crate::config;
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::{ArgsOf, Kernel, KernelParams};
use std::cell::RefCell;
use std::marker::PhantomData;
use std::rc::{Rc, Weak};
use warp_core::Grid;

type Thunk = Box<dyn Fn() -> Result<()>>;
/// A step's backward, given the adjoint stack capacity in bytes.
type Backward = Box<dyn Fn(usize) -> Result<()>>;

/// One recorded step.
struct Record {
    /// What the step was (a kernel's name, or "custom").
    name: &'static str,
    backward: Backward,
    zero: Thunk,
}

#[derive(Default)]
struct TapeInner {
    records: Vec<Record>,
    /// Adjoint stack bytes per thread for this tape (else `config::adstack_bytes`).
    adstack_bytes: Option<usize>,
}

thread_local! {
    /// The tapes recording on this thread, innermost last.
    static RECORDING: RefCell<Vec<Weak<RefCell<TapeInner>>>> = const { RefCell::new(Vec::new()) };
}

/// Records launches for reverse-mode differentiation (Warp's `wp.Tape`).
///
/// (This example runs as a doctest of the `warp-lang` crate, which re-exports the tape.)
/// ```ignore
/// use warp_lang as wp;
/// use wp::prelude::*;
///
/// #[wp::kernel]
/// fn square_sum(x: Array<f32>, loss: Array<f32>) {
///     let i = tid();
///     atomic_add(loss, 0, x[i] * x[i]);
/// }
///
/// let dev = wp::cpu();
/// let x = wp::Array::from_slice(&[1.0f32, 2.0, 3.0], &dev).unwrap().with_grad().unwrap();
/// let loss = wp::Array::<f32>::zeros(1, &dev).unwrap().with_grad().unwrap();
/// let tape = wp::Tape::new();
/// {
///     let _rec = tape.record();
///     wp::launch(square_sum, 3, (&x, &loss), &dev).unwrap();
/// }
/// tape.backward(&loss).unwrap();
/// assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![2.0, 4.0, 6.0]);
/// ```
#[derive(Default)]
pub struct Tape {
    inner: Rc<RefCell<TapeInner>>,
}

/// What a tape's `Debug` shows: how many operations it holds and its adjoint-stack setting
/// (`busy: true` while the tape itself is being changed, when they cannot be read; it never
/// panics).
impl std::fmt::Debug for Tape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut d = f.debug_struct("Tape");
        match self.inner.try_borrow() {
            Ok(inner) => d
                .field("records", &inner.records.len())
                .field("adstack_bytes", &inner.adstack_bytes),
            Err(_) => d.field("busy", &true),
        }
        .finish()
    }
}

impl std::fmt::Debug for Recording<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recording")
            .field("tape_alive", &(self.inner.strong_count() > 0))
            .finish()
    }
}

/// While alive, launches on this thread are recorded on the tape (see [`Tape::record`]).
#[must_use = "the tape records only while the `Recording` is alive: bind it (`let _rec = tape.record();`), not `let _ =`, which drops it at once"]
pub struct Recording<'t> {
    inner: Weak<RefCell<TapeInner>>,
    _tape: PhantomData<&'t Tape>,
}

impl Drop for Recording<'_> {
    fn drop(&mut self) {
        RECORDING.with(|r| {
            let mut r = r.borrow_mut();
            if let Some(k) = r.iter().rposition(|w| w.ptr_eq(&self.inner)) {
                r.remove(k);
            }
        });
    }
}

/// While alive, launches on this thread are recorded on no tape; the tapes that were recording
/// when it was made resume when it drops (tapes started meanwhile stay innermost). For work
/// that manages its own tapes, such as a checkpointed rollout's recomputation.
#[must_use = "the tapes resume when `Paused` drops: bind it for the span to run unrecorded"]
pub(crate) struct Paused {
    saved: Vec<Weak<RefCell<TapeInner>>>,
}

/// Pauses the tapes recording on this thread (see [`Paused`]).
pub(crate) fn pause_recording() -> Paused {
    Paused {
        saved: RECORDING.with(|r| std::mem::take(&mut *r.borrow_mut())),
    }
}

impl Drop for Paused {
    fn drop(&mut self) {
        RECORDING.with(|r| {
            let mut r = r.borrow_mut();
            let newer = std::mem::replace(&mut *r, std::mem::take(&mut self.saved));
            r.extend(newer);
        });
    }
}

/// A gradient seed: the value `backward` writes into the loss's gradient.
pub trait Seed: Element {
    /// One.
    const ONE: Self;
}

impl Seed for f32 {
    const ONE: f32 = 1.0;
}

impl Seed for f64 {
    const ONE: f64 = 1.0;
}

impl Seed for warp_core::f16 {
    const ONE: warp_core::f16 = warp_core::f16::ONE;
}

impl Seed for warp_core::bf16 {
    const ONE: warp_core::bf16 = warp_core::bf16::ONE;
}

impl Tape {
    /// An empty tape.
    pub fn new() -> Tape {
        Tape::default()
    }

    /// Starts recording launches made on this thread; recording stops when the guard drops.
    pub fn record(&self) -> Recording<'_> {
        crate::backend::set_recording_query(recording_adstack_bytes);
        let inner = Rc::downgrade(&self.inner);
        RECORDING.with(|r| r.borrow_mut().push(inner.clone()));
        Recording {
            inner,
            _tape: PhantomData,
        }
    }

    /// How many steps are recorded.
    pub fn len(&self) -> usize {
        self.inner.borrow().records.len()
    }

    /// Whether nothing is recorded.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The names of the recorded steps, in launch order.
    pub fn steps(&self) -> Vec<&'static str> {
        self.inner.borrow().records.iter().map(|r| r.name).collect()
    }

    /// Seeds `loss`'s gradient with one (every element) and runs the recorded steps' adjoints
    /// in reverse order. Gradients accumulate into what the arrays' grads already hold.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `loss` has no gradient; [`Error::NotDifferentiable`]
    /// for a kernel without an adjoint; [`Error::Fault`] from an adjoint thread (including
    /// an adjoint stack overflow, naming the kernel and line). After an error the gradients
    /// hold part of a backward pass (the adjoints that ran, and on a GPU the faulting threads'
    /// reverse sweeps too): [`zero`](Self::zero) them and seed again before another backward.
    pub fn backward<T: Seed, const N: usize>(&self, loss: &Array<T, N>) -> Result<()> {
        self.not_recording()?;
        let Some(g) = loss.grad() else {
            return Err(Error::invalid(
                "backward: the loss has no gradient (create it with .with_grad())",
            ));
        };
        g.fill(T::ONE)?;
        self.backward_from_grads()
    }

    /// Runs the recorded adjoints in reverse order with the output gradients the caller has
    /// already set (for several outputs, or seeds other than one).
    ///
    /// # Errors
    /// As [`backward`](Self::backward), whose note on gradients after an error holds here.
    pub fn backward_from_grads(&self) -> Result<()> {
        self.not_recording()?;
        let inner = self
            .inner
            .try_borrow()
            .map_err(|_| running_backward("backward"))?;
        let cap = inner.adstack_bytes.unwrap_or_else(config::adstack_bytes);
        for r in inner.records.iter().rev() {
            (r.backward)(cap)?;
        }
        Ok(())
    }

    /// An error when this tape is recording on this thread: its backward would run while
    /// launches still go onto it.
    fn not_recording(&self) -> Result<()> {
        let me = Rc::downgrade(&self.inner);
        if RECORDING.with(|r| r.borrow().iter().any(|w| w.ptr_eq(&me))) {
            return Err(Error::invalid(
                "backward on a tape while it is recording (drop its Recording guard first)",
            ));
        }
        Ok(())
    }

    /// Sets this tape's per-thread adjoint stack capacity in bytes (`None`: the process-wide
    /// [`config::adstack_bytes`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when called from a step of this tape's own backward (a
    /// [`record_func`](Self::record_func) step): the running backward holds the tape, and
    /// its capacity is fixed for the pass.
    pub fn set_adstack_bytes(&self, bytes: Option<usize>) -> Result<()> {
        self.inner
            .try_borrow_mut()
            .map_err(|_| running_backward(&format!("set_adstack_bytes({bytes:?})")))?
            .adstack_bytes = bytes;
        Ok(())
    }

    /// Zeroes the gradients of every array the recorded launches took.
    pub fn zero(&self) -> Result<()> {
        let inner = self
            .inner
            .try_borrow()
            .map_err(|_| running_backward("zero"))?;
        for r in &inner.records {
            (r.zero)()?;
        }
        Ok(())
    }

    /// Forgets the recorded steps (gradients are left as they are).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when called from a step of this tape's own backward (a
    /// [`record_func`](Self::record_func) step): the steps being replayed cannot be dropped
    /// under the running backward. Reset after `backward` returns.
    pub fn reset(&self) -> Result<()> {
        self.inner
            .try_borrow_mut()
            .map_err(|_| running_backward("reset"))?
            .records
            .clear();
        Ok(())
    }

    /// Records a host-side step: `backward` runs at its place in the reverse order (for
    /// gradients of work done outside kernels, such as a host-side copy).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when called from a step of this tape's own backward.
    pub fn record_func(&self, backward: impl Fn() -> Result<()> + 'static) -> Result<()> {
        self.inner
            .try_borrow_mut()
            .map_err(|_| running_backward("record_func"))?
            .records
            .push(Record {
                name: "custom",
                backward: Box::new(move |_| backward()),
                zero: Box::new(|| Ok(())),
            });
        Ok(())
    }
}

/// The error of changing a tape whose backward is running (a `record_func` step that records
/// on, resets or reconfigures its own tape).
#[cold]
fn running_backward(what: &str) -> Error {
    Error::invalid(format!(
        "{what} on a tape that runs backward (a record_func step changing its own tape; do it \
         after backward returns)"
    ))
}

/// When a tape records on this thread, the adjoint stack its backward will run with (the
/// innermost tape's): a kernel compiled now for a launch it records compiles its adjoint
/// along, in one unit (the CUDA backend's `module::loaded`, which asks through
/// `backend::recording_adstack_bytes`). `None` when nothing records.
fn recording_adstack_bytes() -> Option<usize> {
    RECORDING.with(|r| {
        let tape = r.borrow().iter().rev().find_map(Weak::upgrade)?;
        // (A tape busy in its own backward records nothing: the launch is refused there.)
        let own = tape.try_borrow().ok().and_then(|t| t.adstack_bytes);
        Some(own.unwrap_or_else(config::adstack_bytes))
    })
}

/// Records the launch of `K` on every tape recording on this thread.
///
/// # Errors
/// When one of them is running its backward pass (the launch came from one of its steps).
pub(crate) fn on_launch<K: Kernel>(
    args: &ArgsOf<'_, K>,
    grid: &Grid,
    device: &Device,
) -> Result<()> {
    RECORDING.with(|r| {
        let r = r.borrow();
        for inner in r.iter().filter_map(Weak::upgrade) {
            let mut records = inner
                .try_borrow_mut()
                .map_err(|_| running_backward(&format!("a launch of kernel `{}`", K::INFO.name)))?;
            let owned = Rc::new(K::Params::own(args));
            let (o1, o2) = (owned.clone(), owned);
            let (grid, device) = (*grid, device.clone());
            records.records.push(Record {
                name: K::INFO.name,
                backward: Box::new(move |cap| {
                    crate::dispatch::launch_adjoint::<K>(
                        &device,
                        &K::Params::borrow(&o1),
                        &grid,
                        cap,
                    )
                }),
                zero: Box::new(move || K::Params::zero_grads(&K::Params::borrow(&o2))),
            });
        }
        Ok(())
    })
}

/// Whether a tape records on this thread (library operations that record themselves, such
/// as the sparse solves, skip the work of a record when none does).
#[cfg_attr(not(feature = "sparse"), allow(dead_code))]
pub(crate) fn recording() -> bool {
    RECORDING.with(|r| r.borrow().iter().any(|w| w.strong_count() > 0))
}

/// Records a library operation named `name` on every tape recording on this thread (the
/// sibling of [`on_launch`] for work that is not one kernel: [`copy`], a sparse solve, an
/// assembly):
/// `backward` runs at its place in the reverse order, `zero` clears the gradients of the
/// arrays it reads and writes ([`Tape::zero`]). Both are shared by the tapes that record it.
///
/// # Errors
/// When one of the tapes is running its backward pass (the operation came from one of its
/// steps).
pub(crate) fn on_op(
    name: &'static str,
    backward: impl Fn() -> Result<()> + 'static,
    zero: impl Fn() -> Result<()> + 'static,
) -> Result<()> {
    let backward: Rc<dyn Fn() -> Result<()>> = Rc::new(backward);
    let zero: Rc<dyn Fn() -> Result<()>> = Rc::new(zero);
    RECORDING.with(|r| {
        for inner in r.borrow().iter().filter_map(Weak::upgrade) {
            let mut records = inner
                .try_borrow_mut()
                .map_err(|_| running_backward(&format!("`{name}`")))?;
            let (b, z) = (backward.clone(), zero.clone());
            records.records.push(Record {
                name,
                backward: Box::new(move |_| b()),
                zero: Box::new(move || z()),
            });
        }
        Ok(())
    })
}

/// Copies `src` into `dst` (same shape); see [`Array::copy_from`]. A recording [`Tape`]
/// records it: backward adds `dst`'s gradient into `src`'s and clears `dst`'s.
pub fn copy<T: Element, const N: usize>(dst: &Array<T, N>, src: &Array<T, N>) -> Result<()> {
    dst.copy_from(src)?;
    on_copy(dst, src)
}

/// Records `copy(dst, src)` on every tape recording on this thread (when `dst` has a
/// gradient to hand back).
fn on_copy<T: Element, const N: usize>(dst: &Array<T, N>, src: &Array<T, N>) -> Result<()> {
    if !dst.requires_grad() {
        return Ok(());
    }
    let (d, s) = (dst.clone(), src.clone());
    let (d2, s2) = (dst.clone(), src.clone());
    on_op(
        "copy",
        move || {
            let Some(dg) = d.grad() else { return Ok(()) };
            if let Some(sg) = s.grad() {
                let mut acc = sg.to_vec()?;
                for (a, b) in acc.iter_mut().zip(dg.to_vec()?) {
                    // SAFETY: `a` is a live, aligned element of a local vector.
                    unsafe { <T as warp_core::GradElement>::grad_add(a, b) };
                }
                let host = Array::from_slice_shape(&acc, sg.shape(), &crate::device::cpu())?;
                sg.copy_from(&host)?;
            }
            dg.fill(T::zeroed())
        },
        move || {
            d2.zero_grad()?;
            s2.zero_grad()
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `record_func` step reaches its own tape (through an `Rc` it captured) and changes
    /// it while the tape's backward runs: before issue 35 `reset` and `set_adstack_bytes`
    /// panicked there (a `RefCell` already borrowed by the backward); now each is an error
    /// naming the call, backward returns it, and the tape still works afterwards.
    fn step_changes_its_tape(change: fn(&Tape) -> Result<()>, names: &str) {
        let tape = Rc::new(Tape::new());
        let t = Rc::downgrade(&tape);
        tape.record_func(move || change(&t.upgrade().expect("the tape is alive")))
            .unwrap();
        let e = tape.backward_from_grads().unwrap_err().to_string();
        assert!(e.contains(names) && e.contains("runs backward"), "{e}");
        // Nothing was changed, and outside backward the same calls work.
        assert_eq!(tape.steps(), vec!["custom"]);
        tape.set_adstack_bytes(Some(64)).unwrap();
        tape.reset().unwrap();
        assert!(tape.is_empty());
        tape.backward_from_grads().unwrap();
    }

    #[test]
    fn reset_during_backward_is_an_error() {
        step_changes_its_tape(|t| t.reset(), "reset");
    }

    #[test]
    fn set_adstack_bytes_during_backward_is_an_error() {
        step_changes_its_tape(
            |t| t.set_adstack_bytes(Some(64)),
            "set_adstack_bytes(Some(64))",
        );
    }

    /// `Debug` shows the record count and the stack setting, also from a step of the tape's
    /// own backward pass (which reads the records: no panic).
    #[test]
    fn debug_shows_records_and_never_panics() {
        let tape = Rc::new(Tape::new());
        tape.set_adstack_bytes(Some(128)).unwrap();
        let t = Rc::downgrade(&tape);
        let seen = Rc::new(RefCell::new(String::new()));
        let s2 = seen.clone();
        tape.record_func(move || {
            *s2.borrow_mut() = format!("{:?}", t.upgrade().expect("the tape is alive"));
            Ok(())
        })
        .unwrap();
        let d = format!("{tape:?}");
        assert_eq!(d, "Tape { records: 1, adstack_bytes: Some(128) }");
        tape.backward_from_grads().unwrap();
        assert_eq!(*seen.borrow(), d);
    }
}
