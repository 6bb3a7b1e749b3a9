//! Several GPUs: the NCCL collectives of `wp::distributed` against host-computed results,
//! their errors, graph capture of collectives, one process per GPU, and the multi-GPU basics
//! (arrays, launches, copies with and without peer access, streams and events across GPUs).
//!
//! Every test uses all visible GPUs as its world (a world of one on a single-GPU machine, which
//! still runs NCCL's code path); tests that need two GPUs print `SKIPPED` with fewer, and all
//! print `SKIPPED` without a GPU or without NCCL (`WARP_NCCL_LIBRARY` names the library when it
//! is not on the loader's path, e.g. PyTorch's `site-packages/nvidia/nccl/lib/libnccl.so.2`).
//! The tests take one lock: NCCL communicators on the same GPUs from parallel tests would only
//! compete for the links.
//!
//! Tolerances: sums, products, minima and maxima of small integers are exact in every type
//! (integer types wrap the same on host and GPU), so those are compared exactly; `Avg` of
//! floats is a scaled sum that NCCL may compute as Σ(x/n), so it is compared to within
//! n ulps of the type (2^-10 for f16, 2^-23 for f32, 2^-52 for f64, relative).

use std::sync::Mutex;
use std::time::Duration;
use warp_lang as wp;
use wp::distributed::{group, CollectiveElement, Communicator, ReduceOp, UniqueId};
use wp::prelude::*;

static SERIAL: Mutex<()> = Mutex::new(());

/// An error and its sources, as anyhow's `{:#}` prints them: messages that moved into a
/// source (the API guidelines' rule: a message does not repeat its source) are still found.
trait Chain {
    fn chain(&self) -> String;
}

impl<E: std::error::Error> Chain for E {
    fn chain(&self) -> String {
        let mut text = self.to_string();
        let mut source = self.source();
        while let Some(s) = source {
            text += &format!(": {s}");
            source = s.source();
        }
        text
    }
}

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|p| p.into_inner())
}

/// Every CUDA device, or `None` (after saying why) when there is none or no NCCL.
fn gpus(test: &str, at_least: usize) -> Option<Vec<wp::Device>> {
    let gpus: Vec<wp::Device> = wp::devices().into_iter().filter(|d| d.is_cuda()).collect();
    if gpus.len() < at_least.max(1) {
        eprintln!(
            "SKIPPED distributed::{test}: needs {} CUDA device(s), found {}",
            at_least.max(1),
            gpus.len()
        );
        return None;
    }
    if !wp::distributed::nccl_available() {
        eprintln!(
            "SKIPPED distributed::{test}: NCCL not found ({:?}; set WARP_NCCL_LIBRARY)",
            wp::distributed::nccl_version().err()
        );
        return None;
    }
    Some(gpus)
}

/// The element types under test: built from small integers, compared exactly or within a
/// relative tolerance.
trait Val: CollectiveElement + Copy + PartialEq + std::fmt::Debug {
    fn of(v: i64) -> Self;
    fn to_f64(self) -> f64;
    /// Relative rounding unit (0 for integer types).
    const EPS: f64;
}

macro_rules! int_vals {
    ($($t:ty),*) => {$(
        impl Val for $t {
            fn of(v: i64) -> Self {
                v as $t // wraps, as the GPU's integer arithmetic does
            }
            fn to_f64(self) -> f64 {
                self as f64
            }
            const EPS: f64 = 0.0;
        }
    )*};
}
int_vals!(i8, u8, i32, u32, i64, u64);

