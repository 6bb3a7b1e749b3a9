//! Gradient checks: the Jacobian from a [`Tape`], the same by central differences, and a
//! comparison of the two (Warp's `wp.autograd.jacobian`, `jacobian_fd`, `gradcheck`); and
//! forward mode: Jacobian-vector products through a kernel's tangent kernel ([`jvp`]) and
//! Hessian-vector products by forward over reverse ([`hvp`]).
//!
//! The computation is a closure that runs the forward launches; it is called once under a
//! tape and then twice per input element with that element nudged. Outputs are zeroed before
//! every call, so kernels that accumulate into them (`atomic_add`) give the same result each
//! time. Inputs and outputs are 1-D float arrays with gradients (`with_grad`).

use crate::array::{Array, Element};
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::{ArgsOf, Forward, Kernel, KernelParams, Launchable};
use crate::launch::Dim;
use crate::tape::{Seed, Tape};

/// A float element type for gradient checks (f32, f64, f16, bf16), with its default check
/// settings.
pub trait CheckFloat: Seed {
    /// Converts to f64.
    fn to_f64(self) -> f64;
    /// Converts from f64 (rounding).
    fn from_f64(v: f64) -> Self;
    /// Default central-difference step and tolerances: see [`GradcheckOptions::for_type`].
    const DEFAULTS: GradcheckOptions;
}

impl CheckFloat for f32 {
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    // f32 has a unit roundoff of 6e-8: a difference quotient with step h carries a rounding
    // error of about 6e-8 |f| / h, and a truncation error of about h^2 |f'''|. h = 1e-3 puts
    // both near 1e-4 relative, so 1e-2 relative (1e-3 absolute near zero) still catches a wrong
    // gradient while never flagging a right one (Warp uses the same values).
    const DEFAULTS: GradcheckOptions = GradcheckOptions {
        eps: 1e-3,
        atol: 1e-3,
        rtol: 1e-2,
    };
}

impl CheckFloat for f64 {
    fn to_f64(self) -> f64 {
        self
    }
    fn from_f64(v: f64) -> Self {
        v
    }
    // f64: roundoff 1e-16 / h and truncation h^2: h = 1e-6 gives about 1e-10 each, so a
    // relative tolerance of 1e-6 leaves a wide margin for functions of moderate curvature.
    const DEFAULTS: GradcheckOptions = GradcheckOptions {
        eps: 1e-6,
        atol: 1e-8,
        rtol: 1e-6,
    };
}

impl CheckFloat for warp_core::f16 {
    fn to_f64(self) -> f64 {
        self.to_f64()
    }
    fn from_f64(v: f64) -> Self {
        warp_core::float16::f16_from_f64(v)
    }
    // f16 has a unit roundoff of 2^-11 (4.9e-4) and a spacing of 2^-10 at 1. A step of 1/16
    // is exact for |x| < 64 (x +- h needs no rounding), and keeps the rounding error of the
    // quotient, two outputs each off by up to 2^-12 |f| over 2h = 1/8, near 4e-3 |f|, with a
    // truncation error of h^2/6 |f'''| = 7e-4 |f'''|. The analytic side is f16 too: every
    // step of an adjoint formula rounds (a few 2^-11 relative). So 5e-2 relative (2e-2
    // absolute near zero) passes a right gradient of moderate curvature and still fails a
    // wrong one by a factor or a sign.
    const DEFAULTS: GradcheckOptions = GradcheckOptions {
        eps: 0.0625,
        atol: 2e-2,
        rtol: 5e-2,
    };
}

impl CheckFloat for warp_core::bf16 {
    fn to_f64(self) -> f64 {
        self.to_f64()
    }
    fn from_f64(v: f64) -> Self {
        warp_core::bfloat16::bf16_from_f64(v)
    }
    // bf16 has 8 significant bits: a unit roundoff of 2^-8 (3.9e-3), 8 times f16's. With a
    // step of 1/4, x +- h rounds by at most 2^-8 |x| (exact where x's last bit is at 1/4 or
    // coarser); the quotient's rounding error is then about 2 * 2^-8 |f| / (2h) = 1.6e-2 |f|, the truncation error h^2/6 |f'''| =
    // 1e-2 |f'''|, and the analytic side rounds each step of its formula (a few 2^-8
    // relative). 1e-1 relative (5e-2 absolute near zero) passes a right gradient of moderate
    // curvature and still fails a wrong one by a factor or a sign.
    const DEFAULTS: GradcheckOptions = GradcheckOptions {
        eps: 0.25,
        atol: 5e-2,
        rtol: 1e-1,
    };
}

