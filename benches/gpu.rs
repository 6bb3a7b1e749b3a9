//! GPU benchmark: each workload as a warp-lang kernel and as hand-written CUDA C++ (compiled
//! with NVRTC and launched through `warp_cuda` directly), measured in the same run; prints the
//! times, the ratios and each workload's accuracy.
//!
//! ```text
//! cargo bench --bench gpu            # needs a CUDA device; prints SKIPPED otherwise
//! cargo bench --bench gpu -- --tile-gemm   # the tile GEMM section alone
//! cargo bench --bench gpu -- --tile-cholesky   # the batched tile Cholesky section alone
//! cargo bench --bench gpu -- --tile-fft   # the batched tile FFT section alone
//! cargo bench --bench gpu -- --tiles   # every tile section (GEMM, Cholesky, FFT, n-body)
//! cargo bench --bench gpu -- --tile-nbody   # the tiled n-body section alone
//! cargo bench --bench gpu -- --ad   # the reverse-mode section alone (plain and atomic backward)
//! ```
//!
//! Workloads (DESIGN.md, "Figures to beat"): the seed particle program (10M x 100 steps),
//! brute-force n-body (64K bodies, f32), host cost per launch of a small kernel with 6
//! arguments, the first launch in a fresh process with an empty and with a warm cache, and a
//! 4096^3 fp32 tile GEMM (issue 31: `examples/common/tile_gemm.rs`'s kernel against cuBLAS
//! SGEMM through PyTorch and Warp 1.19's tile GEMM, both run by `benches/py/tile_gemm.py` on
//! the same inputs in the same run; Warp's side needs `PYTHONPATH` pointing at Warp, e.g.
//! `PYTHONPATH=/root/warp-lang` after ../shared/tools/warp-bundle; a side that cannot run says
//! why on its row). The batched 32 x 32 Cholesky solve (issue 31: `examples/common/
//! tile_cholesky.rs`'s kernel, 65,536 systems) is timed against cuSOLVER's batched factor and
//! solve through PyTorch (`torch.linalg.cholesky`, `torch.cholesky_solve`) and Warp 1.19's
//! `tile_cholesky`/`tile_cholesky_solve`, by `benches/py/tile_cholesky.py` in the same way. The
//! batched 64-point complex FFT in f32 (`examples/common/tile_fft.rs`'s kernel, 1M signals) is
//! timed against cuFFT through CuPy (`cupy.fft.fft` along the last axis: a batched C2C plan)
//! and Warp 1.19's `tile_fft`, by `benches/py/tile_fft.py`. The all-pairs n-body step with
//! shared-memory tiles (`examples/common/tile_nbody.rs`, 64K bodies) is timed against the same
//! step as a scalar kernel, each with its accelerations' error against float64.

use rand::Rng as _;
use std::ffi::c_void;
use std::process::Command;
use std::sync::Arc;
use std::time::Instant;
use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn integrate(x: Array<Vec3>, v: Array<Vec3>, b: f32, mass: f32, gravity: Vec3, dt: f32) {
    let i = tid();
    let a = -b * v[i] / mass + gravity;
    v[i] += a * dt;
    x[i] += v[i] * dt;
}

#[wp::kernel]
fn nbody(pos: Array<Vec3>, mass: Array<f32>, acc: Array<Vec3>, eps2: f32, n: i32) {
    let i = tid();
    let pi = pos[i];
    let mut a = Vec3::ZERO;
    for j in 0..n {
        let d = pos[j] - pi;
        let r2 = d.dot(d) + eps2;
        let inv = 1.0 / sqrt(r2);
        a += d * (mass[j] * (inv * inv * inv));
    }
    acc[i] = a;
}

/// The AD section's kernels are the autodiff example's (one step per tape record, and the loss).
mod common;

#[path = "../examples/common/seed_ad.rs"]
mod seed_ad;

/// The tile GEMM section's kernels are the tile_matmul example's.
#[path = "../examples/common/tile_gemm.rs"]
mod tile_gemm;

/// The tile Cholesky section's kernel, systems and reference are the tile_cholesky example's.
#[path = "../examples/common/tile_cholesky.rs"]
mod tile_cholesky;

/// The tile FFT section's kernel, signals and reference are the tile_fft example's.
#[path = "../examples/common/tile_fft.rs"]
mod tile_fft;

/// The tiled n-body section's kernels, start state and reference are the tile_nbody example's.
#[path = "../examples/common/tile_nbody.rs"]
mod tile_nbody;

#[wp::kernel]
fn small(a: Array<f32>, b: Array<f32>, s: f32, t: f32, k: i32, c: Array<f32>) {
    let i = tid();
    c[i] = a[i] * s + b[i] * t + k as f32;
}

const HAND: &str = r#"
extern "C" __global__ void hand_integrate(float* x, float* v, float b, float mass, float gx, float gy, float gz,
                                          float dt, long long n) {
    long long i = blockIdx.x * (long long)blockDim.x + threadIdx.x;
    if (i >= n) return;
    float* xi = x + 3 * i;
    float* vi = v + 3 * i;
    float vx = vi[0], vy = vi[1], vz = vi[2];
    float ax = -b * vx / mass + gx, ay = -b * vy / mass + gy, az = -b * vz / mass + gz;
    vx += ax * dt; vy += ay * dt; vz += az * dt;
    vi[0] = vx; vi[1] = vy; vi[2] = vz;
    xi[0] += vx * dt; xi[1] += vy * dt; xi[2] += vz * dt;
}
extern "C" __global__ void hand_nbody(const float* pos, const float* mass, float* acc, float eps2, int n) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    float px = pos[3 * i], py = pos[3 * i + 1], pz = pos[3 * i + 2];
    float ax = 0.0f, ay = 0.0f, az = 0.0f;
    for (int j = 0; j < n; ++j) {
        float dx = pos[3 * j] - px, dy = pos[3 * j + 1] - py, dz = pos[3 * j + 2] - pz;
        float r2 = dx * dx + dy * dy + dz * dz + eps2;
        float inv = 1.0f / sqrtf(r2);
        float s = mass[j] * (inv * inv * inv);
        ax += dx * s; ay += dy * s; az += dz * s;
    }
    acc[3 * i] = ax; acc[3 * i + 1] = ay; acc[3 * i + 2] = az;
}
extern "C" __global__ void hand_small(const float* a, const float* b, float s, float t, int k, float* c, long long n) {
    long long i = blockIdx.x * (long long)blockDim.x + threadIdx.x;
    if (i >= n) return;
    c[i] = a[i] * s + b[i] * t + (float)k;
}
"#;

struct Hand {
    gpu: Arc<warp_cuda::Gpu>,
    _module: warp_cuda::Module,
    f_integrate: warp_cuda::Function,
    f_nbody: warp_cuda::Function,
    f_small: warp_cuda::Function,
}

impl Hand {
    fn new() -> Hand {
        let gpu = warp_cuda::Gpu::open(0).expect("gpu");
        let compiled =
            warp_cuda::compile(HAND, "hand", &Default::default(), gpu.arch()).expect("nvrtc");
        let module = gpu.load_module(&compiled.cubin).expect("load");
        let f = |n: &str| module.function(n).expect("function");
        let (f_integrate, f_nbody, f_small) =
            (f("hand_integrate"), f("hand_nbody"), f("hand_small"));
        Hand {
            gpu,
            _module: module,
            f_integrate,
            f_nbody,
            f_small,
        }
    }

