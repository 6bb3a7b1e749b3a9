//! The sparse tier's benchmark (issue 34, slice 9): matrix-vector products and Jacobi-
//! preconditioned CG on a GPU against NVIDIA Warp 1.19 (`warp.sparse`, `warp.optim.linear`)
//! and cuSPARSE through CuPy, timed on the same GPU in the same run on the same matrices; and
//! on the CPU against a plain rayon CSR product and CG loop written here.
//!
//! ```text
//! cargo bench --features sparse --bench sparse            # GPU sections SKIPPED without a GPU
//! cargo bench --features sparse --bench sparse -- --quick # smaller sizes (the CPU run: ~1 min)
//! # on a GPU machine, with Warp 1.19 (and CuPy, for cuSPARSE) importable by python3:
//! cargo bench --features sparse --bench sparse -- [--quick] [--gpu-only | --cpu-only] [--cg-all]
//!     [--only poisson2|poisson3|elasticity ..]
//! # the Python side is benches/py/sparse.py from the working directory, or $SPARSE_BENCH_PY
//! ```
//!
//! Matrices, each in f32 and f64: the 2-D 5-point Poisson matrix on n x n interior nodes
//! (n = 1024, 2048, 4096: 1M to 16M unknowns; diagonal 4, -1 to each neighbour in the grid),
//! the 3-D 7-point one on n^3 (n = 100, 160, 252: 1M to 16M), and the elasticity matrix of
//! `examples/common/fem.rs` (P1 tetrahedra on the unit cube, 3 x 3 blocks, boundary rows the
//! identity's; 68 and 109 cells per side: 0.99M and 3.99M unknowns), assembled on the GPU in
//! f64 (f32: its values rounded).
//!
//! For each matrix the bench writes offsets, columns, the f64 values and a random x into a
//! temporary directory and runs `benches/py/sparse.py` (its last line JSON), which times
//! Warp's `bsr_mv` on `bsr_from_triplets` of the same blocks and cuSPARSE's SpMV through CuPy
//! (`csr_matrix @ x`; the 3 x 3 case expanded to a scalar CSR of 9 entries per block, as its
//! row says). A side that cannot run (no Warp, no CuPy) says why on its row.
//! - **mv**, `y = A x`: GPU milliseconds between CUDA events on every side, median of `REPS`
//!   after a warm-up, two ways: around one call, which also holds the host's dispatch of the
//!   call (the GPU waits for it: a few microseconds from Rust, tens from Python, which
//!   dominate at 1M unknowns), and around `BATCH` calls queued back to back, per call (the
//!   device's time once the host queues calls faster than the GPU runs them; the verdicts
//!   are given for both); GB/s over the compulsory bytes of the block form (offsets,
//!   columns and values read once, x read once, y written), against the peak of the device
//!   attributes (memory clock x bus width x 2) and against a device-to-device copy timed in
//!   the same run; the error max |y - y_ref| / max |y_ref| against the f64 product on the
//!   host. Ours also with 2 to 32 lanes per scalar row (`sparse::set_mv_lanes`).
//! - **CG** from 0 with b = x to |r| <= 1e-6 |b| with point Jacobi (`Precond::PointJacobi`:
//!   the same preconditioner as Warp's `preconditioner(A, "diag")` and CuPy's diagonal
//!   operator; the 3 x 3 case also with block Jacobi): ours in `Mode::Graph` (one captured
//!   graph of the set-up and a conditional loop), Warp's `cg(check_every=0)` and CuPy's
//!   `cupyx.scipy.sparse.linalg.cg`. Wall milliseconds of the whole call on every side (the
//!   host's work, allocation and capture included, synchronised; CuPy's loop reads the
//!   residual back every iteration), median of 3 after a warm-up; iterations; the true
//!   residual |b - A x| / |b| in f64 against the f64 matrix. By default at the first size of
//!   each family (`--cg-all`: every size).
//!
//! Verdict lines per matrix and dtype: mv within 1.2x cuSPARSE's time, no slower than Warp's,
//! and its GB/s as a fraction of the peak.
//!
//! CPU section (`wp::cpu()`, all cores): at about 1M unknowns (2-D 1024^2 and 3-D 100^3;
//! `--quick`: 512^2 and 50^3) ours against a rayon CSR product (a row per task, the same
//! order of sums) and a plain rayon PCG loop (the textbook one: a pass per vector operation,
//! rayon sums for the dots), each row with its error.

use rayon::prelude::*;
#[cfg(feature = "cuda")]
use std::path::Path;
use std::time::Instant;
use warp_lang as wp;
use wp::prelude::*;
use wp::sparse::{self, Block, Bsr, Mode, Precond, SolveOptions, SparseScalar, SquareBlock};

mod common;

/// The elasticity matrix is the FEM scene's (its element and boundary kernels).
#[path = "../examples/common/fem.rs"]
mod fem;

#[cfg(feature = "cuda")]
use common::{event_ms, event_ms_per_call};
use common::{median_of, REPS};

/// Relative tolerance of every CG solve.
const RTOL: f64 = 1e-6;
/// Iteration cap of every CG solve (the 2-D Poisson at 1024^2 needs about 3,500).
const MAX_ITER: usize = 20_000;
/// Timed CG solves (after a warm-up); the median is printed.
const CG_REPS: usize = 3;

