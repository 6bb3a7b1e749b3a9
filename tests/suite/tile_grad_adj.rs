//! Backward through `tile_atomic_add` and through the f16 `tile_matmul` (both forms).
//!
//! `tile_atomic_add(a, t, offsets)`: the value tile's adjoint gathers `a`'s gradient over the
//! window (elements outside the array get nothing), as Warp's `adj_tile_atomic_add`; the
//! returned tile of old values carries no gradient (Warp drops its adjoint), and since the
//! adjoint's replay does not redo atomics, a kernel that reads it is refused, as for the
//! scalar atomics. Checked by `gradcheck` in f64 (tolerance 1e-6 relative, `tile_grad`'s) with
//! windows that overlap between blocks and stick out of the array, and CPU against GPU to 1e-13
//! relative (the overlapping adds meet in an order the GPU's atomics decide).
//!
//! f16 `tile_matmul`: the adjoint tiles of f16 operands are f16 (as Warp's, whose adjoint
//! tiles have the operands' type); each of their elements' sums (`r bᵀ`, `aᵀ r`) is one f32
//! FMA chain of exact products (the forward's arithmetic), rounded once to f16 and added to
//! the f16 adjoint. Tolerance against the f64 product of the same f16 values: each gradient
//! element here goes through at most four f16 roundings (each contribution's, the adjoint
//! tile's two additions, the array gradient's), each at most 2^-11 relative of a value no
//! larger than `S`, the sum of the magnitudes of its terms, plus the f32 chains' `n 2^-24 S`
//! (n <= 16): `|g - g64| <= 2^-8 S` holds with room, while a missing or misplaced term (of
//! the order of `S / n`) is far outside it.

use crate::tile_grad::{check, values};
use crate::{arr, host};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    tile_atomic_add_gradcheck,
    tile_atomic_add_old_values_refused,
    integer_tile_atomic_add_beside_gradients,
    f16_matmul_backward,
    f16_gemm_k_loop_backward,
);

const R: usize = 4;
const C: usize = 3;

/// `tile_atomic_add` of a function of a loaded tile into `acc`, at windows that overlap (rows
/// `2 i .. 2 i + 4`, columns `2 j .. 2 j + 3`) and stick out of the 4 x 4 `acc`: `x`'s columns
/// 5 and 6 land outside it.
#[wp::kernel]
fn k_atomic(x: Array<f64, 2>, w: Array<f64>, acc: Array<f64, 2>) {
    let (i, j) = tid();
    let t: Tile<f64, R, C> = tile_load(x, ((i * R) as i32, (j * C) as i32));
    let u = t * t * w[0] + t;
    tile_atomic_add(acc, u, ((i * 2) as i32, (j * 2) as i32));
}

/// A nonlinear read of `acc`, so that its gradient differs element by element.
#[wp::kernel]
fn k_post(acc: Array<f64, 2>, out: Array<f64, 2>) {
    let (i, j) = tid();
    let v = acc[(i, j)];
    out[(i, j)] = v * v * 0.5 + v * (i as f64 + 1.0) - (j as f64) * v;
}

const XM: usize = 5;
const XN: usize = 7;
const AM: usize = 4;
const AN: usize = 4;

struct AtomicCase {
    x: wp::Array<f64>,
    w: wp::Array<f64>,
    acc: wp::Array<f64>,
    out: wp::Array<f64>,
}

impl AtomicCase {
    fn new(dev: &wp::Device) -> Self {
        AtomicCase {
            x: arr(&values(XM * XN, 3), dev).with_grad().unwrap(),
            w: arr(&[0.7f64], dev).with_grad().unwrap(),
            acc: arr(&[0.0f64; AM * AN], dev).with_grad().unwrap(),
            out: arr(&[0.0f64; AM * AN], dev).with_grad().unwrap(),
        }
    }

