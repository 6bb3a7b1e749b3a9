//! Differentiable sparse solves and operations (the sparse tier on a tape): gradchecks (f64)
//! of a loss of the solution `x` of `A x = b` with respect to `b` and `A`'s values for each
//! solver (`cg` and `cr` with parameters entering `A` symmetrically, through a kernel and
//! `from_triplets`, so assembly -> solve -> loss differentiates end to end; `bicgstab` and
//! `gmres` on a non-symmetric `A` with respect to its values directly); the adjoint against a
//! dense solve on the host (`b̄ = A⁻ᵀ x̄`, `Ā_k = -b̄_r x_cᵀ`) for scalar and 3 x 3 blocks;
//! the assembly's adjoint exactly (duplicates, a device count); `mv` and `mv_transpose` by
//! gradcheck; and the refusals: backward through an unconverged solve, and an adjoint solve
//! that does not converge.

use crate::{arr, host, zeros};
use glam::DMat3;
use warp_lang as wp;
use warp_runtime::sparse::{self, Bsr, Precond, SolveOptions, SolveReport, Stop};
use wp::prelude::*;

backend_tests!(
    cg_gradcheck_through_assembly,
    cr_gradcheck_through_assembly,
    bicgstab_gradcheck,
    gmres_gradcheck,
    adjoints_match_a_dense_solve,
    block_adjoint_matches_a_dense_solve,
    assembly_adjoint_is_exact,
    mv_gradcheck,
    mv_transpose_gradcheck,
    backward_through_an_unconverged_solve_is_refused,
    unconverged_adjoint_solve_is_refused,
    user_preconditioner_and_what_is_recorded,
    gradients_are_the_cpus_bits,
);

/// `tv[t] = p[src[t]]`: the triplet values from the parameters (a parameter may feed
/// several triplets: `(i, j)` and `(j, i)` of a symmetric matrix).
#[wp::kernel]
fn k_gather(p: Array<f64>, src: Array<i32>, tv: Array<f64>) {
    let t = tid();
    tv[t] = p[src[t]];
}

/// A nonlinear loss of the solution, one output per element: `out[i] = w_i x_i^2 + x_i`.
#[wp::kernel]
fn k_loss(x: Array<f64>, w: Array<f64>, out: Array<f64>) {
    let i = tid();
    out[i] = w[i] * x[i] * x[i] + x[i];
}

/// Solves to `rtol` 1e-13 (f64): far below what the gradchecks resolve (see `opts`).
fn tight() -> SolveOptions {
    SolveOptions {
        rtol: 1e-13,
        max_iter: 500,
        ..Default::default()
    }
}

/// The gradchecks' step and tolerances: f64's defaults (step 1e-6, 1e-8 absolute plus 1e-6
/// relative). The solves stop at a relative residual of 1e-13 on matrices of condition number
/// about 10, so each solution is accurate to about 1e-12 relative, and the central
/// difference of two of them over 2e-6 carries up to ~1e-9 of noise where the two stop after
/// different iteration counts (2e-10 at most measured here), within 1e-8; a wrong gradient
/// (a missing term, a transpose, a sign) misses by the gradients' own size, 0.01 to 1.
fn opts() -> wp::GradcheckOptions {
    wp::GradcheckOptions::for_type::<f64>()
}

/// Which solver.
#[derive(Clone, Copy, Debug)]
enum Method {
    Cg,
    Cr,
    BiCgStab,
    Gmres,
}

fn solve<B: sparse::SquareBlock>(
    m: Method,
    a: &Bsr<B>,
    b: &wp::Array<B::Scalar>,
    x: &wp::Array<B::Scalar>,
    p: Precond,
    o: &SolveOptions,
) -> wp::Result<SolveReport> {
    match m {
        Method::Cg => sparse::cg(a, b, x, p, o),
        Method::Cr => sparse::cr(a, b, x, p, o),
        Method::BiCgStab => sparse::bicgstab(a, b, x, p, o),
        Method::Gmres => sparse::gmres(a, b, x, p, o),
    }
}

