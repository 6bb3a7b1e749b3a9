//! The sparse tier (`warp_runtime::sparse`, the facade's `sparse` feature; the suite's
//! dev-dependency turns it on): BSR assembly from triplets against a dense host reference,
//! bad triplets, `mv` and `dot` against references, and CG on a 2-D Poisson matrix. On a GPU
//! every result is also compared with the CPU's bit for bit (the tier promises the same bits).

use glam::{DMat3, DVec3, Mat3, Vec3};
use warp_lang as wp;
use warp_runtime::sparse::{
    self, Block, Bsr, Mode, Precond, SolveOptions, SparseScalar, SquareBlock, Stop,
};
use wp::FaultKind;

use crate::{arr, host};

backend_tests!(
    triplets_f32_sum_duplicates_in_order,
    triplets_f64_sum_duplicates_in_order,
    triplets_mat3_sum_duplicates_in_order,
    triplets_two_pass_sort,
    triplets_empty_and_empty_rows,
    triplets_counts,
    triplets_out_of_range_is_a_fault,
    triplets_non_finite_is_a_fault,
    triplets_bad_arguments,
    mv_matches_dense_reference,
    mv_mat3_matches_dense_reference,
    mv_beta_zero_does_not_read_y,
    mv_lanes_documented_order,
    mv_shape_mismatch,
    mv_survives_overwritten_structure,
    dot_fixed_tree,
    mv_in_a_capture,
    cg_poisson_point_jacobi_f64,
    cg_poisson_f32,
    cg_block_jacobi_dmat3,
    cg_max_iterations_is_ok,
    cg_graph_mode_matches_host_mode,
    cg_singular_preconditioner,
    cg_breakdown_and_non_finite,
    cg_bad_arguments,
    every_block_type_mv_and_cg,
    krylov_poisson_converges,
    krylov_convection_diffusion,
    krylov_graph_mode_matches_host_mode,
    krylov_max_iterations_is_ok,
    krylov_breakdowns,
    krylov_non_finite_zero_and_singular,
    krylov_bad_arguments,
    krylov_block_types,
    krylov_user_preconditioner,
    krylov_poisson_f32,
);

/// A small deterministic generator (xorshift64*), so the cases repeat.
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

/// `count` random triplets of an `nrow x ncol` matrix, with many duplicates (positions drawn
/// from a few rows and columns).
fn random_triplets<T>(
    nrow: usize,
    ncol: usize,
    count: usize,
    seed: u64,
    value: impl Fn(&mut Rng) -> T,
) -> (Vec<i32>, Vec<i32>, Vec<T>) {
    let mut g = Rng(seed);
    let (mut r, mut c, mut v) = (vec![], vec![], vec![]);
    for _ in 0..count {
        r.push(g.below(nrow) as i32);
        c.push(g.below(ncol) as i32);
        v.push(value(&mut g));
    }
    (r, c, v)
}

/// The reference assembly: each position's triplets summed in ascending triplet order (the
/// first value, then `+` each next), as `(row, col) -> block`, sorted.
fn reference<T: Copy>(
    rows: &[i32],
    cols: &[i32],
    vals: &[T],
    add: impl Fn(T, T) -> T,
) -> std::collections::BTreeMap<(i32, i32), T> {
    let mut m = std::collections::BTreeMap::new();
    for t in 0..rows.len() {
        m.entry((rows[t], cols[t]))
            .and_modify(|s| *s = add(*s, vals[t]))
            .or_insert(vals[t]);
    }
    m
}

/// The matrix's blocks as `(row, col) -> block`, checking the structure on the way: offsets
/// start at 0 and never decrease, columns ascend strictly within a row and lie in range.
fn blocks<B: Block + Copy>(a: &Bsr<B>) -> std::collections::BTreeMap<(i32, i32), B> {
    let off = host(a.offsets());
    let cols = host(a.columns());
    let vals = host(a.values());
    assert_eq!(off.len(), a.nrow() + 1);
    assert_eq!(off[0], 0);
    assert_eq!(a.nnz().unwrap(), off[a.nrow()] as usize);
    assert!(off[a.nrow()] as usize <= a.nnz_bound());
    let mut m = std::collections::BTreeMap::new();
    for r in 0..a.nrow() {
        assert!(off[r] <= off[r + 1], "offsets decrease at row {r}: {off:?}");
        for k in off[r] as usize..off[r + 1] as usize {
            assert!((0..a.ncol() as i32).contains(&cols[k]));
            if k > off[r] as usize {
                assert!(
                    cols[k - 1] < cols[k],
                    "row {r}: columns {:?}",
                    &cols[off[r] as usize..]
                );
            }
            m.insert((r as i32, cols[k]), vals[k]);
        }
    }
    m
}

/// Assembles on `dev` and compares with the reference exactly (the sums run in the same order
/// on every device, so even float sums are compared bit for bit: `to_bits` of each scalar).
fn check_triplets<B: Block + Copy + std::fmt::Debug>(
    dev: &wp::Device,
    nrow: usize,
    ncol: usize,
    (rows, cols, vals): (Vec<i32>, Vec<i32>, Vec<B>),
    add: impl Fn(B, B) -> B,
    bits: impl Fn(&B) -> Vec<u64>,
) {
    let a = Bsr::from_triplets(
        nrow,
        ncol,
        &arr(&rows, dev),
        &arr(&cols, dev),
        &arr(&vals, dev),
    )
    .unwrap();
    assert_eq!((a.nrow(), a.ncol()), (nrow, ncol));
    let got = blocks(&a);
    let want = reference(&rows, &cols, &vals, add);
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        want.keys().collect::<Vec<_>>(),
        "the pattern"
    );
    for (k, w) in &want {
        assert_eq!(
            bits(&got[k]),
            bits(w),
            "block {k:?}: got {:?}, want {w:?}",
            got[k]
        );
    }
}

fn triplets_f32_sum_duplicates_in_order(dev: &wp::Device) {
    // Values of very different magnitudes: a sum in another order would differ in the bits.
    let t = random_triplets(13, 7, 3000, 1, |g| {
        (g.unit() * 10f64.powi(g.below(12) as i32 - 6)) as f32
    });
    check_triplets(dev, 13, 7, t, |a, b| a + b, |v| vec![v.to_bits() as u64]);
}

fn triplets_f64_sum_duplicates_in_order(dev: &wp::Device) {
    let t = random_triplets(40, 50, 20_000, 2, |g| {
        g.unit() * 10f64.powi(g.below(30) as i32 - 15)
    });
    check_triplets(dev, 40, 50, t, |a, b| a + b, |v| vec![v.to_bits()]);
}

fn triplets_mat3_sum_duplicates_in_order(dev: &wp::Device) {
    let t = random_triplets(9, 11, 2000, 3, |g| {
        Mat3::from_cols_array(&std::array::from_fn(|_| {
            (g.unit() * 10f64.powi(g.below(8) as i32 - 4)) as f32
        }))
    });
    check_triplets(
        dev,
        9,
        11,
        t,
        |a, b| a + b,
        |m| {
            m.to_cols_array()
                .iter()
                .map(|x| x.to_bits() as u64)
                .collect()
        },
    );
}

/// More cells than a 32-bit key holds (70000 x 70000 blocks): sorted by column, then stably
/// by row; the result is the same as the one-sort path's.
fn triplets_two_pass_sort(dev: &wp::Device) {
    let n = 70_000;
    let mut t = random_triplets(n, n, 500, 4, |g| g.unit() as f32);
    // Duplicates far apart, and positions that differ only in the row or only in the column.
    t.0.extend([69_999, 69_999, 0, 69_999, 5]);
    t.1.extend([69_999, 0, 69_999, 69_999, 5]);
    t.2.extend([1.0, 2.0, 3.0, 4.0, 0.1]);
    check_triplets(dev, n, n, t, |a, b| a + b, |v| vec![v.to_bits() as u64]);
}

/// No triplets: offsets all zero; rows without triplets: empty rows.
fn triplets_empty_and_empty_rows(dev: &wp::Device) {
    let none = arr::<i32>(&[], dev);
    let a = Bsr::<f32>::from_triplets(4, 3, &none, &none, &arr(&[], dev)).unwrap();
    assert_eq!(host(a.offsets()), [0; 5]);
    assert_eq!(a.nnz().unwrap(), 0);
    let a = Bsr::from_triplets(
        6,
        6,
        &arr(&[4, 1, 4], dev),
        &arr(&[0, 5, 0], dev),
        &arr(&[1.0f64, 2.0, 3.0], dev),
    )
    .unwrap();
    assert_eq!(host(a.offsets()), [0, 0, 1, 1, 1, 2, 2]);
    assert_eq!(&host(a.columns())[..2], [5, 0]);
    assert_eq!(&host(a.values())[..2], [2.0, 4.0]);
}

/// The fault of an assembly (on a GPU the step raises it: synchronising reports it).
fn assembly_fault(
    dev: &wp::Device,
    nrow: usize,
    ncol: usize,
    rows: &[i32],
    cols: &[i32],
    vals: &[f32],
) -> wp::Fault {
    let r = Bsr::from_triplets(
        nrow,
        ncol,
        &arr(rows, dev),
        &arr(cols, dev),
        &arr(vals, dev),
    )
    .and_then(|a| a.nnz());
    match r {
        Err(wp::Error::Fault(f)) => f,
        other => panic!("expected a fault, got {other:?}"),
    }
}

fn triplets_out_of_range_is_a_fault(dev: &wp::Device) {
    // Triplet 3 has row 5 of 4 (and triplet 4 a column of -1: the smaller t is reported).
    let f = assembly_fault(dev, 4, 3, &[0, 1, 2, 5, 0], &[0, 1, 2, 0, -1], &[1.0; 5]);
    assert_eq!(f.kernel, "sparse::from_triplets");
    assert_eq!(
        f.kind,
        FaultKind::OutOfBounds {
            arg: "rows",
            index: vec![3, 5],
            shape: vec![5, 4]
        }
    );
    let f = assembly_fault(dev, 4, 3, &[0, 1, 2, 3], &[0, 1, 3, 0], &[1.0; 4]);
    assert_eq!(
        f.kind,
        FaultKind::OutOfBounds {
            arg: "columns",
            index: vec![2, 3],
            shape: vec![4, 3]
        }
    );
    assert!(f.to_string().contains("sparse::from_triplets"), "{f}");
}

fn triplets_non_finite_is_a_fault(dev: &wp::Device) {
    let f = assembly_fault(
        dev,
        2,
        2,
        &[0, 1, 1, 0],
        &[0, 1, 1, 1],
        &[1.0, 2.0, f32::INFINITY, f32::NAN],
    );
    match f.kind {
        FaultKind::NonFiniteInput { arg, index, values } => {
            assert_eq!((arg, index), ("values", 2));
            assert_eq!(values, [f64::INFINITY]);
        }
        k => panic!("{k:?}"),
    }
    // A NaN inside a Mat3 block names its triplet.
    let mut m = Mat3::IDENTITY;
    m.y_axis.z = f32::NAN;
    let r = Bsr::from_triplets(
        2,
        2,
        &arr(&[0, 1], dev),
        &arr(&[0, 1], dev),
        &arr(&[Mat3::IDENTITY, m], dev),
    )
    .and_then(|a| a.nnz());
    match r {
        Err(wp::Error::Fault(f)) => match f.kind {
            FaultKind::NonFiniteInput { arg, index, values } => {
                assert_eq!((arg, index), ("values", 1));
                assert!(values[0].is_nan());
            }
            k => panic!("{k:?}"),
        },
        other => panic!("{other:?}"),
    }
}

fn triplets_bad_arguments(dev: &wp::Device) {
    let e = Bsr::from_triplets(
        2,
        2,
        &arr(&[0, 1], dev),
        &arr(&[0], dev),
        &arr(&[1.0f32, 2.0], dev),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("sparse::from_triplets") && e.contains("[2], [1] and [2]"),
        "{e}"
    );
    let e = Bsr::from_triplets(
        usize::MAX / 2,
        2,
        &arr(&[0], dev),
        &arr(&[0], dev),
        &arr(&[1.0f32], dev),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("`nrow`"), "{e}");
    if !dev.is_cpu() {
        let e = Bsr::from_triplets(
            2,
            2,
            &arr(&[0], &wp::cpu()),
            &arr(&[0], dev),
            &arr(&[1.0f32], dev),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("rows"), "{e}");
    }
}

/// The 2-D 5-point Laplacian on an `m x m` grid (Dirichlet boundary): 4 on the diagonal, -1
/// to each neighbour, as triplets (the diagonal split into two triplets of 3 and 1, so that
/// assembly sums duplicates).
fn poisson(m: usize) -> (Vec<i32>, Vec<i32>, Vec<f64>) {
    let (mut r, mut c, mut v) = (vec![], vec![], vec![]);
    let id = |i: usize, j: usize| (i * m + j) as i32;
    for i in 0..m {
        for j in 0..m {
            r.extend([id(i, j), id(i, j)]);
            c.extend([id(i, j), id(i, j)]);
            v.extend([3.0, 1.0]);
            let mut nb = vec![];
            if i > 0 {
                nb.push(id(i - 1, j));
            }
            if i + 1 < m {
                nb.push(id(i + 1, j));
            }
            if j > 0 {
                nb.push(id(i, j - 1));
            }
            if j + 1 < m {
                nb.push(id(i, j + 1));
            }
            for k in nb {
                r.push(id(i, j));
                c.push(k);
                v.push(-1.0);
            }
        }
    }
    (r, c, v)
}

/// `alpha A x + beta y` from the blocks, in f64 (`get(block, i, j)` reads an entry).
fn dense_mv<B: Block + Copy>(
    a: &Bsr<B>,
    get: impl Fn(&B, usize, usize) -> f64,
    x: &[f64],
    alpha: f64,
    beta: f64,
    y: &[f64],
) -> Vec<f64> {
    let (rr, cc) = (B::ROWS, B::COLS);
    let mut out: Vec<f64> = y.iter().map(|v| beta * v).collect();
    for ((r, c), b) in blocks(a) {
        for i in 0..rr {
            for j in 0..cc {
                out[r as usize * rr + i] += alpha * get(&b, i, j) * x[c as usize * cc + j];
            }
        }
    }
    out
}

/// On a GPU, `f` gives the same bits as on the CPU.
fn same_on_cpu<T: PartialEq + std::fmt::Debug>(
    dev: &wp::Device,
    what: &str,
    f: impl Fn(&wp::Device) -> T,
) {
    if !dev.is_cpu() {
        assert_eq!(
            f(dev),
            f(&wp::cpu()),
            "{what}: the GPU differs from the CPU"
        );
    }
}

/// `sparse::dot`'s documented order in plain Rust (which never contracts into an FMA): chunks
/// of 4096; lane `l` of 256 sums from 0 the products of the chunk's elements `l, l + 256, ..`;
/// the lanes added pairwise at strides 128, .., 1; the chunks' partials reduced the same way.
fn documented_dot(a: &[f32], b: &[f32]) -> f32 {
    fn tree(mut s: Vec<f32>) -> f32 {
        let mut stride = 128;
        while stride > 0 {
            for l in 0..stride {
                s[l] += s[l + stride];
            }
            stride /= 2;
        }
        s[0]
    }
    let n = a.len();
    let chunks = n.div_ceil(4096).max(1);
    let partials: Vec<f32> = (0..chunks)
        .map(|c| {
            tree(
                (0..256)
                    .map(|l| {
                        let idx = (c * 4096 + l..(c + 1) * 4096).step_by(256);
                        idx.filter(|&i| i < n).fold(0.0, |acc, i| acc + a[i] * b[i])
                    })
                    .collect(),
            )
        })
        .collect();
    tree(
        (0..256)
            .map(|l| {
                (l..chunks)
                    .step_by(256)
                    .fold(0.0, |acc, i| acc + partials[i])
            })
            .collect(),
    )
}

/// `sparse::mv`'s documented order for scalar blocks: each row's sum from 0 over its blocks
/// in storage order of `a_k * x[col_k]`, then `alpha * acc`, plus `beta * y` unless beta is 0.
fn documented_mv(a: &Bsr<f32>, x: &[f32], alpha: f32, beta: f32, y: &[f32]) -> Vec<f32> {
    let (off, cols, vals) = (host(a.offsets()), host(a.columns()), host(a.values()));
    (0..a.nrow())
        .map(|r| {
            let blocks = off[r] as usize..off[r + 1] as usize;
            let acc = blocks.fold(0.0f32, |acc, k| acc + vals[k] * x[cols[k] as usize]);
            if beta == 0.0 {
                alpha * acc
            } else {
                alpha * acc + beta * y[r]
            }
        })
        .collect()
}

fn mv_matches_dense_reference(dev: &wp::Device) {
    let (r, c, v) = random_triplets(50, 30, 600, 5, |g| g.unit() as f32);
    let run = |d: &wp::Device| {
        let a = Bsr::from_triplets(50, 30, &arr(&r, d), &arr(&c, d), &arr(&v, d)).unwrap();
        let mut g = Rng(6);
        let x: Vec<f32> = (0..30).map(|_| g.unit() as f32).collect();
        let y0: Vec<f32> = (0..50).map(|_| g.unit() as f32).collect();
        let y = arr(&y0, d);
        sparse::mv(0.5f32, &a, &arr(&x, d), -2.0, &y).unwrap();
        let got = host(&y);
        let f64s = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
        let want = dense_mv(&a, |b, _, _| *b as f64, &f64s(&x), 0.5, -2.0, &f64s(&y0));
        // f32 rounding of at most ~25 products per row of magnitude <= 1 (random duplicates
        // summed first): 1e-5 absolute is ~100 ulps of the row sums' size.
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!((*g as f64 - w).abs() <= 1e-5, "row {i}: {g} vs {w}");
        }
        // The documented order, bit for bit.
        let doc = documented_mv(&a, &x, 0.5, -2.0, &y0);
        let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&got), bits(&doc));
        got.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    };
    run(dev);
    same_on_cpu(dev, "mv f32", run);
}