impl Val for f32 {
    fn of(v: i64) -> Self {
        v as f32
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
    const EPS: f64 = f32::EPSILON as f64;
}
impl Val for f64 {
    fn of(v: i64) -> Self {
        v as f64
    }
    fn to_f64(self) -> f64 {
        self
    }
    const EPS: f64 = f64::EPSILON;
}
impl Val for wp::f16 {
    fn of(v: i64) -> Self {
        wp::f16::from_f64(v as f64)
    }
    fn to_f64(self) -> f64 {
        wp::f16::to_f64(self)
    }
    const EPS: f64 = 1.0 / 1024.0;
}

/// Rank `r`'s element `i` for reduction `op`: 0..=9 for sums, minima and maxima (a sum of 8
/// ranks fits i8); 1 or 2 for products.
fn input(op: ReduceOp, i: usize, r: usize) -> i64 {
    match op {
        ReduceOp::Prod => 1 + (i + r).is_multiple_of(3) as i64,
        _ => ((i * 7 + r * 3) % 10) as i64,
    }
}

/// The reduction over `world` ranks of element `i`, computed in i64 (then wrapped by `of`).
fn reduced(op: ReduceOp, i: usize, world: usize) -> i64 {
    let v = (0..world).map(|r| input(op, i, r));
    match op {
        ReduceOp::Sum => v.sum(),
        ReduceOp::Prod => v.product(),
        ReduceOp::Max => v.max().unwrap(),
        ReduceOp::Min => v.min().unwrap(),
        ReduceOp::Avg => v.sum::<i64>() / world as i64,
        _ => unreachable!(),
    }
}

fn check_close<T: Val>(what: &str, got: &[T], want: impl Fn(usize) -> f64, ulps: f64) {
    for (i, g) in got.iter().enumerate() {
        let (g, w) = (g.to_f64(), want(i));
        let tol = T::EPS * ulps * w.abs();
        assert!(
            (g - w).abs() <= tol,
            "{what}: element {i} is {g}, expected {w} (tolerance {tol})"
        );
    }
}

const OPS: [ReduceOp; 5] = [
    ReduceOp::Sum,
    ReduceOp::Prod,
    ReduceOp::Max,
    ReduceOp::Min,
    ReduceOp::Avg,
];

/// All-reduce of every op on `T` over `comms` (one per GPU, driven from this thread).
fn all_reduce_every_op<T: Val>(comms: &[Communicator], n: usize) {
    let world = comms.len();
    for op in OPS {
        let sends: Vec<wp::Array<T>> = comms
            .iter()
            .enumerate()
            .map(|(r, c)| {
                let data: Vec<T> = (0..n).map(|i| T::of(input(op, i, r))).collect();
                wp::Array::from_slice(&data, c.device()).unwrap()
            })
            .collect();
        let recvs: Vec<wp::Array<T>> = comms
            .iter()
            .map(|c| wp::Array::zeros(n, c.device()).unwrap())
            .collect();
        group(|| {
            for (r, c) in comms.iter().enumerate() {
                c.all_reduce(&sends[r], &recvs[r], op)?;
            }
            Ok(())
        })
        .unwrap();
        for (r, c) in comms.iter().enumerate() {
            c.synchronize().unwrap();
            let got = recvs[r].to_vec().unwrap();
            let what = format!(
                "all_reduce {op:?} of {} on rank {r}",
                std::any::type_name::<T>()
            );
            if T::EPS > 0.0 && op == ReduceOp::Avg {
                let exact = |i: usize| {
                    (0..world).map(|q| input(op, i, q)).sum::<i64>() as f64 / world as f64
                };
                check_close(&what, &got, exact, world as f64);
            } else {
                let want: Vec<T> = (0..n).map(|i| T::of(reduced(op, i, world))).collect();
                assert_eq!(got, want, "{what}");
            }
        }
    }
}

/// Reduce-scatter, all-gather and in-place broadcast of `T` against the host.
fn scatter_gather_broadcast<T: Val>(comms: &[Communicator], block: usize) {
    let world = comms.len();
    let on = |c: &Communicator, data: &[T]| wp::Array::from_slice(data, c.device()).unwrap();
    // Reduce-scatter (Sum): rank r gets block r of the sum.
    let sends: Vec<wp::Array<T>> = (0..world)
        .map(|r| {
            let d: Vec<T> = (0..block * world)
                .map(|i| T::of(input(ReduceOp::Sum, i, r)))
                .collect();
            on(&comms[r], &d)
        })
        .collect();
    let recvs: Vec<wp::Array<T>> = comms
        .iter()
        .map(|c| wp::Array::zeros(block, c.device()).unwrap())
        .collect();
    group(|| {
        for (r, c) in comms.iter().enumerate() {
            c.reduce_scatter(&sends[r], &recvs[r], ReduceOp::Sum)?;
        }
        Ok(())
    })
    .unwrap();
    for (r, c) in comms.iter().enumerate() {
        c.synchronize().unwrap();
        let want: Vec<T> = (0..block)
            .map(|i| T::of(reduced(ReduceOp::Sum, r * block + i, world)))
            .collect();
        assert_eq!(
            recvs[r].to_vec().unwrap(),
            want,
            "reduce_scatter on rank {r}"
        );
    }
    // All-gather: every rank gets every rank's block, in rank order.
    let value = |r: usize, i: usize| T::of(((r * 31 + i * 7) % 100) as i64);
    let parts: Vec<wp::Array<T>> = (0..world)
        .map(|r| {
            on(
                &comms[r],
                &(0..block).map(|i| value(r, i)).collect::<Vec<_>>(),
            )
        })
        .collect();
    let gathered: Vec<wp::Array<T>> = comms
        .iter()
        .map(|c| wp::Array::zeros(block * world, c.device()).unwrap())
        .collect();
    group(|| {
        for (r, c) in comms.iter().enumerate() {
            c.all_gather(&parts[r], &gathered[r])?;
        }
        Ok(())
    })
    .unwrap();
    let want: Vec<T> = (0..world)
        .flat_map(|r| (0..block).map(move |i| value(r, i)))
        .collect();
    for (r, c) in comms.iter().enumerate() {
        c.synchronize().unwrap();
        assert_eq!(
            gathered[r].to_vec().unwrap(),
            want,
            "all_gather on rank {r}"
        );
    }
    // Broadcast from the last rank, in place.
    let root = world - 1;
    let arrays: Vec<wp::Array<T>> = (0..world)
        .map(|r| {
            on(
                &comms[r],
                &(0..block).map(|i| value(r, i)).collect::<Vec<_>>(),
            )
        })
        .collect();
    group(|| {
        for (r, c) in comms.iter().enumerate() {
            c.broadcast(&arrays[r], root)?;
        }
        Ok(())
    })
    .unwrap();
    let want: Vec<T> = (0..block).map(|i| value(root, i)).collect();
    for (r, c) in comms.iter().enumerate() {
        c.synchronize().unwrap();
        assert_eq!(arrays[r].to_vec().unwrap(), want, "broadcast on rank {r}");
    }
}

/// Every reduction and collective on every NCCL element type, over all GPUs.
#[test]
fn collectives_match_the_host_for_every_op_and_type() {
    let _s = serial();
    let Some(gpus) = gpus("collectives_match_the_host_for_every_op_and_type", 1) else {
        return;
    };
    let comms = Communicator::for_devices(&gpus).unwrap();
    assert_eq!(comms.len(), gpus.len());
    for (r, c) in comms.iter().enumerate() {
        assert_eq!((c.rank(), c.world_size()), (r, gpus.len()));
    }
    // 1000 elements: not a multiple of NCCL's chunking, so partial chunks are covered.
    let n = 1000;
    all_reduce_every_op::<i8>(&comms, n);
    all_reduce_every_op::<u8>(&comms, n);
    all_reduce_every_op::<i32>(&comms, n);
    all_reduce_every_op::<u32>(&comms, n);
    all_reduce_every_op::<i64>(&comms, n);
    all_reduce_every_op::<u64>(&comms, n);
    all_reduce_every_op::<wp::f16>(&comms, n);
    all_reduce_every_op::<f32>(&comms, n);
    all_reduce_every_op::<f64>(&comms, n);
    scatter_gather_broadcast::<i8>(&comms, 333);
    scatter_gather_broadcast::<u8>(&comms, 333);
    scatter_gather_broadcast::<i32>(&comms, 333);
    scatter_gather_broadcast::<u32>(&comms, 333);
    scatter_gather_broadcast::<i64>(&comms, 333);
    scatter_gather_broadcast::<u64>(&comms, 333);
    scatter_gather_broadcast::<wp::f16>(&comms, 333);
    scatter_gather_broadcast::<f32>(&comms, 333);
    scatter_gather_broadcast::<f64>(&comms, 333);
    println!(
        "distributed: every op and type over {} GPU(s), NCCL {:?}",
        gpus.len(),
        wp::distributed::nccl_version().unwrap()
    );
}

/// Vector and matrix elements reduce component by component; 2-D arrays reduce as their
/// elements in row-major order.
#[test]
fn vectors_and_matrices_reduce_component_wise() {
    let _s = serial();
    let Some(gpus) = gpus("vectors_and_matrices_reduce_component_wise", 1) else {
        return;
    };
    let comms = Communicator::for_devices(&gpus).unwrap();
    let world = comms.len() as f32;
    let n = 257;
    let vecs: Vec<wp::Array<Vec3>> = comms
        .iter()
        .enumerate()
        .map(|(r, c)| {
            let d: Vec<Vec3> = (0..n).map(|i| Vec3::new(i as f32, r as f32, 1.0)).collect();
            wp::Array::from_slice(&d, c.device()).unwrap()
        })
        .collect();
    let mats: Vec<wp::Array<Mat3, 2>> = comms
        .iter()
        .map(|c| wp::Array::full([4, 5], Mat3::IDENTITY, c.device()).unwrap())
        .collect();
    group(|| {
        for (r, c) in comms.iter().enumerate() {
            c.all_reduce_in_place(&vecs[r], ReduceOp::Sum)?;
            c.all_reduce_in_place(&mats[r], ReduceOp::Sum)?;
        }
        Ok(())
    })
    .unwrap();
    let rank_sum = (0..comms.len()).sum::<usize>() as f32;
    for (r, c) in comms.iter().enumerate() {
        c.synchronize().unwrap();
        let want: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(i as f32 * world, rank_sum, world))
            .collect();
        assert_eq!(vecs[r].to_vec().unwrap(), want, "Vec3 sum on rank {r}");
        assert!(mats[r]
            .to_vec()
            .unwrap()
            .iter()
            .all(|m| *m == Mat3::IDENTITY * world));
    }
}