/// A matrix on the host: block CSR of `block x block` blocks (1 or 3), f64 values, each
/// block row-major.
struct Csr {
    name: String,
    block: usize,
    nrow: usize,
    offsets: Vec<i32>,
    columns: Vec<i32>,
    values: Vec<f64>,
}

impl Csr {
    fn nnz(&self) -> usize {
        self.columns.len()
    }

    /// Scalar unknowns.
    fn unknowns(&self) -> usize {
        self.nrow * self.block
    }

    /// The block row of each stored block (the triplets' rows).
    fn rows(&self) -> Vec<i32> {
        (0..self.nrow)
            .flat_map(|r| {
                let n = (self.offsets[r + 1] - self.offsets[r]) as usize;
                std::iter::repeat_n(r as i32, n)
            })
            .collect()
    }

    /// `A x` in f64 (x of `unknowns()` scalars), a block row per task.
    fn mv_f64(&self, x: &[f64]) -> Vec<f64> {
        let b = self.block;
        let mut y = vec![0.0; self.unknowns()];
        y.par_chunks_mut(b).enumerate().for_each(|(r, yr)| {
            for k in self.offsets[r] as usize..self.offsets[r + 1] as usize {
                let c = self.columns[k] as usize;
                let blk = &self.values[k * b * b..(k + 1) * b * b];
                for (i, yi) in yr.iter_mut().enumerate() {
                    for j in 0..b {
                        *yi += blk[i * b + j] * x[c * b + j];
                    }
                }
            }
        });
        y
    }

    /// `|b - A x| / |b|` in f64.
    fn residual(&self, b: &[f64], x: &[f64]) -> f64 {
        let ax = self.mv_f64(x);
        let r: f64 = b.iter().zip(&ax).map(|(b, a)| (b - a) * (b - a)).sum();
        let n: f64 = b.iter().map(|b| b * b).sum();
        (r / n).sqrt()
    }

    /// The scalar diagonal.
    fn diagonal(&self) -> Vec<f64> {
        let b = self.block;
        let mut d = vec![0.0; self.unknowns()];
        for r in 0..self.nrow {
            for k in self.offsets[r] as usize..self.offsets[r + 1] as usize {
                if self.columns[k] as usize == r {
                    for i in 0..b {
                        d[r * b + i] = self.values[k * b * b + i * b + i];
                    }
                }
            }
        }
        d
    }

    /// Bytes an mv must move at least: offsets, columns and values read once, x read once,
    /// y written (in scalars of `scalar` bytes).
    fn compulsory_bytes(&self, scalar: usize) -> f64 {
        let b = self.block;
        ((self.nrow + 1) * 4
            + self.nnz() * 4
            + self.nnz() * b * b * scalar
            + 2 * self.unknowns() * scalar) as f64
    }
}

/// The 5-point Laplacian on `n x n` interior nodes (Dirichlet boundary eliminated).
fn poisson2(n: usize) -> Csr {
    let nrow = n * n;
    let mut m = Csr {
        name: format!("Poisson 2-D {n}^2"),
        block: 1,
        nrow,
        offsets: Vec::with_capacity(nrow + 1),
        columns: Vec::with_capacity(5 * nrow),
        values: Vec::with_capacity(5 * nrow),
    };
    m.offsets.push(0);
    for j in 0..n {
        for i in 0..n {
            let r = (i + n * j) as i32;
            let n = n as i32;
            let (i, j) = (i as i32, j as i32);
            for (ok, c, v) in [
                (j > 0, r - n, -1.0),
                (i > 0, r - 1, -1.0),
                (true, r, 4.0),
                (i + 1 < n, r + 1, -1.0),
                (j + 1 < n, r + n, -1.0),
            ] {
                if ok {
                    m.columns.push(c);
                    m.values.push(v);
                }
            }
            m.offsets.push(m.columns.len() as i32);
        }
    }
    m
}

/// The 7-point Laplacian on `n^3` interior nodes.
fn poisson3(n: usize) -> Csr {
    let nrow = n * n * n;
    let mut m = Csr {
        name: format!("Poisson 3-D {n}^3"),
        block: 1,
        nrow,
        offsets: Vec::with_capacity(nrow + 1),
        columns: Vec::with_capacity(7 * nrow),
        values: Vec::with_capacity(7 * nrow),
    };
    m.offsets.push(0);
    let (s1, s2) = (n as i64, (n * n) as i64);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let r = (i + n * (j + n * k)) as i64;
                let last = n - 1;
                for (ok, c, v) in [
                    (k > 0, r - s2, -1.0),
                    (j > 0, r - s1, -1.0),
                    (i > 0, r - 1, -1.0),
                    (true, r, 6.0),
                    (i < last, r + 1, -1.0),
                    (j < last, r + s1, -1.0),
                    (k < last, r + s2, -1.0),
                ] {
                    if ok {
                        m.columns.push(c as i32);
                        m.values.push(v);
                    }
                }
                m.offsets.push(m.columns.len() as i32);
            }
        }
    }
    m
}

