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
/// The errors of cudarc and of the file system are kept as the [`source`] of the variants
/// that wrap them; the message itself already names the operation and the driver's
/// description, so printing only the top error loses nothing.
///
/// [`source`]: std::error::Error::source
#[derive(Debug, Clone, thiserror::Error)]
#[non_exhaustive]
pub enum CudaError {
    /// CUDA cannot be used on this machine (no driver library, no device, driver too old,
    /// no NVRTC library). The string is the reason, e.g. "libcuda.so not found".
    #[error("CUDA is not available: {0}")]
    NotAvailable(String),
    /// A driver API call failed.
    #[error("{op}: {message} ({name})")]
    Driver {
        /// What was being done, e.g. "cuMemAllocAsync of 48000000 bytes on cuda:0".
        op: String,
        /// The `CUresult` name, e.g. "CUDA_ERROR_OUT_OF_MEMORY".
        name: String,
        /// The driver's description, e.g. "out of memory".
        message: String,
        /// cudarc's error (the raw `CUresult`).
        #[source]
        source: DriverError,
    },
    /// An NVRTC call other than the compilation itself failed.
    #[error("{op}: {message}")]
    Nvrtc {
        /// What was being done.
        op: String,
        /// NVRTC's description of the failure.
        message: String,
        /// cudarc's error (the raw `nvrtcResult`); `None` where NVRTC reported success but
        /// its result was unusable (an empty cubin).
        #[source]
        source: Option<NvrtcError>,
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
    /// A file-system operation of the kernel cache failed.
    #[error("{op}: {source}")]
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
            (NotAvailable(a), NotAvailable(b)) => a == b,
            (
                Driver {
                    op: o1,
                    name: n1,
                    message: m1,
                    source: s1,
                },
                Driver {
                    op: o2,
                    name: n2,
                    message: m2,
                    source: s2,
                },
            ) => o1 == o2 && n1 == n2 && m1 == m2 && s1 == s2,
            (
                Nvrtc {
                    op: o1,
                    message: m1,
                    source: s1,
                },
                Nvrtc {
                    op: o2,
                    message: m2,
                    source: s2,
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
            source: err,
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
            source: Some(err),
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
            CudaError::Driver { source, .. } => Some(source.0 as u32),
            _ => None,
        }
    }

    /// True for `CUDA_ERROR_OUT_OF_MEMORY` (2).
    pub fn is_out_of_memory(&self) -> bool {
        matches!(
            self,
            CudaError::Driver { source, .. }
                if source.0 == cudarc::driver::sys::CUresult::CUDA_ERROR_OUT_OF_MEMORY
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
            source: DriverError(cudarc::driver::sys::CUresult::CUDA_ERROR_OUT_OF_MEMORY),
        };
        assert_eq!(
            e.to_string(),
            "cuMemAllocAsync of 48000000 bytes on cuda:0: out of memory (CUDA_ERROR_OUT_OF_MEMORY)"
        );
        assert!(e.is_out_of_memory());
        assert_eq!(e.driver_code(), Some(2));
        // The driver's error is the source, not a string.
        let source = std::error::Error::source(&e).expect("a source");
        assert_eq!(
            source.downcast_ref::<DriverError>(),
            Some(&DriverError(
                cudarc::driver::sys::CUresult::CUDA_ERROR_OUT_OF_MEMORY
            ))
        );
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
        assert_eq!(e.to_string(), "writing cache entry /x: denied");
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