/// A ring of sends and receives in one group: rank r sends to r + 1 and receives from r - 1.
#[test]
fn send_and_recv_in_a_ring() {
    let _s = serial();
    let Some(gpus) = gpus("send_and_recv_in_a_ring", 2) else {
        return;
    };
    let comms = Communicator::for_devices(&gpus).unwrap();
    let world = comms.len();
    let n = 10_000;
    let out: Vec<wp::Array<f32>> = comms
        .iter()
        .enumerate()
        .map(|(r, c)| wp::Array::from_slice(&vec![r as f32; n], c.device()).unwrap())
        .collect();
    let inbox: Vec<wp::Array<f32>> = comms
        .iter()
        .map(|c| wp::Array::zeros(n, c.device()).unwrap())
        .collect();
    group(|| {
        for (r, c) in comms.iter().enumerate() {
            c.send(&out[r], (r + 1) % world)?;
            c.recv(&inbox[r], (r + world - 1) % world)?;
        }
        Ok(())
    })
    .unwrap();
    for (r, c) in comms.iter().enumerate() {
        c.synchronize().unwrap();
        let from = ((r + world - 1) % world) as f32;
        assert!(inbox[r].to_vec().unwrap().iter().all(|v| *v == from));
    }
}

/// Handles of one rank used from several threads at once: NCCL allows one call at a time on a
/// communicator, and `Communicator` serialises them (issue 35: before, the calls of clones on
/// different threads reached NCCL concurrently, undefined behaviour). Threads 0..4 call
/// `all_reduce` on clones of rank 0 outside any group (only in a world of one, where every
/// order of calls agrees across ranks); threads 4..8 each issue one group over every rank per
/// step (a group holds its communicators until issued, so each step reaches every rank in the
/// same order, and two groups over the same ranks cannot deadlock). Sums of small integers:
/// compared exactly.
#[test]
fn one_communicator_from_several_threads_at_once() {
    let _s = serial();
    let Some(gpus) = gpus("one_communicator_from_several_threads_at_once", 1) else {
        return;
    };
    let comms = Communicator::for_devices(&gpus).unwrap();
    let world = comms.len();
    let (n, steps) = (4096, 50);
    std::thread::scope(|scope| {
        for t in 0..8usize {
            let comms: Vec<Communicator> = comms.to_vec();
            scope.spawn(move || {
                let value = (t + 1) as f32;
                let send: Vec<wp::Array<f32>> = comms
                    .iter()
                    .map(|c| wp::Array::from_slice(&vec![value; n], c.device()).unwrap())
                    .collect();
                let recv: Vec<wp::Array<f32>> = comms
                    .iter()
                    .map(|c| wp::Array::zeros(n, c.device()).unwrap())
                    .collect();
                let plain = t < 4;
                if plain && world != 1 {
                    return;
                }
                for _ in 0..steps {
                    if plain {
                        comms[0]
                            .all_reduce(&send[0], &recv[0], ReduceOp::Sum)
                            .unwrap();
                    } else {
                        group(|| {
                            for (r, c) in comms.iter().enumerate() {
                                c.all_reduce(&send[r], &recv[r], ReduceOp::Sum)?;
                            }
                            Ok(())
                        })
                        .unwrap();
                    }
                }
                for (r, c) in comms.iter().enumerate() {
                    c.synchronize().unwrap();
                    let want = value * world as f32;
                    let got = recv[r].to_vec().unwrap();
                    assert!(
                        got.iter().all(|v| *v == want),
                        "thread {t}, rank {r}: want {want}, got {:?}",
                        &got[..4]
                    );
                }
            });
        }
    });
}

