//! The CUDA tile adjoints (`warp-cuda/cuda/wp_adjoint_tile.h`), checked without a GPU against
//! the CPU's (`warp_core::tile::adjoint`), bit for bit (tolerance: none).
//!
//! A driver (`warp-cuda/cuda/tests/wp_tile_adjoint_driver.cpp`) runs every function of the
//! header in one block under the block emulator (`wp_prim_emu.h`, as `cuda_tile_host.rs` does
//! for the forward header), compiled with g++ for block sizes 1, 32, 45 (a partial second
//! warp), 96 and 256; each result is compared with warp-core's for the same block size. The
//! adjoint of a uniform scalar (`t * s`) is a sum over the tile in the reductions' order: its
//! data is order-sensitive (a large value, then values of many magnitudes), and the test checks
//! that the block sizes disagree among themselves, so agreeing with the CPU at each shows the
//! order is the same, not merely the value. `adj_tile_extract*` adds with a shared-memory
//! atomic in no fixed order, so its cases have one contribution per element or sums that are
//! exact in any order. Not checked here: NVRTC's acceptance of the header and real hardware.
//!
//! Skipped, saying so, without g++.

#[path = "common/host_cpp.rs"]
mod host_cpp;

use std::collections::HashMap;
use std::path::PathBuf;
use std::process::Command;
use std::sync::{Arc, Mutex, OnceLock};
use warp_core::adjoint::{adj_div, adj_mul, AdjAdd, AdjDiv, AdjMul, AdjNeg, AdjSub, Adjoint};
use warp_core::block::PerLane;
use warp_core::builtins::{MinMax, Scalar};
use warp_core::tile::adjoint as ta;
use warp_core::tile::matmul::Fma;
use warp_core::tile::{Tile, Tile1, Tile2, Tile3, Tile4};
use warp_core::{ArrayView, FaultKind, GradElement, GradView, KResult};

/// The block sizes every test runs.
const BLOCK_DIMS: [usize; 5] = [1, 32, 45, 96, 256];