/// Step and tolerances of [`gradcheck`]: an entry passes when
/// `|analytic - numeric| <= atol + rtol * |numeric|`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GradcheckOptions {
    /// Central-difference step.
    pub eps: f64,
    /// Absolute tolerance.
    pub atol: f64,
    /// Relative tolerance.
    pub rtol: f64,
}

impl GradcheckOptions {
    /// The defaults for element type `T` (f32: eps 1e-3, atol 1e-3, rtol 1e-2; f64: eps
    /// 1e-6, atol 1e-8, rtol 1e-6; f16: eps 1/16, atol 2e-2, rtol 5e-2; bf16: eps 1/4, atol 5e-2, rtol 1e-1; the reasons are in
    /// the source).
    pub fn for_type<T: CheckFloat>() -> Self {
        T::DEFAULTS
    }
}

/// What [`gradcheck`] found.
#[derive(Clone, Debug)]
pub struct GradcheckReport {
    /// Whether every entry was within tolerance.
    pub passed: bool,
    /// Largest |analytic - numeric|.
    pub max_abs_error: f64,
    /// Largest |analytic - numeric| / |numeric| over entries whose numeric value exceeds
    /// `atol` (near zero, a difference quotient's rounding noise is all there is).
    pub max_rel_error: f64,
    /// The worst entry: (output element, input element, analytic, numeric).
    pub worst: Option<(usize, usize, f64, f64)>,
    /// The Jacobian from the tape (rows: output elements, columns: input elements).
    pub analytic: Vec<Vec<f64>>,
    /// The Jacobian by central differences.
    pub numeric: Vec<Vec<f64>>,
}

fn check_arrays<T: Element>(inputs: &[&Array<T>], outputs: &[&Array<T>]) -> Result<()> {
    if inputs.is_empty() || outputs.is_empty() {
        return Err(Error::invalid(
            "jacobian: needs at least one input and one output",
        ));
    }
    for (what, a) in inputs
        .iter()
        .map(|a| ("input", a))
        .chain(outputs.iter().map(|a| ("output", a)))
    {
        if !a.requires_grad() {
            return Err(Error::invalid(format!(
                "jacobian: an {what} of shape {:?} has no gradient (use .with_grad())",
                a.shape()
            )));
        }
    }
    Ok(())
}

fn zero_outputs<T: Element>(outputs: &[&Array<T>]) -> Result<()> {
    outputs.iter().try_for_each(|o| o.fill(T::zeroed()))
}

/// Sets element `k` of `a` to `v`, through `host` (a copy of `a` the caller keeps in step).
fn set_element<T: CheckFloat>(a: &Array<T>, host: &mut [T], k: usize, v: T) -> Result<()> {
    host[k] = v;
    a.copy_from(&Array::from_slice(host, a.device())?)
}

/// The Jacobian of `outputs` with respect to `inputs` from reverse mode: one backward per
/// output element (rows: output elements in order, columns: input elements in order).
pub fn jacobian<T: CheckFloat>(
    mut forward: impl FnMut() -> Result<()>,
    inputs: &[&Array<T>],
    outputs: &[&Array<T>],
) -> Result<Vec<Vec<f64>>> {
    check_arrays(inputs, outputs)?;
    zero_outputs(outputs)?;
    let tape = Tape::new();
    {
        let _rec = tape.record();
        forward()?;
    }
    let mut rows = Vec::new();
    for out in outputs {
        for k in 0..out.len() {
            tape.zero()?;
            for a in inputs.iter().chain(outputs.iter()) {
                a.zero_grad()?;
            }
            let g = out.grad().expect("checked");
            let mut seed = vec![T::zeroed(); out.len()];
            seed[k] = T::ONE;
            g.copy_from(&Array::from_slice(&seed, g.device())?)?;
            tape.backward_from_grads()?;
            let mut row = Vec::new();
            for a in inputs {
                row.extend(
                    a.grad()
                        .expect("checked")
                        .to_vec()?
                        .into_iter()
                        .map(T::to_f64),
                );
            }
            rows.push(row);
        }
    }
    Ok(rows)
}

