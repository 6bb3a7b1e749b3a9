//! Fault records on a GPU: the device memory kernel threads write their first fault into, and
//! how a fault reaches the host thread whose launch raised it.
//!
//! Every host thread has a record of its own on each GPU it launches on, so that two threads
//! launching on one GPU never receive each other's faults, and one thread's faulting launch
//! is not lost behind another thread's. A launch writes into its launching thread's record
//! (`wp::launch_ctx_t` carries the record's address, the kernel's id and the launch's
//! number); a synchronisation reads and clears the calling thread's record. A graph has a
//! record of its own, made when its capture began: a thread that replays a graph also reads
//! the graph's record at its next synchronisation.
//!
//! A record outlives its thread: when the thread ends it goes back to its GPU's spare list
//! (a kernel still running may write into it; device memory is never freed under it) and the
//! next new thread takes it over. A fault found there that a launch older than the takeover
//! raised belongs to the thread that ended: it is logged at error level, not reported to the
//! new owner.
//!
//! A GPU's records are a [`RecordPool`], which its state (`gpu.rs`) holds: this module knows
//! the opened GPU and nothing else of that state, so the imports run one way (`gpu.rs` asks
//! here for the faults at a synchronisation).

use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::KernelInfo;
use std::cell::RefCell;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use warp_core::{Fault, FaultKind, LaunchId};
use warp_cuda::{CudaError, DeviceBuffer, Gpu};

/// A CUDA error about `device`'s fault records.
fn err(device: &Device, e: CudaError) -> Error {
    Error::cuda(device.alias(), e)
}

/// One GPU's fault records: the GPU they are allocated on, and the records whose threads have
/// ended (the spare list).
pub(crate) struct RecordPool {
    gpu: Arc<Gpu>,
    device: Device,
    spare: Mutex<SpareRecords>,
}

impl RecordPool {
    /// The pool of GPU `gpu` (`device`), with no record yet.
    pub(crate) fn new(gpu: Arc<Gpu>, device: Device) -> Arc<RecordPool> {
        Arc::new(RecordPool {
            gpu,
            device,
            spare: Mutex::default(),
        })
    }

    fn spare(&self) -> MutexGuard<'_, SpareRecords> {
        self.spare.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Makes clean spare records until there are at least `n`: a thread's first launch on
    /// this GPU then takes one instead of allocating, so that it may fall inside another
    /// library's stream capture (XLA's command buffers call an op's handler from their own
    /// threads while capturing, where CUDA refuses an allocation).
    #[cfg(feature = "ops")]
    pub(crate) fn reserve(&self, n: usize) -> Result<()> {
        while self.spare().clean.len() < n {
            let rec = FaultRecord::new(self)?;
            self.spare().clean.push(rec);
        }
        Ok(())
    }
}

/// `wp::fault_t` (88 bytes, `wp_core.h`) followed by the `u32` flag the first faulting thread
/// sets (and padding to 8 bytes).
const RECORD_BYTES: usize = 88;
const BYTES: usize = RECORD_BYTES + 8;

/// One fault record in device memory, with what the host knows about its launches.
pub(crate) struct FaultRecord {
    buffer: DeviceBuffer,
    host: Mutex<HostSide>,
}

/// What the host keeps beside a record.
struct HostSide {
    /// Launches numbered below this were made by an earlier owner of the record (a thread
    /// that has ended).
    since: u64,
    /// The primitive the owner queued last, with its launch: the primitives' kernels write no
    /// kernel id or launch number (`wp_primitives.h` builds a bare context), so a fault
    /// without them is the last primitive's.
    primitive: Option<(&'static KernelInfo, LaunchId)>,
}

impl FaultRecord {
    /// A new, clear record on `pool`'s GPU.
    fn new(pool: &RecordPool) -> Result<Arc<FaultRecord>> {
        let buffer = DeviceBuffer::zeros(&pool.gpu, BYTES).map_err(|e| err(&pool.device, e))?;
        Ok(Arc::new(FaultRecord {
            buffer,
            // A new record has had no earlier owner.
            host: Mutex::new(HostSide {
                since: 0,
                primitive: None,
            }),
        }))
    }

    /// The device addresses of the record and of its flag, for a launch's `wp::launch_ctx_t`.
    pub(crate) fn addresses(&self) -> (u64, u64) {
        let base = self.buffer.device_ptr();
        (base, base + RECORD_BYTES as u64)
    }