fn have_gpp() -> bool {
    static HAVE: OnceLock<bool> = OnceLock::new();
    *HAVE.get_or_init(|| {
        let ok = host_cpp::gpp();
        if !ok {
            eprintln!("SKIPPED cuda_tile_adjoint_host: no g++ on this machine");
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
        &format!("tile_adjoint_{bd}"),
        include_str!("../warp-cuda/cuda/tests/wp_tile_adjoint_driver.cpp"),
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

fn flat<X: Tile<Elem: bytemuck::Pod>>(t: &X) -> Vec<u8> {
    bytes(t.as_flat())
}

/// The tile holding `v` (row-major).
fn tile_of<X: Tile + Adjoint>(v: &[X::Elem]) -> X
where
    X::Elem: Copy,
{
    let mut t = X::adj_zero();
    t.as_flat_mut().copy_from_slice(&v[..X::SIZE]);
    t
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

/// The driver's output line for a run without (`Ok`) or with a fault.
fn fault_line(r: KResult<()>) -> Vec<u8> {
    match r {
        Ok(()) => b"nofault".to_vec(),
        Err(f) => {
            assert!(matches!(f.kind, FaultKind::TileIndex { .. }), "{f}");
            // wp_core.h's FAULT_TILE_INDEX.
            b"fault 6".to_vec()
        }
    }
}

/// A driver script.
#[derive(Default)]
struct Script {
    text: String,
}

impl Script {
    /// Buffer `k` holding `data`.
    fn buf<T: bytemuck::Pod>(&mut self, k: usize, data: &[T]) {
        self.text += &format!("buf {k} {}\n", hex(&bytes(data)));
    }
    /// Array argument `slot` (0: the value, 1: its gradient) of `kind` over buffer `k` (none:
    /// a null gradient).
    fn arr(&mut self, kind: &str, slot: usize, shape: &[usize], k: Option<usize>) {
        let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
        let k = k.map_or("-".to_string(), |k| k.to_string());
        self.text += &format!("arr {kind} {slot} {} {k}\n", dims.join(" "));
    }
    fn off(&mut self, o: [i64; 4]) {
        self.text += &format!("off {} {} {} {}\n", o[0], o[1], o[2], o[3]);
    }
    /// Two outputs: what the kernel wrote, then `nofault` or `fault KIND`.
    fn run(&mut self, kernel: &str) {
        self.text += &format!("run {kernel}\n");
    }
    fn dump(&mut self, k: usize) {
        self.text += &format!("dump {k}\n");
    }

    /// Runs the script for block size `bd`: the outputs, in order.
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
                "nofault" | "fault" => got.push(l.as_bytes().to_vec()),
                _ => panic!("block size {bd}: unexpected driver line {l}"),
            }
        }
        got
    }
}

/// What the driver must print: per case, its outputs for each block size of [`BLOCK_DIMS`].
#[derive(Default)]
struct Want(Vec<(String, Vec<Vec<Vec<u8>>>)>);

impl Want {
    /// A case whose outputs for block size `bd` are `f(bd)`.
    fn add(&mut self, what: impl Into<String>, f: impl Fn(usize) -> Vec<Vec<u8>>) {
        self.0
            .push((what.into(), BLOCK_DIMS.iter().map(|&bd| f(bd)).collect()));
    }

    /// Runs `script` at every block size and compares, naming the first differing byte.
    fn check(&self, script: &Script) {
        for (bi, &bd) in BLOCK_DIMS.iter().enumerate() {
            let got = script.exec(bd);
            let mut k = 0;
            for (what, per_bd) in &self.0 {
                for (j, w) in per_bd[bi].iter().enumerate() {
                    let g = got.get(k).unwrap_or_else(|| {
                        panic!("{what}, block size {bd}: the driver printed only {k} outputs")
                    });
                    if g != w {
                        let at = g.iter().zip(w).position(|(a, b)| a != b);
                        panic!(
                            "{what}, output {j}, block size {bd}: {} bytes, {} expected, first \
                             difference at byte {at:?}",
                            g.len(),
                            w.len()
                        );
                    }
                    k += 1;
                }
            }
            assert_eq!(k, got.len(), "block size {bd}: outputs");
        }
    }
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
    /// In [-1, 1) with a full mantissa, times 2^e for e in -8..8.
    fn f32(&mut self) -> f32 {
        let m = (self.next() >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0;
        m * 2f32.powi((self.next() % 16) as i32 - 8)
    }
    /// In [-1, 1) with a full mantissa, times 2^e for e in -20..20.
    fn f64(&mut self) -> f64 {
        let m = (self.next() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
        m * 2f64.powi((self.next() % 40) as i32 - 20)
    }
}

/// The float element types both sides have adjoints for.
trait El:
    bytemuck::Pod
    + Scalar
    + MinMax
    + Adjoint
    + GradElement
    + Fma
    + warp_core::tile::MatmulElem<Acc = Self>
    + AdjAdd<Output = Self>
    + AdjSub<Output = Self>
    + AdjMul<Output = Self>
    + AdjDiv<Output = Self>
    + AdjNeg
    + PartialEq
    + std::fmt::Debug
{
    /// The driver's kernel suffix.
    const NAME: &'static str;
    /// The driver's array kinds of rank 1 and 2.
    const K1: &'static str;
    const K2: &'static str;
    /// A value that absorbs the small ones added to it in one order but not another.
    const BIG: Self;
    fn draw(rng: &mut Rng) -> Self;
    fn of(v: f64) -> Self;
    fn draws(rng: &mut Rng, n: usize) -> Vec<Self> {
        (0..n).map(|_| Self::draw(rng)).collect()
    }
    /// Draws in [0.5, 2) (divisors).
    fn positive(rng: &mut Rng, n: usize) -> Vec<Self> {
        (0..n)
            .map(|_| Self::of(0.5 + 1.5 * (rng.next() >> 11) as f64 / (1u64 << 53) as f64))
            .collect()
    }
    /// Draws with [`El::BIG`] first: sums of these depend on their order.
    fn spiky(rng: &mut Rng, n: usize) -> Vec<Self> {
        let mut v = Self::draws(rng, n);
        v[0] = Self::BIG;
        v
    }
}

impl El for f32 {
    const NAME: &'static str = "f32";
    const K1: &'static str = "f1";
    const K2: &'static str = "f2";
    const BIG: Self = 1e8;
    fn draw(rng: &mut Rng) -> Self {
        rng.f32()
    }
    fn of(v: f64) -> Self {
        v as f32
    }
}

impl El for f64 {
    const NAME: &'static str = "f64";
    const K1: &'static str = "d1";
    const K2: &'static str = "d2";
    const BIG: Self = 1e17;
    fn draw(rng: &mut Rng) -> Self {
        rng.f64()
    }
    fn of(v: f64) -> Self {
        v
    }
}

// ------------------------------------------------------------------------------------------
// Loads and stores
// ------------------------------------------------------------------------------------------

fn loads_and_stores<E: El>(rng: &mut Rng, script: &mut Script, want: &mut Want) {
    // Rank 1, a 37-element tile at `o` of an array of `n`, with and without a gradient.
    for n in [0usize, 5, 37, 50, 100] {
        for o in [
            0i64,
            -1,
            -5,
            -40,
            3,
            n as i64 - 2,
            n as i64 + 1,
            i64::MIN,
            i64::MAX,
        ] {
            for grad in [true, false] {
                let (a, g) = (E::draws(rng, n), E::draws(rng, n));
                let r = E::draws(rng, 37);
                let mut at0 = E::draws(rng, 37);
                at0[3] = E::of(-0.0); // + a taken zero is +0 (and without a gradient too)
                let what = format!("{} n {n} at {o} grad {grad}", E::NAME);
                script.buf(0, &a);
                script.buf(1, &g);
                script.buf(2, &r);
                script.arr(E::K1, 0, &[n], Some(0));
                script.arr(E::K1, 1, &[n], grad.then_some(1));
                script.off([o, 0, 0, 0]);
                script.run(&format!("load1_{}", E::NAME));
                script.dump(1);
                let (a2, g2, r2) = (a.clone(), g.clone(), r.clone());
                want.add(format!("adj_tile_load1 {what}"), move |bd| {
                    let (mut a, mut g) = (a2.clone(), g2.clone());
                    let mut gv = match grad {
                        true => GradView::new(view(&mut g, [n])),
                        false => GradView::none(),
                    };
                    let r: Tile1<E, 37> = tile_of(&r2);
                    let res = ta::adj_tile_load1(&view(&mut a, [n]), o, &mut gv, &mut 0, &r, bd);
                    vec![vec![], fault_line(res), bytes(&g)]
                });
                // The store: buffer 2 the tile's adjoint, 3 the tile.
                // Buffer 1 again: the load's adjoint changed the driver's copy.
                script.buf(1, &g);
                script.buf(2, &at0);
                script.buf(3, &r);
                script.run(&format!("store1_{}", E::NAME));
                script.dump(1);
                want.add(format!("adj_tile_store1 {what}"), move |bd| {
                    let (mut a, mut g) = (a.clone(), g.clone());
                    let mut gv = match grad {
                        true => GradView::new(view(&mut g, [n])),
                        false => GradView::none(),
                    };
                    let t: Tile1<E, 37> = tile_of(&r);
                    let mut at: Tile1<E, 37> = tile_of(&at0);
                    let res = ta::adj_tile_store1(
                        &view(&mut a, [n]),
                        &t,
                        o,
                        &mut gv,
                        &mut at,
                        &mut 0,
                        &(),
                        bd,
                    );
                    vec![flat(&at), fault_line(res), bytes(&g)]
                });
            }
        }
    }
    // Rank 2, a 5 x 7 tile (the load's column offset an i32).
    for shape in [[4usize, 6], [9, 10], [0, 3], [5, 7]] {
        for o in [
            [0i64, 0],
            [-3, -2],
            [2, 3],
            [-1, 5],
            [-4, -6],
            [i64::MIN, 1],
            [i64::MAX, -1],
            [-5, -7],
            [6, 5],
        ] {
            for grad in [true, false] {
                let len = shape[0] * shape[1];
                let (a, g) = (E::draws(rng, len), E::draws(rng, len));
                let r = E::draws(rng, 35);
                let mut at0 = E::draws(rng, 35);
                at0[8] = E::of(-0.0);
                let what = format!("{} {shape:?} at {o:?} grad {grad}", E::NAME);
                script.buf(0, &a);
                script.buf(1, &g);
                script.buf(2, &r);
                script.arr(E::K2, 0, &shape, Some(0));
                script.arr(E::K2, 1, &shape, grad.then_some(1));
                script.off([o[0], o[1], 0, 0]);
                script.run(&format!("load2_{}", E::NAME));
                script.dump(1);
                let (a2, g2, r2) = (a.clone(), g.clone(), r.clone());
                want.add(format!("adj_tile_load2 {what}"), move |bd| {
                    let (mut a, mut g) = (a2.clone(), g2.clone());
                    let mut gv = match grad {
                        true => GradView::new(view(&mut g, shape)),
                        false => GradView::none(),
                    };
                    let r: Tile2<E, 5, 7> = tile_of(&r2);
                    let res = ta::adj_tile_load2(
                        &view(&mut a, shape),
                        o[0],
                        o[1] as i32,
                        &mut gv,
                        &mut 0,
                        &mut 0,
                        &r,
                        bd,
                    );
                    vec![vec![], fault_line(res), bytes(&g)]
                });
                // Buffer 1 again: the load's adjoint changed the driver's copy.
                script.buf(1, &g);
                script.buf(2, &at0);
                script.buf(3, &r);
                script.run(&format!("store2_{}", E::NAME));
                script.dump(1);
                want.add(format!("adj_tile_store2 {what}"), move |bd| {
                    let (mut a, mut g) = (a.clone(), g.clone());
                    let mut gv = match grad {
                        true => GradView::new(view(&mut g, shape)),
                        false => GradView::none(),
                    };
                    let t: Tile2<E, 5, 7> = tile_of(&r);
                    let mut at: Tile2<E, 5, 7> = tile_of(&at0);
                    let res = ta::adj_tile_store2(
                        &view(&mut a, shape),
                        &t,
                        o[0],
                        o[1],
                        &mut gv,
                        &mut at,
                        &mut 0,
                        &mut 0,
                        &(),
                        bd,
                    );
                    vec![flat(&at), fault_line(res), bytes(&g)]
                });
            }
        }
    }
}

/// `adj_tile_load*` and `adj_tile_store*` with ragged and negative offsets (and offsets at the
/// ends of i64), with and without a gradient array: the gradient after the load's adjoint, the
/// tile's adjoint and the gradient after the store's.
#[test]
fn adjoint_loads_and_stores_match() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_0001);
    let (mut script, mut want) = (Script::default(), Want::default());
    loads_and_stores::<f32>(&mut rng, &mut script, &mut want);
    loads_and_stores::<f64>(&mut rng, &mut script, &mut want);
    want.check(&script);
}

/// `adj_tile_load3/4` and `adj_tile_store3/4` (f32) at offsets crossing both ends of every
/// axis and at the ends of i64, with and without a gradient array; and `adj_tile_extract3/4`
/// from many threads at once (contributions exact in any order): against warp-core's.
#[test]
fn adjoint_rank_3_and_4_match() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_0341);
    let (mut script, mut want) = (Script::default(), Want::default());
    let offsets = [
        [0i64, 0, 0, 0],
        [-1, 2, -3, 1],
        [2, -2, 3, -1],
        [1, 1, 1, 1],
        [i64::MIN, 0, 1, i64::MAX],
    ];
    for shape in [[4usize, 5, 6], [2, 3, 4], [3, 4, 5]] {
        for o in offsets {
            for grad in [true, false] {
                let len: usize = shape.iter().product();
                let (a, g) = (f32::draws(&mut rng, len), f32::draws(&mut rng, len));
                let r = f32::draws(&mut rng, 60);
                let mut at0 = f32::draws(&mut rng, 60);
                at0[7] = -0.0;
                let what = format!("{shape:?} at {o:?} grad {grad}");
                script.buf(0, &a);
                script.buf(1, &g);
                script.buf(2, &r);
                script.arr("f3", 0, &shape, Some(0));
                script.arr("f3", 1, &shape, grad.then_some(1));
                script.off(o);
                script.run("load3_f32");
                script.dump(1);
                let (a2, g2, r2) = (a.clone(), g.clone(), r.clone());
                want.add(format!("adj_tile_load3 {what}"), move |bd| {
                    let (mut a, mut g) = (a2.clone(), g2.clone());
                    let mut gv = match grad {
                        true => GradView::new(view(&mut g, shape)),
                        false => GradView::none(),
                    };
                    let r: Tile3<f32, 3, 4, 5> = tile_of(&r2);
                    let res = ta::adj_tile_load3(
                        &view(&mut a, shape),
                        o[0],
                        o[1],
                        o[2] as i32,
                        &mut gv,
                        &mut 0,
                        &mut 0,
                        &mut 0,
                        &r,
                        bd,
                    );
                    vec![vec![], fault_line(res), bytes(&g)]
                });
                // Buffer 1 again: the load's adjoint changed the driver's copy.
                script.buf(1, &g);
                script.buf(2, &at0);
                script.buf(3, &r);
                script.run("store3_f32");
                script.dump(1);
                want.add(format!("adj_tile_store3 {what}"), move |bd| {
                    let (mut a, mut g) = (a.clone(), g.clone());
                    let mut gv = match grad {
                        true => GradView::new(view(&mut g, shape)),
                        false => GradView::none(),
                    };
                    let t: Tile3<f32, 3, 4, 5> = tile_of(&r);
                    let mut at: Tile3<f32, 3, 4, 5> = tile_of(&at0);
                    let res = ta::adj_tile_store3(
                        &view(&mut a, shape),
                        &t,
                        o[0],
                        o[1],
                        o[2],
                        &mut gv,
                        &mut at,
                        &mut 0,
                        &mut 0,
                        &mut 0,
                        &(),
                        bd,
                    );
                    vec![flat(&at), fault_line(res), bytes(&g)]
                });
            }
        }
    }
    for shape in [[2usize, 3, 2, 3], [3, 2, 4, 2], [1, 4, 3, 5]] {
        for o in offsets {
            for grad in [true, false] {
                let len: usize = shape.iter().product();
                let (a, g) = (f32::draws(&mut rng, len), f32::draws(&mut rng, len));
                let r = f32::draws(&mut rng, 36);
                let at0 = f32::draws(&mut rng, 36);
                let what = format!("{shape:?} at {o:?} grad {grad}");
                script.buf(0, &a);
                script.buf(1, &g);
                script.buf(2, &r);
                script.arr("f4", 0, &shape, Some(0));
                script.arr("f4", 1, &shape, grad.then_some(1));
                script.off(o);
                script.run("load4_f32");
                script.dump(1);
                let (a2, g2, r2) = (a.clone(), g.clone(), r.clone());
                want.add(format!("adj_tile_load4 {what}"), move |bd| {
                    let (mut a, mut g) = (a2.clone(), g2.clone());
                    let mut gv = match grad {
                        true => GradView::new(view(&mut g, shape)),
                        false => GradView::none(),
                    };
                    let r: Tile4<f32, 2, 3, 2, 3> = tile_of(&r2);
                    let res = ta::adj_tile_load4(
                        &view(&mut a, shape),
                        o[0],
                        o[1],
                        o[2],
                        o[3],
                        &mut gv,
                        &mut 0,
                        &mut 0,
                        &mut 0,
                        &mut 0,
                        &r,
                        bd,
                    );
                    vec![vec![], fault_line(res), bytes(&g)]
                });
                script.buf(1, &g);
                script.buf(2, &at0);
                script.buf(3, &r);
                script.run("store4_f32");
                script.dump(1);
                want.add(format!("adj_tile_store4 {what}"), move |bd| {
                    let (mut a, mut g) = (a.clone(), g.clone());
                    let mut gv = match grad {
                        true => GradView::new(view(&mut g, shape)),
                        false => GradView::none(),
                    };
                    let t: Tile4<f32, 2, 3, 2, 3> = tile_of(&r);
                    let mut at: Tile4<f32, 2, 3, 2, 3> = tile_of(&at0);
                    let res = ta::adj_tile_store4(
                        &view(&mut a, shape),
                        &t,
                        o[0],
                        o[1],
                        o[2],
                        o[3],
                        &mut gv,
                        &mut at,
                        &mut 0,
                        &mut 0,
                        &mut 0,
                        &mut 0,
                        &(),
                        bd,
                    );
                    vec![flat(&at), fault_line(res), bytes(&g)]
                });
            }
        }
    }
    // Extracts: thread l reads element l mod SIZE with adjoint 1 + l / 8 (small integers: the
    // shared-memory adds are exact in any order).
    let tv = f32::draws(&mut rng, 24);
    script.buf(0, &tv);
    script.run("extract_nd_f32");
    want.add("adj_tile_extract3/4", move |bd| {
        let t3: Tile3<f32, 2, 3, 4> = tile_of(&tv);
        let t4: Tile4<f32, 2, 1, 3, 2> = tile_of(&tv[..12]);
        let mut a3: Tile3<f32, 2, 3, 4> = tile_of(&[0.0; 24]);
        let mut a4: Tile4<f32, 2, 1, 3, 2> = tile_of(&[0.0; 12]);
        for l in 0..bd {
            let r = 1.0 + (l / 8) as f32;
            let e3 = l % 24;
            let (i, j, k) = (e3 / 12, (e3 / 4) % 3, e3 % 4);
            ta::adj_tile_extract3(&t3, i, j, k, &mut a3, &mut 0, &mut 0, &mut 0, r, "k").unwrap();
            let e4 = l % 12;
            let (p, u, v) = (e4 / 6, (e4 / 2) % 3, e4 % 2);
            ta::adj_tile_extract4(
                &t4, p, 0, u, v, &mut a4, &mut 0, &mut 0, &mut 0, &mut 0, r, "k",
            )
            .unwrap();
        }
        let mut out = flat(&a3);
        out.extend(flat(&a4));
        vec![out, fault_line(Ok(()))]
    });
    want.check(&script);
}

