//! The CUDA tile library (`warp-cuda/cuda/wp_tile.h`), checked without a GPU against the CPU's
//! tiles (`warp_core::tile`), bit for bit.
//!
//! A small driver (`warp-cuda/cuda/tests/wp_tile_driver.cpp`) runs the header's cooperative
//! operations in one block under the block emulator (`wp_prim_emu.h`: the block's threads are
//! fibers, `__syncthreads` a barrier, `__shfl_down_sync` an exchange among a warp's 32 lanes).
//! It is compiled with g++ for several block sizes (`-DWP_TILE_BLOCK_DIM`): 1 (sequential), a
//! warp, 45 (a partial second warp), 96 and 256 (three and eight warps); each result is
//! compared with warp-core's function for the same block size. Sums of order-sensitive data
//! (a large value followed by ones) differ between block sizes, so agreeing for each shows the
//! order is the same, not merely the value. What this cannot check is what only hardware does:
//! NVRTC's acceptance of the header, real warps and shared memory.
//!
//! Skipped, saying so, without g++.

#[path = "common/host_cpp.rs"]
mod host_cpp;

use std::collections::HashMap;
use std::path::PathBuf;
use std::process::Command;
use std::sync::{Arc, Mutex, OnceLock};
use warp_core::tile::{self, Tile, Tile1, Tile2, Tile3, Tile4};
use warp_core::ArrayView;

/// The block sizes every test runs.
const BLOCK_DIMS: [usize; 5] = [1, 32, 45, 96, 256];

fn have_gpp() -> bool {
    static HAVE: OnceLock<bool> = OnceLock::new();
    *HAVE.get_or_init(|| {
        let ok = host_cpp::gpp();
        if !ok {
            eprintln!("SKIPPED cuda_tile_host: no g++ on this machine");
        }
        ok
    })
}

/// The driver compiled for block size `bd` (built once per process).
fn executable(bd: usize) -> Arc<PathBuf> {
    type Slot = Arc<Mutex<Option<Arc<PathBuf>>>>;
    static BUILT: OnceLock<Mutex<HashMap<usize, Slot>>> = OnceLock::new();
    let slot = BUILT
        .get_or_init(Default::default)
        .lock()
        .unwrap()
        .entry(bd)
        .or_default()
        .clone();
    let mut slot = slot.lock().unwrap();
    if let Some(exe) = slot.as_ref() {
        return exe.clone();
    }
    let (_dir, exe) = host_cpp::compile_driver(
        &format!("tile_{bd}"),
        include_str!("../warp-cuda/cuda/tests/wp_tile_driver.cpp"),
        &[&format!("WP_TILE_BLOCK_DIM={bd}")],
    );
    let exe = Arc::new(exe);
    *slot = Some(exe.clone());
    exe
}