fn mv_mat3_matches_dense_reference(dev: &wp::Device) {
    let (r, c, v) = random_triplets(20, 15, 200, 7, |g| {
        Mat3::from_cols_array(&std::array::from_fn(|_| g.unit() as f32))
    });
    let run = |d: &wp::Device| {
        let a = Bsr::from_triplets(20, 15, &arr(&r, d), &arr(&c, d), &arr(&v, d)).unwrap();
        let mut g = Rng(8);
        let x: Vec<Vec3> = (0..15)
            .map(|_| Vec3::new(g.unit() as f32, g.unit() as f32, g.unit() as f32))
            .collect();
        let y = arr(&[Vec3::ZERO; 20], d);
        sparse::mv(1.0, &a, &arr(&x, d), 0.0, &y).unwrap();
        let got = host(&y);
        let xs: Vec<f64> = x
            .iter()
            .flat_map(|p| p.to_array())
            .map(|v| v as f64)
            .collect();
        // glam's matrices index (column, row): entry (i, j) is col(j)[i].
        let want = dense_mv(&a, |b, i, j| b.col(j)[i] as f64, &xs, 1.0, 0.0, &[0.0; 60]);
        for (k, w) in want.iter().enumerate() {
            let g = got[k / 3][k % 3] as f64;
            // As above, with 3 products per block entry of a row: 1e-5 absolute.
            assert!((g - w).abs() <= 1e-5, "scalar row {k}: {g} vs {w}");
        }
        got.iter()
            .flat_map(|p| p.to_array().map(f32::to_bits))
            .collect::<Vec<_>>()
    };
    run(dev);
    same_on_cpu(dev, "mv Mat3", run);
}

/// `sparse::set_mv_lanes`: with `w` lanes each row sums its blocks `l, l + w, ..` into lane
/// `l` and adds the lanes pairwise at strides `w/2, .., 1`, bit for bit (f32 and `DMat3`
/// blocks, rows of 0 to ~40 blocks, so some lanes stay empty); the GPU gives the CPU's bits
/// for each `w`; another `w` is refused; `None` is `w = 1` again.
fn mv_lanes_documented_order(dev: &wp::Device) {
    let (r, c, v) = random_triplets(40, 60, 900, 11, |g| g.unit() as f32);
    let (rb, cb, vb) = random_triplets(12, 9, 150, 12, |g| {
        DMat3::from_cols_array(&std::array::from_fn(|_| g.unit()))
    });
    let lanes_sum = |terms: &[f64], w: usize| -> f64 {
        let mut s = vec![0.0f64; w];
        for (n, t) in terms.iter().enumerate() {
            s[n % w] += t;
        }
        let mut stride = w / 2;
        while stride > 0 {
            for l in 0..stride {
                s[l] += s[l + stride];
            }
            stride /= 2;
        }
        s[0]
    };
    let run = |d: &wp::Device| {
        let a = Bsr::from_triplets(40, 60, &arr(&r, d), &arr(&c, d), &arr(&v, d)).unwrap();
        let ab = Bsr::from_triplets(12, 9, &arr(&rb, d), &arr(&cb, d), &arr(&vb, d)).unwrap();
        let mut g = Rng(13);
        let x: Vec<f32> = (0..60).map(|_| g.unit() as f32).collect();
        let xb: Vec<DVec3> = (0..9)
            .map(|_| DVec3::new(g.unit(), g.unit(), g.unit()))
            .collect();
        let (off, cols, vals) = (host(a.offsets()), host(a.columns()), host(a.values()));
        let (offb, colsb, valsb) = (host(ab.offsets()), host(ab.columns()), host(ab.values()));
        let mut out = Vec::new();
        for w in [1usize, 2, 4, 8, 16, 32] {
            sparse::set_mv_lanes(Some(w)).unwrap();
            let y = arr(&[0.0f32; 40], d);
            sparse::mv(1.0f32, &a, &arr(&x, d), 0.0, &y).unwrap();
            let yb = arr(&[DVec3::ZERO; 12], d);
            sparse::mv(1.0, &ab, &arr(&xb, d), 0.0, &yb).unwrap();
            sparse::set_mv_lanes(None).unwrap();
            let got = host(&y);
            for (row, g) in got.iter().enumerate() {
                // f32: the same order in f32 arithmetic (each lane's sum, then the tree).
                let ks = off[row] as usize..off[row + 1] as usize;
                let mut s = vec![0.0f32; w];
                for (n, k) in ks.enumerate() {
                    s[n % w] += vals[k] * x[cols[k] as usize];
                }
                let mut stride = w / 2;
                while stride > 0 {
                    for l in 0..stride {
                        s[l] += s[l + stride];
                    }
                    stride /= 2;
                }
                assert_eq!(g.to_bits(), s[0].to_bits(), "f32, {w} lanes, row {row}");
            }
            let gotb = host(&yb);
            for (row, g) in gotb.iter().enumerate() {
                for i in 0..3 {
                    // A block's scalar row i: its columns in ascending order, one term each
                    // (glam: entry (i, j) is col(j)[i]).
                    let ks = offb[row] as usize..offb[row + 1] as usize;
                    let per_block: Vec<f64> = ks
                        .map(|k| {
                            let xc = xb[colsb[k] as usize];
                            (0..3).fold(0.0, |acc, j| acc + valsb[k].col(j)[i] * xc[j])
                        })
                        .collect();
                    // A lane adds a block's three products to its partial one by one, not
                    // the block's sum as here: equal within f64 rounding (~40 terms of
                    // size <= 3), which the f32 rows above check bit for bit.
                    let want = lanes_sum(&per_block, w);
                    assert!(
                        (g[i] - want).abs() <= 1e-12 * (1.0 + want.abs()),
                        "DMat3, {w} lanes, row {row}.{i}: {} vs {want}",
                        g[i]
                    );
                }
            }
            out.push((
                got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                gotb.iter()
                    .flat_map(|p| p.to_array().map(f64::to_bits))
                    .collect::<Vec<_>>(),
            ));
        }
        out
    };
    let cpu = run(dev);
    // More lanes than blocks in a row change nothing but the order: w = 1 and 32 differ
    // somewhere (the order matters), which shows the setting reached the product.
    assert_ne!(cpu[0].0, cpu[5].0, "32 lanes gave w = 1's bits everywhere");
    same_on_cpu(dev, "mv with lanes", run);
    for bad in [0usize, 3, 64] {
        let e = sparse::set_mv_lanes(Some(bad)).unwrap_err().to_string();
        assert!(
            e.contains("sparse::set_mv_lanes") && e.contains(&format!("`lanes` is {bad}")),
            "{e}"
        );
    }
}

fn mv_beta_zero_does_not_read_y(dev: &wp::Device) {
    let a = Bsr::from_triplets(
        2,
        2,
        &arr(&[0, 1], dev),
        &arr(&[1, 0], dev),
        &arr(&[2.0f64, 3.0], dev),
    )
    .unwrap();
    let y = arr(&[f64::NAN, f64::NAN], dev);
    sparse::mv(1.0, &a, &arr(&[1.0, 10.0], dev), 0.0, &y).unwrap();
    assert_eq!(host(&y), [20.0, 3.0]);
    // beta != 0 reads it: a NaN stays.
    let y = arr(&[f64::NAN, 1.0], dev);
    sparse::mv(1.0, &a, &arr(&[1.0, 10.0], dev), 1.0, &y).unwrap();
    let got = host(&y);
    assert!(got[0].is_nan() && got[1] == 4.0, "{got:?}");
}

fn mv_shape_mismatch(dev: &wp::Device) {
    let a = Bsr::from_triplets(
        3,
        2,
        &arr(&[0], dev),
        &arr(&[1], dev),
        &arr(&[DMat3::IDENTITY], dev),
    )
    .unwrap();
    let e = sparse::mv(
        1.0,
        &a,
        &arr(&[DVec3::ONE; 3], dev),
        0.0,
        &arr(&[DVec3::ZERO; 3], dev),
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(e, wp::Error::InvalidArgument { .. })
            && msg.contains("sparse::mv")
            && msg.contains("`x` has shape [3] of DVec3")
            && msg.contains("3 x 2 blocks of 3 x 3 (9 x 6 scalars)")
            && msg.contains("needs 2 DVec3 elements"),
        "{msg}"
    );
    let e = sparse::mv(
        1.0,
        &a,
        &arr(&[DVec3::ONE; 2], dev),
        0.0,
        &arr(&[DVec3::ZERO; 2], dev),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("`y` has shape [2] of DVec3") && e.contains("needs 3 DVec3 elements"),
        "{e}"
    );
    let sq = Bsr::from_triplets(
        2,
        2,
        &arr(&[0], dev),
        &arr(&[1], dev),
        &arr(&[DMat3::IDENTITY], dev),
    )
    .unwrap();
    let x = arr(&[DVec3::ONE; 2], dev);
    let e = sparse::mv(1.0, &sq, &x, 0.0, &x).unwrap_err().to_string();
    assert!(e.contains("overlap"), "{e}");
    // y over the matrix's own values (f32 blocks: the same element type).
    let f = Bsr::from_triplets(
        2,
        2,
        &arr(&[0, 1], dev),
        &arr(&[0, 1], dev),
        &arr(&[1.0f32, 2.0], dev),
    )
    .unwrap();
    let e = sparse::mv(
        1.0,
        &f,
        &arr(&[1.0f32; 2], dev),
        0.0,
        &f.values().view(0..2).unwrap(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("`y` overlaps the matrix"), "{e}");
}

fn dot_fixed_tree(dev: &wp::Device) {
    for n in [0usize, 1, 255, 4096, 4097, 70_001] {
        let run = |d: &wp::Device| {
            let mut g = Rng(n as u64 + 9);
            let a: Vec<f32> = (0..n).map(|_| g.unit() as f32).collect();
            let b: Vec<f32> = (0..n).map(|_| g.unit() as f32).collect();
            let out = arr(&[f32::NAN], d);
            sparse::dot(&arr(&a, d), &arr(&b, d), &out).unwrap();
            let got = host(&out)[0];
            let want: f64 = a.iter().zip(&b).map(|(x, y)| *x as f64 * *y as f64).sum();
            // f32 products and sums of n terms of magnitude <= 1: each term goes through at
            // most ~30 roundings (its product, 16 serial adds in its lane, 8 tree levels, the
            // final step's few), so 30 u = 30 x 2^-24 ~ 1.8e-6 times the sum of |terms|
            // bounds the error: 2e-6.
            let scale: f64 = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (*x as f64 * *y as f64).abs())
                .sum();
            assert!(
                (got as f64 - want).abs() <= 2e-6 * scale.max(1.0),
                "n {n}: {got} vs {want}"
            );
            // The documented order, bit for bit (a promise, not only CPU-GPU agreement).
            assert_eq!(got.to_bits(), documented_dot(&a, &b).to_bits(), "n {n}");
            got.to_bits()
        };
        run(dev);
        same_on_cpu(dev, &format!("dot of {n}"), run);
    }
    let e = sparse::dot(
        &arr(&[1.0f64; 3], dev),
        &arr(&[1.0; 2], dev),
        &arr(&[0.0], dev),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("sparse::dot") && e.contains("[3] and [2]"),
        "{e}"
    );
}

/// `|b - A x|` by an independent host computation (f64, from the assembled blocks).
fn true_residual<B: Block + Copy>(
    a: &Bsr<B>,
    get: impl Fn(&B, usize, usize) -> f64,
    b: &[f64],
    x: &[f64],
) -> f64 {
    let ax = dense_mv(a, get, x, 1.0, 0.0, &vec![0.0; b.len()]);
    b.iter()
        .zip(&ax)
        .map(|(b, y)| (b - y) * (b - y))
        .sum::<f64>()
        .sqrt()
}

/// CG with point Jacobi on the 32 x 32 Poisson matrix (1024 unknowns), f64, rtol 1e-6: it
/// converges, its true residual (an independent host product) is within the tolerance (1.01
/// times: the recurrence's residual drifts from the true one by rounding, ~1e-13 here), the
/// history has one entry per iteration plus one, and a GPU takes the same iterations to the
/// same bits.
fn cg_poisson_point_jacobi_f64(dev: &wp::Device) {
    let m = 32;
    let (r, c, v) = poisson(m);
    let n = m * m;
    let mut g = Rng(10);
    let b: Vec<f64> = (0..n).map(|_| g.unit()).collect();
    let run = |d: &wp::Device, pre: Precond| {
        let a = Bsr::from_triplets(n, n, &arr(&r, d), &arr(&c, d), &arr(&v, d)).unwrap();
        let x = arr(&vec![0.0f64; n], d);
        let o = SolveOptions {
            rtol: 1e-6,
            ..Default::default()
        };
        let rep = sparse::cg(&a, &arr(&b, d), &x, pre, &o).unwrap();
        assert_eq!(rep.stop, Stop::Converged, "{rep:?}");
        assert!(rep.converged);
        assert_eq!(rep.history.len(), rep.iterations + 1);
        assert!(
            rep.iterations > 10 && rep.iterations < 200,
            "{}",
            rep.iterations
        );
        let bn = b.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((rep.tolerance - 1e-6 * bn).abs() <= 1e-15 * bn);
        assert!(rep.residual <= rep.tolerance);
        let xs = host(&x);
        let tr = true_residual(&a, |b, _, _| *b, &b, &xs);
        assert!(
            tr <= 1.01 * rep.tolerance,
            "true residual {tr} > {}",
            rep.tolerance
        );
        (
            rep.iterations,
            rep.history.iter().map(|h| h.to_bits()).collect::<Vec<_>>(),
            xs.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        )
    };
    let point = run(dev, Precond::PointJacobi);
    // Block Jacobi of 1 x 1 blocks is point Jacobi; without a preconditioner (the diagonal is
    // constant, so Jacobi only scales) the iterations are the same count.
    assert_eq!(run(dev, Precond::Jacobi), point);
    assert_eq!(run(dev, Precond::None).0, point.0);
    same_on_cpu(dev, "cg f64", |d| run(d, Precond::PointJacobi));
}

/// f32: the recurrence reaches rtol 1e-5 (f32's rounding floor for this matrix, whose
/// condition number is ~440, is near 1e-6 |b|), and the true residual is within 2x of the
/// tolerance (f32 drift of the recurrence).
fn cg_poisson_f32(dev: &wp::Device) {
    let m = 32;
    let (r, c, v) = poisson(m);
    let v: Vec<f32> = v.iter().map(|&x| x as f32).collect();
    let n = m * m;
    let b: Vec<f32> = (0..n).map(|i| ((i % 7) as f32 - 3.0) / 3.0).collect();
    let run = |d: &wp::Device| {
        let a = Bsr::from_triplets(n, n, &arr(&r, d), &arr(&c, d), &arr(&v, d)).unwrap();
        let x = arr(&vec![0.0f32; n], d);
        let o = SolveOptions {
            rtol: 1e-5,
            check_every: 7,
            ..Default::default()
        };
        let rep = sparse::cg(&a, &arr(&b, d), &x, Precond::Jacobi, &o).unwrap();
        assert_eq!(rep.stop, Stop::Converged, "{rep:?}");
        let xs: Vec<f64> = host(&x).iter().map(|&v| v as f64).collect();
        let bs: Vec<f64> = b.iter().map(|&v| v as f64).collect();
        let tr = true_residual(&a, |b, _, _| *b as f64, &bs, &xs);
        assert!(
            tr <= 2.0 * rep.tolerance,
            "true residual {tr}, tolerance {}",
            rep.tolerance
        );
        (
            rep.iterations,
            host(&x).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        )
    };
    run(dev);
    same_on_cpu(dev, "cg f32", run);
}

/// Block Jacobi on `DMat3` blocks: the Poisson matrix (16 x 16 grid) Kronecker a symmetric
/// positive definite 3 x 3 K (so SPD): each block is `L_ij K`. Block Jacobi inverts
/// `4 K` exactly up to rounding, so it converges in the iterations of the scalar problem, and
/// in fewer than point Jacobi.
fn cg_block_jacobi_dmat3(dev: &wp::Device) {
    let m = 16;
    let (r, c, v) = poisson(m);
    let k = DMat3::from_cols_array(&[4.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 2.0]);
    let blocks_v: Vec<DMat3> = v.iter().map(|&s| k * s).collect();
    let n = m * m;
    let b: Vec<f64> = (0..3 * n).map(|i| ((i % 5) as f64 - 2.0) * 0.5).collect();
    let run = |d: &wp::Device, pre: Precond| {
        let a = Bsr::from_triplets(n, n, &arr(&r, d), &arr(&c, d), &arr(&blocks_v, d)).unwrap();
        let x = arr(&vec![0.0f64; 3 * n], d);
        let o = SolveOptions {
            rtol: 1e-8,
            ..Default::default()
        };
        let rep = sparse::cg(&a, &arr(&b, d), &x, pre, &o).unwrap();
        assert_eq!(rep.stop, Stop::Converged, "{pre:?}: {rep:?}");
        let tr = true_residual(&a, |b, i, j| b.col(j)[i], &b, &host(&x));
        assert!(
            tr <= 1.01 * rep.tolerance,
            "{pre:?}: {tr} > {}",
            rep.tolerance
        );
        (
            rep.iterations,
            host(&x).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        )
    };
    let block = run(dev, Precond::Jacobi);
    let point = run(dev, Precond::PointJacobi);
    assert!(block.0 < point.0, "block {} vs point {}", block.0, point.0);
    same_on_cpu(dev, "cg DMat3", |d| run(d, Precond::Jacobi));
}

