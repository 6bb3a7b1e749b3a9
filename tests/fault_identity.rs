//! Faults name the kernel and the launch that raised them, and reach the thread that made the
//! launch: on the CPU at the launch itself, on a GPU at that thread's next synchronisation,
//! even when other launches (of other kernels, or by other threads) came in between.
//!
//! A test binary of its own: debug mode (process-wide) is off here, so that a GPU fault is
//! reported by a later synchronisation rather than by the launch (the suite runs GPU tests in
//! debug mode). Every test runs on the CPU and on `cuda:0`, or prints SKIPPED without one; the
//! tests run in parallel threads of this process, which is part of what they check: each
//! thread receives its own faults only.

use std::sync::Barrier;
use warp_lang as wp;
use wp::prelude::*;
use wp::{Error, Fault, FaultKind, LaunchId};

/// Reads `a[i + off]` into `out[i]`: out of bounds for `off` past the end.
#[wp::kernel]
fn k_reads_past(a: Array<f32>, off: usize, out: Array<f32>) {
    let i = tid();
    out[i] = a[i + off];
}

/// Doubles `x`: a launch of another kernel, with other parameter names.
#[wp::kernel]
fn k_double(x: Array<f32>) {
    let i = tid();
    x[i] = x[i] * 2.0;
}

/// Runs `test` on the CPU and on the first GPU (or says it skipped).
fn on_every_backend(name: &str, test: impl Fn(&wp::Device)) {
    wp::config::set_debug(false);
    test(&wp::cpu());
    match wp::get_device("cuda:0") {
        Ok(gpu) => test(&gpu),
        Err(e) => eprintln!("SKIPPED fault_identity::{name} on cuda:0: no CUDA device ({e})"),
    }
}

/// The out-of-bounds fault `k_reads_past` raises reading index `index` of its 4 elements in
/// launch `launch`.
fn read_past(index: i128, launch: LaunchId) -> Fault {
    Fault {
        kernel: "k_reads_past",
        kind: FaultKind::OutOfBounds {
            arg: "a",
            index: vec![index],
            shape: vec![4],
        },
        launch: Some(launch),
    }
}

/// The fault in `r`, or a panic naming what came instead; its message must name the launch.
#[track_caller]
fn fault(r: wp::Result<()>) -> Fault {
    match r {
        Err(Error::Fault(f)) => {
            let launch = f.launch.expect("a reported fault names its launch");
            let msg = Error::Fault(f.clone()).to_string();
            assert!(msg.ends_with(&format!(" ({launch})")), "{msg}");
            f
        }
        other => panic!("expected a kernel fault, got {other:?}"),
    }
}

/// Launches `k_reads_past` reading `a[off]`, returning its launch number and what the launch
/// returned.
fn fault_launch(a: &Array<f32>, off: usize, dev: &wp::Device) -> (LaunchId, wp::Result<()>) {
    let out = Array::<f32>::zeros(1, dev).unwrap();
    let r = wp::launch(k_reads_past, 1, (a, off, &out), dev);
    (wp::last_launch_id().expect("a launch was made"), r)
}

/// Kernel A faults, kernel B launches, then a synchronisation: the fault names A, A's
/// argument and A's launch, not B.
#[test]
fn fault_then_other_launch_then_sync() {
    on_every_backend("fault_then_other_launch_then_sync", |dev| {
        let a = Array::<f32>::zeros(4, dev).unwrap();
        let x = Array::full(8, 1.5f32, dev).unwrap();
        let (id_a, r) = fault_launch(&a, 10, dev);
        let reported = if dev.is_cpu() {
            // The CPU reports at the launch; the later launch and synchronisation are clean.
            let f = fault(r);
            wp::launch(k_double, 8, (&x,), dev).unwrap();
            wp::synchronize().unwrap();
            f
        } else {
            r.unwrap();
            wp::launch(k_double, 8, (&x,), dev).unwrap();
            let id_b = wp::last_launch_id().unwrap();
            assert!(id_b > id_a, "launch numbers grow: {id_a} then {id_b}");
            fault(wp::synchronize())
        };
        assert_eq!(reported, read_past(10, id_a));
        // Reported once, and the launch after the faulting one ran.
        wp::synchronize().unwrap();
        assert_eq!(x.to_vec().unwrap(), vec![3.0; 8]);
    });
}