#[cfg(feature = "cuda")]
/// The FEM scene's elasticity matrix with `n` cells per side (3 (n + 1)^3 unknowns),
/// assembled on `dev` in f64 and read back.
fn elasticity(n: usize, dev: &wp::Device) -> wp::Result<Csr> {
    let nodes = (n + 1).pow(3);
    let elements = 6 * n.pow(3);
    let triplets = 16 * elements + nodes;
    let ni = n as i32;
    let (rows, cols) = (
        wp::Array::<i32>::zeros(triplets, dev)?,
        wp::Array::<i32>::zeros(triplets, dev)?,
    );
    let vals = wp::Array::<DMat3>::zeros(triplets, dev)?;
    // The load triplets are written too; with no quadrature points (nq = 0) they are zero.
    let load_rows = wp::Array::<i32>::zeros(12 * elements, dev)?;
    let load_vals = wp::Array::<f64>::zeros(12 * elements, dev)?;
    let quad = wp::Array::from_slice(&[DVec4::ZERO], dev)?;
    let args = (ni, &quad, 0i32, &rows, &cols, &vals, &load_rows, &load_vals);
    wp::launch(fem::elastic_element, elements, args, dev)?;
    drop((load_rows, load_vals));
    let offset = (16 * elements) as i32;
    let diag = (ni, offset, &rows, &cols, &vals);
    wp::launch(fem::node_diagonal_block, nodes, diag, dev)?;
    let a = Bsr::from_triplets(nodes, nodes, &rows, &cols, &vals)?;
    drop((rows, cols, vals));
    let nnz = a.nnz()?;
    let offsets = a.offsets().to_vec()?;
    // The stored blocks alone (the capacity is one block per triplet).
    let columns = a.columns().view(..nnz)?.to_vec()?;
    let blocks = a.values().view(..nnz)?.to_vec()?;
    let values = blocks
        .iter()
        .flat_map(|m| m.transpose().to_cols_array()) // glam is column-major: rows of m
        .collect();
    Ok(Csr {
        name: format!("elasticity {n}^3 cells (3x3)"),
        block: 3,
        nrow: nodes,
        offsets,
        columns,
        values,
    })
}

/// A block type of the bench: made from a row-major f64 block.
trait Case: SquareBlock {
    const LABEL: &'static str;
    fn from_row_major(v: &[f64]) -> Self;
}

impl Case for f32 {
    const LABEL: &'static str = "f32";
    fn from_row_major(v: &[f64]) -> Self {
        v[0] as f32
    }
}

impl Case for f64 {
    const LABEL: &'static str = "f64";
    fn from_row_major(v: &[f64]) -> Self {
        v[0]
    }
}

impl Case for Mat3 {
    const LABEL: &'static str = "f32";
    fn from_row_major(v: &[f64]) -> Self {
        let m = DMat3::from_cols_array(&v[..9].try_into().expect("9 scalars")).transpose();
        m.as_mat3()
    }
}

impl Case for DMat3 {
    const LABEL: &'static str = "f64";
    fn from_row_major(v: &[f64]) -> Self {
        DMat3::from_cols_array(&v[..9].try_into().expect("9 scalars")).transpose()
    }
}

/// Our matrix of `m` on `dev` from its triplets.
fn to_device<B: Case>(m: &Csr, dev: &wp::Device) -> wp::Result<Bsr<B>> {
    let bs = m.block * m.block;
    let vals: Vec<B> = m.values.chunks(bs).map(B::from_row_major).collect();
    let a = Bsr::from_triplets(
        m.nrow,
        m.nrow,
        &wp::Array::from_slice(&m.rows(), dev)?,
        &wp::Array::from_slice(&m.columns, dev)?,
        &wp::Array::from_slice(&vals, dev)?,
    )?;
    let nnz = a.nnz()?;
    if nnz != m.nnz() {
        return Err(wp::Error::InvalidArgument {
            what: format!(
                "sparse bench: {} assembled to {nnz} blocks, not {}",
                m.name,
                m.nnz()
            ),
        });
    }
    Ok(a)
}

fn scalars<S: SparseScalar>(v: &[f64]) -> Vec<S> {
    v.iter().map(|&x| S::from_f64(x)).collect()
}

fn to_f64<S: SparseScalar>(v: &[S]) -> Vec<f64> {
    v.iter().map(|x| x.to_f64()).collect()
}

/// max |y - r| / max |r|.
fn rel_err(y: &[f64], r: &[f64]) -> f64 {
    let scale = r.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let d = y
        .iter()
        .zip(r)
        .fold(0.0f64, |a, (y, r)| a.max((y - r).abs()));
    d / scale
}

/// A random vector in [-1, 1) (the mv's x, and every solve's b).
fn random_vector(n: usize, seed: u64) -> Vec<f64> {
    use rand::Rng as _;
    let mut r = common::rng(seed);
    (0..n).map(|_| 2.0 * r.random::<f64>() - 1.0).collect()
}

/// What one CG solve of ours measured.
struct CgRun {
    ms: f64,
    iterations: usize,
    residual: f64,
    note: String,
}

