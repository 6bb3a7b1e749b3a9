//! Launches: sizes around the CPU executor's chunking (1 thread, exactly one chunk, one more,
//! a large odd count), multi-dimensional launches, dims given in every form, repeated
//! launches, a kernel without parameters, and print!/println! from kernel threads.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    integrate_particles,
    launch_sizes,
    large_2d_launch,
    dim_forms,
    repeated_launches,
    no_parameters,
    more_threads_than_a_gpu_grid_holds,
    print_from_kernel,
    ahead_of_time_compile,
    ahead_of_time_adjoints,
    load_compiles_before_the_first_launch,
    a_tape_compiles_forward_and_adjoint_as_one_unit,
);

/// Compiled only through `load_compiles_before_the_first_launch`.
#[wp::kernel]
fn k_loaded(a: Array<f32>, b: Array<f32>) {
    let i = tid();
    b[i] = a[i] * a[i];
}

/// Compiled only through `load_compiles_before_the_first_launch`, with its adjoint.
#[wp::kernel]
fn k_loaded_adj(a: Array<f32>, b: Array<f32>) {
    let i = tid();
    b[i] = sin(a[i]);
}

/// `wp::load` compiles the kernels' forward variants (and `load_with_adjoints` their
/// adjoints) before any launch: on a GPU the compile report lists them before they ran, and
/// the launches and backward that follow use them (no second entry); on the CPU it is a no-op.
fn load_compiles_before_the_first_launch(dev: &wp::Device) {
    let reports = |name: &str, adjoint: bool| -> Vec<wp::CompileReport> {
        wp::compile_reports()
            .into_iter()
            .filter(|r| r.kernel == name && r.adjoint == adjoint && r.device == dev.alias())
            .collect()
    };
    let entries = |name: &str, direction: &str| reports(name, direction == "adjoint").len();
    wp::load(&[wp::kernel_info(k_loaded)], dev).unwrap();
    wp::load_with_adjoints(&[wp::kernel_info(k_loaded_adj)], dev).unwrap();
    let expect = usize::from(!dev.is_cpu());
    assert_eq!(entries("k_loaded", "forward"), expect);
    assert_eq!(entries("k_loaded_adj", "forward"), expect);
    assert_eq!(entries("k_loaded_adj", "adjoint"), expect);
    // Neither half was compiled before: one unit for both (a disk cache that holds the halves
    // from an older run would serve them apart; the suite's cache holds this run's units).
    let (fwd, adj) = (
        reports("k_loaded_adj", false),
        reports("k_loaded_adj", true),
    );
    if let (Some(f), Some(a)) = (fwd.first(), adj.first()) {
        assert_eq!(f.one_unit, a.one_unit, "{f:?} {a:?}");
        if f.one_unit {
            assert_eq!((f.cache_key, a.is_unit()), (a.cache_key, false));
        }
    }
    assert!(reports("k_loaded", false).iter().all(|r| !r.one_unit));
    let a = arr(&[1.0f32, 2.0, 3.0], dev).with_grad().unwrap();
    let b = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    wp::launch(k_loaded, 3, (&a, &b), dev).unwrap();
    assert_eq!(host(&b), vec![1.0, 4.0, 9.0]);
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_loaded_adj, 3, (&a, &b), dev).unwrap();
    }
    tape.backward(&b).unwrap();
    // Loaded once: the launches and the backward found the loaded variants.
    assert_eq!(entries("k_loaded", "forward"), expect);
    assert_eq!(entries("k_loaded_adj", "adjoint"), expect);
    // Loading again is a lookup.
    wp::load(&[wp::kernel_info(k_loaded)], dev).unwrap();
    assert_eq!(entries("k_loaded", "forward"), expect);
}

#[wp::func]
fn unit_sq(x: f32) -> f32 {
    x * x
}

/// Launched only by `a_tape_compiles_forward_and_adjoint_as_one_unit`, first under a tape.
#[wp::kernel]
fn k_unit(a: Array<f32>, b: Array<f32>) {
    let i = tid();
    b[i] = unit_sq(a[i]) * 3.0 + sin(a[i]);
}

