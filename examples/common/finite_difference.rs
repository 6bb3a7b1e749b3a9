//! The derivative of u(x) = sin(2 pi x) on the periodic grid x_i = i / n of [0, 1), by a
//! first-order (forward) and a second-order (central) finite difference: two kernels with
//! the same name, `finite_difference`, in the modules `first_order` and `second_order`, as
//! NVIDIA Warp's kernel-cache tutorial edits one kernel's body. Shared by the
//! `finite_difference` example and the stability tests (tests/suite/stability.rs includes
//! this file), so that the tests check the very kernels the example runs.
//!
//! Error bounds, with h = 1/n and k = 2 pi (|u''| <= k^2, |u'''| <= k^3):
//! - truncation: the forward difference errs by at most h/2 max|u''| = 2 pi^2 h (order 1),
//!   the central one by h^2/6 max|u'''| = 4 pi^3 h^2 / 3 (order 2);
//! - rounding: the samples of u are stored in T, each within half an ulp (eps/2, eps =
//!   `T::EPSILON`) of the exact value; their difference divided by h carries up to eps/h
//!   (forward) or eps/(2h) (central). This floor grows as h shrinks: in f32 its bound
//!   crosses the truncation bound near n = 13K (first order) and n = 900 (second), in f64
//!   the second order's near n = 720K. The subtraction and the product round too, by eps/2 of a result of at
//!   most 2 pi (and 1/h = n is a power of two, so the product is exact): a few eps, which
//!   [`rounding_bound`](Order::rounding_bound) leaves out and the tests allow for.

#![allow(dead_code)] // the test uses part of it

use std::f64::consts::PI;
use warp_lang as wp;

/// The wave number of u(x) = sin(K x): one period over [0, 1).
pub const K: f64 = 2.0 * PI;

/// The first-order kernel.
pub mod first_order {
    use warp_lang as wp;
    use wp::prelude::*;

    /// du/dx at x_i by the forward difference (u[i+1] - u[i]) / h, periodic; `inv_h` = 1/h.
    #[wp::kernel]
    pub fn finite_difference<T: Float>(u: Array<T>, du: Array<T>, inv_h: T) {
        let i = tid();
        let n = u.len();
        // `0usize`: an `if` branch does not give a literal its type (it would be i32).
        let ip = if i + 1 == n { 0usize } else { i + 1 };
        du[i] = (u[ip] - u[i]) * inv_h;
    }
}

/// The second-order kernel: the same name and signature, another body (so another source,
/// another cache key).
pub mod second_order {
    use warp_lang as wp;
    use wp::prelude::*;

    /// du/dx at x_i by the central difference (u[i+1] - u[i-1]) / (2h), periodic; `inv_h` = 1/h.
    #[wp::kernel]
    pub fn finite_difference<T: Float>(u: Array<T>, du: Array<T>, inv_h: T) {
        let i = tid();
        let n = u.len();
        let ip = if i + 1 == n { 0usize } else { i + 1 };
        let im = if i == 0 { n - 1 } else { i - 1 };
        du[i] = (u[ip] - u[im]) * (0.5 * inv_h);
    }
}

/// Which kernel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Order {
    /// `first_order::finite_difference`.
    First,
    /// `second_order::finite_difference`.
    Second,
}

impl Order {
    pub const ALL: [Order; 2] = [Order::First, Order::Second];

    /// The order of accuracy, p: the truncation error is O(h^p).
    pub fn p(self) -> i32 {
        match self {
            Order::First => 1,
            Order::Second => 2,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Order::First => "1st order",
            Order::Second => "2nd order",
        }
    }

    /// The kernel's module, as `module_path!()` ends.
    pub fn module(self) -> &'static str {
        match self {
            Order::First => "first_order",
            Order::Second => "second_order",
        }
    }

    /// The largest truncation error on `n` points (module docs): 2 pi^2 h or 4 pi^3 h^2 / 3.
    pub fn truncation_bound(self, n: usize) -> f64 {
        let h = 1.0 / n as f64;
        match self {
            Order::First => h / 2.0 * K * K,
            Order::Second => h * h / 6.0 * K * K * K,
        }
    }

    /// The error that rounding the samples to a type of epsilon `eps` may cause (module docs):
    /// eps/h or eps/(2h).
    pub fn rounding_bound(self, n: usize, eps: f64) -> f64 {
        match self {
            Order::First => eps * n as f64,
            Order::Second => eps * n as f64 / 2.0,
        }
    }

    /// The derivative of the host values `u` by this order's formula, in T, as the kernel
    /// computes it (operation for operation): the CPU backend gives these bits.
    pub fn host<T: Real>(self, u: &[T]) -> Vec<T> {
        let n = u.len();
        let inv_h = T::of(n as f64);
        (0..n)
            .map(|i| {
                let ip = (i + 1) % n;
                let im = (i + n - 1) % n;
                match self {
                    Order::First => (u[ip] - u[i]) * inv_h,
                    Order::Second => (u[ip] - u[im]) * (T::of(0.5) * inv_h),
                }
            })
            .collect()
    }
}