// ------------------------------------------------------------------------------------------
// Elementwise
// ------------------------------------------------------------------------------------------

/// The CPU's outputs of the driver's `elem` kernel (see `k_elem`), and `add_ts`'s scalar
/// adjoint alone.
#[allow(clippy::too_many_arguments)]
fn elem_cpu<X>(x: &X, y: &X, r: &X, a0: &X, b0: &X, s: X::Elem, s0: X::Elem, bd: usize) -> Vec<u8>
where
    X: Tile<Elem: El> + Copy + Adjoint,
{
    let mut out = Vec::new();
    macro_rules! op {
        ($tt:ident, $ts:ident, $st:ident) => {{
            let (mut a, mut b) = (*a0, *b0);
            ta::$tt(x, y, &mut a, &mut b, r, bd);
            out.extend(flat(&a));
            out.extend(flat(&b));
            let (mut a, mut sa) = (*a0, s0);
            ta::$ts(x, s, &mut a, &mut sa, r, bd);
            out.extend(flat(&a));
            out.extend(bytes(&[sa]));
            let (mut b, mut sa) = (*b0, s0);
            ta::$st(s, y, &mut sa, &mut b, r, bd);
            out.extend(flat(&b));
            out.extend(bytes(&[sa]));
        }};
    }
    op!(adj_tile_add_tt, adj_tile_add_ts, adj_tile_add_st);
    op!(adj_tile_sub_tt, adj_tile_sub_ts, adj_tile_sub_st);
    op!(adj_tile_mul_tt, adj_tile_mul_ts, adj_tile_mul_st);
    op!(adj_tile_div_tt, adj_tile_div_ts, adj_tile_div_st);
    let mut a = *a0;
    ta::adj_tile_neg(x, &mut a, r, bd);
    out.extend(flat(&a));
    let mut a = *a0;
    a.adj_accum(*r);
    out.extend(flat(&a));
    out
}