fn cg_max_iterations_is_ok(dev: &wp::Device) {
    let (r, c, v) = poisson(16);
    let n = 256;
    let a = Bsr::from_triplets(n, n, &arr(&r, dev), &arr(&c, dev), &arr(&v, dev)).unwrap();
    let x = arr(&vec![0.0f64; n], dev);
    let o = SolveOptions {
        rtol: 1e-12,
        max_iter: 5,
        check_every: 3,
        ..Default::default()
    };
    let rep = sparse::cg(&a, &arr(&vec![1.0; n], dev), &x, Precond::None, &o).unwrap();
    assert_eq!(
        (rep.stop, rep.iterations, rep.converged),
        (Stop::MaxIterations, 5, false)
    );
    assert_eq!(rep.history.len(), 6);
    assert!(rep.residual > rep.tolerance);
    // CG minimises the A-norm of the error, not |r|, whose history need not fall: only its
    // start (|b| from x = 0: 16) and that it ends at the report's residual are known.
    assert_eq!(rep.history[0], 16.0);
    assert_eq!(rep.history[5], rep.residual);
    assert!(
        rep.history.iter().all(|h| h.is_finite() && *h > 0.0),
        "{:?}",
        rep.history
    );
    // max_iter 0: no iteration.
    let o = SolveOptions { max_iter: 0, ..o };
    let rep = sparse::cg(&a, &arr(&vec![1.0; n], dev), &x, Precond::None, &o).unwrap();
    assert_eq!((rep.stop, rep.iterations), (Stop::MaxIterations, 0));
}

fn cg_singular_preconditioner(dev: &wp::Device) {
    // Row 2 has no diagonal block.
    let a = Bsr::from_triplets(
        3,
        3,
        &arr(&[0, 1, 2, 2], dev),
        &arr(&[0, 1, 1, 0], dev),
        &arr(&[2.0f64, 2.0, 1.0, 1.0], dev),
    )
    .unwrap();
    let x = arr(&[7.0f64, 7.0, 7.0], dev);
    let rep = sparse::cg(
        &a,
        &arr(&[1.0; 3], dev),
        &x,
        Precond::Jacobi,
        &SolveOptions::default(),
    )
    .unwrap();
    assert_eq!(rep.stop, Stop::SingularPreconditioner { block_row: 2 });
    assert_eq!(rep.iterations, 0);
    assert_eq!(host(&x), [7.0; 3], "x untouched");
    // A singular diagonal Mat3 block (rank 2) in row 1.
    let sing = Mat3::from_cols_array(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0]);
    let a = Bsr::from_triplets(
        2,
        2,
        &arr(&[0, 1], dev),
        &arr(&[0, 1], dev),
        &arr(&[Mat3::IDENTITY, sing], dev),
    )
    .unwrap();
    let x = arr(&[0.0f32; 6], dev);
    let rep = sparse::cg(
        &a,
        &arr(&[1.0; 6], dev),
        &x,
        Precond::Jacobi,
        &SolveOptions::default(),
    )
    .unwrap();
    assert_eq!(rep.stop, Stop::SingularPreconditioner { block_row: 1 });
}

fn cg_breakdown_and_non_finite(dev: &wp::Device) {
    // diag(1, -1), b = (1, 1): p = b, p.Ap = 0.
    let a = Bsr::from_triplets(
        2,
        2,
        &arr(&[0, 1], dev),
        &arr(&[0, 1], dev),
        &arr(&[1.0f64, -1.0], dev),
    )
    .unwrap();
    let x = arr(&[0.0f64; 2], dev);
    let rep = sparse::cg(
        &a,
        &arr(&[1.0; 2], dev),
        &x,
        Precond::None,
        &SolveOptions::default(),
    )
    .unwrap();
    assert_eq!(
        rep.stop,
        Stop::Breakdown {
            what: "p.Ap",
            value: 0.0
        }
    );
    assert_eq!(host(&x), [0.0; 2], "x untouched by the broken iteration");
    // An indefinite Jacobi preconditioner: r.z <= 0 is a breakdown, not a NaN later.
    // [[1, -0.5], [-0.5, -1]], b = (1, 1): z = (1, -1), r.z = 0 at the set-up.
    let ind = |n: usize, t: &[(i32, i32, f64)]| {
        let r: Vec<i32> = t.iter().map(|e| e.0).collect();
        let c: Vec<i32> = t.iter().map(|e| e.1).collect();
        let v: Vec<f64> = t.iter().map(|e| e.2).collect();
        Bsr::from_triplets(n, n, &arr(&r, dev), &arr(&c, dev), &arr(&v, dev)).unwrap()
    };
    let a2 = ind(2, &[(0, 0, 1.0), (0, 1, -0.5), (1, 0, -0.5), (1, 1, -1.0)]);
    let x = arr(&[0.0f64; 2], dev);
    let rep = sparse::cg(
        &a2,
        &arr(&[1.0; 2], dev),
        &x,
        Precond::Jacobi,
        &SolveOptions::default(),
    )
    .unwrap();
    let rz = |value| Stop::Breakdown { what: "r.z", value };
    assert_eq!((rep.stop, rep.iterations), (rz(0.0), 0), "{rep:?}");
    assert_eq!(host(&x), [0.0; 2], "x untouched");
    // [[1, 0.5, 0], [0.5, -1, 0], [0, 0, 1]], b = (1, -1, 1): r.z = 1, p.Ap = 2, then the
    // first iteration's r.z = -0.25 (exact in binary); x holds that iteration, 0.5 p.
    let t = [
        (0, 0, 1.0),
        (0, 1, 0.5),
        (1, 0, 0.5),
        (1, 1, -1.0),
        (2, 2, 1.0),
    ];
    for mode in [Mode::Host, Mode::Graph] {
        let x3 = arr(&[0.0f64; 3], dev);
        let o = SolveOptions {
            mode,
            ..Default::default()
        };
        let b3 = arr(&[1.0, -1.0, 1.0], dev);
        let rep = sparse::cg(&ind(3, &t), &b3, &x3, Precond::Jacobi, &o).unwrap();
        assert_eq!(
            (rep.stop, rep.iterations),
            (rz(-0.25), 1),
            "{mode:?}: {rep:?}"
        );
        assert_eq!(host(&x3), [0.5; 3], "{mode:?}");
    }
    let rep = sparse::cg(
        &a,
        &arr(&[f64::NAN, 1.0], dev),
        &x,
        Precond::None,
        &SolveOptions::default(),
    )
    .unwrap();
    assert_eq!((rep.stop, rep.iterations), (Stop::NonFinite, 0));
    // b = 0 from x = 0: converged at once.
    let rep = sparse::cg(
        &a,
        &arr(&[0.0; 2], dev),
        &x,
        Precond::None,
        &SolveOptions::default(),
    )
    .unwrap();
    assert_eq!((rep.stop, rep.iterations), (Stop::Converged, 0));
}

fn cg_bad_arguments(dev: &wp::Device) {
    let a =
        Bsr::from_triplets(2, 3, &arr(&[0], dev), &arr(&[0], dev), &arr(&[1.0f32], dev)).unwrap();
    let e = sparse::cg(
        &a,
        &arr(&[0.0; 2], dev),
        &arr(&[0.0; 2], dev),
        Precond::None,
        &SolveOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("sparse::cg") && e.contains("2 x 3 blocks"),
        "{e}"
    );
    let a =
        Bsr::from_triplets(2, 2, &arr(&[0], dev), &arr(&[0], dev), &arr(&[1.0f32], dev)).unwrap();
    let e = sparse::cg(
        &a,
        &arr(&[0.0; 3], dev),
        &arr(&[0.0; 2], dev),
        Precond::None,
        &SolveOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("`b` has shape [3]") && e.contains("2 x 2 scalars"),
        "{e}"
    );
    let o = SolveOptions {
        check_every: 0,
        ..Default::default()
    };
    let e = sparse::cg(
        &a,
        &arr(&[0.0; 2], dev),
        &arr(&[0.0; 2], dev),
        Precond::None,
        &o,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("check_every"), "{e}");
    // Each further bad argument: the message names sparse::cg and the argument.
    let cg_err = |a: &Bsr<f32>, b: &wp::Array<f32>, x: &wp::Array<f32>, o: SolveOptions| {
        sparse::cg(a, b, x, Precond::None, &o)
            .unwrap_err()
            .to_string()
    };
    let x = arr(&[0.0f32; 2], dev);
    let d = SolveOptions::default();
    let e = cg_err(&a, &x, &x, d);
    assert!(
        e.contains("sparse::cg") && e.contains("`b` and `x` overlap"),
        "{e}"
    );
    // A matrix of two blocks: its values are two scalars, the length of x.
    let a2 = Bsr::from_triplets(
        2,
        2,
        &arr(&[0, 1], dev),
        &arr(&[0, 1], dev),
        &arr(&[1.0f32, 1.0], dev),
    )
    .unwrap();
    let e = cg_err(&a2, &arr(&[0.0; 2], dev), a2.values(), d);
    assert!(
        e.contains("sparse::cg") && e.contains("`x` overlaps the matrix"),
        "{e}"
    );
    let b = arr(&[1.0f32; 2], dev);
    for (name, o) in [
        (
            "rtol",
            SolveOptions {
                rtol: f64::NAN,
                ..d
            },
        ),
        ("rtol", SolveOptions { rtol: -1.0, ..d }),
        (
            "atol",
            SolveOptions {
                atol: f64::INFINITY,
                ..d
            },
        ),
        ("atol", SolveOptions { atol: -1e-3, ..d }),
        (
            "max_iter",
            SolveOptions {
                max_iter: i32::MAX as usize,
                ..d
            },
        ),
    ] {
        let e = cg_err(&a, &b, &x, o);
        assert!(
            e.contains("sparse::cg") && e.contains(&format!("`{name}`")),
            "{o:?}: {e}"
        );
    }
    if !dev.is_cpu() {
        let e = sparse::cg(&a, &arr(&[1.0f32; 2], &wp::cpu()), &x, Precond::None, &d).unwrap_err();
        assert!(
            matches!(
                e,
                wp::Error::DeviceMismatch {
                    kernel: "sparse::cg",
                    arg: "b",
                    ..
                }
            ),
            "{e}"
        );
    }
}

/// `mv` is recorded by a capture: each replay multiplies the arrays' contents at that time
/// (the same bits as a direct call); `dot` (it allocates scratch) and a CG solve (it reads
/// back) are refused inside one.
fn mv_in_a_capture(dev: &wp::Device) {
    let (r, c, v) = poisson(6);
    let a = Bsr::from_triplets(36, 36, &arr(&r, dev), &arr(&c, dev), &arr(&v, dev)).unwrap();
    let x = arr(&[1.0f64; 36], dev);
    let y = arr(&[0.0f64; 36], dev);
    // Once before capturing: a GPU loads the library at the first use.
    sparse::mv(1.0, &a, &x, 0.0, &y).unwrap();
    let g = wp::capture(dev, || sparse::mv(2.0, &a, &x, 0.5, &y)).unwrap();
    let mut want = host(&y);
    for k in 0..3 {
        let xs: Vec<f64> = (0..36).map(|i| (i * (k + 1)) as f64 * 0.25).collect();
        x.copy_from(&arr(&xs, dev)).unwrap();
        g.launch().unwrap();
        let w = arr(&want, dev);
        sparse::mv(2.0, &a, &x, 0.5, &w).unwrap();
        want = host(&w);
        assert_eq!(host(&y), want, "replay {k}");
    }
    let out = arr(&[0.0f64], dev);
    let e = wp::capture(dev, || sparse::dot(&x, &x, &out)).unwrap_err();
    assert!(matches!(e, wp::Error::Capture { .. }), "{e}");
    let e = wp::capture(dev, || {
        sparse::cg(&a, &y, &x, Precond::None, &SolveOptions::default()).map(|_| ())
    })
    .unwrap_err();
    assert!(
        matches!(e, wp::Error::Capture { .. }) && e.to_string().contains("sparse::cg"),
        "{e}"
    );
}

/// `from_triplets_n`: the first `count` triplets, the count on the host or on the device
/// (read where the work runs); a device count leaves room for every triplet of the arrays.
fn triplets_counts(dev: &wp::Device) {
    let (r, c, v) = random_triplets(20, 30, 900, 11, |g| g.unit());
    let (ra, ca, va) = (arr(&r, dev), arr(&c, dev), arr(&v, dev));
    for k in [0usize, 1, 400, 900] {
        let want = reference(&r[..k], &c[..k], &v[..k], |a, b| a + b);
        let host_count = Bsr::from_triplets_n(20, 30, &ra, &ca, &va, k).unwrap();
        assert_eq!(host_count.nnz_bound(), k);
        let count = arr(&[k as i32], dev);
        let device_count = Bsr::from_triplets_n(20, 30, &ra, &ca, &va, &count).unwrap();
        assert_eq!(device_count.nnz_bound(), 900);
        for a in [host_count, device_count] {
            let got = blocks(&a);
            assert_eq!(got.len(), want.len(), "count {k}");
            for (p, w) in &want {
                assert_eq!(got[p].to_bits(), w.to_bits(), "count {k}, block {p:?}");
            }
        }
    }
    // Only the counted triplets are checked: a bad one past the count is never read.
    let bad_rows = arr(&[0, 1, 99], dev);
    let a = Bsr::from_triplets_n(
        2,
        2,
        &bad_rows,
        &arr(&[0, 1, 0], dev),
        &arr(&[1.0f64; 3], dev),
        2,
    )
    .unwrap();
    assert_eq!(a.nnz().unwrap(), 2);
    let e = Bsr::from_triplets_n(2, 2, &ra, &ca, &va, 901)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("sparse::from_triplets") && e.contains("count 901"),
        "{e}"
    );
    // A device count out of range: the fault is the report step's (the sort and scan raise
    // the same kind for the same count, so the kernel tells them apart), and every step and
    // primitive treats the count as 0. The CPU stops at the fault; a GPU (out of debug mode,
    // which would report it at the launch) queues the rest, and the matrix is empty.
    let count = arr(&[901], dev);
    let was = wp::config::debug();
    wp::config::set_debug(false);
    let res = Bsr::from_triplets_n(20, 30, &ra, &ca, &va, &count);
    wp::config::set_debug(was);
    let (e, matrix) = match res {
        Err(e) => (e, None),
        Ok(a) => (a.nnz().unwrap_err(), Some(a)),
    };
    assert_eq!(dev.is_cpu(), matrix.is_none(), "{e}");
    match e {
        wp::Error::Fault(f) => {
            assert_eq!(f.kernel, "sparse::from_triplets");
            assert_eq!(
                f.kind,
                FaultKind::OutOfBounds {
                    arg: "count",
                    index: vec![901],
                    shape: vec![901]
                }
            );
        }
        e => panic!("{e}"),
    }
    if let Some(a) = matrix {
        assert_eq!(host(a.offsets()), [0; 21], "no triplet assembled");
        assert_eq!(a.nnz().unwrap(), 0);
    }
}

/// The structure arrays are handles anyone may write: overwritten offsets or columns never
/// make `mv` or the Jacobi set-up read outside the arrays, and the result is what the
/// documented clamps give (a host reference): `nnz = offsets[nrow]` clamped into
/// `0..=capacity`, row `r`'s blocks `offsets[r]..offsets[r + 1]` each clamped into `0..=nnz`
/// (the end at least the start), blocks with a column out of range skipped; the same on every
/// device.
fn mv_survives_overwritten_structure(dev: &wp::Device) {
    /// `A x` under the clamps, in f64 (exact here: small integers).
    fn reference(off: &[i32], cols: &[i32], vals: &[f64], x: &[f64]) -> Vec<f64> {
        let (nrow, ncol, cap) = (off.len() - 1, x.len() as i32, cols.len() as i32);
        let nnz = off[nrow].clamp(0, cap) as usize;
        (0..nrow)
            .map(|r| {
                let lo = (off[r].max(0) as usize).min(nnz);
                let hi = (off[r + 1].max(0) as usize).clamp(lo, nnz);
                (lo..hi)
                    .filter(|&k| (0..ncol).contains(&cols[k]))
                    .map(|k| vals[k] * x[cols[k] as usize])
                    .sum()
            })
            .collect()
    }
    /// The first block row whose clamped range holds no diagonal block (Jacobi's singular
    /// row: the Poisson diagonal is 4 wherever it is present).
    fn first_without_diagonal(off: &[i32], cols: &[i32]) -> Option<usize> {
        let (nrow, cap) = (off.len() - 1, cols.len() as i32);
        let nnz = off[nrow].clamp(0, cap) as usize;
        (0..nrow).find(|&r| {
            let lo = (off[r].max(0) as usize).min(nnz);
            let hi = (off[r + 1].max(0) as usize).clamp(lo, nnz);
            !(lo..hi).any(|k| cols[k] == r as i32)
        })
    }
    let run = |d: &wp::Device| {
        let (r, c, v) = poisson(4);
        let a = Bsr::from_triplets(16, 16, &arr(&r, d), &arr(&c, d), &arr(&v, d)).unwrap();
        // 80 triplets, 64 blocks: the capacity is above the block count.
        assert_eq!((a.nnz_bound(), a.nnz().unwrap()), (80, 64));
        let xs: Vec<f64> = (0..16).map(|i| (i % 5) as f64 - 2.0).collect();
        let x = arr(&xs, d);
        let y = arr(&[0.0f64; 16], d);
        let off0 = host(a.offsets());
        let vals = host(a.values());
        let mut out = vec![];
        // 1. A few columns out of range (negative, ncol, far off) among valid blocks: those
        // blocks alone are skipped.
        let cols0 = host(a.columns());
        let mut cols = cols0.clone();
        for (k, bad) in [(5, -1), (20, 16), (33, 1000), (63, i32::MIN)] {
            cols[k] = bad;
        }
        a.columns().copy_from(&arr(&cols, d)).unwrap();
        sparse::mv(1.0, &a, &x, 0.0, &y).unwrap();
        assert_eq!(host(&y), reference(&off0, &cols, &vals, &xs), "bad columns");
        out.push(host(&y));
        // 2. The columns valid again; offsets[nrow] above the capacity (clamped to it: the
        // last row reaches the unused tail of the arrays), a negative offset, a decreasing
        // pair, one past the block count but below the capacity.
        a.columns().copy_from(&arr(&cols0, d)).unwrap();
        let mut off = off0.clone();
        off[16] = 1_000_000;
        off[3] = -5;
        off[7] = off[6] - 3;
        off[12] = 70;
        a.offsets().copy_from(&arr(&off, d)).unwrap();
        // nnz() clamps as the steps do (a count that indexes the arrays); a negative count
        // reads as 0.
        assert_eq!(a.nnz().unwrap(), 80);
        sparse::mv(1.0, &a, &x, 0.0, &y).unwrap();
        let want = reference(&off, &cols0, &vals, &xs);
        assert_eq!(host(&y), want, "bad offsets");
        // Clamped rows that are not empty: row 3 starts at the negative offset (clamped to
        // 0), row 7 at the decreased one, row 15 ends at the capacity (the clamped nnz);
        // and the product differs from the untouched matrix's.
        assert!(
            want[3] != 0.0 && want[7] != 0.0 && want[15] != 0.0,
            "{want:?}"
        );
        assert_ne!(want, reference(&off0, &cols0, &vals, &xs));
        out.push(host(&y));
        // The Jacobi set-up under the same clamps: the first row without a diagonal block.
        let rep = sparse::cg(&a, &x, &y, Precond::Jacobi, &SolveOptions::default()).unwrap();
        let row = first_without_diagonal(&off, &cols0).expect("a row loses its diagonal");
        assert_eq!(rep.stop, Stop::SingularPreconditioner { block_row: row });
        a.offsets().view(16..17).unwrap().fill(-7).unwrap();
        assert_eq!(a.nnz().unwrap(), 0);
        out.iter()
            .map(|y| y.iter().map(|v| v.to_bits()).collect::<Vec<_>>())
            .collect::<Vec<_>>()
    };
    run(dev);
    same_on_cpu(dev, "overwritten structure", run);
}