fn hex(bytes: &[u8]) -> String {
    if bytes.is_empty() {
        return "-".into();
    }
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn bytes<T: bytemuck::Pod>(v: &[T]) -> Vec<u8> {
    bytemuck::cast_slice(v).to_vec()
}

fn typed<T: bytemuck::Pod>(b: &[u8]) -> Vec<T> {
    b.chunks_exact(std::mem::size_of::<T>())
        .map(bytemuck::pod_read_unaligned)
        .collect()
}

/// A driver script; `outputs` counts the lines of output it asks for.
#[derive(Default)]
struct Script {
    text: String,
    outputs: usize,
}

impl Script {
    /// Array argument `kind` (`f1 f2 d1 d2 i1`) number `slot`.
    fn arr<T: bytemuck::Pod>(&mut self, kind: &str, slot: usize, shape: &[usize], data: &[T]) {
        assert_eq!(shape.iter().product::<usize>(), data.len());
        let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
        self.text += &format!(
            "arr {kind} {slot} {} {}\n",
            dims.join(" "),
            hex(&bytes(data))
        );
    }
    /// Array argument `kind` number `slot` over `data` with the given shape and strides (in
    /// elements; the driver takes bytes): `data` must hold every element the view reaches.
    fn arr_strided<T: bytemuck::Pod>(
        &mut self,
        kind: &str,
        slot: usize,
        shape: &[usize],
        strides: &[isize],
        data: &[T],
    ) {
        let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
        let sz = std::mem::size_of::<T>() as isize;
        let st: Vec<String> = strides.iter().map(|s| (s * sz).to_string()).collect();
        self.text += &format!(
            "arr {kind} {slot} {} {}\nstrides {kind} {slot} {}\n",
            dims.join(" "),
            hex(&bytes(data)),
            st.join(" ")
        );
    }
    fn off(&mut self, o: [i64; 4]) {
        self.text += &format!("off {} {} {} {}\n", o[0], o[1], o[2], o[3]);
    }
    fn scal(&mut self, s: [f32; 3]) {
        self.text += &format!(
            "scal {:08x} {:08x} {:08x}\n",
            s[0].to_bits(),
            s[1].to_bits(),
            s[2].to_bits()
        );
    }
    fn run(&mut self, kernel: &str) {
        self.text += &format!("run {kernel}\n");
        self.outputs += 1;
    }
    fn dump(&mut self, kind: &str, slot: usize) {
        self.text += &format!("dump {kind} {slot}\n");
        self.outputs += 1;
    }

    /// Runs the script for block size `bd`: the outputs of `run` and `dump`, in order. A fault
    /// fails the test (no case here faults).
    fn exec(&self, bd: usize) -> Vec<Vec<u8>> {
        let exe = executable(bd);
        let path = exe.with_file_name(format!("script_{:?}.txt", std::thread::current().id()));
        std::fs::write(&path, &self.text).unwrap();
        let out = Command::new(exe.as_path()).arg(&path).output().unwrap();
        assert!(
            out.status.success(),
            "driver (block size {bd}) failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8(out.stdout).unwrap();
        let mut got = Vec::new();
        for l in text.lines() {
            let (tag, rest) = l.split_once(' ').unwrap_or((l, ""));
            match tag {
                "out" | "dump" => got.push(unhex(rest)),
                "nofault" => {}
                _ => panic!("block size {bd}: unexpected driver line {l}"),
            }
        }
        assert_eq!(got.len(), self.outputs, "block size {bd}");
        got
    }
}

/// A view of `data` with the given shape (row-major, contiguous).
fn view<T: Copy, const N: usize>(data: &mut [T], shape: [usize; N]) -> ArrayView<T, N> {
    let mut strides = [0isize; N];
    let mut s = 1isize;
    for k in (0..N).rev() {
        strides[k] = s;
        s *= shape[k] as isize;
    }
    assert_eq!(s as usize, data.len());
    // SAFETY: every caller keeps `data` alive and unmoved while it uses the view.
    unsafe { ArrayView::new(data.as_mut_ptr(), shape, strides, "k", "a") }
}

/// A view of `data` with the given shape and strides (in elements, non-negative).
fn view_strided<T: Copy, const N: usize>(
    data: &mut [T],
    shape: [usize; N],
    strides: [isize; N],
) -> ArrayView<T, N> {
    let last: isize = (0..N).map(|k| (shape[k] as isize - 1) * strides[k]).sum();
    assert!(shape.contains(&0) || (last as usize) < data.len());
    // SAFETY: as `view`; every in-bounds index addresses an element of `data` (checked above).
    unsafe { ArrayView::new(data.as_mut_ptr(), shape, strides, "k", "a") }
}

/// Seeded draws (the benches' generator: ChaCha8), shaped for order-sensitive sums.
struct Rng(rand_chacha::ChaCha8Rng);

impl Rng {
    fn seeded(seed: u64) -> Self {
        Rng(<rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(seed))
    }
    fn next(&mut self) -> u64 {
        rand::RngCore::next_u64(&mut self.0)
    }
    /// In [-1, 1) with a full mantissa, times 2^e for e in -8..8 (a spread of magnitudes, so
    /// sums round differently in different orders).
    fn f32(&mut self) -> f32 {
        let m = (self.next() >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0;
        m * 2f32.powi((self.next() % 16) as i32 - 8)
    }
    fn f64(&mut self) -> f64 {
        let m = (self.next() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
        m * 2f64.powi((self.next() % 40) as i32 - 20)
    }
}

fn flat<X: Tile<Elem: bytemuck::Pod>>(t: &X) -> Vec<u8> {
    bytes(t.as_flat())
}

// ------------------------------------------------------------------------------------------
// Loads and stores
// ------------------------------------------------------------------------------------------

#[test]
fn loads_and_stores_with_ragged_and_negative_offsets_match() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0x5eed_0001);
    let mut script = Script::default();
    // (tile bytes, array after the store) per run, from warp-core.
    let mut want: Vec<(Vec<u8>, Vec<u8>, String)> = Vec::new();
    // Rank 1: a Tile1<f32, 37> loaded from `a` at `o` and stored into `b` at `p`.
    for n in [0usize, 5, 37, 50, 100] {
        for (o, p) in [
            (0i64, 0i64),
            (-1, 3),
            (-5, -36),
            (-40, -37),
            (3, 60),
            (n as i64 - 2, n as i64 - 40),
            (n as i64 + 1, -1),
            (i64::MIN, i64::MAX),
            (i64::MAX, i64::MIN),
        ] {
            let mut a: Vec<f32> = (0..n).map(|_| rng.f32()).collect();
            let m = 61;
            let mut b: Vec<f32> = (0..m).map(|i| -(i as f32) - 0.5).collect();
            script.arr("f1", 0, &[n], &a);
            script.arr("f1", 1, &[m], &b);
            script.off([o, p, 0, 0]);
            script.run("load1");
            script.dump("f1", 1);
            let t: Tile1<f32, 37> = tile::load1(&view(&mut a, [n]), o).unwrap();
            tile::store1(&view(&mut b, [m]), p, &t).unwrap();
            want.push((flat(&t), bytes(&b), format!("load1 n {n} o {o} p {p}")));
        }
    }
    // Rank 2: a Tile2<f32, 5, 7> loaded from `a` at (o0, o1), stored into `b` at (p0, p1).
    for shape in [[4usize, 6], [9, 10], [0, 3], [5, 7]] {
        for o in [
            [0i64, 0, 0, 0],
            [-3, -2, 1, 4],
            [2, 3, -4, -6],
            [-1, 5, 3, -2],
            [i64::MIN, 0, 0, i64::MAX],
            [1, i64::MAX, i64::MIN, 1],
            [-5, -7, 6, 5],
        ] {
            let mut a: Vec<f32> = (0..shape[0] * shape[1]).map(|_| rng.f32()).collect();
            let bs = [6usize, 5];
            let mut b: Vec<f32> = (0..30).map(|i| i as f32 + 0.25).collect();
            script.arr("f2", 0, &shape, &a);
            script.arr("f2", 1, &bs, &b);
            script.off(o);
            script.run("load2");
            script.dump("f2", 1);
            let t: Tile2<f32, 5, 7> = tile::load2(&view(&mut a, shape), o[0], o[1]).unwrap();
            tile::store2(&view(&mut b, bs), o[2], o[3], &t).unwrap();
            want.push((flat(&t), bytes(&b), format!("load2 {shape:?} at {o:?}")));
        }
    }
    for bd in BLOCK_DIMS {
        let got = script.exec(bd);
        for (k, (t, b, what)) in want.iter().enumerate() {
            assert_eq!(&got[2 * k], t, "tile, {what}, block size {bd}");
            assert_eq!(&got[2 * k + 1], b, "stored array, {what}, block size {bd}");
        }
    }
}

/// Rank 3 and 4: loads and stores at offsets crossing both ends of every axis (and the i64
/// extremes), an element read, and (rank 3) an atomic add with its old values, against
/// warp-core's `load3`/`store3`/`extract`/`atomic_add3` and `load4`/`store4`, bit for bit.
#[test]
fn loads_and_stores_rank_3_and_4() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0x5eed_0341);
    let mut script = Script::default();
    let mut want: Vec<(Vec<u8>, Vec<u8>, String)> = Vec::new();
    for shape in [[4usize, 5, 6], [2, 3, 4], [3, 4, 5]] {
        for o in [
            [0i64, 0, 0, 0],
            [-1, 2, -3, 1],
            [2, -2, 3, -4],
            [1, 1, 1, 3],
            [i64::MIN, 0, 1, i64::MAX],
        ] {
            let n: usize = shape.iter().product();
            let mut a: Vec<f32> = (0..n).map(|_| rng.f32()).collect();
            let mut b: Vec<f32> = (0..n).map(|i| i as f32 + 0.25).collect();
            script.arr("f3", 0, &shape, &a);
            script.arr("f3", 1, &shape, &b);
            script.off(o);
            script.run("load3");
            script.dump("f3", 1);
            let t: Tile3<f32, 3, 4, 5> =
                tile::load3(&view(&mut a, shape), o[0], o[1], o[2]).unwrap();
            let bv = view(&mut b, shape);
            tile::store3(&bv, o[1], o[2], o[3], &t).unwrap();
            let x = t.extract((o[3] & 1) as i32, 2u32, 4i64, "k").unwrap();
            let old = tile::atomic_add3(&bv, o[2], o[3], o[0], &t).unwrap();
            let mut out = flat(&t);
            out.extend(bytes(&[x]));
            out.extend(flat(&old));
            want.push((out, bytes(&b), format!("load3 {shape:?} at {o:?}")));
        }
    }
    for shape in [[2usize, 3, 2, 3], [3, 2, 4, 2], [1, 4, 3, 5]] {
        for o in [
            [0i64, 0, 0, 0],
            [1, -1, 1, -2],
            [-1, 2, -1, 1],
            [0, 1, 2, 3],
        ] {
            let n: usize = shape.iter().product();
            let mut a: Vec<f32> = (0..n).map(|_| rng.f32()).collect();
            let mut b: Vec<f32> = (0..n).map(|i| -(i as f32)).collect();
            script.arr("f4", 0, &shape, &a);
            script.arr("f4", 1, &shape, &b);
            script.off(o);
            script.run("load4");
            script.dump("f4", 1);
            let t: Tile4<f32, 2, 3, 2, 3> =
                tile::load4(&view(&mut a, shape), o[0], o[1], o[2], o[3]).unwrap();
            tile::store4(&view(&mut b, shape), o[3], o[2], o[1], o[0], &t).unwrap();
            let mut out = flat(&t);
            out.extend(bytes(&[t.extract(1, 2, 0, 2, "k").unwrap()]));
            want.push((out, bytes(&b), format!("load4 {shape:?} at {o:?}")));
        }
    }
    for bd in BLOCK_DIMS {
        let got = script.exec(bd);
        for (k, (t, b, what)) in want.iter().enumerate() {
            assert_eq!(&got[2 * k], t, "tile, {what}, block size {bd}");
            assert_eq!(&got[2 * k + 1], b, "stored array, {what}, block size {bd}");
        }
    }
}