/// Launched only by `a_tape_compiles_forward_and_adjoint_as_one_unit`, first with no tape.
#[wp::kernel]
fn k_unit_plain(a: Array<f32>, b: Array<f32>) {
    let i = tid();
    b[i] = unit_sq(a[i]) * 3.0 + sin(a[i]);
}

/// A kernel's first launch under a recording tape compiles its forward and adjoint as one
/// unit (one NVRTC run, one module): both reports say so, share the key and the entry, and
/// the unit's cost is counted once; backward then compiles nothing. A kernel first launched
/// without a tape compiles its forward alone, and its adjoint when backward needs it. The
/// unit itself is checked with NVRTC alone on every backend (both entry points in its cubin;
/// skipped without NVRTC). Gradients: d/da (3 a^2 + sin a) = 6 a + cos a, to 1e-5 relative
/// (f32 `sin`/`cos` within a few ulps on a GPU).
fn a_tape_compiles_forward_and_adjoint_as_one_unit(dev: &wp::Device) {
    let (_, arch) = aot_target(dev, "one-unit");
    let info = wp::kernel_info(k_unit);
    let src = wp::cuda_source::assemble_with_adjoint(info);
    let adjoint = src.adjoint.clone().expect("the adjoint's names");
    let stack = wp::config::adstack_bytes().to_string();
    let defines = [("WP_CONTIGUOUS", "1"), ("WP_ADSTACK_BYTES", stack.as_str())];
    let headers = warp_cuda::HEADERS.to_vec();
    let opts = warp_cuda::CompileOptions {
        defines: &defines,
        headers: &headers,
        ..Default::default()
    };
    match warp_cuda::compile(&src.text, info.name, &opts, arch) {
        Ok(c) => {
            let has = |name: &str| {
                c.cubin
                    .windows(name.len() + 1)
                    .any(|w| w[..name.len()] == *name.as_bytes() && w[name.len()] == 0)
            };
            assert!(
                has(&src.entry) && has(&adjoint.entry),
                "entries of {}",
                info.name
            );
        }
        Err(e) if warp_cuda::nvrtc_version().is_err() => {
            eprintln!("SKIPPED the NVRTC part of a_tape_compiles_forward_and_adjoint_as_one_unit on {dev}: {e}");
        }
        Err(e) => panic!("NVRTC refused the unit of both halves: {e}"),
    }
    let xs = [0.5f32, 1.0, 2.0];
    let run = |k: bool| -> (Vec<f32>, Vec<f32>) {
        let a = arr(&xs, dev).with_grad().unwrap();
        let b = zeros::<f32, 1>(3, dev).with_grad().unwrap();
        if !k {
            // First launch with no tape: the forward alone.
            wp::launch(k_unit_plain, 3, (&a, &b), dev).unwrap();
        }
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            if k {
                wp::launch(k_unit, 3, (&a, &b), dev).unwrap();
            } else {
                wp::launch(k_unit_plain, 3, (&a, &b), dev).unwrap();
            }
        }
        tape.backward(&b).unwrap();
        (host(&b), a.grad().expect("with_grad").to_vec().unwrap())
    };
    for k in [true, false] {
        let (b, g) = run(k);
        for (i, x) in xs.into_iter().enumerate() {
            let (want_b, want_g) = (3.0 * x * x + x.sin(), 6.0 * x + x.cos());
            assert!((b[i] - want_b).abs() <= 1e-5 * want_b.abs(), "{b:?}");
            assert!((g[i] - want_g).abs() <= 1e-5 * want_g.abs(), "{g:?}");
        }
    }
    if dev.is_cpu() {
        return;
    }
    let reports = |name: &str| -> Vec<wp::CompileReport> {
        wp::compile_reports()
            .into_iter()
            .filter(|r| r.kernel == name && r.device == dev.alias())
            .collect()
    };
    let unit = reports("k_unit");
    assert_eq!(unit.len(), 2, "{unit:?}");
    let (f, a) = (&unit[0], &unit[1]);
    assert!(!f.adjoint && a.adjoint, "{unit:?}");
    assert!(f.one_unit && a.one_unit, "{unit:?}");
    assert_eq!((f.cache_key, &f.cache_entry), (a.cache_key, &a.cache_entry));
    assert!(f.is_unit() && !a.is_unit());
    assert_eq!((a.compile_ms, a.total_ms), (0.0, 0.0));
    // Compiled here, or found whole in the disk cache of an earlier run.
    assert!(f.cache_hit == (f.compile_ms == 0.0), "{f:?}");
    assert!(f.total_ms > 0.0);
    assert!(wp::compile_summary()
        .lines()
        .any(|l| l.contains("k_unit ") && l.contains("in the forward's unit")));
    let plain = reports("k_unit_plain");
    assert_eq!(plain.len(), 2, "{plain:?}");
    assert!(
        plain.iter().all(|r| !r.one_unit && r.is_unit()),
        "{plain:?}"
    );
    assert_ne!(plain[0].cache_key, plain[1].cache_key);
}