/// `Mode::Graph` (the set-up and a `capture_while` loop on the device's stop flag, captured
/// and launched once) gives what `Mode::Host` gives, bit for bit: the same stop, iterations,
/// history and x, at any `check_every` (iterations after the stop do nothing). A GPU needs
/// conditional graph nodes for it.
fn cg_graph_mode_matches_host_mode(dev: &wp::Device) {
    let (r, c, v) = poisson(12);
    let n = 144;
    let a = Bsr::from_triplets(n, n, &arr(&r, dev), &arr(&c, dev), &arr(&v, dev)).unwrap();
    let b: Vec<f64> = (0..n).map(|i| ((i % 9) as f64 - 4.0) * 0.3).collect();
    let x0: Vec<f64> = (0..n).map(|i| (i % 4) as f64 * 0.01).collect();
    let solve = |mode: Mode, every: usize, max_iter: usize, pre: Precond| {
        let x = arr(&x0, dev);
        let o = SolveOptions {
            rtol: 1e-9,
            max_iter,
            check_every: every,
            mode,
            ..Default::default()
        };
        let rep = sparse::cg(&a, &arr(&b, dev), &x, pre, &o).unwrap();
        assert_eq!(rep.history.len(), rep.iterations + 1);
        (
            rep.stop,
            rep.iterations,
            rep.history.iter().map(|h| h.to_bits()).collect::<Vec<_>>(),
            host(&x).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        )
    };
    for pre in [Precond::None, Precond::Jacobi] {
        let host_mode = solve(Mode::Host, 10, 1000, pre);
        assert_eq!(host_mode.0, Stop::Converged);
        for every in [1, 7, 64] {
            assert_eq!(
                solve(Mode::Graph, every, 1000, pre),
                host_mode,
                "{pre:?}, every {every}"
            );
        }
        let capped = solve(Mode::Host, 3, 6, pre);
        assert_eq!((capped.0, capped.1), (Stop::MaxIterations, 6));
        assert_eq!(solve(Mode::Graph, 4, 6, pre), capped, "{pre:?}, max_iter 6");
        // A huge check_every is capped at max_iter per pass (not recorded as is: that would
        // record forever), and gives the same result.
        assert_eq!(
            solve(Mode::Graph, usize::MAX, 6, pre),
            capped,
            "{pre:?}, every usize::MAX"
        );
        assert_eq!(
            solve(Mode::Host, usize::MAX, 6, pre),
            capped,
            "{pre:?}, Host"
        );
    }
    // A stop before the first iteration: the captured loop never runs its body.
    let z = arr(&[0.0f64; 144], dev);
    let o = SolveOptions {
        mode: Mode::Graph,
        ..Default::default()
    };
    let rep = sparse::cg(&a, &z, &arr(&[0.0f64; 144], dev), Precond::None, &o).unwrap();
    assert_eq!((rep.stop, rep.iterations), (Stop::Converged, 0));
}

/// Every block type, each with its own kernels (a GPU looks them up by the type's tag: a wrong
/// tag or a missing instantiation in `wp_sparse.h` fails here): `mv` against a host reference
/// and CG with block Jacobi converging, and on a GPU both the same bits as on the CPU.
fn every_block_type_mv_and_cg(dev: &wp::Device) {
    use glam::{DMat2, DMat4, Mat2, Mat4};
    // `SparseScalar` (imported above) has no arithmetic methods to clash with std's: with
    // both in scope, `x.add(y)` is `Add::add`, not an ambiguity (E0034).
    {
        use std::ops::Add;
        assert_eq!(1.5f32.add(2.0), 3.5);
    }
    block_type_case::<f32>(dev);
    block_type_case::<f64>(dev);
    block_type_case::<Mat2>(dev);
    block_type_case::<Mat3>(dev);
    block_type_case::<Mat4>(dev);
    block_type_case::<DMat2>(dev);
    block_type_case::<DMat3>(dev);
    block_type_case::<DMat4>(dev);
}

/// A `B` array from its scalars (`B::ROWS * B::COLS` per block, in `B`'s storage order).
fn blocks_of<B: Block>(scalars: &[f64], d: &wp::Device) -> wp::Array<B> {
    let s: Vec<B::Scalar> = scalars.iter().map(|&v| B::Scalar::from_f64(v)).collect();
    arr(&s, d).reinterpret::<B>().unwrap()
}

/// `mv` of a random non-symmetric 9 x 7 block matrix (duplicates summed) and a CG solve with
/// block Jacobi of the 5 x 5 Poisson matrix Kronecker an SPD K (so SPD), for block type `B`.
fn block_type_case<B: SquareBlock + Copy>(dev: &wp::Device) {
    let name = std::any::type_name::<B>();
    let d = B::ROWS;
    let f32s = std::mem::size_of::<B::Scalar>() == 4;
    // Scalar entry (i, j) of a block in storage order.
    let at = |i: usize, j: usize| if B::COL_MAJOR { j * d + i } else { i * d + j };
    let bits = |v: Vec<B::Scalar>| v.iter().map(|s| s.to_f64().to_bits()).collect::<Vec<_>>();
    let scal = |v: &[f64], dv: &wp::Device| {
        arr(
            &v.iter()
                .map(|&x| B::Scalar::from_f64(x))
                .collect::<Vec<_>>(),
            dv,
        )
    };
    // What the device holds of an f64 value (f32 rounds it).
    let held = |v: f64| B::Scalar::from_f64(v).to_f64();

    // mv: 40 random triplets of 9 x 7 blocks, y = 0.5 A x - 1.5 y.
    let (nrow, ncol) = (9, 7);
    let mut g = Rng(21 + d as u64);
    let t = 40;
    let rows: Vec<i32> = (0..t).map(|_| g.below(nrow) as i32).collect();
    let cols: Vec<i32> = (0..t).map(|_| g.below(ncol) as i32).collect();
    let vals: Vec<f64> = (0..t * d * d).map(|_| held(g.unit())).collect();
    let x: Vec<f64> = (0..ncol * d).map(|_| held(g.unit())).collect();
    let y0: Vec<f64> = (0..nrow * d).map(|_| held(g.unit())).collect();
    let mut want: Vec<f64> = y0.iter().map(|v| -1.5 * v).collect();
    for k in 0..t {
        let (r, c) = (rows[k] as usize, cols[k] as usize);
        for i in 0..d {
            for j in 0..d {
                want[r * d + i] += 0.5 * vals[k * d * d + at(i, j)] * x[c * d + j];
            }
        }
    }
    let mv_run = |dv: &wp::Device| {
        let a = Bsr::from_triplets(
            nrow,
            ncol,
            &arr(&rows, dv),
            &arr(&cols, dv),
            &blocks_of::<B>(&vals, dv),
        )
        .unwrap();
        let y = scal(&y0, dv);
        let (xv, yv) = (
            scal(&x, dv).reinterpret::<B::In>().unwrap(),
            y.reinterpret::<B::Out>().unwrap(),
        );
        let (alpha, beta) = (B::Scalar::from_f64(0.5), B::Scalar::from_f64(-1.5));
        sparse::mv(alpha, &a, &xv, beta, &yv).unwrap();
        host(&y)
    };
    let got = mv_run(dev);
    // Each y entry sums at most ~40 x 4 products of magnitude <= 1 (and 1.5 y): f32 rounding
    // of such sums stays well under 1e-4 absolute (~1e-5 expected), f64's under 1e-12.
    let tol = if f32s { 1e-4 } else { 1e-12 };
    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!(
            (g.to_f64() - w).abs() <= tol,
            "{name} mv, scalar row {k}: {g:?} vs {w}"
        );
    }
    same_on_cpu(dev, &format!("{name} mv"), |dv| bits(mv_run(dv)));

    // CG: block (p, q) is L_pq K, K = (d + 1) I + 0.5 (off the diagonal) + 0.1 (i + j):
    // symmetric and diagonally dominant, so SPD, and so is the Kronecker product.
    let m = 5;
    let (pr, pc, pv) = poisson(m);
    let n = m * m;
    let kk = |i: usize, j: usize| {
        if i == j {
            d as f64 + 1.0
        } else {
            0.5 + 0.1 * (i + j) as f64
        }
    };
    let cg_vals: Vec<f64> = pv
        .iter()
        .flat_map(|&l| {
            let mut b = vec![0.0; d * d];
            for i in 0..d {
                for j in 0..d {
                    b[at(i, j)] = l * kk(i, j);
                }
            }
            b
        })
        .collect();
    let b: Vec<f64> = (0..n * d).map(|i| ((i % 5) as f64 - 2.0) * 0.5).collect();
    // f32: its rounding floor for this small, well-conditioned system is far below 1e-5.
    let rtol = if f32s { 1e-5 } else { 1e-9 };
    let cg_run = |dv: &wp::Device| {
        let a = Bsr::from_triplets(
            n,
            n,
            &arr(&pr, dv),
            &arr(&pc, dv),
            &blocks_of::<B>(&cg_vals, dv),
        )
        .unwrap();
        let xv = scal(&vec![0.0; n * d], dv);
        let o = SolveOptions {
            rtol,
            ..Default::default()
        };
        let rep = sparse::cg(&a, &scal(&b, dv), &xv, Precond::Jacobi, &o).unwrap();
        (rep, host(&xv))
    };
    let (rep, xs) = cg_run(dev);
    assert_eq!(rep.stop, Stop::Converged, "{name}: {rep:?}");
    // The true residual |b - A x| from the triplets in f64: within 2x the tolerance for f32
    // (the recurrence's residual drifts from the true one by rounding), 1.01x for f64.
    let mut ax = vec![0.0; n * d];
    for k in 0..pr.len() {
        let (r, c) = (pr[k] as usize, pc[k] as usize);
        for i in 0..d {
            for j in 0..d {
                ax[r * d + i] += cg_vals[k * d * d + at(i, j)] * xs[c * d + j].to_f64();
            }
        }
    }
    let tr = b
        .iter()
        .zip(&ax)
        .map(|(b, y)| (b - y) * (b - y))
        .sum::<f64>()
        .sqrt();
    let slack = if f32s { 2.0 } else { 1.01 };
    assert!(
        tr <= slack * rep.tolerance,
        "{name}: true residual {tr}, {}",
        rep.tolerance
    );
    same_on_cpu(dev, &format!("{name} cg"), |dv| {
        let (rep, xs) = cg_run(dv);
        (
            rep.iterations,
            rep.history.iter().map(|h| h.to_bits()).collect::<Vec<_>>(),
            bits(xs),
        )
    });
}

// ------------------------------------------------------------------------------------------
// Slice 2: the structure operations (scale, diag, set_diag/identity, dense both ways,
// transpose, axpy, mm), each against a dense f64 reference built here and against its
// documented order of roundings bit for bit; on a GPU also against the CPU's bits.
// ------------------------------------------------------------------------------------------
mod ops {
    use super::*;
    use glam::{DMat2, Mat2, Mat4};
    use warp_runtime::sparse::{BlockMul, MmWork};
    use wp::{
        DMat23, DMat26, DMat32, DMat43, DMat46, DMat63, Mat23, Mat24, Mat26, Mat32, Mat34, Mat43,
        Mat63,
    };

    backend_tests!(
        ops_scale,
        ops_diag,
        ops_set_diag_and_identity,
        ops_dense_round_trip,
        ops_from_dense_bad_input,
        ops_transpose,
        ops_axpy,
        ops_axpy_bad_input,
        ops_mm,
        ops_mm_capacity_and_bad_input,
        ops_rect_mv,
        ops_rect_transpose_dense_axpy,
        ops_rect_mm,
        ops_in_a_capture,
        ops_mv_transpose,
        ops_overwritten_offsets_stay_in_bounds,
    );

    /// The scalars of an array of blocks, in storage order.
    fn scalars<B: Block>(a: &wp::Array<B>) -> Vec<B::Scalar> {
        host(&a.reinterpret::<B::Scalar>().unwrap())
    }

    /// The bits of scalars (f32 widened exactly to f64 first).
    fn bits<S: SparseScalar>(v: &[S]) -> Vec<u64> {
        v.iter().map(|s| s.to_f64().to_bits()).collect()
    }

    /// Scalar entry `(i, j)` of a block stored as `s`.
    fn at<B: Block>(i: usize, j: usize) -> usize {
        if B::COL_MAJOR {
            j * B::ROWS + i
        } else {
            i * B::COLS + j
        }
    }

    /// The matrix as a dense row-major `Vec` of its scalars' f64 values, from its arrays
    /// (the structure checked by `blocks` on the way).
    fn dense_of<B: Block + Copy>(a: &Bsr<B>) -> Vec<f64> {
        blocks(a);
        let (nr, nc) = a.shape();
        let (off, cols, vals) = (host(a.offsets()), host(a.columns()), scalars(a.values()));
        let rc = B::ROWS * B::COLS;
        let mut d = vec![0.0; nr * nc];
        for r in 0..a.nrow() {
            for k in off[r] as usize..off[r + 1] as usize {
                let c = cols[k] as usize;
                for i in 0..B::ROWS {
                    for j in 0..B::COLS {
                        d[(r * B::ROWS + i) * nc + c * B::COLS + j] =
                            vals[k * rc + at::<B>(i, j)].to_f64();
                    }
                }
            }
        }
        d
    }

    /// A random `nrow x ncol` matrix of `B` (duplicates summed) from `count` triplets.
    fn random<B: Block>(
        dev: &wp::Device,
        nrow: usize,
        ncol: usize,
        count: usize,
        seed: u64,
    ) -> Bsr<B> {
        let rc = B::ROWS * B::COLS;
        let (r, c, v) = random_triplets(nrow, ncol, count, seed, |g| {
            (0..rc).map(|_| g.unit()).collect::<Vec<f64>>()
        });
        let flat: Vec<f64> = v.concat();
        Bsr::from_triplets(
            nrow,
            ncol,
            &arr(&r, dev),
            &arr(&c, dev),
            &blocks_of::<B>(&flat, dev),
        )
        .unwrap()
    }

    fn scale_case<B: Block + Copy>(dev: &wp::Device, seed: u64) -> Vec<u64> {
        let mut a = random::<B>(dev, 13, 9, 60, seed);
        let before = scalars(a.values());
        let alpha = B::Scalar::from_f64(-0.37);
        a.scale(alpha).unwrap();
        let after = scalars(a.values());
        let nnz = a.nnz().unwrap() * B::ROWS * B::COLS;
        // Each stored scalar is `alpha * v` rounded once: the test's own product, bit for bit
        // (Rust never contracts); the slack past nnz is untouched.
        for k in 0..before.len() {
            let want = if k < nnz {
                alpha.to_f64() * before[k].to_f64()
            } else {
                before[k].to_f64()
            };
            let want = B::Scalar::from_f64(want);
            assert_eq!(
                after[k].to_f64().to_bits(),
                want.to_f64().to_bits(),
                "scalar {k}"
            );
        }
        bits(&after)
    }

    fn ops_scale(dev: &wp::Device) {
        scale_case::<f32>(dev, 1);
        scale_case::<Mat3>(dev, 2);
        scale_case::<DMat3>(dev, 3);
        same_on_cpu(dev, "scale", |d| scale_case::<Mat2>(d, 4));
        // A non-finite alpha is an error naming it; the matrix is unchanged.
        let mut a = random::<f64>(dev, 3, 3, 5, 5);
        let before = host(a.values());
        let e = a.scale(f64::NAN).unwrap_err();
        assert!(
            matches!(e, wp::Error::InvalidArgument { .. })
                && e.to_string().contains("sparse::scale")
                && e.to_string().contains("`alpha` is NaN"),
            "{e}"
        );
        assert_eq!(host(a.values()), before);
        // An empty matrix scales to itself.
        let mut z = Bsr::<Mat3>::zeros(4, 2, dev).unwrap();
        z.scale(2.0).unwrap();
        assert_eq!(z.nnz().unwrap(), 0);
    }