// ------------------------------------------------------------------------------------------
// Reductions
// ------------------------------------------------------------------------------------------

/// `[sum, min, max]` of `t` for block size `bd`, as warp-core computes them.
fn reductions<X: Tile<Elem: warp_core::builtins::MinMax + bytemuck::Pod>>(
    t: &X,
    bd: usize,
) -> Vec<u8>
where
    X::Elem: warp_core::builtins::Scalar,
{
    let mut v = bytes(&tile::sum(t, bd).data);
    v.extend(bytes(&tile::min(t, bd).data));
    v.extend(bytes(&tile::max(t, bd).data));
    v
}

#[test]
fn reductions_match_warp_core_bit_for_bit() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0x5eed_0002);
    let mut script = Script::default();
    // Per run: the expected bytes for each block size.
    let mut want: Vec<(Vec<Vec<u8>>, String)> = Vec::new();
    let per_bd = |f: &dyn Fn(usize) -> Vec<u8>| BLOCK_DIMS.iter().map(|&bd| f(bd)).collect();

    // Tile1<f32, 300> from arrays of 300 or fewer elements (zero padding).
    let mut f32_300: Vec<(Vec<f32>, &str)> = vec![
        (
            std::iter::once(1e8)
                .chain(std::iter::repeat_n(1.0, 299))
                .collect(),
            "1e8 then ones",
        ),
        (
            std::iter::repeat_n(1.0, 299)
                .chain(std::iter::once(1e8))
                .collect(),
            "ones then 1e8",
        ),
        ((0..300).map(|_| rng.f32()).collect(), "random"),
        ((0..77).map(|_| rng.f32()).collect(), "77 random, padded"),
        (vec![-0.0; 300], "negative zeros"),
    ];
    let mut spiky: Vec<f32> = (0..300).map(|_| rng.f32()).collect();
    spiky[123] = f32::NAN;
    spiky[7] = 3e38;
    spiky[290] = -3e38;
    f32_300.push((spiky, "NaN and large values"));
    let mut sums_1e8 = Vec::new();
    for (x, what) in &f32_300 {
        let mut x = x.clone();
        let n = x.len();
        script.arr("f1", 0, &[n], &x);
        script.run("red_f32_300");
        let t: Tile1<f32, 300> = tile::load1(&view(&mut x, [n]), 0).unwrap();
        if *what == "1e8 then ones" {
            sums_1e8 = BLOCK_DIMS.map(|bd| tile::sum(&t, bd).data[0]).to_vec();
        }
        want.push((per_bd(&|bd| reductions(&t, bd)), format!("f32 x300 {what}")));
    }
    // Sequentially every 1.0 after 1e8 is lost; with many lanes they are summed first. The
    // test only shows the order if the block sizes disagree.
    assert_eq!(sums_1e8[0], 1e8);
    assert!(sums_1e8.iter().any(|&s| s != 1e8), "{sums_1e8:?}");

    // Tile1<f32, 5>: fewer elements than lanes.
    for _ in 0..3 {
        let mut x: Vec<f32> = (0..5).map(|_| rng.f32()).collect();
        script.arr("f1", 0, &[5], &x);
        script.run("red_f32_5");
        let t: Tile1<f32, 5> = tile::load1(&view(&mut x, [5]), 0).unwrap();
        want.push((per_bd(&|bd| reductions(&t, bd)), "f32 x5".into()));
    }
    // Tile2<f32, 13, 11>: row-major order over two axes.
    for _ in 0..3 {
        let mut x: Vec<f32> = (0..143).map(|_| rng.f32()).collect();
        x[0] = 1e9;
        script.arr("f2", 0, &[13, 11], &x);
        script.run("red_f32_2d");
        let t: Tile2<f32, 13, 11> = tile::load2(&view(&mut x, [13, 11]), 0, 0).unwrap();
        want.push((per_bd(&|bd| reductions(&t, bd)), "f32 13x11".into()));
    }
    // Tile1<i32, 200>: wrapping sums.
    for spread in [1000u64, 1 << 32] {
        let mut x: Vec<i32> = (0..200)
            .map(|_| (rng.next() % spread) as i64 as i32)
            .collect();
        script.arr("i1", 0, &[200], &x);
        script.run("red_i32");
        let t: Tile1<i32, 200> = tile::load1(&view(&mut x, [200]), 0).unwrap();
        want.push((
            per_bd(&|bd| reductions(&t, bd)),
            format!("i32 spread {spread}"),
        ));
    }
    // Tile1<f64, 150>.
    for big in [false, true] {
        let mut x: Vec<f64> = (0..150).map(|_| rng.f64()).collect();
        if big {
            x[0] = 1e17;
        }
        script.arr("d1", 0, &[150], &x);
        script.run("red_f64");
        let t: Tile1<f64, 150> = tile::load1(&view(&mut x, [150]), 0).unwrap();
        want.push((per_bd(&|bd| reductions(&t, bd)), format!("f64 big {big}")));
    }

    for (i, bd) in BLOCK_DIMS.into_iter().enumerate() {
        let got = script.exec(bd);
        for (k, (w, what)) in want.iter().enumerate() {
            assert_eq!(got[k], w[i], "{what}, block size {bd}");
        }
    }
}

