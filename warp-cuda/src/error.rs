//! Errors of the CUDA layer.
//!
//! Every error says what was being done ("cuMemAllocAsync of 48000000 bytes on cuda:0") and
//! why it failed ("out of memory"), because a bare `CUDA_ERROR_OUT_OF_MEMORY` from deep inside
//! a launch is not actionable. The operation text is built only on the error path, so the
//! success path of hot calls (launch, copies) allocates nothing.

use std::sync::Arc;

use cudarc::driver::result::DriverError;
use cudarc::nvrtc::result::NvrtcError;

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, CudaError>;

/// An error from the CUDA driver, NVRTC, the kernel cache, or a rejected argument.
///
/// Following the Rust API guidelines, a message never repeats its
/// [`source`](std::error::Error::source): error reporters (anyhow, eyre, `log` lines that walk
/// the chain) print the message and then each source, so a repeated cause would be printed
/// twice. [`CudaError::Io`] keeps the file system's error as its source and names only the
/// operation. The driver's and NVRTC's codes are not sources but fields
/// ([`CudaError::Driver`]'s and [`CudaError::Nvrtc`]'s `code`): their messages are part of
/// the text, read from the library when the error is made, because cudarc's errors display as
/// their `Debug` form and call back into the library when printed.
#[derive(Debug, Clone, thiserror::Error)]
#[non_exhaustive]
pub enum CudaError {
    /// CUDA cannot be used on this machine (no driver library, no device, driver too old,
    /// no NCCL library for collectives). The string is the reason, e.g. "libcuda.so not
    /// found".
    #[error("CUDA is not available: {0}")]
    NotAvailable(String),
    /// Kernels cannot be compiled at run time: NVRTC cannot be loaded (or is turned off by
    /// `WARP_LANG_NO_NVRTC`). The GPU itself may work: memory, copies and prebuilt cubins
    /// (`wp::aot`) need no NVRTC. The string is the reason, which names NVRTC.
    #[error("kernels cannot be compiled: {0}")]
    NoNvrtc(String),
    /// A driver API call failed.
    #[error("{op}: {message} ({name})")]
    Driver {
        /// What was being done, e.g. "cuMemAllocAsync of 48000000 bytes on cuda:0".
        op: String,
        /// The `CUresult` name, e.g. "CUDA_ERROR_OUT_OF_MEMORY".
        name: String,
        /// The driver's description, e.g. "out of memory".
        message: String,
        /// cudarc's error (the raw `CUresult`). Not the error's `source`: `name` and
        /// `message` already say what it says.
        code: DriverError,
    },
    /// An NVRTC call other than the compilation itself failed.
    #[error("{op}: {message}")]
    Nvrtc {
        /// What was being done.
        op: String,
        /// NVRTC's description of the failure.
        message: String,
        /// cudarc's error (the raw `nvrtcResult`); `None` where NVRTC reported success but
        /// its result was unusable (an empty cubin). Not the error's `source`: `message`
        /// already says what it says.
        code: Option<NvrtcError>,
    },
    /// NVRTC rejected the source; `log` is NVRTC's full log (errors with line numbers).
    #[error("NVRTC failed to compile {name} for sm_{arch}:\n{log}")]
    Compile {
        /// The program name given to `compile`.
        name: String,
        /// The GPU architecture compiled for, e.g. 90.
        arch: u32,
        /// NVRTC's log.
        log: String,
    },
    /// An argument was rejected before reaching CUDA (out-of-range offset, wrong device, ...).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// An NCCL call failed (`warp_cuda::nccl`).
    #[error("{op}: {message}")]
    Nccl {
        /// What was being done, e.g. "ncclAllReduce (Sum) of 1024 F32 on rank 1".
        op: String,
        /// The `ncclResult_t` code.
        code: i32,
        /// NCCL's description and its last error text.
        message: String,
    },
    /// A wait for other ranks or another process passed its timeout; what was waited for has
    /// been aborted.
    #[error("{op}: timed out after {waited:.1?}")]
    Timeout {
        /// What was waited for.
        op: String,
        /// How long it waited.
        waited: std::time::Duration,
    },
    /// A file-system operation of the kernel cache failed; the I/O error is the `source`.
    #[error("I/O error: {op}")]
    Io {
        /// What was being done, with the path.
        op: String,
        /// The I/O error, shared because `std::io::Error` is not `Clone`; as the error's
        /// `source` it downcasts to `Arc<std::io::Error>`.
        #[source]
        source: Arc<std::io::Error>,
    },
}