/// Four threads on one device at once, three of them faulting at an index of their own in
/// each round: each receives its own fault (its index, its launch) at its synchronisation, and
/// the fourth receives none.
#[test]
fn threads_faulting_on_one_device_each_receive_their_own() {
    on_every_backend(
        "threads_faulting_on_one_device_each_receive_their_own",
        |dev| {
            const THREADS: usize = 4;
            let barrier = Barrier::new(THREADS);
            std::thread::scope(|s| {
                for t in 0..THREADS {
                    let barrier = &barrier;
                    s.spawn(move || {
                        // A failed check is kept, not raised at once: the other threads would
                        // wait at the barrier for ever.
                        let mut failures = Vec::new();
                        let a = Array::<f32>::zeros(4, dev).unwrap();
                        let x = Array::full(64, 1.0f32, dev).unwrap();
                        for round in 0..20usize {
                            // Everyone launches at about the same time.
                            barrier.wait();
                            let faults = t + 1 < THREADS;
                            let off = if faults { 100 + 10 * t + round } else { 0 };
                            let (id, launched) = fault_launch(&a, off, dev);
                            let doubled = wp::launch(k_double, 64, (&x,), dev);
                            barrier.wait();
                            let synced = wp::synchronize();
                            // The CPU reports at the launch, a GPU at the synchronisation.
                            let fault = Err(Error::Fault(read_past(off as i128, id)));
                            let (want_launch, want_sync) = match (faults, dev.is_cpu()) {
                                (true, true) => (fault, Ok(())),
                                (true, false) => (Ok(()), fault),
                                (false, _) => (Ok(()), Ok(())),
                            };
                            if (&launched, &doubled, &synced) != (&want_launch, &Ok(()), &want_sync)
                            {
                                failures.push(format!(
                                    "thread {t} round {round}: launch {launched:?} (want \
                                     {want_launch:?}), k_double {doubled:?}, synchronize \
                                     {synced:?} (want {want_sync:?})"
                                ));
                            }
                        }
                        let x = x.to_vec().unwrap();
                        if x != vec![2f32.powi(20); 64] {
                            failures.push(format!("thread {t}: x = {:?}", &x[..4]));
                        }
                        assert!(failures.is_empty(), "{failures:#?}");
                    });
                }
            });
        },
    );
}

/// A graph captured on one thread and replayed on another: the replaying thread receives the
/// fault, naming the launch as captured (on every backend: a replay makes no new launch), the
/// capturing thread none.
#[test]
fn graph_fault_reaches_the_replaying_thread() {
    on_every_backend("graph_fault_reaches_the_replaying_thread", |dev| {
        let a = Array::<f32>::zeros(4, dev).unwrap();
        let out = Array::<f32>::zeros(1, dev).unwrap();
        // Nothing compiles inside a capture: load the kernel first (whether another test of
        // this binary has launched it already depends on the threads' order).
        wp::load(&[wp::kernel_info(k_reads_past)], dev).unwrap();
        let graph =
            wp::capture(dev, || wp::launch(k_reads_past, 1, (&a, 7usize, &out), dev)).unwrap();
        // The capture numbers the launch; its replays keep the number.
        let captured = wp::last_launch_id();
        assert!(captured.is_some());
        let graph = std::thread::scope(|s| {
            s.spawn(move || {
                let r = graph.launch();
                let f = if dev.is_cpu() {
                    // The CPU's replay has run the launch: its fault comes back at once.
                    fault(r)
                } else {
                    r.unwrap();
                    fault(wp::synchronize())
                };
                assert_eq!(f.launch, captured);
                assert_eq!(f.kernel, "k_reads_past");
                assert_eq!(
                    f.kind,
                    FaultKind::OutOfBounds {
                        arg: "a",
                        index: vec![7],
                        shape: vec![4]
                    }
                );
                wp::synchronize().unwrap();
                graph
            })
            .join()
            .unwrap()
        });
        // Nothing for the capturing thread.
        wp::synchronize().unwrap();
        drop(graph);
    });
}