/// `[argmin, argmax]` of `t` for block size `bd`, as warp-core computes them, checked first
/// against the plain definition: the first index of the extremum among the numbers (NaNs only
/// when all are, index 0 then; `-0` ties with `+0`).
fn arg_reductions<X: Tile<Elem: warp_core::builtins::Scalar>>(t: &X, bd: usize) -> Vec<u8> {
    let x = t.as_flat();
    #[allow(clippy::eq_op)] // `v == v` is false exactly for NaN
    let first = |better: &dyn Fn(&X::Elem, &X::Elem) -> bool| {
        let mut best: Option<usize> = None;
        for (e, v) in x.iter().enumerate() {
            if v == v && best.is_none_or(|b| better(v, &x[b])) {
                best = Some(e);
            }
        }
        best.unwrap_or(0) as i32
    };
    let (lo, hi) = (tile::argmin(t, bd).data[0], tile::argmax(t, bd).data[0]);
    assert_eq!(
        lo,
        first(&|a, b| a < b),
        "warp-core argmin, block size {bd}"
    );
    assert_eq!(
        hi,
        first(&|a, b| a > b),
        "warp-core argmax, block size {bd}"
    );
    bytes(&[lo, hi])
}

#[test]
fn argmin_argmax_match_warp_core() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0x5eed_0005);
    let mut script = Script::default();
    let mut want: Vec<(Vec<Vec<u8>>, String)> = Vec::new();
    let per_bd = |f: &dyn Fn(usize) -> Vec<u8>| BLOCK_DIMS.iter().map(|&bd| f(bd)).collect();
    let nan = f32::NAN;

    // Tile1<f32, 300> (arrays shorter than 300 are zero padded: the padding ties).
    let mut cases: Vec<(Vec<f32>, &str)> = Vec::new();
    let mut ties: Vec<f32> = (0..300).map(|_| rng.f32()).collect();
    for e in [299, 37, 200, 5, 133] {
        ties[e] = -500.0;
    }
    for e in [250, 64, 31, 290] {
        ties[e] = 500.0;
    }
    cases.push((ties, "ties across lanes and warps"));
    let mut nans: Vec<f32> = (0..300).map(|_| rng.f32()).collect();
    for e in (0..300).step_by(7) {
        nans[e] = nan;
    }
    nans[1] = -f32::NAN;
    cases.push((nans, "NaNs, one at index 0"));
    let mut nan_extreme = vec![nan; 300];
    nan_extreme[299] = 1.0;
    nan_extreme[150] = 1.0;
    nan_extreme[45] = -1.0;
    cases.push((nan_extreme, "NaNs but three"));
    cases.push((vec![nan; 300], "all NaN"));
    let mut all_neg_nan = vec![-f32::NAN; 300];
    all_neg_nan[17] = f32::from_bits(0x7fc0_0001);
    cases.push((all_neg_nan, "all NaN, mixed signs and payloads"));
    let zeros: Vec<f32> = (0..300)
        .map(|e| if e % 3 == 1 { -0.0 } else { 0.0 })
        .collect();
    cases.push((zeros, "+0 and -0"));
    let neg_first: Vec<f32> = (0..300)
        .map(|e| if e % 5 == 0 { -0.0 } else { 1.0 })
        .collect();
    cases.push((neg_first, "-0 first, ties with ones"));
    let mut inf = vec![f32::INFINITY; 300];
    inf[100] = f32::NEG_INFINITY;
    inf[3] = nan;
    cases.push((inf, "infinities"));
    cases.push(((0..77).map(|_| rng.f32()).collect(), "77 random, padded"));
    cases.push((
        (0..300).map(|_| (rng.next() % 4) as f32 - 1.5).collect(),
        "four values, many ties",
    ));
    for (x, what) in &cases {
        let mut x = x.clone();
        let n = x.len();
        script.arr("f1", 0, &[n], &x);
        script.run("arg_f32_300");
        let t: Tile1<f32, 300> = tile::load1(&view(&mut x, [n]), 0).unwrap();
        want.push((
            per_bd(&|bd| arg_reductions(&t, bd)),
            format!("f32 x300 {what}"),
        ));
    }
    // Tile1<f32, 5>: fewer elements than lanes.
    for x in [
        [nan, 2.0, -1.0, -1.0, 2.0],
        [nan; 5],
        [0.0, -0.0, nan, -0.0, 0.0],
        [3.0, nan, 3.0, 3.0, nan],
    ] {
        let mut x = x.to_vec();
        script.arr("f1", 0, &[5], &x);
        script.run("arg_f32_5");
        let t: Tile1<f32, 5> = tile::load1(&view(&mut x, [5]), 0).unwrap();
        want.push((
            per_bd(&|bd| arg_reductions(&t, bd)),
            format!("f32 x5 {x:?}"),
        ));
    }
    // Tile2<f32, 13, 11>: row-major indices over two axes.
    for k in 0..3 {
        let mut x: Vec<f32> = (0..143).map(|_| (rng.next() % 9) as f32).collect();
        if k == 1 {
            x.iter_mut().step_by(4).for_each(|v| *v = nan);
        }
        if k == 2 {
            x = vec![nan; 143];
        }
        script.arr("f2", 0, &[13, 11], &x);
        script.run("arg_f32_2d");
        let t: Tile2<f32, 13, 11> = tile::load2(&view(&mut x, [13, 11]), 0, 0).unwrap();
        want.push((
            per_bd(&|bd| arg_reductions(&t, bd)),
            format!("f32 13x11 case {k}"),
        ));
    }
    // Tile1<i32, 200>: ties, and the extremes of i32.
    for k in 0..4 {
        let mut x: Vec<i32> = match k {
            0 => (0..200).map(|_| (rng.next() % 5) as i32 - 2).collect(),
            1 => (0..200).map(|_| rng.next() as i32).collect(),
            2 => vec![7; 200],
            _ => (0..200)
                .map(|e| match e % 3 {
                    0 => i32::MAX,
                    1 => i32::MIN,
                    _ => 0,
                })
                .rev()
                .collect(),
        };
        if k == 1 {
            x[190] = i32::MIN;
            x[60] = i32::MIN;
            x[33] = i32::MAX;
            x[199] = i32::MAX;
        }
        script.arr("i1", 0, &[200], &x);
        script.run("arg_i32");
        let t: Tile1<i32, 200> = tile::load1(&view(&mut x, [200]), 0).unwrap();
        want.push((
            per_bd(&|bd| arg_reductions(&t, bd)),
            format!("i32 case {k}"),
        ));
    }

    for (i, bd) in BLOCK_DIMS.into_iter().enumerate() {
        let got = script.exec(bd);
        for (k, (w, what)) in want.iter().enumerate() {
            assert_eq!(
                typed::<i32>(&got[k]),
                typed::<i32>(&w[i]),
                "{what}, block size {bd}"
            );
        }
    }
}

// ------------------------------------------------------------------------------------------
// Elementwise and constructors
// ------------------------------------------------------------------------------------------