    /// Zeroes `acc`, then the two launches.
    fn run(&self, bd: usize, dev: &wp::Device) -> wp::Result<()> {
        self.acc.fill(0.0)?;
        let x2 = self.x.reshape((XM, XN))?;
        let acc2 = self.acc.reshape((AM, AN))?;
        let out2 = self.out.reshape((AM, AN))?;
        let blocks = (XM.div_ceil(R), XN.div_ceil(C));
        wp::launch_tiled(k_atomic, blocks, (&x2, &self.w, &acc2), bd, dev)?;
        wp::launch(k_post, (AM, AN), (&acc2, &out2), dev)
    }
}

/// Gradcheck through `tile_atomic_add` at block sizes 1, 5 and 32 with respect to `x` (each
/// element in one block's tile) and the uniform scalar `w`; the elements whose window position
/// is outside the array get exactly zero.
fn tile_atomic_add_gradcheck(dev: &wp::Device) {
    let case = AtomicCase::new(dev);
    for bd in [1, 5, 32] {
        let run = || case.run(bd, dev);
        check(
            &format!("tile_atomic_add, block_dim {bd}"),
            run,
            &[&case.x, &case.w],
            &case.out,
        );
    }
    // Elements whose window position is outside `acc` get nothing (their only path is the
    // add): x's columns 5 and 6; every other element of x gets something.
    let gx = &atomic_grads(dev)[0];
    for (e, g) in gx.iter().enumerate() {
        let outside = e % XN >= 5;
        assert_eq!(
            *g == 0.0,
            outside,
            "x[{}][{}]: gradient {g}",
            e / XN,
            e % XN
        );
    }
}

/// The returned tile read by the kernel: refused with the reason (the adjoint's replay does
/// not redo the atomic, so it cannot have the old values).
#[wp::kernel]
fn k_atomic_old(x: Array<f64>, acc: Array<f64>, out: Array<f64>) {
    let t = tile_load::<8>(x, 0);
    let old = tile_atomic_add(acc, t, 0);
    tile_store(out, old * t, 0);
}

fn tile_atomic_add_old_values_refused(dev: &wp::Device) {
    let x = arr(&values(8, 4), dev).with_grad().unwrap();
    let acc = arr(&values(8, 5), dev).with_grad().unwrap();
    let out = arr(&[0.0f64; 8], dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_atomic_old, 1, (&x, &acc, &out), 8, dev).unwrap();
    }
    let e = tape.backward(&out).unwrap_err();
    assert!(matches!(e, wp::Error::NotDifferentiable { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("k_atomic_old") && msg.contains("tile_atomic_add"),
        "{msg}"
    );
}

/// The gradients of `x`, `w` and `acc` after one backward of [`AtomicCase`] seeded with ones.
fn atomic_grads(dev: &wp::Device) -> Vec<Vec<f64>> {
    let case = AtomicCase::new(dev);
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        case.run(32, dev).unwrap();
    }
    case.out.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    [&case.x, &case.w, &case.acc]
        .iter()
        .map(|a| a.grad().unwrap().to_vec().unwrap())
        .collect()
}

/// The same `tile_atomic_add` gradients on the CPU and a GPU, to 1e-13 relative: the windows
/// overlap, so an element of `acc` is the sum of several blocks' adds in an order the GPU's
/// atomics decide (seen on an H200: the last bit or two of some `x` gradients, through `k_post`'s
/// read of `acc`), and `w`'s gradient is summed over blocks through atomics too. A few f64
/// roundings apart is far below 1e-13; a missing or misplaced contribution is far above it.
/// Skipped, saying so, without a GPU.
#[test]
fn tile_atomic_add_gradients_cpu_and_gpu_agree() {
    let Ok(gpu) = wp::get_device(&crate::test_gpu()) else {
        eprintln!("SKIPPED tile_atomic_add_gradients_cpu_and_gpu_agree: no GPU");
        return;
    };
    let _gpu = crate::gpu_lock();
    let cpu = wp::get_device("cpu").unwrap();
    let (c, g) = (atomic_grads(&cpu), atomic_grads(&gpu));
    for (k, (c, g)) in c.iter().zip(&g).enumerate() {
        assert_eq!(c.len(), g.len(), "input {k}");
        for (e, (x, y)) in c.iter().zip(g).enumerate() {
            assert!(
                (x - y).abs() <= 1e-13 * x.abs().max(1.0),
                "input {k}, element {e}: CPU {x} vs GPU {y}"
            );
        }
    }
}