fn elementwise<X>(name: &str, rng: &mut Rng, script: &mut Script, want: &mut Want)
where
    X: Tile<Elem: El> + Copy + Adjoint + 'static,
{
    type E<X> = <X as Tile>::Elem;
    let n = X::SIZE;
    for case in 0..3 {
        let x = E::<X>::draws(rng, n);
        // Divisors away from zero; `r` order-sensitive (its contributions are summed for `s`).
        let y = E::<X>::positive(rng, n);
        let r = E::<X>::spiky(rng, n);
        let (a0, b0) = (E::<X>::draws(rng, n), E::<X>::draws(rng, n));
        let s = [E::<X>::positive(rng, 1)[0], E::<X>::draw(rng)];
        for (k, v) in [&x, &y, &r, &a0, &b0].into_iter().enumerate() {
            script.buf(k, v);
        }
        script.buf(5, &s);
        script.run(&format!("elem_{}_{name}", E::<X>::NAME));
        let t = |v: &[E<X>]| -> X { tile_of(v) };
        let (x, y, r, a0, b0) = (t(&x), t(&y), t(&r), t(&a0), t(&b0));
        want.add(format!("elementwise {name} case {case}"), move |bd| {
            vec![
                elem_cpu(&x, &y, &r, &a0, &b0, s[0], s[1], bd),
                b"nofault".to_vec(),
            ]
        });
        // The scalar adjoint of `t + s` is the plain block sum of `r`: the test shows the
        // order only if it differs between block sizes.
        let sums: Vec<E<X>> = BLOCK_DIMS
            .iter()
            .map(|&bd| {
                let (mut a, mut sa) = (a0, E::<X>::ZERO);
                ta::adj_tile_add_ts(&x, s[0], &mut a, &mut sa, &r, bd);
                sa
            })
            .collect();
        assert!(
            sums.iter().any(|v| *v != sums[0]),
            "{name} case {case}: the scalar adjoint is the same for every block size: {sums:?}"
        );
    }
}