#[test]
fn elementwise_and_constructors_match() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0x5eed_0003);
    let mut script = Script::default();
    let mut want = Vec::new();
    for s in [[1.5f32, 0.1, 0.1], [-3.25, -7.0, 0.3]] {
        let mut x: Vec<f32> = (0..40).map(|_| rng.f32()).collect();
        let mut y: Vec<f32> = (0..40).map(|_| rng.f32()).collect();
        script.arr("f1", 0, &[40], &x);
        script.arr("f1", 1, &[40], &y);
        script.scal(s);
        script.run("arith");
        let x: Tile1<f32, 40> = tile::load1(&view(&mut x, [40]), 0).unwrap();
        let y: Tile1<f32, 40> = tile::load1(&view(&mut y, [40]), 0).unwrap();
        let mut w = Vec::new();
        for t in [
            x + y,
            x - y,
            x * y,
            x + s[0],
            s[0] - x,
            x * s[0],
            Tile1::zeros(),
            Tile1::ones(),
            Tile1::arange(s[1], s[2]),
            x * y - x,
        ] {
            w.extend(flat(&t));
        }
        want.push(w);
    }
    // i32: wrapping arithmetic, and an arange that wraps.
    for s in [[7i32, -5, 3], [i32::MAX, i32::MAX - 20, 1 << 30]] {
        let mut x: Vec<i32> = (0..40).map(|_| rng.next() as i32).collect();
        let mut y: Vec<i32> = (0..40).map(|_| (rng.next() % 2001) as i32 - 1000).collect();
        x[0] = i32::MIN;
        y[0] = -1;
        script.arr("i1", 0, &[40], &x);
        script.arr("i1", 1, &[40], &y);
        script.scal(s.map(|v| f32::from_bits(v as u32)));
        script.run("arith_i32");
        let x: Tile1<i32, 40> = tile::load1(&view(&mut x, [40]), 0).unwrap();
        let y: Tile1<i32, 40> = tile::load1(&view(&mut y, [40]), 0).unwrap();
        let mut w = Vec::new();
        for t in [
            x + y,
            x - y,
            x * y,
            x + s[0],
            s[0] - x,
            x * s[0],
            Tile1::zeros(),
            Tile1::ones(),
            Tile1::arange(s[1], s[2]),
            x * y - x,
        ] {
            w.extend(flat(&t));
        }
        want.push(w);
    }
    for bd in BLOCK_DIMS {
        let got = script.exec(bd);
        for (k, w) in want.iter().enumerate() {
            let (g, w) = (typed::<u32>(&got[k]), typed::<u32>(w));
            for (e, (g, w)) in g.iter().zip(&w).enumerate() {
                assert_eq!(
                    g,
                    w,
                    "case {k}, result {} element {}, block size {bd}",
                    e / 40,
                    e % 40
                );
            }
        }
    }
}

#[test]
fn negation_matches() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0x5eed_0006);
    let mut x: Vec<f32> = (0..40).map(|_| rng.f32()).collect();
    x[..6].copy_from_slice(&[0.0, -0.0, f32::NAN, -f32::NAN, f32::INFINITY, f32::MIN]);
    x[6] = f32::from_bits(0x7f80_0001); // a signalling NaN
    let mut y: Vec<i32> = (0..40).map(|_| rng.next() as i32).collect();
    y[..4].copy_from_slice(&[i32::MIN, i32::MAX, 0, -1]);
    let mut script = Script::default();
    script.arr("f1", 0, &[40], &x);
    script.arr("i1", 0, &[40], &y);
    script.run("neg");
    let x: Tile1<f32, 40> = tile::load1(&view(&mut x, [40]), 0).unwrap();
    let y: Tile1<i32, 40> = tile::load1(&view(&mut y, [40]), 0).unwrap();
    assert_eq!((-x).data[1].to_bits(), 0.0f32.to_bits());
    assert_eq!((-y).data[0], i32::MIN);
    let mut w = flat(&-x);
    w.extend(flat(&-y));
    w.extend(flat(&-(-y)));
    for bd in BLOCK_DIMS {
        let got = script.exec(bd);
        assert_eq!(typed::<u32>(&got[0]), typed::<u32>(&w), "block size {bd}");
    }
}

// ------------------------------------------------------------------------------------------
// Matmul
// ------------------------------------------------------------------------------------------

#[test]
fn fma_matmul_matches() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0x5eed_0004);
    let mut script = Script::default();
    let mut want = Vec::new();
    for _ in 0..2 {
        let mut a: Vec<f32> = (0..7 * 13).map(|_| rng.f32()).collect();
        let mut b: Vec<f32> = (0..13 * 5).map(|_| rng.f32()).collect();
        let mut c: Vec<f32> = (0..7 * 5).map(|_| rng.f32()).collect();
        script.arr("f2", 0, &[7, 13], &a);
        script.arr("f2", 1, &[13, 5], &b);
        script.arr("f2", 2, &[7, 5], &c);
        script.run("matmul_f32");
        let a: Tile2<f32, 7, 13> = tile::load2(&view(&mut a, [7, 13]), 0, 0).unwrap();
        let b: Tile2<f32, 13, 5> = tile::load2(&view(&mut b, [13, 5]), 0, 0).unwrap();
        let mut c: Tile2<f32, 7, 5> = tile::load2(&view(&mut c, [7, 5]), 0, 0).unwrap();
        let mut w = flat(&tile::matmul(&a, &b));
        tile::matmul_acc(&a, &b, &mut c);
        w.extend(flat(&c));
        want.push(w);

        let mut a: Vec<f64> = (0..12).map(|_| rng.f64()).collect();
        let mut b: Vec<f64> = (0..24).map(|_| rng.f64()).collect();
        script.arr("d2", 0, &[3, 4], &a);
        script.arr("d2", 1, &[4, 6], &b);
        script.run("matmul_f64");
        let a: Tile2<f64, 3, 4> = tile::load2(&view(&mut a, [3, 4]), 0, 0).unwrap();
        let b: Tile2<f64, 4, 6> = tile::load2(&view(&mut b, [4, 6]), 0, 0).unwrap();
        want.push(flat(&tile::matmul(&a, &b)));
    }
    for bd in BLOCK_DIMS {
        let got = script.exec(bd);
        assert_eq!(got, want, "block size {bd}");
    }
}

