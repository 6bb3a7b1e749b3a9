//! Errors of the CUDA layer.
//!
//! Every error says what was being done ("cuMemAllocAsync of 48000000 bytes on cuda:0") and
//! why it failed ("out of memory"), because a bare `CUDA_ERROR_OUT_OF_MEMORY` from deep inside
//! a launch is not actionable. The operation text is built only on the error path, so the
//! success path of hot calls (launch, copies) allocates nothing.

use std::fmt;

use cudarc::driver::result::DriverError;
use cudarc::nvrtc::result::NvrtcError;

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, CudaError>;

/// An error from the CUDA driver, NVRTC, the kernel cache, or a rejected argument.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum CudaError {
    /// CUDA cannot be used on this machine (no driver library, no device, driver too old,
    /// no NVRTC library). The string is the reason, e.g. "libcuda.so not found".
    NotAvailable(String),
    /// A driver API call failed.
    Driver {
        /// What was being done, e.g. "cuMemAllocAsync of 48000000 bytes on cuda:0".
        op: String,
        /// The raw `CUresult` value.
        code: u32,
        /// The `CUresult` name, e.g. "CUDA_ERROR_OUT_OF_MEMORY".
        name: String,
        /// The driver's description, e.g. "out of memory".
        message: String,
    },
    /// An NVRTC call other than the compilation itself failed.
    Nvrtc {
        /// What was being done.
        op: String,
        /// NVRTC's description of the failure.
        message: String,
    },
    /// NVRTC rejected the source; `log` is NVRTC's full log (errors with line numbers).
    Compile {
        /// The program name given to `compile`.
        name: String,
        /// The GPU architecture compiled for, e.g. 90.
        arch: u32,
        /// NVRTC's log.
        log: String,
    },
    /// An argument was rejected before reaching CUDA (out-of-range offset, wrong device, ...).
    InvalidArgument(String),
    /// A file-system operation of the kernel cache failed.
    Io {
        /// What was being done, with the path.
        op: String,
        /// The I/O error kind.
        kind: std::io::ErrorKind,
        /// The I/O error message.
        message: String,
    },
}

impl CudaError {
    /// Wraps a driver error with a description of the operation.
    pub(crate) fn driver(err: DriverError, op: impl Into<String>) -> Self {
        // `error_name`/`error_string` call back into libcuda; a `DriverError` exists only if
        // the library was loaded, so these calls are safe to make here.
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
            code: err.0 as u32,
            name,
            message,
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
        }
    }

    pub(crate) fn io(err: &std::io::Error, op: impl Into<String>) -> Self {
        CudaError::Io {
            op: op.into(),
            kind: err.kind(),
            message: err.to_string(),
        }
    }

    /// The raw `CUresult` code, for driver errors.
    pub fn driver_code(&self) -> Option<u32> {
        match self {
            CudaError::Driver { code, .. } => Some(*code),
            _ => None,
        }
    }

    /// True for `CUDA_ERROR_OUT_OF_MEMORY` (2).
    pub fn is_out_of_memory(&self) -> bool {
        self.driver_code() == Some(2)
    }
}

impl fmt::Display for CudaError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CudaError::NotAvailable(reason) => write!(f, "CUDA is not available: {reason}"),
            CudaError::Driver {
                op, name, message, ..
            } => write!(f, "{op}: {message} ({name})"),
            CudaError::Nvrtc { op, message } => write!(f, "{op}: {message}"),
            CudaError::Compile { name, arch, log } => {
                write!(f, "NVRTC failed to compile {name} for sm_{arch}:\n{log}")
            }
            CudaError::InvalidArgument(msg) => write!(f, "invalid argument: {msg}"),
            CudaError::Io { op, message, .. } => write!(f, "{op}: {message}"),
        }
    }
}

impl std::error::Error for CudaError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_says_what_and_why() {
        let e = CudaError::Driver {
            op: "cuMemAllocAsync of 48000000 bytes on cuda:0".into(),
            code: 2,
            name: "CUDA_ERROR_OUT_OF_MEMORY".into(),
            message: "out of memory".into(),
        };
        assert_eq!(
            e.to_string(),
            "cuMemAllocAsync of 48000000 bytes on cuda:0: out of memory (CUDA_ERROR_OUT_OF_MEMORY)"
        );
        assert!(e.is_out_of_memory());
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