    /// Launches `f` over `n` threads, 256 per block, with pointers to each argument.
    fn launch(&self, f: &warp_cuda::Function, n: usize, args: &mut [*mut c_void]) {
        let blocks = n.div_ceil(256) as u32;
        // SAFETY: `args` point at values laid out as the kernel's parameters.
        unsafe {
            self.gpu
                .launch_raw(f, self.gpu.default_stream(), blocks, 256, 0, args)
                .expect("launch")
        };
    }
}

fn ptr<T>(v: &mut T) -> *mut c_void {
    v as *mut T as *mut c_void
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn particles(dev: &wp::Device, hand: &Hand) {
    let (n, steps) = (10_000_000usize, 100);
    let (b, mass, g) = (0.05f32, 0.1f32, 9.81f32);
    let dt = 0.01 * (2.0 * mass / b);
    let gravity = Vec3::new(0.0, 0.0, -g);
    let mut seed = common::rng(12345u64);
    let x0: Vec<Vec3> = (0..n)
        .map(|_| {
            Vec3::new(
                seed.random::<f32>(),
                seed.random::<f32>(),
                seed.random::<f32>(),
            ) * 2.0
                - 1.0
        })
        .collect();
    let v0: Vec<Vec3> = (0..n)
        .map(|_| {
            Vec3::new(
                seed.random::<f32>(),
                seed.random::<f32>(),
                seed.random::<f32>(),
            ) - 0.5
        })
        .collect();

    let x = wp::Array::from_slice(&x0, dev).unwrap();
    let v = wp::Array::from_slice(&v0, dev).unwrap();
    wp::launch(integrate, n, (&x, &v, b, mass, gravity, dt), dev).unwrap(); // compile + warm up
    x.copy_from(&wp::Array::from_slice(&x0, dev).unwrap())
        .unwrap();
    v.copy_from(&wp::Array::from_slice(&v0, dev).unwrap())
        .unwrap();
    wp::synchronize().unwrap();
    let t = Instant::now();
    for _ in 0..steps {
        wp::launch(integrate, n, (&x, &v, b, mass, gravity, dt), dev).unwrap();
    }
    wp::synchronize().unwrap();
    let t_wp = ms(t);
    let xs = x.to_vec().unwrap();

    let hx = warp_cuda::DeviceBuffer::from_bytes(&hand.gpu, bytemuck::cast_slice(&x0)).unwrap();
    let hv = warp_cuda::DeviceBuffer::from_bytes(&hand.gpu, bytemuck::cast_slice(&v0)).unwrap();
    let (mut px, mut pv) = (hx.device_ptr(), hv.device_ptr());
    let (mut b_, mut m_, mut gx, mut gy, mut gz, mut dt_, mut n_) =
        (b, mass, 0.0f32, 0.0f32, -g, dt, n as i64);
    let mut run = |h: &Hand| {
        let mut args = [
            ptr(&mut px),
            ptr(&mut pv),
            ptr(&mut b_),
            ptr(&mut m_),
            ptr(&mut gx),
            ptr(&mut gy),
            ptr(&mut gz),
            ptr(&mut dt_),
            ptr(&mut n_),
        ];
        h.launch(&h.f_integrate, n, &mut args);
    };
    run(hand); // warm up
    hx.upload(0, bytemuck::cast_slice(&x0)).unwrap();
    hv.upload(0, bytemuck::cast_slice(&v0)).unwrap();
    hand.gpu.synchronize().unwrap();
    let t = Instant::now();
    for _ in 0..steps {
        run(hand);
    }
    hand.gpu.synchronize().unwrap();
    let t_hand = ms(t);
    let mut hx_host = vec![Vec3::ZERO; n];
    hx.download(0, bytemuck::cast_slice_mut(&mut hx_host))
        .unwrap();

    // Accuracy against the exact solution of the scheme's recurrence, in f64.
    let (k, r) = ((b / mass) as f64, 1.0 - (b / mass) as f64 * dt as f64);
    let geometric = r * (1.0 - r.powi(steps)) / (1.0 - r);
    let mut err = 0.0f64;
    let mut diff = 0.0f32;
    for i in 0..n {
        for c in 0..3 {
            let vinf = gravity[c] as f64 / k;
            let exact = x0[i][c] as f64
                + dt as f64 * (steps as f64 * vinf + (v0[i][c] as f64 - vinf) * geometric);
            err = err.max((xs[i][c] as f64 - exact).abs());
            diff = diff.max((xs[i][c] - hx_host[i][c]).abs());
        }
    }
    println!(
        "particles 10M x 100   warp {t_wp:8.2} ms   hand {t_hand:8.2} ms   ratio {:.3} (target <= 1.1)   \
         max err vs exact recurrence {err:.2e} m, max |warp - hand| {diff:.2e} m",
        t_wp / t_hand
    );
}

fn nbody_bench(dev: &wp::Device, hand: &Hand) {
    let n = 65_536usize;
    let eps2 = 1e-4f32;
    let mut seed = common::rng(7u64);
    let p: Vec<Vec3> = (0..n)
        .map(|_| {
            Vec3::new(
                seed.random::<f32>(),
                seed.random::<f32>(),
                seed.random::<f32>(),
            ) * 2.0
                - 1.0
        })
        .collect();
    let m: Vec<f32> = (0..n).map(|_| 0.5 + seed.random::<f32>()).collect();
    let (pos, mass, acc) = (
        wp::Array::from_slice(&p, dev).unwrap(),
        wp::Array::from_slice(&m, dev).unwrap(),
        wp::Array::<Vec3>::zeros(n, dev).unwrap(),
    );
    wp::launch(nbody, n, (&pos, &mass, &acc, eps2, n as i32), dev).unwrap();
    wp::synchronize().unwrap();
    let reps = 5;
    let t = Instant::now();
    for _ in 0..reps {
        wp::launch(nbody, n, (&pos, &mass, &acc, eps2, n as i32), dev).unwrap();
    }
    wp::synchronize().unwrap();
    let t_wp = ms(t) / reps as f64;
    let a_wp = acc.to_vec().unwrap();

    let hp = warp_cuda::DeviceBuffer::from_bytes(&hand.gpu, bytemuck::cast_slice(&p)).unwrap();
    let hm = warp_cuda::DeviceBuffer::from_bytes(&hand.gpu, bytemuck::cast_slice(&m)).unwrap();
    let ha = warp_cuda::DeviceBuffer::zeros(&hand.gpu, n * 12).unwrap();
    let (mut pp, mut pm, mut pa, mut e, mut nn) = (
        hp.device_ptr(),
        hm.device_ptr(),
        ha.device_ptr(),
        eps2,
        n as i32,
    );
    let mut run = || {
        let mut args = [
            ptr(&mut pp),
            ptr(&mut pm),
            ptr(&mut pa),
            ptr(&mut e),
            ptr(&mut nn),
        ];
        hand.launch(&hand.f_nbody, n, &mut args);
    };
    run();
    hand.gpu.synchronize().unwrap();
    let t = Instant::now();
    for _ in 0..reps {
        run();
    }
    hand.gpu.synchronize().unwrap();
    let t_hand = ms(t) / reps as f64;
    let mut a_hand = vec![Vec3::ZERO; n];
    ha.download(0, bytemuck::cast_slice_mut(&mut a_hand))
        .unwrap();

    // Accuracy: a sample of bodies against an f64 sum.
    let mut rel = 0.0f64;
    for i in (0..n).step_by(4099) {
        let pi = p[i].as_dvec3();
        let mut a = glam::DVec3::ZERO;
        for j in 0..n {
            let d = p[j].as_dvec3() - pi;
            let r2 = d.dot(d) + eps2 as f64;
            a += d * (m[j] as f64 / (r2 * r2.sqrt()));
        }
        rel = rel.max((a_wp[i].as_dvec3() - a).length() / a.length());
    }
    println!(
        "n-body 64K (f32)      warp {t_wp:8.2} ms   hand {t_hand:8.2} ms   ratio {:.3} (target <= 1.05)  \
         max rel err vs f64 (16 bodies) {rel:.2e}",
        t_wp / t_hand
    );
}

fn launch_cost(dev: &wp::Device, hand: &Hand) {
    let n = 1usize;
    let (a, b, c) = (
        wp::Array::<f32>::full(n, 1.0, dev).unwrap(),
        wp::Array::<f32>::full(n, 2.0, dev).unwrap(),
        wp::Array::<f32>::zeros(n, dev).unwrap(),
    );
    wp::launch(small, n, (&a, &b, 0.5, 0.25, 3, &c), dev).unwrap();
    wp::synchronize().unwrap();
    let reps = 2000;
    let mut host = 0.0;
    for _ in 0..reps {
        let t = Instant::now();
        wp::launch(small, n, (&a, &b, 0.5, 0.25, 3, &c), dev).unwrap();
        host += t.elapsed().as_secs_f64();
    }
    wp::synchronize().unwrap();
    let got = c.to_vec().unwrap()[0];
    let us_wp = host / reps as f64 * 1e6;

    let ha =
        warp_cuda::DeviceBuffer::from_bytes(&hand.gpu, bytemuck::cast_slice(&[1.0f32])).unwrap();
    let hb =
        warp_cuda::DeviceBuffer::from_bytes(&hand.gpu, bytemuck::cast_slice(&[2.0f32])).unwrap();
    let hc = warp_cuda::DeviceBuffer::zeros(&hand.gpu, 4).unwrap();
    let (mut pa, mut pb, mut s, mut t_, mut k, mut pc, mut nn) = (
        ha.device_ptr(),
        hb.device_ptr(),
        0.5f32,
        0.25f32,
        3i32,
        hc.device_ptr(),
        1i64,
    );
    let mut host = 0.0;
    for _ in 0..reps {
        let t = Instant::now();
        let mut args = [
            ptr(&mut pa),
            ptr(&mut pb),
            ptr(&mut s),
            ptr(&mut t_),
            ptr(&mut k),
            ptr(&mut pc),
            ptr(&mut nn),
        ];
        hand.launch(&hand.f_small, n, &mut args);
        host += t.elapsed().as_secs_f64();
    }
    hand.gpu.synchronize().unwrap();
    let us_hand = host / reps as f64 * 1e6;
    println!(
        "host cost per launch  warp {us_wp:8.2} us   raw  {us_hand:8.2} us   ratio {:.2} (target <= 4 us)   \
         result {got} (want 4.0)",
        us_wp / us_hand
    );
}

/// Times the first launch of `integrate` in this process (the child mode of `first_launch`).
fn first_launch_child() {
    let dev = wp::get_device("cuda:0").unwrap();
    let x = wp::Array::<Vec3>::zeros(1024, &dev).unwrap();
    let v = wp::Array::<Vec3>::zeros(1024, &dev).unwrap();
    let t = Instant::now();
    wp::launch(
        integrate,
        1024,
        (&x, &v, 0.05, 0.1, Vec3::new(0.0, 0.0, -9.81), 0.04),
        &dev,
    )
    .unwrap();
    wp::synchronize().unwrap();
    let total = ms(t);
    let r = wp::compile_reports();
    let r = r.iter().find(|r| r.kernel == "integrate").expect("report");
    println!(
        "{total:.2} {:.2} {} {}",
        r.compile_ms, r.source_bytes, r.cache_hit
    );
}

fn first_launch() {
    let dir = std::env::temp_dir().join(format!("warp-lang-bench-cache-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let me = std::env::current_exe().unwrap();
    let run_mode = |mode: &str| {
        let out = Command::new(&me)
            .arg(mode)
            .env("WARP_LANG_CACHE_DIR", &dir)
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    };
    let run = || run_mode("--first-launch-child");
    let (cold, warm) = (run(), run());
    let parts = run_mode("--first-launch-parts");
    let parts: Vec<&str> = parts.split_whitespace().collect();
    let cold: Vec<&str> = cold.split_whitespace().collect();
    let warm: Vec<&str> = warm.split_whitespace().collect();
    println!(
        "first launch          cold {} ms (NVRTC {} ms, {} bytes of source, cache hit {})   warm {} ms (cache hit {})   \
         targets: cold <= 150 ms, warm <= 10 ms",
        cold[0], cold[1], cold[2], cold[3], warm[0], warm[3]
    );
    println!(
        "  warm first launch, in parts (another fresh process): opening the GPU and two arrays {} ms \
         (before the timed launch), loading NVRTC {} ms (what the cache stamp lets a warm hit skip), launch {} ms",
        parts[0], parts[1], parts[2]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Times the steps of a warm first launch in a fresh process (the child mode
/// `--first-launch-parts`): opening the GPU, loading NVRTC (to key the cache), and the launch.
fn first_launch_parts_child() {
    let t = Instant::now();
    let dev = wp::get_device("cuda:0").unwrap();
    let x = wp::Array::<Vec3>::zeros(1024, &dev).unwrap();
    let v = wp::Array::<Vec3>::zeros(1024, &dev).unwrap();
    let open = ms(t);
    let t = Instant::now();
    let _ = warp_cuda::nvrtc_version();
    let nvrtc = ms(t);
    let t = Instant::now();
    wp::launch(
        integrate,
        1024,
        (&x, &v, 0.05, 0.1, Vec3::new(0.0, 0.0, -9.81), 0.04),
        &dev,
    )
    .unwrap();
    wp::synchronize().unwrap();
    println!("{open:.2} {nvrtc:.2} {:.2}", ms(t));
}

/// Reverse mode through 1M particles x 100 recorded steps, loss = sum |x_T|^2: forward then
/// backward times, and the gradients against their closed forms.
fn ad_bench(dev: &wp::Device) {
    let (n, steps) = (1_000_000usize, 100usize);
    let (b, mass, dt) = (0.05f32, 0.1f32, 0.01f32);
    let gravity = Vec3::new(0.0, 0.0, -9.81);
    let mut seed = common::rng(11u64);
    let x0: Vec<Vec3> = (0..n)
        .map(|_| {
            Vec3::new(
                seed.random::<f32>(),
                seed.random::<f32>(),
                seed.random::<f32>(),
            )
        })
        .collect();
    let v0: Vec<Vec3> = (0..n)
        .map(|_| Vec3::new(seed.random::<f32>(), seed.random::<f32>(), 0.0))
        .collect();
    let grad_array = |data: Option<&[Vec3]>| {
        match data {
            Some(d) => wp::Array::from_slice(d, dev),
            None => wp::Array::<Vec3>::zeros(n, dev),
        }
        .and_then(|a| a.with_grad())
        .unwrap()
    };
    let mut xs = vec![grad_array(Some(&x0))];
    let mut vs = vec![grad_array(Some(&v0))];
    for _ in 0..steps {
        xs.push(grad_array(None));
        vs.push(grad_array(None));
    }
    let loss = wp::Array::<f32>::zeros(1, dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let record = |tape: &wp::Tape, steps: usize| {
        let _rec = tape.record();
        for s in 0..steps {
            let args = (&xs[s], &vs[s], &xs[s + 1], &vs[s + 1], b, mass, gravity, dt);
            wp::launch(seed_ad::step, n, args, dev).unwrap();
        }
        wp::launch(seed_ad::sum_sq, n, (&xs[steps], &loss), dev).unwrap();
    };
    // Warm-up: compiles the kernels and their adjoints.
    let warm = wp::Tape::new();
    record(&warm, 1);
    warm.backward(&loss).unwrap();
    warm.zero().unwrap();
    loss.fill(0.0).unwrap();
    wp::synchronize().unwrap();

    let tape = wp::Tape::new();
    let t = Instant::now();
    record(&tape, steps);
    wp::synchronize().unwrap();
    let fwd = ms(t);
    // The same backward pass on a stream of its own, where another launch may run beside it,
    // so the gradients of thread-owned elements are added atomically: the baseline of the
    // plain adds a backward pass on the default stream makes (it runs alone). One untimed
    // pass first, so that neither timed one pays a first use.
    tape.backward(&loss).unwrap();
    tape.zero().unwrap();
    wp::synchronize().unwrap();
    let stream = wp::Stream::new(dev).unwrap();
    let t = Instant::now();
    {
        let _on = wp::ScopedStream::new(&stream).unwrap();
        tape.backward(&loss).unwrap();
    }
    wp::synchronize().unwrap();
    let bwd_atomic = ms(t);
    let g_atomic = (
        xs[0].grad().unwrap().to_vec().unwrap(),
        vs[0].grad().unwrap().to_vec().unwrap(),
    );
    tape.zero().unwrap();
    wp::synchronize().unwrap();
    let t = Instant::now();
    tape.backward(&loss).unwrap();
    wp::synchronize().unwrap();
    let bwd = ms(t);
    let r = 1.0 - (b * dt / mass) as f64;
    let c: f64 = dt as f64 * (1..=steps).map(|k| r.powi(k as i32)).sum::<f64>();
    let x_t = xs[steps].to_vec().unwrap();
    let gx = xs[0].grad().unwrap().to_vec().unwrap();
    let gv = vs[0].grad().unwrap().to_vec().unwrap();
    // Each element's gradient is added by one thread per step either way: the same bits.
    let same = g_atomic.0 == gx && g_atomic.1 == gv;
    let rel = |g: Vec3, want: glam::DVec3| {
        (g.as_dvec3() - want).abs().max_element() / want.abs().max_element().max(1.0)
    };
    let (mut ex, mut ev) = (0.0f64, 0.0f64);
    for k in 0..n {
        let xt = x_t[k].as_dvec3();
        ex = ex.max(rel(gx[k], 2.0 * xt));
        ev = ev.max(rel(gv[k], 2.0 * c * xt));
    }
    println!(
        "AD 1M x 100 steps     forward {fwd:6.2} ms   backward {bwd:6.2} ms   ratio {:.2} (target <= 2)   \
         total {:.2} ms (target <= Warp 3.3 + 5.2 = 8.5 ms)   max rel err dL/dx0 {ex:.1e}, dL/dv0 {ev:.1e}\n\
         AD backward on a user stream (atomic adds of owned gradients) {bwd_atomic:6.2} ms   \
         plain / atomic {:.2}   same gradients: {same}",
        bwd / fwd,
        fwd + bwd,
        bwd / bwd_atomic
    );
    assert!(
        same,
        "the backward pass's gradients differ between the plain and atomic adds"
    );
}

/// The tile GEMM section's cold compile (the child mode `--tile-compile-child [f16]`, run with
/// an empty kernel cache): the first launch of the f32 (or, with `f16`, the fp16) tile GEMM
/// kernel in a fresh process, and its NVRTC time.
fn tile_compile_child() {
    let f16 = std::env::args().any(|a| a == "f16");
    let run = || -> wp::Result<String> {
        let dev = wp::get_device("cuda:0")?;
        let t;
        let name = if f16 {
            let h = || wp::Array::<wp::f16, 2>::zeros((128, 128), &dev);
            let (a, b) = (h()?, h()?);
            let c = wp::Array::<f32, 2>::zeros((128, 128), &dev)?;
            t = Instant::now();
            wp::launch_tiled(
                tile_gemm::gemm_tiled_f16,
                (1, 1),
                (&a, &b, &c),
                TILE_BLOCK_DIM,
                &dev,
            )?;
            "gemm_tiled_f16"
        } else {
            let zeros = || wp::Array::<f32, 2>::zeros((64, 64), &dev);
            let (a, b, c) = (zeros()?, zeros()?, zeros()?);
            t = Instant::now();
            wp::launch_tiled(
                tile_gemm::gemm_tiled_f32,
                (1, 1),
                (&a, &b, &c),
                TILE_BLOCK_DIM,
                &dev,
            )?;
            "gemm_tiled_f32"
        };
        wp::synchronize()?;
        let total = ms(t);
        let reports = wp::compile_reports();
        let r = reports.iter().find(|r| r.kernel == name);
        Ok(match r {
            Some(r) => format!("{total:.2} {:.2} {}", r.compile_ms, r.cache_hit),
            None => format!("error: no compile report for {name}"),
        })
    };
    // One line for the parent: the three numbers, or the error (never a panic's backtrace).
    match run() {
        Ok(line) => println!("{line}"),
        Err(e) => println!("error: {e}"),
    }
}

/// The cold compile of a tile GEMM kernel (`--tile-compile-child`, with `f16` for the fp16
/// one), in a fresh process with an empty cache: one line of the section. `warp_first`: Warp's
/// first launch with an empty cache, from the Python side.
fn cold_compile_row(what: &str, f16: bool, warp_first: Option<f64>) {
    let cache = std::env::temp_dir().join(format!("warp-lang-tile-cache-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&cache);
    let mut cmd = Command::new(std::env::current_exe().unwrap());
    cmd.arg("--tile-compile-child");
    if f16 {
        cmd.arg("f16");
    }
    let out = cmd.env("WARP_LANG_CACHE_DIR", &cache).output().unwrap();
    let _ = std::fs::remove_dir_all(&cache);
    let cold = String::from_utf8_lossy(&out.stdout).trim().to_string();
    match cold.split_whitespace().collect::<Vec<_>>().as_slice() {
        [total, nvrtc, hit] if !cold.starts_with("error") => println!(
            "  cold compile of the {what} kernel: first launch {total} ms (NVRTC {nvrtc} ms, cache \
             hit {hit}), target < 5000 ms{}",
            warp_first
                .map(|w| format!("; Warp's first launch with an empty cache: {w:.0} ms"))
                .unwrap_or_default()
        ),
        _ => println!(
            "  cold compile of the {what} kernel: not measured: {}",
            if cold.is_empty() {
                String::from_utf8_lossy(&out.stderr).trim().to_string()
            } else {
                cold
            }
        ),
    }
}

/// Threads per block of the tile GEMM (ours and Warp's).
const TILE_BLOCK_DIM: usize = 256;

/// max over `entries` of |c - c64| / sum_p |a_ip b_pj|, c64 the float64 product: the error of
/// each dot product relative to its magnitude (a k-term f32 FMA chain stays below k 2^-24;
/// plain relative error is unbounded where an entry cancels to about zero).
fn gemm_error(
    c: &[f32],
    a: &[f32],
    b: &[f32],
    (n, k): (usize, usize),
    entries: &[(usize, usize)],
) -> f64 {
    let mut worst = 0.0f64;
    for &(i, j) in entries {
        let (mut exact, mut mag) = (0.0f64, 0.0f64);
        for p in 0..k {
            let t = a[i * k + p] as f64 * b[p * n + j] as f64;
            exact += t;
            mag += t.abs();
        }
        let err = (c[i * n + j] as f64 - exact).abs();
        worst = worst.max(if mag > 0.0 { err / mag } else { err });
    }
    worst
}

/// 4096^3 fp32 GEMM: our tile kernel (and the plain one-thread-per-output kernel) against
/// cuBLAS SGEMM (PyTorch, TF32 off) and Warp 1.19's tile GEMM with the same tiles, all on the
/// same inputs; TFLOP/s, time ratios, the error on 4096 sampled entries against float64, and
/// the tile kernel's cold compile.
fn tile_gemm_bench(dev: &wp::Device, size: usize) {
    use tile_gemm::{BK, BK16, BM, BM16, BN, BN16};
    let (m, n, k) = (size, size, size);
    let mut r = common::rng(31u64);
    let ah: Vec<f32> = (0..m * k).map(|_| r.random::<f32>() * 2.0 - 1.0).collect();
    let bh: Vec<f32> = (0..k * n).map(|_| r.random::<f32>() * 2.0 - 1.0).collect();
    let entries: Vec<(usize, usize)> = (0..4096)
        .map(|_| (r.random_range(0..m), r.random_range(0..n)))
        .collect();
    let tflops = |ms: f64| 2.0 * (m * n * k) as f64 / (ms * 1e-3) / 1e12;
    let bound = k as f64 * f32::EPSILON as f64 / 2.0;
    println!(
        "\ntile GEMM {m} x {k} x {n} fp32 (tiles {BM} x {BN}, k-step {BK}, {TILE_BLOCK_DIM} threads a block; \
         A, B uniform in [-1, 1); err = max |c - c64| / sum |a||b| over {} sampled entries, the \
         bound of an f32 FMA chain k u = {bound:.1e}); times: median of {} after a warm-up",
        entries.len(),
        common::REPS
    );

    // The other sides first (their process frees its GPU memory when it ends), on our inputs.
    let dir = std::env::temp_dir().join(format!("warp-lang-tile-gemm-{}", std::process::id()));
    let written = std::fs::create_dir_all(&dir).and_then(|()| {
        std::fs::write(dir.join("a.f32"), bytemuck::cast_slice(&ah))?;
        std::fs::write(dir.join("b.f32"), bytemuck::cast_slice(&bh))?;
        let idx: Vec<i64> = entries
            .iter()
            .map(|e| e.0 as i64)
            .chain(entries.iter().map(|e| e.1 as i64))
            .collect();
        std::fs::write(dir.join("idx.i64"), bytemuck::cast_slice(&idx))
    });
    let theirs = match written {
        Ok(()) => {
            let args =
                [m, n, k, BM, BN, BK, TILE_BLOCK_DIM, BM16, BN16, BK16].map(|x| x.to_string());
            let mut all = vec![dir.display().to_string()];
            all.extend(args);
            common::python_side("benches/py/tile_gemm.py", &all)
        }
        Err(e) => Err(format!("writing the inputs to {}: {e}", dir.display())),
    };
    let _ = std::fs::remove_dir_all(&dir);
    let side = |key: &str| {
        theirs
            .as_ref()
            .ok()
            .and_then(|t| common::json_number(t, key))
    };
    let why = |key: &str| match &theirs {
        Ok(t) => t
            .get(key)
            .and_then(|v| v.as_str())
            .unwrap_or("no result")
            .to_string(),
        Err(e) => e.clone(),
    };

    let a = wp::Array::from_slice_shape(&ah, (m, k), dev).unwrap();
    let b = wp::Array::from_slice_shape(&bh, (k, n), dev).unwrap();
    let c = wp::Array::<f32, 2>::zeros((m, n), dev).unwrap();
    let blocks = (m.div_ceil(BM), n.div_ceil(BN));
    let t_tile = common::median_ms(|| {
        wp::launch_tiled(
            tile_gemm::gemm_tiled_f32,
            blocks,
            (&a, &b, &c),
            TILE_BLOCK_DIM,
            dev,
        )
    });
    let err_tile = gemm_error(&c.to_vec().unwrap(), &ah, &bh, (n, k), &entries);
    c.fill(0.0).unwrap();
    let t_plain =
        common::median_ms(|| wp::launch(tile_gemm::gemm_plain, (m, n), (&a, &b, &c), dev));
    let err_plain = gemm_error(&c.to_vec().unwrap(), &ah, &bh, (n, k), &entries);

    let row = |what: &str, t: f64, err: f64| {
        println!(
            "  {what:<37} {t:9.3} ms {:7.2} TFLOP/s   err {err:.2e}",
            tflops(t)
        );
    };
    // A launch that fails (a kernel the GPU cannot hold, say) is a row saying so, not a panic
    // that would lose the other rows.
    let (t_tile, t_plain) = match (t_tile, t_plain) {
        (Ok(t), Ok(p)) => {
            row("warp-lang tile_matmul", t, err_tile);
            row("warp-lang plain (thread per output)", p, err_plain);
            (t, p)
        }
        (t, p) => {
            println!("  warp-lang tile_matmul: {t:?}\n  warp-lang plain: {p:?}");
            return;
        }
    };
    let mut ratios = vec![format!("ours / plain {:.2}", t_tile / t_plain)];
    for (what, key, name) in [
        ("Warp 1.19 tile_matmul (same tiles)", "warp", "Warp"),
        ("cuBLAS SGEMM (torch.matmul, no TF32)", "torch", "cuBLAS"),
    ] {
        match (side(&format!("{key}_ms")), side(&format!("{key}_err"))) {
            (Some(t), Some(err)) => {
                row(what, t, err);
                ratios.push(format!("ours / {name} {:.2}", t_tile / t));
            }
            _ => println!("  {what:<37} not run: {}", why(&format!("{key}_error"))),
        }
    }
    println!(
        "  time ratios (above 1: ours is slower): {}",
        ratios.join(", ")
    );

    // The cold compile, in a fresh process with an empty cache.
    cold_compile_row("f32 tile", false, side("warp_first_ms"));

    // fp16: the same inputs rounded to f16 (numpy's astype(float16) on the Python side rounds
    // the same way, to nearest even), f32 accumulation; errors against the float64 product of
    // the f16 values.
    let ah16: Vec<wp::f16> = ah.iter().map(|&x| wp::f16::from_f32(x)).collect();
    let bh16: Vec<wp::f16> = bh.iter().map(|&x| wp::f16::from_f32(x)).collect();
    let (aw, bw): (Vec<f32>, Vec<f32>) = (
        ah16.iter().map(|x| x.to_f32()).collect(),
        bh16.iter().map(|x| x.to_f32()).collect(),
    );
    println!(
        "\ntile GEMM {m} x {k} x {n} fp16 inputs, f32 accumulate (tiles {BM16} x {BN16}, k-step \
         {BK16}, {TILE_BLOCK_DIM} threads a block; tensor cores on sm_80+, the k-loop pipelined: \
         wgmma on sm_90, mma.sync m16n8k16 elsewhere; \
         err against the float64 product of the f16 inputs)"
    );
    drop((a, b));
    let a16 = wp::Array::from_slice_shape(&ah16, (m, k), dev).unwrap();
    let b16 = wp::Array::from_slice_shape(&bh16, (k, n), dev).unwrap();
    c.fill(0.0).unwrap();
    let blocks16 = (m.div_ceil(BM16), n.div_ceil(BN16));
    let t16 = common::median_ms(|| {
        wp::launch_tiled(
            tile_gemm::gemm_tiled_f16,
            blocks16,
            (&a16, &b16, &c),
            TILE_BLOCK_DIM,
            dev,
        )
    });
    match t16 {
        Ok(t16) => {
            let err16 = gemm_error(&c.to_vec().unwrap(), &aw, &bw, (n, k), &entries);
            row("warp-lang tile_matmul fp16", t16, err16);
            let mut ratios = Vec::new();
            for (what, key, name) in [
                ("Warp 1.19 tile_matmul fp16 (same tiles)", "warp16", "Warp"),
                ("cuBLAS fp16 (torch.matmul on half)", "torch16", "cuBLAS"),
            ] {
                match (side(&format!("{key}_ms")), side(&format!("{key}_err"))) {
                    (Some(t), Some(err)) => {
                        row(what, t, err);
                        ratios.push(format!(
                            "ours / {name} {:.2} ({:.0}% of its TFLOP/s)",
                            t16 / t,
                            100.0 * t / t16
                        ));
                    }
                    _ => println!("  {what:<37} not run: {}", why(&format!("{key}_error"))),
                }
            }
            if !ratios.is_empty() {
                println!(
                    "  time ratios (above 1: ours is slower): {}",
                    ratios.join(", ")
                );
            }
        }
        Err(e) => println!("  warp-lang tile_matmul fp16: {e:?}"),
    }
    cold_compile_row("fp16 tile", true, side("warp16_first_ms"));
}

/// Threads per block of the batched Cholesky (ours and Warp's).
const CHOL_BLOCK_DIM: usize = 64;

/// Batched 32 x 32 SPD solves in f32, one system per block (factor and solve in one kernel):
/// ours against cuSOLVER's batched potrf + potrs (PyTorch) and Warp 1.19's tile Cholesky, all
/// on the same systems; time per batch, ratios, and on 1024 sampled systems the forward error
/// |x - x64| / |x64| and the backward error |A x - y| / (|A| |x| + |y|) against float64.
fn tile_cholesky_bench(dev: &wp::Device, batch: usize) {
    use tile_cholesky::N;
    let (a64, y64) = tile_cholesky::systems(batch, 31);
    let ah: Vec<f32> = a64.iter().map(|&v| v as f32).collect();
    let yh: Vec<f32> = y64.iter().map(|&v| v as f32).collect();
    // The reference solves the rounded inputs every side is handed.
    let (a64, y64): (Vec<f64>, Vec<f64>) = (
        ah.iter().map(|&v| v as f64).collect(),
        yh.iter().map(|&v| v as f64).collect(),
    );
    let checked = tile_cholesky::checked_systems(batch, 1024);
    println!(
        "\ntile Cholesky: {batch} SPD systems of {N} x {N} in f32 (B Bt + I, B uniform in [-1, 1)), \
         factor + solve, {CHOL_BLOCK_DIM} threads a block; errors on {} sampled systems against \
         float64: forward |x - x64| / |x64|, backward |Ax - y| / (|A||x| + |y|) (4 N eps = {:.1e}); \
         times: median of {} after a warm-up",
        checked.len(),
        4.0 * N as f64 * f32::EPSILON as f64,
        common::REPS
    );
    let dir = std::env::temp_dir().join(format!("warp-lang-tile-chol-{}", std::process::id()));
    let written = std::fs::create_dir_all(&dir).and_then(|()| {
        std::fs::write(dir.join("a.f32"), bytemuck::cast_slice(&ah))?;
        std::fs::write(dir.join("y.f32"), bytemuck::cast_slice(&yh))?;
        let idx: Vec<i64> = checked.iter().map(|&s| s as i64).collect();
        std::fs::write(dir.join("idx.i64"), bytemuck::cast_slice(&idx))
    });
    let theirs = match written {
        Ok(()) => common::python_side(
            "benches/py/tile_cholesky.py",
            &[
                dir.display().to_string(),
                batch.to_string(),
                N.to_string(),
                CHOL_BLOCK_DIM.to_string(),
            ],
        ),
        Err(e) => Err(format!("writing the inputs to {}: {e}", dir.display())),
    };
    let _ = std::fs::remove_dir_all(&dir);
    let side = |key: &str| {
        theirs
            .as_ref()
            .ok()
            .and_then(|t| common::json_number(t, key))
    };
    let why = |key: &str| match &theirs {
        Ok(t) => t
            .get(key)
            .and_then(|v| v.as_str())
            .unwrap_or("no result")
            .to_string(),
        Err(e) => e.clone(),
    };
    let row = |what: &str, t: f64, fwd: f64, bwd: f64| {
        println!(
            "  {what:<44} {t:9.3} ms {:9.2} M systems/s   forward {fwd:.2e}   backward {bwd:.2e}",
            batch as f64 / (t * 1e-3) / 1e6
        );
    };

    let a = wp::Array::from_slice_shape(&ah, (batch * N, N), dev).unwrap();
    let y = wp::Array::from_slice(&yh, dev).unwrap();
    let x = wp::Array::<f32>::zeros(batch * N, dev).unwrap();
    // Ours at Warp's block size and at one warp (a 32 x 32 system is factored by one warp:
    // a block of 32 threads idles none); the ratios take the faster.
    let (mut t_ours, mut first_ms) = (f64::INFINITY, 0.0);
    for bd in [CHOL_BLOCK_DIM, 32] {
        let launch =
            || wp::launch_tiled(tile_cholesky::chol_solve_f32, batch, (&a, &y, &x), bd, dev);
        let t0 = Instant::now();
        let first = launch().and_then(|()| wp::synchronize());
        if bd == CHOL_BLOCK_DIM {
            first_ms = t0.elapsed().as_secs_f64() * 1e3;
        }
        let t = match first.and_then(|()| common::median_ms(launch)) {
            Ok(t) => t,
            Err(e) => {
                println!("  warp-lang tile_cholesky, block of {bd}: {e}");
                return;
            }
        };
        let xs: Vec<f64> = x.to_vec().unwrap().iter().map(|&v| v as f64).collect();
        row(
            &format!("warp-lang tile_cholesky + solve, block {bd}"),
            t,
            tile_cholesky::max_error(&a64, &y64, &xs, &checked),
            tile_cholesky::max_backward_error(&a64, &y64, &xs, &checked),
        );
        t_ours = t_ours.min(t);
    }
    let mut ratios = Vec::new();
    for (what, key, name) in [
        (
            "Warp 1.19 tile_cholesky + tile_cholesky_solve",
            "warp",
            "Warp",
        ),
        (
            "cuSOLVER batched potrf + potrs (torch)",
            "torch",
            "cuSOLVER",
        ),
    ] {
        match (
            side(&format!("{key}_ms")),
            side(&format!("{key}_err")),
            side(&format!("{key}_berr")),
        ) {
            (Some(t), Some(fwd), Some(bwd)) => {
                row(what, t, fwd, bwd);
                ratios.push(format!("ours / {name} {:.2}", t_ours / t));
            }
            _ => println!("  {what:<44} not run: {}", why(&format!("{key}_error"))),
        }
    }
    println!(
        "  time ratios (above 1: ours is slower): {}",
        if ratios.is_empty() {
            "none (no other side ran)".to_string()
        } else {
            ratios.join(", ")
        }
    );
    println!(
        "  first launch (compile included): ours {first_ms:.0} ms{}",
        side("warp_first_ms")
            .map(|w| format!(", Warp {w:.0} ms (empty kernel cache)"))
            .unwrap_or_default()
    );
}

/// Threads per block of the batched FFT: Warp's (its `tile_fft` needs at least two elements of a
/// signal per thread: 32 for 64 points) and ours, which also runs at 64.
const FFT_BLOCK_DIM: usize = 32;
/// The other block size ours runs at.
const FFT_BLOCK_DIM_WIDE: usize = 64;

/// Batched 64-point complex FFTs in f32, `tile_fft::M` signals a block: ours against cuFFT
/// (CuPy) and Warp 1.19's `tile_fft`, on the same signals; time per batch, ratios, and on 256
/// sampled signals the error `max |y - Y| / max |Y|` against a float64 DFT.
fn tile_fft_bench(dev: &wp::Device, rows: usize) {
    use tile_fft::{M, N};
    if rows == 0 || !rows.is_multiple_of(M) {
        println!("\ntile FFT: {rows} signals is not a positive multiple of {M}: skipped");
        return;
    }
    let x64 = tile_fft::signals(rows, 41);
    let xh: Vec<Vec2> = x64
        .iter()
        .map(|&(a, b)| Vec2::new(a as f32, b as f32))
        .collect();
    // The reference transforms the rounded inputs every side is handed.
    let x64: Vec<(f64, f64)> = xh.iter().map(|v| (v.x as f64, v.y as f64)).collect();
    let checked = tile_fft::checked_rows(rows, 256);
    println!(
        "
tile FFT: {rows} complex signals of {N} points in f32 (uniform in [-1, 1)^2), {M} a \
         block of {FFT_BLOCK_DIM} threads; error on {} sampled signals against a float64 DFT: \
         max |y - Y| / max |Y| (4 eps log2 N = {:.1e}); times: median of {} after a warm-up",
        checked.len(),
        4.0 * f32::EPSILON as f64 * N.trailing_zeros() as f64,
        common::REPS
    );
    let dir = std::env::temp_dir().join(format!("warp-lang-tile-fft-{}", std::process::id()));
    let written = std::fs::create_dir_all(&dir).and_then(|()| {
        std::fs::write(dir.join("x.c64"), bytemuck::cast_slice(&xh))?;
        let idx: Vec<i64> = checked.iter().map(|&s| s as i64).collect();
        std::fs::write(dir.join("idx.i64"), bytemuck::cast_slice(&idx))
    });
    let theirs = match written {
        Ok(()) => common::python_side(
            "benches/py/tile_fft.py",
            &[
                dir.display().to_string(),
                rows.to_string(),
                N.to_string(),
                M.to_string(),
                FFT_BLOCK_DIM.to_string(),
            ],
        ),
        Err(e) => Err(format!("writing the inputs to {}: {e}", dir.display())),
    };
    let _ = std::fs::remove_dir_all(&dir);
    let side = |key: &str| {
        theirs
            .as_ref()
            .ok()
            .and_then(|t| common::json_number(t, key))
    };
    let why = |key: &str| match &theirs {
        Ok(t) => t
            .get(key)
            .and_then(|v| v.as_str())
            .unwrap_or("no result")
            .to_string(),
        Err(e) => e.clone(),
    };
    let row = |what: &str, t: f64, err: f64| {
        println!(
            "  {what:<36} {t:9.3} ms {:9.2} M signals/s   error {err:.2e}",
            rows as f64 / (t * 1e-3) / 1e6
        );
    };

    let x = wp::Array::from_slice_shape(&xh, (rows, N), dev).unwrap();
    let y = wp::Array::<Vec2, 2>::zeros((rows, N), dev).unwrap();
    // Ours at both block sizes; the ratios take the faster.
    let (mut t_ours, mut first_ms) = (f64::INFINITY, 0.0);
    for bd in [FFT_BLOCK_DIM, FFT_BLOCK_DIM_WIDE] {
        let launch = || wp::launch_tiled(tile_fft::fft_rows, rows / M, (&x, &y), bd, dev);
        let t0 = Instant::now();
        let first = launch().and_then(|()| wp::synchronize());
        if bd == FFT_BLOCK_DIM {
            first_ms = t0.elapsed().as_secs_f64() * 1e3;
        }
        let t = match first.and_then(|()| common::median_ms(launch)) {
            Ok(t) => t,
            Err(e) => {
                println!("  warp-lang tile_fft, block of {bd}: {e}");
                return;
            }
        };
        let ys: Vec<(f64, f64)> = y
            .to_vec()
            .unwrap()
            .iter()
            .map(|v| (v.x as f64, v.y as f64))
            .collect();
        row(
            &format!("warp-lang tile_fft, block of {bd}"),
            t,
            tile_fft::max_error(&x64, &ys, &checked),
        );
        t_ours = t_ours.min(t);
    }
    let mut ratios = Vec::new();
    for (what, key, name) in [
        ("Warp 1.19 tile_fft", "warp", "Warp"),
        ("cuFFT batched C2C (CuPy)", "cufft", "cuFFT"),
    ] {
        match (side(&format!("{key}_ms")), side(&format!("{key}_err"))) {
            (Some(t), Some(err)) => {
                row(what, t, err);
                ratios.push(format!("ours / {name} {:.2}", t_ours / t));
            }
            _ => println!("  {what:<36} not run: {}", why(&format!("{key}_error"))),
        }
    }
    println!(
        "  time ratios (above 1: ours is slower): {}",
        if ratios.is_empty() {
            "none (no other side ran)".to_string()
        } else {
            ratios.join(", ")
        }
    );
    println!(
        "  first launch (compile included): ours {first_ms:.0} ms{}",
        side("warp_first_ms")
            .map(|w| format!(", Warp {w:.0} ms (empty kernel cache)"))
            .unwrap_or_default()
    );
}

/// Block sizes the tiled n-body step runs at (each lane owns one body; the tile is always
/// `tile_nbody::TILE` bodies).
const NBODY_BLOCK_DIMS: [usize; 3] = [64, 128, 256];

/// One all-pairs n-body leapfrog step of `n` bodies (the tile_nbody example's start state):
/// tiled (shared-memory chunks of `tile_nbody::TILE` bodies) at each of `NBODY_BLOCK_DIMS`,
/// against the scalar kernel (one thread per body); per row the median time of a step, the
/// pair interactions per second, and the first step's accelerations' error on 64 sampled bodies
/// against float64, relative to the sum of the terms' lengths (the bound `(n + 16) u` printed).
fn tile_nbody_bench(dev: &wp::Device, n: usize) {
    use tile_nbody::{Kernel, Sim, SOFTENING};
    if n == 0 {
        println!("\ntiled n-body: no bodies: skipped");
        return;
    }
    let (x, v, m) = tile_nbody::start(n, 2026);
    let checked = tile_nbody::checked_bodies(n, 64);
    println!(
        "\ntiled n-body: {n} bodies (f32, softening {SOFTENING}), one leapfrog step a launch, \
         {} bodies a tile; error on {} sampled bodies against float64, relative to the sum of \
         the terms' lengths (bound (n + 16) u = {:.1e}); times: median of {} after a warm-up",
        tile_nbody::TILE,
        checked.len(),
        tile_nbody::error_bound(n),
        common::REPS
    );
    let mut kernels: Vec<Kernel> = NBODY_BLOCK_DIMS
        .iter()
        .map(|&block_dim| Kernel::Tiled { block_dim })
        .collect();
    kernels.push(Kernel::Scalar);
    let (mut best_tiled, mut scalar_ms) = (f64::INFINITY, f64::NAN);
    for kernel in kernels {
        let what = match kernel {
            Kernel::Tiled { block_dim } => format!("tiled, block of {block_dim}"),
            Kernel::Scalar => "scalar, one thread per body".to_string(),
        };
        // The first step's accelerations (at the start state) for the error; the timed steps
        // go on from there (the state moves a little; the work per step does not change).
        let measured = Sim::new(kernel, &x, &v, &m, SOFTENING, 1e-3, dev).and_then(|mut sim| {
            let t0 = Instant::now();
            sim.step()?;
            wp::synchronize()?;
            let first_ms = t0.elapsed().as_secs_f64() * 1e3;
            let a = sim.accelerations()?;
            let err = tile_nbody::acceleration_error(&a, &x, &m, SOFTENING, &checked);
            let t = common::median_ms(|| sim.step())?;
            sim.check_finite()?;
            Ok((t, first_ms, err))
        });
        match measured {
            Ok((t, first_ms, err)) => {
                println!(
                    "  {what:<28} {t:9.3} ms {:10.1} G pairs/s   error {err:.2e}   first step \
                     {first_ms:.0} ms",
                    (n * n) as f64 / (t * 1e-3) / 1e9
                );
                match kernel {
                    Kernel::Tiled { .. } => best_tiled = best_tiled.min(t),
                    Kernel::Scalar => scalar_ms = t,
                }
            }
            Err(e) => println!("  {what:<28} failed: {e}"),
        }
    }
    println!(
        "  time ratio tiled (fastest block) / scalar: {:.3} (below 1: the tiles are faster)",
        best_tiled / scalar_ms
    );
}

fn main() {
    if std::env::args().any(|a| a == "--first-launch-child") {
        return first_launch_child();
    }
    if std::env::args().any(|a| a == "--tile-compile-child") {
        return tile_compile_child();
    }
    // `--tile-gemm-cpu N`: the tile GEMM section at N^3 on the CPU, to check its plumbing (the
    // inputs handed to the Python sides, the errors, the rows) on a machine without a GPU; the
    // Python sides still ask for cuda:0, and their rows say why they did not run.
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--tile-gemm-cpu") {
        let size = args.get(i + 1).and_then(|s| s.parse().ok()).unwrap_or(256);
        return tile_gemm_bench(&wp::get_device("cpu").unwrap(), size);
    }
    // `--tile-cholesky-cpu B`: the tile Cholesky section with B systems on the CPU (plumbing).
    if let Some(i) = args.iter().position(|a| a == "--tile-cholesky-cpu") {
        let batch = args.get(i + 1).and_then(|s| s.parse().ok()).unwrap_or(1024);
        return tile_cholesky_bench(&wp::get_device("cpu").unwrap(), batch);
    }
    // `--tile-fft-cpu R`: the tile FFT section with R signals on the CPU (plumbing).
    if let Some(i) = args.iter().position(|a| a == "--tile-fft-cpu") {
        let rows = args.get(i + 1).and_then(|s| s.parse().ok()).unwrap_or(4096);
        return tile_fft_bench(&wp::get_device("cpu").unwrap(), rows);
    }
    // `--tile-nbody-cpu N`: the tiled n-body section with N bodies on the CPU (plumbing).
    if let Some(i) = args.iter().position(|a| a == "--tile-nbody-cpu") {
        let n = args.get(i + 1).and_then(|s| s.parse().ok()).unwrap_or(1024);
        return tile_nbody_bench(&wp::get_device("cpu").unwrap(), n);
    }
    if std::env::args().any(|a| a == "--first-launch-parts") {
        return first_launch_parts_child();
    }
    let dev = match wp::get_device("cuda:0") {
        Ok(d) => d,
        Err(e) => {
            println!("SKIPPED gpu bench: {e}");
            return;
        }
    };
    println!("gpu bench on {} ({})", dev, dev.name());
    // `--tile-gemm`: the tile GEMM section alone (the others take minutes).
    if std::env::args().any(|a| a == "--tile-gemm") {
        return tile_gemm_bench(&dev, 4096);
    }
    // `--tile-cholesky`: the batched tile Cholesky section alone.
    if std::env::args().any(|a| a == "--tile-cholesky") {
        return tile_cholesky_bench(&dev, 65536);
    }
    // `--tile-fft`: the batched tile FFT section alone.
    if std::env::args().any(|a| a == "--tile-fft") {
        return tile_fft_bench(&dev, 1 << 20);
    }
    // `--tile-nbody`: the tiled n-body section alone.
    if std::env::args().any(|a| a == "--tile-nbody") {
        return tile_nbody_bench(&dev, 65536);
    }
    // `--ad`: the reverse-mode section alone (forward, backward, and backward with atomic adds).
    if std::env::args().any(|a| a == "--ad") {
        return ad_bench(&dev);
    }
    // `--tiles`: every tile section, in one run (the issue's beside-Warp-and-cuBLAS/cuFFT table).
    if std::env::args().any(|a| a == "--tiles") {
        tile_gemm_bench(&dev, 4096);
        tile_cholesky_bench(&dev, 65536);
        tile_fft_bench(&dev, 1 << 20);
        return tile_nbody_bench(&dev, 65536);
    }
    let hand = Hand::new();
    particles(&dev, &hand);
    nbody_bench(&dev, &hand);
    launch_cost(&dev, &hand);
    ad_bench(&dev);
    first_launch();
    tile_gemm_bench(&dev, 4096);
    tile_cholesky_bench(&dev, 65536);
    tile_fft_bench(&dev, 1 << 20);
    tile_nbody_bench(&dev, 65536);
    println!("\ngenerated source and compile time per kernel (this process):");
    for r in wp::compile_reports() {
        let name = format!("{}{}", r.kernel, if r.adjoint { " (adjoint)" } else { "" });
        println!(
            "  {:<18} {:>6} bytes  NVRTC {:7.2} ms  first-launch total {:7.2} ms  cache hit {}",
            name, r.source_bytes, r.compile_ms, r.total_ms, r.cache_hit
        );
    }
}
