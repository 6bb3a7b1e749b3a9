//! The ocean scene's kernels (ops `ocean`, `ocean64`, `fd_normals`, `fd_normals64`): a
//! surface displaced by a sum of Gerstner waves, with analytic normals, and the normals of a
//! displaced grid by finite differences (to measure the analytic ones against).
//!
//! The model, for a rest point `x = (x1, x2)` of the horizontal plane at time `t` (y up), with
//! `M` waves of amplitude `a_i`, unit direction `d_i`, wavelength `l_i`, phase `p_i`,
//! `k_i = 2 pi / l_i`, `w_i = sqrt(g k_i)`, `theta_i = k_i d_i.x - w_i t + p_i`, and the
//! steepness `Q` shared out as `Q_i = Q / (k_i sum_j a_j)`:
//!
//! ```text
//! P       = (x1 - sum Q_i a_i d_i1 sin, sum a_i cos, x2 - sum Q_i a_i d_i2 sin)
//! dP/dx_j = (d_1j - sum Q_i a_i k_i d_i1 d_ij cos, -sum a_i k_i d_ij sin, d_2j - sum Q_i a_i k_i d_i2 d_ij cos)
//! N       = normalize(dP/dx2 x dP/dx1)
//! ```

use warp_lang as wp;
use wp::prelude::*;

/// Deep-water dispersion's gravity (m/s^2); ocean.py's closed form uses the same value.
const GRAVITY: f64 = 9.81;

/// A thread per grid point: the displaced position and the analytic normal of `rest[(i, j)]`
/// at `time[0]` (an array, so that a jitted frame loop compiles once).
#[wp::kernel]
#[allow(clippy::too_many_arguments)]
pub fn ocean_surface<F: Float>(
    rest: Array<Vec2<F>, 2>,
    amp: Array<F>,
    dir: Array<Vec2<F>>,
    wavelength: Array<F>,
    phase: Array<F>,
    time: Array<F>,
    steepness: F,
    pos: Array<Vec3<F>, 2>,
    normal: Array<Vec3<F>, 2>,
) {
    let (i, j) = tid();
    let x = rest[(i, j)];
    let t = time[0];
    let m = amp.len();
    let mut amp_sum = 0.0 as F;
    for w in 0..m {
        amp_sum += amp[w];
    }
    // P and its two tangents dP/dx1, dP/dx2, summed wave by wave. The wave's terms are a
    // func: inside a loop the adjoint keeps every value the body assigns on the per-thread
    // stack, inside a func only what the call overwrites (here the three sums).
    let q_per_amp = steepness / amp_sum;
    let mut p = Vec3::<F>::new(x.x, 0.0 as F, x.y);
    let mut t1 = Vec3::<F>::new(1.0 as F, 0.0 as F, 0.0 as F);
    let mut t2 = Vec3::<F>::new(0.0 as F, 0.0 as F, 1.0 as F);
    for w in 0..m {
        add_wave::<F>(
            &mut p, &mut t1, &mut t2, x, amp, dir, wavelength, phase, w, t, q_per_amp,
        );
    }
    pos[(i, j)] = p;
    normal[(i, j)] = normalize(cross(t2, t1));
}

/// Adds wave `w`'s terms of P, dP/dx1 and dP/dx2 at rest point `x` to `p`, `t1` and `t2`;
/// `q_per_amp` is `Q / sum a`.
#[wp::func]
#[allow(clippy::too_many_arguments)]
fn add_wave<F: Float>(
    p: &mut Vec3<F>,
    t1: &mut Vec3<F>,
    t2: &mut Vec3<F>,
    x: Vec2<F>,
    amp: Array<F>,
    dir: Array<Vec2<F>>,
    wavelength: Array<F>,
    phase: Array<F>,
    w: usize,
    t: F,
    q_per_amp: F,
) {
    let a = amp[w];
    let d = dir[w];
    let k = 2.0 as F * F::consts::PI / wavelength[w];
    let omega = sqrt(GRAVITY as F * k);
    let theta = k * dot(d, x) - omega * t + phase[w];
    let s = sin(theta);
    let c = cos(theta);
    // Q_i a_i = Q a_i / (k_i sum a), and Q_i a_i k_i.
    let qak = q_per_amp * a;
    let qa = qak / k;
    *p += Vec3::<F>::new(-qa * d.x * s, a * c, -qa * d.y * s);
    *t1 += Vec3::<F>::new(-qak * d.x * d.x * c, -a * k * d.x * s, -qak * d.y * d.x * c);
    *t2 += Vec3::<F>::new(-qak * d.x * d.y * c, -a * k * d.y * s, -qak * d.y * d.y * c);
}

