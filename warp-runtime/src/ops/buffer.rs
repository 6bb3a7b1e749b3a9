//! A framework's buffer (an address, a shape, a dtype) as an [`Array`] for the length of one
//! op call: no copy, and nothing freed when the array drops (the framework owns the memory).

use super::spec::{Dtype, OpElement};
use crate::array::Array;
use crate::device::Device;
use crate::error::{Error, Result};

/// One array argument of an op call: memory of the call's device that the framework owns.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Buffer {
    /// The address of element zero (host memory for the CPU, a `CUdeviceptr` for a GPU).
    pub ptr: u64,
    /// Every axis: the array's leading axes, then its element's trailing component axes
    /// (`(n, 3)` for an `Array<Vec3>` of `n`).
    pub dims: Vec<usize>,
    /// The stride of each axis in bytes; `None` for contiguous row-major memory.
    pub byte_strides: Option<Vec<isize>>,
    /// The scalar type.
    pub dtype: Dtype,
}

impl Buffer {
    /// A contiguous row-major buffer.
    pub fn contiguous(ptr: u64, dims: &[usize], dtype: Dtype) -> Buffer {
        Buffer {
            ptr,
            dims: dims.to_vec(),
            byte_strides: None,
            dtype,
        }
    }

    /// The byte strides, row-major ones when none were given.
    pub(crate) fn byte_strides_or_row_major(&self) -> Vec<isize> {
        match &self.byte_strides {
            Some(s) => s.clone(),
            None => {
                let mut s = vec![0isize; self.dims.len()];
                let mut step = self.dtype.size() as isize;
                for d in (0..self.dims.len()).rev() {
                    s[d] = step;
                    step = step.saturating_mul(self.dims[d].max(1) as isize);
                }
                s
            }
        }
    }

    /// An array over the buffer on `device`, after checking that it is an `Array<T, N>`: the
    /// dtype, the number of axes, the trailing axes and their strides. The memory is not
    /// freed by the array.
    ///
    /// # Safety
    /// The buffer addresses memory of `device` valid for reads and writes of its layout for
    /// as long as the array or a clone of it lives.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `op`, `param` and both types.
    pub unsafe fn array<T: OpElement, const N: usize>(
        &self,
        device: &Device,
        op: &str,
        param: &str,
    ) -> Result<Array<T, N>> {
        let tail = T::SHAPE;
        let wanted = || {
            let mut dims: Vec<String> = (0..N).map(|d| format!("d{d}")).collect();
            dims.extend(tail.iter().map(|e| e.to_string()));
            format!(
                "Array<{}, {N}> of {} needs ({})",
                T::TYPE_NAME,
                T::DTYPE.name(),
                dims.join(", ")
            )
        };
        if self.dtype != T::DTYPE {
            return Err(Error::invalid(format!(
                "{op}: argument '{param}': a {} buffer; the kernel takes {}",
                self.dtype.name(),
                wanted()
            )));
        }
        let strides = self.byte_strides_or_row_major();
        if self.dims.len() != N + tail.len()
            || strides.len() != self.dims.len()
            || self.dims[N..] != *tail
        {
            return Err(Error::invalid(format!(
                "{op}: argument '{param}': shape {:?}; {}",
                self.dims,
                wanted()
            )));
        }
        let scalar = self.dtype.size() as isize;
        let empty = self.dims[..N].contains(&0);
        let tail_ok = strides[N..]
            .iter()
            .zip(T::STRIDES)
            .zip(tail)
            .all(|((&s, &e), &d)| d == 1 || s == e * scalar);
        if !empty && !tail_ok {
            return Err(Error::invalid(format!(
                "{op}: argument '{param}': the trailing axes have byte strides {:?}; {} keeps \
                 its components at byte strides {:?}",
                &strides[N..],
                T::TYPE_NAME,
                T::STRIDES.iter().map(|s| s * scalar).collect::<Vec<_>>()
            )));
        }
        let mut shape = [0usize; N];
        shape.copy_from_slice(&self.dims[..N]);
        let mut lead = [0isize; N];
        lead.copy_from_slice(&strides[..N]);
        // SAFETY: the caller's contract; the callee checks layout and alignment.
        let made = unsafe { Array::call_scoped("op buffer", self.ptr, shape, lead, device) };
        made.map_err(|e| Error::invalid(format!("{op}: argument '{param}': {e}")))
    }
}
