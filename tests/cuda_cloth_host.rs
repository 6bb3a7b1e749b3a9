//! The implicit cloth scene's kernels (examples/common/implicit_cloth.rs) without a GPU: their
//! CUDA translation units, as the runtime assembles them for NVRTC, compiled as host C++ with
//! g++ against `warp-cuda/cuda/` and run on a 5 x 5 cloth in a bent, moving state, against the
//! CPU backend, bit for bit.
//!
//! Bit-exact is the right tolerance: both sides do the same IEEE f32 operations in the same
//! order (g++ with `-ffp-contract=off`: no FMA contraction; `sqrt` is correctly rounded on
//! both). On a GPU, FMA contraction changes the last bits, which the scene tests
//! (tests/suite/scenes.rs) allow for; this test is about the generated code's meaning: the
//! row iteration `for s in bsr_row(a, i)`, `bsr_col`, `bsr_set_block` of `Mat3` blocks,
//! `outer`'s orientation, the neighbour offsets and the held corners.

use warp_lang as wp;
use wp::prelude::*;

// `implicit_cloth` reaches the sparse tier as `super::sparse`.
#[allow(unused_imports)]
use warp_runtime::sparse;
#[path = "common/host_cpp.rs"]
mod host_cpp;
#[path = "../examples/common/implicit_cloth.rs"]
mod implicit_cloth;

use implicit_cloth::{Params, Spring};
use warp_runtime::sparse::Bsr;

/// A kernel argument: a scalar or vector (its 32-bit words and C++ type), an array of 32-bit
/// words, or a `Bsr<Mat3>`.
enum HArg<'a> {
    /// A by-value parameter: its words and C++ type.
    Val(Vec<u32>, &'static str),
    /// An array: its words, element count and C++ element type.
    Arr(Vec<u32>, usize, &'static str),
    Bsr(&'a Bsr<Mat3>),
}

fn f(x: f32) -> HArg<'static> {
    HArg::Val(vec![x.to_bits()], "wp::f32")
}

fn i(x: i32) -> HArg<'static> {
    HArg::Val(vec![x as u32], "wp::i32")
}

fn v3(x: Vec3) -> HArg<'static> {
    HArg::Val(x.to_array().map(f32::to_bits).to_vec(), "wp::Vec3")
}

fn a3(a: &wp::Array<Vec3>) -> HArg<'static> {
    let v = a.to_vec().unwrap();
    let w = v.iter().flat_map(|p| p.to_array()).map(f32::to_bits);
    HArg::Arr(w.collect(), v.len(), "wp::Vec3")
}

fn af(a: &wp::Array<f32>) -> HArg<'static> {
    let v = a.to_vec().unwrap();
    HArg::Arr(v.iter().map(|x| x.to_bits()).collect(), v.len(), "wp::f32")
}

fn ai(a: &wp::Array<i32>) -> HArg<'static> {
    let v = a.to_vec().unwrap();
    HArg::Arr(v.iter().map(|&x| x as u32).collect(), v.len(), "wp::i32")
}

fn ai2(a: &wp::Array<IVec2>) -> HArg<'static> {
    let v = a.to_vec().unwrap();
    let w = v.iter().flat_map(|p| p.to_array()).map(|x| x as u32);
    HArg::Arr(w.collect(), v.len(), "wp::IVec2")
}

/// The words a run leaves in the arguments that it may write: every array and the matrix's
/// values, in argument order.
fn words(args: &[HArg]) -> Vec<u32> {
    let mut out = Vec::new();
    for a in args {
        match a {
            HArg::Val(..) => {}
            HArg::Arr(w, ..) => out.extend(w),
            HArg::Bsr(m) => {
                let v = m.values().to_vec().unwrap();
                let n = m.nnz().unwrap();
                out.extend(
                    v[..n]
                        .iter()
                        .flat_map(|b| b.to_cols_array())
                        .map(f32::to_bits),
                );
            }
        }
    }
    out
}