// ---- f16 matmul --------------------------------------------------------------------------

const HM: usize = 16;
const HK: usize = 16;
const HN: usize = 8;

/// Both forms of the f16 matmul on one pair of tiles: `p = a b` (f16) and `c += a b` (f32).
/// The arrays are ragged (15 x 13 and 13 x 7), the tiles the tensor cores' shapes.
#[wp::kernel]
fn k_mm_f16(a: Array<f16, 2>, b: Array<f16, 2>, p: Array<f16, 2>, c: Array<f32, 2>) {
    let ta: Tile<f16, HM, HK> = tile_load(a, (0, 0));
    let tb: Tile<f16, HK, HN> = tile_load(b, (0, 0));
    let t = tile_matmul(ta, tb);
    tile_store(p, t, (0, 0));
    let mut acc = tile_zeros::<f32, HM, HN>();
    tile_matmul(ta, tb, &mut acc);
    tile_store(c, acc, (0, 0));
}

fn h(x: f64) -> f16 {
    f16::from_f32(x as f32)
}

/// Values in [-1, 1) as f16 (full significands).
fn hvalues(n: usize, seed: usize) -> Vec<f16> {
    (0..n)
        .map(|t| h((((t * 7919 + seed) % 2039) as f64) / 1019.5 - 1.0))
        .collect()
}

