//! Sparse matrices in kernels (`a: Bsr<B>` parameters; the sparse tier's `Bsr`, the suite's
//! dev-dependency turns its feature on): a residual `r = b - A x` written with the row
//! iteration against the library's `mv`; assembly into a fixed pattern with `bsr_add_block`;
//! the structure queries against the host's arrays; block writes of square and rectangular
//! blocks; out-of-range rows and slots as faults naming the matrix; the gradient through
//! `bsr_block` into the values' gradient (exact for a linear loss, a gradcheck for a
//! nonlinear one).

use crate::{arr, host, zeros};
use warp_lang as wp;
use warp_runtime::sparse::{self, Bsr};
use wp::prelude::*;
use wp::{Error, FaultKind};

backend_tests!(
    residual_matches_mv_f64,
    residual_matches_mv_mat3,
    assembly_into_a_fixed_pattern,
    structure_queries,
    block_writes_square_and_rectangular,
    out_of_range_rows_and_slots_fault,
    value_gradients_are_exact_for_a_linear_loss,
    value_gradients_pass_gradcheck,
    backward_through_a_block_write_is_refused,
);

#[wp::kernel]
fn k_residual_f64(a: Bsr<f64>, x: Array<f64>, b: Array<f64>, r: Array<f64>) {
    let i = tid();
    let mut s = b[i];
    for k in bsr_row(a, i as i32) {
        s -= bsr_block(a, k) * x[bsr_col(a, k)];
    }
    r[i] = s;
}