/// One thread per GPU, each capturing a graph with a kernel and an all-reduce and replaying it:
/// collectives are recorded into graphs like launches.
#[test]
fn collectives_inside_a_captured_graph() {
    let _s = serial();
    let Some(gpus) = gpus("collectives_inside_a_captured_graph", 1) else {
        return;
    };
    let comms = Communicator::for_devices(&gpus).unwrap();
    let world = comms.len() as f32;
    let n = 4096;
    std::thread::scope(|s| {
        for c in &comms {
            s.spawn(move || {
                let dev = c.device();
                wp::load(&[wp::kernel_info(d_add_one)], dev).unwrap();
                let a = wp::Array::<f32>::zeros(n, dev).unwrap();
                let graph = wp::capture(dev, || {
                    wp::launch(d_add_one, n, (&a,), dev)?;
                    c.all_reduce_in_place(&a, ReduceOp::Sum)
                })
                .unwrap();
                // Nothing ran during the capture.
                assert!(a.to_vec().unwrap().iter().all(|v| *v == 0.0));
                // Replays: a <- world * (a + 1), three times.
                let mut want = 0.0f32;
                for _ in 0..3 {
                    graph.launch().unwrap();
                    want = world * (want + 1.0);
                }
                c.synchronize().unwrap();
                assert!(
                    a.to_vec().unwrap().iter().all(|v| *v == want),
                    "rank {}: expected {want}",
                    c.rank()
                );
            });
        }
    });
}

