//! GPU benchmark of the host side of step loops: a 10-kernel substep run 1000 times, launched
//! plainly, through launch objects (`wp::Launch`), as replays of a captured graph, and as one
//! graph of all 10,000 launches; beside the same loop of hand-written CUDA launched raw
//! (`cuLaunchKernel` through `warp_cuda`) and as a raw graph, and beside NVIDIA Warp 1.19
//! (`benches/py/warp_graph.py`: `wp.launch`, `wp.Launch`, `wp.capture_launch`) in the same
//! run. Every mode's result is compared with the plain launches' (bit for bit) and with the
//! closed form of the oscillator it integrates. The hand-written substep as a raw graph
//! replayed 1000 times is the floor of the replays of warp-lang's substep graph. Two more raw
//! graphs of the hand-written kernels, one with as many parameter bytes as warp-lang's kernels
//! take and one with a 64-bit grid-stride loop (warp-lang's entries had one until their
//! threads became one per element), say what each costs a graph replay.
//!
//! ```text
//! cargo bench --bench graph                    # needs a CUDA device; SKIPPED otherwise
//! # on the GPU machine, with Warp unpacked by ../shared/tools/warp-bundle:
//! PYTHONPATH=/root/warp-lang .gpu/bin/graph-*
//! ```
//!
//! The substep: five pairs of `v -= k x dt; x += v dt` (symplectic Euler of x'' = -k x) over
//! 1024 oscillators, so that every kernel is tiny and the loop measures launch costs. "host"
//! is the time until the launching loop returns (what the CPU spends queueing), "total" until
//! the GPU has finished; both per kernel launched.

use std::ffi::c_void;
use std::time::Instant;
use warp_lang as wp;
use wp::prelude::*;

mod common;
use common::{json_number, python_side};

/// The springs scene's chain and its kernels.
#[path = "../examples/common/springs.rs"]
mod springs;
// The sparse tier, for common/springs.rs (its coloured XPBD series).
use warp_runtime::sparse;

const N: usize = 1024;
const SUBSTEPS: usize = 1000;
const PAIRS: usize = 5;
const KERNELS: usize = SUBSTEPS * 2 * PAIRS;
const K: f32 = 40.0;
const DT: f32 = 1e-4;
const REPS: usize = 7;

#[wp::kernel]
fn velocity(x: Array<f32>, v: Array<f32>, k: f32, dt: f32) {
    let i = tid();
    v[i] = v[i] - k * x[i] * dt;
}

#[wp::kernel]
fn position(x: Array<f32>, v: Array<f32>, dt: f32) {
    let i = tid();
    x[i] = x[i] + v[i] * dt;
}

/// One thread: counts down, and keeps the loop's flag set while the count is positive.
#[wp::kernel]
fn count_down(counter: Array<i32>, flag: Array<i32>) {
    let _i = tid();
    let c = counter[0] - 1;
    counter[0] = c;
    flag[0] = if c > 0 { 1 } else { 0 };
}

const HAND: &str = r#"
extern "C" __global__ void hand_velocity(const float* x, float* v, float k, float dt, int n) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) v[i] = v[i] - k * x[i] * dt;
}
extern "C" __global__ void hand_position(float* x, const float* v, float dt, int n) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) x[i] = x[i] + v[i] * dt;
}
// The same with 128 parameter bytes more, unused: as many as warp-lang's kernels take (152
// for `velocity`: the 48-byte grid, the 32-byte fault record, two 32-byte arrays, two f32).
struct pad_t { long long w[16]; };
extern "C" __global__ void hand_velocity_pad(pad_t pad, const float* x, float* v, float k, float dt, int n) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) v[i] = v[i] - k * x[i] * dt;
}
extern "C" __global__ void hand_position_pad(pad_t pad, float* x, const float* v, float dt, int n) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) x[i] = x[i] + v[i] * dt;
}
// The same with warp-lang's loop: 64-bit indices striding over the grid.
extern "C" __global__ void hand_velocity_stride(const float* x, float* v, float k, float dt, int n) {
    const long long stride = (long long)blockDim.x * gridDim.x;
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < n; i += stride)
        v[i] = v[i] - k * x[i] * dt;
}
extern "C" __global__ void hand_position_stride(float* x, const float* v, float dt, int n) {
    const long long stride = (long long)blockDim.x * gridDim.x;
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < n; i += stride)
        x[i] = x[i] + v[i] * dt;
}
"#;

fn x0() -> Vec<f32> {
    (0..N).map(|i| 0.5 + (i % 7) as f32 * 0.1).collect()
}