/// The pattern of a symmetric `n x n` matrix from parameters: `A_ii = p_i`, and `A_ij = A_ji
/// = p_(n+k)` for the k-th pair `(i, j)` of `pairs`. Returns the triplets' rows, columns and
/// parameter indices.
fn symmetric_pattern(n: usize, pairs: &[(i32, i32)]) -> (Vec<i32>, Vec<i32>, Vec<i32>) {
    let (mut rows, mut cols, mut src) = (vec![], vec![], vec![]);
    for i in 0..n as i32 {
        rows.push(i);
        cols.push(i);
        src.push(i);
    }
    for (k, &(i, j)) in pairs.iter().enumerate() {
        let p = (n + k) as i32;
        rows.extend([i, j]);
        cols.extend([j, i]);
        src.extend([p, p]);
    }
    (rows, cols, src)
}

/// Gradcheck of `k_loss(x)` with `x` from `method` on `A(p)` assembled from triplets (`p`
/// through `k_gather` and `from_triplets`: the assembly's adjoint), with respect to `p` and
/// `b`.
fn gradcheck_through_assembly(dev: &wp::Device, method: Method, indefinite: bool) {
    let n = 6;
    let pairs = [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (0, 3)];
    let (rows, cols, src) = symmetric_pattern(n, &pairs);
    // Diagonal parameters 3 + small (negative at odd i when indefinite: a symmetric
    // indefinite matrix for CR), couplings of about 0.5: diagonally dominant either way.
    let mut p: Vec<f64> = (0..n)
        .map(|i| {
            let d = 3.0 + 0.1 * i as f64;
            if indefinite && i % 2 == 1 {
                -d
            } else {
                d
            }
        })
        .collect();
    p.extend([0.5, -0.4, 0.3, 0.45, -0.35, 0.2]);
    let p = arr(&p, dev).with_grad().unwrap();
    let b = arr(&[1.0, -0.5, 0.25, 2.0, -1.0, 0.75], dev)
        .with_grad()
        .unwrap();
    let w = arr(&[0.3, -0.2, 0.5, 0.1, 0.7, -0.4], dev);
    let (rows, cols, src) = (arr(&rows, dev), arr(&cols, dev), arr(&src, dev));
    let tv = zeros::<f64, 1>(src.len(), dev).with_grad().unwrap();
    let x = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    // CR on an indefinite matrix: no preconditioner (Jacobi of a negative diagonal is not
    // positive definite); CG with Jacobi.
    let pre = if indefinite {
        Precond::None
    } else {
        Precond::Jacobi
    };
    let mut forward = || -> wp::Result<()> {
        wp::launch(k_gather, src.len(), (&p, &src, &tv), dev)?;
        let a = Bsr::from_triplets(n, n, &rows, &cols, &tv)?;
        x.fill(0.0)?;
        let r = solve(method, &a, &b, &x, pre, &tight())?;
        assert_eq!(r.stop, Stop::Converged, "{method:?}: {r:?}");
        wp::launch(k_loss, n, (&x, &w, &out), dev)
    };
    let report = wp::gradcheck(&mut forward, &[&p, &b], &[&out], opts()).unwrap();
    assert!(report.passed, "{method:?}: worst {:?}", report.worst);
    // Every parameter and every entry of b reaches the loss.
    let reached = (0..p.len() + n)
        .filter(|&c| report.analytic.iter().any(|row| row[c].abs() > 1e-6))
        .count();
    assert_eq!(reached, p.len() + n, "{method:?}");
}

fn cg_gradcheck_through_assembly(dev: &wp::Device) {
    gradcheck_through_assembly(dev, Method::Cg, false);
}

fn cr_gradcheck_through_assembly(dev: &wp::Device) {
    gradcheck_through_assembly(dev, Method::Cr, true);
}

/// A non-symmetric `n x n` matrix of f64 blocks (no duplicates, so its capacity is its block
/// count): tridiag(-1.5, 3, -0.5) plus a few off-band entries, each value perturbed.
fn nonsymmetric(n: usize, dev: &wp::Device) -> Bsr<f64> {
    let (mut rows, mut cols, mut vals) = (vec![], vec![], vec![]);
    for i in 0..n as i32 {
        for (j, v) in [(i - 1, -1.5), (i, 3.0), (i + 1, -0.5), (i + 3, 0.25)] {
            if (0..n as i32).contains(&j) {
                rows.push(i);
                cols.push(j);
                vals.push(v + 0.05 * ((i * 7 + j * 3) % 5) as f64);
            }
        }
    }
    Bsr::from_triplets(n, n, &arr(&rows, dev), &arr(&cols, dev), &arr(&vals, dev)).unwrap()
}

