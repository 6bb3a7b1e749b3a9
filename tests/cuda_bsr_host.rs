//! The CUDA sparse-matrix queries (`warp-cuda/cuda/wp_bsr.h` and `wp_adjoint_bsr.h`) against
//! warp-core's (`objects::bsr`), bit for bit, on the host.
//!
//! One C++ driver reads a stream of cases (u32 words) and prints one line per case; the same
//! cases run through warp-core's functions here and print the same line format, compared as
//! text (floats as their bits). Cases: matrices of `Mat3` blocks from random structures (empty
//! rows, a matrix of no rows), and structures overwritten with garbage (offsets out of order,
//! negative, past the capacity; columns out of order), each queried at random rows, columns and
//! slots in and out of range: the row iteration, `bsr_col`, `bsr_block`, `bsr_block_index`,
//! `bsr_row_index`, `bsr_nnz`, then `bsr_add_block`, `bsr_set_block` and the adjoint of
//! `bsr_block` (single-threaded: the atomics' order cannot differ). Faults must be the same
//! (index and shape) on both sides. Skipped, saying so, without g++.
//!
//! A second test checks that NVRTC accepts the headers (every function instantiated in a
//! kernel, for scalar, square and rectangular blocks); skipped, saying so, without libnvrtc.

use std::process::Command;

use warp_core::glam::Mat3;
use warp_core::objects::bsr::{
    adj_bsr_block, bsr_add_block, bsr_block, bsr_block_index, bsr_col, bsr_nnz, bsr_row,
    bsr_row_done, bsr_row_index, bsr_row_item, bsr_row_next, bsr_set_block, BsrView,
};
use warp_core::{ArrayView, Fault, FaultKind, KResult};

#[path = "common/host_cpp.rs"]
mod host_cpp;

/// The fault argument index the driver gives its matrix, and the name Rust faults carry.
const ARG: i32 = 5;
const ARG_NAME: &str = "a";

const DRIVER: &str = r#"
#include <cstdio>
#include <cstring>
#include <vector>
#include "wp_adjoint_bsr.h"
using namespace wp;

static std::vector<u32> in;
static size_t at = 0;
static u32 w() { return in[at++]; }
static i32 wi() { return (i32)w(); }
static f32 wf() { f32 x; u32 u = w(); memcpy(&x, &u, 4); return x; }
static Mat3 wm() { Mat3 m; f32* p = (f32*)&m; for (int i = 0; i < 9; ++i) p[i] = wf(); return m; }
static void pf(f32 x) { u32 u; memcpy(&u, &x, 4); printf(" %08x", u); }
static void pm(const Mat3& m) { const f32* p = (const f32*)&m; for (int i = 0; i < 9; ++i) pf(p[i]); }
static fault_t fault;
static u32 flag;
static launch_ctx_t rec;
static ctx_t fresh() {
  memset(&fault, 0, sizeof fault);
  flag = 0;
  rec = launch_ctx_make(&fault, &flag);
  return ctx_make(&rec);
}
static bool pfault(const ctx_t& c) {
  if (!c.raised) return false;
  printf(" F %d %lld %lld", fault.arg, (long long)fault.index[0], (long long)fault.shape[0]);
  return true;
}

