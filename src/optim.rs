//! Optimizers over parameter arrays (Warp's `warp.optim`): [`Adam`] and [`Sgd`] (momentum,
//! dampening, weight decay, Nesterov), with Warp's update rules.
//!
//! A parameter is any contiguous array with a gradient (`.with_grad()`) whose elements are
//! floats: `f32`, `f64`, their glam vectors, matrices and quaternions. Its bytes are viewed as
//! a flat array of scalars, so the rules apply component by component, and each step is one
//! fused kernel per parameter array on the array's device (moments and parameters updated in
//! one pass). The gradient is read as it is: zero it between steps with
//! [`Adam::zero_grad`] (or a tape's `zero`).
//!
//! ```ignore
//! // (tests/suite/optim.rs runs this on every backend)
//! let x = wp::Array::from_slice(&start, &dev)?.with_grad()?;
//! let mut opt = wp::optim::Adam::new(0.05);
//! opt.add(&x)?;
//! for _ in 0..steps {
//!     opt.zero_grad()?;
//!     let tape = wp::Tape::new();
//!     { let _rec = tape.record(); wp::launch(loss_kernel, n, (&x, &loss), &dev)?; }
//!     tape.backward(&loss)?;
//!     opt.step()?;
//! }
//! ```

use crate as wp;
use crate::prelude::*;
use crate::{Array, Element, Error, Result};

/// `params -= lr * mhat / (sqrt(vhat) + eps)` with the moments updated first; `c1`, `c2`
/// are the bias corrections 1 / (1 - beta^t), computed on the host.
#[wp::kernel]
fn adam_step<T: Float>(
    g: Array<T>,
    m: Array<T>,
    v: Array<T>,
    params: Array<T>,
    lr: T,
    beta1: T,
    beta2: T,
    c1: T,
    c2: T,
    eps: T,
) {
    let i = tid();
    let gi = g[i];
    let mi = beta1 * m[i] + (1.0 - beta1) * gi;
    let vi = beta2 * v[i] + (1.0 - beta2) * gi * gi;
    m[i] = mi;
    v[i] = vi;
    params[i] = params[i] - lr * (mi * c1) / (sqrt(vi * c2) + eps);
}

/// Warp's (and PyTorch's) SGD: weight decay, then momentum with dampening (the buffer starts
/// as the first gradient), optionally Nesterov's look-ahead.
#[wp::kernel]
fn sgd_step<T: Float>(
    g: Array<T>,
    b: Array<T>,
    params: Array<T>,
    lr: T,
    momentum: T,
    dampening: T,
    weight_decay: T,
    nesterov: i32,
    first: i32,
) {
    let i = tid();
    let mut gi = g[i];
    if weight_decay != 0.0 {
        gi += weight_decay * params[i];
    }
    if momentum != 0.0 {
        let mut bi = gi;
        if first == 0 {
            bi = momentum * b[i] + (1.0 - dampening) * gi;
        }
        b[i] = bi;
        if nesterov != 0 {
            gi += momentum * bi;
        } else {
            gi = bi;
        }
    }
    params[i] = params[i] - lr * gi;
}

/// An element type whose components are all `f32` or all `f64`: what an optimizer can update.
pub trait OptimElement: Element {
    /// Whether the components are `f64`.
    const DOUBLE: bool;
}

macro_rules! optim_elements {
    ($double:expr => $($t:ty),*) => {$(
        impl OptimElement for $t {
            const DOUBLE: bool = $double;
        }
    )*};
}
optim_elements!(false => f32, Vec2, Vec3, Vec4, Mat2, Mat3, Mat4, Quat);
optim_elements!(true => f64, DVec2, DVec3, DVec4, DMat2, DMat3, DMat4, DQuat);

/// A parameter, its gradient and an optimizer's state arrays, as flat arrays of scalars `S`.
type Parts<S> = (Array<S>, Array<S>, Vec<Array<S>>);

/// A parameter as flat scalars of its component type.
enum Flat {
    F32(Array<f32>, Array<f32>, Vec<Array<f32>>),
    F64(Array<f64>, Array<f64>, Vec<Array<f64>>),
}

impl Flat {
    /// Views `param` and its gradient as flat scalars, with `states` zeroed state arrays of the
    /// same length on its device.
    fn of<T: OptimElement, const N: usize>(
        param: &Array<T, N>,
        states: usize,
        who: &str,
    ) -> Result<Flat> {
        let Some(grad) = param.grad() else {
            return Err(Error::InvalidArgument {
                what: format!(
                    "{who}: a parameter of shape {:?} ({}) has no gradient (create it with \
                     .with_grad())",
                    param.shape(),
                    T::TYPE_NAME
                ),
            });
        };
        fn flat<S: Element, T: Element, const N: usize>(
            p: &Array<T, N>,
            g: &Array<T, N>,
            states: usize,
        ) -> Result<Parts<S>> {
            let (p, g) = (p.reinterpret::<S>()?, g.reinterpret::<S>()?);
            let s = (0..states)
                .map(|_| Array::<S>::zeros(p.len(), p.device()))
                .collect::<Result<_>>()?;
            Ok((p, g, s))
        }
        Ok(if T::DOUBLE {
            let (p, g, s) = flat::<f64, T, N>(param, &grad, states)?;
            Flat::F64(p, g, s)
        } else {
            let (p, g, s) = flat::<f32, T, N>(param, &grad, states)?;
            Flat::F32(p, g, s)
        })
    }