/// The derivative of `pos` along one grid axis at index `k` of `n`, in units of the grid
/// step: central inside, second-order one-sided at the two borders (so the whole grid
/// converges as h^2, and the largest error is not a first-order border's).
#[wp::func]
fn axis_diff<F: Float>(f0: Vec3<F>, f1: Vec3<F>, f2: Vec3<F>) -> Vec3<F> {
    // (-3 f(x) + 4 f(x + h) - f(x + 2h)) / 2: f0 the border, f1 and f2 its inward neighbours
    // (for the far border they come in reversed order and the caller negates).
    (f1 * 4.0 - f0 * 3.0 - f2) * 0.5
}

/// A thread per grid point: the normal of the displaced grid `pos` by finite differences.
/// The grid step need not be given: scaling either tangent does not turn their cross product.
#[wp::kernel]
pub fn fd_normals<F: Float>(pos: Array<Vec3<F>, 2>, normal: Array<Vec3<F>, 2>) {
    let (i, j) = tid();
    let n1 = pos.shape()[0];
    let n2 = pos.shape()[1];
    let mut t1 = Vec3::<F>::splat(0.0);
    if i == 0 {
        t1 = axis_diff::<F>(pos[(0, j)], pos[(1, j)], pos[(2, j)]);
    } else if i == n1 - 1 {
        t1 = -axis_diff::<F>(pos[(i, j)], pos[(i - 1, j)], pos[(i - 2, j)]);
    } else {
        t1 = (pos[(i + 1, j)] - pos[(i - 1, j)]) * 0.5;
    }
    let mut t2 = Vec3::<F>::splat(0.0);
    if j == 0 {
        t2 = axis_diff::<F>(pos[(i, 0)], pos[(i, 1)], pos[(i, 2)]);
    } else if j == n2 - 1 {
        t2 = -axis_diff::<F>(pos[(i, j)], pos[(i, j - 1)], pos[(i, j - 2)]);
    } else {
        t2 = (pos[(i, j + 1)] - pos[(i, j - 1)]) * 0.5;
    }
    normal[(i, j)] = normalize(cross(t2, t1));
}

type Surface<F, V2, V3> = (
    Array<V2, 2>,
    Array<F>,
    Array<V2>,
    Array<F>,
    Array<F>,
    Array<F>,
    F,
    Array<V3, 2>,
    Array<V3, 2>,
);

/// The ops: `ocean` (f32) and `ocean64` take `(rest, amp, dir, wavelength, phase, time,
/// steepness)` and return `(pos, normal)`, each of `rest`'s grid shape (the launch's, by
/// default); `fd_normals` and `fd_normals64` take `pos` and return `normal`.
pub fn ops() -> wp::Result<Vec<wp::ops::Op>> {
    use wp::ops::Op;
    Ok(vec![
        Op::instance::<_, Surface<f32, Vec2, Vec3>>("ocean", ocean_surface)
            .outputs(["pos", "normal"])
            .build()?,
        Op::instance::<_, Surface<f64, DVec2, DVec3>>("ocean64", ocean_surface)
            .outputs(["pos", "normal"])
            .build()?,
        Op::instance::<_, (Array<Vec3, 2>, Array<Vec3, 2>)>("fd_normals", fd_normals)
            .outputs(["normal"])
            .build()?,
        Op::instance::<_, (Array<DVec3, 2>, Array<DVec3, 2>)>("fd_normals64", fd_normals)
            .outputs(["normal"])
            .build()?,
    ])
}
