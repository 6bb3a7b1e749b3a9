//! The runtime's error type.
//!
//! Every fallible host-side operation returns [`Result`]. Messages name the kernel, the argument
//! and the offending values, because the person reading them usually has only the message and
//! the kernel source in front of them.

use std::fmt;
use warp_core::Fault;

/// The result type of the runtime.
pub type Result<T> = std::result::Result<T, Error>;

/// What can go wrong on the host side of warp-lang.
///
/// An error that wraps a lower-level one keeps it as its
/// [`source`](std::error::Error::source) ([`Error::Cuda`]'s driver or NVRTC error,
/// [`Error::OutOfMemory`]'s on a GPU, [`Error::Step`]'s step error), and its message does not
/// repeat it, as the Rust API guidelines ask: reporters (anyhow, eyre, a loop over `source()`)
/// print the message and then each source, so a repeated cause would show twice. Print the
/// chain, not the message alone, to see why (`{:#}` of an `anyhow::Error`, or walk
/// `source()`). [`Error::Fault`] is the fault itself: its message and source are the fault's.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A kernel thread faulted (out-of-bounds index, integer division by zero, zero step). The
    /// launch stopped at the first fault it saw.
    // The fault already names the kernel, argument, index and shape: the error is the fault
    // (transparent), not a message wrapping it, so that it is not printed twice.
    #[error(transparent)]
    Fault(Fault),
    /// An array argument lives on another device than the one the launch runs on.
    #[error(
        "kernel `{kernel}`: argument `{arg}` is on device \"{found}\" but the launch is on \
         device \"{expected}\""
    )]
    DeviceMismatch {
        /// The kernel being launched.
        kernel: &'static str,
        /// The parameter the array was passed as.
        arg: &'static str,
        /// The launch device's alias.
        expected: String,
        /// The array's device alias.
        found: String,
    },
    /// The launch dimensions are not usable.
    #[error("kernel `{kernel}`: invalid launch dim {dim:?}: {reason}")]
    InvalidDim {
        /// The kernel being launched.
        kernel: &'static str,
        /// The dimensions as given.
        dim: Vec<usize>,
        /// Why they were rejected.
        reason: String,
    },
    /// The kernel destructures `tid()` into a different number of dimensions than the launch has.
    #[error(
        "kernel `{kernel}`: tid() is destructured into {tid_ndim} dimension(s) but the kernel \
         was launched with {launch_ndim} dimension(s)"
    )]
    TidMismatch {
        /// The kernel being launched.
        kernel: &'static str,
        /// How many dimensions the kernel's `tid()` yields.
        tid_ndim: usize,
        /// How many dimensions the launch has.
        launch_ndim: usize,
    },
    /// Arguments declared with `same_shape` have different shapes.
    #[error(
        "kernel `{kernel}`: arguments declared same_shape differ in shape: {}",
        ShapeList(args, shapes)
    )]
    ShapeMismatch {
        /// The kernel being launched.
        kernel: &'static str,
        /// The parameters of the group (`"dim"` stands for the launch dimensions).
        args: Vec<String>,
        /// Their shapes, in the same order.
        shapes: Vec<Vec<usize>>,
    },
    /// A tiled kernel launched with [`launch`](crate::launch()), or an ordinary kernel with
    /// [`launch_tiled`](crate::launch_tiled()): a tiled kernel's `dim` counts blocks and it
    /// needs a block size, an ordinary one has neither.
    #[error("kernel `{kernel}`: {why}")]
    LaunchKind {
        /// The kernel being launched.
        kernel: &'static str,
        /// Which launch was made and which one the kernel takes.
        why: String,
    },
    /// A `#[kernel(deterministic)]` launch that cannot keep its promise of the same bits on
    /// every run: calling a func that accumulates floats atomically (a func's accumulations
    /// are not recorded), or on a GPU inside a graph capture or with more record slots than
    /// its ordering sorts.
    #[error("kernel `{kernel}` is deterministic, but {why}")]
    Deterministic {
        /// The kernel being launched.
        kernel: &'static str,
        /// What stands in the way.
        why: String,
    },
    /// The block size of a tiled launch is unusable: zero, above 1024 (or above what the GPU
    /// allows for the kernel), or not the width the kernel's tiles fix.
    #[error("kernel `{kernel}`: invalid block_dim {block_dim}: {why}")]
    InvalidBlockDim {
        /// The kernel being launched.
        kernel: &'static str,
        /// The block size as given.
        block_dim: usize,
        /// Why it was rejected.
        why: String,
    },
    /// One block of a tiled kernel needs more stack on the CPU (its tiles and per-lane values)
    /// than the threads that run tiled launches have to give it.
    #[error(
        "kernel `{kernel}`: a block needs {bytes} bytes of stack on the CPU for its tiles and \
         per-lane values, more than the {limit} bytes a block may take; use smaller tiles or a \
         smaller block_dim"
    )]
    TileFrame {
        /// The kernel being launched.
        kernel: &'static str,
        /// The stack one block needs.
        bytes: usize,
        /// The most a block may take (half the stack of a tiled launch's threads).
        limit: usize,
    },
    /// One block of a tiled kernel needs more shared memory than the GPU gives a block.
    #[error(
        "kernel `{kernel}`: a block of {block_dim} threads needs {requested} bytes of shared \
         memory on \"{device}\", which gives a block at most {available}; use smaller tiles"
    )]
    SharedMemory {
        /// The kernel being launched.
        kernel: &'static str,
        /// The device's alias.
        device: String,
        /// The shared memory one block needs (its tiles and the kernel's static shared memory).
        requested: usize,
        /// The most one block may have on the device (with the opt-in carve-out).
        available: usize,
        /// The block size of the launch.
        block_dim: usize,
    },
    /// The CUDA driver or NVRTC reported an error (copy, compilation, launch, an allocation
    /// failing for another reason than memory). Only with the `cuda` feature: without it
    /// nothing reaches CUDA.
    #[cfg(feature = "cuda")]
    #[error("CUDA error on \"{device}\"")]
    Cuda {
        /// The device (`"nvrtc"` for ahead-of-time compilation, which has none).
        device: String,
        /// What failed and why (an NVRTC error includes the compiler's log): the error's
        /// `source`.
        #[source]
        source: warp_cuda::CudaError,
    },
    /// A device could not allocate `bytes` bytes: the host allocator returned nothing, or the
    /// CUDA driver said `CUDA_ERROR_OUT_OF_MEMORY`. The device is still usable (smaller
    /// allocations may succeed, and earlier arrays are intact).
    ///
    /// A size that does not even fit in `usize` (a shape whose byte count overflows) is an
    /// [`Error::InvalidArgument`] instead: no allocation was attempted.
    #[error("out of memory on \"{device}\": {bytes} bytes could not be allocated")]
    #[non_exhaustive]
    OutOfMemory {
        /// The device's alias.
        device: String,
        /// The size of the allocation that failed.
        bytes: usize,
        /// On a GPU, the driver's error (it names the allocation call); `None` on the CPU,
        /// whose allocator gives no reason, and for a size past `isize::MAX` bytes, which no
        /// device is asked for.
        #[cfg(feature = "cuda")]
        #[source]
        source: Option<warp_cuda::CudaError>,
    },
    /// No such device, or it cannot be used.
    #[error("no device \"{name}\": {reason}")]
    NoDevice {
        /// The alias that was asked for.
        name: String,
        /// Why it cannot be used.
        reason: String,
    },
    /// A launch in `config::set_verify_fp` mode left a NaN or an infinity in an array.
    #[error("kernel `{kernel}` wrote a non-finite value to `{arg}` at index {index:?}: {value}")]
    NonFinite {
        /// The kernel.
        kernel: &'static str,
        /// The array parameter.
        arg: &'static str,
        /// The index of the first such element (row-major order).
        index: Vec<usize>,
        /// The element.
        value: String,
    },
    /// [`Array::check_finite`](crate::Array::check_finite) found a NaN or an infinity.
    #[error("{what} diverged: non-finite value at index {index:?}: {value}")]
    Diverged {
        /// What was checked (the caller's words).
        what: String,
        /// The index of the first such element (row-major order).
        index: Vec<usize>,
        /// The element.
        value: String,
    },
    /// Backward through a kernel that has no adjoint.
    #[error("cannot run backward through kernel `{kernel}`: it {reason}")]
    NotDifferentiable {
        /// The kernel.
        kernel: &'static str,
        /// Why (a construct the reverse sweep does not handle yet, `enable_backward = false`,
        /// or a device without adjoint support yet).
        reason: String,
    },
    /// Forward mode ([`jvp`](crate::autograd::jvp), [`hvp`](crate::autograd::hvp)) through a
    /// kernel that has no tangent kernel.
    #[error("cannot differentiate kernel `{kernel}` in forward mode: it {reason}")]
    NoTangent {
        /// The kernel.
        kernel: &'static str,
        /// Why: the construct forward mode does not differentiate and its line, or a build
        /// without the `forward-mode` feature.
        reason: &'static str,
    },
    /// An operation that a graph capture cannot record was called inside one (an allocation,
    /// a read-back, a kernel not compiled before the capture, a nested capture, work on
    /// another device), or a graph was launched where it cannot run.
    #[error("graph capture: {what}")]
    Capture {
        /// What was refused and what to do instead.
        what: String,
    },
    /// A kernel uses a capability the device lacks (see `warp_core::capability`): found when
    /// the kernel is loaded there, before anything is compiled.
    #[error(
        "kernel `{kernel}` cannot run on \"{device}\" ({found}): it uses {capability}, which \
         needs {needs}"
    )]
    MissingCapability {
        /// The kernel.
        kernel: &'static str,
        /// The device's alias.
        device: String,
        /// What the device is (`sm_35`).
        found: String,
        /// The capability, in words.
        capability: &'static str,
        /// What it needs (`sm_50 or newer`).
        needs: String,
    },
    /// A host-side API was called with unusable arguments (lengths that do not match a shape,
    /// a view range out of bounds, an impossible reinterpretation, ...).
    #[error("invalid argument: {what}")]
    InvalidArgument {
        /// What was wrong, with the values involved.
        what: String,
    },
    /// The step function of a checkpointed rollout ([`Checkpointed`](crate::Checkpointed))
    /// failed; `source` is its error.
    #[error("step {step} of a checkpointed rollout ({pass} pass) failed")]
    Step {
        /// The step `t` (the step from state `t` to state `t + 1`).
        step: usize,
        /// The pass that ran it: "forward", "recomputation" or "backward".
        pass: &'static str,
        /// The step function's error: the error's `source`.
        source: Box<Error>,
    },
}

