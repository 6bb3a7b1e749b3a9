//! The CUDA primitives, checked without a GPU: the launch plans the runtime runs on a GPU
//! (`wp::primitives::plan`) are run over the same kernel source (`wp_primitives.h`, one
//! module as the runtime hands it to NVRTC), compiled with g++ under a block emulator
//! (`warp-cuda/cuda/tests/wp_prim_emu.h`: a block's threads are host threads, `__syncthreads`
//! a barrier, blocks one after another), and the results are compared with serial
//! references.
//!
//! The kernels are compiled for small tiles (64 threads x 2 elements; 16 x 3, 96 x 2 and, for
//! vector loads, 32 x 4) so that small inputs already span many blocks, the one-block "spine"
//! loops over several tiles of block totals, and the single-pass scan's look-backs are long. Scratch buffers start filled with 0xCD bytes, so a kernel that read
//! scratch before writing it would show. What this cannot check is what only hardware does:
//! NVRTC's acceptance of the source, warp scheduling and memory ordering on the GPU (the
//! backend suite's `primitives` tests do that on a GPU).
//!
//! Skipped, saying so, without g++.

use std::collections::HashMap;
use std::process::Command;
use std::sync::{Arc, Mutex, OnceLock};
use warp_lang as wp;
use wp::primitives::plan::{
    self, Len, Module, Plan, ReduceOp, ScanAlgorithm, SortConfig, SortVariant, Tile,
};
use wp::primitives::SortKey;

/// 64 threads, like the GPU's 256 an even power of two: the block scan's double buffer ends
/// in the same half.
const TILE: Tile = Tile {
    threads: 64,
    items: 2,
};
/// The smallest block the kernels allow (one partial warp) and a tile that is not a power
/// of two.
const ODD_TILE: Tile = Tile {
    threads: 16,
    items: 3,
};
/// Three whole warps: a block that is not a power of two, and whose threads hold more than
/// one digit each in the sort's per-digit steps (the last thread fewer).
const WARPS_TILE: Tile = Tile {
    threads: 96,
    items: 2,
};

/// The sort's kernels of `variant` compiled for `tile`.
fn sort_config(variant: SortVariant, tile: Tile) -> SortConfig {
    SortConfig {
        variant,
        tile,
        min_blocks: 1,
    }
}

fn have_gpp() -> bool {
    static HAVE: OnceLock<bool> = OnceLock::new();
    *HAVE.get_or_init(|| {
        let ok = Command::new("g++").arg("--version").output().is_ok();
        if !ok {
            eprintln!("SKIPPED cuda_primitives_host: no g++ on this machine");
        }
        ok
    })
}