/// Runs K's CUDA unit under g++ (no FMA contraction) over `dim` threads, one after another,
/// with `args`; returns `words` of the arguments after the run, or None without g++.
fn host_run<K: wp::Kernel>(dim: usize, args: &[HArg]) -> Option<Vec<u32>> {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_cloth_host: no g++ on this machine");
        return None;
    }
    let info = &K::INFO;
    let src = wp::cuda_source::assemble(info);
    let (mut decl, mut print) = (String::new(), String::new());
    let list = |w: &[u32]| {
        let mut s: Vec<String> = w.iter().map(|x| format!("{x}u")).collect();
        s.push("0u".into());
        s.join(", ")
    };
    for (k, a) in args.iter().enumerate() {
        match a {
            HArg::Val(w, ty) => {
                decl += &format!("static unsigned int d{k}[] = {{{}}};\n", list(w));
                decl += &format!("{ty} p{k}; std::memcpy(&p{k}, d{k}, sizeof(p{k}));\n");
            }
            HArg::Arr(w, n, ty) => {
                let size = 4 * (w.len() / (*n).max(1));
                decl += &format!(
                    "alignas(16) static unsigned int d{k}[] = {{{}}};\n",
                    list(w)
                );
                decl += &format!(
                    "wp::array_t<{ty}, 1> p{k} = {{({ty}*)d{k}, {{{n}}}, {{{size}}}, {k}, 0}};\n"
                );
                print += &format!(
                    "for (int e = 0; e < {}; ++e) printf(\"%u\\n\", d{k}[e]);\n",
                    w.len()
                );
            }
            HArg::Bsr(m) => {
                let off = m.offsets().to_vec().unwrap();
                let col = m.columns().to_vec().unwrap();
                let nnz = m.nnz().unwrap();
                let vals: Vec<u32> = m.values().to_vec().unwrap()[..nnz]
                    .iter()
                    .flat_map(|b| b.to_cols_array())
                    .map(f32::to_bits)
                    .collect();
                let ints = |v: &[i32]| v.iter().map(|&x| x as u32).collect::<Vec<u32>>();
                decl += &format!(
                    "alignas(16) static unsigned int o{k}[] = {{{}}};\n",
                    list(&ints(&off))
                );
                decl += &format!(
                    "alignas(16) static unsigned int c{k}[] = {{{}}};\n",
                    list(&ints(&col[..nnz]))
                );
                decl += &format!(
                    "alignas(16) static unsigned int d{k}[] = {{{}}};\n",
                    list(&vals)
                );
                decl += &format!(
                    "wp::bsr_t<wp::Mat3> p{k} = {{(const wp::i32*)o{k}, (const wp::i32*)c{k}, \
                     (wp::Mat3*)d{k}, nullptr, {nr}, {nc}, {nnz}, {k}}};\n",
                    nr = m.nrow(),
                    nc = m.ncol()
                );
                print += &format!(
                    "for (int e = 0; e < {}; ++e) printf(\"%u\\n\", d{k}[e]);\n",
                    vals.len()
                );
            }
        }
    }
    Some(host_cpp::run_unit(
        &format!("cloth_{}", info.name),
        &src.text,
        &src.thread_fn,
        args.len(),
        &decl,
        &print,
        dim,
    ))
}

/// A 5 x 5 cloth bent out of its plane (some springs compressed, some stretched, so both
/// branches of the transverse clamp run) and moving.
fn state(p: &Params) -> (Vec<Vec3>, Vec<Vec3>) {
    let x = p
        .start()
        .iter()
        .enumerate()
        .map(|(k, q)| {
            let s = k as f64;
            (*q + DVec3::new(
                0.01 * (s * 0.7).sin(),
                0.05 * (s * 1.3).cos(),
                -0.02 * (s * 0.4).sin(),
            ))
            .as_vec3()
        })
        .collect();
    let v = (0..p.particles())
        .map(|k| {
            let s = k as f32;
            Vec3::new(
                (s * 0.9).cos(),
                (s * 0.3).sin() - 0.5,
                0.2 * (s * 2.1).sin(),
            )
        })
        .collect();
    (x, v)
}

fn compare(name: &str, want: &[u32], got: &[u32]) {
    assert_eq!(want.len(), got.len(), "{name}: word counts");
    let differ: Vec<usize> = (0..want.len()).filter(|&k| want[k] != got[k]).collect();
    assert!(
        differ.is_empty(),
        "{name}: {} of {} words differ, the first at {}: CPU {:#x}, C++ {:#x}",
        differ.len(),
        want.len(),
        differ[0],
        want[differ[0]],
        got[differ[0]]
    );
}

