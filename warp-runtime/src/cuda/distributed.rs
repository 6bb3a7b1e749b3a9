//! Several GPUs: NCCL collectives on arrays, and peer access between GPUs.
//!
//! A [`Communicator`] is one rank of an NCCL clique, on one GPU. Its collectives take
//! [`Array`]s of that GPU and are queued like a launch: on the thread's capture stream inside
//! a [`capture`](crate::capture) (so they are recorded into the graph), else on the current
//! [`ScopedStream`](crate::ScopedStream), else on the GPU's default stream, in the stream
//! ordering model of [`stream`](crate::stream) (an array is never freed or read back while a
//! collective may still use it).
//!
//! Two ways to make communicators:
//! - **One process drives several GPUs**: [`Communicator::for_devices`] gives one per GPU.
//!   One thread calling collectives on several of them must put the calls in one
//!   [`group`] (NCCL would otherwise wait on the first GPU for the others forever); one thread
//!   per GPU needs no group.
//! - **One process per GPU** (also the multi-node path): rank 0 makes a [`UniqueId`], the
//!   launcher hands it to every rank, and each calls [`Communicator::new`], or
//!   [`Communicator::from_env`] with `WARP_RANK`, `WARP_WORLD_SIZE` and `WARP_NCCL_ID` (the
//!   id as hex) or `WARP_NCCL_ID_FILE` (a file holding it) set. NCCL finds the other nodes
//!   through the id's bootstrap address, so the same code spans machines.
//!
//! # Errors, not hangs
//! Arrays on the wrong GPU, sizes that do not fit the collective, and element types NCCL has
//! no reduction for (a compile error: [`CollectiveElement`]) are refused before NCCL sees
//! them. Inside a [`group`], the calls of the communicators of one `for_devices` clique are
//! compared before anything is issued: a rank whose call differs from another's (another
//! collective, count, element type, reduction or root; a send without its receive) is an
//! [`Error::InvalidArgument`] naming both, and nothing runs. Across processes, ranks cannot
//! see each other's calls; [`Communicator::set_verify`] makes each collective first exchange
//! a description of itself (one small all-gather and a host round trip) and fail on a
//! mismatch. What is left (a peer that never posts its part, a process that died) ends in
//! the communicator's timeout ([`Communicator::set_timeout`], two minutes by default):
//! [`Communicator::synchronize`] then aborts the communicator and returns an error.

use super::gpu;
use crate::array::{Array, NdComponents};
use crate::device::{Device, DeviceKind};
use crate::error::{Error, Result};
use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use warp_cuda::nccl;

pub use warp_cuda::nccl::{DataType, ReduceOp, UniqueId};

/// The scalar types NCCL reduces: `i8`, `u8`, `i32`, `u32`, `i64`, `u64`, `f16`, `f32`, `f64`.
pub trait CollectiveScalar: sealed::Sealed {
    /// NCCL's type.
    const DTYPE: DataType;
}

mod sealed {
    pub trait Sealed {}
}

macro_rules! collective_scalars {
    ($($t:ty => $d:ident),*) => {$(
        impl sealed::Sealed for $t {}
        impl CollectiveScalar for $t {
            const DTYPE: DataType = DataType::$d;
        }
    )*};
}
collective_scalars!(
    i8 => I8, u8 => U8, i32 => I32, u32 => U32, i64 => I64, u64 => U64,
    warp_core::f16 => F16, f32 => F32, f64 => F64
);

/// An element type collectives accept: a [`CollectiveScalar`], or a vector, quaternion or
/// matrix of one (reduced component by component). `i16` and `u16` have no NCCL type: an
/// array of them in a collective is a compile error.
pub trait CollectiveElement: NdComponents {
    /// NCCL's type of the components.
    const DTYPE: DataType;
    /// Scalars per element.
    const LANES: usize;
}

impl<T: NdComponents> CollectiveElement for T
where
    T::Scalar: CollectiveScalar,
{
    const DTYPE: DataType = <T::Scalar as CollectiveScalar>::DTYPE;
    const LANES: usize = std::mem::size_of::<T>() / std::mem::size_of::<T::Scalar>();
}

/// Which collective a call is, for the consistency checks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    AllReduce(ReduceOp),
    ReduceScatter(ReduceOp),
    AllGather,
    Broadcast { root: usize },
    Send { to: usize },
    Recv { from: usize },
}