/// Gradcheck of `k_loss(x)` with `x` from `method` (non-symmetric A) with respect to A's
/// values and b.
fn gradcheck_values(dev: &wp::Device, method: Method, o: SolveOptions) {
    let n = 7;
    let a = nonsymmetric(n, dev).with_grad().unwrap();
    assert_eq!(a.nnz().unwrap(), a.nnz_bound());
    let b = arr(&[1.0, -0.5, 0.25, 2.0, -1.0, 0.75, 0.5], dev)
        .with_grad()
        .unwrap();
    let w = arr(&[0.3, -0.2, 0.5, 0.1, 0.7, -0.4, 0.25], dev);
    let x = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let mut forward = || -> wp::Result<()> {
        x.fill(0.0)?;
        let r = solve(method, &a, &b, &x, Precond::Jacobi, &o)?;
        assert_eq!(r.stop, Stop::Converged, "{method:?}: {r:?}");
        wp::launch(k_loss, n, (&x, &w, &out), dev)
    };
    let report = wp::gradcheck(&mut forward, &[a.values(), &b], &[&out], opts()).unwrap();
    assert!(report.passed, "{method:?}: worst {:?}", report.worst);
    let inputs = a.nnz_bound() + n;
    let reached = (0..inputs)
        .filter(|&c| report.analytic.iter().any(|row| row[c].abs() > 1e-6))
        .count();
    assert_eq!(reached, inputs, "{method:?}");
}

fn bicgstab_gradcheck(dev: &wp::Device) {
    gradcheck_values(dev, Method::BiCgStab, tight());
}

fn gmres_gradcheck(dev: &wp::Device) {
    // A restart shorter than n: the forward and adjoint solves take several cycles.
    let o = SolveOptions {
        restart: 4,
        ..tight()
    };
    gradcheck_values(dev, Method::Gmres, o);
}

/// `A^-T w` by Gaussian elimination with partial pivoting on the host (`a` dense, row-major).
fn dense_solve_transposed(a: &[f64], n: usize, w: &[f64]) -> Vec<f64> {
    // The augmented [A^T | w].
    let mut m: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            let mut row: Vec<f64> = (0..n).map(|j| a[j * n + i]).collect();
            row.push(w[i]);
            row
        })
        .collect();
    for c in 0..n {
        let piv = (c..n)
            .max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs()))
            .unwrap();
        m.swap(c, piv);
        let pivot = m[c].clone();
        for row in &mut m[c + 1..] {
            let f = row[c] / pivot[c];
            for (e, p) in row[c..].iter_mut().zip(&pivot[c..]) {
                *e -= f * p;
            }
        }
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let s: f64 = (i + 1..n).map(|k| m[i][k] * x[k]).sum();
        x[i] = (m[i][n] - s) / m[i][i];
    }
    x
}

/// `|u - v|_inf <= tol (|v|_inf)`, saying what differs.
fn assert_close(what: &str, u: &[f64], v: &[f64], tol: f64) {
    assert_eq!(u.len(), v.len(), "{what}");
    let scale = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for (i, (a, b)) in u.iter().zip(v).enumerate() {
        assert!(
            (a - b).abs() <= tol * scale,
            "{what}[{i}]: {a} vs {b} (tolerance {tol} x {scale})"
        );
    }
}