/// Semi-implicit Euler's step, backward Euler's assembly (Baraff-Witkin's first iteration and
/// a Newton iteration, with damping) and positions, and XPBD's three kernels, on the CPU
/// backend and as CUDA C++ under g++: the same bits in every output array and stored block.
#[test]
fn cloth_kernels_match_the_cpu_bit_for_bit() {
    use implicit_cloth::{be_assemble, euler_step, xpbd_project_colour};
    let dev = wp::cpu();
    let p = Params {
        n: 5,
        k: 1e3,
        kd: 0.01,
    };
    let np = p.particles();
    let (x, v) = state(&p);
    let arr = |d: &[Vec3]| wp::Array::from_slice(d, &dev).unwrap();
    let (n, spacing, mass) = (p.n as i32, p.spacing() as f32, p.mass() as f32);
    let k = p.stiffnesses().as_vec3();
    let (kd, h) = (p.kd as f32, 1.0f32 / 60.0);
    let gravity = Vec3::new(0.0, -9.81, 0.0);

    // Semi-implicit Euler.
    let (xa, va) = (arr(&x), arr(&v));
    let (x1, v1) = (arr(&vec![Vec3::ZERO; np]), arr(&vec![Vec3::ZERO; np]));
    let host = [
        a3(&xa),
        a3(&va),
        a3(&x1),
        a3(&v1),
        i(n),
        f(spacing),
        v3(k),
        f(kd),
        f(mass),
        v3(gravity),
        f(h),
    ];
    let args = (&xa, &va, &x1, &v1, n, spacing, k, kd, mass, gravity, h);
    wp::launch(euler_step, np, args, &dev).unwrap();
    let want = words(&[a3(&xa), a3(&va), a3(&x1), a3(&v1)]);
    let Some(got) = host_run::<euler_step>(np, &host) else {
        return;
    };
    compare("euler_step", &want, &got);

    // Backward Euler's assembly, both kinds of iteration; v0 differs from v.
    for first in [1, 0] {
        let a = implicit_cloth::pattern(p, &dev).unwrap();
        let a_host = implicit_cloth::pattern(p, &dev).unwrap();
        let v0: Vec<Vec3> = v.iter().map(|q| *q * 0.5).collect();
        let (x0, v0a, va) = (arr(&x), arr(&v0), arr(&v));
        let rhs = arr(&vec![Vec3::ZERO; np]);
        let host = [
            HArg::Bsr(&a_host),
            a3(&x0),
            a3(&v0a),
            a3(&va),
            a3(&rhs),
            i(n),
            f(spacing),
            v3(k),
            f(kd),
            f(mass),
            v3(gravity),
            f(h),
            i(first),
        ];
        let args = (
            &a, &x0, &v0a, &va, &rhs, n, spacing, k, kd, mass, gravity, h, first,
        );
        wp::launch(be_assemble, np, args, &dev).unwrap();
        let want = words(&[HArg::Bsr(&a), a3(&x0), a3(&v0a), a3(&va), a3(&rhs)]);
        let got = host_run::<be_assemble>(np, &host).expect("g++ ran above");
        compare(&format!("be_assemble (first = {first})"), &want, &got);
        // Not vacuous: the blocks and the right-hand side were written.
        assert!(want.iter().filter(|&&w| w != 0).count() > want.len() / 2);
    }

    // XPBD: one colour of springs sharing no particle (the structural springs (r, c)-(r, c+1)
    // with c even), projected by one thread each.
    let springs: Vec<Spring> = p.springs();
    let order: Vec<i32> = springs
        .iter()
        .enumerate()
        .filter(|(_, s)| s.b == s.a + 1 && (s.a % p.n).is_multiple_of(2))
        .map(|(k, _)| k as i32)
        .collect();
    let pairs: Vec<IVec2> = springs
        .iter()
        .map(|s| IVec2::new(s.a as i32, s.b as i32))
        .collect();
    let rest: Vec<f32> = springs.iter().map(|s| s.rest as f32).collect();
    let stiff: Vec<f32> = springs.iter().map(|s| s.k as f32).collect();
    let lam: Vec<f32> = (0..springs.len()).map(|k| 1e-4 * k as f32).collect();
    let xa = arr(&x);
    let fa = |d: &[f32]| wp::Array::from_slice(d, &dev).unwrap();
    let (la, ra, sa) = (fa(&lam), fa(&rest), fa(&stiff));
    let pa = wp::Array::from_slice(&pairs, &dev).unwrap();
    let oa = wp::Array::from_slice(&order, &dev).unwrap();
    let inv = 1.0 / mass;
    let host = [
        a3(&xa),
        af(&la),
        ai2(&pa),
        af(&ra),
        af(&sa),
        ai(&oa),
        i(0),
        i(n),
        f(inv),
        f(h),
    ];
    let args = (&xa, &la, &pa, &ra, &sa, &oa, 0i32, n, inv, h);
    wp::launch(xpbd_project_colour, order.len(), args, &dev).unwrap();
    let want = words(&[a3(&xa), af(&la), ai2(&pa), af(&ra), af(&sa), ai(&oa)]);
    let got = host_run::<xpbd_project_colour>(order.len(), &host).expect("g++ ran above");
    compare("xpbd_project_colour", &want, &got);

    // XPBD's predictor and velocities, backward Euler's positions (a thread per particle).
    use implicit_cloth::{be_positions, xpbd_predict, xpbd_velocity};
    let (xa, va, pa) = (arr(&x), arr(&v), arr(&vec![Vec3::ZERO; np]));
    let host = [a3(&xa), a3(&va), a3(&pa), i(n), v3(gravity), f(h)];
    wp::launch(xpbd_predict, np, (&xa, &va, &pa, n, gravity, h), &dev).unwrap();
    let want = words(&[a3(&xa), a3(&va), a3(&pa)]);
    let got = host_run::<xpbd_predict>(np, &host).expect("g++ ran above");
    compare("xpbd_predict", &want, &got);
    let host = [a3(&xa), a3(&va), a3(&pa), f(h)];
    wp::launch(xpbd_velocity, np, (&xa, &va, &pa, h), &dev).unwrap();
    let want = words(&[a3(&xa), a3(&va), a3(&pa)]);
    let got = host_run::<xpbd_velocity>(np, &host).expect("g++ ran above");
    compare("xpbd_velocity", &want, &got);
    let host = [a3(&xa), a3(&va), f(h)];
    wp::launch(be_positions, np, (&xa, &va, h), &dev).unwrap();
    let want = words(&[a3(&xa), a3(&va)]);
    let got = host_run::<be_positions>(np, &host).expect("g++ ran above");
    compare("be_positions", &want, &got);
}