/// A refit reads nothing back: on a GPU its check of the boxes (a mesh's points) is a fault
/// of the refit's own launch, reported by the next synchronisation after other launches,
/// naming the operation, the argument and the first bad index; the CPU refuses at the
/// refit, as before. Finite again, the refit is clean (its check reset).
#[test]
fn refit_faults_reach_the_next_synchronisation() {
    on_every_backend("refit_faults_reach_the_next_synchronisation", |dev| {
        let boxes: Vec<Vec3> = (0..64).map(|i| Vec3::splat(i as f32)).collect();
        let lo = Array::from_slice(&boxes, dev).unwrap();
        let hi = Array::from_slice(&boxes, dev).unwrap();
        let mut bvh = wp::Bvh::new(&lo, &hi).unwrap();
        let mut bad = boxes.clone();
        bad[9] = Vec3::new(1.0, f32::INFINITY, 2.0);
        bad[40] = Vec3::NEG_INFINITY;
        hi.copy_from(&Array::from_slice(&bad, dev).unwrap())
            .unwrap();
        let x = Array::<f32>::zeros(4, dev).unwrap();
        let r = bvh.refit();
        if dev.is_cpu() {
            let e = r.unwrap_err().to_string();
            assert!(
                e.contains("argument `uppers`") && e.contains("index 9"),
                "{e}"
            );
        } else {
            r.unwrap();
            let refit = wp::last_launch_id();
            wp::launch(k_double, 4, (&x,), dev).unwrap();
            let f = fault(wp::synchronize());
            assert_eq!(
                f,
                Fault {
                    kernel: "Bvh::refit",
                    kind: FaultKind::NonFiniteInput {
                        arg: "uppers",
                        index: 9,
                        values: vec![1.0, f64::INFINITY, 2.0],
                    },
                    launch: refit,
                }
            );
            wp::synchronize().unwrap();
        }
        hi.copy_from(&lo).unwrap();
        bvh.refit().unwrap();
        wp::synchronize().unwrap();
        // A mesh's points.
        let points = Array::from_slice(&boxes[..4], dev).unwrap();
        let indices = Array::from_slice(&[0, 1, 2, 1, 2, 3], dev).unwrap();
        let mut mesh = wp::Mesh::new(&points, &indices, None).unwrap();
        let mut moved = boxes[..4].to_vec();
        moved[2] = Vec3::new(f32::INFINITY, 0.0, 0.0);
        points
            .copy_from(&Array::from_slice(&moved, dev).unwrap())
            .unwrap();
        let r = mesh.refit();
        let e = if dev.is_cpu() {
            r.unwrap_err()
        } else {
            r.unwrap();
            Error::Fault(fault(wp::synchronize()))
        };
        let t = e.to_string();
        assert!(
            t.contains("Mesh::refit") && t.contains("argument `points`") && t.contains("index 2"),
            "{t}"
        );
        // A hash grid's points: the build's own check (a GPU build reads nothing back).
        let mut grid = wp::HashGrid::new(8, 8, 8, dev).unwrap();
        let pts = Array::from_slice(&moved, dev).unwrap();
        let r = grid.build(&pts, 0.5);
        if dev.is_cpu() {
            let e = r.unwrap_err().to_string();
            assert!(
                e.contains("HashGrid::build")
                    && e.contains("argument `points`")
                    && e.contains("index 2"),
                "{e}"
            );
            assert!(
                !grid.is_built(),
                "a refused CPU build leaves the grid unbuilt"
            );
        } else {
            r.unwrap();
            let build = wp::last_launch_id();
            let f = fault(wp::synchronize());
            assert_eq!(f.kernel, "HashGrid::build");
            assert_eq!(f.launch, build, "the fault is the build's last step's");
            assert!(
                matches!(
                    &f.kind,
                    FaultKind::NonFiniteInput {
                        arg: "points",
                        index: 2,
                        ..
                    }
                ),
                "{f:?}"
            );
            wp::synchronize().unwrap();
            assert!(
                grid.is_built(),
                "a GPU build of a non-finite point is complete"
            );
        }
        // A build of finite points afterwards is a plain one: the same ranges and order as a
        // fresh grid's (the rebuild clears what the faulted build left from its keys).
        let finite = Array::from_slice(&boxes[..4], dev).unwrap();
        grid.build(&finite, 0.5).unwrap();
        let mut fresh = wp::HashGrid::new(8, 8, 8, dev).unwrap();
        fresh.build(&finite, 0.5).unwrap();
        wp::synchronize().unwrap();
        assert!(grid.is_built());
        let table = |g: &wp::HashGrid| {
            let (starts, ends) = g.cell_ranges().unwrap();
            let ids = g.point_ids().unwrap();
            (
                starts.to_vec().unwrap(),
                ends.to_vec().unwrap(),
                ids.to_vec().unwrap(),
            )
        };
        assert_eq!(table(&grid), table(&fresh), "the rebuilt grid's tables");
    });
}