#[wp::kernel]
fn d_add_one(a: Array<f32>) {
    let i = tid();
    a[i] += 1.0;
}

/// Bad arguments are errors naming the call, the rank and the values, before NCCL sees them;
/// the communicators work normally afterwards.
#[test]
fn bad_arguments_are_errors() {
    let _s = serial();
    let Some(gpus) = gpus("bad_arguments_are_errors", 1) else {
        return;
    };
    let comms = Communicator::for_devices(&gpus).unwrap();
    let c = &comms[0];
    let world = comms.len();
    let a = wp::Array::<f32>::zeros(8, c.device()).unwrap();
    // An array on the CPU.
    let host = wp::Array::<f32>::zeros(8, &wp::cpu()).unwrap();
    let e = c.all_reduce(&host, &a, ReduceOp::Sum).unwrap_err().chain();
    assert!(
        e.contains("all_reduce on rank 0") && e.contains("\"cpu\""),
        "{e}"
    );
    // Lengths that do not fit.
    let b = wp::Array::<f32>::zeros(9, c.device()).unwrap();
    let e = c.all_reduce(&a, &b, ReduceOp::Sum).unwrap_err().chain();
    assert!(e.contains("send has 8 elements and recv 9"), "{e}");
    // (In a world of one, recv = 1 × send: the same length is right.)
    if world > 1 {
        let e = c.all_gather(&a, &a).unwrap_err().chain();
        assert!(e.contains(&format!("recv = world ({world}) × send")), "{e}");
    }
    let e = c.reduce_scatter(&a, &b, ReduceOp::Sum).unwrap_err().chain();
    assert!(e.contains("reduce_scatter"), "{e}");
    // A non-contiguous view.
    let m = wp::Array::<f32, 2>::zeros([4, 4], c.device()).unwrap();
    let t = m.transpose();
    let e = c
        .all_reduce_in_place(&t, ReduceOp::Sum)
        .unwrap_err()
        .chain();
    assert!(e.contains("not contiguous"), "{e}");
    // Roots and peers outside the world.
    let e = c.broadcast(&a, world).unwrap_err().chain();
    assert!(e.contains(&format!("root {world} is not a rank")), "{e}");
    let e = c.send(&a, 0).unwrap_err().chain();
    assert!(e.contains("peer 0 is not another rank"), "{e}");
    // The same GPU twice in one world.
    let e = Communicator::for_devices(&[gpus[0].clone(), gpus[0].clone()])
        .unwrap_err()
        .chain();
    assert!(e.contains("one rank per GPU"), "{e}");
    // Groups do not nest, and a failing body issues nothing.
    let e = group(|| group(|| Ok(()))).unwrap_err().chain();
    assert!(e.contains("do not nest"), "{e}");
    // The communicators still work.
    let ones: Vec<wp::Array<f32>> = comms
        .iter()
        .map(|c| wp::Array::from_slice(&[1.0f32; 8], c.device()).unwrap())
        .collect();
    group(|| {
        for (r, c) in comms.iter().enumerate() {
            c.all_reduce_in_place(&ones[r], ReduceOp::Sum)?;
        }
        Ok(())
    })
    .unwrap();
    comms[0].synchronize().unwrap();
    assert_eq!(ones[0].to_vec().unwrap(), vec![world as f32; 8]);
}