/// What one rank asked for: the kind, the element type and the per-rank count (the count NCCL
/// is given), which every rank of the clique must agree on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Call {
    kind: Kind,
    dtype: DataType,
    count: usize,
}

impl Call {
    fn describe(&self) -> String {
        let what = match self.kind {
            Kind::AllReduce(op) => format!("all_reduce ({op:?})"),
            Kind::ReduceScatter(op) => format!("reduce_scatter ({op:?})"),
            Kind::AllGather => "all_gather".into(),
            Kind::Broadcast { root } => format!("broadcast from rank {root}"),
            Kind::Send { to } => format!("send to rank {to}"),
            Kind::Recv { from } => format!("recv from rank {from}"),
        };
        format!("{what} of {} {:?} per rank", self.count, self.dtype)
    }

    /// The call as five integers, for the cross-process check.
    fn encode(&self) -> [i64; 5] {
        let (k, a) = match self.kind {
            Kind::AllReduce(op) => (0, op as i64),
            Kind::ReduceScatter(op) => (1, op as i64),
            Kind::AllGather => (2, 0),
            Kind::Broadcast { root } => (3, root as i64),
            Kind::Send { to } => (4, to as i64),
            Kind::Recv { from } => (5, from as i64),
        };
        [k, a, self.dtype as i64, self.count as i64, 0]
    }
}

/// One rank of an NCCL communicator, bound to one GPU. See the module documentation.
/// Cloning gives another handle to the same rank.
///
/// Handles may be used from several threads at once: NCCL allows only one call at a time
/// on a communicator, so the calls are serialised (each takes the rank's call lock until
/// NCCL has accepted its work; a [`group`] holds it until the group is issued). Collectives
/// from different threads on one rank therefore run in the order they took the lock, and
/// every rank must see the same order: threads sharing one rank need an order of their own
/// (a barrier, a channel), or one thread per rank.
#[derive(Clone)]
pub struct Communicator(Arc<Inner>);

struct Inner {
    comm: nccl::Comm,
    device: Device,
    /// The clique of communicators made together by `for_devices` (compared in groups).
    clique: Option<Arc<()>>,
    verify: AtomicBool,
    /// The stream of the last call, which `synchronize` waits for.
    last: Mutex<Option<warp_cuda::Stream>>,
    /// The cross-process check's buffers: this rank's call and every rank's.
    scratch: Mutex<Option<(Array<i64, 1>, Array<i64, 1>)>>,
}

impl std::fmt::Debug for Communicator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Communicator(rank {} of {} on {})",
            self.rank(),
            self.world_size(),
            self.0.device
        )
    }
}

fn ordinal(device: &Device, what: &str) -> Result<usize> {
    match device.kind() {
        DeviceKind::Cuda { ordinal } => Ok(ordinal),
        DeviceKind::Cpu => Err(Error::invalid(format!(
            "{what} needs a CUDA device, got \"{device}\" (NCCL communicates between GPUs)"
        ))),
    }
}

fn env_var(name: &str) -> Result<String> {
    std::env::var(name).map_err(|_| {
        Error::invalid(format!(
            "Communicator::from_env: {name} is not set (set WARP_RANK, WARP_WORLD_SIZE and \
             WARP_NCCL_ID or WARP_NCCL_ID_FILE)"
        ))
    })
}

fn env_usize(name: &str) -> Result<usize> {
    let v = env_var(name)?;
    v.trim().parse().map_err(|_| {
        Error::invalid(format!(
            "Communicator::from_env: {name}={v:?} is not a non-negative integer"
        ))
    })
}

impl Communicator {
    /// One communicator per device of `devices`, in this process: rank `i` on `devices[i]`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a CPU device or a GPU given twice; [`Error::Cuda`]
    /// when NCCL cannot be loaded or fails.
    pub fn for_devices(devices: &[Device]) -> Result<Vec<Communicator>> {
        if devices.is_empty() {
            return Err(Error::invalid(
                "Communicator::for_devices: no devices (a world needs at least one rank)",
            ));
        }
        let mut gpus = Vec::with_capacity(devices.len());
        for d in devices {
            let o = ordinal(d, "Communicator::for_devices")?;
            gpus.push(gpu::state(d, o)?.gpu.clone());
        }
        let comms = nccl::Comm::init_all(&gpus, nccl::DEFAULT_TIMEOUT)
            .map_err(|e| Error::cuda(devices[0].alias(), e))?;
        let clique = Arc::new(());
        Ok(comms
            .into_iter()
            .zip(devices)
            .map(|(comm, d)| Communicator::wrap(comm, d, Some(clique.clone())))
            .collect())
    }