static std::vector<i32> offsets, columns;
static std::vector<Mat3> values, grad;

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  FILE* f = fopen(argv[1], "rb");
  if (!f) return 2;
  u32 word;
  while (fread(&word, 4, 1, f) == 1) in.push_back(word);
  fclose(f);
  bsr_t<Mat3> a{};
  while (at < in.size()) {
    const u32 op = w();
    switch (op) {
      case 1: {  // a matrix: nrow, ncol, cap, offsets, columns, values
        const i32 nrow = wi(), ncol = wi(), cap = wi();
        offsets.resize(nrow + 1);
        for (auto& o : offsets) o = wi();
        columns.resize(cap);
        for (auto& c : columns) c = wi();
        values.resize(cap);
        for (auto& v : values) v = wm();
        grad.assign(cap, Mat3{});
        a.offsets = offsets.data();
        a.columns = columns.data();
        a.values = values.data();
        a.grad = grad.data();
        a.nrow = nrow;
        a.ncol = ncol;
        a.cap = cap;
        a.arg = 5;
        printf("m");
        break;
      }
      case 2: {  // queries at r, c, k with a block v
        const i32 r = wi(), c = wi(), k = wi();
        const Mat3 v = wm();
        ctx_t x = fresh();
        printf("q %d |", bsr_nnz(a, &x));
        bsr_row_query_t q = bsr_row(a, r, &x);
        if (!pfault(x)) {
          for (q = bsr_row_next(a, q, &x); !bsr_row_done(q); q = bsr_row_next(a, q, &x))
            printf(" %d", bsr_row_item(q));
        }
        x = fresh();
        const i32 col = bsr_col(a, k, &x);
        printf(" |"); if (!pfault(x)) printf(" %d", col);
        x = fresh();
        const Mat3 b = bsr_block(a, k, &x);
        printf(" |"); if (!pfault(x)) pm(b);
        x = fresh();
        const i32 bi = bsr_block_index(a, r, c, &x);
        printf(" |"); if (!pfault(x)) printf(" %d", bi);
        x = fresh();
        const i32 ri = bsr_row_index(a, k, &x);
        printf(" |"); if (!pfault(x)) printf(" %d", ri);
        x = fresh();
        bsr_add_block(a, k, v, &x);
        printf(" |"); if (!pfault(x)) pm(values[k]);
        x = fresh();
        bsr_t<Mat3> adj_a{};
        i32 adj_k = 0;
        adj_bsr_block(a, k, adj_a, adj_k, v, &x);
        printf(" |"); if (!pfault(x)) pm(grad[k]);
        x = fresh();
        bsr_set_block(a, k, b, &x);
        printf(" |"); if (!pfault(x)) pm(values[k]);
        break;
      }
      default:
        fprintf(stderr, "bad op %u at word %zu\n", op, at - 1);
        return 3;
    }
    printf("\n");
  }
  return 0;
}
"#;

/// xorshift64*, seeded.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    /// An integer in `lo..hi` (as i64, any range).
    fn int(&mut self, lo: i64, hi: i64) -> i32 {
        (lo + (self.next() % (hi - lo) as u64) as i64) as i32
    }
    fn f(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32 * 4.0 - 2.0
    }
    fn m(&mut self) -> Mat3 {
        Mat3::from_cols_array(&[0; 9].map(|_| self.f()))
    }
}

fn hm(m: Mat3) -> String {
    m.to_cols_array()
        .iter()
        .map(|x| format!(" {:08x}", x.to_bits()))
        .collect()
}

/// A fault as the driver prints it (`F arg index shape`).
fn hfault(e: &Fault) -> String {
    match &e.kind {
        FaultKind::OutOfBounds { arg, index, shape } => {
            assert_eq!(*arg, ARG_NAME, "{e}");
            format!(" F {ARG} {} {}", index[0], shape[0])
        }
        k => panic!("unexpected fault kind {k:?}"),
    }
}

fn line<T>(r: KResult<T>, f: impl FnOnce(T) -> String) -> String {
    match r {
        Ok(t) => f(t),
        Err(e) => hfault(&e),
    }
}

/// One matrix's host copy and its view.
struct Matrix {
    nrow: i32,
    ncol: i32,
    offsets: Vec<i32>,
    columns: Vec<i32>,
    values: Vec<Mat3>,
    grad: Vec<Mat3>,
}

impl Matrix {
    fn view(&mut self) -> BsrView<Mat3> {
        // SAFETY: the vectors outlive every use of the view (one case at a time).
        unsafe {
            let i = |d: &mut Vec<i32>| {
                ArrayView::new(d.as_mut_ptr(), [d.len()], [1], "bsr_host", ARG_NAME)
            };
            let m = |d: &mut Vec<Mat3>| {
                ArrayView::new(d.as_mut_ptr(), [d.len()], [1], "bsr_host", ARG_NAME)
            };
            BsrView::new(
                i(&mut self.offsets),
                i(&mut self.columns),
                m(&mut self.values),
                Some(m(&mut self.grad)),
                self.nrow,
                self.ncol,
            )
        }
    }
}

#[derive(Default)]
struct Cases {
    words: Vec<u32>,
    want: Vec<String>,
}