/// Writes `v` at `ix[k]` (one thread): a kernel that corrupts a mesh's indices.
#[wp::kernel]
fn k_set_index(ix: Array<i32>, k: usize, v: i32) {
    ix[k] = v;
}

/// A mesh's index a kernel wrote outside the points after the build: the CPU's refit refuses
/// it, naming `indices`, the value and its position; a GPU's refit (which reads nothing back)
/// raises it as an out-of-bounds fault of `Mesh::refit` on `indices`, index `[position,
/// value]` of shape `[indices, points]` (the smallest bad position), reported by the next
/// synchronisation after another kernel's launch. Valid again, the refit is clean (its check
/// word reset).
#[test]
fn mesh_refit_faults_on_a_bad_index() {
    on_every_backend("mesh_refit_faults_on_a_bad_index", |dev| {
        let pts: Vec<Vec3> = (0..6)
            .map(|i| Vec3::new(i as f32, (i * i) as f32, 0.5))
            .collect();
        let points = Array::from_slice(&pts, dev).unwrap();
        let ix = [0, 1, 2, 1, 2, 3, 2, 3, 4, 3, 4, 5];
        let indices = Array::from_slice(&ix, dev).unwrap();
        let mut mesh = wp::Mesh::new(&points, &indices, None).unwrap();
        wp::launch(k_set_index, 1, (mesh.indices(), 10usize, -3i32), dev).unwrap();
        wp::launch(k_set_index, 1, (mesh.indices(), 7usize, 6i32), dev).unwrap();
        let x = Array::<f32>::zeros(4, dev).unwrap();
        let r = mesh.refit();
        if dev.is_cpu() {
            let e = r.unwrap_err().to_string();
            assert!(
                e.contains("Mesh::refit")
                    && e.contains("argument `indices`")
                    && e.contains("6 at position 7"),
                "{e}"
            );
        } else {
            r.unwrap();
            let refit = wp::last_launch_id();
            wp::launch(k_double, 4, (&x,), dev).unwrap();
            let f = fault(wp::synchronize());
            assert_eq!(
                f,
                Fault {
                    kernel: "Mesh::refit",
                    kind: FaultKind::OutOfBounds {
                        arg: "indices",
                        index: vec![7, 6],
                        shape: vec![12, 6],
                    },
                    launch: refit,
                }
            );
            wp::synchronize().unwrap();
        }
        wp::launch(k_set_index, 1, (mesh.indices(), 7usize, ix[7]), dev).unwrap();
        wp::launch(k_set_index, 1, (mesh.indices(), 10usize, ix[10]), dev).unwrap();
        mesh.refit().unwrap();
        wp::synchronize().unwrap();
    });
}