/// The register-blocked matmul (every micro-tile plan the header picks for these shapes and
/// block sizes: 4 x 4 with vector reads of A and B, 4 x 2 and 2 x 1 with strided columns,
/// K not a multiple of the vector width, N odd, several rounds of micro-tiles per thread, and
/// the plain loop), with 16-byte aligned slots and with slots 4 bytes off (the scalar
/// fallback), against warp-core's FMA chains, bit for bit (tolerance: none).
#[test]
fn register_blocked_matmul_matches() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0x5eed_0007);
    let mut script = Script::default();
    let mut want: Vec<(Vec<u8>, String)> = Vec::new();
    macro_rules! case {
        ($t:ty, $kind:literal, $name:literal, $gen:ident, $m:literal, $k:literal, $n:literal) => {{
            let mut a: Vec<$t> = (0..$m * $k).map(|_| rng.$gen()).collect();
            let mut b: Vec<$t> = (0..$k * $n).map(|_| rng.$gen()).collect();
            let mut c: Vec<$t> = (0..$m * $n).map(|_| rng.$gen()).collect();
            let ta: Tile2<$t, $m, $k> = tile::load2(&view(&mut a, [$m, $k]), 0, 0).unwrap();
            let tb: Tile2<$t, $k, $n> = tile::load2(&view(&mut b, [$k, $n]), 0, 0).unwrap();
            let mut tc: Tile2<$t, $m, $n> = tile::load2(&view(&mut c, [$m, $n]), 0, 0).unwrap();
            let mut w = flat(&tile::matmul(&ta, &tb));
            tile::matmul_acc(&ta, &tb, &mut tc);
            w.extend(flat(&tc));
            for mis in ["", "_mis"] {
                script.arr($kind, 0, &[$m, $k], &a);
                script.arr($kind, 1, &[$k, $n], &b);
                script.arr($kind, 2, &[$m, $n], &c);
                let name = format!("mm_{}_{}x{}x{}{mis}", $name, $m, $k, $n);
                script.run(&name);
                want.push((w.clone(), name));
            }
        }};
    }
    for _ in 0..2 {
        case!(f32, "f2", "f32", f32, 64, 16, 64);
        case!(f32, "f2", "f32", f32, 32, 12, 24);
        case!(f32, "f2", "f32", f32, 24, 7, 20);
        case!(f32, "f2", "f32", f32, 12, 5, 9);
        case!(f32, "f2", "f32", f32, 16, 8, 6);
        case!(f64, "d2", "f64", f64, 16, 8, 16);
        case!(f64, "d2", "f64", f64, 8, 6, 10);
        case!(f64, "d2", "f64", f64, 64, 8, 64);
    }
    for bd in BLOCK_DIMS {
        let got = script.exec(bd);
        for (k, (w, what)) in want.iter().enumerate() {
            if got[k] != *w {
                let sz = if what.contains("f64") { 8 } else { 4 };
                let first = (0..w.len() / sz)
                    .find(|&e| got[k][e * sz..(e + 1) * sz] != w[e * sz..(e + 1) * sz])
                    .unwrap();
                panic!("{what}, block size {bd}: first differing output element {first}");
            }
        }
    }
}

/// The f16 matmul of wp_tile_mma.h on the host (its FMA path: the tensor cores are the GPU's):
/// `p = a b` rounded once to f16 and `c += a b` in f32, against warp-core's f16 matmul, bit for
/// bit (tolerance: none), for a shape the tensor cores would take on a GPU (32 x 16 x 32) and
/// one they would not (12 x 20 x 8).
#[test]
fn f16_matmul_fma_path_matches() {
    if !have_gpp() {
        return;
    }
    use warp_core::f16;
    let mut rng = Rng::seeded(0x5eed_0016);
    let mut script = Script::default();
    let mut want: Vec<(Vec<u8>, String)> = Vec::new();
    // f16 bits, little-endian (half's f16 is not bytemuck's Pod here).
    fn bits<X: Tile<Elem = f16>>(t: &X) -> Vec<u8> {
        t.as_flat()
            .iter()
            .flat_map(|x| x.to_bits().to_le_bytes())
            .collect()
    }
    macro_rules! case {
        ($m:literal, $k:literal, $n:literal) => {{
            let mut r = |len: usize| -> Vec<f32> {
                (0..len)
                    .map(|_| f16::from_f32(rng.f32()).to_f32())
                    .collect()
            };
            let (a, b, c) = (r($m * $k), r($k * $n), r($m * $n));
            let h = |v: &[f32], i: usize| f16::from_f32(v[i]);
            let ta = Tile2::<f16, $m, $k> {
                data: std::array::from_fn(|i| std::array::from_fn(|j| h(&a, i * $k + j))),
            };
            let tb = Tile2::<f16, $k, $n> {
                data: std::array::from_fn(|i| std::array::from_fn(|j| h(&b, i * $n + j))),
            };
            let mut tc = Tile2::<f32, $m, $n> {
                data: std::array::from_fn(|i| std::array::from_fn(|j| c[i * $n + j])),
            };
            let mut w = bits(&tile::matmul(&ta, &tb));
            tile::matmul_acc(&ta, &tb, &mut tc);
            w.extend(flat(&tc));
            script.arr("f2", 0, &[$m, $k], &a);
            script.arr("f2", 1, &[$k, $n], &b);
            script.arr("f2", 2, &[$m, $n], &c);
            let name = format!("mm16_{}x{}x{}", $m, $k, $n);
            script.run(&name);
            want.push((w, name));
        }};
    }
    for _ in 0..2 {
        case!(32, 16, 32);
        case!(12, 20, 8);
    }
    for bd in BLOCK_DIMS {
        let got = script.exec(bd);
        for (k, (w, what)) in want.iter().enumerate() {
            assert!(got[k] == *w, "{what}, block size {bd}");
        }
    }
}

