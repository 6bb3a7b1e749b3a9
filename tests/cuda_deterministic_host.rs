//! The GPU path of `#[kernel(deterministic)]`, checked without a GPU: a deterministic
//! kernel's CUDA translation unit (as the runtime assembles it for NVRTC) is compiled as host
//! C++ with g++ against the builtin library, its per-thread function records into the slots
//! of a `wp::det_t` buffer (threads run in reverse order: the slots, not the schedule, fix the
//! order), and the runtime's steps after the launch run on the host: `det_prepare_at`, a
//! stable sort of (low address word, slot), `det_high_at`, a stable sort by the high words,
//! `det_apply_at` (positions in reverse order: each lane's records are added by its first
//! position alone). The results are compared with the CPU backend's launch, bit for bit: both
//! add each lane's records in launch order with the same IEEE operations (g++ with
//! `-ffp-contract=off`; the additions have no products to contract anyway).
//!
//! The GPU's radix sort is the primitives' (`tests/cuda_primitives_host.rs` checks it, stable
//! by contract); `std::stable_sort` stands in for it here. What this cannot check is NVRTC's
//! acceptance of the unit (`suite/deterministic.rs`'s `nvrtc_compiles_the_deterministic_units`)
//! and the GPU's run (the suite's `deterministic::cuda_backend` tests).
//!
//! Skipped, saying so, without g++.

use std::fmt::Write as _;
use std::process::Command;
use warp_lang as wp;
use wp::prelude::*;
use wp::Kernel;

#[wp::kernel(deterministic)]
fn k_bins(x: Array<f32>, bins: Array<f32>) {
    let i = tid();
    atomic_add(bins, i % 4, x[i]);
}

#[wp::kernel(deterministic)]
fn k_add_sub(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    atomic_add(out, i % 3, x[i]);
    atomic_sub(out, i % 3, x[i] * 0.37);
    atomic_add(out, (i + 1) % 3, x[i] * 0.37);
}

#[wp::kernel(deterministic)]
fn k_kinds(x: Array<f32>, v: Array<Vec3>, d: Array<f64>, h: Array<f16>) {
    let i = tid();
    let s = x[i];
    atomic_add(v, i % 2, Vec3::new(s, -s, s * 0.5));
    atomic_sub(d, 0, s as f64 * 1.0e-3);
    atomic_add(h, i % 2, (s * 1.0e-6) as f16);
}

#[wp::kernel(deterministic(max_records = 2))]
fn k_limited(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    for k in 0..(i % 4) {
        atomic_add(out, k, x[i]);
    }
}

/// Values of many magnitudes and both signs: their sums round differently in another order.
fn values(n: usize) -> Vec<f32> {
    let mut s = 0x9e37_79b9_u32;
    (0..n)
        .map(|i| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            let m = (s >> 8) as f32 / (1u32 << 24) as f32 - 0.5;
            m * [1e-3f32, 1.0, 1e3, 1e6][i % 7 % 4]
        })
        .collect()
}

/// One array argument: its C++ element type, element size and elements as bit patterns.
struct Arg {
    cpp: &'static str,
    bytes: usize,
    bits: Vec<u64>,
}

fn f32s(v: &[f32]) -> Arg {
    Arg {
        cpp: "wp::f32",
        bytes: 4,
        bits: v.iter().map(|x| u64::from(x.to_bits())).collect(),
    }
}