impl Error {
    /// The error, with a fault that does not name its launch yet naming `launch` (the CPU's
    /// faults come back from the launch that raised them).
    pub(crate) fn in_launch(self, launch: warp_core::LaunchId) -> Error {
        match self {
            Error::Fault(f) if f.launch.is_none() => Error::Fault(f.in_launch(launch)),
            e => e,
        }
    }
}

impl From<Box<Fault>> for Error {
    #[cold]
    fn from(fault: Box<Fault>) -> Self {
        Error::Fault(*fault)
    }
}

impl From<Fault> for Error {
    #[cold]
    fn from(fault: Fault) -> Self {
        Error::Fault(fault)
    }
}

impl Error {
    /// Shorthand for [`Error::InvalidArgument`]; cold because errors are the rare path.
    #[cold]
    pub(crate) fn invalid(what: impl Into<String>) -> Self {
        Error::InvalidArgument { what: what.into() }
    }

    /// [`Error::invalid`] as "`what`: `why`" (the call or object, then what is wrong).
    #[cold]
    pub(crate) fn invalid_in(what: &str, why: impl fmt::Display) -> Self {
        Self::invalid(format!("{what}: {why}"))
    }

    /// [`Error::Cuda`]: `source` on `device`.
    #[cfg(feature = "cuda")]
    #[cold]
    pub(crate) fn cuda(device: impl Into<String>, source: warp_cuda::CudaError) -> Self {
        Error::Cuda {
            device: device.into(),
            source,
        }
    }