/// The same Jacobian by central differences with step `eps`: the closure runs twice per input
/// element, with the element at `x + eps` and `x - eps` (outputs zeroed before each run).
pub fn jacobian_fd<T: CheckFloat>(
    mut forward: impl FnMut() -> Result<()>,
    inputs: &[&Array<T>],
    outputs: &[&Array<T>],
    eps: f64,
) -> Result<Vec<Vec<f64>>> {
    check_arrays(inputs, outputs)?;
    let n_out: usize = outputs.iter().map(|o| o.len()).sum();
    let mut cols: Vec<Vec<f64>> = Vec::new();
    let run = |forward: &mut dyn FnMut() -> Result<()>| -> Result<Vec<f64>> {
        zero_outputs(outputs)?;
        forward()?;
        let mut v = Vec::with_capacity(n_out);
        for o in outputs {
            v.extend(o.to_vec()?.into_iter().map(T::to_f64));
        }
        Ok(v)
    };
    for a in inputs {
        // Read once; each nudge uploads this copy with one element changed.
        let mut host = a.to_vec()?;
        for k in 0..a.len() {
            let x = host[k];
            // The step actually taken, after rounding x +- eps to T.
            let (hi, lo) = (T::from_f64(x.to_f64() + eps), T::from_f64(x.to_f64() - eps));
            set_element(a, &mut host, k, hi)?;
            let f_hi = run(&mut forward)?;
            set_element(a, &mut host, k, lo)?;
            let f_lo = run(&mut forward)?;
            set_element(a, &mut host, k, x)?;
            let h = hi.to_f64() - lo.to_f64();
            cols.push(f_hi.iter().zip(&f_lo).map(|(p, m)| (p - m) / h).collect());
        }
    }
    // Transpose columns (one per input element) into rows (one per output element).
    Ok((0..n_out)
        .map(|r| cols.iter().map(|c| c[r]).collect())
        .collect())
}

/// Compares [`jacobian`] with [`jacobian_fd`] under `opts` (use
/// [`GradcheckOptions::for_type`] for the defaults). The forward closure is run again at the
/// end, so outputs hold the unperturbed result afterwards.
pub fn gradcheck<T: CheckFloat>(
    mut forward: impl FnMut() -> Result<()>,
    inputs: &[&Array<T>],
    outputs: &[&Array<T>],
    opts: GradcheckOptions,
) -> Result<GradcheckReport> {
    let analytic = jacobian(&mut forward, inputs, outputs)?;
    let numeric = jacobian_fd(&mut forward, inputs, outputs, opts.eps)?;
    zero_outputs(outputs)?;
    forward()?;
    let mut report = GradcheckReport {
        passed: true,
        max_abs_error: 0.0,
        max_rel_error: 0.0,
        worst: None,
        analytic,
        numeric,
    };
    let mut worst_excess = f64::NEG_INFINITY;
    for (r, (ra, rn)) in report.analytic.iter().zip(&report.numeric).enumerate() {
        for (c, (&a, &n)) in ra.iter().zip(rn).enumerate() {
            let err = (a - n).abs();
            let err = if err.is_nan() { f64::INFINITY } else { err };
            report.max_abs_error = report.max_abs_error.max(err);
            if n.abs() > opts.atol {
                report.max_rel_error = report.max_rel_error.max(err / n.abs());
            }
            let excess = err - (opts.atol + opts.rtol * n.abs());
            if excess > 0.0 {
                report.passed = false;
            }
            if excess > worst_excess {
                worst_excess = excess;
                report.worst = Some((r, c, a, n));
            }
        }
    }
    Ok(report)
}

/// Forward mode: launches the tangent kernel of `kernel` (see [`Forward`]) over `dim` with the
/// launch arguments `args` and their tangents `tangents` (a tuple of the same types: an array
/// of the same shape for each array, a value for each value), on `device`.
///
/// The kernel runs as [`launch`](crate::launch()) would run it, and every float it writes
/// (stores, `atomic_add`/`atomic_sub`) gets its tangent, the directional derivative along the
/// input tangents, written at the same place of the tangent array: for `y = f(x)`, the
/// tangent array of `y` receives the Jacobian-vector product `J v` where `v` is the tangent
/// array of `x` (JAX's `jvp(f, primals, tangents)`). Output tangents are written or
/// accumulated as the outputs are, so clear those that the kernel accumulates into, as for the
/// outputs themselves. Integer, bool, struct and object parameters are held constant: their
/// tangents must be passed (the same value does) but are never read.
///
/// On a recording [`Tape`] the launch is recorded like any other; its backward sends
/// gradients to the primal and tangent arrays alike (see [`hvp`]).
///
/// Forward mode covers the arithmetic operators, casts between floats, vector, matrix and
/// quaternion construction and members, array loads, stores and `atomic_add`/`atomic_sub`,
/// control flow, random draws (constant), and these builtins: `sqrt cbrt exp exp2 log log2
/// log10 sin cos tan asin acos atan atan2 sinh cosh tanh pow erf erfc degrees radians frac abs
/// min max clamp lerp dot cross outer ddot cw_mul cw_div transpose trace diag skew get_diag
/// length norm_l2 length_sq normalize inverse determinant`, plus every builtin whose
/// derivative is zero (`floor`, `sign`, `step`, ..).
///
/// ```ignore
/// // (tests/suite/jvp.rs runs this on every backend)
/// wp::jvp(energy, n, (&x, &e), (&x_dot, &e_dot), &dev)?; // e_dot = J_e(x) x_dot
/// ```
///
/// # Errors
/// [`Error::NoTangent`] when the kernel has a construct forward mode does not differentiate
/// (its name and line) or was built without the `forward-mode` feature of warp-lang;
/// [`Error::ShapeMismatch`] when a tangent array's shape differs from its array's; then
/// every error of [`launch`](crate::launch()).
pub fn jvp<'a, L, A>(
    kernel: L,
    dim: impl Into<Dim>,
    args: A,
    tangents: A,
    device: &Device,
) -> Result<()>
where
    L: Launchable<A>,
    L::Kernel: Forward + Kernel<Params: KernelParams<Args<'a> = A>>,
{
    let _ = kernel;
    let joined = tangent_args::<L::Kernel>(args, tangents)?;
    crate::launch::launch(
        <L::Kernel as Forward>::Tangent::default(),
        dim,
        joined,
        device,
    )
}