    /// Notes that `info`, a primitive, was queued as `launch` with this record.
    pub(crate) fn set_primitive(&self, info: &'static KernelInfo, launch: LaunchId) {
        self.lock().primitive = Some((info, launch));
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HostSide> {
        self.host.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Reads the record (waiting for the default stream only) and, when a fault is there,
    /// clears it and returns it. A fault of a launch made by an earlier owner is logged and
    /// not returned.
    fn take(&self, device: &Device) -> Result<Option<Fault>> {
        // Held from the read to the clear: two threads reading one record (a graph replayed
        // from both) get its fault once.
        let host = self.lock();
        let mut rec = [0u8; BYTES];
        self.buffer
            .download(0, &mut rec)
            .map_err(|e| err(device, e))?;
        let flag = u32::from_le_bytes(rec[RECORD_BYTES..RECORD_BYTES + 4].try_into().unwrap());
        if flag == 0 {
            return Ok(None);
        }
        self.buffer
            .upload(0, &[0u8; BYTES])
            .map_err(|e| err(device, e))?;
        let fault = decode(&rec, host.primitive);
        match fault.launch {
            Some(LaunchId(n)) if n < host.since => {
                log::error!(
                    "{fault} on {device}: raised by a launch from a thread that ended without \
                     synchronising (found when another thread reused its fault record)"
                );
                Ok(None)
            }
            _ => Ok(Some(fault)),
        }
    }
}

/// The fault a record holds (`rec`: `wp::fault_t`, then the flag); `primitive` names a fault
/// that carries no kernel id.
fn decode(rec: &[u8; BYTES], primitive: Option<(&'static KernelInfo, LaunchId)>) -> Fault {
    let i32_at = |o: usize| i32::from_le_bytes(rec[o..o + 4].try_into().expect("4 bytes"));
    let i64_at = |o: usize| i64::from_le_bytes(rec[o..o + 8].try_into().expect("8 bytes"));
    let (kind, arg, ndim) = (i32_at(0), i32_at(4), i32_at(72).clamp(0, 4) as usize);
    let by_id = usize::try_from(i32_at(76) - 1).ok().and_then(|k| {
        kernel_ids()
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get(k)
            .copied()
    });
    let (info, launch) = match (by_id, i64_at(80) as u64) {
        (Some(info), 0) => (info, None),
        (Some(info), n) => (info, Some(LaunchId(n))),
        (None, _) => match primitive {
            Some((info, launch)) => (info, Some(launch)),
            None => (&UNKNOWN, None),
        },
    };
    let kind = match kind {
        4 => FaultKind::AdStackOverflow {
            line: i64_at(8) as u32,
            capacity: i64_at(40) as usize,
        },
        1 => FaultKind::OutOfBounds {
            arg: info.params.get(arg as usize).copied().unwrap_or("?"),
            index: (0..ndim).map(|k| i64_at(8 + 8 * k) as i128).collect(),
            shape: (0..ndim).map(|k| i64_at(40 + 8 * k) as usize).collect(),
        },
        2 => FaultKind::DivisionByZero,
        // wp_core.h FAULT_NON_FINITE: the sample position's coordinates as f64 bit patterns.
        5 => FaultKind::NonFinite {
            what: "volume sample position",
            values: (0..ndim)
                .map(|k| f64::from_bits(i64_at(8 + 8 * k) as u64))
                .collect(),
        },
        // wp_core.h FAULT_NON_FINITE_INPUT: the element's index, then its coordinates as f64
        // bit patterns.
        7 => FaultKind::NonFiniteInput {
            arg: info.params.get(arg as usize).copied().unwrap_or("?"),
            index: i64_at(8) as usize,
            values: (1..ndim)
                .map(|k| f64::from_bits(i64_at(8 + 8 * k) as u64))
                .collect(),
        },
        // wp_core.h FAULT_TILE_INDEX: an index outside a tile of rank `ndim`.
        6 => {
            let mut index = [0i64; 4];
            let mut shape = [0u32; 4];
            for k in 0..ndim.min(4) {
                index[k] = i64_at(8 + 8 * k);
                shape[k] = u32::try_from(i64_at(40 + 8 * k)).unwrap_or(u32::MAX);
            }
            FaultKind::TileIndex {
                index,
                shape,
                rank: ndim as u8,
            }
        }
        // wp_core.h FAULT_ASSERTION: the line and column (the message is found by them in the
        // kernel's and its callees' tables), then the flat thread index (-1 in a func).
        8 => {
            let (line, column) = (i64_at(8) as u32, i64_at(16) as u32);
            let thread = usize::try_from(i64_at(24)).ok();
            FaultKind::AssertionFailed {
                line,
                message: assert_message(info, line, column, thread.is_none()),
                thread,
            }
        }
        // wp_core.h FAULT_LOCAL_INDEX: the index, the local array's length, the source line.
        9 => FaultKind::LocalIndex {
            index: i64_at(8),
            len: i64_at(16) as usize,
            line: i64_at(24) as u32,
        },
        // wp_core.h FAULT_DETERMINISTIC_RECORDS: the thread's flat index, the limit.
        10 => FaultKind::DeterministicRecords {
            thread: i64_at(8) as usize,
            limit: i64_at(16) as u32,
        },
        _ => FaultKind::BadStep { step: i64_at(8) },
    };
    Fault {
        kernel: info.name,
        kind,
        launch,
    }
}

/// The message of the assertion at `line` and `column` of `info`'s kernel (`in_func` false:
/// the record has the thread index, which only a kernel's own assertions know) or of a func it
/// calls, directly or not (`in_func`); a placeholder when no table has it (a fault of a kernel
/// the host could not name). Sites are told apart by line and column only: two in one func
/// tree at the same position (a `macro_rules!` expanding to several asserts, funcs of
/// different files) give the first one's message.
fn assert_message(info: &KernelInfo, line: u32, column: u32, in_func: bool) -> &'static str {
    fn in_funcs(
        funcs: &[&'static warp_core::FuncInfo],
        line: u32,
        column: u32,
        depth: usize,
    ) -> Option<&'static str> {
        // Funcs cannot recurse (a cycle fails to compile), so the walk ends; the bound only
        // keeps a corrupt record from costing more than a deep call tree.
        if depth > 64 {
            return None;
        }
        funcs.iter().find_map(|f| {
            f.asserts
                .iter()
                .find(|s| s.line == line && s.column == column)
                .map(|s| s.message)
                .or_else(|| in_funcs(f.callees, line, column, depth + 1))
        })
    }
    let found = match in_func {
        false => info
            .asserts
            .iter()
            .find(|s| s.line == line && s.column == column)
            .map(|s| s.message),
        true => in_funcs(info.callees, line, column, 0),
    };
    found.unwrap_or("assertion failed (its message is not in the kernel's tables)")
}

static UNKNOWN: KernelInfo = KernelInfo {
    name: "?",
    ..KernelInfo::BLANK
};

/// Gives `info` a kernel id for fault records (`wp::launch_ctx_t::kernel`): ids start at 1,
/// and 0 means "not set". A kernel loaded several times (variants, GPUs) has several ids.
pub(crate) fn kernel_id(info: &'static KernelInfo) -> i32 {
    let mut ids = kernel_ids().lock().unwrap_or_else(|p| p.into_inner());
    ids.push(info);
    i32::try_from(ids.len()).unwrap_or(0)
}

fn kernel_ids() -> &'static Mutex<Vec<&'static KernelInfo>> {
    static IDS: OnceLock<Mutex<Vec<&'static KernelInfo>>> = OnceLock::new();
    IDS.get_or_init(Default::default)
}

/// The calling thread's records, one per GPU, and the graph records it must read at its next
/// synchronisation.
#[derive(Default)]
struct ThreadRecords {
    own: Vec<(usize, Arc<RecordPool>, Arc<FaultRecord>)>,
    /// Records of graphs this thread replayed since its last full synchronisation of the GPU.
    graphs: Vec<(usize, Arc<FaultRecord>)>,
    /// The record of the graph this thread is capturing, with its GPU: launches inside the
    /// capture write there.
    capture: Option<(usize, Arc<FaultRecord>)>,
}

impl Drop for ThreadRecords {
    fn drop(&mut self) {
        // The thread has ended: its records go back to their GPUs for the next new thread.
        for (_, pool, rec) in self.own.drain(..) {
            pool.spare().ended.push(rec);
        }
    }
}

/// A GPU's records whose threads have ended.
#[derive(Default)]
struct SpareRecords {
    /// Not read since their thread ended: they may hold its last fault.
    ended: Vec<Arc<FaultRecord>>,
    /// Read (and cleared) while the GPU was idle: nothing writes them any more.
    clean: Vec<Arc<FaultRecord>>,
}

thread_local! {
    static RECORDS: RefCell<ThreadRecords> = RefCell::default();
}

/// The record that `launch`, made by the calling thread on GPU `ordinal` (`pool`'s), writes:
/// the capture's inside a capture, else the thread's own (taken from the spare list, or made,
/// at the thread's first launch there).
pub(crate) fn with_record<R>(
    pool: &Arc<RecordPool>,
    ordinal: usize,
    launch: LaunchId,
    f: impl FnOnce(&FaultRecord) -> R,
) -> Result<R> {
    let records = RECORDS.try_with(|r| {
        let mut r = r.borrow_mut();
        if let Some((o, rec)) = &r.capture {
            if *o == ordinal {
                return Ok(f(rec));
            }
        }
        if let Some((_, _, rec)) = r.own.iter().find(|(o, _, _)| *o == ordinal) {
            return Ok(f(rec));
        }
        let spare = {
            let mut spare = pool.spare();
            spare.clean.pop().or_else(|| spare.ended.pop())
        };
        let rec = match spare {
            Some(rec) => {
                // Faults of this launch and later ones are the new owner's (launch numbers
                // grow: the earlier owner's launches all have smaller ones).
                rec.lock().since = launch.0;
                rec
            }
            None => FaultRecord::new(pool)?,
        };
        let out = f(&rec);
        r.own.push((ordinal, pool.clone(), rec));
        Ok(out)
    });
    records.unwrap_or_else(|_| {
        Err(Error::invalid(format!(
            "a launch on {} while its thread is ending (its fault record is gone)",
            pool.device
        )))
    })
}

/// Starts a graph's record for the calling thread's capture on GPU `ordinal`: launches in
/// the capture write into it. Returns the record (the graph keeps it).
pub(crate) fn begin_capture(pool: &RecordPool, ordinal: usize) -> Result<Arc<FaultRecord>> {
    // Its faults all belong to the graph (launch numbers are fixed at capture: every replay's
    // fault names the captured launch).
    let rec = FaultRecord::new(pool)?;
    RECORDS.with(|r| r.borrow_mut().capture = Some((ordinal, rec.clone())));
    Ok(rec)
}

/// Ends the calling thread's capture: its launches write into the thread's record again.
pub(crate) fn end_capture() {
    RECORDS.with(|r| r.borrow_mut().capture = None);
}

/// Notes that the calling thread replayed a graph whose record is `rec` on GPU `ordinal`:
/// the thread's next synchronisation there reads it.
pub(crate) fn replayed(ordinal: usize, rec: &Arc<FaultRecord>) {
    RECORDS.with(|r| {
        let mut r = r.borrow_mut();
        if !r
            .graphs
            .iter()
            .any(|(o, g)| *o == ordinal && Arc::ptr_eq(g, rec))
        {
            r.graphs.push((ordinal, rec.clone()));
        }
    });
}

/// Reports (and clears) a fault that a launch of the calling thread on GPU `ordinal` recorded,
/// or a graph it replayed there, without waiting for other work than the default stream's.
/// `idle`: every stream of the GPU has finished (a full synchronisation), so the replayed
/// graphs need not be read again.
pub(crate) fn check(pool: &RecordPool, ordinal: usize, idle: bool) -> Result<()> {
    let (own, graphs) = RECORDS.with(|r| {
        let r = r.borrow();
        let own = r
            .own
            .iter()
            .find(|(o, _, _)| *o == ordinal)
            .map(|(_, _, rec)| rec.clone());
        let graphs: Vec<_> = r
            .graphs
            .iter()
            .filter(|(o, _)| *o == ordinal)
            .map(|(_, g)| g.clone())
            .collect();
        (own, graphs)
    });
    for rec in own.iter().chain(&graphs) {
        // One fault per check: the others stay in their records for the next.
        if let Some(fault) = rec.take(&pool.device)? {
            return Err(Error::Fault(fault));
        }
    }
    if idle {
        RECORDS.with(|r| r.borrow_mut().graphs.retain(|(o, _)| *o != ordinal));
        // Records of threads that have ended: their last faults are logged, never lost.
        let ended = std::mem::take(&mut pool.spare().ended);
        for rec in ended {
            let fault = rec.take(&pool.device);
            pool.spare().clean.push(rec);
            if let Some(fault) = fault? {
                log::error!(
                    "{fault} on {}: raised by a launch from a thread that ended without \
                     synchronising",
                    pool.device
                );
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record as `wp::raise` fills it: kind, arg, index[4], shape[4], ndim, kernel, launch,
    /// then the flag.
    fn record(
        kind: i32,
        arg: i32,
        index: [i64; 4],
        ndim: i32,
        kernel: i32,
        launch: u64,
    ) -> [u8; BYTES] {
        let mut rec = [0u8; BYTES];
        rec[0..4].copy_from_slice(&kind.to_le_bytes());
        rec[4..8].copy_from_slice(&arg.to_le_bytes());
        for (k, v) in index.iter().enumerate() {
            rec[8 + 8 * k..16 + 8 * k].copy_from_slice(&v.to_le_bytes());
        }
        rec[72..76].copy_from_slice(&ndim.to_le_bytes());
        rec[76..80].copy_from_slice(&kernel.to_le_bytes());
        rec[80..88].copy_from_slice(&launch.to_le_bytes());
        rec[RECORD_BYTES..RECORD_BYTES + 4].copy_from_slice(&1u32.to_le_bytes());
        rec
    }

    /// A failed assertion's record leads to its message by line and column, in the kernel's
    /// table or in a func's below it (two on one line told apart by the column); a func's
    /// names no thread.
    #[test]
    fn an_assertion_finds_its_message_in_the_kernel_or_its_funcs() {
        use warp_core::{AssertSite, FuncInfo};
        static LEAF: FuncInfo = FuncInfo {
            name: "leaf",
            module: "m",
            file: "src/m.rs",
            cuda: "",
            cuda_ret: "void",
            sections: &[],
            callees: &[],
            structs: &[],
            cuda_adj: "",
            cuda_adj_error: None,
            consts: &[],
            requires: &[],
            asserts: &[AssertSite {
                line: 3,
                column: 4,
                message: "in the leaf",
            }],
            float_atomics: false,
            needs_adjoints: false,
        };
        static MID: FuncInfo = FuncInfo {
            name: "mid",
            callees: &[&LEAF],
            asserts: &[],
            ..LEAF
        };
        static K: KernelInfo = KernelInfo {
            name: "k_asserts",
            callees: &[&MID],
            asserts: &[
                AssertSite {
                    line: 10,
                    column: 4,
                    message: "first",
                },
                AssertSite {
                    line: 10,
                    column: 30,
                    message: "second",
                },
            ],
            ..KernelInfo::BLANK
        };
        let id = kernel_id(&K);
        let at = |line, column, thread| {
            decode(&record(8, -1, [line, column, thread, 0], 3, id, 5), None)
        };
        let want = |line, message, thread| FaultKind::AssertionFailed {
            line,
            message,
            thread,
        };
        assert_eq!(at(10, 30, 7).kind, want(10, "second", Some(7)));
        assert_eq!(at(10, 4, 0).kind, want(10, "first", Some(0)));
        assert_eq!(at(3, 4, -1).kind, want(3, "in the leaf", None));
        let lost = at(99, 1, 2);
        assert_eq!(lost.kernel, "k_asserts");
        assert!(matches!(
            lost.kind,
            FaultKind::AssertionFailed { line: 99, message, .. } if message.contains("not in")
        ));
        assert_eq!(
            at(10, 30, 7).to_string(),
            "kernel `k_asserts`: second (line 10, thread 7) (launch #5)"
        );
    }

    #[test]
    fn a_build_steps_non_finite_input_names_its_argument_index_and_values() {
        static NAMES: KernelInfo = KernelInfo {
            name: "Bvh::refit",
            params: &["lowers", "uppers"],
            ..KernelInfo::BLANK
        };
        let id = kernel_id(&NAMES);
        let bits = |x: f32| f64::from(x).to_bits() as i64;
        let rec = record(
            7,
            1,
            [12, bits(0.5), bits(f32::NAN), bits(f32::NEG_INFINITY)],
            4,
            id,
            41,
        );
        let f = decode(&rec, None);
        assert_eq!((f.kernel, f.launch), ("Bvh::refit", Some(LaunchId(41))));
        match &f.kind {
            FaultKind::NonFiniteInput { arg, index, values } => {
                assert_eq!((*arg, *index), ("uppers", 12));
                assert_eq!(values.len(), 3);
                assert_eq!(values[0], 0.5);
                assert!(values[1].is_nan() && values[2] == f64::NEG_INFINITY);
            }
            k => panic!("{k:?}"),
        }
        let msg = f.to_string();
        assert!(
            msg.starts_with("`Bvh::refit`: argument `uppers` has a non-finite value at index 12")
                && msg.ends_with("(launch #41)"),
            "{msg}"
        );
    }
    /// wp_core.h's FAULT_DETERMINISTIC_RECORDS (10) decodes to the CPU's fault: the thread
    /// and the limit, named by the kernel; the code is the library's.
    #[test]
    fn a_deterministic_record_fault_names_the_thread_and_limit() {
        static K: KernelInfo = KernelInfo {
            name: "k_det",
            ..KernelInfo::BLANK
        };
        let f = decode(&record(10, -1, [70000, 4, 0, 0], 2, kernel_id(&K), 3), None);
        assert_eq!(f.kernel, "k_det");
        assert_eq!(
            f.kind,
            FaultKind::DeterministicRecords {
                thread: 70000,
                limit: 4
            }
        );
        assert!(warp_cuda::library::CORE
            .text
            .contains("FAULT_DETERMINISTIC_RECORDS = 10,"));
    }
}