impl Cases {
    fn m(&mut self, m: Mat3) {
        self.words.extend(m.to_cols_array().map(f32::to_bits));
    }

    fn matrix(&mut self, m: &Matrix) {
        self.words
            .extend([1, m.nrow as u32, m.ncol as u32, m.values.len() as u32]);
        self.words.extend(m.offsets.iter().map(|&o| o as u32));
        self.words.extend(m.columns.iter().map(|&c| c as u32));
        for v in &m.values {
            self.m(*v);
        }
        self.want.push("m".into());
    }

    fn query(&mut self, m: &mut Matrix, r: i32, c: i32, k: i32, v: Mat3) {
        self.words.extend([2, r as u32, c as u32, k as u32]);
        self.m(v);
        let a = m.view();
        let mut s = format!("q {} |", bsr_nnz(a).unwrap());
        s += &line(bsr_row(a, r), |mut q| {
            let mut out = String::new();
            loop {
                q = bsr_row_next(a, q).unwrap();
                if bsr_row_done(q) {
                    break out;
                }
                out += &format!(" {}", bsr_row_item(q));
            }
        });
        s += " |";
        s += &line(bsr_col(a, k), |c| format!(" {c}"));
        s += " |";
        let b = bsr_block(a, k);
        let b0 = b.as_ref().ok().copied();
        s += &line(b, hm);
        s += " |";
        s += &line(bsr_block_index(a, r, c), |i| format!(" {i}"));
        s += " |";
        s += &line(bsr_row_index(a, k), |i| format!(" {i}"));
        s += " |";
        s += &line(bsr_add_block(a, k, v), |()| hm(m.values[k as usize]));
        s += " |";
        let (mut adj_a, mut adj_k) = (BsrView::empty(), 0);
        s += &line(adj_bsr_block(a, k, &mut adj_a, &mut adj_k, v), |()| {
            hm(m.grad[k as usize])
        });
        s += " |";
        // The driver writes back the block it read (zero after a fault: a fault again).
        s += &line(bsr_set_block(a, k, b0.unwrap_or_default()), |()| {
            hm(m.values[k as usize])
        });
        self.want.push(s);
    }
}

/// A random assembled structure: `nrow x ncol` blocks, ascending columns per row, `cap` at
/// least the block count.
fn assembled(g: &mut Rng, nrow: usize, ncol: usize) -> Matrix {
    let (mut offsets, mut columns) = (vec![0], vec![]);
    for r in 0..nrow {
        if r % 4 != 2 {
            for c in 0..ncol {
                if g.below(3) == 0 {
                    columns.push(c as i32);
                }
            }
        }
        offsets.push(columns.len() as i32);
    }
    let cap = columns.len() + g.below(4);
    columns.resize(cap, 0);
    Matrix {
        nrow: nrow as i32,
        ncol: ncol as i32,
        offsets,
        values: (0..cap).map(|_| g.m()).collect(),
        grad: vec![Mat3::ZERO; cap],
        columns,
    }
}