/// Ranks of one process that disagree (sizes, types, ops, a send without its receive) are
/// refused before anything is issued, naming both ranks; nothing hangs and the communicators
/// stay usable.
#[test]
fn mismatched_ranks_in_a_group_are_errors_not_hangs() {
    let _s = serial();
    let Some(gpus) = gpus("mismatched_ranks_in_a_group_are_errors_not_hangs", 2) else {
        return;
    };
    let comms = Communicator::for_devices(&gpus).unwrap();
    let arr = |r: usize, n: usize| wp::Array::<f32>::zeros(n, comms[r].device()).unwrap();
    let (a0, a1, b1) = (arr(0, 8), arr(1, 8), arr(1, 16));
    let e = group(|| {
        comms[0].all_reduce_in_place(&a0, ReduceOp::Sum)?;
        comms[1].all_reduce_in_place(&b1, ReduceOp::Sum)
    })
    .unwrap_err()
    .chain();
    assert!(
        e.contains("rank 0 calls all_reduce (Sum) of 8 F32")
            && e.contains("rank 1 calls all_reduce (Sum) of 16 F32"),
        "{e}"
    );
    let e = group(|| {
        comms[0].all_reduce_in_place(&a0, ReduceOp::Sum)?;
        comms[1].all_reduce_in_place(&a1, ReduceOp::Max)
    })
    .unwrap_err()
    .chain();
    assert!(e.contains("(Max)"), "{e}");
    let e = group(|| {
        comms[0].send(&a0, 1)?;
        comms[1].recv(&b1, 0)
    })
    .unwrap_err()
    .chain();
    assert!(
        e.contains("rank 0 posts 1 send to rank 1 of 8 F32")
            && e.contains("rank 1 posts 0 matching recv from rank 0 of 8 F32"),
        "{e}"
    );
    // An array of the other GPU.
    let e = comms[0]
        .all_reduce_in_place(&a1, ReduceOp::Sum)
        .unwrap_err()
        .chain();
    assert!(
        e.contains("all_reduce on rank 0") && e.contains("is on \"cuda:1\""),
        "{e}"
    );
    // Still usable: a matching pair.
    a0.fill(2.0).unwrap();
    group(|| {
        comms[0].send(&a0, 1)?;
        comms[1].recv(&a1, 0)
    })
    .unwrap();
    comms[1].synchronize().unwrap();
    assert_eq!(a1.to_vec().unwrap(), vec![2.0; 8]);
}