    /// [`Error::OutOfMemory`] with no source: the host allocator's (it gives no reason), or a
    /// size past what any device can address.
    #[cold]
    pub(crate) fn out_of_memory(device: impl Into<String>, bytes: usize) -> Self {
        Error::OutOfMemory {
            device: device.into(),
            bytes,
            #[cfg(feature = "cuda")]
            source: None,
        }
    }

    /// A failed GPU allocation of `bytes` bytes: [`Error::OutOfMemory`] when the driver says
    /// so (keeping its error as the source), [`Error::Cuda`] otherwise.
    #[cfg(feature = "cuda")]
    #[cold]
    pub(crate) fn cuda_alloc(
        device: impl Into<String>,
        bytes: usize,
        source: warp_cuda::CudaError,
    ) -> Self {
        if source.is_out_of_memory() {
            Error::OutOfMemory {
                device: device.into(),
                bytes,
                source: Some(source),
            }
        } else {
            Error::cuda(device, source)
        }
    }
}

/// An error and its sources, "error: source: source's source", for a `log` line (a message
/// alone no longer carries its source).
#[cfg_attr(not(feature = "cuda"), allow(dead_code))]
pub(crate) struct Chain<'a>(pub &'a (dyn std::error::Error + 'static));

impl fmt::Display for Chain<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)?;
        let mut source = self.0.source();
        while let Some(s) = source {
            write!(f, ": {s}")?;
            source = s.source();
        }
        Ok(())
    }
}

/// `same_shape`'s arguments and their shapes, as [`Error::ShapeMismatch`] lists them.
struct ShapeList<'a>(&'a [String], &'a [Vec<usize>]);