/// The host executable of `module` compiled for `tile`, with the `extra` definitions
/// (`NAME=VALUE`), built once per process.
fn executable(module: &Module, tile: Tile, extra: &[&str]) -> Arc<std::path::PathBuf> {
    // One slot per build: the first test to need it compiles it, others wait.
    type Slot = Arc<Mutex<Option<Arc<std::path::PathBuf>>>>;
    type Built = Mutex<HashMap<(String, u32, u32, String), Slot>>;
    static BUILT: OnceLock<Built> = OnceLock::new();
    let slot = BUILT
        .get_or_init(Default::default)
        .lock()
        .unwrap()
        .entry((module.name(), tile.threads, tile.items, extra.join(" ")))
        .or_default()
        .clone();
    let mut slot = slot.lock().unwrap();
    if let Some(exe) = slot.as_ref() {
        return exe.clone();
    }
    let dir = std::env::temp_dir().join(format!(
        "wp_prims_{}_{}x{}_{}_{}",
        module.name(),
        tile.threads,
        tile.items,
        extra.len(),
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let cpp = dir.join("module.cpp");
    std::fs::write(
        &cpp,
        format!(
            "#include \"wp_prim_emu.h\"\n{}#include \"wp_prim_driver.h\"\n",
            module.source()
        ),
    )
    .unwrap();
    let cuda = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    let exe = dir.join("module");
    let defines: Vec<String> = module
        .defines(tile)
        .iter()
        .map(|(k, v)| format!("-D{k}={v}"))
        .chain(extra.iter().map(|d| format!("-D{d}")))
        .collect();
    let out = Command::new("g++")
        .args([
            "-std=c++17",
            "-O1",
            "-ffp-contract=off",
            "-pthread",
            "-Wall",
            "-Wextra",
            "-Werror",
        ])
        .args(&defines)
        .args(["-I", cuda, "-I", &format!("{cuda}/tests")])
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
    let exe = Arc::new(exe);
    *slot = Some(exe.clone());
    exe
}

/// One run of a plan: the caller's buffers before, and after.
struct Case {
    plan: Plan,
    users: Vec<Vec<u8>>,
}

struct Ran {
    users: Vec<Vec<u8>>,
    /// `(kind, arg, index[0], shape[0])` of a recorded fault.
    fault: Option<(i32, i32, i64, i64)>,
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

/// Runs the cases (all of one module) in one process of the host build.
fn run(tile: Tile, cases: &[Case]) -> Vec<Ran> {
    run_with(tile, &[], cases)
}

/// `run` on a build with the `extra` definitions.
fn run_with(tile: Tile, extra: &[&str], cases: &[Case]) -> Vec<Ran> {
    let module = &cases[0].plan.module;
    assert!(cases.iter().all(|c| &c.plan.module == module));
    let exe = executable(module, tile, extra);
    let mut script = String::new();
    for c in cases {
        let u = c.users.len();
        for (k, data) in c.users.iter().enumerate() {
            script += &format!("buf {k} {}\n", data.len());
            if !data.is_empty() {
                script += &format!("data {k} {}\n", hex(data));
            }
        }
        for (k, &bytes) in c.plan.scratch.iter().enumerate() {
            script += &format!("buf {} {bytes}\n", u + k);
        }
        for s in &c.plan.steps {
            script += &format!("launch {} {}", s.entry, s.blocks);
            let mut words: Vec<String> = s
                .args
                .iter()
                .map(|w| match *w {
                    plan::Word::Addr(plan::Buf::User(k), off) => format!("a{k}+{off}"),
                    plan::Word::Addr(plan::Buf::Scratch(k), off) => format!("a{}+{off}", u + k),
                    plan::Word::Null => "null".into(),
                    plan::Word::Int(v) => format!("i{v}"),
                    plan::Word::Fault => "fault".into(),
                    plan::Word::FaultFlag => "flag".into(),
                })
                .collect();
            words.resize(16, "i0".into());
            script += &format!(" {}\n", words.join(" "));
        }
        for k in 0..u {
            script += &format!("dump {k}\n");
        }
        script += "check\nreset\n";
    }
    let path = exe.with_file_name(format!("script_{:?}.txt", std::thread::current().id()));
    std::fs::write(&path, script).unwrap();
    let out = Command::new(exe.as_path()).arg(&path).output().unwrap();
    assert!(
        out.status.success(),
        "host run of {} failed: {}",
        module.name(),
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let mut lines = text.lines();
    cases
        .iter()
        .map(|c| {
            let users = (0..c.users.len())
                .map(|k| {
                    let l = lines.next().expect("a dump line");
                    let mut parts = l.split(' ');
                    assert_eq!(parts.next(), Some("dump"));
                    assert_eq!(parts.next(), Some(k.to_string().as_str()));
                    unhex(parts.next().unwrap_or(""))
                })
                .collect();
            let l = lines.next().expect("a check line");
            let fault = if l == "nofault" {
                None
            } else {
                let v: Vec<i64> = l.split(' ').skip(1).map(|x| x.parse().unwrap()).collect();
                Some((v[0] as i32, v[1] as i32, v[2], v[3]))
            };
            Ran { users, fault }
        })
        .collect()
}

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn bytes<T: bytemuck::Pod>(v: &[T]) -> Vec<u8> {
    bytemuck::cast_slice(v).to_vec()
}

fn typed<T: bytemuck::Pod>(b: &[u8]) -> Vec<T> {
    b.chunks_exact(std::mem::size_of::<T>())
        .map(bytemuck::pod_read_unaligned)
        .collect()
}

/// Sizes around the tile boundaries, and one whose block totals need several spine tiles.
fn sizes(tile: Tile) -> Vec<usize> {
    let t = tile.elements() as usize;
    vec![0, 1, 2, 7, t - 1, t, t + 1, 3 * t + 5, t * (t + 2) + 3]
}

// ------------------------------------------------------------------------------------------
// Scan and reductions
// ------------------------------------------------------------------------------------------

#[path = "common/primitives_data.rs"]
mod primitives_data;
use primitives_data::{serial_scan, Elem, F32_SPECIALS};

/// Both scan algorithms.
const SCANS: [ScanAlgorithm; 2] = [ScanAlgorithm::ThreePass, ScanAlgorithm::OnePass];

fn scan_cases<T: Elem>(tile: Tile) {
    scan_cases_with::<T>(tile, &[], &SCANS);
}

/// Scans of every size around the tile boundaries by each of `algorithms`, into a longer
/// output and in place with a device count, on a build with the `defines` (`NAME=VALUE`).
fn scan_cases_with<T: Elem>(tile: Tile, defines: &[&str], algorithms: &[ScanAlgorithm]) {
    if !have_gpp() {
        return;
    }
    for &alg in algorithms {
        scan_algorithm_cases::<T>(tile, defines, alg);
    }
}

fn scan_algorithm_cases<T: Elem>(tile: Tile, defines: &[&str], alg: ScanAlgorithm) {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ T::CUDA.len() as u64);
    let size = std::mem::size_of::<T>() as u64;
    let mut cases = Vec::new();
    let mut want = Vec::new();
    for &n in &sizes(tile) {
        for inclusive in [false, true] {
            let x: Vec<T> = (0..n).map(|_| T::small(rng.next())).collect();
            let out0: Vec<T> = (0..n + 3).map(|_| T::small(rng.next())).collect();
            // Host length, into a longer output (its tail stays).
            cases.push(Case {
                plan: alg.plan(tile, T::CUDA, size, Len::Host(n as u64), inclusive),
                users: vec![bytes(&x), bytes(&out0)],
            });
            let mut w = out0.clone();
            w[..n].copy_from_slice(&serial_scan(&x, inclusive));
            want.push((w, format!("n {n} inclusive {inclusive}")));
            // In place, with the count on the device (at most the capacity).
            let count = rng.below(n as u64 + 1) as usize;
            let len = Len::Device {
                count: 2,
                capacity: n as u64,
                arg: 2,
            };
            cases.push(Case {
                plan: alg.plan(tile, T::CUDA, size, len, inclusive),
                users: vec![bytes(&x), bytes(&x), bytes(&[count as i32])],
            });
            let mut w = x.clone();
            w[..count].copy_from_slice(&serial_scan(&x[..count], inclusive));
            want.push((w, format!("in place, n {n}, device count {count}")));
        }
    }
    let ran = run_with(tile, defines, &cases);
    for (k, (r, (w, what))) in ran.iter().zip(&want).enumerate() {
        assert_eq!(r.fault, None, "{} {alg:?} {what}", T::CUDA);
        // Case 2k writes user 1; case 2k+1 in place writes user 1 too (same data).
        let got: Vec<T> = typed(&r.users[1]);
        assert_eq!(&got, w, "{} {alg:?} scan, {what} (case {k})", T::CUDA);
    }
}

#[test]
fn scan_i32() {
    scan_cases::<i32>(TILE);
}
#[test]
fn scan_u32_wraps() {
    scan_cases::<u32>(TILE);
}
#[test]
fn scan_i64() {
    scan_cases::<i64>(TILE);
}
#[test]
fn scan_u64_wraps() {
    scan_cases::<u64>(TILE);
}
#[test]
fn scan_f32() {
    scan_cases::<f32>(TILE);
}
#[test]
fn scan_f64() {
    scan_cases::<f64>(TILE);
}
#[test]
fn scan_odd_tile() {
    scan_cases::<i32>(ODD_TILE);
    scan_cases::<f64>(WARPS_TILE);
}

/// The single-pass scan's look-back over tiles that have published only their aggregate:
/// in the emulator the tile before is always finished, so without this every walk would end
/// at once. With an inclusive prefix published by every 5th tile, walks add aggregates within
/// one window; by every 40th (more than a window of 32 or 16 lanes), they cross windows.
/// Blocks of one partial warp (16 threads), of two and of three warps.
#[test]
fn scan_onepass_walks_back_over_aggregates() {
    for every in [
        "WP_PRIM_SCAN_INCLUSIVE_EVERY=5",
        "WP_PRIM_SCAN_INCLUSIVE_EVERY=40",
    ] {
        let defines = [every];
        let one = [ScanAlgorithm::OnePass];
        scan_cases_with::<i32>(TILE, &defines, &one);
        scan_cases_with::<u64>(TILE, &defines, &one);
        scan_cases_with::<f32>(ODD_TILE, &defines, &one);
        scan_cases_with::<f64>(ODD_TILE, &defines, &one);
        scan_cases_with::<i64>(WARPS_TILE, &defines, &one);
    }
}

/// Float scans of fractional data, by both algorithms: within the bound of any summation
/// order, `|error| <= 2 k eps sum |x|` for the k-th prefix (the single-pass scan also with
/// walks over aggregates).
#[test]
fn scan_f32_fractional_within_rounding() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng(7);
    let n = 3000;
    let x: Vec<f32> = (0..n)
        .map(|_| (rng.below(2_000_001) as f32 - 1e6) * 1e-6)
        .collect();
    for (alg, defines) in [
        (ScanAlgorithm::ThreePass, &[][..]),
        (ScanAlgorithm::OnePass, &[][..]),
        (
            ScanAlgorithm::OnePass,
            &["WP_PRIM_SCAN_INCLUSIVE_EVERY=40"][..],
        ),
    ] {
        let ran = run_with(
            TILE,
            defines,
            &[Case {
                plan: alg.plan(TILE, "f32", 4, Len::Host(n as u64), true),
                users: vec![bytes(&x), bytes(&vec![0f32; n])],
            }],
        );
        let got: Vec<f32> = typed(&ran[0].users[1]);
        let (mut acc, mut abs) = (0f64, 0f64);
        for (k, (&g, &v)) in got.iter().zip(&x).enumerate() {
            acc += v as f64;
            abs += v.abs() as f64;
            let bound = 2.0 * (k + 1) as f64 * f32::EPSILON as f64 * abs;
            assert!(
                (g as f64 - acc).abs() <= bound,
                "{alg:?} {defines:?} k {k}: {g} vs {acc}"
            );
        }
    }
}

/// The single-pass scan's float results do not depend on where a look-back ends: with the
/// groups' inclusive values (a group: 32 tiles in blocks of two warps, 16 in a block of one
/// partial warp) published by every group, every 3rd, 5th and 40th (walks of one group, within
/// a window of groups and, in the 16-lane blocks' 300 tiles, across windows, as timing decides
/// on a GPU), f32 and f64 results are the same bit for bit. (The tree walk of the integers'
/// look-back would not pass this: its sums depend on where the walk ends.)
#[test]
fn scan_onepass_floats_same_bits_wherever_the_walk_ends() {
    if !have_gpp() {
        return;
    }
    fn check<T: Elem>(tile: Tile, x: &[T]) {
        let n = x.len();
        let runs: Vec<(&str, Vec<u8>)> = ["1", "3", "5", "40"]
            .iter()
            .map(|every| {
                let define = format!("WP_PRIM_SCAN_INCLUSIVE_EVERY={every}");
                let size = std::mem::size_of::<T>() as u64;
                let plan =
                    ScanAlgorithm::OnePass.plan(tile, T::CUDA, size, Len::Host(n as u64), true);
                let ran = run_with(
                    tile,
                    &[define.as_str()],
                    &[Case {
                        plan,
                        users: vec![bytes(x), bytes(&vec![T::ZERO; n])],
                    }],
                );
                (*every, ran[0].users[1].clone())
            })
            .collect();
        for (every, got) in &runs[1..] {
            assert!(
                got == &runs[0].1,
                "{} {tile:?}: groups published every {every} give other bits than every group",
                T::CUDA
            );
        }
    }
    let mut rng = Rng(11);
    // 16 x 3 = 48 elements a tile in the 16-lane blocks: 300 tiles are 19 groups of 16, more
    // than a window of 16 groups. 64 x 2 = 128 elements a tile in the others: 90 tiles, three
    // groups of 32.
    let n = 48 * 300 - 5;
    let x32: Vec<f32> = (0..n)
        .map(|_| (rng.below(2_000_001) as f32 - 1e6) * 1e-3)
        .collect();
    let x64: Vec<f64> = x32.iter().map(|&v| v as f64 * 1.000_000_1).collect();
    let wide = 128 * 90 - 17;
    check(TILE, &x32[..wide]);
    check(TILE, &x64[..wide]);
    check(ODD_TILE, &x32);
    check(ODD_TILE, &x64);
}

fn reduce_cases<T: Elem>(extra: &[Vec<T>]) {
    reduce_cases_on::<T>(TILE, extra)
}

/// Sums, minima and maxima of every size around `tile`'s boundaries and of `extra`, with host
/// and device counts.
fn reduce_cases_on<T: Elem>(tile: Tile, extra: &[Vec<T>]) {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng(0x1234_5678 ^ T::CUDA.len() as u64);
    let size = std::mem::size_of::<T>() as u64;
    let mut inputs: Vec<Vec<T>> = sizes(tile)
        .into_iter()
        .map(|n| (0..n).map(|_| T::small(rng.next())).collect())
        .collect();
    inputs.extend(extra.iter().cloned());
    let mut cases = Vec::new();
    let mut want = Vec::new();
    for x in &inputs {
        for op in [ReduceOp::Sum, ReduceOp::Min, ReduceOp::Max] {
            let (id, f): (T, fn(T, T) -> T) = match op {
                ReduceOp::Sum => (T::ZERO, T::add),
                ReduceOp::Min => (T::MIN_IDENTITY, T::min_of),
                ReduceOp::Max => (T::MAX_IDENTITY, T::max_of),
            };
            cases.push(Case {
                plan: plan::reduce(tile, T::CUDA, size, op, Len::Host(x.len() as u64)),
                users: vec![bytes(x), bytes(&[T::small(1)])],
            });
            want.push((x.iter().fold(id, |a, &v| f(a, v)), x.len(), op));
            // The first half, counted on the device.
            let count = x.len() / 2;
            let len = Len::Device {
                count: 2,
                capacity: x.len() as u64,
                arg: 2,
            };
            cases.push(Case {
                plan: plan::reduce(tile, T::CUDA, size, op, len),
                users: vec![bytes(x), bytes(&[T::small(1)]), bytes(&[count as i32])],
            });
            want.push((x[..count].iter().fold(id, |a, &v| f(a, v)), count, op));
        }
    }
    for (r, (w, n, op)) in run(tile, &cases).iter().zip(&want) {
        let got: Vec<T> = typed(&r.users[1]);
        // Bit patterns: NaN-free results must match exactly, signed zeros included.
        assert_eq!(
            bytes(&got),
            bytes(&[*w]),
            "{} {op:?} of {n}: {got:?} vs {w:?}",
            T::CUDA
        );
    }
}

#[test]
fn reductions_int() {
    // 70001 elements: more block totals (of 4 tiles each) than one spine tile holds.
    reduce_cases::<i32>(&[
        vec![i32::MIN, i32::MAX, -1, 5],
        (0..70_001).map(|i| (i * 7919 % 1001) - 500).collect(),
    ]);
    reduce_cases::<u32>(&[]);
    reduce_cases::<i64>(&[vec![i64::MIN, 3]]);
    reduce_cases::<u64>(&[]);
}

/// The block total's shuffle tree in a block of one partial warp (16 threads) and of three
/// warps.
#[test]
fn reductions_odd_tiles() {
    let nan = f32::NAN;
    for tile in [ODD_TILE, WARPS_TILE] {
        reduce_cases_on::<i32>(
            tile,
            &[(0..20_001).map(|i| (i * 7919 % 1001) - 500).collect()],
        );
        reduce_cases_on::<f32>(tile, &[vec![nan, 3.0, -2.0, nan, f32::INFINITY]]);
        reduce_cases_on::<u64>(tile, &[]);
    }
}

/// A tile whose threads' elements are whole 16-byte vectors for every element type (4 of 4
/// bytes, 2 of 8): full tiles of an aligned array are read by vector loads.
const VEC_TILE: Tile = Tile {
    threads: 32,
    items: 4,
};

/// Reductions by vector loads (full tiles of an aligned input; the driver's buffers are
/// malloc'd, 16-byte aligned) and, for the same inputs one element in, by scalar loads (the
/// kernel checks the address), against the serial fold.
#[test]
fn reductions_vector_loads() {
    if !have_gpp() {
        return;
    }
    reduce_cases_on::<i32>(
        VEC_TILE,
        &[(0..20_001).map(|i| (i * 7919 % 1001) - 500).collect()],
    );
    reduce_cases_on::<f64>(VEC_TILE, &[vec![f64::NAN, -1e300, f64::NEG_INFINITY, 7.0]]);
    reduce_cases_on::<f32>(VEC_TILE, &[]);
    reduce_cases_on::<u64>(VEC_TILE, &[]);
    let x: Vec<i64> = (0..5000).map(|i| (i * 7919 % 1001) - 500).collect();
    let mut cases = Vec::new();
    for op in [ReduceOp::Sum, ReduceOp::Min, ReduceOp::Max] {
        let mut p = plan::reduce(VEC_TILE, "i64", 8, op, Len::Host(x.len() as u64 - 1));
        p.steps[0].args[0] = plan::Word::Addr(plan::Buf::User(0), 8);
        cases.push(Case {
            plan: p,
            users: vec![bytes(&x), bytes(&[0i64])],
        });
    }
    let ran = run(VEC_TILE, &cases);
    let rest = &x[1..];
    let want = [
        rest.iter().sum::<i64>(),
        *rest.iter().min().unwrap(),
        *rest.iter().max().unwrap(),
    ];
    for (r, w) in ran.iter().zip(want) {
        assert_eq!(typed::<i64>(&r.users[1]), vec![w]);
    }
}

#[test]
fn reductions_float_ignore_nan() {
    let nan = f32::NAN;
    reduce_cases::<f32>(&[
        vec![nan, 3.0, -2.0, nan, f32::INFINITY],
        vec![nan; 300],
        (0..500)
            .map(|i| if i % 7 == 0 { nan } else { i as f32 })
            .collect(),
    ]);
    reduce_cases::<f64>(&[vec![f64::NAN, -1e300, f64::NEG_INFINITY, 7.0]]);
}

// ------------------------------------------------------------------------------------------
// Radix sort
// ------------------------------------------------------------------------------------------

/// The serial reference: a stable sort by the low `bits` bits of the keys' images.
fn sort_reference<K: SortKey + bytemuck::Pod>(
    keys: &[K],
    values: &[u32],
    bits: u32,
) -> (Vec<K>, Vec<u32>) {
    let mask = if bits == 32 {
        u32::MAX
    } else {
        (1 << bits) - 1
    };
    let mut pairs: Vec<(K, u32)> = keys.iter().copied().zip(values.iter().copied()).collect();
    pairs.sort_by_key(|(k, _)| k.to_radix() & mask);
    pairs.into_iter().unzip()
}

fn sort_cases<K: SortKey + bytemuck::Pod + std::fmt::Debug>(
    config: SortConfig,
    key_bits: &[u32],
    gen: impl Fn(&mut Rng) -> K,
    extra: &[Vec<K>],
) {
    sort_cases_with(config, &[], key_bits, gen, extra)
}

/// `sort_cases` on a build with the `defines` (`NAME=VALUE`) too.
fn sort_cases_with<K: SortKey + bytemuck::Pod + std::fmt::Debug>(
    config: SortConfig,
    defines: &[&str],
    key_bits: &[u32],
    gen: impl Fn(&mut Rng) -> K,
    extra: &[Vec<K>],
) {
    if !have_gpp() {
        return;
    }
    let tile = config.tile;
    let mut rng = Rng(0xdead_beef ^ K::CUDA.len() as u64);
    let mut inputs: Vec<Vec<K>> = sizes(tile)
        .into_iter()
        .map(|n| (0..n).map(|_| gen(&mut rng)).collect())
        .collect();
    inputs.extend(extra.iter().cloned());
    let mut cases = Vec::new();
    let mut want = Vec::new();
    for keys in &inputs {
        let n = keys.len();
        for &bits in key_bits {
            // Values: the original positions, so stability shows.
            let values: Vec<u32> = (0..n as u32).collect();
            // Host count of all but the last few (the tail stays put).
            let count = n - n.min(3);
            cases.push(Case {
                plan: plan::sort(config, K::CUDA, bits, Len::Host(count as u64)),
                users: vec![bytes(keys), bytes(&values)],
            });
            let (mut wk, mut wv) = sort_reference(&keys[..count], &values[..count], bits);
            wk.extend_from_slice(&keys[count..]);
            wv.extend_from_slice(&values[count..]);
            want.push((wk, wv, format!("n {n} count {count} bits {bits}")));
            // A count on the device.
            let count = rng.below(n as u64 + 1) as usize;
            let len = Len::Device {
                count: 2,
                capacity: n as u64,
                arg: 2,
            };
            cases.push(Case {
                plan: plan::sort(config, K::CUDA, bits, len),
                users: vec![bytes(keys), bytes(&values), bytes(&[count as i32])],
            });
            let (mut wk, mut wv) = sort_reference(&keys[..count], &values[..count], bits);
            wk.extend_from_slice(&keys[count..]);
            wv.extend_from_slice(&values[count..]);
            want.push((wk, wv, format!("n {n} device count {count} bits {bits}")));
        }
    }
    for (r, (wk, wv, what)) in run_with(tile, defines, &cases).iter().zip(&want) {
        assert_eq!(r.fault, None, "{what}");
        let gk: Vec<K> = typed(&r.users[0]);
        let gv: Vec<u32> = typed(&r.users[1]);
        assert_eq!(bytes(&gk), bytes(wk), "{} keys, {what}: {gk:?}", K::CUDA);
        assert_eq!(&gv, wv, "{} values, {what}", K::CUDA);
    }
}

/// The GPU's sort kernel on the small tile.
fn ballot() -> SortConfig {
    sort_config(SortVariant::Ballot, TILE)
}

#[test]
fn sort_u32_with_duplicates_and_key_bits() {
    // Few distinct keys: long runs of equal keys test stability.
    sort_cases::<u32>(
        ballot(),
        &[32, 5, 9, 1],
        |r| (r.below(37) as u32) * 0x0101_0101,
        &[],
    );
    sort_cases::<u32>(
        ballot(),
        &[32],
        |r| r.next() as u32,
        &[vec![u32::MAX, 0, u32::MAX, 1]],
    );
}

/// 8-bit passes with `key_bits` cutting them: 8 bits (one pass and the copy back), 16 (two),
/// 21 (the hash grid's cell ids: three passes, user -> B -> C -> user), 24, 32 (four), with
/// random high bits the sort must ignore; the histograms of every pass come from one upfront
/// read (which counts runs of one digit among a thread's keys at once: sorted keys have long
/// ones), and 131 tiles make long look-back chains.
#[test]
fn sort_u32_passes_by_key_bits() {
    let mut r = Rng(9);
    let mut sorted: Vec<u32> = (0..40_000).map(|_| r.next() as u32 >> 4).collect();
    sorted.sort_unstable();
    sort_cases::<u32>(
        ballot(),
        &[8, 16, 21, 24, 32],
        |r| r.next() as u32,
        &[sorted],
    );
    // Few distinct digits per pass: long runs inside tiles, most digits absent from a tile.
    sort_cases::<u32>(
        ballot(),
        &[21, 17],
        |r| {
            ((r.below(3) as u32) << 16)
                | ((r.below(2) as u32) << 8)
                | (r.next() as u32 & 0xFF00_0000)
        },
        &[],
    );
}

#[test]
fn sort_i32_negative() {
    sort_cases::<i32>(
        ballot(),
        &[32, 12],
        |r| r.below(2001) as i32 - 1000,
        &[vec![i32::MIN, i32::MAX, -1, 0, 1, i32::MIN, -1]],
    );
}

#[test]
fn sort_f32_total_order() {
    let specials = F32_SPECIALS.to_vec();
    sort_cases::<f32>(
        ballot(),
        &[32],
        |r| (r.below(41) as f32 - 20.0) * 0.25,
        &[specials],
    );
}

#[test]
fn sort_odd_tile() {
    let odd = sort_config(SortVariant::Ballot, ODD_TILE);
    // 600 tiles: more than the histogram kernel's blocks, so that some count two tiles.
    let mut r = Rng(7);
    let many: Vec<u32> = (0..600 * 48).map(|_| r.below(1000) as u32).collect();
    let upsweep = &plan::sort(odd, "u32", 32, Len::Host(many.len() as u64)).steps[1];
    assert!(upsweep.blocks < 600, "{upsweep:?}");
    sort_cases::<u32>(odd, &[32, 7, 21], |r| r.below(1000) as u32, &[many]);
    sort_cases::<f32>(odd, &[32], |r| (r.below(41) as f32 - 20.0) * 0.25, &[]);
}

/// The other kernels give the same results (bit for bit: the reference is a stable sort):
/// ranking by `__match_any_sync`, the 4-bit counting passes, warp ballots in a block of three
/// warps, and the layout of large tiles (the warps' counts in the sorted keys' memory, which
/// small tiles take only when told to).
#[test]
fn sort_variants_agree() {
    let dup = |r: &mut Rng| (r.below(37) as u32) * 0x0101_0101;
    for config in [
        sort_config(SortVariant::MatchAny, TILE),
        sort_config(SortVariant::Nibbles, TILE),
        sort_config(SortVariant::Ballot, WARPS_TILE),
    ] {
        sort_cases::<u32>(config, &[32, 21, 5], dup, &[]);
    }
    sort_cases_with::<u32>(
        sort_config(SortVariant::Ballot, WARPS_TILE),
        &["WP_PRIM_SORT_SHARE_COUNTS=1"],
        &[32, 21],
        dup,
        &[],
    );
    sort_cases::<f32>(
        sort_config(SortVariant::MatchAny, WARPS_TILE),
        &[32],
        |r| (r.below(41) as f32 - 20.0) * 0.25,
        &[F32_SPECIALS.to_vec()],
    );
}

// ------------------------------------------------------------------------------------------
// Compaction
// ------------------------------------------------------------------------------------------

fn compact_cases(word: u32, words: u32) {
    if !have_gpp() {
        return;
    }
    let size = (word * words) as usize;
    let mut rng = Rng(0xc0ffee ^ size as u64);
    let mut cases = Vec::new();
    let mut want = Vec::new();
    for &n in &sizes(TILE) {
        for density in [0, 1, 2, 4] {
            let values: Vec<u8> = (0..n * size).map(|_| rng.next() as u8).collect();
            // density 0: keep nothing; 4: keep everything; else about 1/density... of them.
            let flags: Vec<i32> = (0..n)
                .map(|_| match density {
                    0 => 0,
                    4 => -7,
                    d => (rng.below(d) == 0) as i32 * (rng.below(5) as i32 + 1),
                })
                .collect();
            let out0: Vec<u8> = (0..(n + 2) * size).map(|_| rng.next() as u8).collect();
            for device_count in [false, true] {
                let (count, len, mut users) = if device_count {
                    let c = rng.below(n as u64 + 1) as usize;
                    let len = Len::Device {
                        count: 4,
                        capacity: n as u64,
                        arg: 4,
                    };
                    (c, len, vec![bytes(&[c as i32])])
                } else {
                    (n, Len::Host(n as u64), vec![])
                };
                users.splice(
                    0..0,
                    [values.clone(), bytes(&flags), out0.clone(), bytes(&[-5i32])],
                );
                cases.push(Case {
                    plan: plan::compact(TILE, word, words, len),
                    users,
                });
                let mut w = out0.clone();
                let mut kept = 0;
                for i in 0..count {
                    if flags[i] != 0 {
                        w[kept * size..(kept + 1) * size]
                            .copy_from_slice(&values[i * size..(i + 1) * size]);
                        kept += 1;
                    }
                }
                want.push((
                    w,
                    kept as i32,
                    format!("n {n} count {count} density {density}"),
                ));
            }
        }
    }
    for (r, (w, kept, what)) in run(TILE, &cases).iter().zip(&want) {
        assert_eq!(r.fault, None, "{what}");
        assert_eq!(typed::<i32>(&r.users[3]), vec![*kept], "count, {what}");
        assert_eq!(&r.users[2], w, "{word}x{words} out, {what}");
    }
}

#[test]
fn compact_bytes_halves_vec3_dvec2() {
    compact_cases(1, 1);
    compact_cases(2, 1);
    compact_cases(4, 3);
    compact_cases(8, 2);
}

// ------------------------------------------------------------------------------------------
// Device counts out of range
// ------------------------------------------------------------------------------------------

/// A device count outside 0..=capacity is one fault (OutOfBounds on the count argument,
/// index [count], shape [capacity + 1]) and nothing is written.
#[test]
fn bad_device_counts_fault_and_write_nothing() {
    if !have_gpp() {
        return;
    }
    let x: Vec<i32> = (0..300).collect();
    let out0 = vec![-1i32; 300];
    for bad in [301, -1, i32::MAX] {
        let len = Len::Device {
            count: 2,
            capacity: 300,
            arg: 2,
        };
        let ran = run(
            TILE,
            &[
                Case {
                    plan: plan::scan(TILE, "i32", 4, len, true),
                    users: vec![bytes(&x), bytes(&out0), bytes(&[bad])],
                },
                Case {
                    plan: plan::reduce(TILE, "i32", 4, ReduceOp::Sum, len),
                    users: vec![bytes(&x), bytes(&[-1i32]), bytes(&[bad])],
                },
                Case {
                    plan: plan::scan_onepass(TILE, "i32", 4, len, true),
                    users: vec![bytes(&x), bytes(&out0), bytes(&[bad])],
                },
            ],
        );
        for k in [0, 2] {
            assert_eq!(ran[k].fault, Some((1, 2, bad as i64, 301)), "case {k}");
            assert_eq!(
                typed::<i32>(&ran[k].users[1]),
                out0,
                "scan (case {k}) wrote with count {bad}"
            );
        }
        assert_eq!(ran[1].fault, Some((1, 2, bad as i64, 301)));
        // A reduction of "nothing": the identity (the plan cannot skip writing `out`).
        assert_eq!(typed::<i32>(&ran[1].users[1]), vec![0]);

        let keys: Vec<u32> = (0..300).rev().collect();
        let ran = run(
            TILE,
            &[Case {
                plan: plan::sort(ballot(), "u32", 32, len),
                users: vec![bytes(&keys), bytes(&x), bytes(&[bad])],
            }],
        );
        assert_eq!(ran[0].fault, Some((1, 2, bad as i64, 301)));
        assert_eq!(typed::<u32>(&ran[0].users[0]), keys, "sort moved keys");

        let len = Len::Device {
            count: 4,
            capacity: 300,
            arg: 4,
        };
        let ran = run(
            TILE,
            &[Case {
                plan: plan::compact(TILE, 4, 1, len),
                users: vec![
                    bytes(&x),
                    bytes(&vec![1i32; 300]),
                    bytes(&out0),
                    bytes(&[-3i32]),
                    bytes(&[bad]),
                ],
            }],
        );
        assert_eq!(ran[0].fault, Some((1, 4, bad as i64, 301)));
        assert_eq!(typed::<i32>(&ran[0].users[2]), out0, "compact wrote");
        assert_eq!(typed::<i32>(&ran[0].users[3]), vec![0]);
    }
}

// ------------------------------------------------------------------------------------------
// NVRTC
// ------------------------------------------------------------------------------------------

/// Every module the runtime may build compiles with NVRTC for the GPUs of the benchmarks
/// (sm_90: H100, H200) and an older one (sm_80: A100), with the runtime's options. Needs
/// only libnvrtc, no GPU; skipped, saying so, without it.
#[test]
fn nvrtc_compiles_every_module() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED nvrtc_compiles_every_module: {e}");
        return;
    }
    // Each scan type in its default block shape and in the three-phase scan's 256 x 8.
    let mut modules: Vec<Module> = [
        ("i32", 4),
        ("u32", 4),
        ("i64", 8),
        ("u64", 8),
        ("f32", 4),
        ("f64", 8),
    ]
    .into_iter()
    .flat_map(|(t, size)| {
        [
            Module::Scan(t, plan::default_gpu_scan(t, size).1),
            Module::Scan(t, plan::GPU_TILE),
        ]
    })
    .collect();
    modules.dedup();
    let gpu = plan::GPU_SORT;
    modules.extend(["u32", "i32", "f32"].map(|k| Module::Sort(k, gpu)));
    // The other kernels, and a block of 384 threads (12 keys each: the keys and values of a
    // tile stay within the 48 KiB of static shared memory).
    let big = Tile {
        threads: 384,
        items: 12,
    };
    // (The 4-bit counting passes keep a count per thread and nibble beside the tile: the
    // benchmarks' 256 x 16 fits the 48 KiB of static shared memory, the default 512 x 8 does
    // not.)
    let nibbles = Tile {
        threads: 256,
        items: 16,
    };
    for (variant, tile) in [
        (SortVariant::MatchAny, gpu.tile),
        (SortVariant::Nibbles, nibbles),
        (SortVariant::Ballot, big),
    ] {
        modules.push(Module::Sort(
            "u32",
            SortConfig {
                variant,
                tile,
                min_blocks: 2,
            },
        ));
    }
    // The scans' largest block shapes (the spatial bench times them): 8192 elements of a
    // 4-byte type, 4096 of an 8-byte one, in the static shared memory.
    for (t, threads, items) in [("f32", 1024, 8), ("f32", 512, 16), ("f64", 512, 8)] {
        modules.push(Module::Scan(t, Tile { threads, items }));
    }
    for word in [1, 2, 4, 8] {
        for words in [1, 3] {
            modules.push(Module::Compact { word, words });
        }
    }
    for arch in [90, 80] {
        for m in &modules {
            let c = wp::primitives::compile_module(m, arch)
                .unwrap_or_else(|e| panic!("{} for sm_{arch}: {e}", m.name()));
            assert!(!c.cubin.is_empty());
            assert!(
                !c.log.contains("warning"),
                "{} for sm_{arch}: {}",
                m.name(),
                c.log
            );
        }
    }
}