/// A rank that never joins: the others' `Communicator::new` fails after the timeout instead of
/// waiting forever (a world of two with only rank 0 present: runs on one GPU).
#[test]
fn a_missing_rank_times_out() {
    let _s = serial();
    let Some(gpus) = gpus("a_missing_rank_times_out", 1) else {
        return;
    };
    let id = UniqueId::new().unwrap();
    let start = std::time::Instant::now();
    let e = Communicator::with_timeout(&gpus[0], 0, 2, &id, Duration::from_secs(3))
        .unwrap_err()
        .chain();
    let waited = start.elapsed();
    assert!(
        e.contains("ncclCommInitRank (rank 0 of 2") && e.contains("timed out"),
        "{e}"
    );
    assert!(
        waited < Duration::from_secs(30),
        "returned after {waited:?}"
    );
    // A rank outside the world.
    let e = Communicator::new(&gpus[0], 2, 2, &id).unwrap_err().chain();
    assert!(e.contains("rank 2 of a world of 2"), "{e}");
    // Unique ids round-trip through hex; malformed text is an error.
    assert_eq!(
        UniqueId::from_hex(&id.to_hex()).unwrap().to_bytes(),
        id.to_bytes()
    );
    let e = UniqueId::from_hex("abc").unwrap_err().chain();
    assert!(e.contains("256 hexadecimal digits"), "{e}");
}

/// Unique ids need no GPU: their text form round-trips and malformed text is refused.
#[test]
fn unique_id_text_form() {
    let id = UniqueId::from_bytes(std::array::from_fn(|i| (i * 37) as u8));
    let hex = id.to_hex();
    assert_eq!(hex.len(), 256);
    assert_eq!(
        UniqueId::from_hex(&format!(" {hex}\n")).unwrap().to_bytes(),
        id.to_bytes()
    );
    for bad in ["", "zz", &hex[..254], &format!("{}g", &hex[..255])] {
        assert!(UniqueId::from_hex(bad).is_err(), "{bad:?} accepted");
    }
    // Without a device, making a communicator from the environment names what is missing.
    if std::env::var_os("WARP_RANK").is_none() {
        let e = Communicator::from_env(&wp::cpu()).unwrap_err().chain();
        assert!(e.contains("WARP_RANK is not set"), "{e}");
    }
}

/// What a child process of `one_process_per_gpu` runs (ignored unless run as one).
#[test]
#[ignore = "run by one_process_per_gpu in a child process"]
fn child_rank() {
    let Ok(rank) = std::env::var("WARP_RANK") else {
        return;
    };
    let rank: usize = rank.parse().unwrap();
    let dev = wp::get_device(&format!("cuda:{rank}")).unwrap();
    let comm = Communicator::from_env(&dev).unwrap();
    comm.set_verify(true);
    let world = comm.world_size();
    let n = if std::env::var_os("WARP_TEST_MISMATCH").is_some() && rank == 1 {
        64
    } else {
        32
    };
    let a = wp::Array::from_slice(&vec![rank as f64 + 1.0; n], &dev).unwrap();
    let r = comm.all_reduce_in_place(&a, ReduceOp::Sum);
    if std::env::var_os("WARP_TEST_MISMATCH").is_some() {
        let e = r.unwrap_err().chain();
        assert!(
            e.contains("rank 0 calls all_reduce (Sum) of 32 F64")
                || e.contains("rank 1 calls all_reduce (Sum) of 64 F64"),
            "{e}"
        );
        println!("child {rank}: mismatch reported: {e}");
        return;
    }
    r.unwrap();
    comm.synchronize().unwrap();
    let want = (world * (world + 1) / 2) as f64;
    assert_eq!(a.to_vec().unwrap(), vec![want; n]);
    println!("child {rank}: all_reduce over {world} processes gave {want}");
}