    /// Rank `rank` of a world of `world` ranks named by `id`, on `device`: one process (or
    /// thread) per GPU. Returns when every rank has joined; fails after the timeout
    /// (two minutes) when one does not.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a CPU device or a rank outside the world;
    /// [`Error::Cuda`] when NCCL cannot be loaded, fails or times out.
    pub fn new(device: &Device, rank: usize, world: usize, id: &UniqueId) -> Result<Communicator> {
        Communicator::with_timeout(device, rank, world, id, nccl::DEFAULT_TIMEOUT)
    }

    /// [`new`](Self::new) with a timeout for joining and for later waits.
    ///
    /// # Errors
    /// As [`new`](Self::new).
    pub fn with_timeout(
        device: &Device,
        rank: usize,
        world: usize,
        id: &UniqueId,
        timeout: Duration,
    ) -> Result<Communicator> {
        let o = ordinal(device, "Communicator::new")?;
        let g = gpu::state(device, o)?.gpu.clone();
        let comm = nccl::Comm::init_rank(&g, rank, world, id, timeout)
            .map_err(|e| Error::cuda(device.alias(), e))?;
        Ok(Communicator::wrap(comm, device, None))
    }

    /// A communicator from the launcher's environment: `WARP_RANK`, `WARP_WORLD_SIZE`, and
    /// the id as `WARP_NCCL_ID` (256 hex digits, [`UniqueId::to_hex`]) or in the file named
    /// by `WARP_NCCL_ID_FILE`. The launcher makes the id once ([`UniqueId::new`]) and
    /// passes the same one to every rank; on several nodes the file lives on a shared file
    /// system or the variable is set by the job script.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming a missing or malformed variable; as
    /// [`new`](Self::new).
    pub fn from_env(device: &Device) -> Result<Communicator> {
        let rank = env_usize("WARP_RANK")?;
        let world = env_usize("WARP_WORLD_SIZE")?;
        let hex = match std::env::var("WARP_NCCL_ID") {
            Ok(h) => h,
            Err(_) => {
                let path = env_var("WARP_NCCL_ID_FILE")?;
                std::fs::read_to_string(&path).map_err(|e| {
                    Error::invalid(format!(
                        "Communicator::from_env: cannot read WARP_NCCL_ID_FILE={path:?}: {e}"
                    ))
                })?
            }
        };
        let id = UniqueId::from_hex(&hex).map_err(|e| Error::cuda(device.alias(), e))?;
        Communicator::new(device, rank, world, &id)
    }

    fn wrap(comm: nccl::Comm, device: &Device, clique: Option<Arc<()>>) -> Communicator {
        Communicator(Arc::new(Inner {
            comm,
            device: device.clone(),
            clique,
            verify: AtomicBool::new(false),
            last: Mutex::new(None),
            scratch: Mutex::new(None),
        }))
    }

    /// This communicator's rank.
    pub fn rank(&self) -> usize {
        self.0.comm.rank()
    }

    /// The number of ranks.
    pub fn world_size(&self) -> usize {
        self.0.comm.world_size()
    }

    /// The GPU this rank runs on.
    pub fn device(&self) -> &Device {
        &self.0.device
    }

    /// How long waits for peers may take before the communicator is aborted.
    pub fn timeout(&self) -> Duration {
        self.0.comm.timeout()
    }

    /// Sets the timeout (two minutes by default), for every handle of this rank.
    pub fn set_timeout(&self, timeout: Duration) {
        self.0.comm.set_timeout(timeout);
    }

    /// Makes each collective outside a [`group`] first check, across all ranks, that every
    /// rank is making the same call (one small all-gather and a wait: for development and
    /// tests, like PyTorch's `TORCH_DISTRIBUTED_DEBUG`). Off by default. Not inside a graph
    /// capture (the check reads results back on the host).
    pub fn set_verify(&self, on: bool) {
        self.0.verify.store(on, Ordering::Relaxed);
    }

    /// Whether the communicator was aborted (after a timeout or a peer's failure); it then
    /// refuses every call.
    pub fn is_aborted(&self) -> bool {
        self.0.comm.is_aborted()
    }

