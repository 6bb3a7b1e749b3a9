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
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Error {
    /// A kernel thread faulted (out-of-bounds index, integer division by zero, zero step). The
    /// launch stopped at the first fault it saw.
    Fault(Fault),
    /// An array argument lives on another device than the one the launch runs on.
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
    InvalidDim {
        /// The kernel being launched.
        kernel: &'static str,
        /// The dimensions as given.
        dim: Vec<usize>,
        /// Why they were rejected.
        reason: String,
    },
    /// The kernel destructures `tid()` into a different number of dimensions than the launch has.
    TidMismatch {
        /// The kernel being launched.
        kernel: &'static str,
        /// How many dimensions the kernel's `tid()` yields.
        tid_ndim: usize,
        /// How many dimensions the launch has.
        launch_ndim: usize,
    },
    /// Arguments declared with `same_shape` have different shapes.
    ShapeMismatch {
        /// The kernel being launched.
        kernel: &'static str,
        /// The parameters of the group (`"dim"` stands for the launch dimensions).
        args: Vec<String>,
        /// Their shapes, in the same order.
        shapes: Vec<Vec<usize>>,
    },
    /// A device is unknown or not available in this build.
    /// The CUDA driver or NVRTC reported an error (allocation, copy, compilation, launch).
    Cuda {
        /// The device.
        device: String,
        /// What failed and why (an NVRTC error includes the compiler's log).
        message: String,
    },
    /// No such device, or it cannot be used.
    NoDevice {
        /// The alias that was asked for.
        name: String,
        /// Why it cannot be used.
        reason: String,
    },
    /// A launch in `config::set_verify_fp` mode left a NaN or an infinity in an array.
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
    Diverged {
        /// What was checked (the caller's words).
        what: String,
        /// The index of the first such element (row-major order).
        index: Vec<usize>,
        /// The element.
        value: String,
    },
    /// Backward through a kernel that has no adjoint.
    NotDifferentiable {
        /// The kernel.
        kernel: &'static str,
        /// Why (a construct the reverse sweep does not handle yet, `enable_backward = false`,
        /// or a device without adjoint support yet).
        reason: String,
    },
    /// Forward mode ([`jvp`](crate::autograd::jvp), [`hvp`](crate::autograd::hvp)) through a
    /// kernel that has no tangent kernel.
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
    Capture {
        /// What was refused and what to do instead.
        what: String,
    },
    /// A host-side API was called with unusable arguments (lengths that do not match a shape,
    /// a view range out of bounds, an impossible reinterpretation, ...).
    InvalidArgument {
        /// What was wrong, with the values involved.
        what: String,
    },
    /// The step function of a checkpointed rollout ([`Checkpointed`](crate::Checkpointed))
    /// failed; `source` is its error.
    Step {
        /// The step `t` (the step from state `t` to state `t + 1`).
        step: usize,
        /// The pass that ran it: "forward", "recomputation" or "backward".
        pass: &'static str,
        /// The step function's error.
        source: Box<Error>,
    },
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
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            // The fault already names the kernel, argument, index and shape.
            Error::Fault(fault) => write!(f, "{fault}"),
            Error::DeviceMismatch {
                kernel,
                arg,
                expected,
                found,
            } => write!(
                f,
                "kernel `{kernel}`: argument `{arg}` is on device \"{found}\" but the launch is \
                 on device \"{expected}\""
            ),
            Error::InvalidDim {
                kernel,
                dim,
                reason,
            } => {
                write!(f, "kernel `{kernel}`: invalid launch dim {dim:?}: {reason}")
            }
            Error::TidMismatch {
                kernel,
                tid_ndim,
                launch_ndim,
            } => write!(
                f,
                "kernel `{kernel}`: tid() is destructured into {tid_ndim} dimension(s) but the \
                 kernel was launched with {launch_ndim} dimension(s)"
            ),
            Error::ShapeMismatch {
                kernel,
                args,
                shapes,
            } => {
                write!(
                    f,
                    "kernel `{kernel}`: arguments declared same_shape differ in shape: "
                )?;
                for (i, (arg, shape)) in args.iter().zip(shapes).enumerate() {
                    if i > 0 {
                        write!(f, ", ")?;
                    }
                    write!(f, "`{arg}` has shape {shape:?}")?;
                }
                Ok(())
            }
            Error::NoDevice { name, reason } => write!(f, "no device \"{name}\": {reason}"),
            Error::Cuda { device, message } => write!(f, "CUDA error on \"{device}\": {message}"),
            Error::InvalidArgument { what } => write!(f, "invalid argument: {what}"),
            Error::Step { step, pass, source } => write!(
                f,
                "step {step} of a checkpointed rollout ({pass} pass): {source}"
            ),
            Error::Capture { what } => write!(f, "graph capture: {what}"),
            Error::NonFinite {
                kernel,
                arg,
                index,
                value,
            } => write!(
                f,
                "kernel `{kernel}` wrote a non-finite value to `{arg}` at index {index:?}: {value}"
            ),
            Error::Diverged { what, index, value } => {
                write!(
                    f,
                    "{what} diverged: non-finite value at index {index:?}: {value}"
                )
            }
            Error::NotDifferentiable { kernel, reason } => {
                write!(
                    f,
                    "cannot run backward through kernel `{kernel}`: it {reason}"
                )
            }
            Error::NoTangent { kernel, reason } => {
                write!(
                    f,
                    "cannot differentiate kernel `{kernel}` in forward mode: it {reason}"
                )
            }
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Fault(fault) => Some(fault),
            Error::Step { source, .. } => Some(source.as_ref()),
            _ => None,
        }
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
        assert!(std::error::Error::source(&err).is_some());
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
}