/// `adj_tile_{add,sub,mul,div}_{tt,ts,st}`, `adj_tile_neg` and `adj_tile_accum`, f32 and f64,
/// rank 1 (more elements than most block sizes) and rank 2.
#[test]
fn adjoint_elementwise_matches() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_0002);
    let (mut script, mut want) = (Script::default(), Want::default());
    elementwise::<Tile1<f32, 300>>("300", &mut rng, &mut script, &mut want);
    elementwise::<Tile1<f64, 300>>("300", &mut rng, &mut script, &mut want);
    elementwise::<Tile2<f32, 13, 11>>("13x11", &mut rng, &mut script, &mut want);
    elementwise::<Tile2<f64, 13, 11>>("13x11", &mut rng, &mut script, &mut want);
    want.check(&script);
}

fn maps<E: El>(rng: &mut Rng, script: &mut Script, want: &mut Want) {
    for case in 0..3 {
        let x = E::draws(rng, 45);
        let y = E::positive(rng, 45);
        let r = E::draws(rng, 45);
        let (a0, b0) = (E::draws(rng, 45), E::draws(rng, 45));
        for (k, v) in [&x, &y, &r, &a0, &b0].into_iter().enumerate() {
            script.buf(k, v);
        }
        script.run(&format!("map_{}", E::NAME));
        let t = |v: &[E]| -> Tile1<E, 45> { tile_of(v) };
        let (x, y, r, a0, b0) = (t(&x), t(&y), t(&r), t(&a0), t(&b0));
        want.add(format!("map {} case {case}", E::NAME), move |_bd| {
            let mut out = Vec::new();
            let mut a = a0;
            ta::adj_tile_map1(&x, &mut a, &r, |v, av, g| {
                let mut unused = E::ZERO;
                adj_div(v, E::of(3.0), av, &mut unused, g)
            });
            out.extend(flat(&a));
            let (mut a, mut b) = (a0, b0);
            ta::adj_tile_map2(&x, &y, &mut a, &mut b, &r, |u, v, au, av, g| {
                adj_mul(u, v, au, av, g)
            });
            out.extend(flat(&a));
            out.extend(flat(&b));
            let (mut a, mut b) = (a0, b0);
            ta::adj_tile_map2(&x, &y, &mut a, &mut b, &r, |u, v, au, av, g| {
                adj_div(u, v, au, av, g)
            });
            out.extend(flat(&a));
            out.extend(flat(&b));
            vec![out, b"nofault".to_vec()]
        });
    }
}

/// `adj_tile_map1` (of `x / 3`) and `adj_tile_map2` (of `x * y` and `x / y`) with functors
/// calling the scalar adjoints.
#[test]
fn adjoint_maps_match() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_0003);
    let (mut script, mut want) = (Script::default(), Want::default());
    maps::<f32>(&mut rng, &mut script, &mut want);
    maps::<f64>(&mut rng, &mut script, &mut want);
    want.check(&script);
}

// ------------------------------------------------------------------------------------------
// Reductions
// ------------------------------------------------------------------------------------------

fn reductions<X>(name: &str, rng: &mut Rng, script: &mut Script, want: &mut Want)
where
    X: Tile<Elem: El> + Copy + Adjoint + 'static,
{
    type E<X> = <X as Tile>::Elem;
    let n = X::SIZE;
    let mut cases: Vec<(Vec<E<X>>, &str)> = vec![(E::<X>::draws(rng, n), "random")];
    // Ties: the smallest value at three places, the largest at three (the draws are within
    // +-256): the first of each gets the adjoint.
    let mut ties = E::<X>::draws(rng, n);
    for p in [1, n / 2, n - 1] {
        ties[p] = E::<X>::of(-300.0);
    }
    for p in [0, n / 3 + 1, n - 2] {
        ties[p] = E::<X>::of(300.0);
    }
    cases.push((ties, "ties"));
    // -0 and +0 tie: every element is the extremum, the first wins.
    let zeros = (0..n)
        .map(|i| E::<X>::of(if i % 3 == 1 { -0.0 } else { 0.0 }))
        .collect();
    cases.push((zeros, "signed zeros"));
    // NaN loses to every number.
    let mut nans = E::<X>::draws(rng, n);
    nans[0] = E::<X>::of(f64::NAN);
    nans[n / 2] = E::<X>::of(f64::NAN);
    cases.push((nans, "NaNs"));
    cases.push((vec![E::<X>::of(f64::NAN); n], "all NaN"));
    for (t, what) in cases {
        let r = [E::<X>::draw(rng)];
        let a0 = E::<X>::draws(rng, n);
        script.buf(0, &t);
        script.buf(1, &r);
        script.buf(2, &a0);
        script.run(&format!("red_{}_{name}", E::<X>::NAME));
        let (t, a0): (X, X) = (tile_of(&t), tile_of(&a0));
        let r = Tile1 { data: r };
        want.add(format!("reductions {name} {what}"), move |bd| {
            let mut out = Vec::new();
            let mut a = a0;
            ta::adj_tile_sum(&t, &mut a, &r, bd);
            out.extend(flat(&a));
            let mut a = a0;
            ta::adj_tile_min(&t, &mut a, &r, bd);
            out.extend(flat(&a));
            let mut a = a0;
            ta::adj_tile_max(&t, &mut a, &r, bd);
            out.extend(flat(&a));
            vec![out, b"nofault".to_vec()]
        });
    }
}

/// `adj_tile_sum`, `adj_tile_min`, `adj_tile_max` (ties: the first extremum; signed zeros;
/// NaNs), tiles larger and smaller than the block, rank 1 and 2.
#[test]
fn adjoint_reductions_match() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_0004);
    let (mut script, mut want) = (Script::default(), Want::default());
    reductions::<Tile1<f32, 300>>("300", &mut rng, &mut script, &mut want);
    reductions::<Tile1<f64, 300>>("300", &mut rng, &mut script, &mut want);
    reductions::<Tile2<f32, 13, 11>>("13x11", &mut rng, &mut script, &mut want);
    reductions::<Tile2<f64, 13, 11>>("13x11", &mut rng, &mut script, &mut want);
    reductions::<Tile1<f32, 5>>("5", &mut rng, &mut script, &mut want);
    reductions::<Tile1<f64, 5>>("5", &mut rng, &mut script, &mut want);
    want.check(&script);
}

// ------------------------------------------------------------------------------------------
// Shapes and matmul
// ------------------------------------------------------------------------------------------

