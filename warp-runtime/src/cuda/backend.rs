//! [`Cuda`]: the CUDA backend as the runtime dispatches to it (`backend.rs`).

use super::capture::{self, CudaGraph};
use super::memory::CudaBuffer;
use super::stream::Stream;
use super::{gpu, launch, objects, primitives};
use crate::backend::{Backend, Conditional, ObjectStep, Op, Record};
use crate::device::Device;
use crate::error::Result;
use crate::kernel::{ArgsOf, Kernel, KernelInfo};
use crate::primitives::elements::{Extent, ScanOps, SortKeyOps, SortValueOps};
use crate::primitives::plan::ReduceOp;
use warp_core::{Grid, LaunchId};

/// A CUDA GPU as a backend, for one launch or array operation on `device`.
pub(crate) struct Cuda<'d> {
    device: &'d Device,
    ordinal: usize,
}

impl<'d> Cuda<'d> {
    /// The backend of `device`, GPU `ordinal`.
    pub(crate) fn new(device: &'d Device, ordinal: usize) -> Self {
        Cuda { device, ordinal }
    }

    /// The backend of `stream`'s GPU.
    pub(crate) fn of_stream(stream: &'d Stream) -> Self {
        Cuda::new(stream.device(), stream.cuda_stream().ordinal())
    }

    /// [`Backend::launch`] on `stream` rather than on the calling thread's current stream.
    pub(crate) fn launch_on<K: Kernel>(
        &self,
        args: &ArgsOf<'_, K>,
        grid: &Grid,
        stream: &Stream,
        id: LaunchId,
    ) -> Result<()> {
        let on = Some(stream.cuda_stream());
        launch::launch::<K>(args, grid, self.device, self.ordinal, on, None, id)
    }

    /// [`Backend::launch_adjoint`] on `stream`.
    pub(crate) fn launch_adjoint_on<K: Kernel>(
        &self,
        args: &ArgsOf<'_, K>,
        grid: &Grid,
        stream: &Stream,
        adstack_bytes: usize,
        id: LaunchId,
    ) -> Result<()> {
        let on = Some(stream.cuda_stream());
        launch::launch::<K>(
            args,
            grid,
            self.device,
            self.ordinal,
            on,
            Some(adstack_bytes),
            id,
        )
    }

    /// [`Backend::begin_capture`] on `stream` (not the default stream).
    pub(crate) fn begin_capture_on(&self, stream: &Stream) -> Result<()> {
        capture::begin(self.device, self.ordinal, Some(stream))
    }

    /// [`Backend::replay`] on `stream` rather than on the calling thread's current stream.
    pub(crate) fn replay_on(&self, graph: &CudaGraph, stream: &Stream) -> Result<()> {
        capture::launch(graph, self.device, Some(stream))
    }
}

impl Backend for Cuda<'_> {
    type Buffer = CudaBuffer;
    type Graph = CudaGraph;

    fn launch<K: Kernel>(&self, args: &ArgsOf<'_, K>, grid: &Grid, id: LaunchId) -> Result<()> {
        launch::launch::<K>(args, grid, self.device, self.ordinal, None, None, id)
    }

    fn launch_adjoint<K: Kernel>(
        &self,
        args: &ArgsOf<'_, K>,
        grid: &Grid,
        adstack_bytes: usize,
        id: LaunchId,
    ) -> Result<()> {
        launch::launch::<K>(
            args,
            grid,
            self.device,
            self.ordinal,
            None,
            Some(adstack_bytes),
            id,
        )
    }

    fn alloc_zeroed(&self, bytes: usize, _align: usize) -> Result<CudaBuffer> {
        // Device allocations are aligned to at least 256 bytes.
        CudaBuffer::zeros(self.device, self.ordinal, bytes)
    }

    fn synchronize(&self) -> Result<()> {
        gpu::synchronize(self.device, self.ordinal)
    }

    fn scan<T: ScanOps>(
        &self,
        func: &'static str,
        input: u64,
        output: u64,
        len: Extent,
        inclusive: bool,
    ) -> Result<()> {
        primitives::scan::<T>(
            self.device,
            self.ordinal,
            func,
            input,
            output,
            len,
            inclusive,
        )
    }

    fn reduce<T: ScanOps>(
        &self,
        func: &'static str,
        input: u64,
        out: u64,
        len: Extent,
        op: ReduceOp,
    ) -> Result<()> {
        primitives::reduce::<T>(self.device, self.ordinal, func, input, out, len, op)
    }

    fn radix_sort_pairs<K: SortKeyOps, V: SortValueOps>(
        &self,
        func: &'static str,
        keys: u64,
        values: u64,
        len: Extent,
        key_bits: u32,
    ) -> Result<()> {
        primitives::radix_sort_pairs::<K>(
            self.device,
            self.ordinal,
            func,
            keys,
            values,
            len,
            key_bits,
        )
    }

    fn compact<T: bytemuck::Pod + Send + Sync>(
        &self,
        func: &'static str,
        arrays: [u64; 4],
        len: Extent,
    ) -> Result<()> {
        primitives::compact::<T>(self.device, self.ordinal, func, arrays, len)
    }

    fn object_step<S: ObjectStep>(&self, step: &S) -> Result<()> {
        objects::object_step(self.device, self.ordinal, step)
    }

    fn prepare(
        &self,
        kernels: &[&'static KernelInfo],
        adjoint: Option<usize>,
        block_dim: Option<usize>,
    ) -> Result<()> {
        super::module::prepare(self.device, self.ordinal, kernels, adjoint, block_dim)
    }

    fn synchronize_all() -> Result<()> {
        gpu::synchronize_all()
    }

    fn begin_capture(&self) -> Result<()> {
        capture::begin(self.device, self.ordinal, None)
    }

    fn end_capture(&self) -> Result<CudaGraph> {
        capture::end()
    }

    fn abort_capture(&self) {
        capture::abort();
    }

    /// Everything this backend queues goes on the thread's capture stream while it captures
    /// (`GpuState::queue`): the caller runs the operation now.
    fn record(&self, _op: impl FnOnce() -> Op) -> Record {
        Record::Enqueue
    }

    fn capture_conditional(
        &self,
        kind: Conditional,
        cond: u64,
        then: &mut dyn FnMut() -> Result<()>,
        otherwise: Option<&mut dyn FnMut() -> Result<()>>,
    ) -> Result<()> {
        let kind = match kind {
            Conditional::If => warp_cuda::Conditional::If,
            Conditional::While => warp_cuda::Conditional::While,
        };
        capture::conditional(self.device, self.ordinal, kind, cond, then, otherwise)
    }

    fn replay(&self, graph: &CudaGraph) -> Result<()> {
        capture::launch(graph, self.device, None)
    }
}