/// Runs `K`'s CUDA unit on the host over `n` threads with `args` as the GPU path would, and
/// returns every array's elements as bit patterns afterwards, or the fault it raised
/// (`fault <kind> <index0> <index1>`).
fn run_on_host<K: Kernel>(n: usize, args: &[Arg]) -> Option<Vec<String>> {
    if Command::new("g++").arg("--version").output().is_err() {
        eprintln!("SKIPPED cuda_deterministic_host: no g++ on this machine");
        return None;
    }
    let det = K::INFO.deterministic.expect("a deterministic kernel");
    let src = wp::cuda_source::assemble(&K::INFO);
    let (mut decl, mut print, mut params) = (String::new(), String::new(), Vec::new());
    for (k, a) in args.iter().enumerate() {
        let raw = match a.bytes {
            2 => "wp::u16",
            4 => "wp::u32",
            _ => "wp::u64",
        };
        let lanes = if a.cpp == "wp::Vec3" { 3 } else { 1 };
        let list: Vec<String> = a.bits.iter().map(|b| format!("{b}u")).collect();
        writeln!(decl, "static {raw} r{k}[] = {{{}}};", list.join(", ")).unwrap();
        writeln!(
            decl,
            "wp::array_t<{}, 1> p{k} = {{({}*)r{k}, {{{}}}, {{{}}}, {k}, 0}};",
            a.cpp,
            a.cpp,
            a.bits.len() / lanes,
            a.bytes * lanes
        )
        .unwrap();
        writeln!(
            print,
            "for (size_t e = 0; e < sizeof(r{k}) / sizeof(r{k}[0]); ++e) printf(\"%llx\\n\", (unsigned long long)r{k}[e]);"
        )
        .unwrap();
        params.push(format!("p{k}"));
    }
    let program = format!(
        "#include <cstdio>\n#include <cstring>\n#include <vector>\n#include <algorithm>\n#include <utility>\n\
         {text}\n\
         int main() {{\n\
         {decl}\n\
         wp::fault_t fault = {{}}; unsigned int flag = 0;\n\
         wp::launch_ctx_t rec = wp::launch_ctx_make(&fault, &flag);\n\
         wp::ctx_t ctx = wp::ctx_make(&rec);\n\
         wp::launch_t launch = {{{{{n}, 1, 1, 1}}, {n}, 1, 0}};\n\
         const wp::i64 lanes = (wp::i64){limit} * {width}, slots = lanes * {n};\n\
         std::vector<wp::u64> keys(slots, 0x5555u), values(slots);\n\
         std::vector<wp::u8> tags(slots);\n\
         wp::det_t d = {{keys.data(), values.data(), tags.data(), lanes, {limit}, 0}};\n\
         for (wp::i64 flat = {n} - 1; flat >= 0; --flat) {{\n\
           wp::det_thread_t t = wp::det_begin(d, flat);\n\
           {thread}({params}, launch, flat, &ctx, &t);\n\
           wp::det_end(&t);\n\
         }}\n\
         if (flag) {{ printf(\"fault %d %lld %lld\\n\", fault.kind, (long long)fault.index[0], (long long)fault.index[1]); return 0; }}\n\
         std::vector<wp::u32> word(slots), order(slots);\n\
         auto sort = [&]() {{\n\
           std::vector<std::pair<wp::u32, wp::u32>> p(slots);\n\
           for (wp::i64 i = 0; i < slots; ++i) p[i] = {{word[i], order[i]}};\n\
           std::stable_sort(p.begin(), p.end(), [](auto& a, auto& b) {{ return a.first < b.first; }});\n\
           for (wp::i64 i = 0; i < slots; ++i) {{ word[i] = p[i].first; order[i] = p[i].second; }}\n\
         }};\n\
         for (wp::i64 i = 0; i < slots; ++i) wp::det_prepare_at(d, word.data(), order.data(), i);\n\
         sort();\n\
         for (wp::i64 j = 0; j < slots; ++j) wp::det_high_at(d, word.data(), order.data(), j);\n\
         sort();\n\
         for (wp::i64 j = slots - 1; j >= 0; --j) wp::det_apply_at(d, order.data(), slots, j);\n\
         {print}\n\
         return 0;\n}}\n",
        text = src.text,
        limit = det.max_records,
        width = det.lanes,
        thread = src.thread_fn,
        params = params.join(", "),
    );
    let dir = std::env::temp_dir().join(format!(
        "wp_det_host_{}_{}",
        K::INFO.name,
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    let cpp = dir.join("k.cpp");
    std::fs::write(&cpp, program).unwrap();
    let exe = dir.join("k");
    let out = Command::new("g++")
        .args([
            "-std=c++17",
            "-O1",
            "-ffp-contract=off",
            "-Wno-unused",
            "-DWP_CONTIGUOUS=1",
            "-I",
            include,
        ])
        .arg(&cpp)
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "g++ failed on {}:\n{}",
        cpp.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let run = Command::new(&exe).output().unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
    Some(
        String::from_utf8(run.stdout)
            .unwrap()
            .lines()
            .map(str::to_string)
            .collect(),
    )
}

fn hex(bits: impl IntoIterator<Item = u64>) -> Vec<String> {
    bits.into_iter().map(|b| format!("{b:x}")).collect()
}

/// A contended f32 sum into bins with old values: the host run of the GPU path gives the CPU
/// backend's bits.
#[test]
fn contended_bins_match_the_cpu_backend() {
    let n = 3000;
    let xs = values(n);
    let old = [0.5f32, -0.5, 1e6, 3.0];
    let host = run_on_host::<k_bins>(n, &[f32s(&xs), f32s(&old)]);
    let dev = wp::cpu();
    let (x, bins) = (
        wp::Array::from_slice(&xs, &dev).unwrap(),
        wp::Array::from_slice(&old, &dev).unwrap(),
    );
    wp::launch(k_bins, n, (&x, &bins), &dev).unwrap();
    let mut want = hex(xs.iter().map(|v| u64::from(v.to_bits())));
    want.extend(hex(bins
        .to_vec()
        .unwrap()
        .iter()
        .map(|v| u64::from(v.to_bits()))));
    if let Some(host) = host {
        assert_eq!(host, want);
    }
}

/// Additions and subtractions of one thread into one element keep their program order.
#[test]
fn adds_and_subs_keep_program_order() {
    let n = 2000;
    let xs = values(n);
    let old = [1.0e7f32, -3.5e6, 0.25];
    let host = run_on_host::<k_add_sub>(n, &[f32s(&xs), f32s(&old)]);
    let dev = wp::cpu();
    let (x, out) = (
        wp::Array::from_slice(&xs, &dev).unwrap(),
        wp::Array::from_slice(&old, &dev).unwrap(),
    );
    wp::launch(k_add_sub, n, (&x, &out), &dev).unwrap();
    let got = out.to_vec().unwrap();
    let mut want = old.to_vec();
    for (i, v) in xs.iter().enumerate() {
        want[i % 3] += v;
        want[i % 3] -= v * 0.37;
        want[(i + 1) % 3] += v * 0.37;
    }
    assert_eq!(
        got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        want.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        "the CPU backend against the documented order"
    );
    if let Some(host) = host {
        assert_eq!(&host[n..], hex(got.iter().map(|v| u64::from(v.to_bits()))));
    }
}

/// Vec3 (a record per lane), f64 subtraction and f16 (through f32, rounded once) give the CPU
/// backend's bits.
#[test]
fn vectors_f64_and_f16_match_the_cpu_backend() {
    let n = 1500;
    let xs = values(n);
    let v0 = [Vec3::new(1.0, 2.0, -3.0), Vec3::ZERO];
    let d0 = [2.0f64];
    let h0 = [f16::from_f32(0.5), f16::ZERO];
    let args = [
        f32s(&xs),
        Arg {
            cpp: "wp::Vec3",
            bytes: 4,
            bits: v0
                .iter()
                .flat_map(|v| v.to_array())
                .map(|c| u64::from(c.to_bits()))
                .collect(),
        },
        Arg {
            cpp: "wp::f64",
            bytes: 8,
            bits: d0.iter().map(|v| v.to_bits()).collect(),
        },
        Arg {
            cpp: "wp::f16",
            bytes: 2,
            bits: h0.iter().map(|v| u64::from(v.to_bits())).collect(),
        },
    ];
    let host = run_on_host::<k_kinds>(n, &args);
    let dev = wp::cpu();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let v = wp::Array::from_slice(&v0, &dev).unwrap();
    let d = wp::Array::from_slice(&d0, &dev).unwrap();
    let h = wp::Array::from_slice(&h0, &dev).unwrap();
    wp::launch(k_kinds, n, (&x, &v, &d, &h), &dev).unwrap();
    let mut want = hex(xs.iter().map(|v| u64::from(v.to_bits())));
    want.extend(hex(v
        .to_vec()
        .unwrap()
        .iter()
        .flat_map(|v| v.to_array())
        .map(|c| u64::from(c.to_bits()))));
    want.extend(hex(d.to_vec().unwrap().iter().map(|v| v.to_bits())));
    want.extend(hex(h
        .to_vec()
        .unwrap()
        .iter()
        .map(|v| u64::from(v.to_bits()))));
    if let Some(host) = host {
        assert_eq!(host, want);
    }
}

/// A thread past its limit raises the CPU's fault: wp_core.h's FAULT_DETERMINISTIC_RECORDS
/// (10) with the thread's flat index and the limit. Thread 3 makes 3 calls against 2; the
/// host runs threads in reverse order, so the first fault is thread 7's (also 3 calls).
#[test]
fn the_record_limit_is_the_cpu_fault() {
    let n = 8;
    let xs = values(n);
    let host = run_on_host::<k_limited>(n, &[f32s(&xs), f32s(&[0.0; 4])]);
    let dev = wp::cpu();
    let (x, out) = (
        wp::Array::from_slice(&xs, &dev).unwrap(),
        wp::Array::<f32>::zeros(4, &dev).unwrap(),
    );
    let e = wp::launch(k_limited, n, (&x, &out), &dev).unwrap_err();
    assert!(
        matches!(&e, wp::Error::Fault(f) if matches!(f.kind,
            wp::FaultKind::DeterministicRecords { thread: 3 | 7, limit: 2 })),
        "{e}"
    );
    if let Some(host) = host {
        assert_eq!(host, ["fault 10 7 2"]);
    }
}