    /// Sum (or another reduction) over ranks, element by element: `recv` gets the reduction
    /// of every rank's `send`. `send` and `recv` may be the same array (in place).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for arrays on another device, non-contiguous arrays or
    /// different lengths; [`Error::Cuda`] when NCCL fails.
    pub fn all_reduce<T: CollectiveElement, const N: usize>(
        &self,
        send: &Array<T, N>,
        recv: &Array<T, N>,
        op: ReduceOp,
    ) -> Result<()> {
        let what = "all_reduce";
        self.check_array(send, what, "send")?;
        self.check_array(recv, what, "recv")?;
        if send.len() != recv.len() {
            return Err(self.size_error(what, send.len(), recv.len(), "the same length"));
        }
        let call = Call {
            kind: Kind::AllReduce(op),
            dtype: T::DTYPE,
            count: send.len() * T::LANES,
        };
        let (s, r) = (send.device_ptr(), recv.device_ptr());
        let keep = (send.clone(), recv.clone());
        self.submit(call, move |c, st| unsafe {
            let _keep = keep;
            // SAFETY: both arrays are contiguous on this GPU with `count` scalars, kept alive by
            // the stream ordering of the runtime (see the module).
            c.all_reduce(s, r, call.count, call.dtype, op, st)
        })
    }

    /// [`all_reduce`](Self::all_reduce) with `array` as both input and output.
    ///
    /// # Errors
    /// As [`all_reduce`](Self::all_reduce).
    pub fn all_reduce_in_place<T: CollectiveElement, const N: usize>(
        &self,
        array: &Array<T, N>,
        op: ReduceOp,
    ) -> Result<()> {
        self.all_reduce(array, array, op)
    }

    /// Reduce, then scatter: `send` has `world * recv.len()` elements; rank `r`'s `recv` gets
    /// block `r` (elements `r * recv.len() ..`) of the reduction over ranks.
    ///
    /// # Errors
    /// As [`all_reduce`](Self::all_reduce), for the lengths above.
    pub fn reduce_scatter<T: CollectiveElement, const N: usize, const M: usize>(
        &self,
        send: &Array<T, N>,
        recv: &Array<T, M>,
        op: ReduceOp,
    ) -> Result<()> {
        let what = "reduce_scatter";
        self.check_array(send, what, "send")?;
        self.check_array(recv, what, "recv")?;
        if recv.len().checked_mul(self.world_size()) != Some(send.len()) {
            return Err(self.size_error(
                what,
                send.len(),
                recv.len(),
                &format!("send = world ({}) × recv", self.world_size()),
            ));
        }
        let call = Call {
            kind: Kind::ReduceScatter(op),
            dtype: T::DTYPE,
            count: recv.len() * T::LANES,
        };
        let (s, r) = (send.device_ptr(), recv.device_ptr());
        let keep = (send.clone(), recv.clone());
        self.submit(call, move |c, st| unsafe {
            let _keep = keep;
            // SAFETY: as in `all_reduce`, sizes checked above.
            c.reduce_scatter(s, r, call.count, call.dtype, op, st)
        })
    }

    /// Gather to all: `recv` has `world * send.len()` elements and gets every rank's `send`,
    /// in rank order.
    ///
    /// # Errors
    /// As [`all_reduce`](Self::all_reduce), for the lengths above.
    pub fn all_gather<T: CollectiveElement, const N: usize, const M: usize>(
        &self,
        send: &Array<T, N>,
        recv: &Array<T, M>,
    ) -> Result<()> {
        let what = "all_gather";
        self.check_array(send, what, "send")?;
        self.check_array(recv, what, "recv")?;
        if send.len().checked_mul(self.world_size()) != Some(recv.len()) {
            return Err(self.size_error(
                what,
                send.len(),
                recv.len(),
                &format!("recv = world ({}) × send", self.world_size()),
            ));
        }
        let call = Call {
            kind: Kind::AllGather,
            dtype: T::DTYPE,
            count: send.len() * T::LANES,
        };
        let (s, r) = (send.device_ptr(), recv.device_ptr());
        let keep = (send.clone(), recv.clone());
        self.submit(call, move |c, st| unsafe {
            let _keep = keep;
            // SAFETY: as in `all_reduce`, sizes checked above.
            c.all_gather(s, r, call.count, call.dtype, st)
        })
    }