    fn diag_case<B: SquareBlock + Copy>(dev: &wp::Device, nrow: usize, ncol: usize) -> Vec<u64> {
        let n = nrow.min(ncol);
        // Random blocks, and every third diagonal block for sure.
        let rc = B::ROWS * B::COLS;
        let (mut r, mut c, v) = random_triplets(nrow, ncol, 3 * nrow, 7, |g| {
            (0..rc).map(|_| g.unit()).collect::<Vec<f64>>()
        });
        let mut flat = v.concat();
        for i in (0..n).step_by(3) {
            r.push(i as i32);
            c.push(i as i32);
            flat.extend((0..rc).map(|e| (i * rc + e) as f64 * 0.25 + 1.0));
        }
        let a = Bsr::from_triplets(
            nrow,
            ncol,
            &arr(&r, dev),
            &arr(&c, dev),
            &blocks_of::<B>(&flat, dev),
        )
        .unwrap();
        let out = wp::Array::<B>::zeros(n, dev).unwrap();
        sparse::diag(&a, &out).unwrap();
        let got = scalars(&out);
        let d = dense_of(&a);
        let w = ncol * B::COLS;
        let rc = B::ROWS * B::COLS;
        let mut missing = 0;
        for b in 0..n {
            let stored = blocks(&a).contains_key(&(b as i32, b as i32));
            missing += !stored as usize;
            for i in 0..B::ROWS {
                for j in 0..B::COLS {
                    // Copied unchanged (zero where no block is stored): exact.
                    let want = d[(b * B::ROWS + i) * w + b * B::COLS + j];
                    assert_eq!(
                        got[b * rc + at::<B>(i, j)].to_f64(),
                        want,
                        "block {b} ({i}, {j})"
                    );
                }
            }
        }
        // The case has both stored and missing diagonal blocks.
        assert!(missing > 0 && missing < n, "missing {missing} of {n}");
        bits(&got)
    }