/// `ā = (p̄ + c̄) bᵀ` and `b̄ = aᵀ (p̄ + c̄)` of both forms, at block sizes 1, 32 and 64
/// (whole warps: the forward on tensor cores on an sm_80+ GPU), against the f64 products of
/// the same f16 values within the module docs' `2^-8 S`.
fn f16_matmul_backward(dev: &wp::Device) {
    let (m, k, n) = (15usize, 13usize, 7usize);
    let (ad, bd_) = (hvalues(m * k, 3), hvalues(k * n, 11));
    let gp = hvalues(m * n, 5);
    let gc: Vec<f32> = hvalues(m * n, 9).iter().map(|v| v.to_f32() * 0.5).collect();
    for bd in [1, 32, 64] {
        let a = wp::Array::from_slice_shape(&ad, (m, k), dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let b = wp::Array::from_slice_shape(&bd_, (k, n), dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let p = wp::Array::<f16, 2>::zeros((m, n), dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let c = wp::Array::<f32, 2>::zeros((m, n), dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            wp::launch_tiled(k_mm_f16, 1, (&a, &b, &p, &c), bd, dev).unwrap();
        }
        let seed_p = wp::Array::from_slice_shape(&gp, (m, n), dev).unwrap();
        let seed_c = wp::Array::from_slice_shape(&gc, (m, n), dev).unwrap();
        p.grad().unwrap().copy_from(&seed_p).unwrap();
        c.grad().unwrap().copy_from(&seed_c).unwrap();
        tape.backward_from_grads().unwrap();
        let ga = host(&a.grad().unwrap());
        let gb = host(&b.grad().unwrap());
        // The seed of the product, in f64 (both forms' seeds add up in the reference).
        let r = |i: usize, j: usize| gp[i * n + j].to_f32() as f64 + gc[i * n + j] as f64;
        let (av, bv) = (
            |i: usize, q: usize| ad[i * k + q].to_f32() as f64,
            |q: usize, j: usize| bd_[q * n + j].to_f32() as f64,
        );
        for i in 0..m {
            for q in 0..k {
                let (want, mag) = (0..n).fold((0.0, 0.0), |(s, g), j| {
                    let (x, y) = (r(i, j) * bv(q, j), r(i, j).abs() * bv(q, j).abs());
                    (s + x, g + y)
                });
                let got = ga[i * k + q].to_f32() as f64;
                assert!(
                    (got - want).abs() <= mag / 256.0,
                    "ā[{i}][{q}] at block_dim {bd}: {got} vs {want} (S = {mag})"
                );
            }
        }
        for q in 0..k {
            for j in 0..n {
                let (want, mag) = (0..m).fold((0.0, 0.0), |(s, g), i| {
                    let (x, y) = (av(i, q) * r(i, j), av(i, q).abs() * r(i, j).abs());
                    (s + x, g + y)
                });
                let got = gb[q * n + j].to_f32() as f64;
                assert!(
                    (got - want).abs() <= mag / 256.0,
                    "b̄[{q}][{j}] at block_dim {bd}: {got} vs {want} (S = {mag})"
                );
            }
        }
    }
}

/// The CUDA adjoints the GPU compiles (their text checked here without one): the atomic's
/// adjoint call and no replay of the atomic itself; both f16 matmuls' adjoint calls.
#[test]
fn cuda_adjoints_call_the_new_rules() {
    let info = wp::kernel_info(k_atomic);
    assert!(
        info.adjoint_error.is_none() && info.cuda_adjoint_error.is_none(),
        "{:?} {:?}",
        info.adjoint_error,
        info.cuda_adjoint_error
    );
    let adj = &info.cuda_adjoint;
    assert!(adj.contains("wp::adj_tile_atomic_add2("), "{adj}");
    assert!(
        !adj.contains("wp::tile_atomic_add("),
        "the replay redoes it: {adj}"
    );
    let info = wp::kernel_info(k_mm_f16);
    assert!(
        info.adjoint_error.is_none() && info.cuda_adjoint_error.is_none(),
        "{:?} {:?}",
        info.adjoint_error,
        info.cuda_adjoint_error
    );
    let adj = &info.cuda_adjoint;
    assert_eq!(adj.matches("wp::adj_tile_matmul(").count(), 2, "{adj}");
}

/// An integer `tile_atomic_add` (a counter) in a kernel that is differentiated for its floats:
/// nothing to propagate through the counter, and it is not redone by the backward pass.
#[wp::kernel]
fn k_count(x: Array<f64>, count: Array<i32>, out: Array<f64>) {
    let b = tid();
    let t = tile_load::<8>(x, (b * 8) as i32);
    tile_atomic_add(count, tile_ones::<i32, 8>(), 0);
    tile_store(out, t * t, (b * 8) as i32);
}

fn integer_tile_atomic_add_beside_gradients(dev: &wp::Device) {
    let x = arr(&values(16, 7), dev).with_grad().unwrap();
    let count = arr(&[0i32; 8], dev);
    let out = arr(&[0.0f64; 16], dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_count, 2, (&x, &count, &out), 8, dev).unwrap();
    }
    out.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    assert_eq!(
        host(&count),
        vec![2; 8],
        "the backward pass redid the atomic"
    );
    let (xs, gx) = (host(&x), host(&x.grad().unwrap()));
    for (k, (v, g)) in xs.iter().zip(&gx).enumerate() {
        assert_eq!(*g, 2.0 * v, "x[{k}]");
    }
}

const KM: usize = 16;
const KK: usize = 16;
const KN: usize = 8;

/// An f16 GEMM's k-loop (the form the CUDA emitter pipelines on tensor cores) with an f32
/// accumulator, stored as f32.
#[wp::kernel]
fn k_gemm_f16(a: Array<f16, 2>, b: Array<f16, 2>, kt: i32, c: Array<f32, 2>) {
    let mut acc = tile_zeros::<f32, KM, KN>();
    for k in 0..kt {
        let ta = tile_load::<KM, KK>(a, (0, k * KK as i32));
        let tb = tile_load::<KK, KN>(b, (k * KK as i32, 0));
        tile_matmul(ta, tb, &mut acc);
    }
    tile_store(c, acc, (0, 0));
}

/// Backward through the k-loop over three k-steps (the last ragged: K = 37) at block sizes 1,
/// 32 and 64: each gradient element gets one step's contribution, within the module docs'
/// `2^-8 S` of the f64 product.
fn f16_gemm_k_loop_backward(dev: &wp::Device) {
    let (m, k, n) = (KM, 37usize, KN);
    let (ad, bd_) = (hvalues(m * k, 21), hvalues(k * n, 23));
    let gc: Vec<f32> = hvalues(m * n, 25).iter().map(|v| v.to_f32()).collect();
    for bd in [1, 32, 64] {
        let a = wp::Array::from_slice_shape(&ad, (m, k), dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let b = wp::Array::from_slice_shape(&bd_, (k, n), dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let c = wp::Array::<f32, 2>::zeros((m, n), dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            let kt = k.div_ceil(KK) as i32;
            wp::launch_tiled(k_gemm_f16, 1, (&a, &b, kt, &c), bd, dev).unwrap();
        }
        let seed = wp::Array::from_slice_shape(&gc, (m, n), dev).unwrap();
        c.grad().unwrap().copy_from(&seed).unwrap();
        tape.backward_from_grads().unwrap();
        let (ga, gb) = (host(&a.grad().unwrap()), host(&b.grad().unwrap()));
        let r = |i: usize, j: usize| gc[i * n + j] as f64;
        let av = |i: usize, q: usize| ad[i * k + q].to_f32() as f64;
        let bv = |q: usize, j: usize| bd_[q * n + j].to_f32() as f64;
        for i in 0..m {
            for q in 0..k {
                let (want, mag) = (0..n).fold((0.0, 0.0), |(s, g), j| {
                    (s + r(i, j) * bv(q, j), g + (r(i, j) * bv(q, j)).abs())
                });
                let got = ga[i * k + q].to_f32() as f64;
                assert!(
                    (got - want).abs() <= mag / 256.0,
                    "ā[{i}][{q}] at block_dim {bd}: {got} vs {want}"
                );
            }
        }
        for q in 0..k {
            for j in 0..n {
                let (want, mag) = (0..m).fold((0.0, 0.0), |(s, g), i| {
                    (s + av(i, q) * r(i, j), g + (av(i, q) * r(i, j)).abs())
                });
                let got = gb[q * n + j].to_f32() as f64;
                assert!(
                    (got - want).abs() <= mag / 256.0,
                    "b̄[{q}][{j}] at block_dim {bd}: {got} vs {want}"
                );
            }
        }
    }
}

/// `k_mm_f16`'s gradients (both forms, one backward) on `dev` at block size 64.
fn f16_matmul_grads(dev: &wp::Device) -> Vec<Vec<u16>> {
    let (m, k, n) = (15usize, 13usize, 7usize);
    let a = wp::Array::from_slice_shape(&hvalues(m * k, 3), (m, k), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let b = wp::Array::from_slice_shape(&hvalues(k * n, 11), (k, n), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let p = wp::Array::<f16, 2>::zeros((m, n), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let c = wp::Array::<f32, 2>::zeros((m, n), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_mm_f16, 1, (&a, &b, &p, &c), 64, dev).unwrap();
    }
    let gc: Vec<f32> = hvalues(m * n, 9).iter().map(|v| v.to_f32()).collect();
    let seed_p = wp::Array::from_slice_shape(&hvalues(m * n, 5), (m, n), dev).unwrap();
    let seed_c = wp::Array::from_slice_shape(&gc, (m, n), dev).unwrap();
    p.grad().unwrap().copy_from(&seed_p).unwrap();
    c.grad().unwrap().copy_from(&seed_c).unwrap();
    tape.backward_from_grads().unwrap();
    [&a, &b]
        .iter()
        .map(|x| {
            host(&x.grad().unwrap())
                .iter()
                .map(|v| v.to_bits())
                .collect()
        })
        .collect()
}

/// The f16 matmul's gradients on the CPU and a GPU, bit for bit: the adjoint is the FMA-chain
/// rule on both (not the tensor cores, which only the GPU's forward uses), each element of the
/// operands' gradients one such chain per form, added in the same order. Skipped, saying so,
/// without a GPU.
#[test]
fn f16_matmul_gradients_cpu_and_gpu_agree() {
    let Ok(gpu) = wp::get_device(&crate::test_gpu()) else {
        eprintln!("SKIPPED f16_matmul_gradients_cpu_and_gpu_agree: no GPU");
        return;
    };
    let _gpu = crate::gpu_lock();
    let cpu = wp::get_device("cpu").unwrap();
    assert_eq!(f16_matmul_grads(&cpu), f16_matmul_grads(&gpu));
}