    /// Broadcast in place: every rank's `array` gets rank `root`'s.
    ///
    /// # Errors
    /// As [`all_reduce`](Self::all_reduce); a `root` outside the world.
    pub fn broadcast<T: CollectiveElement, const N: usize>(
        &self,
        array: &Array<T, N>,
        root: usize,
    ) -> Result<()> {
        let what = "broadcast";
        self.check_array(array, what, "array")?;
        if root >= self.world_size() {
            return Err(Error::invalid(format!(
                "{}: root {root} is not a rank of this world of {}",
                self.at(what),
                self.world_size()
            )));
        }
        let call = Call {
            kind: Kind::Broadcast { root },
            dtype: T::DTYPE,
            count: array.len() * T::LANES,
        };
        let p = array.device_ptr();
        let keep = array.clone();
        self.submit(call, move |c, st| unsafe {
            let _keep = keep;
            // SAFETY: as in `all_reduce`.
            c.broadcast(p, p, call.count, call.dtype, root, st)
        })
    }

    /// Sends `array` to rank `peer`, which posts a [`recv`](Self::recv) of the same length.
    /// Two ranks that exchange data put their send and receive in one [`group`].
    ///
    /// # Errors
    /// As [`all_reduce`](Self::all_reduce); `peer` not another rank.
    pub fn send<T: CollectiveElement, const N: usize>(
        &self,
        array: &Array<T, N>,
        peer: usize,
    ) -> Result<()> {
        self.check_peer("send", peer)?;
        self.check_array(array, "send", "array")?;
        let call = Call {
            kind: Kind::Send { to: peer },
            dtype: T::DTYPE,
            count: array.len() * T::LANES,
        };
        let p = array.device_ptr();
        let keep = array.clone();
        self.submit(call, move |c, st| unsafe {
            let _keep = keep;
            // SAFETY: as in `all_reduce`.
            c.send(p, call.count, call.dtype, peer, st)
        })
    }

    /// Receives into `array` from rank `peer` (see [`send`](Self::send)).
    ///
    /// # Errors
    /// As [`send`](Self::send).
    pub fn recv<T: CollectiveElement, const N: usize>(
        &self,
        array: &Array<T, N>,
        peer: usize,
    ) -> Result<()> {
        self.check_peer("recv", peer)?;
        self.check_array(array, "recv", "array")?;
        let call = Call {
            kind: Kind::Recv { from: peer },
            dtype: T::DTYPE,
            count: array.len() * T::LANES,
        };
        let p = array.device_ptr();
        let keep = array.clone();
        self.submit(call, move |c, st| unsafe {
            let _keep = keep;
            // SAFETY: as in `all_reduce`.
            c.recv(p, call.count, call.dtype, peer, st)
        })
    }

    /// Waits until this rank's collectives have finished, with the timeout: a peer that
    /// never posts its part, or fails, aborts the communicator and returns an error instead
    /// of a hang. Also reports a kernel fault of the GPU, as [`synchronize`](crate::synchronize).
    ///
    /// # Errors
    /// [`Error::Cuda`] with a timeout or NCCL's error.
    pub fn synchronize(&self) -> Result<()> {
        let last = self
            .0
            .last
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        if let Some(stream) = last {
            self.0
                .comm
                .synchronize(&stream)
                .map_err(|e| Error::cuda(self.0.device.alias(), e))?;
        }
        let o = ordinal(&self.0.device, "Communicator::synchronize")?;
        gpu::synchronize(&self.0.device, o)
    }

    fn at(&self, what: &str) -> String {
        format!(
            "{what} on rank {} of {} ({})",
            self.rank(),
            self.world_size(),
            self.0.device
        )
    }

    fn size_error(&self, what: &str, send: usize, recv: usize, rule: &str) -> Error {
        Error::invalid(format!(
            "{}: send has {send} elements and recv {recv}; the collective needs {rule}",
            self.at(what)
        ))
    }

    fn check_peer(&self, what: &str, peer: usize) -> Result<()> {
        if peer >= self.world_size() || peer == self.rank() {
            return Err(Error::invalid(format!(
                "{}: peer {peer} is not another rank of this world of {}",
                self.at(what),
                self.world_size()
            )));
        }
        Ok(())
    }