#[wp::kernel]
fn k_residual_mat3(a: Bsr<Mat3>, x: Array<Vec3>, b: Array<Vec3>, r: Array<Vec3>) {
    let i = tid();
    let mut s = b[i];
    for k in bsr_row(a, i as i32) {
        s -= bsr_block(a, k) * x[bsr_col(a, k)];
    }
    r[i] = s;
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
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    /// In [-1, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// Random triplets of an `n x n` block matrix with a few empty rows (rows divisible by 7 get
/// none) and duplicates.
fn triplets(n: usize, count: usize, seed: u64) -> (Vec<i32>, Vec<i32>, Rng) {
    let mut g = Rng(seed);
    let (mut rows, mut cols) = (vec![], vec![]);
    while rows.len() < count {
        let r = g.below(n);
        if r % 7 == 3 {
            continue;
        }
        rows.push(r as i32);
        cols.push(g.below(n) as i32);
    }
    (rows, cols, g)
}

fn residual_matches_mv_f64(dev: &wp::Device) {
    let n = 60;
    let (rows, cols, mut g) = triplets(n, 400, 11);
    let vals: Vec<f64> = rows.iter().map(|_| g.unit()).collect();
    let a = Bsr::from_triplets(n, n, &arr(&rows, dev), &arr(&cols, dev), &arr(&vals, dev)).unwrap();
    let x: Vec<f64> = (0..n).map(|_| g.unit()).collect();
    let b: Vec<f64> = (0..n).map(|_| g.unit()).collect();
    let (xa, ba) = (arr(&x, dev), arr(&b, dev));
    let r = zeros::<f64, 1>(n, dev);
    wp::launch(k_residual_f64, n, (&a, &xa, &ba, &r), dev).unwrap();
    let y = arr(&b, dev);
    sparse::mv(-1.0, &a, &xa, 1.0, &y).unwrap();
    // Both sum a row's products in slot order; the kernel subtracts each from b, mv adds them
    // and then subtracts the sum: a few roundings of terms of size ~1 apart (f64: 1e-12 is
    // ~5000 ulps of 1, far above those and far below a wrong or missing term).
    let (got, want) = (host(&r), host(&y));
    for i in 0..n {
        assert!(
            (got[i] - want[i]).abs() <= 1e-12,
            "row {i}: {} vs mv {}",
            got[i],
            want[i]
        );
    }
    // And against a dense host reference of the triplets (duplicates summed).
    let mut dense = vec![0.0f64; n * n];
    for t in 0..rows.len() {
        dense[rows[t] as usize * n + cols[t] as usize] += vals[t];
    }
    for i in 0..n {
        let want = b[i] - (0..n).map(|j| dense[i * n + j] * x[j]).sum::<f64>();
        assert!((got[i] - want).abs() <= 1e-12, "row {i}");
    }
}

fn residual_matches_mv_mat3(dev: &wp::Device) {
    let n = 40;
    let (rows, cols, mut g) = triplets(n, 250, 5);
    let mut m = || Mat3::from_cols_array(&[0; 9].map(|_| g.unit() as f32));
    let vals: Vec<Mat3> = rows.iter().map(|_| m()).collect();
    let a = Bsr::from_triplets(n, n, &arr(&rows, dev), &arr(&cols, dev), &arr(&vals, dev)).unwrap();
    let mut v = || Vec3::new(g.unit() as f32, g.unit() as f32, g.unit() as f32);
    let x: Vec<Vec3> = (0..n).map(|_| v()).collect();
    let b: Vec<Vec3> = (0..n).map(|_| v()).collect();
    let (xa, ba) = (arr(&x, dev), arr(&b, dev));
    let r = zeros::<Vec3, 1>(n, dev);
    wp::launch(k_residual_mat3, n, (&a, &xa, &ba, &r), dev).unwrap();
    let y = arr(&b, dev);
    sparse::mv(-1.0, &a, &xa, 1.0, &y).unwrap();
    // f32, rows of up to ~20 blocks of entries below 1 (with duplicates summed, below ~5):
    // the two orders differ by a few hundred roundings of values below ~100, so 1e-4
    // absolute; a wrong block is off by ~0.1 or more.
    let (got, want) = (host(&r), host(&y));
    for i in 0..n {
        assert!(
            (got[i] - want[i]).abs().max_element() <= 1e-4,
            "row {i}: {} vs mv {}",
            got[i],
            want[i]
        );
    }
}

/// One spring element per `e`: `(e, e + 1)` with stiffness `k[e]` times the identity block,
/// added into the four blocks it touches of a pattern made beforehand.
#[wp::kernel]
fn k_assemble(a: Bsr<Mat3>, k: Array<f32>) {
    let e = tid();
    let (i, j) = (e as i32, e as i32 + 1);
    let s = Mat3::IDENTITY * k[e];
    bsr_add_block(a, bsr_block_index(a, i, i), s);
    bsr_add_block(a, bsr_block_index(a, j, j), s);
    bsr_add_block(a, bsr_block_index(a, i, j), -s);
    bsr_add_block(a, bsr_block_index(a, j, i), -s);
}

fn assembly_into_a_fixed_pattern(dev: &wp::Device) {
    let n = 33;
    // The tridiagonal pattern, blocks zero.
    let (mut rows, mut cols) = (vec![], vec![]);
    for i in 0..n as i32 {
        for j in [i - 1, i, i + 1] {
            if (0..n as i32).contains(&j) {
                rows.push(i);
                cols.push(j);
            }
        }
    }
    let zero = vec![Mat3::ZERO; rows.len()];
    let a = Bsr::from_triplets(n, n, &arr(&rows, dev), &arr(&cols, dev), &arr(&zero, dev)).unwrap();
    // Small integers: every sum is exact, so the atomic adds' order cannot show.
    let k: Vec<f32> = (0..n - 1).map(|e| (1 + e % 5) as f32).collect();
    wp::launch(k_assemble, n - 1, (&a, &arr(&k, dev)), dev).unwrap();
    let x: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new(i as f32, (i * i % 7) as f32, -(i as f32)))
        .collect();
    let y = zeros::<Vec3, 1>(n, dev);
    sparse::mv(1.0, &a, &arr(&x, dev), 0.0, &y).unwrap();
    let y = host(&y);
    for i in 0..n {
        let mut want = Vec3::ZERO;
        if i > 0 {
            want += k[i - 1] * (x[i] - x[i - 1]);
        }
        if i + 1 < n {
            want += k[i] * (x[i] - x[i + 1]);
        }
        assert_eq!(y[i], want, "row {i}");
    }
    // The pattern is unchanged.
    assert_eq!(a.nnz().unwrap(), rows.len());
}