    fn ops_diag(dev: &wp::Device) {
        diag_case::<f32>(dev, 30, 20);
        diag_case::<Mat3>(dev, 12, 15);
        same_on_cpu(dev, "diag", |d| diag_case::<DMat2>(d, 16, 16));
        // Bad input: the length, an overlap with the matrix, a device.
        let a = random::<f32>(dev, 4, 6, 12, 8);
        let e = sparse::diag(&a, &wp::Array::<f32>::zeros(5, dev).unwrap())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sparse::diag")
                && e.contains("`out` has shape [5] of f32")
                && e.contains("4 x 6 blocks of 1 x 1")
                && e.contains("needs 4 elements"),
            "{e}"
        );
        let e = sparse::diag(&a, &a.values().view(0..4).unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("`out` overlaps the matrix"), "{e}");
        if !dev.is_cpu() {
            let e = sparse::diag(&a, &wp::Array::<f32>::zeros(4, &wp::cpu()).unwrap()).unwrap_err();
            assert!(matches!(e, wp::Error::DeviceMismatch { .. }), "{e}");
        }
    }

    fn ops_set_diag_and_identity(dev: &wp::Device) {
        // The identity of Mat3 and DMat2 blocks: its dense matrix is the identity.
        let i3 = Bsr::<Mat3>::identity(5, dev).unwrap();
        let d = dense_of(&i3);
        for r in 0..15 {
            for c in 0..15 {
                assert_eq!(d[r * 15 + c], (r == c) as i32 as f64, "({r}, {c})");
            }
        }
        assert_eq!(i3.nnz().unwrap(), 5);
        // set_diag of a non-square (block) matrix: min(nrow, ncol) blocks, the structure
        // replaced, the dimensions kept; d may be the matrix's own diagonal.
        let mut a = random::<DMat2>(dev, 7, 4, 30, 9);
        let old = a.clone();
        let dg = wp::Array::<DMat2>::zeros(4, dev).unwrap();
        sparse::diag(&a, &dg).unwrap();
        sparse::set_diag(&mut a, &dg).unwrap();
        assert_eq!((a.nrow(), a.ncol(), a.nnz().unwrap()), (7, 4, 4));
        let (d, od) = (dense_of(&a), dense_of(&old));
        for r in 0..14 {
            for c in 0..8 {
                let want = if r / 2 == c / 2 { od[r * 8 + c] } else { 0.0 };
                assert_eq!(d[r * 8 + c].to_bits(), want.to_bits(), "({r}, {c})");
            }
        }
        // The old matrix's clone keeps its own arrays.
        assert_eq!(dense_of(&old), od);
        // from_diag's bad length names both.
        let e = Bsr::<f32>::from_diag(3, 5, &arr(&[1.0f32; 4], dev))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sparse::from_diag") && e.contains("[4] of f32") && e.contains("3 diagonal"),
            "{e}"
        );
        let e = sparse::set_diag(&mut a, &wp::Array::<DMat2>::zeros(3, dev).unwrap())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sparse::set_diag") && e.contains("has 4 diagonal"),
            "{e}"
        );
        same_on_cpu(dev, "from_diag", |d| {
            let v: Vec<f64> = (0..8 * 4).map(|i| i as f64 * 0.5 - 3.0).collect();
            let m = Bsr::<DMat2>::from_diag(8, 9, &blocks_of::<DMat2>(&v, d)).unwrap();
            (
                host(m.offsets()),
                host(m.columns()),
                bits(&scalars(m.values())),
            )
        });
    }

    fn dense_case<B: Block + Copy>(
        dev: &wp::Device,
        nrow: usize,
        ncol: usize,
        seed: u64,
    ) -> Vec<u64> {
        // Triplets that cancel make a stored block of zeros (kept by from_triplets, dropped by
        // from_dense).
        let rc = B::ROWS * B::COLS;
        let (r0, c0, v0) = random_triplets(nrow, ncol, 2 * nrow, seed, |g| {
            (0..rc).map(|_| g.unit()).collect::<Vec<f64>>()
        });
        // None of the random triplets at the cancelling pair's block (0, ncol - 1), which
        // must end up exactly zero (seed 75 put one there for DMat26 in 4 x 3 blocks).
        let keep: Vec<usize> = (0..r0.len())
            .filter(|&t| (r0[t], c0[t]) != (0, ncol as i32 - 1))
            .collect();
        let mut r: Vec<i32> = keep.iter().map(|&t| r0[t]).collect();
        let mut c: Vec<i32> = keep.iter().map(|&t| c0[t]).collect();
        let mut flat: Vec<f64> = keep.iter().flat_map(|&t| v0[t].clone()).collect();
        r.extend([0, 0]);
        c.extend([(ncol - 1) as i32, (ncol - 1) as i32]);
        flat.extend((0..rc).map(|e| e as f64 + 0.5));
        flat.extend((0..rc).map(|e| -(e as f64 + 0.5)));
        let a = Bsr::from_triplets(
            nrow,
            ncol,
            &arr(&r, dev),
            &arr(&c, dev),
            &blocks_of::<B>(&flat, dev),
        )
        .unwrap();
        let (nr, nc) = a.shape();
        let out = wp::Array::<B::Scalar, 2>::zeros([nr, nc], dev).unwrap();
        out.fill(B::Scalar::from_f64(7.0)).unwrap(); // overwritten: every entry
        a.to_dense(&out).unwrap();
        let got = host(&out);
        let want = dense_of(&a);
        assert_eq!(
            got.iter().map(|v| v.to_f64().to_bits()).collect::<Vec<_>>(),
            want.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            "to_dense"
        );
        // Back: the same blocks except the zero one.
        let b = Bsr::<B>::from_dense(&out).unwrap();
        assert_eq!((b.nrow(), b.ncol()), (nrow, ncol));
        assert_eq!(b.nnz().unwrap() + 1, a.nnz().unwrap());
        assert!(!blocks(&b).contains_key(&(0, ncol as i32 - 1)));
        assert_eq!(dense_of(&b), want);
        let mut all = bits(&got);
        all.extend(host(b.offsets()).iter().map(|&o| o as u64));
        all
    }

    fn ops_dense_round_trip(dev: &wp::Device) {
        // Mat3 and DMat2 (column-major: the dense layout is row-major whatever the block's),
        // scalars, non-square dims.
        dense_case::<Mat3>(dev, 5, 7, 11);
        dense_case::<f64>(dev, 20, 3, 12);
        same_on_cpu(dev, "dense", |d| dense_case::<DMat2>(d, 6, 4, 13));
        // An empty shape.
        let e = wp::Array::<f32, 2>::zeros([0, 4], dev).unwrap();
        let b = Bsr::<f32>::from_dense(&e).unwrap();
        assert_eq!((b.nrow(), b.ncol(), b.nnz().unwrap()), (0, 4, 0));
        // to_dense's bad shape names both.
        let a = random::<Mat3>(dev, 2, 3, 4, 14);
        let e = a
            .to_dense(&wp::Array::<f32, 2>::zeros([6, 8], dev).unwrap())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sparse::to_dense")
                && e.contains("`out` has shape [6, 8]")
                && e.contains("2 x 3 blocks of 3 x 3 (6 x 9 scalars)")
                && e.contains("needs shape [6, 9]"),
            "{e}"
        );
    }

    fn ops_from_dense_bad_input(dev: &wp::Device) {
        // Not a whole number of blocks.
        let a = wp::Array::<f32, 2>::zeros([6, 8], dev).unwrap();
        let e = Bsr::<Mat3>::from_dense(&a).unwrap_err().to_string();
        assert!(
            e.contains("sparse::from_dense") && e.contains("[6, 8]") && e.contains("3 x 3 blocks"),
            "{e}"
        );
        // Non-finite scalars: the first in row-major order (row 1, column 5: index 1 * 6 + 5)
        // although a NaN sits in an earlier block (block (0, 0), row 2).
        let mut v = vec![1.0f64; 4 * 6];
        v[6 + 5] = f64::INFINITY;
        v[2 * 6] = f64::NAN;
        let a = arr(&v, dev).reshape([4, 6]).unwrap();
        let r = Bsr::<DMat2>::from_dense(&a).and_then(|m| m.nnz());
        match r {
            Err(wp::Error::Fault(f)) => {
                assert_eq!(f.kernel, "sparse::from_dense");
                assert_eq!(
                    f.kind,
                    FaultKind::NonFiniteInput {
                        arg: "a",
                        index: 11,
                        values: vec![f64::INFINITY]
                    }
                );
            }
            other => panic!("expected a fault, got {other:?}"),
        }
    }

    /// The transpose against the dense one (exact: values are copied), with the structure
    /// checked (offsets, ascending columns).
    fn transpose_case<B: Block + Copy>(
        dev: &wp::Device,
        nrow: usize,
        ncol: usize,
        seed: u64,
    ) -> Vec<u64>
    where
        B::Transpose: Copy,
    {
        let a = random::<B>(dev, nrow, ncol, 4 * nrow, seed);
        let t = a.transpose().unwrap();
        assert_eq!((t.nrow(), t.ncol()), (ncol, nrow));
        assert_eq!(t.nnz().unwrap(), a.nnz().unwrap());
        let (d, dt) = (dense_of(&a), dense_of(&t));
        let (nr, nc) = a.shape();
        for i in 0..nr {
            for j in 0..nc {
                assert_eq!(
                    dt[j * nr + i].to_bits(),
                    d[i * nc + j].to_bits(),
                    "({i}, {j})"
                );
            }
        }
        // Twice is the matrix, bit for bit (same structure, same blocks).
        let tt = t.transpose().unwrap();
        let n = a.nnz().unwrap();
        assert_eq!(host(tt.offsets()), host(a.offsets()));
        assert_eq!(host(tt.columns())[..n], host(a.columns())[..n]);
        let mut out = bits(&scalars(t.values()));
        out.extend(host(t.offsets()).iter().map(|&o| o as u64));
        out.extend(host(t.columns()).iter().map(|&o| o as u64));
        out
    }

    fn ops_transpose(dev: &wp::Device) {
        transpose_case::<f32>(dev, 100, 60, 21);
        transpose_case::<Mat3>(dev, 9, 14, 22);
        transpose_case::<DMat2>(dev, 17, 5, 23);
        same_on_cpu(dev, "transpose", |d| transpose_case::<Mat4>(d, 11, 13, 24));
        // Empty matrices: no block, and no block row.
        let z = Bsr::<Mat2>::zeros(3, 5, dev).unwrap().transpose().unwrap();
        assert_eq!((z.nrow(), z.ncol(), z.nnz().unwrap()), (5, 3, 0));
        let z = Bsr::<f64>::zeros(0, 5, dev).unwrap().transpose().unwrap();
        assert_eq!((z.nrow(), z.ncol(), host(z.offsets())), (5, 0, vec![0; 6]));
    }

    /// axpy against the dense `alpha X + beta Y` (f64, with a tolerance) and against its
    /// documented rounding bit for bit: `alpha * x` and `beta * y` each rounded, then their
    /// rounded sum where both have the block.
    fn axpy_case<B: Block + Copy>(dev: &wp::Device, seed: u64) -> Vec<u64> {
        let (nrow, ncol) = (11, 8);
        let x = random::<B>(dev, nrow, ncol, 25, seed);
        let mut y = random::<B>(dev, nrow, ncol, 25, seed + 100);
        let (dx, dy) = (dense_of(&x), dense_of(&y));
        let (alpha, beta) = (B::Scalar::from_f64(0.75), B::Scalar::from_f64(-1.5));
        let (px, py) = (blocks(&x), blocks(&y));
        sparse::axpy(alpha, &x, beta, &mut y).unwrap();
        let got = dense_of(&y);
        // The union structure.
        let mut keys: Vec<_> = px.keys().chain(py.keys()).copied().collect();
        keys.sort();
        keys.dedup();
        assert_eq!(blocks(&y).keys().copied().collect::<Vec<_>>(), keys);
        let s = |v: f64| B::Scalar::from_f64(v);
        for k in 0..got.len() {
            let (a, b) = (dx[k], dy[k]);
            // f32: two products and a sum of magnitudes <= 3, each rounded: 2e-6 absolute.
            let tol = if std::mem::size_of::<B::Scalar>() == 4 {
                2e-6
            } else {
                1e-14
            };
            let exact = alpha.to_f64() * a + beta.to_f64() * b;
            assert!(
                (got[k] - exact).abs() <= tol,
                "scalar {k}: {} vs {exact}",
                got[k]
            );
        }
        for (&(r, c), _) in blocks(&y).iter() {
            for i in 0..B::ROWS {
                for j in 0..B::COLS {
                    let k = (r as usize * B::ROWS + i) * ncol * B::COLS + c as usize * B::COLS + j;
                    // (An f32 product or sum computed in f64, then rounded to f32, is the
                    // correctly rounded f32 one: f64 has more than 2 x 24 + 2 bits.)
                    let ax = px.contains_key(&(r, c)).then(|| s(alpha.to_f64() * dx[k]));
                    let by = py.contains_key(&(r, c)).then(|| s(beta.to_f64() * dy[k]));
                    let want = match (ax, by) {
                        (Some(p), Some(q)) => s(p.to_f64() + q.to_f64()),
                        (Some(p), None) | (None, Some(p)) => p,
                        (None, None) => unreachable!(),
                    };
                    assert_eq!(
                        got[k].to_bits(),
                        want.to_f64().to_bits(),
                        "({r}, {c}) ({i}, {j})"
                    );
                }
            }
        }
        bits(&scalars(y.values()))
    }

    fn ops_axpy(dev: &wp::Device) {
        axpy_case::<f32>(dev, 31);
        axpy_case::<Mat3>(dev, 32);
        axpy_case::<DMat3>(dev, 33);
        same_on_cpu(dev, "axpy", |d| axpy_case::<Mat2>(d, 34));
        // x and y the same matrix (a clone): y = (alpha + beta) y's values, structure kept.
        let x = random::<f64>(dev, 6, 6, 12, 35);
        let mut y = x.clone();
        sparse::axpy(2.0, &x, 3.0, &mut y).unwrap();
        let (dx, dy) = (dense_of(&x), dense_of(&y));
        for k in 0..dx.len() {
            assert_eq!(dy[k], 2.0 * dx[k] + 3.0 * dx[k], "{k}");
        }
        assert_eq!(y.nnz().unwrap(), x.nnz().unwrap());
    }

    fn ops_axpy_bad_input(dev: &wp::Device) {
        let x = random::<Mat3>(dev, 4, 5, 6, 36);
        let mut y = random::<Mat3>(dev, 5, 4, 6, 37);
        let e = sparse::axpy(1.0, &x, 1.0, &mut y).unwrap_err().to_string();
        assert!(
            e.contains("sparse::axpy")
                && e.contains("`x` is 4 x 5 blocks of 3 x 3 (12 x 15 scalars)")
                && e.contains("`y` is 5 x 4 blocks of 3 x 3 (15 x 12 scalars)"),
            "{e}"
        );
        let mut y = random::<Mat3>(dev, 4, 5, 6, 38);
        let e = sparse::axpy(1.0, &x, f32::INFINITY, &mut y)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sparse::axpy") && e.contains("`beta` is inf"),
            "{e}"
        );
        if !dev.is_cpu() {
            let xc = random::<Mat3>(&wp::cpu(), 4, 5, 6, 36);
            let e = sparse::axpy(1.0, &xc, 1.0, &mut y).unwrap_err();
            assert!(matches!(e, wp::Error::DeviceMismatch { .. }), "{e}");
        }
    }

    /// `alpha A B + beta C` against the dense product (f64, with a tolerance), and against
    /// the documented order bit for bit for scalar blocks: per position, the products
    /// `alpha (0 + a b)` in the order of A's blocks then B's, summed left to right, then `+
    /// beta c`.
    fn mm_case<B: BlockMul<B, Output = B> + Copy>(
        dev: &wp::Device,
        beta: f64,
        seed: u64,
    ) -> Vec<u64> {
        let (m, k, n) = (9, 7, 10);
        let a = random::<B>(dev, m, k, 30, seed);
        let b = random::<B>(dev, k, n, 30, seed + 1);
        let mut c = random::<B>(dev, m, n, 20, seed + 2);
        let (da, db, dc) = (dense_of(&a), dense_of(&b), dense_of(&c));
        let alpha = B::Scalar::from_f64(-1.25);
        let mut work = MmWork::new();
        sparse::mm(alpha, &a, &b, B::Scalar::from_f64(beta), &mut c, &mut work).unwrap();
        let got = dense_of(&c);
        let (rows, inner, cols) = (m * B::ROWS, k * B::COLS, n * B::COLS);
        let f32s = std::mem::size_of::<B::Scalar>() == 4;
        for i in 0..rows {
            for j in 0..cols {
                let mut want = beta * dc[i * cols + j];
                let mut mag = (beta * dc[i * cols + j]).abs();
                for q in 0..inner {
                    want += -1.25 * da[i * inner + q] * db[q * cols + j];
                    mag += (1.25 * da[i * inner + q] * db[q * cols + j]).abs();
                }
                // Each term through at most ~30 roundings (products of <= 4 terms, sums of the
                // row's products): 30 u times the sum of the magnitudes.
                let u = if f32s { 2f64.powi(-24) } else { 2f64.powi(-53) };
                let g = got[i * cols + j];
                assert!(
                    (g - want).abs() <= 30.0 * u * mag.max(1e-300),
                    "({i}, {j}): {g} vs {want}"
                );
            }
        }
        bits(&scalars(c.values()))
    }

    /// The documented order for f64 scalar blocks, as a map (row, col) -> value.
    fn mm_documented(
        a: &Bsr<f64>,
        b: &Bsr<f64>,
        alpha: f64,
        beta: f64,
        c: &Bsr<f64>,
    ) -> std::collections::BTreeMap<(i32, i32), f64> {
        let (ao, ac, av) = (host(a.offsets()), host(a.columns()), host(a.values()));
        let (bo, bc, bv) = (host(b.offsets()), host(b.columns()), host(b.values()));
        let mut out = std::collections::BTreeMap::new();
        for r in 0..a.nrow() {
            for k in ao[r] as usize..ao[r + 1] as usize {
                let q = ac[k] as usize;
                for l in bo[q] as usize..bo[q + 1] as usize {
                    let p = alpha * (0.0 + av[k] * bv[l]);
                    out.entry((r as i32, bc[l]))
                        .and_modify(|s: &mut f64| *s += p)
                        .or_insert(p);
                }
            }
        }
        if beta != 0.0 {
            for (&(r, cc), &v) in blocks(c).iter() {
                out.entry((r, cc))
                    .and_modify(|s| *s += beta * v)
                    .or_insert(beta * v);
            }
        }
        out
    }

    fn ops_mm(dev: &wp::Device) {
        mm_case::<f32>(dev, 0.0, 41);
        mm_case::<Mat3>(dev, 0.5, 42);
        mm_case::<DMat3>(dev, -2.0, 43);
        same_on_cpu(dev, "mm Mat3", |d| mm_case::<Mat3>(d, 0.5, 44));
        same_on_cpu(dev, "mm DMat2", |d| mm_case::<DMat2>(d, 0.0, 45));
        // The documented order, bit for bit (f64 scalars with duplicates: many products per
        // position), with and without C; a reused, growing MmWork.
        let mut work = MmWork::new();
        for (beta, seed) in [(0.0, 46), (0.3, 47), (1.0, 48)] {
            let a = random::<f64>(dev, 20, 15, 120, seed);
            let b = random::<f64>(dev, 15, 25, 150, seed + 1);
            let c0 = random::<f64>(dev, 20, 25, 50, seed + 2);
            let want = mm_documented(&a, &b, 0.7, beta, &c0);
            let mut c = c0.clone();
            sparse::mm(0.7, &a, &b, beta, &mut c, &mut work).unwrap();
            let got = blocks(&c);
            assert_eq!(
                got.keys().collect::<Vec<_>>(),
                want.keys().collect::<Vec<_>>()
            );
            for (k, w) in &want {
                assert_eq!(got[k].to_bits(), w.to_bits(), "beta {beta}: {k:?}");
            }
        }
        // An empty factor: an empty product.
        let a = random::<Mat3>(dev, 4, 3, 6, 49);
        let z = Bsr::<Mat3>::zeros(3, 5, dev).unwrap();
        let mut c = Bsr::<Mat3>::zeros(4, 5, dev).unwrap();
        sparse::mm(1.0, &a, &z, 0.0, &mut c, &mut MmWork::new()).unwrap();
        assert_eq!(c.nnz().unwrap(), 0);
    }

    fn ops_mm_capacity_and_bad_input(dev: &wp::Device) {
        let a = random::<f32>(dev, 8, 6, 30, 51);
        let b = random::<f32>(dev, 6, 9, 30, 52);
        // The product count, by hand.
        let (ao, ac) = (host(a.offsets()), host(a.columns()));
        let bo = host(b.offsets());
        let products: i32 = (0..ao[8] as usize)
            .map(|k| bo[ac[k] as usize + 1] - bo[ac[k] as usize])
            .sum();
        // Room enough: the same result as a growing work's.
        let mut c1 = Bsr::<f32>::zeros(8, 9, dev).unwrap();
        let mut c2 = c1.clone();
        sparse::mm(1.0, &a, &b, 0.0, &mut c1, &mut MmWork::new()).unwrap();
        sparse::mm(
            1.0,
            &a,
            &b,
            0.0,
            &mut c2,
            &mut MmWork::with_capacity(products as usize),
        )
        .unwrap();
        assert_eq!(dense_of(&c1), dense_of(&c2));
        // One product too many: a fault of sparse::mm on `products`, and C empty.
        let mut c3 = Bsr::<f32>::zeros(8, 9, dev).unwrap();
        let cap = products as usize - 1;
        let r = sparse::mm(1.0, &a, &b, 0.0, &mut c3, &mut MmWork::with_capacity(cap))
            .and_then(|()| c3.nnz());
        match r {
            Err(wp::Error::Fault(f)) => {
                assert_eq!(f.kernel, "sparse::mm");
                assert_eq!(
                    f.kind,
                    FaultKind::OutOfBounds {
                        arg: "products",
                        index: vec![products as i128],
                        shape: vec![cap + 1]
                    }
                );
            }
            other => panic!("expected a fault, got {other:?}"),
        }
        if !dev.is_cpu() {
            // A GPU ran the steps after the fault: the product is empty (the count read as 0).
            assert_eq!(c3.nnz().unwrap(), 0);
        }
        // With beta != 0, C's blocks join the products: the capacity counts the products
        // alone, C's room comes from its bound (the same result as a growing work's).
        let (mut c4, mut c5) = (c1.clone(), c1.clone());
        sparse::mm(1.0, &a, &b, 0.5, &mut c4, &mut MmWork::new()).unwrap();
        let mut exact = MmWork::with_capacity(products as usize);
        sparse::mm(1.0, &a, &b, 0.5, &mut c5, &mut exact).unwrap();
        assert_eq!(dense_of(&c4), dense_of(&c5));
        // Dimension mismatches name the shapes.
        let mut c = Bsr::<f32>::zeros(8, 9, dev).unwrap();
        let e = sparse::mm(1.0, &a, &a, 0.0, &mut c, &mut MmWork::new())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sparse::mm")
                && e.contains("`a`'s 6 block columns must equal `b`'s 8 block rows"),
            "{e}"
        );
        let mut c = Bsr::<f32>::zeros(9, 8, dev).unwrap();
        let e = sparse::mm(1.0, &a, &b, 0.0, &mut c, &mut MmWork::new())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`c` is 9 x 8 blocks of 1 x 1") && e.contains("has 8 x 9 blocks"),
            "{e}"
        );
        let mut c = Bsr::<f32>::zeros(8, 9, dev).unwrap();
        let e = sparse::mm(f32::NAN, &a, &b, 0.0, &mut c, &mut MmWork::new())
            .unwrap_err()
            .to_string();
        assert!(e.contains("`alpha` is NaN"), "{e}");
    }

    // --------------------------------------------------------------------------------------
    // Rectangular blocks (warp-core's row-major Mat23 .. Mat64)
    // --------------------------------------------------------------------------------------

    /// `mv` of a random matrix of `B` against the dense f64 product, and its documented
    /// order bit for bit: each row scalar's sum from 0 over the row's blocks in storage order
    /// and ascending columns in a block, then `alpha acc + beta y`.
    fn rect_mv_case<B: Block + Copy>(dev: &wp::Device, seed: u64) -> Vec<u64> {
        let (nrow, ncol) = (13, 8);
        let a = random::<B>(dev, nrow, ncol, 50, seed);
        let mut g = Rng(seed + 1);
        let xs: Vec<f64> = (0..ncol * B::COLS).map(|_| g.unit()).collect();
        let ys: Vec<f64> = (0..nrow * B::ROWS).map(|_| g.unit()).collect();
        let sc = |v: &[f64]| {
            v.iter()
                .map(|&x| B::Scalar::from_f64(x))
                .collect::<Vec<_>>()
        };
        let (xs, ys) = (sc(&xs), sc(&ys));
        let x = arr(&xs, dev).reinterpret::<B::In>().unwrap();
        let y = arr(&ys, dev).reinterpret::<B::Out>().unwrap();
        let (alpha, beta) = (B::Scalar::from_f64(0.5), B::Scalar::from_f64(-2.0));
        sparse::mv(alpha, &a, &x, beta, &y).unwrap();
        let got = host(&y.reinterpret::<B::Scalar>().unwrap());
        let d = dense_of(&a);
        let w = ncol * B::COLS;
        let f32s = std::mem::size_of::<B::Scalar>() == 4;
        let (off, cols, vals) = (host(a.offsets()), host(a.columns()), scalars(a.values()));
        let rc = B::ROWS * B::COLS;
        for i in 0..nrow * B::ROWS {
            let mut want = -2.0 * ys[i].to_f64();
            for j in 0..w {
                want += 0.5 * d[i * w + j] * xs[j].to_f64();
            }
            // f32: at most ~40 rounded products and sums of magnitude <= 10: 1e-5 absolute.
            let tol = if f32s { 1e-5 } else { 1e-13 };
            assert!(
                (got[i].to_f64() - want).abs() <= tol,
                "row {i}: {:?} vs {want}",
                got[i]
            );
            // The documented order.
            let (r, p) = (i / B::ROWS, i % B::ROWS);
            let mut acc = B::Scalar::ZERO;
            for k in off[r] as usize..off[r + 1] as usize {
                for q in 0..B::COLS {
                    let prod = B::Scalar::from_f64(
                        vals[k * rc + at::<B>(p, q)].to_f64()
                            * xs[cols[k] as usize * B::COLS + q].to_f64(),
                    );
                    acc = B::Scalar::from_f64(acc.to_f64() + prod.to_f64());
                }
            }
            let want = B::Scalar::from_f64(
                B::Scalar::from_f64(0.5 * acc.to_f64()).to_f64()
                    + B::Scalar::from_f64(-2.0 * ys[i].to_f64()).to_f64(),
            );
            assert_eq!(
                got[i].to_f64().to_bits(),
                want.to_f64().to_bits(),
                "row {i}"
            );
        }
        bits(&got)
    }

    fn ops_rect_mv(dev: &wp::Device) {
        rect_mv_case::<Mat23>(dev, 61);
        rect_mv_case::<Mat63>(dev, 62);
        rect_mv_case::<DMat26>(dev, 63);
        rect_mv_case::<DMat43>(dev, 64);
        same_on_cpu(dev, "mv Mat26", |d| rect_mv_case::<Mat26>(d, 65));
        same_on_cpu(dev, "mv DMat32", |d| rect_mv_case::<DMat32>(d, 66));
        // x of the wrong length names the block's vector types.
        let a = random::<Mat23>(dev, 4, 5, 6, 67);
        let e = sparse::mv(
            1.0,
            &a,
            &wp::Array::<glam::Vec3>::zeros(4, dev).unwrap(),
            0.0,
            &wp::Array::<glam::Vec2>::zeros(4, dev).unwrap(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("`x` has shape [4] of Vec3")
                && e.contains("4 x 5 blocks of 2 x 3 (8 x 15 scalars)")
                && e.contains("needs 5 Vec3 elements"),
            "{e}"
        );
    }

    fn ops_rect_transpose_dense_axpy(dev: &wp::Device) {
        // The transpose of Mat23 blocks is of Mat32 blocks (exact), and back.
        transpose_case::<Mat23>(dev, 12, 7, 71);
        transpose_case::<DMat46>(dev, 6, 9, 72);
        same_on_cpu(dev, "transpose Mat63", |d| {
            transpose_case::<Mat63>(d, 8, 10, 73)
        });
        // Dense both ways with row-major rectangular blocks.
        dense_case::<Mat34>(dev, 5, 6, 74);
        same_on_cpu(dev, "dense DMat26", |d| dense_case::<DMat26>(d, 4, 3, 75));
        // axpy, its order bit for bit.
        axpy_case::<Mat24>(dev, 76);
        same_on_cpu(dev, "axpy DMat63", |d| axpy_case::<DMat63>(d, 77));
    }

    /// `alpha A B + beta C` of blocks `A x B -> O` against the dense f64 product.
    fn rect_mm_case<A, B>(dev: &wp::Device, beta: f64, seed: u64) -> Vec<u64>
    where
        A: BlockMul<B> + Copy,
        B: Block<Scalar = A::Scalar> + Copy,
        A::Output: Copy,
    {
        let (m, k, n) = (8, 6, 9);
        let a = random::<A>(dev, m, k, 25, seed);
        let b = random::<B>(dev, k, n, 25, seed + 1);
        let mut c = random::<A::Output>(dev, m, n, 15, seed + 2);
        let (da, db, dc) = (dense_of(&a), dense_of(&b), dense_of(&c));
        let alpha = A::Scalar::from_f64(0.75);
        sparse::mm(
            alpha,
            &a,
            &b,
            A::Scalar::from_f64(beta),
            &mut c,
            &mut MmWork::new(),
        )
        .unwrap();
        assert_eq!((c.nrow(), c.ncol()), (m, n));
        let got = dense_of(&c);
        let (rows, inner, cols) = (m * A::ROWS, k * A::COLS, n * B::COLS);
        let u = if std::mem::size_of::<A::Scalar>() == 4 {
            2f64.powi(-24)
        } else {
            2f64.powi(-53)
        };
        for i in 0..rows {
            for j in 0..cols {
                let mut want = beta * dc[i * cols + j];
                let mut mag = want.abs();
                for q in 0..inner {
                    want += 0.75 * da[i * inner + q] * db[q * cols + j];
                    mag += (0.75 * da[i * inner + q] * db[q * cols + j]).abs();
                }
                // As mm_case: 30 u times the sum of the magnitudes.
                let g = got[i * cols + j];
                assert!(
                    (g - want).abs() <= 30.0 * u * mag.max(1e-300),
                    "({i}, {j}): {g} vs {want}"
                );
            }
        }
        bits(&scalars(c.values()))
    }

    fn ops_rect_mm(dev: &wp::Device) {
        // Rectangular times rectangular into a square (glam, column-major) block and into a
        // rectangular one; square (column-major) times rectangular (row-major).
        rect_mm_case::<Mat23, Mat32>(dev, 0.0, 81);
        rect_mm_case::<Mat32, Mat23>(dev, 0.5, 82);
        rect_mm_case::<Mat24, Mat43>(dev, -1.0, 83);
        rect_mm_case::<DMat2, DMat26>(dev, 0.25, 84);
        same_on_cpu(dev, "mm Mat63 x Mat32", |d| {
            rect_mm_case::<Mat63, Mat32>(d, 0.5, 85)
        });
        same_on_cpu(dev, "mm DMat32 x DMat23", |d| {
            rect_mm_case::<DMat32, DMat23>(d, 0.0, 86)
        });
    }

    /// `scale`, `diag` and `to_dense` are recorded by a capture (each replay works on the
    /// arrays' contents then); the operations that allocate are refused there.
    fn ops_in_a_capture(dev: &wp::Device) {
        let mut a = random::<Mat3>(dev, 6, 6, 20, 91);
        let nnz = a.nnz().unwrap();
        let out = wp::Array::<Mat3>::zeros(6, dev).unwrap();
        let dense = wp::Array::<f32, 2>::zeros([18, 18], dev).unwrap();
        // Once before capturing: a GPU loads the library at the first use.
        a.scale(1.0).unwrap();
        sparse::diag(&a, &out).unwrap();
        a.to_dense(&dense).unwrap();
        let b = a.clone();
        let g = wp::capture(dev, || {
            a.scale(2.0)?;
            sparse::diag(&a, &out)?;
            a.to_dense(&dense)
        })
        .unwrap();
        let v0 = scalars(b.values());
        for k in 1..=2 {
            g.launch().unwrap();
            // Each replay doubles the values (exactly: a power of two).
            let f = (1u32 << k) as f32;
            let want: Vec<f32> = v0[..nnz * 9].iter().map(|v| v * f).collect();
            assert_eq!(scalars(b.values())[..nnz * 9], want[..], "replay {k}");
            assert_eq!(
                host(&dense).iter().map(|&v| v as f64).collect::<Vec<_>>(),
                dense_of(&b),
                "replay {k}"
            );
            let d = dense_of(&b);
            let got = scalars(&out);
            for i in 0..6 {
                for p in 0..3 {
                    for q in 0..3 {
                        assert_eq!(
                            got[i * 9 + at::<Mat3>(p, q)] as f64,
                            d[(i * 3 + p) * 18 + i * 3 + q],
                            "replay {k}"
                        );
                    }
                }
            }
        }
        let e = wp::capture(dev, || b.transpose().map(|_| ())).unwrap_err();
        assert!(matches!(e, wp::Error::Capture { .. }), "{e}");
        let mut y = b.clone();
        let e = wp::capture(dev, || sparse::axpy(1.0, &b, 1.0, &mut y)).unwrap_err();
        assert!(matches!(e, wp::Error::Capture { .. }), "{e}");
    }

    /// `alpha Aᵀ x + beta y` against the dense f64 product (tolerance) and against `mv` of the
    /// transpose (bit for bit: it is that).
    fn mv_transpose_case<B: Block + Copy>(dev: &wp::Device, beta: f64, seed: u64) -> Vec<u64>
    where
        B::Transpose: Copy,
    {
        let (nrow, ncol) = (11, 14);
        let a = random::<B>(dev, nrow, ncol, 40, seed);
        let mut g = Rng(seed + 1);
        let sc = |v: Vec<f64>| v.into_iter().map(B::Scalar::from_f64).collect::<Vec<_>>();
        let xs = sc((0..nrow * B::ROWS).map(|_| g.unit()).collect());
        let ys = sc((0..ncol * B::COLS).map(|_| g.unit()).collect());
        let x = arr(&xs, dev).reinterpret::<B::Out>().unwrap();
        let y = arr(&ys, dev).reinterpret::<B::In>().unwrap();
        let (al, be) = (B::Scalar::from_f64(-0.75), B::Scalar::from_f64(beta));
        sparse::mv_transpose(al, &a, &x, be, &y).unwrap();
        let got = host(&y.reinterpret::<B::Scalar>().unwrap());
        let d = dense_of(&a);
        let (h, w) = a.shape();
        let f32s = std::mem::size_of::<B::Scalar>() == 4;
        for j in 0..w {
            let mut want = beta * ys[j].to_f64();
            for i in 0..h {
                want += -0.75 * d[i * w + j] * xs[i].to_f64();
            }
            // f32: ~50 rounded terms of magnitude <= 1: 1e-5 absolute.
            let tol = if f32s { 1e-5 } else { 1e-13 };
            assert!(
                (got[j].to_f64() - want).abs() <= tol,
                "{j}: {:?} vs {want}",
                got[j]
            );
        }
        let y2 = arr(&ys, dev).reinterpret::<B::In>().unwrap();
        sparse::mv(al, &a.transpose().unwrap(), &x, be, &y2).unwrap();
        assert_eq!(
            bits(&host(&y2.reinterpret::<B::Scalar>().unwrap())),
            bits(&got)
        );
        bits(&got)
    }

    fn ops_mv_transpose(dev: &wp::Device) {
        mv_transpose_case::<f32>(dev, 0.0, 101);
        mv_transpose_case::<Mat3>(dev, 1.5, 102);
        mv_transpose_case::<Mat23>(dev, -1.0, 103);
        same_on_cpu(dev, "mv_transpose DMat46", |d| {
            mv_transpose_case::<DMat46>(d, 0.5, 104)
        });
        // Lengths are those of the transpose: x has nrow, y ncol elements.
        let a = random::<Mat23>(dev, 4, 5, 6, 105);
        let e = sparse::mv_transpose(
            1.0,
            &a,
            &wp::Array::<glam::Vec2>::zeros(5, dev).unwrap(),
            0.0,
            &wp::Array::<glam::Vec3>::zeros(5, dev).unwrap(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("sparse::mv_transpose")
                && e.contains("`x` has 5 Vec2 elements")
                && e.contains("4 x 5 blocks of 2 x 3")
                && e.contains("needs 4 Vec2 elements"),
            "{e}"
        );
    }

    /// Offsets a user overwrote so that they no longer ascend (`[0, 5, 3, 5]`: rows 0 and 2
    /// overlap, the count in range): `transpose` and `axpy` stay in bounds and return, on
    /// both backends (their results are unspecified; on the CPU the overlapping rows' tasks
    /// write one element by atomic stores, never a data race).
    fn ops_overwritten_offsets_stay_in_bounds(dev: &wp::Device) {
        let (r, c) = ([0, 0, 1, 2, 2], [0, 1, 2, 3, 0]);
        let v = [1.0f32, 2.0, 3.0, 4.0, 5.0];
        let a = Bsr::from_triplets(3, 4, &arr(&r, dev), &arr(&c, dev), &arr(&v, dev)).unwrap();
        assert_eq!(host(a.offsets()), [0, 2, 3, 5]);
        a.offsets()
            .copy_from(&wp::Array::from_slice(&[0, 5, 3, 5], dev).unwrap())
            .unwrap();
        let t = a.transpose().unwrap();
        let mut y = Bsr::<f32>::zeros(3, 4, dev).unwrap();
        sparse::axpy(1.0, &a, 1.0, &mut y).unwrap();
        // Read back whole (unspecified contents: on a GPU the racing rows may leave a row's
        // columns repeated, so no structure check).
        let _ = (host(t.offsets()), host(t.columns()), host(y.offsets()));
        let _ = (host(t.values()), host(y.columns()), host(y.values()));
        wp::synchronize().unwrap();
    }
}

// ------------------------------------------------------------------------------------------
// Krylov solvers beyond CG: BiCGSTAB, CR, restarted GMRES (slice 3)
// ------------------------------------------------------------------------------------------

/// A Krylov method of the tier, by name (the suite runs each through the same cases).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Method {
    BiCgStab,
    Cr,
    Gmres,
}