/// Runs `child_rank` in one process per GPU, the id passed in a file as a launcher would.
fn run_children(test: &str, world: usize, extra_env: &[(&str, &str)]) {
    let id = UniqueId::new().unwrap();
    let dir = std::env::temp_dir().join(format!("warp-nccl-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("id");
    std::fs::write(&file, id.to_hex()).unwrap();
    let exe = std::env::current_exe().unwrap();
    let children: Vec<_> = (0..world)
        .map(|r| {
            let mut cmd = std::process::Command::new(&exe);
            cmd.args(["--exact", "child_rank", "--ignored", "--nocapture"])
                .env("WARP_RANK", r.to_string())
                .env("WARP_WORLD_SIZE", world.to_string())
                .env("WARP_NCCL_ID_FILE", &file);
            for (k, v) in extra_env {
                cmd.env(k, v);
            }
            cmd.output_spawn()
        })
        .collect();
    for (r, child) in children.into_iter().enumerate() {
        let out = child.wait_with_output().unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        print!("{text}");
        assert!(
            out.status.success() && text.contains("1 passed"),
            "rank {r} failed: {text}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

trait SpawnPiped {
    fn output_spawn(&mut self) -> std::process::Child;
}

impl SpawnPiped for std::process::Command {
    fn output_spawn(&mut self) -> std::process::Child {
        self.stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    }
}

/// One process per GPU, ranks and id from the environment (the multi-node path).
#[test]
fn one_process_per_gpu() {
    let _s = serial();
    let Some(gpus) = gpus("one_process_per_gpu", 1) else {
        return;
    };
    run_children("one_process_per_gpu", gpus.len(), &[]);
}

/// Processes whose calls differ: with `set_verify` each finds out and returns an error naming
/// the other rank's call, instead of a hang or a wrong result.
#[test]
fn mismatched_sizes_across_processes_are_errors() {
    let _s = serial();
    let Some(gpus) = gpus("mismatched_sizes_across_processes_are_errors", 2) else {
        return;
    };
    run_children(
        "mismatched_sizes_across_processes_are_errors",
        gpus.len(),
        &[("WARP_TEST_MISMATCH", "1")],
    );
}

#[wp::kernel]
fn d_scale(a: Array<f32>, s: f32) {
    let i = tid();
    a[i] = a[i] * s;
}

/// Arrays and launches on every GPU, copies between every pair with peer access on and off,
/// a stream on one GPU waiting for an event of another.
#[test]
fn multi_gpu_basics() {
    let _s = serial();
    let Some(gpus) = gpus("multi_gpu_basics", 2) else {
        return;
    };
    let n = 1 << 20;
    let data: Vec<f32> = (0..n).map(|i| (i % 1000) as f32).collect();
    let arrays: Vec<wp::Array<f32>> = gpus
        .iter()
        .enumerate()
        .map(|(k, d)| {
            let a = wp::Array::from_slice(&data, d).unwrap();
            wp::launch(d_scale, n, (&a, (k + 1) as f32), d).unwrap();
            a
        })
        .collect();
    for (k, a) in arrays.iter().enumerate() {
        let got = a.to_vec().unwrap();
        assert!(
            got.iter().zip(&data).all(|(g, d)| *g == d * (k + 1) as f32),
            "cuda:{k}"
        );
    }
    for (i, a) in gpus.iter().enumerate() {
        for (j, b) in gpus.iter().enumerate() {
            if i == j {
                continue;
            }
            let supported = wp::distributed::peer_access_supported(a, b).unwrap();
            for on in [true, false] {
                let enabled = wp::distributed::set_peer_access(b, a, on).unwrap();
                assert_eq!(enabled, on && supported);
                let dst = wp::Array::<f32>::zeros(n, b).unwrap();
                dst.copy_from(&arrays[i]).unwrap();
                let got = dst.to_vec().unwrap();
                assert!(
                    got.iter().zip(&data).all(|(g, d)| *g == d * (i + 1) as f32),
                    "copy cuda:{i} -> cuda:{j}, peer access {on}"
                );
            }
            println!("cuda:{i} -> cuda:{j}: peer access supported: {supported}");
        }
    }
    // A stream of GPU 1 waits for an event recorded after a long stretch of work on GPU 0:
    // once GPU 1's stream has finished, the event must be complete (were the cross-device
    // wait lost, GPU 1's single launch would finish long before GPU 0's 200).
    let (g0, g1) = (&gpus[0], &gpus[1]);
    let s0 = wp::Stream::new(g0).unwrap();
    let s1 = wp::Stream::new(g1).unwrap();
    let x = wp::Array::from_slice(&data, g0).unwrap();
    let y = wp::Array::from_slice(&data, g1).unwrap();
    for _ in 0..200 {
        wp::launch_on(d_scale, n, (&x, 1.0f32), &s0).unwrap();
    }
    let ev = s0.record_event().unwrap();
    s1.wait_event(&ev).unwrap();
    wp::launch_on(d_scale, n, (&y, 2.0f32), &s1).unwrap();
    s1.synchronize().unwrap();
    assert!(
        ev.is_complete().unwrap(),
        "cuda:1's stream finished before cuda:0's event"
    );
    wp::synchronize().unwrap();
    assert!(y
        .to_vec()
        .unwrap()
        .iter()
        .zip(&data)
        .all(|(g, d)| *g == d * 2.0));
}