/// The precisions the kernels run in.
pub trait Real:
    wp::Element + Copy + std::ops::Sub<Output = Self> + std::ops::Mul<Output = Self>
{
    const NAME: &'static str;
    /// Machine epsilon (the gap from 1 to the next value).
    const EPS: f64;
    fn of(x: f64) -> Self;
    fn to_f64(self) -> f64;
    /// Launches `order`'s kernel over `u.len()` threads: `du` = du/dx of `u`.
    fn launch(
        order: Order,
        u: &wp::Array<Self>,
        du: &wp::Array<Self>,
        dev: &wp::Device,
    ) -> wp::Result<()>;
}

impl Real for f32 {
    const NAME: &'static str = "f32";
    const EPS: f64 = f32::EPSILON as f64;
    fn of(x: f64) -> Self {
        x as f32
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn launch(
        order: Order,
        u: &wp::Array<f32>,
        du: &wp::Array<f32>,
        dev: &wp::Device,
    ) -> wp::Result<()> {
        let (n, inv_h) = (u.len(), u.len() as f32);
        match order {
            Order::First => wp::launch(first_order::finite_difference, n, (u, du, inv_h), dev),
            Order::Second => wp::launch(second_order::finite_difference, n, (u, du, inv_h), dev),
        }
    }
}

impl Real for f64 {
    const NAME: &'static str = "f64";
    const EPS: f64 = f64::EPSILON;
    fn of(x: f64) -> Self {
        x
    }
    fn to_f64(self) -> f64 {
        self
    }
    fn launch(
        order: Order,
        u: &wp::Array<f64>,
        du: &wp::Array<f64>,
        dev: &wp::Device,
    ) -> wp::Result<()> {
        let (n, inv_h) = (u.len(), u.len() as f64);
        match order {
            Order::First => wp::launch(first_order::finite_difference, n, (u, du, inv_h), dev),
            Order::Second => wp::launch(second_order::finite_difference, n, (u, du, inv_h), dev),
        }
    }
}

/// x_i = i / n (exact in f64 for n up to 2^53).
pub fn x(i: usize, n: usize) -> f64 {
    i as f64 / n as f64
}

/// u(x_i) = sin(K x_i) on `n` points, computed in f64 and rounded to T.
pub fn samples<T: Real>(n: usize) -> Vec<T> {
    (0..n).map(|i| T::of((K * x(i, n)).sin())).collect()
}

/// The largest |du_i - u'(x_i)| over the grid, u'(x) = K cos(K x), in f64.
pub fn max_error<T: Real>(du: &[T]) -> f64 {
    let n = du.len();
    du.iter()
        .enumerate()
        .map(|(i, d)| (d.to_f64() - K * (K * x(i, n)).cos()).abs())
        .fold(0.0, f64::max)
}

/// The backward pass of `order`'s kernel (its adjoint, through a Tape) in f64 on `n` points:
/// with the seed dL/d(du) = w = cos(K x), it gives dL/du = D^T w, where D is the difference
/// matrix. On a periodic grid D^T w is minus the backward difference of w (first order) or
/// minus the central difference (second), so it approximates -w' = K sin(K x) with the
/// same order and the same truncation bound. Returns the largest error of dL/du against
/// K sin(K x), and the time of the backward pass in seconds (the first call on a GPU
/// compiles the adjoint: call once to warm up).
pub fn adjoint_error(order: Order, n: usize, dev: &wp::Device) -> wp::Result<(f64, f64)> {
    let u = wp::Array::from_slice(&samples::<f64>(n), dev)?.with_grad()?;
    let du = wp::Array::<f64>::zeros(n, dev)?.with_grad()?;
    let w: Vec<f64> = (0..n).map(|i| (K * x(i, n)).cos()).collect();
    let w = wp::Array::from_slice(&w, dev)?;
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        f64::launch(order, &u, &du, dev)?;
    }
    du.grad().expect("with_grad").copy_from(&w)?;
    wp::synchronize()?;
    let t = std::time::Instant::now();
    tape.backward_from_grads()?;
    wp::synchronize()?;
    let seconds = t.elapsed().as_secs_f64();
    let g = u.grad().expect("with_grad").to_vec()?;
    let err = g
        .iter()
        .enumerate()
        .map(|(i, &g)| (g - K * (K * x(i, n)).sin()).abs())
        .fold(0.0, f64::max);
    Ok((err, seconds))
}