impl Method {
    /// The solve.
    fn solve<B: SquareBlock>(
        self,
        a: &Bsr<B>,
        b: &wp::Array<B::Scalar>,
        x: &wp::Array<B::Scalar>,
        pre: Precond,
        o: &SolveOptions,
    ) -> wp::Result<sparse::SolveReport> {
        match self {
            Method::BiCgStab => sparse::bicgstab(a, b, x, pre, o),
            Method::Cr => sparse::cr(a, b, x, pre, o),
            Method::Gmres => sparse::gmres(a, b, x, pre, o),
        }
    }

    /// The function name in its errors.
    fn name(self) -> &'static str {
        match self {
            Method::BiCgStab => "sparse::bicgstab",
            Method::Cr => "sparse::cr",
            Method::Gmres => "sparse::gmres",
        }
    }
}

const METHODS: [Method; 3] = [Method::BiCgStab, Method::Cr, Method::Gmres];

/// A scalar matrix from triplets `(row, col, value)` on `dev`.
fn scalar_matrix(n: usize, t: &[(i32, i32, f64)], dev: &wp::Device) -> Bsr<f64> {
    let r: Vec<i32> = t.iter().map(|e| e.0).collect();
    let c: Vec<i32> = t.iter().map(|e| e.1).collect();
    let v: Vec<f64> = t.iter().map(|e| e.2).collect();
    Bsr::from_triplets(n, n, &arr(&r, dev), &arr(&c, dev), &arr(&v, dev)).unwrap()
}

/// The 2-D convection-diffusion operator on an `m x m` grid (Dirichlet boundary), central
/// differences: 4 on the diagonal, `-1 -/+ cx` to the west/east and `-1 -/+ cy` to the
/// south/north neighbours: non-symmetric for nonzero `(cx, cy)` (cell Peclet numbers 2 cx,
/// 2 cy below 1 keep it diagonally dominant).
fn convection_diffusion(m: usize, cx: f64, cy: f64) -> Vec<(i32, i32, f64)> {
    let id = |i: usize, j: usize| (i * m + j) as i32;
    let mut t = vec![];
    for i in 0..m {
        for j in 0..m {
            t.push((id(i, j), id(i, j), 4.0));
            if j > 0 {
                t.push((id(i, j), id(i, j - 1), -1.0 - cx));
            }
            if j + 1 < m {
                t.push((id(i, j), id(i, j + 1), -1.0 + cx));
            }
            if i > 0 {
                t.push((id(i, j), id(i - 1, j), -1.0 - cy));
            }
            if i + 1 < m {
                t.push((id(i, j), id(i + 1, j), -1.0 + cy));
            }
        }
    }
    t
}

/// The f64 reference solution of the dense system from triplets (summed), by Gaussian
/// elimination with partial pivoting on the host: independent of the tier's code.
fn dense_solve(n: usize, t: &[(i32, i32, f64)], b: &[f64]) -> Vec<f64> {
    let mut a = vec![vec![0.0; n + 1]; n];
    for &(r, c, v) in t {
        a[r as usize][c as usize] += v;
    }
    for (row, &bi) in a.iter_mut().zip(b) {
        row[n] = bi;
    }
    for col in 0..n {
        let p = (col..n)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap();
        a.swap(p, col);
        let (top, rest) = a.split_at_mut(col + 1);
        let pivot = &top[col];
        for row in rest {
            let f = row[col] / pivot[col];
            if f != 0.0 {
                for (x, p) in row[col..].iter_mut().zip(&pivot[col..]) {
                    *x -= f * p;
                }
            }
        }
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let s: f64 = (i + 1..n).map(|j| a[i][j] * x[j]).sum();
        x[i] = (a[i][n] - s) / a[i][i];
    }
    x
}

/// Solves with `method` on `dev` from x = 0 and checks it: converged, `iterations + 1`
/// history entries, the true residual `|b - A x|` (an independent host product) within
/// `slack` times the tolerance, and x within `rel` (relative, in the 2-norm) of the dense
/// reference solution. Returns (iterations, history bits, x bits).
#[allow(clippy::too_many_arguments)]
fn krylov_case(
    method: Method,
    t: &[(i32, i32, f64)],
    n: usize,
    b: &[f64],
    pre: Precond,
    o: &SolveOptions,
    (slack, rel): (f64, f64),
    dev: &wp::Device,
) -> (usize, Vec<u64>, Vec<u64>) {
    let what = format!("{method:?} {pre:?}");
    let a = scalar_matrix(n, t, dev);
    let x = arr(&vec![0.0f64; n], dev);
    let rep = method.solve(&a, &arr(b, dev), &x, pre, o).unwrap();
    assert_eq!(rep.stop, Stop::Converged, "{what}: {rep:?}");
    assert!(rep.converged);
    assert_eq!(rep.history.len(), rep.iterations + 1, "{what}");
    assert!(rep.residual <= rep.tolerance, "{what}: {rep:?}");
    let xs = host(&x);
    let tr = true_residual(&a, |b, _, _| *b, b, &xs);
    assert!(
        tr <= slack * rep.tolerance,
        "{what}: true residual {tr}, tolerance {}",
        rep.tolerance
    );
    let xr = dense_solve(n, t, b);
    let err = xs
        .iter()
        .zip(&xr)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt();
    let norm = xr.iter().map(|v| v * v).sum::<f64>().sqrt();
    assert!(
        err <= rel * norm,
        "{what}: |x - x_ref| = {err}, |x_ref| = {norm}"
    );
    (
        rep.iterations,
        rep.history.iter().map(|h| h.to_bits()).collect(),
        xs.iter().map(|v| v.to_bits()).collect(),
    )
}

/// Each method on the 16 x 16 Poisson matrix (256 unknowns, condition number ~120), f64,
/// rtol 1e-10, without and with Jacobi: it converges, the true residual is within 1.5x the
/// tolerance (the recurrences' residuals drift from the true one by rounding, ~1e-14 |b|
/// here; GMRES's estimate is exact in exact arithmetic), and x is within 1e-7 of the dense
/// f64 reference (cond x rtol ~ 1.2e-8, with margin for the drift). CR without a
/// preconditioner minimises |r|: its history does not increase (1e-12 relative slack for
/// rounding). A GPU gives the same bits as the CPU.
fn krylov_poisson_converges(dev: &wp::Device) {
    let m = 16;
    let (r, c, v) = poisson(m);
    let t: Vec<(i32, i32, f64)> = (0..r.len()).map(|k| (r[k], c[k], v[k])).collect();
    let n = m * m;
    let mut g = Rng(33);
    let b: Vec<f64> = (0..n).map(|_| g.unit()).collect();
    let o = SolveOptions {
        rtol: 1e-10,
        ..Default::default()
    };
    for method in METHODS {
        for pre in [Precond::None, Precond::Jacobi] {
            let run = |d: &wp::Device| krylov_case(method, &t, n, &b, pre, &o, (1.5, 1e-7), d);
            let (iters, hist, _) = run(dev);
            assert!(iters > 5 && iters < 400, "{method:?} {pre:?}: {iters}");
            if method == Method::Cr && pre == Precond::None {
                let h: Vec<f64> = hist.iter().map(|&b| f64::from_bits(b)).collect();
                for w in h.windows(2) {
                    assert!(w[1] <= w[0] * (1.0 + 1e-12), "CR history rose: {h:?}");
                }
            }
            same_on_cpu(dev, &format!("{method:?} {pre:?} poisson"), run);
        }
    }
}

/// BiCGSTAB and GMRES(20) on a non-symmetric convection-diffusion matrix (16 x 16 grid,
/// cell Peclet numbers 0.8 and 0.4), f64, rtol 1e-10: converged, the true residual within
/// 1.5x the tolerance, x within 1e-7 of the dense reference (the matrix is diagonally
/// dominant with a condition number near the Poisson matrix's), the same bits on a GPU.
/// GMRES takes no more iterations than 20 per restart times the cycles it needs; BiCGSTAB
/// takes two products per iteration.
fn krylov_convection_diffusion(dev: &wp::Device) {
    let m = 16;
    let n = m * m;
    let t = convection_diffusion(m, 0.4, 0.2);
    let b: Vec<f64> = (0..n).map(|i| ((i % 11) as f64 - 5.0) * 0.2).collect();
    for method in [Method::BiCgStab, Method::Gmres] {
        for pre in [Precond::None, Precond::Jacobi, Precond::PointJacobi] {
            let o = SolveOptions {
                rtol: 1e-10,
                restart: 20,
                ..Default::default()
            };
            let run = |d: &wp::Device| krylov_case(method, &t, n, &b, pre, &o, (1.5, 1e-7), d);
            run(dev);
            same_on_cpu(dev, &format!("{method:?} {pre:?} convection"), run);
        }
    }
}

/// `Mode::Graph` gives what `Mode::Host` gives, bit for bit, for every method: the same stop,
/// iterations, history and x, at any `check_every` (GMRES: restart 7, so a pass holds one
/// cycle or several), also when `max_iter` stops the solve (for GMRES inside a cycle).
fn krylov_graph_mode_matches_host_mode(dev: &wp::Device) {
    let m = 10;
    let n = m * m;
    let t = convection_diffusion(m, 0.3, -0.1);
    // CR needs a symmetric matrix: the symmetric part's pattern is the same (cx = cy = 0).
    let ts = convection_diffusion(m, 0.0, 0.0);
    let b: Vec<f64> = (0..n).map(|i| ((i % 9) as f64 - 4.0) * 0.3).collect();
    let x0: Vec<f64> = (0..n).map(|i| (i % 4) as f64 * 0.01).collect();
    for method in METHODS {
        let a = scalar_matrix(n, if method == Method::Cr { &ts } else { &t }, dev);
        let solve = |mode: Mode, every: usize, max_iter: usize, pre: Precond| {
            let x = arr(&x0, dev);
            let o = SolveOptions {
                rtol: 1e-9,
                max_iter,
                check_every: every,
                mode,
                restart: 7,
                ..Default::default()
            };
            let rep = method.solve(&a, &arr(&b, dev), &x, pre, &o).unwrap();
            assert_eq!(rep.history.len(), rep.iterations + 1);
            (
                rep.stop,
                rep.iterations,
                rep.history.iter().map(|h| h.to_bits()).collect::<Vec<_>>(),
                host(&x).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            )
        };
        for pre in [Precond::None, Precond::Jacobi] {
            let what = format!("{method:?} {pre:?}");
            let host_mode = solve(Mode::Host, 10, 1000, pre);
            assert_eq!(host_mode.0, Stop::Converged, "{what}");
            for every in [1, 7, 64, usize::MAX] {
                assert_eq!(
                    solve(Mode::Graph, every, 1000, pre),
                    host_mode,
                    "{what}, every {every}"
                );
                assert_eq!(solve(Mode::Host, every, 1000, pre), host_mode, "{what}");
            }
            let capped = solve(Mode::Host, 3, 9, pre);
            assert_eq!((capped.0, capped.1), (Stop::MaxIterations, 9), "{what}");
            assert_ne!(
                capped.3,
                host(&arr(&x0, dev))
                    .iter()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            );
            assert_eq!(solve(Mode::Graph, 4, 9, pre), capped, "{what}, max_iter 9");
            assert_eq!(solve(Mode::Graph, usize::MAX, 9, pre), capped, "{what}");
        }
    }
}

/// `max_iter` reached: `Ok` with `MaxIterations`, `max_iter` iterations and their history;
/// `max_iter` 0: no iteration (for GMRES also when the restart is longer).
fn krylov_max_iterations_is_ok(dev: &wp::Device) {
    let (r, c, v) = poisson(16);
    let n = 256;
    let a = Bsr::from_triplets(n, n, &arr(&r, dev), &arr(&c, dev), &arr(&v, dev)).unwrap();
    for method in METHODS {
        let x = arr(&vec![0.0f64; n], dev);
        let o = SolveOptions {
            rtol: 1e-12,
            max_iter: 5,
            check_every: 3,
            restart: 4,
            ..Default::default()
        };
        let rep = method
            .solve(&a, &arr(&vec![1.0; n], dev), &x, Precond::None, &o)
            .unwrap();
        assert_eq!(
            (rep.stop, rep.iterations, rep.converged),
            (Stop::MaxIterations, 5, false),
            "{method:?}"
        );
        assert_eq!(rep.history.len(), 6);
        assert_eq!(rep.history[0], 16.0, "{method:?}: |b| from x = 0");
        assert!(rep.residual > rep.tolerance);
        assert!(rep.history.iter().all(|h| h.is_finite() && *h > 0.0));
        assert!(host(&x).iter().any(|&v| v != 0.0), "{method:?}: x moved");
        let o = SolveOptions { max_iter: 0, ..o };
        let x = arr(&vec![0.0f64; n], dev);
        let rep = method
            .solve(&a, &arr(&vec![1.0; n], dev), &x, Precond::None, &o)
            .unwrap();
        assert_eq!((rep.stop, rep.iterations), (Stop::MaxIterations, 0));
        assert_eq!(host(&x), vec![0.0; n], "{method:?}: x untouched");
    }
}