#[wp::kernel]
fn k_block_index(a: Bsr<Mat23>, out: Array<i32, 2>) {
    let (r, c) = tid();
    out[(r, c)] = bsr_block_index(a, r as i32, c as i32 - 1);
}

#[wp::kernel]
fn k_slots(a: Bsr<Mat23>, rows: Array<i32>, cols: Array<i32>, sizes: Array<i32>) {
    let k = tid();
    rows[k] = bsr_row_index(a, k as i32);
    cols[k] = bsr_col(a, k as i32);
    if k == 0 {
        sizes[0] = bsr_nrow(a);
        sizes[1] = bsr_ncol(a);
        sizes[2] = bsr_nnz(a);
    }
}

#[wp::kernel]
fn k_row_lengths(a: Bsr<Mat23>, len: Array<i32>) {
    let r = tid();
    let mut c = 0;
    let mut last = -1;
    for k in bsr_row(a, r as i32) {
        // Slots ascend through the row.
        if k > last {
            c += 1;
        }
        last = k;
    }
    len[r] = c;
}

/// A 5 x 4 matrix of `Mat23` blocks from random triplets (rows 3 empty), and its host arrays.
fn rect_case(dev: &wp::Device) -> (Bsr<Mat23>, Vec<i32>, Vec<i32>) {
    let (n, m) = (5usize, 4usize);
    let mut g = Rng(3);
    let (mut rows, mut cols) = (vec![], vec![]);
    for _ in 0..14 {
        let r = [0, 1, 2, 4][g.below(4)];
        rows.push(r);
        cols.push(g.below(m) as i32);
    }
    let vals: Vec<Mat23> = (0..rows.len())
        .map(|t| Mat23(Vec3::splat(t as f32), Vec3::new(1.0, 2.0, t as f32)))
        .collect();
    let a = Bsr::from_triplets(n, m, &arr(&rows, dev), &arr(&cols, dev), &arr(&vals, dev)).unwrap();
    let offsets = host(a.offsets());
    let columns = host(a.columns());
    (a, offsets, columns)
}

fn structure_queries(dev: &wp::Device) {
    let (a, offsets, columns) = rect_case(dev);
    let (n, m) = (a.nrow(), a.ncol());
    let nnz = a.nnz().unwrap();
    // Columns -1 and m (no block there) included.
    let out = zeros::<i32, 2>((n, m + 2), dev);
    wp::launch(k_block_index, (n, m + 2), (&a, &out), dev).unwrap();
    let out = host(&out);
    for r in 0..n {
        for c in -1..=m as i32 {
            let row = offsets[r] as usize..offsets[r + 1] as usize;
            let want = row
                .clone()
                .find(|&k| columns[k] == c)
                .map_or(-1, |k| k as i32);
            assert_eq!(out[r * (m + 2) + (c + 1) as usize], want, "({r}, {c})");
        }
    }
    let (rows, cols, sizes) = (zeros::<i32, 1>(nnz, dev), zeros(nnz, dev), zeros(3, dev));
    wp::launch(k_slots, nnz, (&a, &rows, &cols, &sizes), dev).unwrap();
    assert_eq!(host(&sizes), [n as i32, m as i32, nnz as i32]);
    assert_eq!(host(&cols), columns[..nnz]);
    let want: Vec<i32> = (0..nnz)
        .map(|k| (0..n).find(|&r| offsets[r + 1] as usize > k).unwrap() as i32)
        .collect();
    assert_eq!(host(&rows), want);
    let len = zeros::<i32, 1>(n, dev);
    wp::launch(k_row_lengths, n, (&a, &len), dev).unwrap();
    let want: Vec<i32> = (0..n).map(|r| offsets[r + 1] - offsets[r]).collect();
    assert_eq!(host(&len), want);
    assert_eq!(want[3], 0, "row 3 is empty");
}