/// A thread that faults and ends without synchronising: its fault is not handed to another
/// thread (it is logged), and a new thread taking over its record starts clean.
#[test]
fn an_ended_threads_fault_goes_to_no_other_thread() {
    on_every_backend("an_ended_threads_fault_goes_to_no_other_thread", |dev| {
        let a = Array::<f32>::zeros(4, dev).unwrap();
        std::thread::scope(|s| {
            s.spawn(|| {
                let (id, r) = fault_launch(&a, 40, dev);
                if dev.is_cpu() {
                    assert_eq!(fault(r), read_past(40, id));
                }
            });
        });
        wp::synchronize().unwrap();
        std::thread::scope(|s| {
            s.spawn(|| {
                let x = Array::full(4, 1.0f32, dev).unwrap();
                wp::launch(k_double, 4, (&x,), dev).unwrap();
                wp::synchronize().unwrap();
                assert_eq!(x.to_vec().unwrap(), vec![2.0; 4]);
            });
        });
    });
}

/// A parallel primitive's fault (a device count out of range, only a GPU's fault: the CPU
/// checks the count before running) names the primitive and its launch after a later launch.
#[test]
fn primitive_fault_names_the_primitive_launch() {
    on_every_backend("primitive_fault_names_the_primitive_launch", |dev| {
        let input = Array::from_slice(&[1i32, 2, 3, 4], dev).unwrap();
        let output = Array::<i32>::zeros(4, dev).unwrap();
        let count = Array::from_slice(&[9i32], dev).unwrap();
        let r = wp::array_scan_n(&input, &output, &count, true);
        if dev.is_cpu() {
            assert!(matches!(r, Err(Error::InvalidArgument { .. })), "{r:?}");
            return;
        }
        r.unwrap();
        let id = wp::last_launch_id().unwrap();
        let x = Array::full(4, 1.0f32, dev).unwrap();
        wp::launch(k_double, 4, (&x,), dev).unwrap();
        let f = fault(wp::synchronize());
        assert_eq!(
            f,
            Fault {
                kernel: "array_scan_n",
                kind: FaultKind::OutOfBounds {
                    arg: "count",
                    index: vec![9],
                    shape: vec![5]
                },
                launch: Some(id),
            }
        );
    });
}

/// Counts the points of `x` within `r` of `x[0]` through the grid (one thread).
#[wp::kernel]
fn k_count_near_first(grid: HashGrid, x: Array<Vec3>, r: f32, out: Array<i32>) {
    let p = x[0];
    let mut c = 0;
    for j in hash_grid_query(grid, p, r) {
        if length(p - x[j]) <= r {
            c += 1;
        }
    }
    out[0] = c;
}

/// The grid the query-fault tests corrupt: points 0 and 1 in cell (0, 0, 0), bucket 0, and
/// point 2 in (2, 2, 2), cells of width 1 in 4 x 4 x 4 buckets; with a count to write.
fn three_point_grid(dev: &wp::Device) -> (Array<Vec3>, wp::HashGrid, Array<i32>) {
    let pts = [
        Vec3::new(0.1, 0.1, 0.1),
        Vec3::new(0.2, 0.1, 0.1),
        Vec3::new(2.5, 2.5, 2.5),
    ];
    let x = Array::from_slice(&pts, dev).unwrap();
    let mut grid = wp::HashGrid::new(4, 4, 4, dev).unwrap();
    grid.build(&x, 1.0).unwrap();
    (x, grid, Array::<i32>::zeros(1, dev).unwrap())
}