    fn check_array<T: CollectiveElement, const N: usize>(
        &self,
        a: &Array<T, N>,
        what: &str,
        arg: &str,
    ) -> Result<()> {
        if a.device() != &self.0.device {
            return Err(Error::invalid(format!(
                "{}: `{arg}` is on \"{}\", not the communicator's device",
                self.at(what),
                a.device()
            )));
        }
        if !a.is_contiguous() {
            return Err(Error::invalid(format!(
                "{}: `{arg}` is not contiguous (strides {:?}); copy it into a contiguous array \
                 first",
                self.at(what),
                a.strides()
            )));
        }
        Ok(())
    }

    /// Issues `issue` now, or records it in the thread's open [`group`].
    fn submit(
        &self,
        call: Call,
        issue: impl FnOnce(&nccl::Comm, &warp_cuda::Stream) -> warp_cuda::Result<()> + 'static,
    ) -> Result<()> {
        let pending = Pending {
            comm: self.clone(),
            call,
            issue: Box::new(issue),
        };
        let deferred = GROUP.with(|g| match &mut *g.borrow_mut() {
            Some(ops) => {
                ops.push(pending);
                None
            }
            None => Some(pending),
        });
        let Some(pending) = deferred else {
            return Ok(());
        };
        if self.0.verify.load(Ordering::Relaxed) {
            self.verify_across_ranks(&call)?;
        }
        self.issue(pending.issue)
    }

    fn issue(&self, issue: Issue) -> Result<()> {
        let o = ordinal(&self.0.device, "a collective")?;
        let st = gpu::state(&self.0.device, o)?;
        // Unordered: the call may wait for another thread's group (see `queue_unordered`).
        st.queue_unordered(o, None, |stream| {
            issue(&self.0.comm, stream).map_err(|e| Error::cuda(self.0.device.alias(), e))?;
            *self.0.last.lock().unwrap_or_else(|p| p.into_inner()) = Some(stream.clone());
            Ok(())
        })
    }

    /// The cross-process check of [`set_verify`](Self::set_verify): every rank all-gathers
    /// the description of its call, then compares.
    fn verify_across_ranks(&self, call: &Call) -> Result<()> {
        let o = ordinal(&self.0.device, "a collective")?;
        gpu::refuse_in_capture(o, "Communicator::set_verify's check")?;
        let world = self.world_size();
        let mut scratch = self.0.scratch.lock().unwrap_or_else(|p| p.into_inner());
        if scratch.is_none() {
            *scratch = Some((
                Array::zeros(5, &self.0.device)?,
                Array::zeros(5 * world, &self.0.device)?,
            ));
        }
        let (mine, all) = scratch.as_ref().expect("set above");
        mine.copy_from(&Array::from_slice(&call.encode(), &self.0.device)?)?;
        let (s, r) = (mine.device_ptr(), all.device_ptr());
        self.issue(Box::new(move |c, st| unsafe {
            // SAFETY: 5 and 5 × world i64 on this GPU, owned by `self.0.scratch`.
            c.all_gather(s, r, 5, DataType::I64, st)
        }))?;
        self.synchronize()?;
        let got = all.to_vec()?;
        let me = call.encode();
        for (peer, theirs) in got.chunks(5).enumerate() {
            let matches = match call.kind {
                // Point-to-point calls pair up rather than agree: checked in groups only.
                Kind::Send { .. } | Kind::Recv { .. } => true,
                _ => theirs == me,
            };
            if !matches {
                return Err(Error::invalid(format!(
                    "{}: this rank calls {} but rank {peer} calls {} (every rank must make the \
                     same collective call)",
                    self.at("a collective"),
                    call.describe(),
                    decode(theirs)
                )));
            }
        }
        Ok(())
    }
}

fn decode(v: &[i64]) -> String {
    let op = |k: i64| match k {
        0 => "Sum",
        1 => "Prod",
        2 => "Max",
        3 => "Min",
        _ => "Avg",
    };
    let what = match v[0] {
        0 => format!("all_reduce ({})", op(v[1])),
        1 => format!("reduce_scatter ({})", op(v[1])),
        2 => "all_gather".into(),
        3 => format!("broadcast from rank {}", v[1]),
        4 => format!("send to rank {}", v[1]),
        _ => format!("recv from rank {}", v[1]),
    };
    let dtype = ["I8", "U8", "I32", "U32", "I64", "U64", "F16", "F32", "F64"]
        .get(v[2] as usize)
        .copied()
        .unwrap_or("?");
    format!("{what} of {} {dtype} per rank", v[3])
}