#[wp::kernel]
fn k_write_rect(a: Bsr<Mat23>, out: Array<Mat23>) {
    let k = tid() as i32;
    let b = bsr_block(a, k);
    out[k] = b;
    bsr_set_block(a, k, b * 2.0);
    bsr_add_block(a, k, b);
}

#[wp::kernel]
fn k_write_dmat3(a: Bsr<DMat3>) {
    let k = tid() as i32;
    let r = bsr_row_index(a, k) as f64;
    bsr_set_block(a, k, DMat3::IDENTITY * r);
}

fn block_writes_square_and_rectangular(dev: &wp::Device) {
    let (a, _, _) = rect_case(dev);
    let nnz = a.nnz().unwrap();
    let before = host(a.values());
    let out = zeros::<Mat23, 1>(nnz, dev);
    wp::launch(k_write_rect, nnz, (&a, &out), dev).unwrap();
    assert_eq!(host(&out), before[..nnz]);
    let after = host(a.values());
    for k in 0..nnz {
        let b = before[k];
        // 2b + b: exact for these small integers.
        assert_eq!(after[k], Mat23(b.0 * 3.0, b.1 * 3.0), "slot {k}");
    }
    // A square f64 block type: each slot set to its row times the identity.
    let (rows, cols) = (vec![0, 2, 2, 1, 0], vec![1, 0, 2, 1, 0]);
    let vals = vec![DMat3::ZERO; 5];
    let d = Bsr::from_triplets(3, 3, &arr(&rows, dev), &arr(&cols, dev), &arr(&vals, dev)).unwrap();
    wp::launch(k_write_dmat3, 5, (&d,), dev).unwrap();
    let offsets = host(d.offsets());
    let got = host(d.values());
    for r in 0..3 {
        for k in offsets[r]..offsets[r + 1] {
            assert_eq!(got[k as usize], DMat3::IDENTITY * r as f64);
        }
    }
}

#[wp::kernel]
fn k_read_slot(a: Bsr<Mat3>, k: i32, out: Array<Mat3>) {
    out[0] = bsr_block(a, k);
}

#[wp::kernel]
fn k_row_at(a: Bsr<Mat3>, r: i32, out: Array<i32>) {
    let mut c = 0;
    for _k in bsr_row(a, r) {
        c += 1;
    }
    out[0] = c;
}

#[wp::kernel]
fn k_index_at(a: Bsr<Mat3>, r: i32, out: Array<i32>) {
    out[0] = bsr_block_index(a, r, 0);
}

#[wp::kernel]
fn k_add_at(a: Bsr<Mat3>, k: i32) {
    bsr_add_block(a, k, Mat3::IDENTITY);
}

fn out_of_bounds(r: wp::Result<()>) -> (Vec<i128>, Vec<usize>) {
    match r {
        Err(Error::Fault(f)) => match &f.kind {
            FaultKind::OutOfBounds { arg, index, shape } => {
                assert_eq!(*arg, "a", "{f}");
                (index.clone(), shape.clone())
            }
            k => panic!("{k:?}"),
        },
        r => panic!("expected a fault, got {r:?}"),
    }
}