/// The breakdowns, each built so that every quantity is exact in binary (found by a search
/// over small integer systems in exact rational arithmetic), in both modes:
/// - BiCGSTAB: `r0 . v = 0` at once (a rotation), `omega = 0` and `rho = 0` after the first
///   iteration;
/// - CR: `z . Az = 0` at the set-up (diag(1, -1), b = (1, 1));
/// - GMRES: a zero Hessenberg column at the second step (a nilpotent A): x gets the first
///   column's contribution (0 here).
fn krylov_breakdowns(dev: &wp::Device) {
    let brk = |what, value| Stop::Breakdown { what, value };
    type Case = (Method, usize, Vec<(i32, i32, f64)>, Vec<f64>, Stop, usize);
    let cases: Vec<Case> = vec![
        (
            Method::BiCgStab,
            2,
            vec![(0, 1, 1.0), (1, 0, -1.0)],
            vec![1.0, 0.0],
            brk("r0.v", 0.0),
            0,
        ),
        (
            Method::BiCgStab,
            3,
            vec![
                (0, 0, 1.0),
                (0, 2, 1.0),
                (1, 0, 1.0),
                (1, 1, -2.0),
                (1, 2, -2.0),
                (2, 1, 1.0),
            ],
            vec![1.0, -1.0, 0.0],
            brk("omega", 0.0),
            1,
        ),
        (
            Method::BiCgStab,
            3,
            vec![
                (0, 0, 2.0),
                (0, 1, -1.0),
                (1, 1, 2.0),
                (1, 2, 1.0),
                (2, 0, 2.0),
                (2, 2, 2.0),
            ],
            vec![0.0, -1.0, 0.0],
            brk("rho", 0.0),
            1,
        ),
        (
            Method::Cr,
            2,
            vec![(0, 0, 1.0), (1, 1, -1.0)],
            vec![1.0, 1.0],
            brk("z.Az", 0.0),
            0,
        ),
        (
            Method::Gmres,
            2,
            vec![(0, 1, 1.0)],
            vec![0.0, 1.0],
            brk("H_jj", 0.0),
            1,
        ),
    ];
    for (method, n, t, b, stop, iters) in cases {
        let a = scalar_matrix(n, &t, dev);
        for mode in [Mode::Host, Mode::Graph] {
            let x = arr(&vec![0.0f64; n], dev);
            let o = SolveOptions {
                mode,
                ..Default::default()
            };
            let rep = method
                .solve(&a, &arr(&b, dev), &x, Precond::None, &o)
                .unwrap();
            assert_eq!(
                (rep.stop, rep.iterations),
                (stop, iters),
                "{method:?} {mode:?}: {rep:?}"
            );
            assert_eq!(rep.history.len(), iters + 1);
            if iters == 0 || method == Method::Gmres {
                assert_eq!(host(&x), vec![0.0; n], "{method:?}: x untouched");
            }
        }
    }
}

/// NaN in b: `NonFinite` before any iteration; b = 0 from x = 0: converged at once; a
/// missing diagonal block with Jacobi: `SingularPreconditioner`, x untouched. Every method.
fn krylov_non_finite_zero_and_singular(dev: &wp::Device) {
    let a = scalar_matrix(
        2,
        &[(0, 0, 2.0), (1, 1, 3.0), (0, 1, 0.5), (1, 0, 0.5)],
        dev,
    );
    let d = SolveOptions::default();
    for method in METHODS {
        let x = arr(&[0.0f64; 2], dev);
        let rep = method
            .solve(&a, &arr(&[f64::NAN, 1.0], dev), &x, Precond::None, &d)
            .unwrap();
        assert_eq!(
            (rep.stop, rep.iterations),
            (Stop::NonFinite, 0),
            "{method:?}"
        );
        let rep = method
            .solve(&a, &arr(&[0.0; 2], dev), &x, Precond::Jacobi, &d)
            .unwrap();
        assert_eq!(
            (rep.stop, rep.iterations),
            (Stop::Converged, 0),
            "{method:?}"
        );
        // Row 2 has no diagonal block.
        let s = scalar_matrix(
            3,
            &[(0, 0, 2.0), (1, 1, 2.0), (2, 1, 1.0), (2, 0, 1.0)],
            dev,
        );
        let x = arr(&[7.0f64; 3], dev);
        for pre in [Precond::Jacobi, Precond::PointJacobi] {
            let rep = method.solve(&s, &arr(&[1.0; 3], dev), &x, pre, &d).unwrap();
            assert_eq!(
                (rep.stop, rep.iterations),
                (Stop::SingularPreconditioner { block_row: 2 }, 0),
                "{method:?}"
            );
            assert_eq!(host(&x), [7.0; 3], "{method:?}: x untouched");
        }
    }
}

/// Bad arguments: each an `Err` naming the method and the argument.
fn krylov_bad_arguments(dev: &wp::Device) {
    let rect =
        Bsr::from_triplets(2, 3, &arr(&[0], dev), &arr(&[0], dev), &arr(&[1.0f64], dev)).unwrap();
    let sq = scalar_matrix(2, &[(0, 0, 1.0), (1, 1, 1.0)], dev);
    let d = SolveOptions::default();
    let err = |method: Method, a: &Bsr<f64>, b: &[f64], x: &[f64], o: SolveOptions| {
        method
            .solve(a, &arr(b, dev), &arr(x, dev), Precond::None, &o)
            .unwrap_err()
            .to_string()
    };
    for method in METHODS {
        let f = method.name();
        let e = err(method, &rect, &[0.0; 2], &[0.0; 2], d);
        assert!(e.contains(f) && e.contains("2 x 3 blocks"), "{e}");
        let e = err(method, &sq, &[0.0; 3], &[0.0; 2], d);
        assert!(e.contains(f) && e.contains("`b` has shape [3]"), "{e}");
        let e = err(
            method,
            &sq,
            &[0.0; 2],
            &[0.0; 2],
            SolveOptions {
                check_every: 0,
                ..d
            },
        );
        assert!(e.contains(f) && e.contains("check_every"), "{e}");
        let e = err(
            method,
            &sq,
            &[0.0; 2],
            &[0.0; 2],
            SolveOptions {
                rtol: f64::NAN,
                ..d
            },
        );
        assert!(e.contains(f) && e.contains("`rtol`"), "{e}");
        let x = arr(&[0.0f64; 2], dev);
        let e = method
            .solve(&sq, &x, &x, Precond::None, &d)
            .unwrap_err()
            .to_string();
        assert!(e.contains(f) && e.contains("`b` and `x` overlap"), "{e}");
        // Inside a user's capture: refused (the host-driven loop reads back).
        let (bb, xx) = (arr(&[1.0f64; 2], dev), arr(&[0.0f64; 2], dev));
        let e = wp::capture(dev, || {
            method.solve(&sq, &bb, &xx, Precond::None, &d).map(|_| ())
        })
        .unwrap_err();
        assert!(
            matches!(e, wp::Error::Capture { .. }) && e.to_string().contains(f),
            "{e}"
        );
    }
    for restart in [0, 1025] {
        let e = err(
            Method::Gmres,
            &sq,
            &[1.0; 2],
            &[0.0; 2],
            SolveOptions { restart, ..d },
        );
        assert!(
            e.contains("sparse::gmres") && e.contains("`restart` is"),
            "{e}"
        );
    }
    // CR and BiCGSTAB ignore `restart`.
    for method in [Method::BiCgStab, Method::Cr] {
        let x = arr(&[0.0f64; 2], dev);
        let o = SolveOptions { restart: 0, ..d };
        let rep = method
            .solve(&sq, &arr(&[1.0; 2], dev), &x, Precond::None, &o)
            .unwrap();
        assert_eq!(rep.stop, Stop::Converged);
    }
}

/// Block types: the 6 x 6 Poisson matrix Kronecker an SPD 3 x 3 K (`DMat3`, so symmetric
/// positive definite) and a non-symmetric `Mat2` version (K non-symmetric, diagonally
/// dominant): every method (CR on the symmetric one) converges with block Jacobi, the true
/// residual within 1.5x (f64) or 3x (f32: the recurrences drift more) the tolerance, and a
/// GPU gives the same bits.
fn krylov_block_types(dev: &wp::Device) {
    let m = 6;
    let (r, c, v) = poisson(m);
    let n = m * m;
    let k3 = DMat3::from_cols_array(&[4.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 2.0]);
    let v3: Vec<DMat3> = v.iter().map(|&s| k3 * s).collect();
    let k2 = glam::Mat2::from_cols_array(&[3.0, 0.5, -1.0, 2.0]);
    let v2: Vec<glam::Mat2> = v.iter().map(|&s| k2 * s as f32).collect();
    let b3: Vec<f64> = (0..3 * n).map(|i| ((i % 5) as f64 - 2.0) * 0.5).collect();
    let b2: Vec<f32> = (0..2 * n).map(|i| ((i % 7) as f32 - 3.0) * 0.25).collect();
    for method in METHODS {
        let run3 = |d: &wp::Device| {
            let a = Bsr::from_triplets(n, n, &arr(&r, d), &arr(&c, d), &arr(&v3, d)).unwrap();
            let x = arr(&vec![0.0f64; 3 * n], d);
            let o = SolveOptions {
                rtol: 1e-9,
                restart: 15,
                ..Default::default()
            };
            let rep = method
                .solve(&a, &arr(&b3, d), &x, Precond::Jacobi, &o)
                .unwrap();
            assert_eq!(rep.stop, Stop::Converged, "{method:?} DMat3: {rep:?}");
            let tr = true_residual(&a, |b, i, j| b.col(j)[i], &b3, &host(&x));
            assert!(tr <= 1.5 * rep.tolerance, "{method:?} DMat3: {tr}");
            (
                rep.iterations,
                host(&x).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            )
        };
        run3(dev);
        same_on_cpu(dev, &format!("{method:?} DMat3"), run3);
        if method == Method::Cr {
            continue;
        }
        let run2 = |d: &wp::Device| {
            let a = Bsr::from_triplets(n, n, &arr(&r, d), &arr(&c, d), &arr(&v2, d)).unwrap();
            let x = arr(&vec![0.0f32; 2 * n], d);
            let o = SolveOptions {
                rtol: 1e-5,
                restart: 15,
                ..Default::default()
            };
            let rep = method
                .solve(&a, &arr(&b2, d), &x, Precond::Jacobi, &o)
                .unwrap();
            assert_eq!(rep.stop, Stop::Converged, "{method:?} Mat2: {rep:?}");
            let xs: Vec<f64> = host(&x).iter().map(|&v| v as f64).collect();
            let bs: Vec<f64> = b2.iter().map(|&v| v as f64).collect();
            let tr = true_residual(&a, |b, i, j| b.col(j)[i] as f64, &bs, &xs);
            assert!(
                tr <= 3.0 * rep.tolerance,
                "{method:?} Mat2: {tr}, {}",
                rep.tolerance
            );
            (
                rep.iterations,
                host(&x).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            )
        };
        run2(dev);
        same_on_cpu(dev, &format!("{method:?} Mat2"), run2);
    }
}

/// A user preconditioner (`&p` for `p: Preconditioner`, here a closure): point Jacobi written
/// as `z = D^-1 r` by `sparse::mv` with a diagonal matrix of the host's `1 / a_ii` gives
/// exactly what the built-in `PointJacobi` gives (its inverse of a 1 x 1 block is the one
/// rounded division, and its apply sums `0 + d r` as mv does), for every method, in both
/// modes (in `Mode::Graph` the closure's mv is recorded into the solver's graph and replayed
/// each iteration). Its errors come back from the solve: an mv of the wrong length, and a
/// read-back inside `Mode::Graph`'s capture.
fn krylov_user_preconditioner(dev: &wp::Device) {
    let m = 10;
    let n = m * m;
    let conv = convection_diffusion(m, 0.3, 0.15);
    // Scale the rows so that the diagonal is not constant (Jacobi then changes the iterates).
    let scale = |i: i32| 1.0 + (i % 3) as f64;
    let t: Vec<(i32, i32, f64)> = conv.iter().map(|&(r, c, v)| (r, c, v * scale(r))).collect();
    let (pr, pc, pv) = poisson(m);
    let ts: Vec<(i32, i32, f64)> = (0..pr.len())
        .map(|k| (pr[k], pc[k], pv[k] * scale(pr[k]) * scale(pc[k])))
        .collect();
    let b: Vec<f64> = (0..n).map(|i| ((i % 9) as f64 - 4.0) * 0.3).collect();
    let methods: [(&str, bool); 4] = [
        ("cg", true),
        ("cr", true),
        ("bicgstab", false),
        ("gmres", false),
    ];
    for (name, symmetric) in methods {
        let trip = if symmetric { &ts } else { &t };
        let a = scalar_matrix(n, trip, dev);
        let mut diag = vec![0.0; n];
        for &(r, c, v) in trip.iter() {
            if r == c {
                diag[r as usize] += v;
            }
        }
        let inv: Vec<(i32, i32, f64)> = (0..n as i32)
            .map(|i| (i, i, 1.0 / diag[i as usize]))
            .collect();
        let dm = scalar_matrix(n, &inv, dev);
        let user = |r: &wp::Array<f64>, z: &wp::Array<f64>| sparse::mv(1.0, &dm, r, 0.0, z);
        for mode in [Mode::Host, Mode::Graph] {
            let o = SolveOptions {
                rtol: 1e-9,
                restart: 12,
                mode,
                ..Default::default()
            };
            let solve = |pre_user: bool| {
                let x = arr(&vec![0.0f64; n], dev);
                let bb = arr(&b, dev);
                let rep = match (name, pre_user) {
                    ("cg", true) => sparse::cg(&a, &bb, &x, &user, &o),
                    ("cg", false) => sparse::cg(&a, &bb, &x, Precond::PointJacobi, &o),
                    ("cr", true) => sparse::cr(&a, &bb, &x, &user, &o),
                    ("cr", false) => sparse::cr(&a, &bb, &x, Precond::PointJacobi, &o),
                    ("bicgstab", true) => sparse::bicgstab(&a, &bb, &x, &user, &o),
                    ("bicgstab", false) => sparse::bicgstab(&a, &bb, &x, Precond::PointJacobi, &o),
                    (_, true) => sparse::gmres(&a, &bb, &x, &user, &o),
                    (_, false) => sparse::gmres(&a, &bb, &x, Precond::PointJacobi, &o),
                }
                .unwrap();
                assert_eq!(rep.stop, Stop::Converged, "{name} {mode:?} user {pre_user}");
                (
                    rep.iterations,
                    rep.history.iter().map(|h| h.to_bits()).collect::<Vec<_>>(),
                    host(&x).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                )
            };
            let builtin = solve(false);
            assert_eq!(solve(true), builtin, "{name} {mode:?}");
            // Jacobi matters here: without it the iterations differ.
            let x = arr(&vec![0.0f64; n], dev);
            let plain = match name {
                "cg" => sparse::cg(&a, &arr(&b, dev), &x, Precond::None, &o),
                "cr" => sparse::cr(&a, &arr(&b, dev), &x, Precond::None, &o),
                "bicgstab" => sparse::bicgstab(&a, &arr(&b, dev), &x, Precond::None, &o),
                _ => sparse::gmres(&a, &arr(&b, dev), &x, Precond::None, &o),
            }
            .unwrap();
            assert_ne!(plain.iterations, builtin.0, "{name} {mode:?}");
        }
        // The closure's errors are the solve's.
        let short = arr(&[0.0f64; 3], dev);
        let bad = |r: &wp::Array<f64>, _z: &wp::Array<f64>| sparse::mv(1.0, &dm, r, 0.0, &short);
        let e = sparse::gmres(
            &a,
            &arr(&b, dev),
            &arr(&vec![0.0; n], dev),
            &bad,
            &SolveOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("sparse::mv") && e.contains("`y`"), "{e}");
        let reads = |r: &wp::Array<f64>, z: &wp::Array<f64>| {
            r.to_vec()?;
            sparse::mv(1.0, &dm, r, 0.0, z)
        };
        let o = SolveOptions {
            mode: Mode::Graph,
            ..Default::default()
        };
        let e =
            sparse::bicgstab(&a, &arr(&b, dev), &arr(&vec![0.0; n], dev), &reads, &o).unwrap_err();
        assert!(matches!(e, wp::Error::Capture { .. }), "{e}");
    }
}

/// f32: each method on the 16 x 16 Poisson matrix with Jacobi to rtol 1e-5 (f32's rounding
/// floor for this matrix, condition number ~120, is near 1e-6 |b|): converged, the true
/// residual (f64, from the f32 data) within 3x the tolerance (the recurrences' drift in f32;
/// GMRES's estimate drifts from the true residual too), and the same bits on a GPU.
fn krylov_poisson_f32(dev: &wp::Device) {
    let m = 16;
    let (r, c, v) = poisson(m);
    let v: Vec<f32> = v.iter().map(|&x| x as f32).collect();
    let n = m * m;
    let b: Vec<f32> = (0..n).map(|i| ((i % 7) as f32 - 3.0) / 3.0).collect();
    for method in METHODS {
        let run = |d: &wp::Device| {
            let a = Bsr::from_triplets(n, n, &arr(&r, d), &arr(&c, d), &arr(&v, d)).unwrap();
            let x = arr(&vec![0.0f32; n], d);
            let o = SolveOptions {
                rtol: 1e-5,
                restart: 20,
                ..Default::default()
            };
            let rep = method
                .solve(&a, &arr(&b, d), &x, Precond::Jacobi, &o)
                .unwrap();
            assert_eq!(rep.stop, Stop::Converged, "{method:?}: {rep:?}");
            let xs: Vec<f64> = host(&x).iter().map(|&v| v as f64).collect();
            let bs: Vec<f64> = b.iter().map(|&v| v as f64).collect();
            let tr = true_residual(&a, |b, _, _| *b as f64, &bs, &xs);
            assert!(
                tr <= 3.0 * rep.tolerance,
                "{method:?}: true residual {tr}, tolerance {}",
                rep.tolerance
            );
            (
                rep.iterations,
                host(&x).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            )
        };
        run(dev);
        same_on_cpu(dev, &format!("{method:?} f32"), run);
    }
}