/// For a linear loss `w . x` (seeded directly: `x.grad = w`), each solver's backward gives
/// `b.grad = A^-T w` and `A.grad_k = -b.grad_r x_c` on the stored blocks, against a dense
/// solve on the host (1e-10 relative: the solves stop at 1e-13 relative residual on a
/// matrix of condition number about 10). The solve's one record clears x's gradient.
fn adjoints_match_a_dense_solve(dev: &wp::Device) {
    let n = 7;
    let w = [0.3, -0.2, 0.5, 0.1, 0.7, -0.4, 0.25];
    for (method, symmetric) in [
        (Method::Cg, true),
        (Method::Cr, true),
        (Method::BiCgStab, false),
        (Method::Gmres, false),
    ] {
        // The symmetric case: A + A^T of the non-symmetric matrix's values.
        let base = nonsymmetric(n, dev);
        let a = if symmetric {
            let t = base.transpose().unwrap();
            let mut s = Bsr::identity(n, dev).unwrap();
            sparse::axpy(1.0, &base, 0.0, &mut s).unwrap();
            sparse::axpy(1.0, &t, 1.0, &mut s).unwrap();
            s
        } else {
            base
        }
        .with_grad()
        .unwrap();
        let dense = zeros::<f64, 2>((n, n), dev);
        a.to_dense(&dense).unwrap();
        let dense = host(&dense);
        let b = arr(&[1.0, -0.5, 0.25, 2.0, -1.0, 0.75, 0.5], dev)
            .with_grad()
            .unwrap();
        let x = zeros::<f64, 1>(n, dev).with_grad().unwrap();
        let tape = wp::Tape::new();
        // On the CPU, GMRES's forward and adjoint solves run captured (`Mode::Graph`: the
        // CPU replays the captured loop); on a GPU the solver suite covers that mode.
        let mode = match method {
            Method::Gmres if dev.is_cpu() => sparse::Mode::Graph,
            _ => sparse::Mode::Host,
        };
        {
            let _rec = tape.record();
            let o = SolveOptions { mode, ..tight() };
            let r = solve(method, &a, &b, &x, Precond::Jacobi, &o).unwrap();
            assert_eq!(r.stop, Stop::Converged, "{method:?}");
        }
        assert_eq!(tape.steps(), [format!("sparse::{method:?}").to_lowercase()]);
        x.grad().unwrap().copy_from(&arr(&w, dev)).unwrap();
        tape.backward_from_grads().unwrap();
        let lambda = dense_solve_transposed(&dense, n, &w);
        assert_close(
            &format!("{method:?} b.grad"),
            &host(&b.grad().unwrap()),
            &lambda,
            1e-10,
        );
        assert!(host(&x.grad().unwrap()).iter().all(|&g| g == 0.0));
        let xs = host(&x);
        let (offsets, columns) = (host(a.offsets()), host(a.columns()));
        let mut want = vec![0.0; a.nnz_bound()];
        for r in 0..n {
            for k in offsets[r] as usize..offsets[r + 1] as usize {
                want[k] = -lambda[r] * xs[columns[k] as usize];
            }
        }
        assert_close(
            &format!("{method:?} A.grad"),
            &host(&a.values().grad().unwrap()),
            &want,
            1e-10,
        );
    }
}