fn out_of_range_rows_and_slots_fault(dev: &wp::Device) {
    // 3 x 3 blocks, 4 stored, room for 6 (two duplicates summed).
    let rows = [0, 0, 2, 2, 1, 0];
    let cols = [0, 2, 1, 1, 1, 0];
    let vals = [Mat3::IDENTITY; 6];
    let a = Bsr::from_triplets(3, 3, &arr(&rows, dev), &arr(&cols, dev), &arr(&vals, dev)).unwrap();
    assert_eq!((a.nnz().unwrap(), a.nnz_bound()), (4, 6));
    let (o, c) = (zeros::<Mat3, 1>(1, dev), zeros::<i32, 1>(1, dev));
    // Slot 4 is capacity, not a block: out of range, as -1 is.
    for k in [4, 5, -1] {
        let f = out_of_bounds(wp::launch(k_read_slot, 1, (&a, k, &o), dev));
        assert_eq!(f, (vec![k as i128], vec![4]), "slot {k}");
        let f = out_of_bounds(wp::launch(k_add_at, 1, (&a, k), dev));
        assert_eq!(f, (vec![k as i128], vec![4]), "slot {k}");
    }
    for r in [3, -1] {
        let f = out_of_bounds(wp::launch(k_row_at, 1, (&a, r, &c), dev));
        assert_eq!(f, (vec![r as i128], vec![3]), "row {r}");
        let f = out_of_bounds(wp::launch(k_index_at, 1, (&a, r, &c), dev));
        assert_eq!(f, (vec![r as i128], vec![3]), "row {r}");
    }
    // In range: no fault, and nothing else changed.
    wp::launch(k_row_at, 1, (&a, 2, &c), dev).unwrap();
    assert_eq!(host(&c), [1]);
    wp::launch(k_read_slot, 1, (&a, 3, &o), dev).unwrap();
    assert_eq!(host(&o), [Mat3::IDENTITY * 2.0]);
    assert_eq!(host(a.values())[4..], [Mat3::ZERO; 2]);
}

/// `out[r] = sum over row r's slots of ddot(A_k, w_k)`: linear in the blocks, so the values'
/// gradient under the seed 1 is exactly `w`.
#[wp::kernel]
fn k_ddot(a: Bsr<DMat3>, w: Array<DMat3>, out: Array<f64>) {
    let r = tid();
    let mut s = 0.0;
    for k in bsr_row(a, r as i32) {
        s += ddot(bsr_block(a, k), w[k]);
    }
    out[r] = s;
}

fn value_gradients_are_exact_for_a_linear_loss(dev: &wp::Device) {
    let n = 12;
    let (rows, cols, mut g) = triplets(n, 50, 9);
    let mut m = || DMat3::from_cols_array(&[0; 9].map(|_| g.unit()));
    let vals: Vec<DMat3> = rows.iter().map(|_| m()).collect();
    let a = Bsr::from_triplets(n, n, &arr(&rows, dev), &arr(&cols, dev), &arr(&vals, dev))
        .unwrap()
        .with_grad()
        .unwrap();
    let cap = a.nnz_bound();
    let w: Vec<DMat3> = (0..cap).map(|_| m()).collect();
    let out = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_ddot, n, (&a, &arr(&w, dev), &out), dev).unwrap();
    }
    tape.backward(&out).unwrap();
    let grad = host(
        &a.values()
            .grad()
            .expect("with_grad gave the values a gradient"),
    );
    let nnz = a.nnz().unwrap();
    // Each stored slot is read once, with seed 1: its gradient is w exactly; the capacity
    // past nnz is never read.
    assert_eq!(grad[..nnz], w[..nnz]);
    assert!(grad[nnz..].iter().all(|g| *g == DMat3::ZERO));
    // zero_grad through the tape reaches the values' gradient.
    tape.zero().unwrap();
    assert!(host(&a.values().grad().unwrap())
        .iter()
        .all(|g| *g == DMat3::ZERO));
}

/// A nonlinear loss of the blocks and of x: `out[r] = sum_k (a_k x_c)^2 + sin(a_k)`.
#[wp::kernel]
fn k_nonlinear(a: Bsr<f64>, x: Array<f64>, out: Array<f64>) {
    let r = tid();
    let mut s = 0.0;
    for k in bsr_row(a, r as i32) {
        let v = bsr_block(a, k);
        let p = v * x[bsr_col(a, k)];
        s += p * p + sin(v);
    }
    out[r] = s;
}