/// Our CG (`Mode::Graph`, falling back to `Mode::Host` where the device has no conditional
/// graph nodes): a warm-up, then the median of `CG_REPS` whole calls from x = 0.
fn cg_ours<B: Case>(m: &Csr, a: &Bsr<B>, b64: &[f64], precond: Precond) -> wp::Result<CgRun> {
    let dev = a.device().clone();
    let b = wp::Array::from_slice(&scalars::<B::Scalar>(b64), &dev)?;
    let x = wp::Array::<B::Scalar>::zeros(m.unknowns(), &dev)?;
    let mut o = SolveOptions {
        rtol: RTOL,
        max_iter: MAX_ITER,
        check_every: 10,
        mode: Mode::Graph,
        ..SolveOptions::default()
    };
    let mut note = String::from("Mode::Graph");
    let warm = sparse::cg(a, &b, &x, precond, &o);
    if let Err(e) = warm {
        note = format!("Mode::Host (Graph: {e})");
        o.mode = Mode::Host;
    }
    let mut times = Vec::new();
    let mut report = None;
    for _ in 0..CG_REPS {
        x.fill(B::Scalar::ZERO)?;
        wp::synchronize()?;
        let t = Instant::now();
        let r = sparse::cg(a, &b, &x, precond, &o)?;
        wp::synchronize()?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        report = Some(r);
    }
    let report = report.expect("CG_REPS > 0");
    if !report.converged {
        note.push_str(&format!(", stopped: {:?}", report.stop));
    }
    let xs = to_f64(&x.to_vec()?);
    Ok(CgRun {
        ms: median_of(times),
        iterations: report.iterations,
        residual: m.residual(b64, &xs),
        note,
    })
}

fn main() -> wp::Result<()> {
    wp::init();
    let args: Vec<String> = std::env::args().collect();
    let flag = |f: &str| args.iter().any(|a| a == f);
    let quick = flag("--quick");
    println!(
        "sparse bench{}: mv and Jacobi CG to rtol {RTOL:e}",
        if quick { " (--quick)" } else { "" }
    );
    if !flag("--cpu-only") {
        gpu_section(quick, flag("--cg-all"))?;
    }
    if !flag("--gpu-only") {
        cpu_section(quick)?;
    }
    Ok(())
}

// ------------------------------------------------------------------------------------------
// GPU
// ------------------------------------------------------------------------------------------

#[cfg(not(feature = "cuda"))]
fn gpu_section(_quick: bool, _cg_all: bool) -> wp::Result<()> {
    println!("GPU sections SKIPPED: built without the `cuda` feature");
    Ok(())
}

/// The device's peak bandwidth from its attributes, GB/s: memory clock (kHz) x bus width
/// (bits) / 8 x 2 (double data rate), or why not.
#[cfg(feature = "cuda")]
fn peak_gbs(ordinal: usize) -> Result<f64, String> {
    use warp_cuda::cudarc::driver::{result, sys::CUdevice_attribute as A};
    result::init().map_err(|e| format!("cuInit: {e}"))?;
    let d = result::device::get(ordinal as i32).map_err(|e| format!("cuDeviceGet: {e}"))?;
    // SAFETY: a device handle just obtained from the driver.
    let attr = |a| unsafe { result::device::get_attribute(d, a) };
    let clock = attr(A::CU_DEVICE_ATTRIBUTE_MEMORY_CLOCK_RATE).map_err(|e| format!("{e}"))?;
    let bus = attr(A::CU_DEVICE_ATTRIBUTE_GLOBAL_MEMORY_BUS_WIDTH).map_err(|e| format!("{e}"))?;
    if clock <= 0 || bus <= 0 {
        return Err(format!("memory clock {clock} kHz, bus {bus} bits"));
    }
    Ok(2.0 * clock as f64 * 1e3 * (bus as f64 / 8.0) / 1e9)
}

/// Calls per timing of the back-to-back figures.
#[cfg(feature = "cuda")]
const BATCH: usize = 50;

/// The bandwidth of a device-to-device copy of 1 GiB (read + write), GB/s.
#[cfg(feature = "cuda")]
fn copy_gbs(dev: &wp::Device) -> wp::Result<f64> {
    let n = 1usize << 28; // f32s: 1 GiB
    let (a, b) = (
        wp::Array::<f32>::zeros(n, dev)?,
        wp::Array::<f32>::zeros(n, dev)?,
    );
    let ms = event_ms(dev, || b.copy_from(&a))?;
    Ok(2.0 * (4 * n) as f64 / (ms * 1e-3) / 1e9)
}

#[cfg(feature = "cuda")]
struct Peaks {
    attr: Option<f64>,
    copy: f64,
}

#[cfg(feature = "cuda")]
impl Peaks {
    fn describe(&self, gbs: f64) -> String {
        let attr = self.attr.map_or(String::new(), |p| {
            format!("{:4.1}% of peak, ", 100.0 * gbs / p)
        });
        format!(
            "{gbs:6.0} GB/s ({attr}{:4.1}% of copy)",
            100.0 * gbs / self.copy
        )
    }
}