/// A bucket start a kernel wrote below 0 after the build: a query entering that bucket
/// faults as the out-of-bounds read of the grid's points there (the grid's parameter, index
/// the start, shape the point count) on both backends, and the query ends (on a GPU the
/// thread goes on without the bucket). An end past the points is clamped, no fault.
#[test]
fn hash_grid_query_faults_on_a_corrupt_start() {
    on_every_backend("hash_grid_query_faults_on_a_corrupt_start", |dev| {
        let (x, grid, out) = three_point_grid(dev);
        let (starts, ends) = grid.cell_ranges().unwrap();
        // Cell (0, 0, 0) is bucket 0 and holds points 0 and 1; (2, 2, 2) holds point 2.
        assert_eq!(
            (starts.to_vec().unwrap()[0], ends.to_vec().unwrap()[0]),
            (0, 2)
        );
        wp::launch(k_count_near_first, 1, (&grid, &x, 0.5f32, &out), dev).unwrap();
        wp::synchronize().unwrap();
        assert_eq!(out.to_vec().unwrap(), [2]);
        // An end past the points: clamped to the point count, so bucket 0 reads points 0..3
        // (the third is out of reach); no fault.
        wp::launch(k_set_index, 1, (&ends, 0usize, 7i32), dev).unwrap();
        wp::launch(k_count_near_first, 1, (&grid, &x, 0.5f32, &out), dev).unwrap();
        wp::synchronize().unwrap();
        assert_eq!(out.to_vec().unwrap(), [2]);
        // A start below 0: the fault of the query's launch.
        wp::launch(k_set_index, 1, (&starts, 0usize, -2i32), dev).unwrap();
        let r = wp::launch(k_count_near_first, 1, (&grid, &x, 0.5f32, &out), dev);
        let launch = wp::last_launch_id().unwrap();
        let f = fault(r.and_then(|()| wp::synchronize()));
        assert_eq!(
            f,
            Fault {
                kernel: "k_count_near_first",
                kind: FaultKind::OutOfBounds {
                    arg: "grid",
                    index: vec![-2],
                    shape: vec![3],
                },
                launch: Some(launch),
            }
        );
        // Mended, the grid answers again.
        wp::launch(k_set_index, 1, (&starts, 0usize, 0i32), dev).unwrap();
        wp::launch(k_count_near_first, 1, (&grid, &x, 0.5f32, &out), dev).unwrap();
        wp::synchronize().unwrap();
        assert_eq!(out.to_vec().unwrap(), [2]);
    });
}

/// A point id a kernel wrote into the grid after the build that is not a point index (past
/// the points, or negative): the query yielding it faults as an out-of-bounds access of the
/// grid's points at that id (the grid's parameter, index the id, shape the point count) on
/// both backends, before the kernel's `x[j]` could read with it, and the query ends. Every
/// candidate being a point index is what lets a query loop's `x[j]` skip its own check on a
/// GPU once `x` holds as many elements as the grid has points.
#[test]
fn hash_grid_query_faults_on_a_corrupt_point_id() {
    on_every_backend("hash_grid_query_faults_on_a_corrupt_point_id", |dev| {
        let (x, grid, out) = three_point_grid(dev);
        let ids = grid.point_ids().unwrap();
        // Bucket 0 holds positions 0 and 1 of the ids (points 0 and 1).
        assert_eq!(&ids.to_vec().unwrap()[..2], &[0, 1]);
        for bad in [7i32, 3, -3] {
            wp::launch(k_set_index, 1, (&ids, 1usize, bad), dev).unwrap();
            let r = wp::launch(k_count_near_first, 1, (&grid, &x, 0.5f32, &out), dev);
            let launch = wp::last_launch_id().unwrap();
            let f = fault(r.and_then(|()| wp::synchronize()));
            assert_eq!(
                f,
                Fault {
                    kernel: "k_count_near_first",
                    kind: FaultKind::OutOfBounds {
                        arg: "grid",
                        index: vec![bad as i128],
                        shape: vec![3],
                    },
                    launch: Some(launch),
                },
                "point id {bad}"
            );
        }
        // Mended, the grid answers again.
        wp::launch(k_set_index, 1, (&ids, 1usize, 1i32), dev).unwrap();
        wp::launch(k_count_near_first, 1, (&grid, &x, 0.5f32, &out), dev).unwrap();
        wp::synchronize().unwrap();
        assert_eq!(out.to_vec().unwrap(), [2]);
    });
}