fn value_gradients_pass_gradcheck(dev: &wp::Device) {
    let n = 8;
    let (rows, cols, mut g) = triplets(n, 30, 21);
    let vals: Vec<f64> = rows.iter().map(|_| g.unit()).collect();
    let a = Bsr::from_triplets(n, n, &arr(&rows, dev), &arr(&cols, dev), &arr(&vals, dev))
        .unwrap()
        .with_grad()
        .unwrap();
    let x = arr(&(0..n).map(|_| g.unit()).collect::<Vec<f64>>(), dev)
        .with_grad()
        .unwrap();
    let out = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let mut forward = || wp::launch(k_nonlinear, n, (&a, &x, &out), dev);
    let report = wp::gradcheck(
        &mut forward,
        &[a.values(), &x],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    // Every stored block has a nonzero gradient somewhere (its own row's output).
    let nnz = a.nnz().unwrap();
    let nonzero = report
        .analytic
        .iter()
        .filter(|row| row[..nnz].iter().any(|g| g.abs() > 1e-9))
        .count();
    assert!(nonzero > 0);
    let cols_hit = (0..nnz)
        .filter(|&k| report.analytic.iter().any(|row| row[k].abs() > 1e-9))
        .count();
    assert_eq!(cols_hit, nnz, "every stored block reaches the loss");
}

#[wp::kernel]
fn k_scale_blocks(a: Bsr<f64>, s: Array<f64>) {
    let k = tid() as i32;
    bsr_set_block(a, k, bsr_block(a, k) * s[0]);
}

fn backward_through_a_block_write_is_refused(dev: &wp::Device) {
    let a = Bsr::from_triplets(
        2,
        2,
        &arr(&[0, 1], dev),
        &arr(&[1, 0], dev),
        &arr(&[1.0f64, 2.0], dev),
    )
    .unwrap()
    .with_grad()
    .unwrap();
    let s = arr(&[3.0f64], dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_scale_blocks, 2, (&a, &s), dev).unwrap();
    }
    assert_eq!(host(a.values()), [3.0, 6.0]);
    let e = tape.backward(&s).unwrap_err().to_string();
    assert!(e.contains("bsr_set_block"), "{e}");
}

/// NVRTC accepts every kernel above, forward, and with its adjoint where it has one (the
/// generated code against `wp_bsr.h` and `wp_adjoint_bsr.h`), for sm_90 and sm_80: needs
/// libnvrtc, no GPU; skipped, saying so, without it.
#[test]
fn nvrtc_compiles_the_kernels() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED bsr::nvrtc_compiles_the_kernels: {e}");
        return;
    }
    let dir = std::env::temp_dir().join(format!("wp_bsr_aot_{}", std::process::id()));
    let forward = [
        wp::aot::kernel(k_assemble),
        wp::aot::kernel(k_write_rect),
        wp::aot::kernel(k_write_dmat3),
        wp::aot::kernel(k_add_at),
        wp::aot::kernel(k_scale_blocks),
    ];
    let both = [
        wp::aot::kernel(k_residual_f64),
        wp::aot::kernel(k_residual_mat3),
        wp::aot::kernel(k_block_index),
        wp::aot::kernel(k_slots),
        wp::aot::kernel(k_row_lengths),
        wp::aot::kernel(k_read_slot),
        wp::aot::kernel(k_row_at),
        wp::aot::kernel(k_index_at),
        wp::aot::kernel(k_ddot),
        wp::aot::kernel(k_nonlinear),
    ];
    let built = wp::aot::compile(&forward, &[90, 80], &dir).unwrap();
    assert_eq!(built.len(), forward.len() * 2 * 2);
    let built = wp::aot::compile_with_adjoints(&both, &[90, 80], &dir).unwrap();
    assert_eq!(built.len(), both.len() * 2 * 2 * 2);
    let _ = std::fs::remove_dir_all(&dir);
}