/// Equality compares what the variants say; two I/O errors are equal when their kinds and
/// messages are (`std::io::Error` has no equality of its own).
impl PartialEq for CudaError {
    fn eq(&self, other: &Self) -> bool {
        use CudaError::*;
        match (self, other) {
            (NotAvailable(a), NotAvailable(b)) | (NoNvrtc(a), NoNvrtc(b)) => a == b,
            (
                Driver {
                    op: o1,
                    name: n1,
                    message: m1,
                    code: s1,
                },
                Driver {
                    op: o2,
                    name: n2,
                    message: m2,
                    code: s2,
                },
            ) => o1 == o2 && n1 == n2 && m1 == m2 && s1 == s2,
            (
                Nvrtc {
                    op: o1,
                    message: m1,
                    code: s1,
                },
                Nvrtc {
                    op: o2,
                    message: m2,
                    code: s2,
                },
            ) => o1 == o2 && m1 == m2 && s1 == s2,
            (
                Compile {
                    name: n1,
                    arch: a1,
                    log: l1,
                },
                Compile {
                    name: n2,
                    arch: a2,
                    log: l2,
                },
            ) => n1 == n2 && a1 == a2 && l1 == l2,
            (InvalidArgument(a), InvalidArgument(b)) => a == b,
            (
                Nccl {
                    op: o1,
                    code: c1,
                    message: m1,
                },
                Nccl {
                    op: o2,
                    code: c2,
                    message: m2,
                },
            ) => o1 == o2 && c1 == c2 && m1 == m2,
            (Timeout { op: o1, waited: w1 }, Timeout { op: o2, waited: w2 }) => {
                o1 == o2 && w1 == w2
            }
            (Io { op: o1, source: s1 }, Io { op: o2, source: s2 }) => {
                o1 == o2 && s1.kind() == s2.kind() && s1.to_string() == s2.to_string()
            }
            _ => false,
        }
    }
}

impl Eq for CudaError {}

/// An error and its sources, "error: source: source's source", as a `log` line shows an error
/// (the message alone no longer carries its source).
pub(crate) struct Chain<'a>(pub &'a (dyn std::error::Error + 'static));

impl std::fmt::Display for Chain<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.0)?;
        let mut source = self.0.source();
        while let Some(s) = source {
            write!(f, ": {s}")?;
            source = s.source();
        }
        Ok(())
    }
}