/// The tangent kernel's arguments, after checking that there is a tangent kernel and that each
/// tangent array has its array's shape.
fn tangent_args<'a, K: Forward>(
    args: ArgsOf<'a, K>,
    tangents: ArgsOf<'a, K>,
) -> Result<ArgsOf<'a, K::Tangent>> {
    if let Some(reason) = K::TANGENT_ERROR {
        return Err(Error::NoTangent {
            kernel: K::INFO.name,
            reason,
        });
    }
    let shapes = <K::Params as KernelParams>::shapes(&args);
    let tshapes = <K::Params as KernelParams>::shapes(&tangents);
    for (k, (s, t)) in shapes.into_iter().zip(tshapes).enumerate() {
        if let (Some(s), Some(t)) = (s, t) {
            if s != t {
                let name = K::INFO.params[k];
                return Err(Error::ShapeMismatch {
                    kernel: K::INFO.name,
                    args: vec![name.to_string(), format!("{name}_dot")],
                    shapes: vec![s, t],
                });
            }
        }
    }
    Ok(K::join(args, tangents))
}

/// A Hessian-vector product by forward over reverse: for a kernel that computes a scalar
/// loss `L(x)` into `output` (an array of one element; with more, `L` is the sum of its
/// elements), leaves `H v` in the gradients of the array arguments `args` (`x.grad()`), where
/// `H` is the Hessian of `L` with respect to every float input and `v` the direction in
/// `tangents` (as for [`jvp`]), and `∇L` in the gradients of the tangent arrays.
///
/// It records [`jvp`] on a fresh [`Tape`], so the tangent of the loss, in `output`'s tangent
/// array (the one in `tangents` at `output`'s place, passed as `output_tangent`), is
/// `∇L · v`; then runs backward from it: the gradient of `∇L · v` with respect to `x` is
/// `H v`. The gradients of `args` and `tangents` are cleared first; the arrays whose Hessian
/// rows are wanted need gradients (`with_grad()`), and so does `output_tangent`. As with
/// [`jvp`], clear `output` and `output_tangent` first if the kernel accumulates into them.
///
/// ```ignore
/// // (tests/suite/jvp.rs runs this on every backend)
/// loss.zero()?; loss_dot.zero()?;
/// wp::hvp(energy, n, (&x, &loss), (&v, &loss_dot), &loss_dot, &dev)?;
/// let hv = x.grad().unwrap().to_vec()?;
/// ```
///
/// # Errors
/// As [`jvp`], and as [`Tape::backward`] (kernels without an adjoint; `output_tangent`
/// without a gradient).
pub fn hvp<'a, L, A, T: Seed, const N: usize>(
    kernel: L,
    dim: impl Into<Dim>,
    args: A,
    tangents: A,
    output_tangent: &Array<T, N>,
    device: &Device,
) -> Result<()>
where
    L: Launchable<A>,
    L::Kernel: Forward + Kernel<Params: KernelParams<Args<'a> = A>>,
    A: Copy,
{
    if output_tangent.grad().is_none() {
        return Err(Error::invalid(
            "hvp: the output tangent has no gradient (create it with .with_grad())",
        ));
    }
    <<L::Kernel as Kernel>::Params as KernelParams>::zero_grads(&args)?;
    <<L::Kernel as Kernel>::Params as KernelParams>::zero_grads(&tangents)?;
    let tape = Tape::new();
    {
        let _rec = tape.record();
        jvp(kernel, dim, args, tangents, device)?;
    }
    tape.backward(output_tangent)
}