/// wp_tile_mma.h's tensor-core path (device code for sm_80+, which no host driver runs)
/// type-checks for f16 and bf16 operands: `g++ -fsyntax-only` over
/// `cuda/tests/wp_tile_mma_syntax.cpp`, which fakes `__CUDA_ARCH__` and instantiates both
/// element types' matmuls on tensor-core shapes.
#[test]
fn tensor_core_path_type_checks_for_f16_and_bf16() {
    if !have_gpp() {
        return;
    }
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    let out = Command::new("g++")
        .args(["-std=c++17", "-fsyntax-only", "-ffp-contract=off"])
        .args(["-Wall", "-Wextra", "-Werror", "-DWP_TILE_BLOCK_DIM=64"])
        .args(["-I", include, "-I", &format!("{include}/tests")])
        .arg(format!("{include}/tests/wp_tile_mma_syntax.cpp"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "g++: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The bf16 matmul of wp_tile_mma.h on the host (its FMA path; the tensor cores are device-only): `p = a b`
/// rounded once to bf16 and `c += a b` in f32, against warp-core's bf16 matmul, bit for bit
/// (both are f32 chains of exact products in ascending k; the conversions are the same bit
/// operations), at every block size.
#[test]
fn bf16_matmul_fma_path_matches() {
    if !have_gpp() {
        return;
    }
    use warp_core::bf16;
    let mut rng = Rng::seeded(0x5eed_bf16);
    let mut script = Script::default();
    let mut want: Vec<(Vec<u8>, String)> = Vec::new();
    fn bits<X: Tile<Elem = bf16>>(t: &X) -> Vec<u8> {
        t.as_flat()
            .iter()
            .flat_map(|x| x.to_bits().to_le_bytes())
            .collect()
    }
    macro_rules! case {
        ($m:literal, $k:literal, $n:literal) => {{
            let mut r = |len: usize| -> Vec<f32> {
                (0..len)
                    .map(|_| bf16::from_f32(rng.f32()).to_f32())
                    .collect()
            };
            let (a, b, c) = (r($m * $k), r($k * $n), r($m * $n));
            let h = |v: &[f32], i: usize| bf16::from_f32(v[i]);
            let ta = Tile2::<bf16, $m, $k> {
                data: std::array::from_fn(|i| std::array::from_fn(|j| h(&a, i * $k + j))),
            };
            let tb = Tile2::<bf16, $k, $n> {
                data: std::array::from_fn(|i| std::array::from_fn(|j| h(&b, i * $n + j))),
            };
            let mut tc = Tile2::<f32, $m, $n> {
                data: std::array::from_fn(|i| std::array::from_fn(|j| c[i * $n + j])),
            };
            let mut w = bits(&tile::matmul(&ta, &tb));
            tile::matmul_acc(&ta, &tb, &mut tc);
            w.extend(flat(&tc));
            script.arr("f2", 0, &[$m, $k], &a);
            script.arr("f2", 1, &[$k, $n], &b);
            script.arr("f2", 2, &[$m, $n], &c);
            let name = format!("mmb16_{}x{}x{}", $m, $k, $n);
            script.run(&name);
            want.push((w, name));
        }};
    }
    for _ in 0..2 {
        case!(32, 16, 32);
        case!(12, 21, 9);
    }
    for bd in BLOCK_DIMS {
        let got = script.exec(bd);
        for (k, (w, what)) in want.iter().enumerate() {
            assert!(got[k] == *w, "{what}, block size {bd}");
        }
    }
}

/// The loads' and stores' fast paths (the tile fully inside a contiguous-row array: direct,
/// and 16-byte vectors when the row starts allow) and their fallbacks (partly outside, rows
/// not 16-byte aligned, strided rows, a strided innermost axis), against warp-core, bit for bit.
#[test]
fn load_store_fast_paths_match() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0x5eed_0008);
    let mut script = Script::default();
    let mut want: Vec<(Vec<u8>, Vec<u8>, String)> = Vec::new();
    // Rank 2, f32 4 x 8 (32-byte rows: vectors when aligned) and 3 x 12, f64 3 x 4, from `a`
    // (shape `sa`, row stride `ra` elements, inner stride `ia`) into `b` (10 x 24, contiguous).
    macro_rules! case2 {
        ($t:ty, $kind:literal, $name:literal, $gen:ident, $n0:literal, $n1:literal,
         $sa:expr, $ra:expr, $ia:expr, $o:expr) => {{
            let (sa, ra, ia, o): ([usize; 2], usize, usize, [i64; 4]) = ($sa, $ra, $ia, $o);
            let len = if sa[0] * sa[1] == 0 {
                0
            } else {
                (sa[0] - 1) * ra + (sa[1] - 1) * ia + 1
            };
            let mut a: Vec<$t> = (0..len).map(|_| rng.$gen()).collect();
            let mut b: Vec<$t> = (0..240).map(|i| i as $t + 0.25).collect();
            script.arr_strided($kind, 0, &sa, &[ra as isize, ia as isize], &a);
            script.arr($kind, 1, &[10, 24], &b);
            script.off(o);
            let name = format!("ld2_{}_{}x{}", $name, $n0, $n1);
            script.run(&name);
            script.dump($kind, 1);
            let t: Tile2<$t, $n0, $n1> = tile::load2(
                &view_strided(&mut a, sa, [ra as isize, ia as isize]),
                o[0],
                o[1],
            )
            .unwrap();
            tile::store2(&view(&mut b, [10, 24]), o[2], o[3], &t).unwrap();
            want.push((
                flat(&t),
                bytes(&b),
                format!("{name} {sa:?} rows {ra} inner {ia} at {o:?}"),
            ));
        }};
    }
    for o in [
        [0i64, 0, 0, 0], // inside, aligned: vectors both ways
        [2, 4, 3, 8],    // inside, aligned (4 f32 = 16 bytes)
        [1, 1, 2, 3],    // inside, misaligned starts: direct scalar
        [5, 2, 6, 16],   // partly outside on load (rows) and store (columns)
        [-1, 4, 7, -2],  // partly outside, negative
        [0, 12, 0, 20],  // columns partly outside
    ] {
        case2!(f32, "f2", "f32", f32, 4, 8, [8, 16], 16, 1, o);
        case2!(f32, "f2", "f32", f32, 4, 8, [8, 13], 13, 1, o); // rows 52 bytes apart
        case2!(f32, "f2", "f32", f32, 4, 8, [8, 13], 20, 1, o); // padded rows, 80 bytes
        case2!(f32, "f2", "f32", f32, 4, 8, [8, 16], 33, 2, o); // strided inner axis
        case2!(f32, "f2", "f32", f32, 3, 12, [6, 24], 24, 1, o);
        case2!(f64, "d2", "f64", f64, 3, 4, [8, 16], 16, 1, o);
        case2!(f64, "d2", "f64", f64, 3, 4, [8, 9], 9, 1, o);
    }
    // Rank 1: f32 x 64 and f64 x 9 (a vector tail), contiguous and strided.
    macro_rules! case1 {
        ($t:ty, $kind:literal, $name:literal, $gen:ident, $n:literal, $sa:expr, $st:expr,
         $o:expr, $p:expr) => {{
            let (sa, st, o, p): (usize, usize, i64, i64) = ($sa, $st, $o, $p);
            let len = if sa == 0 { 0 } else { (sa - 1) * st + 1 };
            let mut a: Vec<$t> = (0..len).map(|_| rng.$gen()).collect();
            let name = format!("ld1_{}_{}", $name, $n);
            let what = format!("{name} n {sa} stride {st} at {o} store at {p}");
            script.arr_strided($kind, 0, &[sa], &[st as isize], &a);
            let t: Tile1<$t, $n> =
                tile::load1(&view_strided(&mut a, [sa], [st as isize]), o).unwrap();
            if $name == "f32" {
                let mut b: Vec<$t> = (0..100).map(|i| -(i as $t) - 0.5).collect();
                script.arr($kind, 1, &[100], &b);
                script.off([o, p, 0, 0]);
                script.run(&name);
                script.dump($kind, 1);
                tile::store1(&view(&mut b, [100]), p, &t).unwrap();
                want.push((flat(&t), bytes(&b), what));
            } else {
                // The f64 store goes back into array 0, after the load.
                script.off([o, p, 0, 0]);
                script.run(&name);
                script.dump($kind, 0);
                tile::store1(&view_strided(&mut a, [sa], [st as isize]), p, &t).unwrap();
                want.push((flat(&t), bytes(&a), what));
            }
        }};
    }
    for (o, p) in [(0i64, 0i64), (4, 8), (1, 3), (-2, 30), (50, -5), (36, 36)] {
        case1!(f32, "f1", "f32", f32, 64, 100, 1, o, p);
        case1!(f32, "f1", "f32", f32, 64, 100, 3, o, p);
        case1!(f64, "d1", "f64", f64, 9, 20, 1, o, p);
        case1!(f64, "d1", "f64", f64, 9, 20, 2, o, p);
    }
    for bd in BLOCK_DIMS {
        let got = script.exec(bd);
        for (k, (t, b, what)) in want.iter().enumerate() {
            assert_eq!(&got[2 * k], t, "tile, {what}, block size {bd}");
            assert_eq!(&got[2 * k + 1], b, "stored array, {what}, block size {bd}");
        }
    }
}

// ------------------------------------------------------------------------------------------
// NVRTC
// ------------------------------------------------------------------------------------------

/// A kernel that instantiates every operation of `wp_tile.h` for f32, f64 and i32 (matmul:
/// floats), over one dynamic shared-memory buffer as the emitter will lay it out.
const NVRTC_SOURCE: &str = r#"
#include "wp_tile.h"

template <typename T>
__device__ unsigned char* all_ops(const wp::array_t<T, 1>& a1, const wp::array_t<T, 2>& a2,
                                  unsigned char* at, wp::ctx_t* c) {
  wp::tile_t<T, 300> t(at);
  at += (wp::tile_t<T, 300>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, 5, 7> u(at);
  at += (wp::tile_t<T, 5, 7>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, 5, 7> v(at);
  at += (wp::tile_t<T, 5, 7>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, 1> r(at);
  at += 16;
  wp::tile_load(t, a1, (wp::i64)-3, c);
  wp::tile_load(u, a2, -1, (wp::u64)2, c);
  wp::tile_zeros(v);
  wp::tile_ones(v);
  wp::tile_add(v, u, v);
  wp::tile_sub(v, v, (T)2);
  wp::tile_mul(v, (T)3, v);
  wp::tile_map(u, v, [](T x) { return x; });
  wp::tile_sum(r, t);
  wp::tile_min(r, u);
  wp::tile_max(r, t);
  wp::tile_neg(v, v);
  wp::tile_t<int, 1> k(at);
  at += 16;
  wp::tile_argmin(k, t);
  wp::tile_argmax(k, u);
  wp::tile_store(a2, 1, -2, v, c);
  wp::tile_store(a1, (wp::i64)7, t, c);
  wp::tile_t<T, 300> w(at);
  at += (wp::tile_t<T, 300>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_arange(w, (T)1, (T)3);
  return at;
}

template <typename T>
__device__ unsigned char* matmuls(unsigned char* at) {
  wp::tile_t<T, 7, 13> a(at);
  at += (wp::tile_t<T, 7, 13>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, 13, 5> b(at);
  at += (wp::tile_t<T, 13, 5>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, 7, 5> p(at);
  at += (wp::tile_t<T, 7, 5>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_ones(a);
  wp::tile_ones(b);
  wp::tile_matmul(p, a, b);
  wp::tile_matmul_acc(p, a, b);
  // The benchmark's shapes (register blocking, 16-byte vector reads of the slots).
  wp::tile_t<T, 64, 8> ba(at);
  at += (wp::tile_t<T, 64, 8>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, 8, 64> bb(at);
  at += (wp::tile_t<T, 8, 64>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, 64, 64> bc(at);
  at += (wp::tile_t<T, 64, 64>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_ones(ba);
  wp::tile_ones(bb);
  wp::tile_matmul(bc, ba, bb);
  wp::tile_matmul_acc(bc, ba, bb);
  return at;
}

// Ranks 3 and 4: loads and stores (signed and unsigned offsets), elementwise, a reduction,
// a reshape across ranks, an element read.
template <typename T>
__device__ unsigned char* nd_ops(const wp::array_t<T, 3>& a3, const wp::array_t<T, 4>& a4,
                                 unsigned char* at, wp::ctx_t* c) {
  wp::tile_t<T, 3, 4, 5> t(at);
  at += (wp::tile_t<T, 3, 4, 5>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, 2, 3, 2, 5> q(at);
  at += (wp::tile_t<T, 2, 3, 2, 5>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, 1> r(at);
  at += 16;
  wp::tile_load(t, a3, -1, (wp::u64)2, 3, c);
  wp::tile_load(q, a4, 0, -2, (wp::i64)1, 4u, c);
  wp::tile_mul(t, t, (T)2);
  wp::tile_reshape(q, t);
  wp::tile_sum(r, q);
  wp::tile_store(a3, 1, 0, -1, t, c);
  wp::tile_store(a4, 0, 1, 2, -3, q, c);
  (void)wp::tile_extract(t, 2, 3, 4, c);
  (void)wp::tile_extract(q, 1, 2, 1, 4, c);
  return at;
}

extern "C" __global__ void __launch_bounds__(WP_TILE_BLOCK_DIM)
    tile_all(wp::array_t<float, 1> f1, wp::array_t<float, 2> f2, wp::array_t<double, 1> d1,
             wp::array_t<double, 2> d2, wp::array_t<int, 1> i1, wp::array_t<int, 2> i2,
             wp::array_t<float, 3> f3, wp::array_t<float, 4> f4, wp::fault_t* fault,
             wp::u32* flag) {
  extern __shared__ __align__(16) unsigned char smem[];
  wp::launch_ctx_t rec = wp::launch_ctx_make(fault, flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  unsigned char* at = smem;
  at = all_ops(f1, f2, at, &c);
  at = all_ops(d1, d2, at, &c);
  at = all_ops(i1, i2, at, &c);
  at = matmuls<float>(at);
  at = matmuls<double>(at);
  at = nd_ops(f3, f4, at, &c);
}
"#;

/// `wp_tile.h` compiles with NVRTC, without warnings, for block sizes that fill warps and one
/// that does not, on the benchmarks' GPUs (sm_90) and an older one (sm_80), as the tile
/// section's units will (no FMA contraction). Needs only libnvrtc, no GPU; skipped, saying so,
/// without it.
#[test]
fn nvrtc_compiles_the_tile_library() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED nvrtc_compiles_the_tile_library: {e}");
        return;
    }
    for bd in ["45", "128", "1024"] {
        let defines = [("WP_TILE_BLOCK_DIM", bd)];
        let opts = warp_cuda::CompileOptions {
            fmad: false,
            defines: &defines,
            headers: warp_cuda::HEADERS,
            ..Default::default()
        };
        for arch in [90, 80] {
            let c = warp_cuda::compile(NVRTC_SOURCE, "tile_all.cu", &opts, arch)
                .unwrap_or_else(|e| panic!("block size {bd}, sm_{arch}: {e}"));
            assert!(!c.cubin.is_empty());
            assert!(
                !c.log.contains("warning"),
                "block size {bd}, sm_{arch}: {}",
                c.log
            );
        }
    }
}