type Issue = Box<dyn FnOnce(&nccl::Comm, &warp_cuda::Stream) -> warp_cuda::Result<()>>;

/// A call recorded in an open group; its closure keeps the arrays it uses alive.
struct Pending {
    comm: Communicator,
    call: Call,
    issue: Issue,
}

thread_local! {
    static GROUP: RefCell<Option<Vec<Pending>>> = const { RefCell::new(None) };
}

/// Runs `body`, whose collectives are recorded rather than issued, then checks them and
/// issues them together in one NCCL group. One thread driving several GPUs puts each step's
/// collectives (one per GPU) in a group; two ranks exchanging data put the send and the
/// receive in one.
///
/// The calls of communicators made together by [`Communicator::for_devices`] are compared
/// first, among the ranks that have calls in this group: they must make the same collective
/// calls in the same order, and a send must meet a receive of the same size and type, else
/// nothing is issued and the error names the two ranks and their calls.
/// Groups do not nest.
///
/// # Errors
/// `body`'s error (nothing is issued then); [`Error::InvalidArgument`] for mismatched calls
/// or a nested group; [`Error::Cuda`] when NCCL fails.
pub fn group<R>(body: impl FnOnce() -> Result<R>) -> Result<R> {
    let nested = GROUP.with(|g| {
        let mut g = g.borrow_mut();
        if g.is_some() {
            return true;
        }
        *g = Some(Vec::new());
        false
    });
    if nested {
        return Err(Error::invalid(
            "distributed::group: groups do not nest (issue the inner calls in the outer group)",
        ));
    }
    let out = body();
    let ops = GROUP.with(|g| g.borrow_mut().take()).unwrap_or_default();
    let out = out?;
    let mut ops: Vec<(Communicator, Call, Issue)> =
        ops.into_iter().map(|p| (p.comm, p.call, p.issue)).collect();
    check_group(&ops)?;
    // Each communicator's call lock (one per GPU) is taken at its first call below and held
    // until the NCCL group ends (NCCL allows no other thread's call on that GPU meanwhile).
    // Issuing in one global order, by GPU and then communicator (a stable sort, so each
    // communicator's own calls keep their order; the order across communicators does not
    // matter inside one NCCL group), means two threads' groups take their locks in the same
    // order, and cannot deadlock.
    ops.sort_by_key(|(c, ..)| (c.0.comm.gpu().ordinal(), Arc::as_ptr(&c.0) as usize));
    let nccl_group = nccl::Group::start().map_err(|e| Error::cuda("cuda", e))?;
    let mut first_err = None;
    let mut used: Vec<Communicator> = Vec::new();
    for (comm, _, issue) in ops {
        if !used.iter().any(|c| Arc::ptr_eq(&c.0, &comm.0)) {
            used.push(comm.clone());
        }
        if let Err(e) = comm.issue(issue) {
            first_err.get_or_insert(e);
        }
    }
    let end = nccl_group.end().map_err(|e| Error::cuda("cuda", e));
    if let Some(e) = first_err {
        return Err(e);
    }
    end?;
    for c in used {
        c.0.comm
            .wait_queued()
            .map_err(|e| Error::cuda(c.0.device.alias(), e))?;
    }
    Ok(out)
}