/// Median of `REPS` runs of `f` after one warm-up: (host ms, total ms).
fn timed(mut f: impl FnMut() -> wp::Result<()>) -> wp::Result<(f64, f64)> {
    f()?;
    wp::synchronize()?;
    let (mut host, mut total) = (Vec::new(), Vec::new());
    for _ in 0..REPS {
        wp::synchronize()?;
        let t = Instant::now();
        f()?;
        host.push(t.elapsed().as_secs_f64() * 1e3);
        wp::synchronize()?;
        total.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok((common::median_of(host), common::median_of(total)))
}

/// Host microseconds per launch when the GPU keeps up: 200 launches of `launch` from an idle
/// GPU (fewer than the driver queues, so the host never waits for the GPU), median of 15.
fn host_cost(mut launch: impl FnMut() -> wp::Result<()>) -> wp::Result<f64> {
    const LAUNCHES: usize = 200;
    let mut t = Vec::new();
    for _ in 0..16 {
        wp::synchronize()?;
        let s = Instant::now();
        for _ in 0..LAUNCHES {
            launch()?;
        }
        t.push(s.elapsed().as_secs_f64() * 1e6 / LAUNCHES as f64);
    }
    wp::synchronize()?;
    t.remove(0);
    Ok(common::median_of(t))
}

/// Microseconds per kernel of `ms` spent on `KERNELS` launches.
fn per_kernel(ms: f64) -> f64 {
    ms * 1e3 / KERNELS as f64
}

/// The largest distance of the oscillators from the closed form x0 cos(sqrt(k) t) after
/// `steps` steps (symplectic Euler's error is O(dt)).
fn closed_form_error(x: &[f32], steps: usize) -> f64 {
    let t = steps as f64 * DT as f64;
    let w = (K as f64).sqrt();
    x.iter()
        .zip(x0())
        .map(|(&a, b)| (a as f64 - b as f64 * (w * t).cos()).abs())
        .fold(0.0, f64::max)
}

struct Row {
    name: &'static str,
    host_us: f64,
    total_us: f64,
    max_diff: f64,
    error: f64,
    warp_us: Option<f64>,
}

fn main() -> wp::Result<()> {
    let dev = match wp::get_device("cuda:0") {
        Ok(d) => d,
        Err(e) => {
            println!("graph bench SKIPPED: no CUDA device ({e})");
            return Ok(());
        }
    };
    let warp = python_side("benches/py/warp_graph.py", &[]);
    let warp_us = |key: &str| warp.as_ref().ok().and_then(|j| json_number(j, key));
    wp::load(
        &[
            wp::kernel_info(velocity),
            wp::kernel_info(position),
            wp::kernel_info(count_down),
        ],
        &dev,
    )?;
    let x = wp::Array::from_slice(&x0(), &dev)?;
    let v = wp::Array::<f32>::zeros(N, &dev)?;
    let reset = || -> wp::Result<()> {
        x.copy_from(&wp::Array::from_slice(&x0(), &wp::cpu())?)?;
        v.fill(0.0)
    };
    let substep = || -> wp::Result<()> {
        for _ in 0..PAIRS {
            wp::launch(velocity, N, (&x, &v, K, DT), &dev)?;
            wp::launch(position, N, (&x, &v, DT), &dev)?;
        }
        Ok(())
    };
    // Each mode runs the loop from the start (REPS + 1 times); the result compared is the
    // state after one loop of the mode, against one plain loop.
    let one_loop_result = |run: &mut dyn FnMut() -> wp::Result<()>| -> wp::Result<Vec<f32>> {
        reset()?;
        run()?;
        x.to_vec()
    };
    let mut rows = Vec::new();
    let mut plain_loop = || -> wp::Result<()> {
        for _ in 0..SUBSTEPS {
            substep()?;
        }
        Ok(())
    };
    let reference = one_loop_result(&mut plain_loop)?;
    let steps = SUBSTEPS * PAIRS;
    let mut record = |name, (host, total): (f64, f64), result: Vec<f32>, warp: Option<f64>| {
        let max_diff = result
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs() as f64)
            .fold(0.0, f64::max);
        rows.push(Row {
            name,
            host_us: per_kernel(host),
            total_us: per_kernel(total),
            max_diff,
            error: closed_form_error(&result, steps),
            warp_us: warp,
        });
    };

    // Plain launches.
    let t = timed(&mut plain_loop)?;
    let r = one_loop_result(&mut plain_loop)?;
    record("plain wp::launch", t, r, warp_us("plain_us"));

    // Launch objects: one per kernel of a pair, launched five times a substep.
    let mut vel = wp::Launch::new(velocity, N, (&x, &v, K, DT), &dev)?;
    let mut pos = wp::Launch::new(position, N, (&x, &v, DT), &dev)?;
    let mut objects = || -> wp::Result<()> {
        for _ in 0..SUBSTEPS * PAIRS {
            vel.launch()?;
            pos.launch()?;
        }
        Ok(())
    };
    let t = timed(&mut objects)?;
    let r = one_loop_result(&mut objects)?;
    record(
        "launch objects (wp::Launch)",
        t,
        r,
        warp_us("launch_object_us"),
    );

    let host_plain = host_cost(|| wp::launch(velocity, N, (&x, &v, K, DT), &dev))?;
    let host_object = host_cost(|| vel.launch())?;

    // One substep captured, replayed 1000 times.
    let tc = Instant::now();
    let one = wp::capture(&dev, substep)?;
    let capture_one_ms = tc.elapsed().as_secs_f64() * 1e3;
    let mut replays = || -> wp::Result<()> {
        for _ in 0..SUBSTEPS {
            one.launch()?;
        }
        Ok(())
    };
    let t = timed(&mut replays)?;
    let r = one_loop_result(&mut replays)?;
    record(
        "graph of a substep x 1000",
        t,
        r,
        warp_us("graph_substep_us"),
    );

    // All 10,000 launches in one graph.
    let tc = Instant::now();
    let all = wp::capture(&dev, || {
        for _ in 0..SUBSTEPS {
            substep()?;
        }
        Ok(())
    })?;
    let capture_all_ms = tc.elapsed().as_secs_f64() * 1e3;
    let mut whole = || all.launch();
    let t = timed(&mut whole)?;
    let r = one_loop_result(&mut whole)?;
    record(
        "one graph of 10,000 launches",
        t,
        r,
        warp_us("graph_all_us"),
    );

    // An adaptive loop on the device: capture_while over the substep and a count-down kernel
    // (11 kernels an iteration), the count and the flag set inside the graph.
    let (counter, flag) = (
        wp::Array::<i32>::zeros(1, &dev)?,
        wp::Array::<i32>::zeros(1, &dev)?,
    );
    let looped = wp::capture(&dev, || {
        counter.fill(SUBSTEPS as i32)?;
        flag.fill(1)?;
        wp::capture_while(&flag, || {
            substep()?;
            wp::launch(count_down, 1, (&counter, &flag), &dev)
        })
    });
    match looped {
        Ok(looped) => {
            let mut run = || looped.launch();
            let (host, total) = timed(&mut run)?;
            let r = one_loop_result(&mut run)?;
            // Per kernel of the 11 an iteration runs.
            let scale = KERNELS as f64 / (SUBSTEPS * (2 * PAIRS + 1)) as f64;
            record(
                "capture_while (device loop), 11/iter",
                (host * scale, total * scale),
                r,
                warp_us("capture_while_us"),
            );
        }
        Err(e) => println!("capture_while: not run ({e})"),
    }

    // Hand-written CUDA, raw launches and a raw graph, on buffers of their own.
    let hand = Hand::new();
    let hx = warp_cuda::DeviceBuffer::from_bytes(&hand.gpu, bytemuck::cast_slice(&x0()))
        .expect("upload");
    let hv = warp_cuda::DeviceBuffer::zeros(&hand.gpu, 4 * N).expect("alloc");
    let (xp, vp) = (hx.device_ptr(), hv.device_ptr());
    let raw_loop_of = |variant: HandVariant, stream: &warp_cuda::Stream| {
        for _ in 0..SUBSTEPS * PAIRS {
            hand.velocity(variant, stream, xp, vp);
            hand.position(variant, stream, xp, vp);
        }
    };
    let raw_loop = |stream: &warp_cuda::Stream| -> wp::Result<()> {
        raw_loop_of(HandVariant::Plain, stream);
        Ok(())
    };
    let raw_result = |run: &mut dyn FnMut() -> wp::Result<()>| -> wp::Result<Vec<f32>> {
        hx.upload(0, bytemuck::cast_slice(&x0())).expect("upload");
        hv.fill_pattern(0, 4 * N, &[0]).expect("fill");
        run()?;
        wp::synchronize()?;
        Ok(bytemuck::cast_slice(&hx.to_vec().expect("download")).to_vec())
    };
    let default = hand.gpu.default_stream().clone();
    let host_raw = host_cost(|| {
        hand.velocity(HandVariant::Plain, &default, xp, vp);
        Ok(())
    })?;
    let t = timed(|| raw_loop(&default))?;
    let r = raw_result(&mut || raw_loop(&default))?;
    record("hand-written CUDA, raw launches", t, r, None);
    // The floor of "graph of a substep x 1000": the hand kernels' substep (10 launches) as a
    // raw graph, replayed 1000 times (each replay pays a graph launch).
    {
        let stream = hand.gpu.new_stream().expect("stream");
        stream.begin_capture().expect("capture");
        for _ in 0..PAIRS {
            hand.velocity(HandVariant::Plain, &stream, xp, vp);
            hand.position(HandVariant::Plain, &stream, xp, vp);
        }
        let graph = stream.end_capture(&hand.gpu).expect("graph");
        let mut replays = || -> wp::Result<()> {
            for _ in 0..SUBSTEPS {
                graph.launch(&default).expect("graph launch");
            }
            Ok(())
        };
        let t = timed(&mut replays)?;
        let r = raw_result(&mut replays)?;
        record("hand, raw graph of a substep x 1000", t, r, None);
    }
    // Raw graphs: the hand kernels, and, to tell what of the gap between warp-lang's graph and
    // the raw one is parameter bytes and what the loop, the same with warp-lang's parameter
    // size and with its loop.
    for (variant, name) in [
        (HandVariant::Plain, "hand-written CUDA, one raw graph"),
        (HandVariant::Padded, "hand, +128 param bytes, raw graph"),
        (HandVariant::Stride, "hand, 64-bit stride, raw graph"),
    ] {
        let stream = hand.gpu.new_stream().expect("stream");
        stream.begin_capture().expect("capture");
        raw_loop_of(variant, &stream);
        let graph = stream.end_capture(&hand.gpu).expect("graph");
        let mut replay = || -> wp::Result<()> {
            graph.launch(&default).expect("graph launch");
            Ok(())
        };
        let t = timed(&mut replay)?;
        let r = raw_result(&mut replay)?;
        record(name, t, r, None);
    }

    // A scene's loop end to end: the springs scene's chains (semi-implicit Euler, a kernel a
    // step over 4096 chains of 21 particles), 512 steps plainly and as two replays of a
    // 256-step graph, k = 1000 N/m, dt = 1/960 s; the graph's result against the plain one's
    // and against the f64 RK4 reference of chain 0.
    let (k_chain, dt_chain, steps_chain) = (1000.0f32, 1.0f32 / 960.0, 512usize);
    let solver = springs::Solver::Euler;
    let reference = springs::reference(k_chain as f64, steps_chain as f64 * dt_chain as f64, 1e-5);
    wp::load(&[wp::kernel_info(springs::euler_step)], &dev)?;
    let run_chains = |graph: bool| -> wp::Result<(f64, Vec<glam::DVec3>)> {
        let mut chains = springs::Chains::new(4096, &dev)?;
        let mut captured = None;
        if graph {
            let g = wp::capture(&dev, || {
                for _ in 0..256 {
                    chains.step(solver, k_chain, dt_chain, &dev)?;
                }
                Ok(())
            })?;
            captured = Some(g);
        } else {
            chains.step(solver, k_chain, dt_chain, &dev)?; // compiles; a fresh state follows
            chains = springs::Chains::new(4096, &dev)?;
        }
        wp::synchronize()?;
        let t = Instant::now();
        match &captured {
            Some(g) => {
                for _ in 0..steps_chain / 256 {
                    g.launch()?;
                }
            }
            None => {
                for _ in 0..steps_chain {
                    chains.step(solver, k_chain, dt_chain, &dev)?;
                }
            }
        }
        wp::synchronize()?;
        Ok((t.elapsed().as_secs_f64() * 1e3, chains.first()?.0))
    };
    let (plain_ms, plain_x) = run_chains(false)?;
    let (graph_ms, graph_x) = run_chains(true)?;
    let diff = plain_x
        .iter()
        .zip(&graph_x)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);
    let err = graph_x
        .iter()
        .zip(&reference)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);

    println!(
        "springs scene, 4096 chains, {steps_chain} Euler steps: plain {plain_ms:.2} ms, graph \
         {graph_ms:.2} ms ({:.2}x); |graph - plain| = {diff:.1e} m, error against the f64 RK4 \
         reference {err:.2e} m",
        plain_ms / graph_ms
    );
    println!(
        "host side of a step loop on \"{}\": {SUBSTEPS} substeps x {} kernels over {N} \
         oscillators (k = {K}, dt = {DT}), microseconds per kernel, medians of {REPS}",
        dev.name(),
        2 * PAIRS
    );
    println!(
        "{:<34} {:>9} {:>9} {:>13} {:>11} {:>13}",
        "mode", "host us", "total us", "vs plain", "closed form", "Warp 1.19 us"
    );
    for r in &rows {
        let warp = match r.warp_us {
            Some(w) => format!("{w:8.2} ({:.2}x)", r.total_us / w),
            None => "-".into(),
        };
        println!(
            "{:<34} {:>9.3} {:>9.3} {:>13} {:>11.2e} {:>13}",
            r.name,
            r.host_us,
            r.total_us,
            if r.max_diff == 0.0 {
                "bit for bit".to_string()
            } else {
                format!("{:.1e}", r.max_diff)
            },
            r.error,
            warp
        );
    }
    let warp_host = |key: &str| warp_us(key).map_or("-".to_string(), |w| format!("{w:.2} us"));
    println!(
        "host cost per launch of one tiny kernel, 200 launches from an idle GPU: plain \
         {host_plain:.2} us, launch object {host_object:.2} us, hand-written raw launch \
         {host_raw:.2} us; Warp 1.19 plain {}, wp.Launch {}",
        warp_host("host_plain_us"),
        warp_host("host_launch_object_us")
    );
    println!(
        "capture: {capture_one_ms:.2} ms for 10 launches, {capture_all_ms:.1} ms for {KERNELS} \
         (graph nodes {})",
        all.node_count()
    );
    match &warp {
        Ok(j) => println!("Warp 1.19 (same run): {j}"),
        Err(e) => println!("Warp 1.19: not run ({e})"),
    }
    println!(
        "(Warp's 'total' per kernel is beside ours; the DESIGN goal is <= 1 us per kernel in a \
         graph, Warp's figure 1.28 us)"
    );
    Ok(())
}