#[test]
fn cuda_bsr_matches_warp_core_bit_for_bit() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_bsr_matches_warp_core_bit_for_bit: no g++");
        return;
    }
    let mut g = Rng(17);
    let mut c = Cases::default();
    for case in 0..40 {
        let (nrow, ncol) = match case {
            0 => (0, 0),
            1 => (1, 1),
            _ => (1 + g.below(12), 1 + g.below(12)),
        };
        let mut m = assembled(&mut g, nrow, ncol);
        // A third of the matrices get a garbage structure: offsets and columns overwritten.
        if case % 3 == 2 {
            let cap = m.values.len() as i64;
            for o in &mut m.offsets {
                *o = g.int(-3, cap + 4);
            }
            for col in &mut m.columns {
                *col = g.int(-2, nrow as i64 + 3);
            }
        }
        c.matrix(&m);
        let nnz = bsr_nnz(m.view()).unwrap() as i64;
        for _ in 0..30 {
            let r = g.int(-2, nrow as i64 + 2);
            let col = g.int(-2, ncol as i64 + 2);
            let k = g.int(-2, nnz + 3);
            let v = g.m();
            c.query(&mut m, r, col, k, v);
        }
        for k in [i32::MIN, i32::MAX] {
            c.query(&mut m, k, k, k, Mat3::IDENTITY);
        }
    }

    let (dir, exe) = host_cpp::compile_driver("cuda_bsr", DRIVER, &[]);
    let input = dir.join("cases.bin");
    let bytes: Vec<u8> = c.words.iter().flat_map(|w| w.to_le_bytes()).collect();
    std::fs::write(&input, bytes).unwrap();
    let run = Command::new(&exe).arg(&input).output().unwrap();
    assert!(
        run.status.success(),
        "driver: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = String::from_utf8(run.stdout).unwrap();
    let got: Vec<&str> = text.lines().collect();
    assert_eq!(got.len(), c.want.len(), "one line per case");
    let bad: Vec<String> = got
        .iter()
        .zip(&c.want)
        .enumerate()
        .filter(|(_, (g, w))| g != w)
        .map(|(k, (g, w))| format!("case {k}:\n  C++:  {g}\n  Rust: {w}"))
        .collect();
    let faults = c.want.iter().filter(|l| l.contains(" F ")).count();
    eprintln!(
        "{} cases ({faults} with a fault), {} mismatches",
        c.want.len(),
        bad.len()
    );
    assert!(
        bad.is_empty(),
        "{} of {} cases differ:\n{}",
        bad.len(),
        c.want.len(),
        bad[..bad.len().min(10)].join("\n")
    );
    assert!(faults > 300, "too few fault cases: {faults}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// NVRTC accepts the headers, every function instantiated in a kernel (forward and adjoint)
/// for an f64 scalar, a square and a rectangular block: needs libnvrtc, no GPU; skipped,
/// saying so, without it.
#[test]
fn nvrtc_compiles_the_bsr_headers() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED nvrtc_compiles_the_bsr_headers: {e}");
        return;
    }
    let source = r#"
#define WP_ADJOINT_UNIT 1
#include "wp_core.h"
#include "wp_scalar.h"
#include "wp_vector.h"
#include "wp_matrix.h"
#include "wp_atomic.h"
#include "wp_bsr.h"
#include "wp_adjoint_core.h"
#include "wp_adjoint_bsr.h"
template <typename B>
__device__ wp::i32 all(const wp::bsr_t<B>& a, wp::ctx_t* c) {
  using namespace wp;
  i32 n = bsr_nrow(a, c) + bsr_ncol(a, c) + bsr_nnz(a, c);
  bsr_row_query_t q = bsr_row(a, 0, c);
  for (q = bsr_row_next(a, q, c); !bsr_row_done(q); q = bsr_row_next(a, q, c)) {
    const i32 k = bsr_row_item(q);
    n += bsr_col(a, k, c) + bsr_row_index(a, k, c);
    const B b = bsr_block(a, k, c);
    bsr_set_block(a, k, b, c);
    bsr_add_block(a, k, b, c);
    bsr_t<B> adj_a = adj_zero<bsr_t<B>>();
    i32 adj_k = 0;
    adj_bsr_block(a, k, adj_a, adj_k, b, c);
  }
  bsr_row_query_t z = adj_zero<bsr_row_query_t>();
  adj_accum(z, q);
  return n + bsr_block_index(a, 0, 1, c) + z.cur;
}
extern "C" __global__ void bsr_all(wp::bsr_t<double> a, wp::bsr_t<wp::Mat3> b,
                                   wp::bsr_t<wp::Mat23> m, wp::i32* out, wp::fault_t* fault,
                                   wp::u32* flag) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(fault, flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  out[threadIdx.x] = all(a, &c) + all(b, &c) + all(m, &c);
}
"#;
    let headers: Vec<(&str, &str)> = warp_cuda::HEADERS.to_vec();
    for arch in [90, 80] {
        let opts = warp_cuda::CompileOptions {
            fmad: false,
            headers: &headers,
            ..Default::default()
        };
        let c = warp_cuda::compile(source, "bsr_all.cu", &opts, arch)
            .unwrap_or_else(|e| panic!("sm_{arch}: {e}"));
        assert!(!c.cubin.is_empty());
        assert!(!c.log.contains("warning"), "sm_{arch}: {}", c.log);
    }
}