fn shapes<E: El>(rng: &mut Rng, script: &mut Script, want: &mut Want) {
    // Transpose.
    let (x, r, a0) = (E::draws(rng, 35), E::draws(rng, 35), E::draws(rng, 35));
    script.buf(0, &x);
    script.buf(1, &r);
    script.buf(2, &a0);
    script.run(&format!("transpose_{}", E::NAME));
    want.add(format!("transpose {}", E::NAME), move |bd| {
        let x: Tile2<E, 7, 5> = tile_of(&x);
        let mut a: Tile2<E, 7, 5> = tile_of(&a0);
        let r: Tile2<E, 5, 7> = tile_of(&r);
        ta::adj_tile_transpose(&x, &mut a, &r, bd);
        vec![flat(&a), b"nofault".to_vec()]
    });
    // Broadcasts: order-sensitive targets (their sums are chains in row-major order).
    for case in 0..2 {
        let r1 = E::spiky(rng, 40);
        let mut r2 = E::spiky(rng, 143);
        r2[11] = E::BIG; // the second row too, for the column sums
        let a0 = E::draws(rng, 143);
        script.buf(0, &r1);
        script.buf(1, &r2);
        script.buf(2, &a0);
        script.run(&format!("bcast_{}", E::NAME));
        want.add(format!("broadcasts {} case {case}", E::NAME), move |bd| {
            let r1: Tile1<E, 40> = tile_of(&r1);
            let r2: Tile2<E, 13, 11> = tile_of(&r2);
            let mut out = Vec::new();
            macro_rules! b1 {
                ($f:ident, $x:ty, $r:expr) => {{
                    let mut s: $x = tile_of(&a0);
                    let x = s;
                    ta::$f(&x, &mut s, $r, bd);
                    out.extend(flat(&s));
                }};
            }
            b1!(adj_tile_broadcast11, Tile1<E, 1>, &r1);
            b1!(adj_tile_broadcast11, Tile1<E, 40>, &r1);
            b1!(adj_tile_broadcast12, Tile1<E, 11>, &r2);
            b1!(adj_tile_broadcast12, Tile1<E, 1>, &r2);
            b1!(adj_tile_broadcast22, Tile2<E, 1, 11>, &r2);
            b1!(adj_tile_broadcast22, Tile2<E, 13, 1>, &r2);
            b1!(adj_tile_broadcast22, Tile2<E, 1, 1>, &r2);
            b1!(adj_tile_broadcast22, Tile2<E, 13, 11>, &r2);
            vec![out, b"nofault".to_vec()]
        });
    }
}

/// `adj_tile_transpose` and `adj_tile_broadcast11/12/22` (every source shape that sums over
/// rows, columns, both or neither).
#[test]
fn adjoint_shapes_match() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_0005);
    let (mut script, mut want) = (Script::default(), Want::default());
    shapes::<f32>(&mut rng, &mut script, &mut want);
    shapes::<f64>(&mut rng, &mut script, &mut want);
    want.check(&script);
}

fn matmul<E: El, const M: usize, const K: usize, const N: usize>(
    rng: &mut Rng,
    script: &mut Script,
    want: &mut Want,
) {
    let v = [
        E::draws(rng, M * K),
        E::draws(rng, K * N),
        E::spiky(rng, M * N),
        E::draws(rng, M * K),
        E::draws(rng, K * N),
    ];
    for (k, v) in v.iter().enumerate() {
        script.buf(k, v);
    }
    let name = format!("mm_{}_{M}x{K}x{N}", E::NAME);
    script.run(&name);
    want.add(name, move |bd| {
        let a: Tile2<E, M, K> = tile_of(&v[0]);
        let b: Tile2<E, K, N> = tile_of(&v[1]);
        let r: Tile2<E, M, N> = tile_of(&v[2]);
        let mut aa: Tile2<E, M, K> = tile_of(&v[3]);
        let mut ab: Tile2<E, K, N> = tile_of(&v[4]);
        ta::adj_tile_matmul(&a, &b, &mut aa, &mut ab, &r, bd);
        let mut out = flat(&aa);
        out.extend(flat(&ab));
        vec![out, b"nofault".to_vec()]
    });
}

/// `adj_tile_matmul`: FMA chains over `r`'s columns and rows.
#[test]
fn adjoint_matmul_matches() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_0006);
    let (mut script, mut want) = (Script::default(), Want::default());
    for _ in 0..2 {
        matmul::<f32, 7, 13, 5>(&mut rng, &mut script, &mut want);
        matmul::<f32, 16, 8, 6>(&mut rng, &mut script, &mut want);
        matmul::<f32, 1, 1, 1>(&mut rng, &mut script, &mut want);
        matmul::<f32, 3, 33, 2>(&mut rng, &mut script, &mut want);
        matmul::<f64, 7, 13, 5>(&mut rng, &mut script, &mut want);
        matmul::<f64, 16, 8, 6>(&mut rng, &mut script, &mut want);
        matmul::<f64, 1, 1, 1>(&mut rng, &mut script, &mut want);
        matmul::<f64, 3, 33, 2>(&mut rng, &mut script, &mut want);
    }
    want.check(&script);
}

// ------------------------------------------------------------------------------------------
// Threads and elements
// ------------------------------------------------------------------------------------------

fn lanes<E: El, const N: usize>(rng: &mut Rng, script: &mut Script, want: &mut Want) {
    let (r, x0) = (E::draws(rng, N), E::draws(rng, 1024));
    let (a0, y) = (E::draws(rng, N), E::draws(rng, 1024));
    for (k, v) in [&r, &x0, &a0, &y].into_iter().enumerate() {
        script.buf(k, v);
    }
    script.run(&format!("lanes_{}_{N}", E::NAME));
    want.add(format!("lanes {} {N}", E::NAME), move |bd| {
        let r: Tile1<E, N> = tile_of(&r);
        let mut x = PerLane::<E>::new(bd);
        let mut ys = PerLane::<E>::new(bd);
        for l in 0..bd {
            x[l] = x0[l];
            ys[l] = y[l];
        }
        ta::adj_tile_lanes(&mut x, &r, bd);
        let mut out = bytes(x.lanes());
        let mut a: Tile1<E, N> = tile_of(&a0);
        ta::adj_untile(&mut a, &ys, bd);
        out.extend(flat(&a));
        vec![out, b"nofault".to_vec()]
    });
}

/// `adj_tile_lanes` (`tile(x)`) and `adj_untile`, with tiles shorter and longer than the block.
#[test]
fn adjoint_lanes_match() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_0007);
    let (mut script, mut want) = (Script::default(), Want::default());
    lanes::<f32, 40>(&mut rng, &mut script, &mut want);
    lanes::<f64, 40>(&mut rng, &mut script, &mut want);
    lanes::<f32, 300>(&mut rng, &mut script, &mut want);
    lanes::<f64, 300>(&mut rng, &mut script, &mut want);
    want.check(&script);
}