    fn zero_grad(&self) -> Result<()> {
        match self {
            Flat::F32(_, g, _) => g.fill(0.0),
            Flat::F64(_, g, _) => g.fill(0.0),
        }
    }

    fn zero_states(&self) -> Result<()> {
        match self {
            Flat::F32(_, _, s) => s.iter().try_for_each(|a| a.fill(0.0)),
            Flat::F64(_, _, s) => s.iter().try_for_each(|a| a.fill(0.0)),
        }
    }
}

/// A learning-rate schedule: the rate for step `t` (1 for the first step).
type Schedule = Box<dyn FnMut(u64) -> f64>;

/// What every optimizer keeps: its parameters (with `states` state arrays each), the fixed
/// learning rate or a schedule, and the step count.
struct Params {
    flats: Vec<Flat>,
    states: usize,
    who: &'static str,
    lr: f64,
    schedule: Option<Schedule>,
    t: u64,
}

/// What an optimizer's `Debug` shows: its settings and progress, not its arrays' contents (a
/// schedule is a closure, shown only as present).
impl std::fmt::Debug for Params {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Params")
            .field("parameters", &self.flats.len())
            .field("lr", &self.lr)
            .field("schedule", &self.schedule.is_some())
            .field("step", &self.t)
            .finish()
    }
}

impl Params {
    fn new(who: &'static str, states: usize, lr: f64) -> Params {
        Params {
            flats: Vec::new(),
            states,
            who,
            lr,
            schedule: None,
            t: 0,
        }
    }

    /// Counts a step and returns it (from 1) with its learning rate.
    fn next_step(&mut self) -> (u64, f64) {
        self.t += 1;
        let lr = match &mut self.schedule {
            Some(s) => s(self.t),
            None => self.lr,
        };
        (self.t, lr)
    }
}

/// A step of any optimizer, for code that picks one at run time (`Box<dyn Optimizer>`).
pub trait Optimizer {
    /// One update of every parameter from its gradient.
    ///
    /// # Errors
    /// A launch's error (a fault, a device error).
    fn step(&mut self) -> Result<()>;

    /// Zeroes every parameter's gradient.
    ///
    /// # Errors
    /// A device error.
    fn zero_grad(&self) -> Result<()>;
}

/// The methods every optimizer has, over its `params: Params`.
macro_rules! optimizer_methods {
    ($opt:ident) => {
        impl $opt {
            /// A learning-rate schedule: step `t` (from 1) uses `schedule(t)` instead of the
            /// fixed rate.
            pub fn schedule(mut self, schedule: impl FnMut(u64) -> f64 + 'static) -> $opt {
                self.params.schedule = Some(Box::new(schedule));
                self
            }

            /// Adds a parameter array (contiguous, with a gradient; see [`OptimElement`]).
            ///
            /// # Errors
            /// [`Error::InvalidArgument`] for an array without a gradient or not contiguous.
            pub fn add<T: OptimElement, const N: usize>(
                &mut self,
                param: &Array<T, N>,
            ) -> Result<()> {
                let flat = Flat::of(param, self.params.states, self.params.who)?;
                self.params.flats.push(flat);
                Ok(())
            }

            /// Sets the fixed learning rate.
            pub fn set_lr(&mut self, lr: f64) {
                self.params.lr = lr;
            }

            /// Steps taken so far.
            pub fn steps(&self) -> u64 {
                self.params.t
            }

            /// Zeroes every parameter's gradient.
            ///
            /// # Errors
            /// A device error.
            pub fn zero_grad(&self) -> Result<()> {
                self.params.flats.iter().try_for_each(Flat::zero_grad)
            }

            /// Forgets the optimizer's state (moments, momentum buffers) and the step count;
            /// the parameters are left as they are.
            ///
            /// # Errors
            /// A device error.
            pub fn reset(&mut self) -> Result<()> {
                self.params.t = 0;
                self.params.flats.iter().try_for_each(Flat::zero_states)
            }
        }

        impl Optimizer for $opt {
            fn step(&mut self) -> Result<()> {
                $opt::step(self)
            }

            fn zero_grad(&self) -> Result<()> {
                $opt::zero_grad(self)
            }
        }
    };
}

