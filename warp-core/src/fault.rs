//! Faults: what a kernel thread reports instead of panicking or invoking undefined behaviour.
//!
//! Generated kernel code returns `KResult<()>` from every thread; the executor stops at the
//! first fault and the runtime turns it into an `Err` that names the kernel, the argument and
//! the offending values. Faults are boxed so that the `Ok` path stays one word wide.

use std::fmt;

/// The result type of generated kernel and func code on the CPU.
pub type KResult<T> = Result<T, Box<Fault>>;

/// A fault raised by one kernel thread.
#[derive(Clone, Debug, PartialEq)]
pub struct Fault {
    /// Name of the kernel (or func) whose code raised the fault.
    pub kernel: &'static str,
    /// What went wrong.
    pub kind: FaultKind,
    /// The launch that faulted, when the runtime knows it (it sets it on every fault it
    /// reports; a fault made by generated code starts without one).
    pub launch: Option<LaunchId>,
}

/// The identity of one kernel launch: launches are numbered from 1 in the order the process
/// makes them, on every device (`warp_runtime::last_launch_id` gives the calling thread's
/// latest). A launch recorded into a graph keeps the number it was given at capture time on
/// every replay.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct LaunchId(pub u64);

impl fmt::Display for LaunchId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "launch #{}", self.0)
    }
}

/// The kinds of kernel fault.
#[derive(Clone, Debug, PartialEq)]
pub enum FaultKind {
    /// An array index outside the array's shape.
    OutOfBounds {
        /// The kernel parameter the array came from.
        arg: &'static str,
        /// The index, one entry per dimension (negative or huge values are shown as given).
        index: Vec<i128>,
        /// The array's shape.
        shape: Vec<usize>,
    },
    /// Integer division or remainder by zero.
    DivisionByZero,
    /// `step_by(k)` with `k <= 0` in a range loop (Rust panics at `step_by(0)`).
    BadStep {
        /// The step given.
        step: i64,
    },
    /// The reverse sweep of an adjoint kernel needed more per-thread stack than configured
    /// (`wp::config::set_adstack_bytes`).
    AdStackOverflow {
        /// The kernel source line whose value did not fit.
        line: u32,
        /// The capacity in bytes.
        capacity: usize,
    },
    /// A float input that must be finite was NaN or infinite (a volume sample position:
    /// Warp's result there is undefined, and CPU and GPU would disagree).
    NonFinite {
        /// What the values are (`"volume sample position"`).
        what: &'static str,
        /// The values as given (every component, finite or not).
        values: Vec<f64>,
    },
    /// An element of a host object's input array that must be finite has a NaN or infinite
    /// coordinate: a BVH's boxes or a mesh's points at a GPU refit, a hash grid's points at a
    /// build recorded into a graph. On a GPU such a check is a fault raised by the object's
    /// own build kernel, reported at the next synchronisation (no read-back, so the step can
    /// be recorded into a graph); `Fault::kernel` names the operation (`"Bvh::refit"`).
    NonFiniteInput {
        /// The operation's argument holding the element (`"lowers"`, `"points"`).
        arg: &'static str,
        /// The element's index (the smallest such index).
        index: usize,
        /// The element's coordinates as given.
        values: Vec<f64>,
    },
    /// Two threads of one CPU launch wrote the same array element without an atomic: a data
    /// race (undefined behaviour in Rust's memory model, as in CUDA's). Reported only with
    /// the runtime's race check on (`wp::config::set_race_check`), at the second write, which
    /// does not happen.
    WriteRace {
        /// The kernel parameter the second write went through.
        arg: &'static str,
        /// The element's index in that array, one entry per dimension.
        index: Vec<i128>,
        /// The flat launch indices (row-major over the launch dimensions) of the thread that
        /// wrote first and of the thread that wrote again.
        threads: (usize, usize),
    },
    /// A tile element index outside the tile's shape (`t[i, j]`, `tile_extract`).
    // Fixed-size and narrow fields: a fault travels inside every `Result` a launch returns,
    // so this variant must stay no larger than `OutOfBounds` (clippy's `result_large_err`).
    TileIndex {
        /// The index, one entry per dimension of the tile (the first `rank` entries count;
        /// saturated to `i64`, which a tile's extent never approaches).
        index: [i64; 4],
        /// The tile's shape (the first `rank` entries count).
        shape: [u32; 4],
        /// The tile's rank, 1..=4.
        rank: u8,
    },
    /// An index outside a fixed-size local array (`a[i]` of `let mut a = [0.0f32; 8];`), or
    /// outside the lanes of a vector, quaternion or matrix (`v[i]`, `m[(i, j)]`; `len` is the
    /// lane count, or a matrix's number of rows or columns).
    LocalIndex {
        /// The index as given (saturated to `i64`).
        index: i64,
        /// The array's length.
        len: usize,
        /// The source line of the access.
        line: u32,
    },
    /// A failed `assert!` or `debug_assert!` (checked only in debug mode), or a failed
    /// expectation (`expect_eq`, `expect_neq`, `expect_near`) in a kernel or func.
    AssertionFailed {
        /// The source line of the assertion.
        line: u32,
        /// The assertion's message: its own, else `assertion failed: <condition>` or
        /// `expect_eq(<a>, <b>) failed`, the arguments as written.
        message: &'static str,
        /// The flat launch index (row-major over the launch dimensions) of the thread that
        /// failed; `None` when the assertion is in a func, which does not know it.
        thread: Option<usize>,
    },
    /// `tile(x)` of a width other than the block's lane count, or a block dimension outside
    /// `1..=1024` (`launch_tiled` refuses such launches, so generated code never sees this).
    TileWidth {
        /// The width of the tile (its one dimension).
        width: usize,
        /// The block's lane count.
        block_dim: usize,
    },
    /// A thread of a `#[kernel(deterministic)]` launch made more float `atomic_add`/
    /// `atomic_sub` calls (in a backward launch: gradient accumulations) than the kernel's
    /// per-thread record limit: its accumulations cannot all be recorded, and none is dropped
    /// silently.
    DeterministicRecords {
        /// The flat launch index of the thread.
        thread: usize,
        /// The kernel's per-thread record limit.
        limit: u32,
    },
}