/// One `adj_tile_extract*` case: threads `0..count` (of the block) add `r[l]` at index `idx[l]`
/// (rank 2: `(idx[2l], idx[2l + 1])`).
struct Extract<E> {
    what: &'static str,
    count: usize,
    idx: Vec<i64>,
    r: Vec<E>,
    start: Vec<E>,
}

fn extracts<E: El>(rng: &mut Rng, script: &mut Script, want: &mut Want) {
    // Exactly representable: small integers, whose sums are exact in any order.
    let small = |rng: &mut Rng, n: usize| -> Vec<E> {
        (0..n)
            .map(|_| E::of((rng.next() % 9) as f64 - 4.0))
            .collect()
    };
    // Rank 1 (40 elements).
    let cases = vec![
        Extract {
            what: "one thread",
            count: 1,
            idx: vec![17; 1024],
            r: E::draws(rng, 1024),
            start: E::draws(rng, 40),
        },
        Extract {
            what: "distinct elements",
            count: 40,
            idx: (0..1024).map(|l| (l * 3) % 40).collect(),
            r: E::draws(rng, 1024),
            start: E::draws(rng, 40),
        },
        Extract {
            what: "shared elements, exact sums",
            count: 1024,
            idx: (0..1024).map(|l| (l * 7) % 40).collect(),
            r: small(rng, 1024),
            start: small(rng, 40),
        },
        Extract {
            what: "outside the tile",
            count: 3,
            idx: [5, 40, -1].into_iter().chain([0; 1021]).collect(),
            r: small(rng, 1024),
            start: small(rng, 40),
        },
    ];
    for c in cases {
        let tv = E::draws(rng, 40);
        script.buf(0, &tv);
        script.buf(1, &c.start);
        script.buf(2, &c.idx);
        script.buf(3, &c.r);
        script.off([c.count as i64, 0, 0, 0]);
        script.run(&format!("extract1_{}", E::NAME));
        want.add(format!("extract1 {} {}", E::NAME, c.what), move |bd| {
            let t: Tile1<E, 40> = tile_of(&tv);
            let mut a: Tile1<E, 40> = tile_of(&c.start);
            let mut res = Ok(());
            for l in 0..c.count.min(bd) {
                let e = ta::adj_tile_extract1(&t, c.idx[l], &mut a, &mut 0, c.r[l], "k");
                res = res.and(e);
            }
            vec![flat(&a), fault_line(res)]
        });
    }
    // Rank 2 (5 x 7; the column index an i32).
    let cases = vec![
        Extract {
            what: "one thread",
            count: 1,
            idx: [3, 6].repeat(1024),
            r: E::draws(rng, 1024),
            start: E::draws(rng, 35),
        },
        Extract {
            what: "distinct elements",
            count: 35,
            idx: (0..1024)
                .flat_map(|l| [(l * 2) % 35 / 7, (l * 2) % 35 % 7])
                .collect(),
            r: E::draws(rng, 1024),
            start: E::draws(rng, 35),
        },
        Extract {
            what: "shared elements, exact sums",
            count: 1024,
            idx: (0..1024).flat_map(|l| [l % 5, (l / 5) % 7]).collect(),
            r: small(rng, 1024),
            start: small(rng, 35),
        },
        Extract {
            what: "outside the tile",
            count: 4,
            idx: [1, 2, 5, 0, 0, -1, -1, 7]
                .into_iter()
                .chain([0; 2040])
                .collect(),
            r: small(rng, 1024),
            start: small(rng, 35),
        },
    ];
    for c in cases {
        let tv = E::draws(rng, 35);
        script.buf(0, &tv);
        script.buf(1, &c.start);
        script.buf(2, &c.idx);
        script.buf(3, &c.r);
        script.off([c.count as i64, 0, 0, 0]);
        script.run(&format!("extract2_{}", E::NAME));
        want.add(format!("extract2 {} {}", E::NAME, c.what), move |bd| {
            let t: Tile2<E, 5, 7> = tile_of(&tv);
            let mut a: Tile2<E, 5, 7> = tile_of(&c.start);
            let mut res = Ok(());
            for l in 0..c.count.min(bd) {
                let (i, j) = (c.idx[2 * l], c.idx[2 * l + 1] as i32);
                let e = ta::adj_tile_extract2(&t, i, j, &mut a, &mut 0, &mut 0, c.r[l], "k");
                res = res.and(e);
            }
            vec![flat(&a), fault_line(res)]
        });
    }
}

/// `adj_tile_extract1/2` from one thread, from many at distinct elements, from many at shared
/// elements with exact sums (the GPU's atomics have no fixed order), and outside the tile (the
/// forward's TileIndex fault on both sides; the threads inside still add).
#[test]
fn adjoint_extracts_match() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_0008);
    let (mut script, mut want) = (Script::default(), Want::default());
    extracts::<f32>(&mut rng, &mut script, &mut want);
    extracts::<f64>(&mut rng, &mut script, &mut want);
    want.check(&script);
}

// ------------------------------------------------------------------------------------------
// Atomic add
// ------------------------------------------------------------------------------------------