impl CudaError {
    /// Wraps a driver error with a description of the operation.
    pub(crate) fn driver(err: DriverError, op: impl Into<String>) -> Self {
        // `error_name`/`error_string` call back into libcuda; a `DriverError` exists only if
        // the library was loaded, so these calls are safe to make here. They are made now,
        // not when the error is displayed, so that a message never depends on the library
        // still being usable.
        let name = err
            .error_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|_| format!("{:?}", err.0));
        let message = err
            .error_string()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|_| name.clone());
        CudaError::Driver {
            op: op.into(),
            name,
            message,
            code: err,
        }
    }

    /// Wraps an NVRTC error with a description of the operation.
    pub(crate) fn nvrtc(err: NvrtcError, op: impl Into<String>) -> Self {
        let message = unsafe {
            // SAFETY: nvrtcGetErrorString returns a pointer to a static NUL-terminated string
            // (or null for unknown codes, which we check).
            let p = cudarc::nvrtc::sys::nvrtcGetErrorString(err.0);
            if p.is_null() {
                format!("{:?}", err.0)
            } else {
                std::ffi::CStr::from_ptr(p).to_string_lossy().into_owned()
            }
        };
        CudaError::Nvrtc {
            op: op.into(),
            message,
            code: Some(err),
        }
    }

    pub(crate) fn io(err: std::io::Error, op: impl Into<String>) -> Self {
        CudaError::Io {
            op: op.into(),
            source: Arc::new(err),
        }
    }

    /// The raw `CUresult` code, for driver errors.
    pub fn driver_code(&self) -> Option<u32> {
        match self {
            CudaError::Driver { code, .. } => Some(code.0 as u32),
            _ => None,
        }
    }

    /// True for `CUDA_ERROR_OUT_OF_MEMORY` (2).
    pub fn is_out_of_memory(&self) -> bool {
        matches!(
            self,
            CudaError::Driver { code, .. }
                if code.0 == cudarc::driver::sys::CUresult::CUDA_ERROR_OUT_OF_MEMORY
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_says_what_and_why() {
        // Built by hand: `CudaError::driver` would ask libcuda for the name, and CI has none.
        let e = CudaError::Driver {
            op: "cuMemAllocAsync of 48000000 bytes on cuda:0".into(),
            name: "CUDA_ERROR_OUT_OF_MEMORY".into(),
            message: "out of memory".into(),
            code: DriverError(cudarc::driver::sys::CUresult::CUDA_ERROR_OUT_OF_MEMORY),
        };
        assert_eq!(
            e.to_string(),
            "cuMemAllocAsync of 48000000 bytes on cuda:0: out of memory (CUDA_ERROR_OUT_OF_MEMORY)"
        );
        assert!(e.is_out_of_memory());
        assert_eq!(e.driver_code(), Some(2));
        // The driver's description is in the message, so its raw error is not the source too
        // (a reporter would print the cause twice).
        assert!(std::error::Error::source(&e).is_none());
        let c = CudaError::Compile {
            name: "k.cu".into(),
            arch: 90,
            log: "k.cu(3): error: x".into(),
        };
        assert!(c.to_string().contains("sm_90") && c.to_string().contains("error: x"));
        assert!(CudaError::NotAvailable("no CUDA device".into())
            .to_string()
            .contains("no CUDA device"));
    }
}

#[cfg(test)]
mod io_tests {
    use super::*;

    #[test]
    fn io_error_is_the_source_and_compares_by_kind_and_message() {
        let e = CudaError::io(
            std::io::Error::new(std::io::ErrorKind::PermissionDenied, "denied"),
            "writing cache entry /x",
        );
        // The message names the operation; the cause is the source, printed once by a reporter.
        assert_eq!(e.to_string(), "I/O error: writing cache entry /x");
        assert_eq!(
            Chain(&e).to_string(),
            "I/O error: writing cache entry /x: denied"
        );
        let source = std::error::Error::source(&e).expect("a source");
        // The source is the `Arc` (it is an error itself, forwarding to the `io::Error`).
        let io = source
            .downcast_ref::<Arc<std::io::Error>>()
            .expect("an Arc<io::Error>");
        assert_eq!(io.kind(), std::io::ErrorKind::PermissionDenied);
        assert_eq!(e.clone(), e);
        let other = CudaError::io(
            std::io::Error::new(std::io::ErrorKind::NotFound, "denied"),
            "writing cache entry /x",
        );
        assert_ne!(e, other);
    }
}

#[cfg(test)]
mod source_tests {
    use super::*;
    use std::error::Error as _;

    /// One error of each variant (a driver error built by hand: CI has no libcuda to name it).
    fn every_variant() -> Vec<CudaError> {
        use cudarc::driver::sys::CUresult;
        vec![
            CudaError::NotAvailable("libcuda.so not found".into()),
            CudaError::NoNvrtc("NVRTC's libnvrtc.so not found".into()),
            CudaError::Driver {
                op: "cuMemAllocAsync of 8 bytes on cuda:0".into(),
                name: "CUDA_ERROR_OUT_OF_MEMORY".into(),
                message: "out of memory".into(),
                code: DriverError(CUresult::CUDA_ERROR_OUT_OF_MEMORY),
            },
            CudaError::Nvrtc {
                op: "nvrtcGetCUBIN(k)".into(),
                message: "NVRTC produced no cubin".into(),
                code: None,
            },
            CudaError::Compile {
                name: "k.cu".into(),
                arch: 90,
                log: "k.cu(3): error: x".into(),
            },
            CudaError::InvalidArgument("offset 9 past 8".into()),
            CudaError::Nccl {
                op: "ncclAllReduce".into(),
                code: 3,
                message: "internal error".into(),
            },
            CudaError::Timeout {
                op: "waiting for rank 1".into(),
                waited: std::time::Duration::from_secs(2),
            },
            CudaError::io(
                std::io::Error::new(std::io::ErrorKind::PermissionDenied, "permission denied"),
                "writing cache entry /x",
            ),
        ]
    }

    #[test]
    fn no_message_repeats_its_source() {
        for e in every_variant() {
            if let Some(source) = e.source() {
                let (message, cause) = (e.to_string(), source.to_string());
                assert!(!message.contains(&cause), "{message:?} repeats {cause:?}");
            }
        }
    }

    #[test]
    fn a_chain_walk_prints_the_cause_once() {
        // What anyhow's `{:#}` or eyre's report does: the message, then each source.
        let e = CudaError::io(
            std::io::Error::new(std::io::ErrorKind::PermissionDenied, "permission denied"),
            "writing cache entry /x",
        );
        let mut lines = vec![e.to_string()];
        let mut source = e.source();
        while let Some(s) = source {
            lines.push(s.to_string());
            source = s.source();
        }
        assert_eq!(
            lines,
            ["I/O error: writing cache entry /x", "permission denied"]
        );
        let report = lines.join(": ");
        assert_eq!(report.matches("permission denied").count(), 1, "{report}");
        assert_eq!(Chain(&e).to_string(), report);
    }
}