impl Fault {
    /// A new boxed fault.
    #[cold]
    pub fn new(kernel: &'static str, kind: FaultKind) -> Box<Fault> {
        Box::new(Fault {
            kernel,
            kind,
            launch: None,
        })
    }

    /// A failed assertion or expectation: what generated CPU code returns (`kernel` is the
    /// kernel or func whose code failed; `thread` as in [`FaultKind::AssertionFailed`]).
    #[cold]
    pub fn assertion_failed(
        kernel: &'static str,
        line: u32,
        message: &'static str,
        thread: Option<usize>,
    ) -> Box<Fault> {
        Fault::new(
            kernel,
            FaultKind::AssertionFailed {
                line,
                message,
                thread,
            },
        )
    }

    /// The fault, naming `launch` as the launch that raised it.
    pub fn in_launch(mut self, launch: LaunchId) -> Fault {
        self.launch = Some(launch);
        self
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.fmt_what(f)?;
        match self.launch {
            Some(launch) => write!(f, " ({launch})"),
            None => Ok(()),
        }
    }
}

impl Fault {
    /// The message without the launch.
    fn fmt_what(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.kind {
            FaultKind::OutOfBounds { arg, index, shape } => write!(
                f,
                "kernel `{}`: index {:?} is out of bounds for argument `{}` of shape {:?}",
                self.kernel, index, arg, shape
            ),
            FaultKind::DivisionByZero => {
                write!(f, "kernel `{}`: integer division by zero", self.kernel)
            }
            FaultKind::AdStackOverflow { line, capacity } => write!(
                f,
                "kernel `{}`: backward needs more than the {capacity} bytes of per-thread \
                 stack configured for loop values (at line {line}); raise it with \
                 wp::config::set_adstack_bytes or Tape::set_adstack_bytes, zero the \
                 gradients (Tape::zero), seed them and run backward again",
                self.kernel
            ),
            FaultKind::BadStep { step } => write!(
                f,
                "kernel `{}`: step_by({step}) in a range loop: the step must be positive",
                self.kernel
            ),
            FaultKind::NonFinite { what, values } => write!(
                f,
                "kernel `{}`: {what} {values:?} is not finite (NaN or infinite)",
                self.kernel
            ),
            FaultKind::NonFiniteInput { arg, index, values } => write!(
                f,
                "`{}`: argument `{arg}` has a non-finite value at index {index}: {values:?}",
                self.kernel
            ),
            FaultKind::TileIndex { index, shape, rank } => {
                let r = usize::from(*rank).min(4);
                write!(
                    f,
                    "kernel `{}`: index {:?} is out of bounds for a tile of shape {:?}",
                    self.kernel,
                    &index[..r],
                    &shape[..r]
                )
            }
            FaultKind::LocalIndex { index, len, line } => write!(
                f,
                "kernel `{}`: index {index} is out of bounds for a local array or vector of \
                 length {len} (line {line})",
                self.kernel
            ),
            FaultKind::AssertionFailed {
                line,
                message,
                thread,
            } => {
                write!(f, "kernel `{}`: {message} (line {line}", self.kernel)?;
                match thread {
                    Some(t) => write!(f, ", thread {t})"),
                    None => write!(f, ")"),
                }
            }
            FaultKind::TileWidth { width, block_dim } => write!(
                f,
                "kernel `{}`: `tile(x)` makes a tile of width {width}, but the block has \
                 {block_dim} lanes (a block has 1..=1024 lanes, and the width must equal them)",
                self.kernel
            ),
            FaultKind::WriteRace {
                arg,
                index,
                threads: (a, b),
            } => write!(
                f,
                "kernel `{}`: threads {a} and {b} (flat launch indices) both wrote element \
                 {index:?} of argument `{arg}` in one launch without an atomic (a data race); \
                 use an atomic_* builtin, or give each thread its own element",
                self.kernel
            ),
            FaultKind::DeterministicRecords { thread, limit } => write!(
                f,
                "kernel `{}`: thread {thread} made more than {limit} recorded accumulations \
                 (float atomic_add/atomic_sub calls, or in a backward launch gradient \
                 accumulations), the per-thread record limit of a deterministic kernel; raise \
                 it with #[kernel(deterministic(max_records = N))]",
                self.kernel
            ),
        }
    }
}

impl std::error::Error for Fault {}
