//! Adjoints of Perlin noise ([`crate::builtins::noise`]): `noise` and `pnoise` are
//! differentiable with respect to their position (Warp's rule); the state and the periods are
//! integers and get nothing.
//!
//! `adj_x[k] += grad[k] * adj_ret`, where `grad` is the analytic gradient of the noise at `x`
//! (computed with the value's blends, see `perlin`). Inside a cell the noise is a polynomial
//! of the offsets, so this is its exact derivative up to rounding; across cell faces the noise
//! is C¹, so the gradient is continuous too.

use crate::builtins::noise::{perlin, NoiseArg};

/// Adjoint of `noise(state, x)`.
#[inline(always)]
pub fn adj_noise<T: NoiseArg>(state: u32, x: T, _adj_state: &mut u32, adj_x: &mut T, adj_ret: f32) {
    let (_, g) = perlin(state, x.lanes(), None, T::N, true);
    adj_x.accum_scaled(g, adj_ret);
}

/// Adjoint of `pnoise(state, x, period)`.
#[inline(always)]
pub fn adj_pnoise<T: NoiseArg>(
    state: u32,
    x: T,
    period: T::Period,
    _adj_state: &mut u32,
    adj_x: &mut T,
    _adj_period: &mut T::Period,
    adj_ret: f32,
) {
    let (_, g) = perlin(state, x.lanes(), Some(T::periods(period)), T::N, true);
    adj_x.accum_scaled(g, adj_ret);
}