/// The same for a matrix of `DMat3` blocks (GMRES): the block outer product's layout
/// (glam's column-major blocks), and b's gradient, against the dense solve.
fn block_adjoint_matches_a_dense_solve(dev: &wp::Device) {
    let nb = 4;
    let n = 3 * nb;
    let (mut rows, mut cols, mut vals) = (vec![], vec![], vec![]);
    for i in 0..nb as i32 {
        for j in [i - 1, i, i + 1] {
            if (0..nb as i32).contains(&j) {
                let d = if i == j { 6.0 } else { 0.0 };
                let m = DMat3::from_cols_array(&std::array::from_fn(|e| {
                    let (r, c) = (e % 3, e / 3);
                    let v = 0.1 * ((i * 5 + j * 3 + r as i32 * 7 + c as i32 * 2) % 9) as f64;
                    v - 0.4 + if r == c { d } else { 0.0 }
                }));
                rows.push(i);
                cols.push(j);
                vals.push(m);
            }
        }
    }
    let a = Bsr::from_triplets(nb, nb, &arr(&rows, dev), &arr(&cols, dev), &arr(&vals, dev))
        .unwrap()
        .with_grad()
        .unwrap();
    let dense = zeros::<f64, 2>((n, n), dev);
    a.to_dense(&dense).unwrap();
    let dense = host(&dense);
    let b: Vec<f64> = (0..n).map(|i| ((i * 3) % 5) as f64 - 2.0).collect();
    let b = arr(&b, dev).with_grad().unwrap();
    let x = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        let r = sparse::gmres(&a, &b, &x, Precond::Jacobi, &tight()).unwrap();
        assert_eq!(r.stop, Stop::Converged);
    }
    let w: Vec<f64> = (0..n).map(|i| 0.1 * i as f64 - 0.5).collect();
    x.grad().unwrap().copy_from(&arr(&w, dev)).unwrap();
    tape.backward_from_grads().unwrap();
    let lambda = dense_solve_transposed(&dense, n, &w);
    assert_close("b.grad", &host(&b.grad().unwrap()), &lambda, 1e-10);
    let xs = host(&x);
    let (offsets, columns) = (host(a.offsets()), host(a.columns()));
    let grads: Vec<DMat3> = host(&a.values().grad().unwrap());
    let (mut got, mut want) = (vec![], vec![]);
    for r in 0..nb {
        for k in offsets[r] as usize..offsets[r + 1] as usize {
            let c = columns[k] as usize;
            for i in 0..3 {
                for j in 0..3 {
                    got.push(grads[k].col(j)[i]);
                    want.push(-lambda[3 * r + i] * xs[3 * c + j]);
                }
            }
        }
    }
    assert_close("A.grad", &got, &want, 1e-10);
}

/// `out[0] += w_k . A_k` over the stored blocks (slot k = tid): a linear loss of the blocks.
#[wp::kernel]
fn k_blocks_dot(a: Bsr<f64>, w: Array<f64>, out: Array<f64>) {
    let k = tid() as i32;
    if k < bsr_nnz(a) {
        atomic_add(out, 0, w[k] * bsr_block(a, k));
    }
}

/// The assembly's adjoint, exactly: each triplet's gradient is its block's (duplicates share
/// one), with a host count and with a device count (triplets past it get none).
fn assembly_adjoint_is_exact(dev: &wp::Device) {
    let rows = [2, 0, 2, 1, 0, 2, 1];
    let cols = [1, 0, 1, 2, 0, 0, 2];
    let vals = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
    // Blocks in (row, col) order: (0,0) <- t 1, 4; (1,2) <- 3, 6; (2,0) <- 5; (2,1) <- 0, 2.
    let block_of = [3, 0, 3, 1, 0, 2, 1];
    let w = arr(&[0.5, -1.25, 2.0, 0.75, 9.0, 9.0, 9.0], dev);
    for count in [None, Some(5)] {
        let tv = arr(&vals, dev).with_grad().unwrap();
        let (r, c) = (arr(&rows, dev), arr(&cols, dev));
        let out = zeros::<f64, 1>(1, dev).with_grad().unwrap();
        let dc = arr(&[count.unwrap_or(0)], dev);
        let tape = wp::Tape::new();
        let a = {
            let _rec = tape.record();
            let a = match count {
                None => Bsr::from_triplets(3, 3, &r, &c, &tv).unwrap(),
                Some(_) => Bsr::from_triplets_n(3, 3, &r, &c, &tv, &dc).unwrap(),
            };
            assert!(a.values().requires_grad());
            wp::launch(k_blocks_dot, a.nnz_bound(), (&a, &w, &out), dev).unwrap();
            a
        };
        assert_eq!(tape.steps(), ["sparse::from_triplets", "k_blocks_dot"]);
        tape.backward(&out).unwrap();
        let wv = host(&w);
        let want: Vec<f64> = match count {
            None => block_of.iter().map(|&k| wv[k]).collect(),
            // The first five triplets: (0,0) <- 1, 4; (1,2) <- 3; (2,1) <- 0, 2.
            Some(_) => {
                let of = [2, 0, 2, 1, 0];
                (0..7)
                    .map(|t| if t < 5 { wv[of[t]] } else { 0.0 })
                    .collect()
            }
        };
        assert_eq!(host(&tv.grad().unwrap()), want, "count {count:?}");
        // The assembly wrote the matrix's values: their gradient is cleared.
        assert!(host(&a.values().grad().unwrap()).iter().all(|&g| g == 0.0));
        tape.zero().unwrap();
        assert!(host(&tv.grad().unwrap()).iter().all(|&g| g == 0.0));
    }
}

