//! Tests that need a GPU. Each one calls `probe()` first and, without a device, prints
//! "SKIPPED <test>: no CUDA device (<reason>)" and returns, so the suite passes (loudly) on
//! machines without CUDA and exercises everything on the GPU machine.

use std::ffi::c_void;
use std::sync::Arc;

use crate::cache::tests::TempDir;
use crate::*;

fn gpu_or_skip(test: &str) -> Option<Arc<Gpu>> {
    match probe() {
        Err(reason) => {
            println!("SKIPPED {test}: no CUDA device ({reason})");
            None
        }
        Ok(_) => Some(Gpu::open(0).expect("open cuda:0")),
    }
}

const ADD1: &str = r#"
extern "C" __global__ void add1(float* a, int n) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) a[i] += 1.0f;
}
"#;

fn floats_to_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn bytes_to_floats(b: &[u8]) -> Vec<f32> {
    b.chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// Launches `add1` over `buf` (n floats) on `stream`.
fn launch_add1(gpu: &Gpu, f: &Function, stream: &Stream, buf: &DeviceBuffer, n: i32) {
    let mut ptr = buf.device_ptr();
    let mut n_arg = n;
    let mut params = [
        &mut ptr as *mut u64 as *mut c_void,
        &mut n_arg as *mut i32 as *mut c_void,
    ];
    let grid = (n as u32).div_ceil(256);
    // SAFETY: params match add1(float*, int); `buf` outlives the kernel (callers download on
    // the same stream before dropping it).
    unsafe { gpu.launch_raw(f, stream, grid, 256, 0, &mut params) }.expect("launch add1");
}

#[test]
fn probe_reports_absence_without_panicking() {
    // On a machine without libcuda the reason must say so.
    // SAFETY: only tries to dlopen candidate names.
    if !unsafe { cudarc::driver::sys::is_culib_present() } {
        let reason = probe().expect_err("no driver, yet probe() succeeded");
        assert!(reason.contains("libcuda.so not found"), "{reason}");
        assert!(driver_version().is_none());
    } else {
        println!("probe: {:?}, driver {:?}", probe(), driver_version());
    }
}

#[test]
fn alloc_upload_download_round_trip() {
    let Some(gpu) = gpu_or_skip("alloc_upload_download_round_trip") else {
        return;
    };
    let buf = DeviceBuffer::zeros(&gpu, 1000).unwrap();
    assert_eq!(buf.len(), 1000);
    assert_ne!(buf.device_ptr(), 0);
    assert_eq!(buf.to_vec().unwrap(), vec![0u8; 1000]);
    let data: Vec<u8> = (0..500u32).map(|i| (i % 251) as u8 + 1).collect();
    buf.upload(100, &data).unwrap();
    let mut all = vec![0u8; 1000];
    buf.download(0, &mut all).unwrap();
    assert!(all[..100].iter().all(|&b| b == 0));
    assert_eq!(&all[100..600], &data[..]);
    assert!(all[600..].iter().all(|&b| b == 0));
    let mut part = vec![0u8; 10];
    buf.download(105, &mut part).unwrap();
    assert_eq!(&part[..], &data[5..15]);
    // Out of range is an error, not a crash.
    assert!(matches!(
        buf.upload(999, &[1, 2]),
        Err(CudaError::InvalidArgument(_))
    ));
    assert!(matches!(
        buf.download(1001, &mut []),
        Err(CudaError::InvalidArgument(_))
    ));
    // Zero-byte buffers work and allocate nothing.
    let empty = DeviceBuffer::zeros(&gpu, 0).unwrap();
    assert_eq!(empty.device_ptr(), 0);
    empty.upload(0, &[]).unwrap();
    empty.download(0, &mut []).unwrap();
    empty.fill_pattern(0, 0, &[1, 2, 3]).unwrap();
    assert!(empty.to_vec().unwrap().is_empty());
    // Big-ish buffer through from_bytes.
    let big: Vec<u8> = (0..(8usize << 20)).map(|i| (i * 31 % 256) as u8).collect();
    let b = DeviceBuffer::from_bytes(&gpu, &big).unwrap();
    assert!(b.to_vec().unwrap() == big);
}

#[test]
fn dtod_copy() {
    let Some(gpu) = gpu_or_skip("dtod_copy") else {
        return;
    };
    let data: Vec<u8> = (0..256u32).map(|i| i as u8).collect();
    let a = DeviceBuffer::from_bytes(&gpu, &data).unwrap();
    let b = DeviceBuffer::zeros(&gpu, 256).unwrap();
    b.copy_from_device(10, &a, 20, 100).unwrap();
    let out = b.to_vec().unwrap();
    assert!(out[..10].iter().all(|&x| x == 0));
    assert_eq!(&out[10..110], &data[20..120]);
    assert!(out[110..].iter().all(|&x| x == 0));
    // Within one buffer: disjoint is fine, overlapping is rejected.
    a.copy_from_device(0, &a, 128, 128).unwrap();
    let out = a.to_vec().unwrap();
    assert_eq!(&out[..128], &data[128..]);
    assert!(matches!(
        a.copy_from_device(0, &a, 10, 20),
        Err(CudaError::InvalidArgument(_))
    ));
    assert!(b.copy_from_device(200, &a, 0, 100).is_err());
}

#[test]
fn peer_copy_between_gpus() {
    let Some(gpu0) = gpu_or_skip("peer_copy_between_gpus") else {
        return;
    };
    if probe().unwrap().len() < 2 {
        println!("SKIPPED peer_copy_between_gpus: only one CUDA device");
        return;
    }
    let gpu1 = Gpu::open(1).unwrap();
    let data: Vec<u8> = (0..4096u32).map(|i| (i * 13) as u8).collect();
    let a = DeviceBuffer::from_bytes(&gpu0, &data).unwrap();
    let b = DeviceBuffer::zeros(&gpu1, 4096).unwrap();
    b.copy_from_device(0, &a, 0, 4096).unwrap();
    assert_eq!(b.to_vec().unwrap(), data);
}

#[test]
fn fill_patterns() {
    let Some(gpu) = gpu_or_skip("fill_patterns") else {
        return;
    };
    // 4-byte pattern (memsetD32) in the middle of a zeroed buffer.
    let buf = DeviceBuffer::zeros(&gpu, 4096 + 16).unwrap();
    let pat = 1.5f32.to_le_bytes();
    buf.fill_pattern(8, 4096, &pat).unwrap();
    let out = buf.to_vec().unwrap();
    assert!(out[..8].iter().all(|&b| b == 0));
    assert!(bytes_to_floats(&out[8..8 + 4096]).iter().all(|&x| x == 1.5));
    assert!(out[8 + 4096..].iter().all(|&b| b == 0));
    // 4-byte pattern at an unaligned offset (host-chunk path).
    buf.fill_pattern(1, 4000, &[1, 2, 3, 4]).unwrap();
    let out = buf.to_vec().unwrap();
    assert_eq!(out[0], 0);
    assert!(out[1..4001].chunks(4).all(|c| c == [1, 2, 3, 4]));
    // 2- and 1-byte patterns.
    buf.fill_pattern(0, 100, &[7, 9]).unwrap();
    assert!(buf.to_vec().unwrap()[..100].chunks(2).all(|c| c == [7, 9]));
    buf.fill_pattern(0, 33, &[0xEE]).unwrap();
    assert!(buf.to_vec().unwrap()[..33].iter().all(|&b| b == 0xEE));
    // 12-byte pattern (a Vec3), large enough to need the doubling copies.
    let n = 100_003usize;
    let v3: Vec<u8> = [1.0f32, -2.0, 3.25]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let big = DeviceBuffer::zeros(&gpu, 12 * n + 24).unwrap();
    big.fill_pattern(12, 12 * n, &v3).unwrap();
    let out = big.to_vec().unwrap();
    assert!(out[..12].iter().all(|&b| b == 0));
    assert!(out[12..12 + 12 * n].chunks(12).all(|c| c == &v3[..]));
    assert!(out[12 + 12 * n..].iter().all(|&b| b == 0));
    // Bad lengths are errors.
    assert!(big.fill_pattern(0, 13, &v3).is_err());
    assert!(big.fill_pattern(0, 12, &[]).is_err());
}

#[test]
fn compile_load_launch_add1() {
    let Some(gpu) = gpu_or_skip("compile_load_launch_add1") else {
        return;
    };
    let ver = nvrtc_version().expect("NVRTC on a GPU machine");
    let archs = nvrtc_supported_archs().unwrap();
    println!("NVRTC {ver:?}, archs {archs:?}, device sm_{}", gpu.arch());
    let c = compile(ADD1, "add1.cu", &CompileOptions::default(), gpu.arch()).expect("compile add1");
    assert!(c.cubin.starts_with(b"\x7fELF"), "not a cubin");
    assert!(c.compile_ms > 0.0);
    println!(
        "add1: {} byte cubin in {:.1} ms",
        c.cubin.len(),
        c.compile_ms
    );
    let module = gpu.load_module(&c.cubin).unwrap();
    let f = module.function("add1").unwrap();
    assert!(f.max_threads_per_block().unwrap() >= 256);
    assert!(matches!(
        module.function("nope"),
        Err(CudaError::Driver { .. })
    ));

    let n = 100_000i32;
    let host: Vec<f32> = (0..n).map(|i| i as f32 * 0.5).collect();
    let buf = DeviceBuffer::from_bytes(&gpu, &floats_to_bytes(&host)).unwrap();
    launch_add1(&gpu, &f, gpu.default_stream(), &buf, n);
    launch_add1(&gpu, &f, gpu.default_stream(), &buf, n);
    let out = bytes_to_floats(&buf.to_vec().unwrap());
    for (i, (o, h)) in out.iter().zip(&host).enumerate() {
        assert_eq!(*o, h + 2.0, "element {i}");
    }
    // A zero grid is a no-op.
    let mut params: [*mut c_void; 0] = [];
    unsafe { gpu.launch_raw(&f, gpu.default_stream(), 0, 256, 0, &mut params) }.unwrap();
}

#[test]
fn compile_with_headers_defines_and_errors() {
    let Some(gpu) = gpu_or_skip("compile_with_headers_defines_and_errors") else {
        return;
    };
    let src = r#"
#include "helper.h"
extern "C" __global__ void k(float* a) { a[threadIdx.x] = helper(threadIdx.x) + SCALE; }
"#;
    let headers = [(
        "helper.h",
        "__device__ float helper(unsigned i) { return 2.0f * i; }",
    )];
    let defines = [("SCALE", "10.0f")];
    for fmad in [true, false] {
        let opts = CompileOptions {
            fmad,
            line_info: true,
            headers: &headers,
            defines: &defines,
            ..Default::default()
        };
        let c = compile(src, "k.cu", &opts, gpu.arch()).expect("compile with header");
        let f = gpu.load_module(&c.cubin).unwrap().function("k").unwrap();
        let buf = DeviceBuffer::zeros(&gpu, 32 * 4).unwrap();
        let mut p = buf.device_ptr();
        let mut params = [&mut p as *mut u64 as *mut c_void];
        unsafe { gpu.launch_raw(&f, gpu.default_stream(), 1, 32, 0, &mut params) }.unwrap();
        let out = bytes_to_floats(&buf.to_vec().unwrap());
        for (i, x) in out.iter().enumerate() {
            assert_eq!(*x, 2.0 * i as f32 + 10.0);
        }
    }
    match compile(
        "extern \"C\" __global__ void bad() { undeclared_thing(); }",
        "bad.cu",
        &Default::default(),
        gpu.arch(),
    ) {
        Err(CudaError::Compile { log, name, .. }) => {
            assert_eq!(name, "bad.cu");
            assert!(log.contains("undeclared_thing"), "{log}");
        }
        other => panic!("expected a compile error, got {other:?}"),
    }
    // Not a kernel image: rejected before reaching the driver.
    assert!(gpu.load_module(b"\x7fELF\x02\x01 truncated").is_err());
}

#[test]
fn compile_cache_hit_on_second_compile() {
    let Some(gpu) = gpu_or_skip("compile_cache_hit_on_second_compile") else {
        return;
    };
    let t = TempDir::new("gpu-cache");
    let cache = KernelCache::new(&t.0);
    let opts = CompileOptions::default();
    let (first, o1) = cache
        .compile_cached(ADD1, "add1", &opts, gpu.arch())
        .unwrap();
    assert_eq!(o1, CacheOutcome::Miss);
    let t0 = std::time::Instant::now();
    let (second, o2) = cache
        .compile_cached(ADD1, "add1", &opts, gpu.arch())
        .unwrap();
    let warm_ms = t0.elapsed().as_secs_f64() * 1e3;
    assert_eq!(o2, CacheOutcome::Hit);
    assert_eq!(first.cubin, second.cubin);
    println!(
        "add1: cold {:.1} ms, warm lookup {warm_ms:.2} ms",
        first.compile_ms
    );
    // Damage the entry: it is rebuilt, then hit again.
    let key = cache_key(ADD1, "add1", &opts, gpu.arch(), nvrtc_version().unwrap());
    let path = cache.path_for("add1", key);
    let mut bytes = std::fs::read(&path).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0xFF;
    std::fs::write(&path, &bytes).unwrap();
    let (_, o3) = cache
        .compile_cached(ADD1, "add1", &opts, gpu.arch())
        .unwrap();
    assert_eq!(o3, CacheOutcome::Rebuilt);
    let (hit, o4) = cache
        .compile_cached(ADD1, "add1", &opts, gpu.arch())
        .unwrap();
    assert_eq!(o4, CacheOutcome::Hit);
    // The cached cubin runs.
    let f = gpu
        .load_module(&hit.cubin)
        .unwrap()
        .function("add1")
        .unwrap();
    let buf = DeviceBuffer::zeros(&gpu, 4 * 1000).unwrap();
    launch_add1(&gpu, &f, gpu.default_stream(), &buf, 1000);
    assert!(bytes_to_floats(&buf.to_vec().unwrap())
        .iter()
        .all(|&x| x == 1.0));
}

#[test]
fn pinned_async_copies() {
    let Some(gpu) = gpu_or_skip("pinned_async_copies") else {
        return;
    };
    let n = 1 << 20;
    let mut src = PinnedBuffer::new(&gpu, n).unwrap();
    assert!(src.as_slice().iter().all(|&b| b == 0));
    for (i, b) in src.as_mut_slice().iter_mut().enumerate() {
        *b = (i * 7 % 256) as u8;
    }
    let expect = src.as_slice().to_vec();
    let dev = DeviceBuffer::alloc(&gpu, n).unwrap();
    let mut dst = PinnedBuffer::new(&gpu, n).unwrap();

    // On a separate stream, ordered after the buffer's allocation on the default stream.
    let stream = gpu.new_stream().unwrap();
    stream.wait_stream(gpu.default_stream()).unwrap();
    src.copy_to_device_async(0, &dev, 0, n, &stream).unwrap();
    dst.copy_from_device_async(0, &dev, 0, n, &stream).unwrap();
    assert_eq!(dst.as_slice(), &expect[..]);
    // Default stream drops `dev` later: order it after our stream's use.
    gpu.default_stream().wait_stream(&stream).unwrap();

    // On the default stream, partial ranges, and a launch in between.
    let c = compile(ADD1, "add1.cu", &CompileOptions::default(), gpu.arch()).unwrap();
    let f = gpu.load_module(&c.cubin).unwrap().function("add1").unwrap();
    let floats: Vec<f32> = (0..1024).map(|i| i as f32).collect();
    let mut pin = PinnedBuffer::new(&gpu, 4096).unwrap();
    pin.as_mut_slice()
        .copy_from_slice(&floats_to_bytes(&floats));
    let fb = DeviceBuffer::alloc(&gpu, 4096).unwrap();
    let ds = gpu.default_stream();
    pin.copy_to_device_async(0, &fb, 0, 4096, ds).unwrap();
    launch_add1(&gpu, &f, ds, &fb, 1024);
    pin.copy_from_device_async(0, &fb, 0, 2048, ds).unwrap();
    let got = bytes_to_floats(pin.as_slice());
    for (i, g) in got.iter().enumerate() {
        let want = if i < 512 { i as f32 + 1.0 } else { i as f32 };
        assert_eq!(*g, want, "element {i}");
    }
    // Mismatched devices / ranges are errors.
    assert!(pin.copy_to_device_async(0, &fb, 1, 4096, ds).is_err());
    let empty = PinnedBuffer::new(&gpu, 0).unwrap();
    assert!(empty.as_slice().is_empty());
}

#[test]
fn events_and_streams() {
    let Some(gpu) = gpu_or_skip("events_and_streams") else {
        return;
    };
    let c = compile(ADD1, "add1.cu", &CompileOptions::default(), gpu.arch()).unwrap();
    let f = gpu.load_module(&c.cubin).unwrap().function("add1").unwrap();
    let n = 1 << 22;
    let buf = DeviceBuffer::zeros(&gpu, 4 * n).unwrap();
    let start = gpu.new_event(true).unwrap();
    let end = gpu.new_event(true).unwrap();
    let s = gpu.default_stream();
    start.record(s).unwrap();
    for _ in 0..10 {
        launch_add1(&gpu, &f, s, &buf, n as i32);
    }
    end.record(s).unwrap();
    let ms = start.elapsed_ms(&end).unwrap();
    assert!(ms >= 0.0);
    assert!(end.is_complete().unwrap());
    println!("10 x add1 over {n} floats: {ms:.3} ms");

    // Host cost per launch (informational; the benchmark owns the figure).
    let t0 = std::time::Instant::now();
    for _ in 0..1000 {
        launch_add1(&gpu, &f, s, &buf, 256);
    }
    let per_launch_us = t0.elapsed().as_secs_f64() * 1e6 / 1000.0;
    gpu.synchronize().unwrap();
    println!("host time per launch_raw: {per_launch_us:.2} us");

    // Work on a second stream, joined back.
    let other = gpu.new_stream().unwrap();
    other.wait_stream(s).unwrap();
    launch_add1(&gpu, &f, &other, &buf, n as i32);
    s.wait_stream(&other).unwrap();
    let out = bytes_to_floats(&buf.to_vec().unwrap());
    assert_eq!(out[0], 1011.0);
    assert_eq!(out[n - 1], 11.0);
    other.synchronize().unwrap();
    let ev = gpu.new_event(false).unwrap();
    ev.record(&other).unwrap();
    ev.synchronize().unwrap();
    let (free, total) = gpu.mem_info().unwrap();
    assert!(free <= total && total as u64 == gpu.info().total_memory);
}