/// Compares the recorded calls of each `for_devices` clique, rank by rank.
fn check_group(ops: &[(Communicator, Call, Issue)]) -> Result<()> {
    let mut cliques: Vec<&Arc<()>> = Vec::new();
    for (c, ..) in ops {
        if let Some(k) = &c.0.clique {
            if !cliques.iter().any(|q| Arc::ptr_eq(q, k)) {
                cliques.push(k);
            }
        }
    }
    for clique in cliques {
        let in_clique =
            |c: &Communicator| c.0.clique.as_ref().is_some_and(|k| Arc::ptr_eq(k, clique));
        let world = ops
            .iter()
            .find(|(c, ..)| in_clique(c))
            .map(|(c, ..)| c.world_size())
            .unwrap_or(0);
        let mut per_rank: Vec<Vec<Call>> = vec![Vec::new(); world];
        for (c, call, _) in ops.iter().filter(|(c, ..)| in_clique(c)) {
            per_rank[c.rank()].push(*call);
        }
        // Collectives: every rank present makes the same sequence.
        let collectives = |r: usize| -> Vec<Call> {
            per_rank[r]
                .iter()
                .filter(|c| !matches!(c.kind, Kind::Send { .. } | Kind::Recv { .. }))
                .copied()
                .collect()
        };
        let present: Vec<usize> = (0..world).filter(|&r| !per_rank[r].is_empty()).collect();
        if let Some(&first) = present.first() {
            let reference = collectives(first);
            for &r in &present[1..] {
                let mine = collectives(r);
                if mine != reference {
                    let k = mine
                        .iter()
                        .zip(&reference)
                        .position(|(a, b)| a != b)
                        .unwrap_or(mine.len().min(reference.len()));
                    let show = |v: &[Call]| {
                        v.get(k)
                            .map(Call::describe)
                            .unwrap_or_else(|| "nothing".into())
                    };
                    return Err(Error::invalid(format!(
                        "distributed::group: collective {k} of the group differs between \
                         ranks: rank {first} calls {} but rank {r} calls {} (every rank must \
                         make the same collective calls in the same order); nothing was issued",
                        show(&reference),
                        show(&mine)
                    )));
                }
            }
        }
        // Point to point: each send meets a receive of the same size and type, where both
        // ranks are in this group (with one thread per GPU, the peer's calls are in its own
        // thread's group).
        for r in 0..world {
            for call in &per_rank[r] {
                let peer_present = |p: usize| !per_rank[p].is_empty();
                if let Kind::Send { to } = call.kind {
                    if !peer_present(to) {
                        continue;
                    }
                    let want = Call {
                        kind: Kind::Recv { from: r },
                        ..*call
                    };
                    let sends = per_rank[r].iter().filter(|c| **c == *call).count();
                    let recvs = per_rank[to].iter().filter(|c| **c == want).count();
                    if sends != recvs {
                        return Err(Error::invalid(format!(
                            "distributed::group: rank {r} posts {sends} {} but rank {to} posts \
                             {recvs} matching {} (sizes and types must agree); nothing was \
                             issued",
                            call.describe(),
                            want.describe()
                        )));
                    }
                }
            }
        }
    }
    Ok(())
}

/// Whether GPU `a` can access GPU `b`'s memory directly (NVLink or PCIe peer to peer).
///
/// # Errors
/// [`Error::InvalidArgument`] for a CPU device; [`Error::Cuda`] from the driver.
pub fn peer_access_supported(a: &Device, b: &Device) -> Result<bool> {
    let (ga, gb) = gpus(a, b, "peer_access_supported")?;
    ga.can_access_peer(&gb)
        .map_err(|e| Error::cuda(a.alias(), e))
}

/// Turns direct access from `a` to `b`'s memory on (or off); returns whether it is on now.
/// Copies between GPUs ([`Array::copy_from`], [`copy`](crate::copy)) work either way: with
/// access on they go over NVLink or PCIe directly, otherwise the driver stages them through
/// host memory. Where the hardware has no path, turning access on returns `false`.
///
/// # Errors
/// [`Error::InvalidArgument`] for a CPU device; [`Error::Cuda`] from the driver.
pub fn set_peer_access(a: &Device, b: &Device, on: bool) -> Result<bool> {
    let (ga, gb) = gpus(a, b, "set_peer_access")?;
    let r = if on {
        ga.enable_peer_access(&gb)
    } else {
        ga.disable_peer_access(&gb).map(|_| false)
    };
    r.map_err(|e| Error::cuda(a.alias(), e))
}

fn gpus(a: &Device, b: &Device, what: &str) -> Result<(Arc<warp_cuda::Gpu>, Arc<warp_cuda::Gpu>)> {
    let oa = ordinal(a, what)?;
    let ob = ordinal(b, what)?;
    Ok((
        gpu::state(a, oa)?.gpu.clone(),
        gpu::state(b, ob)?.gpu.clone(),
    ))
}

/// Whether NCCL can be loaded on this machine (see `warp_cuda::nccl` for where it is looked
/// for).
pub fn nccl_available() -> bool {
    nccl::is_available()
}

/// The loaded NCCL's version, `(major, minor, patch)`.
///
/// # Errors
/// [`Error::Cuda`] when NCCL cannot be loaded.
pub fn nccl_version() -> Result<(u32, u32, u32)> {
    nccl::version().map_err(|e| Error::cuda("cuda", e))
}