/// The hand-written kernels, launched through `warp_cuda` directly.
struct Hand {
    gpu: std::sync::Arc<warp_cuda::Gpu>,
    _module: warp_cuda::Module,
    /// `velocity` and `position` of each [`HandVariant`], in its order.
    kernels: Vec<(warp_cuda::Function, warp_cuda::Function)>,
}

/// Which of the hand-written pairs: the plain one, with 128 unused parameter bytes first, or
/// with a 64-bit grid-stride loop.
#[derive(Clone, Copy)]
enum HandVariant {
    Plain,
    Padded,
    Stride,
}

impl Hand {
    fn new() -> Hand {
        let gpu = warp_cuda::Gpu::open(0).expect("gpu");
        let compiled =
            warp_cuda::compile(HAND, "hand", &Default::default(), gpu.arch()).expect("nvrtc");
        let module = gpu.load_module(&compiled.cubin).expect("load");
        let kernels = ["", "_pad", "_stride"]
            .iter()
            .map(|suffix| {
                let f = |name: &str| {
                    module
                        .function(&format!("{name}{suffix}"))
                        .expect("function")
                };
                (f("hand_velocity"), f("hand_position"))
            })
            .collect();
        Hand {
            kernels,
            gpu,
            _module: module,
        }
    }

    fn velocity(&self, variant: HandVariant, stream: &warp_cuda::Stream, mut x: u64, mut v: u64) {
        let (mut k, mut dt, mut n, mut pad) = (K, DT, N as i32, [0i64; 16]);
        let mut args = vec![
            ptr(&mut x),
            ptr(&mut v),
            ptr(&mut k),
            ptr(&mut dt),
            ptr(&mut n),
        ];
        if let HandVariant::Padded = variant {
            args.insert(0, ptr(&mut pad));
        }
        self.launch(&self.kernels[variant as usize].0, stream, &mut args);
    }

    fn position(&self, variant: HandVariant, stream: &warp_cuda::Stream, mut x: u64, mut v: u64) {
        let (mut dt, mut n, mut pad) = (DT, N as i32, [0i64; 16]);
        let mut args = vec![ptr(&mut x), ptr(&mut v), ptr(&mut dt), ptr(&mut n)];
        if let HandVariant::Padded = variant {
            args.insert(0, ptr(&mut pad));
        }
        self.launch(&self.kernels[variant as usize].1, stream, &mut args);
    }

    fn launch(
        &self,
        f: &warp_cuda::Function,
        stream: &warp_cuda::Stream,
        args: &mut [*mut c_void],
    ) {
        let blocks = N.div_ceil(256) as u32;
        // SAFETY: `args` point at values laid out as the kernel's parameters; the arrays
        // outlive the launches (the bench synchronises before dropping them).
        unsafe {
            self.gpu
                .launch_raw(f, stream, blocks, 256, 0, args)
                .expect("launch")
        };
    }
}

fn ptr<T>(v: &mut T) -> *mut c_void {
    v as *mut T as *mut c_void
}
