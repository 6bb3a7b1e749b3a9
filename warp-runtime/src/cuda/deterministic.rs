//! A `#[kernel(deterministic)]` launch on a GPU: the same bits as on the CPU
//! (`cpu/deterministic.rs`) and on every run.
//!
//! The kernel records its float accumulations instead of making them: each thread owns
//! `limit x lanes` slots of a record buffer (`wp::det_t`, wp_core.h's "Deterministic
//! accumulation", which holds the device side), one record per float lane (the lane's
//! address, the value's bits, its type and operation), and marks its unused slots. Slot
//! `flat * lanes + k` is the thread's k-th lane record, so slot order is launch order. After
//! the kernel, on the same stream:
//! 1. `_det_prepare`: each slot's low address word and its index;
//! 2. a stable radix sort of those (the primitives' `u32` sort);
//! 3. `_det_high`: the high address word of each slot in that order;
//! 4. a second stable sort, which leaves the slots in (address, slot) order;
//! 5. `_det_apply`: the first slot of each lane adds the lane's records into it one after the
//!    other, with the lane type's `+`/`-` (an f16 or bf16 through f32, rounded once, as the
//!    CPU's `half` types do).
//!
//! The record buffer is the GPU's (`GpuState::det_records`), kept between launches at the
//! largest size needed and ordered across streams like the primitives' workspace; its lock is
//! held from the kernel's launch to the addition's, so launches from several threads take
//! turns. Not supported yet (refused with `Error::Deterministic`): recording inside a graph
//! capture (the buffer may have to grow, an allocation) and launches of more than
//! `i32::MAX` slots (the sort's limit).

use super::gpu::{self, err, GpuState, Scratch};
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::KernelInfo;
use std::ffi::c_void;
use std::sync::{Arc, MutexGuard};
use warp_cuda::{Function, Module};

/// `wp::det_t` (wp_core.h): the record buffer as the kernel's entry takes it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct DetArgs {
    keys: u64,
    values: u64,
    tags: u64,
    lanes: i64,
    limit: i32,
    pad: i32,
}
const _: () = assert!(
    std::mem::size_of::<DetArgs>() == 40,
    "wp::det_t is 40 bytes"
);

/// The ordering and addition entries of a deterministic kernel's unit (`DET_ENTRIES` of
/// warp-macros' back/cuda.rs).
#[derive(Clone)]
pub(crate) struct DetFns {
    prepare: Function,
    high: Function,
    apply: Function,
}

impl DetFns {
    /// The entries of `module`, whose kernel entry is `entry` (the forward's or the
    /// adjoint's), when `info` is deterministic.
    pub(crate) fn of(
        device: &Device,
        info: &KernelInfo,
        module: &Module,
        entry: &str,
    ) -> Result<Option<DetFns>> {
        if info.deterministic.is_none() {
            return Ok(None);
        }
        let base = entry.strip_suffix("_adj").unwrap_or(entry);
        let f = |step: &str| {
            module
                .function(&format!("{base}_det_{step}"))
                .map_err(|e| err(device, e))
        };
        Ok(Some(DetFns {
            prepare: f("prepare")?,
            high: f("high")?,
            apply: f("apply")?,
        }))
    }
}

/// Where the arrays of `n` slots lie in the record buffer (byte offsets, each 256-byte
/// aligned): keys (u64), values (u64), tags (u8), the sort's keys (u32) and its values, the
/// slot indices (u32); and the bytes in all.
pub(crate) fn layout(n: u64) -> ([u64; 5], u64) {
    let sizes = [8 * n, 8 * n, n, 4 * n, 4 * n];
    let mut at = [0u64; 5];
    let mut end = 0u64;
    for (a, s) in at.iter_mut().zip(sizes) {
        *a = end;
        end += s.next_multiple_of(256);
    }
    (at, end)
}

/// The slots of a launch of `total` threads with `limit` records of `lanes` lanes each, if
/// the sort can order them (at most `i32::MAX`).
pub(crate) fn slots(total: u64, limit: u32, lanes: u32) -> Option<u64> {
    let per_thread = u64::from(limit).checked_mul(u64::from(lanes))?;
    total
        .checked_mul(per_thread)
        .filter(|n| *n <= i32::MAX as u64)
}

/// A deterministic launch's record buffer, held (locked) from the kernel's launch to the
/// addition's.
pub(crate) struct Records<'a> {
    guard: MutexGuard<'a, Option<Arc<Scratch>>>,
    pub(crate) args: DetArgs,
    n: u64,
    order: u64,
    word: u64,
}