#[cfg(feature = "cuda")]
fn gpu_section(quick: bool, cg_all: bool) -> wp::Result<()> {
    // `--only poisson2|poisson3|elasticity` (repeatable): those families alone.
    let args: Vec<String> = std::env::args().collect();
    let only: Vec<&str> = args
        .windows(2)
        .filter(|w| w[0] == "--only")
        .map(|w| w[1].as_str())
        .collect();
    let wanted = |f: &str| only.is_empty() || only.contains(&f);
    let dev = match wp::get_device("cuda:0") {
        Ok(d) => d,
        Err(e) => {
            println!("GPU sections SKIPPED: no CUDA device ({e})");
            return Ok(());
        }
    };
    println!("GPU: {dev} ({})", dev.name());
    let attr = peak_gbs(0);
    let copy = copy_gbs(&dev)?;
    match &attr {
        Ok(p) => println!(
            "peak bandwidth {p:.0} GB/s (memory clock x bus width x 2); a device copy of 1 GiB \
             reaches {copy:.0} GB/s ({:.0}%)",
            100.0 * copy / p
        ),
        Err(e) => println!(
            "peak bandwidth from the device attributes not available ({e}); a device copy of \
             1 GiB reaches {copy:.0} GB/s"
        ),
    }
    let peaks = Peaks {
        attr: attr.ok(),
        copy,
    };
    let (p2, p3, el): (&[usize], &[usize], &[usize]) = if quick {
        (&[1024], &[100], &[68])
    } else {
        (&[1024, 2048, 4096], &[100, 160, 252], &[68, 109])
    };
    let dir = std::env::temp_dir().join(format!("warp-sparse-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| io_err(&dir, e))?;
    // Each matrix is made when its turn comes (the largest take GBs of host memory).
    type Make = Box<dyn Fn() -> wp::Result<Csr>>;
    let mut families: Vec<(usize, Make)> = Vec::new();
    let none: &[usize] = &[];
    let (p2, p3, el) = (
        if wanted("poisson2") { p2 } else { none },
        if wanted("poisson3") { p3 } else { none },
        if wanted("elasticity") { el } else { none },
    );
    for (i, &n) in p2.iter().enumerate() {
        families.push((i, Box::new(move || Ok(poisson2(n)))));
    }
    for (i, &n) in p3.iter().enumerate() {
        families.push((i, Box::new(move || Ok(poisson3(n)))));
    }
    for (i, &n) in el.iter().enumerate() {
        let d = dev.clone();
        families.push((i, Box::new(move || elasticity(n, &d))));
    }
    let t0 = Instant::now();
    for (index, make) in &families {
        let m = make()?;
        let with_cg = cg_all || *index == 0;
        gpu_matrix(&m, &dev, &dir, &peaks, with_cg)?;
        println!(
            "  ({:.0} s into the GPU section)",
            t0.elapsed().as_secs_f64()
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

#[cfg(feature = "cuda")]
fn io_err(path: &Path, e: std::io::Error) -> wp::Error {
    wp::Error::InvalidArgument {
        what: format!("sparse bench: {}: {e}", path.display()),
    }
}

#[cfg(feature = "cuda")]
fn write_raw<T: bytemuck::Pod>(dir: &Path, name: &str, v: &[T]) -> wp::Result<()> {
    let p = dir.join(name);
    std::fs::write(&p, bytemuck::cast_slice(v)).map_err(|e| io_err(&p, e))
}

/// One matrix on the GPU: its files, the Python sides, then ours in f32 and f64.
#[cfg(feature = "cuda")]
fn gpu_matrix(
    m: &Csr,
    dev: &wp::Device,
    dir: &Path,
    peaks: &Peaks,
    with_cg: bool,
) -> wp::Result<()> {
    println!(
        "\n== {}: {} unknowns, {} stored blocks of {b}x{b} ==",
        m.name,
        m.unknowns(),
        m.nnz(),
        b = m.block
    );
    let x = random_vector(m.unknowns(), 0x5eed_0000 ^ m.nnz() as u64);
    write_raw(dir, "offsets.i32", &m.offsets)?;
    write_raw(dir, "columns.i32", &m.columns)?;
    write_raw(dir, "values.f64", &m.values)?;
    write_raw(dir, "x.f64", &x)?;
    let py_args: Vec<String> = [
        "--dir",
        &dir.display().to_string(),
        "--block",
        &m.block.to_string(),
        "--nrow",
        &m.nrow.to_string(),
        "--reps",
        &REPS.to_string(),
        "--cg",
        if with_cg { "1" } else { "0" },
        "--cg-reps",
        &CG_REPS.to_string(),
        "--rtol",
        &RTOL.to_string(),
        "--maxiter",
        &MAX_ITER.to_string(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let t = Instant::now();
    let theirs = common::python_side(&script_path(), &py_args);
    match &theirs {
        Ok(j) => println!(
            "Python side ({:.0} s): Warp {}, CuPy {}",
            t.elapsed().as_secs_f64(),
            j.get("warp")
                .and_then(|v| v.as_str())
                .map_or_else(|| side_error(j, "warp"), str::to_string),
            j.get("cupy")
                .and_then(|v| v.as_str())
                .map_or_else(|| side_error(j, "cupy"), str::to_string),
        ),
        Err(e) => println!("Python side not run: {e}"),
    }
    let y_ref = m.mv_f64(&x);
    if m.block == 1 {
        gpu_case::<f32>(m, dev, &x, &y_ref, theirs.as_ref().ok(), peaks, with_cg)?;
        gpu_case::<f64>(m, dev, &x, &y_ref, theirs.as_ref().ok(), peaks, with_cg)?;
    } else {
        gpu_case::<Mat3>(m, dev, &x, &y_ref, theirs.as_ref().ok(), peaks, with_cg)?;
        gpu_case::<DMat3>(m, dev, &x, &y_ref, theirs.as_ref().ok(), peaks, with_cg)?;
    }
    for f in ["offsets.i32", "columns.i32", "values.f64", "x.f64"] {
        let _ = std::fs::remove_file(dir.join(f));
    }
    Ok(())
}

#[cfg(feature = "cuda")]
/// Where the Python side is: `SPARSE_BENCH_PY`, else `benches/py/sparse.py` from the
/// repository root (the working directory of `cargo bench`).
fn script_path() -> String {
    std::env::var("SPARSE_BENCH_PY").unwrap_or_else(|_| "benches/py/sparse.py".into())
}

#[cfg(feature = "cuda")]
/// Why a Python side did not run: its top-level error.
fn side_error(j: &serde_json::Value, side: &str) -> String {
    format!(
        "not run ({})",
        j.get(format!("{side}_error"))
            .and_then(|v| v.as_str())
            .unwrap_or("no reason given")
    )
}

#[cfg(feature = "cuda")]
/// One row of another side: its figure, or why it has none.
fn their_row(
    j: Option<&serde_json::Value>,
    dtype: &str,
    side: &str,
    key: &str,
) -> Result<f64, String> {
    let Some(j) = j else {
        return Err("the Python side did not run".into());
    };
    if let Some(e) = j.get(format!("{side}_error")).and_then(|v| v.as_str()) {
        return Err(e.to_string());
    }
    let sec = j.get(dtype).ok_or("no section for the dtype")?;
    if let Some(e) = sec.get(format!("{side}_error")).and_then(|v| v.as_str()) {
        return Err(e.to_string());
    }
    sec.get(format!("{side}_{key}"))
        .and_then(|v| v.as_f64())
        .ok_or_else(|| format!("no `{side}_{key}`"))
}

#[cfg(feature = "cuda")]
#[allow(clippy::too_many_arguments)]
fn gpu_case<B: Case>(
    m: &Csr,
    dev: &wp::Device,
    x64: &[f64],
    y_ref: &[f64],
    theirs: Option<&serde_json::Value>,
    peaks: &Peaks,
    with_cg: bool,
) -> wp::Result<()> {
    let d = B::LABEL;
    let scalar = std::mem::size_of::<B::Scalar>();
    let bytes = m.compulsory_bytes(scalar);
    let a = to_device::<B>(m, dev)?;
    let x = wp::Array::from_slice(&scalars::<B::Scalar>(x64), dev)?;
    let y = wp::Array::<B::Scalar>::zeros(m.unknowns(), dev)?;
    let (xv, yv) = (x.reinterpret::<B::In>()?, y.reinterpret::<B::Out>()?);
    let one = B::Scalar::ONE;
    let ours = event_ms(dev, || sparse::mv(one, &a, &xv, B::Scalar::ZERO, &yv))?;
    let ours_b2b = event_ms_per_call(dev, BATCH, || {
        sparse::mv(one, &a, &xv, B::Scalar::ZERO, &yv)
    })?;
    let err = rel_err(&to_f64(&y.to_vec()?), y_ref);
    let gbs = |ms: f64| bytes / (ms * 1e-3) / 1e9;
    println!(
        "{d} mv (compulsory {:.0} MB; one call between CUDA events, its host dispatch \
         included; then {BATCH} calls back to back, per call: the device's time)",
        bytes / 1e6
    );
    println!(
        "  {:<30} {ours:8.3} ms  {}  err {err:.1e}",
        "ours",
        peaks.describe(gbs(ours))
    );
    println!(
        "  {:<30} {ours_b2b:8.3} ms  {}",
        "  back to back",
        peaks.describe(gbs(ours_b2b))
    );
    let row = |label: &str, side: &str| -> (Option<f64>, Option<f64>) {
        match (
            their_row(theirs, d, side, "mv_ms"),
            their_row(theirs, d, side, "mv_err"),
        ) {
            (Ok(ms), Ok(e)) => {
                println!(
                    "  {label:<30} {ms:8.3} ms  {}  err {e:.1e}   ours/theirs {:.2}",
                    peaks.describe(gbs(ms)),
                    ours / ms
                );
                let b2b = their_row(theirs, d, side, "mv_b2b_ms").ok();
                if let Some(b) = b2b {
                    println!(
                        "  {:<30} {b:8.3} ms  {}   ours/theirs {:.2}",
                        "  back to back",
                        peaks.describe(gbs(b)),
                        ours_b2b / b
                    );
                }
                (Some(ms), b2b)
            }
            (Err(e), _) | (_, Err(e)) => {
                println!("  {label:<30} not run: {e}");
                (None, None)
            }
        }
    };
    // Our product with w lanes per scalar row (`sparse::set_mv_lanes`; the default is 1):
    // the run that decides the default.
    for w in [2usize, 4, 8, 16, 32] {
        sparse::set_mv_lanes(Some(w))?;
        let ms = event_ms(dev, || sparse::mv(one, &a, &xv, B::Scalar::ZERO, &yv))?;
        let err = rel_err(&to_f64(&y.to_vec()?), y_ref);
        println!(
            "  {:<30} {ms:8.3} ms  {}  err {err:.1e}   /w=1 {:.2}",
            format!("ours, {w} lanes per row"),
            peaks.describe(gbs(ms)),
            ms / ours
        );
    }
    sparse::set_mv_lanes(None)?;
    let warp = row("Warp bsr_mv", "warp");
    let cusparse = row(
        if m.block == 1 {
            "cuSPARSE (CuPy csr @ x)"
        } else {
            "cuSPARSE (CuPy, as scalar CSR)"
        },
        "cupy",
    );
    let verdict = |ours: f64, theirs: Option<f64>, goal: f64| match theirs {
        Some(t) => format!(
            "{:.2}x (goal <= {goal}: {})",
            ours / t,
            if ours <= goal * t { "met" } else { "MISSED" }
        ),
        None => "- (not run)".into(),
    };
    println!(
        "  verdict {d} {}: ours/cuSPARSE {}, ours/Warp {}, {}",
        m.name,
        verdict(ours, cusparse.0, 1.2),
        verdict(ours, warp.0, 1.0),
        peaks.describe(gbs(ours)).trim()
    );
    println!(
        "  verdict {d} {} (back to back, device time): ours/cuSPARSE {}, ours/Warp {}, {}",
        m.name,
        verdict(ours_b2b, cusparse.1, 1.2),
        verdict(ours_b2b, warp.1, 1.0),
        peaks.describe(gbs(ours_b2b)).trim()
    );
    if !with_cg {
        return Ok(());
    }
    println!("{d} CG, point Jacobi, b = x, from 0 to |r| <= {RTOL:e} |b|");
    let mut ours_rows = vec![("ours", Precond::PointJacobi)];
    if m.block > 1 {
        ours_rows.push(("ours, block Jacobi", Precond::Jacobi));
    }
    for (label, p) in ours_rows {
        let r = cg_ours(m, &a, x64, p)?;
        println!(
            "  {label:<30} {:9.1} ms  {:6} it  {:6.2} us/it  true residual {:.1e}  [{}]",
            r.ms,
            r.iterations,
            1e3 * r.ms / r.iterations.max(1) as f64,
            r.residual,
            r.note
        );
    }
    for (label, side) in [("Warp cg(check_every=0)", "warp"), ("CuPy cg", "cupy")] {
        match (
            their_row(theirs, d, side, "cg_ms"),
            their_row(theirs, d, side, "cg_iters"),
            their_row(theirs, d, side, "cg_resid"),
        ) {
            (Ok(ms), Ok(it), Ok(res)) => println!(
                "  {label:<30} {ms:9.1} ms  {it:6} it  {:6.2} us/it  true residual {res:.1e}",
                1e3 * ms / it.max(1.0)
            ),
            (Err(e), _, _) | (_, Err(e), _) | (_, _, Err(e)) => {
                println!("  {label:<30} not run: {e}")
            }
        }
    }
    Ok(())
}

// ------------------------------------------------------------------------------------------
// CPU
// ------------------------------------------------------------------------------------------

/// The float operations of the rayon baseline.
trait Real:
    SparseScalar
    + Send
    + Sync
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::iter::Sum
{
}
impl Real for f32 {}
impl Real for f64 {}

/// A scalar CSR in `S` for the baseline.
struct Plain<S> {
    offsets: Vec<i32>,
    columns: Vec<i32>,
    values: Vec<S>,
}

impl<S: Real> Plain<S> {
    /// `y = A x`, a row per rayon task, each row summed from 0 in storage order (our order).
    fn mv(&self, x: &[S], y: &mut [S]) {
        y.par_iter_mut().enumerate().for_each(|(r, yr)| {
            let mut acc = S::ZERO;
            for k in self.offsets[r] as usize..self.offsets[r + 1] as usize {
                acc = acc + self.values[k] * x[self.columns[k] as usize];
            }
            *yr = acc;
        });
    }
}

fn dot<S: Real>(a: &[S], b: &[S]) -> S {
    a.par_iter().zip(b).map(|(&a, &b)| a * b).sum()
}

/// The textbook Jacobi PCG from x = 0: a pass per vector operation. Returns the iterations.
fn plain_cg<S: Real>(a: &Plain<S>, dinv: &[S], b: &[S], x: &mut [S]) -> usize {
    let n = b.len();
    x.par_iter_mut().for_each(|v| *v = S::ZERO);
    let mut r = b.to_vec();
    let mut z: Vec<S> = r.par_iter().zip(dinv).map(|(&r, &d)| r * d).collect();
    let mut p = z.clone();
    let mut ap = vec![S::ZERO; n];
    let mut rz = dot(&r, &z);
    let tol2 = S::from_f64(RTOL * RTOL) * dot(b, b);
    let mut it = 0;
    while it < MAX_ITER && dot(&r, &r) > tol2 {
        a.mv(&p, &mut ap);
        let alpha = rz / dot(&p, &ap);
        x.par_iter_mut()
            .zip(&p)
            .for_each(|(x, &p)| *x = *x + alpha * p);
        r.par_iter_mut()
            .zip(&ap)
            .for_each(|(r, &q)| *r = *r - alpha * q);
        z.par_iter_mut()
            .zip(&r)
            .zip(dinv)
            .for_each(|((z, &r), &d)| *z = r * d);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.par_iter_mut()
            .zip(&z)
            .for_each(|(p, &z)| *p = z + beta * *p);
        it += 1;
    }
    it
}

fn cpu_section(quick: bool) -> wp::Result<()> {
    let threads = rayon::current_num_threads();
    println!("\nCPU ({threads} threads): ours against a plain rayon CSR mv and Jacobi CG loop");
    let (n2, n3) = if quick { (512, 50) } else { (1024, 100) };
    for m in [poisson2(n2), poisson3(n3)] {
        println!(
            "\n== {} (CPU): {} unknowns, {} stored entries ==",
            m.name,
            m.unknowns(),
            m.nnz()
        );
        let x = random_vector(m.unknowns(), 0xc0ffee ^ m.nnz() as u64);
        let y_ref = m.mv_f64(&x);
        // CG on the 3-D matrix (a few hundred iterations); the 2-D one at 1M unknowns takes
        // thousands, too many for a CPU run of a minute.
        let with_cg = m.name.contains("3-D");
        cpu_case::<f32>(&m, &x, &y_ref, with_cg)?;
        cpu_case::<f64>(&m, &x, &y_ref, with_cg)?;
    }
    Ok(())
}

fn cpu_case<S>(m: &Csr, x64: &[f64], y_ref: &[f64], with_cg: bool) -> wp::Result<()>
where
    S: Real + Case + Block<Scalar = S, In = S, Out = S>,
{
    let d = S::LABEL;
    let cpu = wp::cpu();
    let a = to_device::<S>(m, &cpu)?;
    let xs: Vec<S> = scalars(x64);
    let x = wp::Array::from_slice(&xs, &cpu)?;
    let y = wp::Array::<S>::zeros(m.unknowns(), &cpu)?;
    // The CPU backend runs a step in the call (nothing to synchronise): timed as the
    // baseline is, a warm-up then the median of REPS calls.
    sparse::mv(S::ONE, &a, &x, S::ZERO, &y)?;
    let mut times = Vec::with_capacity(REPS);
    for _ in 0..REPS {
        let t = Instant::now();
        sparse::mv(S::ONE, &a, &x, S::ZERO, &y)?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let ours = median_of(times);
    let y_ours = y.to_vec()?;
    let plain = Plain {
        offsets: m.offsets.clone(),
        columns: m.columns.clone(),
        values: scalars::<S>(&m.values),
    };
    let mut yp = vec![S::ZERO; m.unknowns()];
    let base = median_of(
        (0..REPS)
            .map(|_| {
                let t = Instant::now();
                plain.mv(&xs, &mut yp);
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    );
    let same = y_ours
        .iter()
        .zip(&yp)
        .all(|(a, b)| a.to_f64().to_bits() == b.to_f64().to_bits());
    let gbs = |ms: f64| m.compulsory_bytes(std::mem::size_of::<S>()) / (ms * 1e-3) / 1e9;
    println!(
        "{d} mv   ours {ours:8.3} ms ({:5.1} GB/s)   rayon CSR {base:8.3} ms ({:5.1} GB/s)   \
         ours/rayon {:.2}   err {:.1e} (rayon's {:.1e}; {})",
        gbs(ours),
        gbs(base),
        ours / base,
        rel_err(&to_f64(&y_ours), y_ref),
        rel_err(&to_f64(&yp), y_ref),
        if same { "the same bits" } else { "bits differ" }
    );
    if !with_cg {
        return Ok(());
    }
    let r = cg_ours(m, &a, x64, Precond::PointJacobi)?;
    let dinv: Vec<S> = m.diagonal().iter().map(|&d| S::from_f64(1.0 / d)).collect();
    let b: Vec<S> = scalars(x64);
    let mut xp = vec![S::ZERO; m.unknowns()];
    plain_cg(&plain, &dinv, &b, &mut xp);
    let mut times = Vec::new();
    let mut it = 0;
    for _ in 0..CG_REPS {
        let t = Instant::now();
        it = plain_cg(&plain, &dinv, &b, &mut xp);
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let base = median_of(times);
    println!(
        "{d} CG   ours {:8.1} ms {:5} it, true residual {:.1e} [{}]   rayon loop {base:8.1} ms \
         {it:5} it, true residual {:.1e}   ours/rayon {:.2}",
        r.ms,
        r.iterations,
        r.residual,
        r.note,
        m.residual(x64, &to_f64(&xp)),
        r.ms / base
    );
    Ok(())
}