/// A fresh ahead-of-time directory for a test (`name`) on `dev`, and the architecture to
/// compile for: the GPU's, or 90 on the CPU backend (where only the compile is tested).
fn aot_target(dev: &wp::Device, name: &str) -> (std::path::PathBuf, u32) {
    let dir = std::env::temp_dir().join(format!(
        "wp-{name}-{}-{}",
        dev.alias().replace(':', ""),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    let arch = match dev.kind() {
        wp::DeviceKind::Cuda { ordinal } => warp_cuda::Gpu::open(ordinal).unwrap().arch(),
        wp::DeviceKind::Cpu => 90,
    };
    (dir, arch)
}

/// An ahead-of-time compile failed: only acceptable without NVRTC (CI), which the error must
/// say; the test then says it skipped.
fn skipped_without_nvrtc(e: wp::Error, test: &str, dev: &wp::Device) {
    assert!(e.to_string().contains("nvrtc"), "{e}");
    assert!(
        warp_cuda::nvrtc_version().is_err(),
        "NVRTC is there, yet: {e}"
    );
    eprintln!("SKIPPED {test} on {dev}: no NVRTC ({e})");
}

/// Launched only by `ahead_of_time_compile`, so that its first launch is the one measured.
#[wp::kernel]
fn k_aot(a: Array<f32>, s: f32) {
    let i = tid();
    a[i] = a[i] * s + 1.0;
}

/// `wp::aot::compile` writes both variants per architecture (needs NVRTC, not a GPU); with
/// the directory set, the first launch loads the cubin from it instead of compiling, even with
/// an empty kernel cache.
fn ahead_of_time_compile(dev: &wp::Device) {
    let (dir, arch) = aot_target(dev, "aot");
    let built = match wp::aot::compile(&[wp::aot::kernel(k_aot)], &[arch], &dir) {
        Ok(b) => b,
        Err(e) => return skipped_without_nvrtc(e, "ahead_of_time_compile", dev),
    };
    assert_eq!(built.len(), 2);
    assert!(built.iter().all(|b| b.path.is_file() && b.arch == arch));
    assert_eq!(built.iter().filter(|b| b.contiguous).count(), 1);
    if dev.is_cpu() {
        let _ = std::fs::remove_dir_all(&dir);
        return;
    }
    let empty_cache = dir.join("empty-cache");
    warp_cuda::set_cache_dir(Some(empty_cache.clone()));
    wp::aot::set_aot_dir(Some(dir.clone()));
    let a = arr(&[1.0f32, 2.0, 3.0], dev);
    let r = wp::launch(k_aot, 3, (&a, 2.0), dev);
    wp::aot::set_aot_dir(None);
    warp_cuda::set_cache_dir(None);
    r.unwrap();
    assert_eq!(a.to_vec().unwrap(), vec![3.0, 5.0, 7.0]);
    let report = wp::compile_reports()
        .into_iter()
        .find(|r| r.kernel == "k_aot")
        .expect("a compile report for k_aot");
    assert!(
        report.aot && report.cache_hit && report.compile_ms == 0.0,
        "{report:?}"
    );
    // Nothing was compiled, so nothing went to the (empty) kernel cache.
    assert!(!empty_cache.exists() || std::fs::read_dir(&empty_cache).unwrap().next().is_none());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Launched and differentiated only by `ahead_of_time_adjoints`.
#[wp::kernel]
fn k_aot_adj(a: Array<f32>, b: Array<f32>) {
    let i = tid();
    b[i] = sin(a[i]) * a[i];
}

/// `wp::aot::compile_with_adjoints` writes the adjoint units too (both variants, the default
/// adjoint stack), and `wp::aot::verify` finds every entry the runtime will look for (needs
/// NVRTC, not a GPU: on the CPU backend this is the whole test). On a GPU, with the directory
/// set and an empty kernel cache, the forward launch and the first backward pass load their
/// cubins from it: nothing is compiled.
fn ahead_of_time_adjoints(dev: &wp::Device) {
    let (dir, arch) = aot_target(dev, "aot-adj");
    let kernels = [wp::aot::kernel(k_aot_adj)];
    let before = wp::aot::verify(&kernels, &[arch], &dir, true);
    assert_eq!(before.len(), 4);
    assert!(before.iter().all(|c| !c.found), "{before:?}");
    let built = match wp::aot::compile_with_adjoints(&kernels, &[arch], &dir) {
        Ok(b) => b,
        Err(e) => return skipped_without_nvrtc(e, "ahead_of_time_adjoints", dev),
    };
    // Forward and adjoint, each contiguous and strided.
    assert_eq!(built.len(), 4);
    for (adjoint, contiguous) in [(false, true), (false, false), (true, true), (true, false)] {
        assert_eq!(
            built
                .iter()
                .filter(|b| b.adjoint == adjoint && b.contiguous == contiguous)
                .count(),
            1,
            "{built:?}"
        );
    }
    assert!(built.iter().all(|b| b.path.is_file() && b.arch == arch));
    // The runtime's keys find them: the paths `verify` computes are the files written.
    let after = wp::aot::verify(&kernels, &[arch], &dir, true);
    assert!(after.iter().all(|c| c.found), "{after:?}");
    let mut written: Vec<_> = built.iter().map(|b| b.path.clone()).collect();
    let mut looked: Vec<_> = after.iter().map(|c| c.path.clone()).collect();
    written.sort();
    looked.sort();
    assert_eq!(written, looked);
    // Another architecture's entries are not there.
    assert!(wp::aot::verify(&kernels, &[arch + 1], &dir, true)
        .iter()
        .all(|c| !c.found));
    // An unknown architecture is refused before anything is compiled.
    let e = wp::aot::compile(&kernels, &[42], &dir.join("none")).unwrap_err();
    assert!(crate::chain(&e).contains("sm_42"), "{}", crate::chain(&e));
    assert!(!dir.join("none").exists());
    if dev.is_cpu() {
        let _ = std::fs::remove_dir_all(&dir);
        return;
    }
    let empty_cache = dir.join("empty-cache");
    warp_cuda::set_cache_dir(Some(empty_cache.clone()));
    wp::aot::set_aot_dir(Some(dir.clone()));
    let run = || -> wp::Result<(Vec<f32>, Vec<f32>)> {
        let a = arr(&[0.5f32, 1.0, 2.0], dev).with_grad()?;
        let b = zeros::<f32, 1>(3, dev).with_grad()?;
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            wp::launch(k_aot_adj, 3, (&a, &b), dev)?;
        }
        tape.backward(&b)?;
        Ok((b.to_vec()?, a.grad().expect("with_grad").to_vec()?))
    };
    let r = run();
    wp::aot::set_aot_dir(None);
    warp_cuda::set_cache_dir(None);
    let (b, g) = r.unwrap();
    for (k, x) in [0.5f32, 1.0, 2.0].into_iter().enumerate() {
        assert!((b[k] - x.sin() * x).abs() < 1e-6, "{b:?}");
        assert!((g[k] - (x.cos() * x + x.sin())).abs() < 1e-5, "{g:?}");
    }
    let reports: Vec<_> = wp::compile_reports()
        .into_iter()
        .filter(|r| r.kernel == "k_aot_adj")
        .collect();
    assert_eq!(reports.len(), 2, "{reports:?}");
    assert!(reports.iter().any(|r| r.adjoint));
    for r in &reports {
        assert!(r.aot && r.cache_hit && r.compile_ms == 0.0, "{r:?}");
        assert!(
            r.cache_entry.as_ref().is_some_and(|p| p.starts_with(&dir)),
            "{r:?}"
        );
    }
    // Nothing of this kernel went to the (empty) kernel cache.
    let compiled_here = std::fs::read_dir(&empty_cache)
        .into_iter()
        .flatten()
        .flatten()
        .any(|e| e.file_name().to_string_lossy().starts_with("k_aot_adj-"));
    assert!(!compiled_here);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The example of the crate documentation: explicit Euler steps of damped particles.
#[wp::kernel]
fn integrate(x: Array<Vec3>, v: Array<Vec3>, b: f32, mass: f32, gravity: Vec3, dt: f32) {
    let i = tid();
    let a = -b * v[i] / mass + gravity;
    v[i] += a * dt;
    x[i] += v[i] * dt;
}

fn integrate_particles(dev: &wp::Device) {
    let n = 4;
    let x0: Vec<Vec3> = (0..n).map(|k| vec3(k as f32, 0.0, 1.0)).collect();
    let v0: Vec<Vec3> = (0..n).map(|k| vec3(1.0, 0.5 * k as f32, 0.0)).collect();
    let (x, v) = (arr(&x0, dev), arr(&v0, dev));
    let (b, mass, gravity, dt) = (0.05f32, 0.1f32, vec3(0.0, 0.0, -9.81), 0.01f32);
    let (mut hx, mut hv) = (x0, v0);
    for _ in 0..10 {
        wp::launch(integrate, n, (&x, &v, b, mass, gravity, dt), dev).unwrap();
        for i in 0..n {
            let a = -b * hv[i] / mass + gravity;
            hv[i] += a * dt;
            hx[i] += hv[i] * dt;
        }
    }
    // Ten steps of products and sums: FMA on CUDA may change the last bits of each; the
    // tolerance is a few FMA roundings per step.
    let rel = 20.0 * crate::fma_rel(dev);
    for i in 0..n {
        crate::assert_close_slice(&host(&v)[i].to_array(), &hv[i].to_array(), rel, "velocity");
        crate::assert_close_slice(&host(&x)[i].to_array(), &hx[i].to_array(), rel, "position");
    }
    assert!(host(&x)[0].x > 0.0);
}

#[wp::kernel]
fn k_fill(out: Array<u32>, count: Array<u32>) {
    let i = tid();
    out[i] = i as u32 * 3 + 1;
    atomic_add(count, 0, 1);
}

fn launch_sizes(dev: &wp::Device) {
    // A launch of at most `cpu_min_chunk` threads runs serially; larger ones are cut into
    // chunks, the last of which is partial for odd counts.
    let chunk = wp::config::cpu_min_chunk();
    for n in [1, 2, chunk - 1, chunk, chunk + 1, 3 * chunk + 7, 1_000_003] {
        let out = wp::Array::<u32>::full(n, u32::MAX, dev).unwrap();
        let count = zeros::<u32, 1>(1, dev);
        wp::launch(k_fill, n, (&out, &count), dev).unwrap();
        let got = host(&out);
        if let Some(bad) = (0..n).find(|&i| got[i] != i as u32 * 3 + 1) {
            panic!(
                "n = {n}: thread {bad} wrote {} (every thread must run once)",
                got[bad]
            );
        }
        assert_eq!(host(&count), vec![n as u32], "n = {n}: threads run");
    }
}

#[wp::kernel]
fn k_fill_2d(out: Array<u32, 2>) {
    let (i, j) = tid();
    out[(i, j)] = (i * 10_000 + j) as u32;
}

fn large_2d_launch(dev: &wp::Device) {
    let (rows, cols) = (101usize, 4099usize);
    let out = wp::Array::<u32, 2>::full((rows, cols), u32::MAX, dev).unwrap();
    wp::launch(k_fill_2d, (rows, cols), (&out,), dev).unwrap();
    let got = host(&out);
    for i in 0..rows {
        for j in 0..cols {
            assert_eq!(got[i * cols + j], (i * 10_000 + j) as u32, "({i}, {j})");
        }
    }
}

#[wp::kernel]
fn k_mark(out: Array<i32>) {
    let i = tid();
    out[i] += 1;
}

#[wp::kernel]
fn k_mark_2d(out: Array<i32, 2>) {
    let (i, j) = tid();
    out[(i, j)] += 1;
}

/// Launch dims as a `usize`, a one-element array, a tuple, an array and a `wp::Dim`.
fn dim_forms(dev: &wp::Device) {
    let a = zeros::<i32, 1>(6, dev);
    wp::launch(k_mark, 6, (&a,), dev).unwrap();
    wp::launch(k_mark, [6], (&a,), dev).unwrap();
    wp::launch(k_mark, wp::Dim::from(6), (&a,), dev).unwrap();
    assert_eq!(host(&a), vec![3; 6]);
    let b = zeros::<i32, 2>((2, 3), dev);
    wp::launch(k_mark_2d, (2, 3), (&b,), dev).unwrap();
    wp::launch(k_mark_2d, [2, 3], (&b,), dev).unwrap();
    wp::launch(k_mark_2d, wp::Dim::from((2, 3)), (&b,), dev).unwrap();
    assert_eq!(host(&b), vec![3; 6]);
    // Fewer threads than elements: only the first ones are touched.
    wp::launch(k_mark_2d, (1, 2), (&b,), dev).unwrap();
    assert_eq!(host(&b), vec![4, 4, 3, 3, 3, 3]);
}

#[wp::kernel]
fn k_step(x: Array<f32>, v: Array<f32>, dt: f32) {
    let i = tid();
    v[i] -= 9.5 * dt;
    x[i] += v[i] * dt;
}

fn repeated_launches(dev: &wp::Device) {
    let x0 = [0.0f32, 1.0, 2.0];
    let v0 = [1.0f32, 0.0, -1.0];
    let (x, v) = (arr(&x0, dev), arr(&v0, dev));
    let (mut hx, mut hv) = (x0, v0);
    for _ in 0..10 {
        wp::launch(k_step, 3, (&x, &v, 0.25), dev).unwrap();
        for i in 0..3 {
            hv[i] -= 9.5 * 0.25;
            hx[i] += hv[i] * 0.25;
        }
    }
    // Multiples of 1/32 well inside f32's precision: exact, fused or not.
    assert_eq!(host(&v), hv);
    assert_eq!(host(&x), hx);
    wp::synchronize().unwrap();
}

#[wp::kernel]
fn k_noop() {
    let i = tid();
    let _ = i * 2;
}

fn no_parameters(dev: &wp::Device) {
    wp::launch(k_noop, 5, (), dev).unwrap();
}

/// A GPU runs one thread per element, in at most `i32::MAX` blocks (the entry has no
/// grid-stride loop): a launch that would need more is an error naming the kernel and the
/// count, before anything runs. 2^42 threads is over the limit at every block size (at most
/// 1024 threads a block: 2^41 threads); the CPU has no such limit, and 2^42 threads would take
/// it a while, so this is checked on GPUs only.
fn more_threads_than_a_gpu_grid_holds(dev: &wp::Device) {
    if dev.is_cpu() {
        return;
    }
    let n = 1usize << 42;
    let e = wp::launch(k_noop, n, (), dev).unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(e, wp::Error::InvalidDim { .. })
            && msg.contains("k_noop")
            && msg.contains(&n.to_string()),
        "{msg}"
    );
    // A launch within the limit runs.
    wp::launch(k_noop, 1usize << 20, (), dev).unwrap();
}

#[wp::kernel]
fn k_print(v: Array<Vec3>, x: f32, flag: bool) {
    let i = tid();
    let n = i as i32 - 1;
    println!("thread {} of v: {:?}, x = {}, flag = {}", i, v[i], x, flag);
    print!("n = {n}, ");
    print!("{{braces}} {:?}\n", n);
    println!();
}

/// Output is not captured from kernel threads in a checkable way: this only checks that
/// `{}`, `{:?}`, `{name}` and `{{`/`}}` compile and run.
fn print_from_kernel(dev: &wp::Device) {
    let v = arr(&[vec3(1.0, 2.0, 3.0), Vec3::NEG_ONE], dev);
    wp::launch(k_print, 2, (&v, 0.5, true), dev).unwrap();
}
