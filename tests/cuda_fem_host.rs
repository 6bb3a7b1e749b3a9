//! The finite-element scene's kernels (examples/common/fem.rs) without a GPU: their CUDA
//! translation units, as the runtime assembles them for NVRTC, compiled as host C++ with g++
//! against `warp-cuda/cuda/` and run over the grid, against the CPU backend, bit for bit.
//!
//! Bit-exact is the right tolerance: both sides do the same IEEE operations in the same order
//! (g++ with `-ffp-contract=off`: no FMA contraction; `sin`/`cos` of f64 are glibc's on both
//! sides here). On a GPU, FMA contraction and CUDA's `sin` change the last bits, which the
//! scene tests (tests/suite/scenes.rs) allow for; this test is about the generated code's
//! meaning: vertex numbering, lane writes, `outer`'s orientation, the boundary's redirection.

use warp_lang as wp;

// `fem` reaches the sparse tier as `super::sparse`.
#[allow(unused_imports)]
use warp_runtime::sparse;
#[path = "../examples/common/fem.rs"]
mod fem;
#[path = "common/host_cpp.rs"]
mod host_cpp;

/// A kernel argument: an `i32`, or an array the program declares and prints.
enum HArg<'a> {
    I(i32),
    Is(&'a wp::Array<i32>),
    Fs(&'a wp::Array<f64>),
    V4s(&'a wp::Array<glam::DVec4>),
    M3s(&'a wp::Array<glam::DMat3>),
}

/// An array argument's contents as 64-bit words (f64 bits, or an i32 zero-extended), its
/// element count, its C++ element type and whether it holds i32s; None for a scalar.
fn words(a: &HArg) -> Option<(Vec<u64>, usize, &'static str, bool)> {
    Some(match a {
        HArg::I(_) => return None,
        HArg::Is(x) => {
            let v = x.to_vec().unwrap();
            let n = v.len();
            (
                v.into_iter().map(|i| i as u32 as u64).collect(),
                n,
                "wp::i32",
                true,
            )
        }
        HArg::Fs(x) => {
            let v = x.to_vec().unwrap();
            let n = v.len();
            (
                v.into_iter().map(f64::to_bits).collect(),
                n,
                "wp::f64",
                false,
            )
        }
        HArg::V4s(x) => {
            let v = x.to_vec().unwrap();
            let n = v.len();
            (
                v.into_iter()
                    .flat_map(|q| q.to_array())
                    .map(f64::to_bits)
                    .collect(),
                n,
                "wp::DVec4",
                false,
            )
        }
        HArg::M3s(x) => {
            let v = x.to_vec().unwrap();
            let n = v.len();
            (
                v.into_iter()
                    .flat_map(|q| q.to_cols_array())
                    .map(f64::to_bits)
                    .collect(),
                n,
                "wp::DMat3",
                false,
            )
        }
    })
}

/// Runs K's CUDA unit under g++ (no FMA contraction) over `dim` threads with `args` as they
/// are now; returns the arrays' words after the run, or None without g++.
fn host_run<K: wp::Kernel>(dim: usize, args: &[HArg]) -> Option<Vec<u64>> {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_fem_host: no g++ on this machine");
        return None;
    }
    let info = &K::INFO;
    let src = wp::cuda_source::assemble(info);
    let mut decl = String::new();
    let mut print = String::new();
    for (k, a) in args.iter().enumerate() {
        match words(a) {
            None => {
                if let HArg::I(v) = a {
                    decl += &format!("wp::i32 p{k} = {v};\n");
                }
            }
            Some((w, n, ty, is_i32)) => {
                let size = if is_i32 { 4 } else { 8 * (w.len() / n.max(1)) };
                if is_i32 {
                    let list: Vec<String> = w.iter().map(|x| format!("{}u", *x as u32)).collect();
                    decl += &format!(
                        "static unsigned int d{k}[] = {{{}, 0u}};\n",
                        list.join(", ")
                    );
                    print += &format!(
                        "for (int e = 0; e < {}; ++e) printf(\"%u\\n\", d{k}[e]);\n",
                        w.len()
                    );
                } else {
                    let list: Vec<String> = w.iter().map(|x| format!("{x}ull")).collect();
                    decl += &format!(
                        "static unsigned long long d{k}[] = {{{}, 0ull}};\n",
                        list.join(", ")
                    );
                    print += &format!(
                        "for (int e = 0; e < {}; ++e) printf(\"%llu\\n\", d{k}[e]);\n",
                        w.len()
                    );
                }
                decl += &format!(
                    "wp::array_t<{ty}, 1> p{k} = {{({ty}*)d{k}, {{{n}}}, {{{size}}}, {k}, 0}};\n"
                );
            }
        }
    }
    Some(host_cpp::run_unit(
        &format!("fem_{}", info.name),
        &src.text,
        &src.thread_fn,
        args.len(),
        &decl,
        &print,
        dim,
    ))
}

/// The words of every array argument, in order.
fn all_words(args: &[HArg]) -> Vec<u64> {
    args.iter()
        .filter_map(words)
        .flat_map(|(w, ..)| w)
        .collect()
}

/// The element kernels (stiffness and load triplets) of the three problems on a small grid
/// (2-D: 3 x 3 cells, 18 triangles; 3-D: 2³ cells, 48 tetrahedra, boundary nodes included),
/// run by the CPU backend and by their CUDA units under g++: every triplet's row, column and
/// value the same bits.
#[test]
fn element_kernels_match_the_cpu_bit_for_bit() {
    use fem::{elastic_element, poisson2_element, poisson3_element, quadrature, Problem};
    use glam::DMat3;
    let dev = wp::cpu();
    for (problem, n) in [
        (Problem::Poisson2, 3i32),
        (Problem::Poisson3, 2),
        (Problem::Elasticity, 2),
    ] {
        let dim = problem.dim();
        let quad = wp::Array::from_slice(&quadrature(dim), &dev).unwrap();
        let nq = quad.len() as i32;
        let per = dim + 1;
        let elements = (n as usize).pow(dim as u32) * problem.per_cell();
        let (t, l) = (elements * per * per, elements * per * problem.components());
        // Two sets of outputs: the CPU's, and the C++ program's starting state (zeros).
        let outputs = || {
            (
                wp::Array::<i32>::zeros(t, &dev).unwrap(),
                wp::Array::<i32>::zeros(t, &dev).unwrap(),
                wp::Array::<i32>::zeros(l, &dev).unwrap(),
                wp::Array::<f64>::zeros(l, &dev).unwrap(),
            )
        };
        let (r, c, lr, lv) = outputs();
        let (r2, c2, lr2, lv2) = outputs();
        let (want, got) = if problem == Problem::Elasticity {
            let (m, m2) = (
                wp::Array::<DMat3>::zeros(t, &dev).unwrap(),
                wp::Array::<DMat3>::zeros(t, &dev).unwrap(),
            );
            let args = (n, &quad, nq, &r, &c, &m, &lr, &lv);
            wp::launch(elastic_element, elements, args, &dev).unwrap();
            let want = all_words(&[
                HArg::Is(&r),
                HArg::Is(&c),
                HArg::M3s(&m),
                HArg::Is(&lr),
                HArg::Fs(&lv),
            ]);
            let host = [
                HArg::I(n),
                HArg::V4s(&quad),
                HArg::I(nq),
                HArg::Is(&r2),
                HArg::Is(&c2),
                HArg::M3s(&m2),
                HArg::Is(&lr2),
                HArg::Fs(&lv2),
            ];
            (want, host_run::<elastic_element>(elements, &host))
        } else {
            let (v, v2) = (
                wp::Array::<f64>::zeros(t, &dev).unwrap(),
                wp::Array::<f64>::zeros(t, &dev).unwrap(),
            );
            let args = (n, &quad, nq, &r, &c, &v, &lr, &lv);
            let host = [
                HArg::I(n),
                HArg::V4s(&quad),
                HArg::I(nq),
                HArg::Is(&r2),
                HArg::Is(&c2),
                HArg::Fs(&v2),
                HArg::Is(&lr2),
                HArg::Fs(&lv2),
            ];
            let got = if problem == Problem::Poisson2 {
                wp::launch(poisson2_element, elements, args, &dev).unwrap();
                host_run::<poisson2_element>(elements, &host)
            } else {
                wp::launch(poisson3_element, elements, args, &dev).unwrap();
                host_run::<poisson3_element>(elements, &host)
            };
            (
                all_words(&[
                    HArg::Is(&r),
                    HArg::Is(&c),
                    HArg::Fs(&v),
                    HArg::Is(&lr),
                    HArg::Fs(&lv),
                ]),
                got,
            )
        };
        let Some(got) = got else { return };
        // The program prints the quadrature array first (unchanged): skip it.
        let got = &got[quad.len() * 4..];
        assert_eq!(want.len(), got.len(), "{}: word counts", problem.name());
        let differ: Vec<usize> = (0..want.len()).filter(|&k| want[k] != got[k]).collect();
        assert!(
            differ.is_empty(),
            "{}: {} of {} words differ, the first at {}: CPU {:#x}, C++ {:#x}",
            problem.name(),
            differ.len(),
            want.len(),
            differ[0],
            want[differ[0]],
            got[differ[0]]
        );
    }
}