/// Gradcheck of `k_loss(y)` for `y = alpha A x + beta y0` (`y0` copied into y on the tape)
/// with respect to A's values, x and y0; `transposed`: `y = alpha A^T x + beta y0`.
fn gradcheck_mv(dev: &wp::Device, transposed: bool) {
    let n = 7;
    let a = nonsymmetric(n, dev).with_grad().unwrap();
    let x = arr(&[0.5, -1.0, 0.25, 1.5, -0.75, 0.1, 0.9], dev)
        .with_grad()
        .unwrap();
    let y0 = arr(&[1.0, 0.2, -0.3, 0.4, -0.5, 0.6, -0.7], dev)
        .with_grad()
        .unwrap();
    let y = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let w = arr(&[0.3, -0.2, 0.5, 0.1, 0.7, -0.4, 0.25], dev);
    let out = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let mut forward = || -> wp::Result<()> {
        wp::copy(&y, &y0)?;
        if transposed {
            sparse::mv_transpose(1.5, &a, &x, -0.5, &y)?;
        } else {
            sparse::mv(1.5, &a, &x, -0.5, &y)?;
        }
        wp::launch(k_loss, n, (&y, &w, &out), dev)
    };
    let report = wp::gradcheck(&mut forward, &[a.values(), &x, &y0], &[&out], opts()).unwrap();
    assert!(
        report.passed,
        "transposed {transposed}: worst {:?}",
        report.worst
    );
}

fn mv_gradcheck(dev: &wp::Device) {
    gradcheck_mv(dev, false);
}

fn mv_transpose_gradcheck(dev: &wp::Device) {
    gradcheck_mv(dev, true);
}

/// §12: backward through a solve that stopped before converging is an error naming the
/// solver, its stop, residual and tolerance; the gradients are left alone.
fn backward_through_an_unconverged_solve_is_refused(dev: &wp::Device) {
    let n = 7;
    for method in [Method::Cg, Method::Cr, Method::BiCgStab, Method::Gmres] {
        let base = nonsymmetric(n, dev);
        let a = match method {
            Method::Cg | Method::Cr => {
                let mut s = Bsr::identity(n, dev).unwrap();
                sparse::axpy(1.0, &base, 0.0, &mut s).unwrap();
                sparse::axpy(1.0, &base.transpose().unwrap(), 1.0, &mut s).unwrap();
                s
            }
            _ => base,
        };
        let b = arr(&[1.0, -0.5, 0.25, 2.0, -1.0, 0.75, 0.5], dev)
            .with_grad()
            .unwrap();
        let x = zeros::<f64, 1>(n, dev).with_grad().unwrap();
        let o = SolveOptions {
            max_iter: 2,
            restart: 2,
            ..tight()
        };
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            let r = solve(method, &a, &b, &x, Precond::None, &o).unwrap();
            assert_eq!(r.stop, Stop::MaxIterations, "{method:?}");
        }
        x.grad().unwrap().fill(1.0).unwrap();
        let e = tape.backward_from_grads().unwrap_err();
        assert!(matches!(e, wp::Error::NotDifferentiable { .. }), "{e:?}");
        let msg = e.to_string();
        let name = format!("sparse::{method:?}").to_lowercase();
        assert!(
            msg.contains(&name) && msg.contains("MaxIterations") && msg.contains("tolerance"),
            "{msg}"
        );
        assert!(host(&b.grad().unwrap()).iter().all(|&g| g == 0.0));
    }
}

/// An adjoint solve that does not converge is an error naming it: `b = 0` converges at
/// iteration 0 with `max_iter` 0 (x stays 0), but the adjoint `A^T lambda = x.grad` with
/// a nonzero seed cannot in 0 iterations.
fn unconverged_adjoint_solve_is_refused(dev: &wp::Device) {
    let a = nonsymmetric(5, dev);
    let b = zeros::<f64, 1>(5, dev).with_grad().unwrap();
    let x = zeros::<f64, 1>(5, dev).with_grad().unwrap();
    let o = SolveOptions {
        max_iter: 0,
        ..tight()
    };
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        let r = sparse::bicgstab(&a, &b, &x, Precond::Jacobi, &o).unwrap();
        assert_eq!(r.stop, Stop::Converged);
    }
    x.grad().unwrap().fill(1.0).unwrap();
    let msg = tape.backward_from_grads().unwrap_err().to_string();
    assert!(
        msg.contains("sparse::bicgstab") && msg.contains("adjoint solve"),
        "{msg}"
    );
}