impl fmt::Display for ShapeList<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, (arg, shape)) in self.0.iter().zip(self.1).enumerate() {
            if i > 0 {
                write!(f, ", ")?;
            }
            write!(f, "`{arg}` has shape {shape:?}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use warp_core::FaultKind;

    #[test]
    fn fault_converts_and_displays() {
        let fault = Fault::new(
            "k",
            FaultKind::OutOfBounds {
                arg: "a",
                index: vec![-1],
                shape: vec![4],
            },
        );
        let err = Error::from(fault);
        assert_eq!(
            err.to_string(),
            "kernel `k`: index [-1] is out of bounds for argument `a` of shape [4]"
        );
        // The error is the fault (transparent): not the fault again as its source.
        assert!(std::error::Error::source(&err).is_none());
    }

    #[test]
    fn messages_name_everything() {
        let e = Error::DeviceMismatch {
            kernel: "k",
            arg: "x",
            expected: "cpu".into(),
            found: "cuda:0".into(),
        };
        assert_eq!(
            e.to_string(),
            "kernel `k`: argument `x` is on device \"cuda:0\" but the launch is on device \"cpu\""
        );
        let e = Error::ShapeMismatch {
            kernel: "k",
            args: vec!["a".into(), "dim".into()],
            shapes: vec![vec![3], vec![4]],
        };
        assert_eq!(
            e.to_string(),
            "kernel `k`: arguments declared same_shape differ in shape: `a` has shape [3], `dim` \
             has shape [4]"
        );
        let e = Error::TidMismatch {
            kernel: "k",
            tid_ndim: 2,
            launch_ndim: 1,
        };
        assert_eq!(
            e.to_string(),
            "kernel `k`: tid() is destructured into 2 dimension(s) but the kernel was launched \
             with 1 dimension(s)"
        );
        let e = Error::InvalidDim {
            kernel: "k",
            dim: vec![0],
            reason: "zero".into(),
        };
        assert_eq!(e.to_string(), "kernel `k`: invalid launch dim [0]: zero");
    }

    /// One error of each variant that can have a source, and a few without.
    fn representative() -> Vec<Error> {
        let fault = Fault::new(
            "k",
            FaultKind::OutOfBounds {
                arg: "a",
                index: vec![4],
                shape: vec![4],
            },
        );
        let mut errors = vec![
            Error::from(fault.clone()),
            Error::Step {
                step: 3,
                pass: "forward",
                source: Box::new(Error::from(fault)),
            },
            Error::out_of_memory("cpu", 1 << 40),
            Error::invalid("Array::view: range 0..9 past 8"),
        ];
        #[cfg(feature = "cuda")]
        {
            let io = warp_cuda::CudaError::Io {
                op: "writing cache entry /x".into(),
                source: std::sync::Arc::new(std::io::Error::other("disk full")),
            };
            errors.push(Error::cuda("cuda:0", io));
            errors.push(Error::cuda(
                "nvrtc",
                warp_cuda::CudaError::Compile {
                    name: "k.cu".into(),
                    arch: 90,
                    log: "k.cu(3): error: x".into(),
                },
            ));
        }
        errors
    }

    #[test]
    fn no_message_repeats_its_source() {
        let mut with_source = 0;
        for e in representative() {
            if let Some(source) = std::error::Error::source(&e) {
                with_source += 1;
                let (message, cause) = (e.to_string(), source.to_string());
                assert!(!message.contains(&cause), "{message:?} repeats {cause:?}");
            }
        }
        assert!(with_source >= 1);
    }

    #[test]
    fn a_chain_walk_prints_each_cause_once() {
        // What anyhow's `{:#}` or eyre's report does: the message, then each source.
        let fault = Fault::new(
            "k",
            FaultKind::OutOfBounds {
                arg: "a",
                index: vec![4],
                shape: vec![4],
            },
        );
        let cause = fault.to_string();
        let e = Error::Step {
            step: 3,
            pass: "backward",
            source: Box::new(Error::from(fault)),
        };
        let mut lines = vec![e.to_string()];
        let mut source = std::error::Error::source(&e);
        while let Some(s) = source {
            lines.push(s.to_string());
            source = s.source();
        }
        assert_eq!(
            lines,
            [
                "step 3 of a checkpointed rollout (backward pass) failed".to_string(),
                cause.clone()
            ]
        );
        let report = Chain(&e).to_string();
        assert_eq!(report, lines.join(": "));
        assert_eq!(report.matches(&cause).count(), 1, "{report}");
    }

    #[cfg(feature = "cuda")]
    #[test]
    fn a_cuda_error_reads_alone_and_in_its_chain() {
        let e = Error::cuda(
            "nvrtc",
            warp_cuda::CudaError::Compile {
                name: "k.cu".into(),
                arch: 90,
                log: "k.cu(3): error: x".into(),
            },
        );
        assert_eq!(e.to_string(), "CUDA error on \"nvrtc\"");
        assert_eq!(
            Chain(&e).to_string(),
            "CUDA error on \"nvrtc\": NVRTC failed to compile k.cu for sm_90:\nk.cu(3): error: x"
        );
    }
}