/// Adam (Kingma and Ba), as Warp's `warp.optim.Adam`: per component,
/// `m = b1 m + (1 - b1) g`, `v = b2 v + (1 - b2) g^2`,
/// `p -= lr (m / (1 - b1^t)) / (sqrt(v / (1 - b2^t)) + eps)`.
#[derive(Debug)]
pub struct Adam {
    params: Params,
    beta1: f64,
    beta2: f64,
    eps: f64,
}

optimizer_methods!(Adam);

impl Adam {
    /// An Adam optimizer with learning rate `lr` and Warp's defaults: betas (0.9, 0.999),
    /// eps 1e-8.
    pub fn new(lr: f64) -> Adam {
        Adam {
            params: Params::new("Adam", 2, lr),
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }

    /// Sets the moment decay rates.
    pub fn betas(mut self, beta1: f64, beta2: f64) -> Adam {
        (self.beta1, self.beta2) = (beta1, beta2);
        self
    }

    /// Sets the denominator's epsilon.
    pub fn eps(mut self, eps: f64) -> Adam {
        self.eps = eps;
        self
    }

    /// One update of every parameter from its gradient (one kernel per parameter array).
    ///
    /// # Errors
    /// A launch's error (a fault, a device error).
    pub fn step(&mut self) -> Result<()> {
        let (t, lr) = self.params.next_step();
        let t = t as i32;
        let c1 = 1.0 / (1.0 - self.beta1.powi(t));
        let c2 = 1.0 / (1.0 - self.beta2.powi(t));
        let (b1, b2, eps) = (self.beta1, self.beta2, self.eps);
        for p in &self.params.flats {
            match p {
                Flat::F32(x, g, s) => {
                    let f = |v: f64| v as f32;
                    let args = (
                        g,
                        &s[0],
                        &s[1],
                        x,
                        f(lr),
                        f(b1),
                        f(b2),
                        f(c1),
                        f(c2),
                        f(eps),
                    );
                    wp::launch(adam_step, x.len(), args, x.device())?;
                }
                Flat::F64(x, g, s) => {
                    let args = (g, &s[0], &s[1], x, lr, b1, b2, c1, c2, eps);
                    wp::launch(adam_step, x.len(), args, x.device())?;
                }
            }
        }
        Ok(())
    }
}

/// Stochastic gradient descent, as Warp's `warp.optim.SGD` (and PyTorch's): per component,
/// `g += weight_decay p`; with momentum, `b = g` at the first step and
/// `b = momentum b + (1 - dampening) g` after, then `g = b` (or `g += momentum b` with
/// Nesterov); `p -= lr g`.
#[derive(Debug)]
pub struct Sgd {
    params: Params,
    momentum: f64,
    dampening: f64,
    weight_decay: f64,
    nesterov: bool,
}

optimizer_methods!(Sgd);

impl Sgd {
    /// Plain SGD with learning rate `lr` (no momentum, dampening or weight decay).
    pub fn new(lr: f64) -> Sgd {
        Sgd {
            params: Params::new("Sgd", 1, lr),
            momentum: 0.0,
            dampening: 0.0,
            weight_decay: 0.0,
            nesterov: false,
        }
    }

    /// Sets the momentum.
    pub fn momentum(mut self, momentum: f64) -> Sgd {
        self.momentum = momentum;
        self
    }

    /// Sets the dampening of the momentum buffer's update.
    pub fn dampening(mut self, dampening: f64) -> Sgd {
        self.dampening = dampening;
        self
    }

    /// Sets the weight decay (an L2 penalty's gradient added to the gradient).
    pub fn weight_decay(mut self, weight_decay: f64) -> Sgd {
        self.weight_decay = weight_decay;
        self
    }

    /// Uses Nesterov's momentum.
    pub fn nesterov(mut self, nesterov: bool) -> Sgd {
        self.nesterov = nesterov;
        self
    }

    /// One update of every parameter from its gradient (one kernel per parameter array).
    ///
    /// # Errors
    /// A launch's error (a fault, a device error).
    pub fn step(&mut self) -> Result<()> {
        let (t, lr) = self.params.next_step();
        let (mu, damp, wd) = (self.momentum, self.dampening, self.weight_decay);
        let (nesterov, first) = (self.nesterov as i32, (t == 1) as i32);
        for p in &self.params.flats {
            match p {
                Flat::F32(x, g, s) => {
                    let f = |v: f64| v as f32;
                    let args = (g, &s[0], x, f(lr), f(mu), f(damp), f(wd), nesterov, first);
                    wp::launch(sgd_step, x.len(), args, x.device())?;
                }
                Flat::F64(x, g, s) => {
                    let args = (g, &s[0], x, lr, mu, damp, wd, nesterov, first);
                    wp::launch(sgd_step, x.len(), args, x.device())?;
                }
            }
        }
        Ok(())
    }
}
