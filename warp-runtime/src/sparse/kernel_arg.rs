//! A [`Bsr`] as a kernel parameter (`a: Bsr<Mat3>`): its [`HostObject`] impl, which makes the
//! CPU view (`warp_core::objects::BsrView`) and the CUDA record ([`CudaBsr`], the mirror of
//! `wp::bsr_t<B>` in `wp_bsr.h`), and the values' gradient the views carry.
//!
//! Kernels read the structure and read and write the values through the `bsr_*` builtins;
//! the gradient of `bsr_block` flows into the values' gradient ([`Bsr::with_grad`]).

use super::{Block, Bsr};
use crate::device::Device;
use crate::error::Result;
use crate::kernel::ArgCtx;
use crate::objects::HostObject;
use warp_core::objects::{BsrBlock, BsrView};

/// A `Bsr<B>` kernel parameter as CUDA kernels receive it: `wp::bsr_t<B>` in
/// `warp-cuda/cuda/wp_bsr.h`, field for field (48 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CudaBsr {
    /// Device address of the row offsets (`nrow + 1`).
    pub offsets: u64,
    /// Device address of the block columns.
    pub columns: u64,
    /// Device address of the blocks.
    pub values: u64,
    /// Device address of the blocks' gradient, 0 for none.
    pub grad: u64,
    /// Block rows.
    pub nrow: i32,
    /// Block columns.
    pub ncol: i32,
    /// Elements of `columns`, `values` (and `grad`): the capacity.
    pub cap: i32,
    /// The kernel parameter's index (reported in out-of-bounds faults).
    pub arg: i32,
}

const _: () = assert!(std::mem::size_of::<CudaBsr>() == 48);

impl<B: Block> Bsr<B> {
    /// This matrix with a gradient for its values (zeroed, of the values' shape, shared by
    /// every clone; a matrix whose values have one keeps it): what the adjoint of a kernel's
    /// `bsr_block` adds into, read with `a.values().grad()`.
    ///
    /// # Errors
    /// An allocation failure.
    pub fn with_grad(mut self) -> Result<Self> {
        self.values = self.values.with_grad()?;
        Ok(self)
    }
}

impl<B: Block + BsrBlock> HostObject for Bsr<B> {
    type View = BsrView<B>;
    type Cuda = CudaBsr;

    fn device(&self) -> &Device {
        self.values.device()
    }

    unsafe fn cpu_view(&self, ctx: &ArgCtx<'_>) -> Result<BsrView<B>> {
        let (k, a) = (ctx.kernel, ctx.arg);
        let grad = self.values.grad().map(|g| g.cpu_view(k, a));
        // Every size is an i32 (checked when the matrix was made) and every array contiguous
        // (the matrix allocates them), as `BsrView::new` asserts.
        Ok(BsrView::new(
            self.offsets.cpu_view(k, a),
            self.columns.cpu_view(k, a),
            self.values.cpu_view(k, a),
            grad,
            self.nrow as i32,
            self.ncol as i32,
        ))
    }

    fn cuda_record(&self, ctx: &ArgCtx<'_>) -> Result<CudaBsr> {
        Ok(CudaBsr {
            offsets: self.offsets.device_address(),
            columns: self.columns.device_address(),
            values: self.values.device_address(),
            grad: self.values.grad().map_or(0, |g| g.device_address()),
            nrow: self.nrow as i32,
            ncol: self.ncol as i32,
            cap: self.values.len() as i32,
            arg: ctx.index as i32,
        })
    }

    /// Zeroes the values' gradient (nothing without one).
    fn zero_grad(&self) -> Result<()> {
        self.values.zero_grad()
    }
}