fn atomics<E: El>(rng: &mut Rng, script: &mut Script, want: &mut Want) {
    // Rank 1, a 37-element tile at `o` of an array of `n`, with and without a gradient.
    for n in [0usize, 5, 50] {
        for o in [0i64, -5, 3, n as i64 - 2, i64::MIN, i64::MAX] {
            for grad in [true, false] {
                let (a, g) = (E::draws(rng, n), E::draws(rng, n));
                let (t, r, at0) = (E::draws(rng, 37), E::draws(rng, 37), E::draws(rng, 37));
                script.buf(0, &a);
                script.buf(1, &g);
                script.buf(2, &at0);
                script.buf(3, &t);
                script.buf(4, &r);
                script.arr(E::K1, 0, &[n], Some(0));
                script.arr(E::K1, 1, &[n], grad.then_some(1));
                script.off([o, 0, 0, 0]);
                script.run(&format!("atomic1_{}", E::NAME));
                script.dump(1);
                let what = format!("adj_tile_atomic_add1 {} n {n} at {o} grad {grad}", E::NAME);
                want.add(what, move |bd| {
                    let (mut a, mut g) = (a.clone(), g.clone());
                    let mut gv = match grad {
                        true => GradView::new(view(&mut g, [n])),
                        false => GradView::none(),
                    };
                    let (t, r): (Tile1<E, 37>, Tile1<E, 37>) = (tile_of(&t), tile_of(&r));
                    let mut at: Tile1<E, 37> = tile_of(&at0);
                    let av = view(&mut a, [n]);
                    let res =
                        ta::adj_tile_atomic_add1(&av, &t, o, &mut gv, &mut at, &mut 0, &r, bd);
                    vec![flat(&at), fault_line(res), bytes(&g)]
                });
            }
        }
    }
    // Rank 2, a 5 x 7 tile (the column offset an i32).
    for shape in [[4usize, 6], [9, 10], [0, 3]] {
        for o in [[0i64, 0], [-3, -2], [2, 3], [i64::MIN, 1], [6, 5]] {
            for grad in [true, false] {
                let len = shape[0] * shape[1];
                let (a, g) = (E::draws(rng, len), E::draws(rng, len));
                let (t, r, at0) = (E::draws(rng, 35), E::draws(rng, 35), E::draws(rng, 35));
                script.buf(0, &a);
                script.buf(1, &g);
                script.buf(2, &at0);
                script.buf(3, &t);
                script.buf(4, &r);
                script.arr(E::K2, 0, &shape, Some(0));
                script.arr(E::K2, 1, &shape, grad.then_some(1));
                script.off([o[0], o[1], 0, 0]);
                script.run(&format!("atomic2_{}", E::NAME));
                script.dump(1);
                let what = format!(
                    "adj_tile_atomic_add2 {} {shape:?} at {o:?} grad {grad}",
                    E::NAME
                );
                want.add(what, move |bd| {
                    let (mut a, mut g) = (a.clone(), g.clone());
                    let mut gv = match grad {
                        true => GradView::new(view(&mut g, shape)),
                        false => GradView::none(),
                    };
                    let (t, r): (Tile2<E, 5, 7>, Tile2<E, 5, 7>) = (tile_of(&t), tile_of(&r));
                    let mut at: Tile2<E, 5, 7> = tile_of(&at0);
                    let av = view(&mut a, shape);
                    let (o0, o1) = (o[0], o[1] as i32);
                    let res = ta::adj_tile_atomic_add2(
                        &av, &t, o0, o1, &mut gv, &mut at, &mut 0, &mut 0, &r, bd,
                    );
                    vec![flat(&at), fault_line(res), bytes(&g)]
                });
            }
        }
    }
}

/// `adj_tile_atomic_add*`: the tile's adjoint gathers the gradient over the window (nothing
/// outside the array, nothing without a gradient), the gradient unchanged.
#[test]
fn adjoint_atomic_add_matches() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_00a7);
    let (mut script, mut want) = (Script::default(), Want::default());
    atomics::<f32>(&mut rng, &mut script, &mut want);
    atomics::<f64>(&mut rng, &mut script, &mut want);
    want.check(&script);
}

/// The f16 matmul's adjoint: a seed of `R` (f16, or the f32 accumulator's) against
/// warp-core's, bit for bit (f32 chains of exact products, each rounded once to f16).
fn matmul_h<R, const M: usize, const K: usize, const N: usize>(
    rng: &mut Rng,
    script: &mut Script,
    want: &mut Want,
    seed: impl Fn(f32) -> R,
) where
    R: warp_core::tile::MatmulElem<Acc = f32> + Copy + 'static,
{
    use warp_core::f16;
    // f16 values (and seeds) as their bits, little-endian (half's f16 is not bytemuck's Pod).
    fn le<X: Copy>(v: &[X]) -> Vec<u8> {
        let n = std::mem::size_of::<X>();
        // SAFETY: f16 and f32 are plain bit patterns of `n` bytes.
        v.iter()
            .flat_map(|x| unsafe { std::slice::from_raw_parts(x as *const X as *const u8, n) })
            .copied()
            .collect()
    }
    let hs = |rng: &mut Rng, n: usize| -> Vec<f16> {
        (0..n).map(|_| f16::from_f32(rng.f32())).collect()
    };
    let (a, b) = (hs(rng, M * K), hs(rng, K * N));
    let r: Vec<R> = (0..M * N).map(|_| seed(rng.f32())).collect();
    let (aa0, ab0) = (hs(rng, M * K), hs(rng, K * N));
    script.text += &format!("buf 0 {}\n", hex(&le(&a)));
    script.text += &format!("buf 1 {}\n", hex(&le(&b)));
    script.text += &format!("buf 2 {}\n", hex(&le(&r)));
    script.text += &format!("buf 3 {}\n", hex(&le(&aa0)));
    script.text += &format!("buf 4 {}\n", hex(&le(&ab0)));
    let rname = if std::mem::size_of::<R>() == 2 {
        "f16"
    } else {
        "f32"
    };
    let name = format!("mmh_{rname}_{M}x{K}x{N}");
    script.run(&name);
    want.add(name, move |bd| {
        let mut ta_ = Tile2::<f16, M, K> {
            data: [[f16::ZERO; K]; M],
        };
        let mut tb = Tile2::<f16, K, N> {
            data: [[f16::ZERO; N]; K],
        };
        let mut tr = Tile2::<R, M, N> {
            data: [[r[0]; N]; M],
        };
        let mut aa = Tile2::<f16, M, K> {
            data: [[f16::ZERO; K]; M],
        };
        let mut ab = Tile2::<f16, K, N> {
            data: [[f16::ZERO; N]; K],
        };
        for i in 0..M {
            for k in 0..K {
                ta_.data[i][k] = a[i * K + k];
                aa.data[i][k] = aa0[i * K + k];
            }
            for j in 0..N {
                tr.data[i][j] = r[i * N + j];
            }
        }
        for k in 0..K {
            for j in 0..N {
                tb.data[k][j] = b[k * N + j];
                ab.data[k][j] = ab0[k * N + j];
            }
        }
        ta::adj_tile_matmul(&ta_, &tb, &mut aa, &mut ab, &tr, bd);
        let mut out = le(aa.data.as_flattened());
        out.extend(le(ab.data.as_flattened()));
        vec![out, b"nofault".to_vec()]
    });
}

/// `adj_tile_matmul` of f16 operands, both seeds (the returning form's f16, the accumulating
/// form's f32), at a ragged shape and the tensor cores' 16 x 16 x 8.
#[test]
fn adjoint_f16_matmul_matches() {
    if !have_gpp() {
        return;
    }
    let mut rng = Rng::seeded(0xad_0f16);
    let (mut script, mut want) = (Script::default(), Want::default());
    let h = warp_core::f16::from_f32;
    for _ in 0..2 {
        matmul_h::<_, 7, 13, 5>(&mut rng, &mut script, &mut want, h);
        matmul_h::<_, 16, 16, 8>(&mut rng, &mut script, &mut want, h);
        matmul_h::<_, 7, 13, 5>(&mut rng, &mut script, &mut want, |x: f32| x);
        matmul_h::<_, 16, 16, 8>(&mut rng, &mut script, &mut want, |x: f32| x);
    }
    want.check(&script);
}