/// `z = d r` element by element (a user preconditioner's kernel).
#[wp::kernel]
fn k_diag_apply(d: Array<f64>, r: Array<f64>, z: Array<f64>) {
    let i = tid();
    z[i] = d[i] * r[i];
}

/// A solve records one step, and only when x has a gradient: a user preconditioner's
/// launches reach no tape. The adjoint of a solve with a user preconditioner (run without
/// one) still gives `A^-T x̄` (against the dense solve, 1e-10 relative as above), and the
/// tape's zero clears the gradients the record reaches.
fn user_preconditioner_and_what_is_recorded(dev: &wp::Device) {
    let n = 7;
    let base = nonsymmetric(n, dev);
    let mut a = Bsr::identity(n, dev).unwrap();
    sparse::axpy(1.0, &base, 0.0, &mut a).unwrap();
    sparse::axpy(1.0, &base.transpose().unwrap(), 1.0, &mut a).unwrap();
    let a = a.with_grad().unwrap();
    let dense = zeros::<f64, 2>((n, n), dev);
    a.to_dense(&dense).unwrap();
    let dense = host(&dense);
    let d: Vec<f64> = (0..n).map(|i| 1.0 / dense[i * n + i]).collect();
    let d = arr(&d, dev);
    let pre = |r: &wp::Array<f64>, z: &wp::Array<f64>| wp::launch(k_diag_apply, n, (&d, r, z), dev);
    let b = arr(&[1.0, -0.5, 0.25, 2.0, -1.0, 0.75, 0.5], dev)
        .with_grad()
        .unwrap();
    let tape = wp::Tape::new();
    // x without a gradient: nothing to differentiate, nothing recorded.
    {
        let _rec = tape.record();
        let x = zeros::<f64, 1>(n, dev);
        sparse::cg(&a, &b, &x, &pre, &tight()).unwrap();
    }
    assert!(tape.is_empty(), "{:?}", tape.steps());
    let x = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    {
        let _rec = tape.record();
        let r = sparse::cg(&a, &b, &x, &pre, &tight()).unwrap();
        assert_eq!(r.stop, Stop::Converged);
    }
    assert_eq!(tape.steps(), ["sparse::cg"]);
    let w = [0.3, -0.2, 0.5, 0.1, 0.7, -0.4, 0.25];
    x.grad().unwrap().copy_from(&arr(&w, dev)).unwrap();
    tape.backward_from_grads().unwrap();
    let lambda = dense_solve_transposed(&dense, n, &w);
    assert_close("b.grad", &host(&b.grad().unwrap()), &lambda, 1e-10);
    assert!(host(&a.values().grad().unwrap()).iter().any(|&g| g != 0.0));
    tape.zero().unwrap();
    assert!(host(&b.grad().unwrap()).iter().all(|&g| g == 0.0));
    assert!(host(&a.values().grad().unwrap()).iter().all(|&g| g == 0.0));
}