/// The record buffer of a launch of `info` (`adjoint`: its adjoint) over `total` threads on
/// GPU `ordinal`, grown if needed and locked.
pub(crate) fn records<'a>(
    st: &'a GpuState,
    device: &Device,
    ordinal: usize,
    info: &KernelInfo,
    total: u64,
    adjoint: bool,
) -> Result<Records<'a>> {
    let det = info
        .deterministic
        .expect("only deterministic launches have records");
    let limit = det.limit(adjoint);
    let n = slots(total, limit, det.lanes).ok_or_else(|| Error::Deterministic {
        kernel: info.name,
        why: format!(
            "a launch of {total} threads with {limit} records of up to {} lanes each needs \
             more record slots than a GPU's ordering sorts (at most {}): launch fewer threads \
             or lower max_records",
            det.lanes,
            i32::MAX
        ),
    })?;
    refuse_capture(info, ordinal)?;
    let (at, need) = layout(n);
    let mut guard = st.det_records.lock().unwrap_or_else(|p| p.into_inner());
    if guard
        .as_ref()
        .is_none_or(|s| (s.buffer.len() as u64) < need)
    {
        let old = guard.as_ref().map_or(0, |s| s.buffer.len());
        // The old buffer's free is queued on the default stream: after its last user.
        st.join_pending()?;
        *guard = None;
        let bytes = (need as usize).max(old + old / 2);
        let buf = warp_cuda::DeviceBuffer::alloc(&st.gpu, bytes)
            .map_err(|e| Error::cuda_alloc(device.alias(), bytes, e))?;
        *guard = Some(Scratch::new(buf));
    }
    let base = guard.as_ref().expect("made above").buffer.device_ptr();
    let args = DetArgs {
        keys: base + at[0],
        values: base + at[1],
        tags: base + at[2],
        lanes: i64::from(limit) * i64::from(det.lanes),
        limit: limit as i32,
        pad: 0,
    };
    Ok(Records {
        guard,
        args,
        n,
        word: base + at[3],
        order: base + at[4],
    })
}

impl Records<'_> {
    /// Orders the buffer's use on `stream` after its last use (call inside the queue of the
    /// kernel's launch, before it).
    pub(crate) fn order_on(&self, device: &Device, stream: &warp_cuda::Stream) -> Result<()> {
        let scratch = self.guard.as_ref().expect("made by records");
        gpu::order_scratch(device, &mut scratch.last(), stream)
    }

    /// Queues the ordering and the addition of the records on `stream` (the kernel's), after
    /// the kernel.
    pub(crate) fn reduce(
        self,
        st: &GpuState,
        device: &Device,
        ordinal: usize,
        fns: &DetFns,
        stream: Option<&warp_cuda::Stream>,
    ) -> Result<()> {
        if self.n == 0 {
            return Ok(());
        }
        let step = |f: &Function| {
            let mut d = self.args;
            let (mut word, mut order, mut n) = (self.word, self.order, self.n as i64);
            st.queue(ordinal, stream, |on| {
                let mut ptrs = [
                    (&mut d) as *mut DetArgs as *mut c_void,
                    (&mut word) as *mut u64 as *mut c_void,
                    (&mut order) as *mut u64 as *mut c_void,
                    (&mut n) as *mut i64 as *mut c_void,
                ];
                let blocks = self.n.div_ceil(BLOCK as u64).min(MAX_BLOCKS) as u32;
                // SAFETY: every `_det_*` entry takes (wp::det_t, u32*, u32*, i64), which
                // `ptrs` point at, alive until the call returns; the addresses are the record
                // buffer's, held by `self.guard`, `n` slots each.
                unsafe {
                    st.gpu
                        .launch_raw(f, on, blocks, BLOCK, 0, &mut ptrs)
                        .map_err(|e| err(device, e))
                }
            })
        };
        let sort = || {
            let n = self.n as usize;
            super::primitives::sort_u32_pairs_on(
                device,
                ordinal,
                stream,
                "a deterministic launch's ordering",
                self.word,
                self.order,
                n,
            )
        };
        step(&fns.prepare)?;
        sort()?;
        step(&fns.high)?;
        sort()?;
        step(&fns.apply)?;
        Ok(())
    }
}

/// Threads per block of the ordering and addition entries (grid-stride loops).
const BLOCK: u32 = 256;
/// Their blocks at most: the loops cover the rest.
const MAX_BLOCKS: u64 = 65_535;

/// A deterministic launch inside a graph capture is refused (its record buffer may have to
/// grow, an allocation a capture cannot hold). Checked before the kernel is compiled, so that
/// the refusal is what a capture reports, not the compilation a capture cannot hold either.
pub(crate) fn refuse_capture(info: &KernelInfo, ordinal: usize) -> Result<()> {
    if info.deterministic.is_some() && gpu::capture_stream(ordinal).is_some() {
        return Err(Error::Deterministic {
            kernel: info.name,
            why: "a deterministic launch cannot be recorded into a graph yet (its record \
                  buffer may have to grow): launch it outside the capture"
                .to_string(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The record buffer's arrays are aligned and disjoint; the slot count is bounded by the
    /// sort's limit and never overflows.
    #[test]
    fn layout_and_slots() {
        let (at, end) = layout(10);
        assert_eq!(at, [0, 256, 512, 768, 1024]);
        assert_eq!(end, 1280);
        assert_eq!(slots(1000, 64, 3), Some(192_000));
        assert_eq!(slots(1 << 30, 2, 1), None);
        assert_eq!(slots(u64::MAX, u32::MAX, u32::MAX), None);
        assert_eq!(slots(0, 5, 5), Some(0));
    }

    /// `DetArgs` is `wp::det_t` field for field (wp_core.h's layout comment).
    #[test]
    fn det_args_match_the_library() {
        assert_eq!(std::mem::offset_of!(DetArgs, lanes), 24);
        assert_eq!(std::mem::offset_of!(DetArgs, limit), 32);
        let core = warp_cuda::library::CORE.text;
        assert!(core.contains("static_assert(sizeof(det_t) == 40 && alignof(det_t) == 8"));
    }
}