/// The gradients of an assembly -> CG (Jacobi) solve, of a BiCGSTAB (Jacobi) solve, and of an
/// assembly of `Mat3` triplets -> CG in f32, seeded with `x̄ = w`: the triplets', b's and the
/// blocks' gradients, as bits.
fn seeded_gradients(dev: &wp::Device) -> Vec<u64> {
    let n = 6;
    let pairs = [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (0, 3)];
    let (rows, cols, src) = symmetric_pattern(n, &pairs);
    let p = [
        3.0, 3.1, 3.2, 3.3, 3.4, 3.5, 0.5, -0.4, 0.3, 0.45, -0.35, 0.2,
    ];
    let tv: Vec<f64> = src.iter().map(|&k| p[k as usize]).collect();
    let tv = arr(&tv, dev).with_grad().unwrap();
    let w = [0.3, -0.2, 0.5, 0.1, 0.7, -0.4, 0.25];
    let mut bits = vec![];
    let tape = wp::Tape::new();
    let b = arr(&[1.0, -0.5, 0.25, 2.0, -1.0, 0.75], dev)
        .with_grad()
        .unwrap();
    let x = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    {
        let _rec = tape.record();
        let a = Bsr::from_triplets(n, n, &arr(&rows, dev), &arr(&cols, dev), &tv).unwrap();
        sparse::cg(&a, &b, &x, Precond::Jacobi, &tight()).unwrap();
    }
    x.grad().unwrap().copy_from(&arr(&w[..n], dev)).unwrap();
    tape.backward_from_grads().unwrap();
    for g in [tv.grad().unwrap(), b.grad().unwrap()] {
        bits.extend(host(&g).iter().map(|v| v.to_bits()));
    }
    let a = nonsymmetric(7, dev).with_grad().unwrap();
    let b = arr(&[1.0, -0.5, 0.25, 2.0, -1.0, 0.75, 0.5], dev)
        .with_grad()
        .unwrap();
    let x = zeros::<f64, 1>(7, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        sparse::bicgstab(&a, &b, &x, Precond::Jacobi, &tight()).unwrap();
    }
    x.grad().unwrap().copy_from(&arr(&w, dev)).unwrap();
    tape.backward_from_grads().unwrap();
    for g in [b.grad().unwrap(), a.values().grad().unwrap()] {
        bits.extend(host(&g).iter().map(|v| v.to_bits()));
    }
    // f32 and 3 x 3 blocks: a symmetric block tridiagonal matrix assembled from `Mat3`
    // triplets with a gradient ((i, j) gets M, (j, i) its transpose), solved by CG.
    let nb = 5;
    let (mut rows, mut cols, mut vals) = (vec![], vec![], vec![]);
    for i in 0..nb as i32 {
        let d = Mat3::from_diagonal(Vec3::splat(6.0 + i as f32));
        rows.push(i);
        cols.push(i);
        vals.push(d);
        if i + 1 < nb as i32 {
            let m = Mat3::from_cols_array(&std::array::from_fn(|e| {
                0.1 * ((i as usize * 5 + e * 3) % 7) as f32 - 0.3
            }));
            rows.extend([i, i + 1]);
            cols.extend([i + 1, i]);
            vals.extend([m, m.transpose()]);
        }
    }
    let tv = arr(&vals, dev).with_grad().unwrap();
    let b: Vec<f32> = (0..3 * nb).map(|i| ((i * 3) % 5) as f32 - 2.0).collect();
    let b = arr(&b, dev).with_grad().unwrap();
    let x = zeros::<f32, 1>(3 * nb, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        let a = Bsr::from_triplets(nb, nb, &arr(&rows, dev), &arr(&cols, dev), &tv).unwrap();
        let o = SolveOptions {
            rtol: 1e-6,
            ..Default::default()
        };
        let r = sparse::cg(&a, &b, &x, Precond::Jacobi, &o).unwrap();
        assert_eq!(r.stop, Stop::Converged);
    }
    let w: Vec<f32> = (0..3 * nb).map(|i| 0.25 * i as f32 - 1.0).collect();
    x.grad().unwrap().copy_from(&arr(&w, dev)).unwrap();
    tape.backward_from_grads().unwrap();
    let tg: Vec<Mat3> = host(&tv.grad().unwrap());
    bits.extend(
        tg.iter()
            .flat_map(|m| m.to_cols_array())
            .map(|v| v.to_bits() as u64),
    );
    bits.extend(host(&b.grad().unwrap()).iter().map(|v| v.to_bits() as u64));
    bits
}

/// The gradients of the solves and the assembly are the same bits on every device as on
/// the CPU (the adjoint solves, with built-in preconditioners, and the adjoint steps run the
/// same operations in the same order everywhere).
fn gradients_are_the_cpus_bits(dev: &wp::Device) {
    assert_eq!(seeded_gradients(dev), seeded_gradients(&wp::cpu()));
}
