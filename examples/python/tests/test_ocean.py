"""The ocean scene (ocean.py; kernels in src/ocean.rs): the ops `ocean` (f32) and `ocean64`
against the closed form in NumPy float64 (the f32 rounding bound, f64 within 1e-12), the
second-order convergence of `fd_normals64`, and the amplitude fit through `ocean64.jax`
(the gradient against jax.grad of the jax.numpy closed form, Adam, BFGS). The NumPy tests
need no JAX; the JAX ones print SKIPPED without it, the CUDA ones without a GPU jaxlib. Run
through run.py."""

import numpy as np
import ocean
import warp_sim as ws
from _harness import jax_device as _device
from _harness import jax_x64 as _jax

# Times with phases of both signs and a few periods of the slowest wave.
TIMES = (0.0, 1.3, 4.0)




def _scene(n=96, m=16, q=0.6):
    return ocean.make_grid(n), ocean.make_waves(m), q


def test_f32_bound():
    rest, w, q = _scene()
    errs = ocean.errors(rest, w, TIMES, q)
    b_pos, b_ang = ocean.f32_bounds(rest, w, TIMES)
    ep, ea = errs["ocean (f32)"]
    # The bound is the rounding of the phases (f32's eps times the largest phase, per wave);
    # measured about 7x below it for positions and 40x for normals.
    assert ep < b_pos and ea < b_ang, (errs, b_pos, b_ang)
    # And not vacuous: f32 arithmetic does show.
    assert ep > 1e-7, ep


def test_f64_closed_form():
    rest, w, q = _scene()
    ep, ea = ocean.errors(rest, w, TIMES, q)["ocean64 (f64)"]
    # The same sums as the closed form in another order: rounding of positions up to 64 m.
    assert ep < 1e-12 and ea < 1e-12, (ep, ea)


def test_fd_normals_second_order():
    # Halving the step divides the largest angle by about 4 (second order, borders included:
    # they are one-sided of second order). Measured 4.06, 4.04, 4.03 (and within 3.91..4.26
    # at other times), the largest error on a border where an h^3 term still moves it off 4.
    _, w, q = _scene()
    errs = ocean.fd_convergence(w, q, 0.7, ocean.FD_SIZES)
    ratios = [a / b for a, b in zip(errs, errs[1:])]
    assert len(ratios) == 3 and all(3.6 <= r <= 4.4 for r in ratios), (errs, ratios)
    # The f32 instance agrees with the f64 one where rounding is far below truncation.
    rest = ocean.make_grid(129)
    p, _ = ws.ocean.numpy(*ocean.op_args(rest, w, 0.7, np.float32), q)
    p64, _ = ws.ocean64.numpy(*ocean.op_args(rest, w, 0.7, np.float64), q)
    n32, n64 = ws.fd_normals.numpy(p), ws.fd_normals64.numpy(p64)
    assert ocean.angle(n32.astype(np.float64), n64).max() < 1e-4


def _surface_jit(kind):
    jax = _jax()
    import jax.numpy as jnp

    dev = _device(jax, kind)
    rest, w, q = _scene()
    b_pos, b_ang = ocean.f32_bounds(rest, w, TIMES)
    for op, dt, (bp, ba) in ((ws.ocean, np.float32, (b_pos, b_ang)), (ws.ocean64, np.float64, (1e-12, 1e-12))):
        args = [jax.device_put(a, dev) for a in ocean.op_args(rest, w, 0.0, dt)]
        f = jax.jit(lambda *a: op.jax(*a, q))
        for t in TIMES:
            p, n = f(*args[:5], jax.device_put(np.array([t], dt), dev))
            assert list(p.devices())[0] == dev and p.dtype == jnp.dtype(dt)
            host = [a.astype(np.float64) for a in ocean.op_args(rest, w, t, dt)]
            exact = ocean.closed_form(np, *host[:5], host[5][0], float(dt(q)))
            assert np.abs(np.asarray(p) - exact[0]).max() < bp
            assert ocean.angle(np.asarray(n).astype(np.float64), exact[1]).max() < ba


def _fit_setup(jax, dev):
    import jax.numpy as jnp

    rest, w, true, start = ocean.fit_problem()
    targets = ocean.fit_targets(rest, w)
    with jax.default_device(dev):
        loss = ocean.fit_loss(jax, ws.ocean64, rest, w, targets, jnp.float64)
        closed = ocean.fit_loss(jax, None, rest, w, targets, jnp.float64, closed=True)
        loss32 = ocean.fit_loss(jax, ws.ocean, rest, w, targets, jnp.float32)
    return loss, closed, loss32, true, jax.device_put(start, dev)


def _rel(a, true):
    return float(np.abs(np.asarray(a) - true).max() / np.abs(true).max())


def _fit_gradient(kind):
    jax = _jax()
    dev = _device(jax, kind)
    loss, closed, _, _, start = _fit_setup(jax, dev)
    g = np.asarray(jax.jit(jax.grad(loss))(start))
    g_cf = np.asarray(jax.jit(jax.grad(closed))(start))
    # The op's adjoint sums over the grid with atomics, the closed form by XLA's reduction:
    # equal up to the order of the sums (measured 2e-15 on the CPU).
    assert np.abs(g - g_cf).max() <= 1e-10 * np.abs(g_cf).max(), (g, g_cf)
    np.testing.assert_allclose(float(loss(start)), float(closed(start)), rtol=1e-12)


def _fit_adam(kind):
    jax = _jax()
    import jax.numpy as jnp

    dev = _device(jax, kind)
    loss, _, loss32, true, start = _fit_setup(jax, dev)
    with jax.default_device(dev):
        a, curve = ocean.adam(jax, loss, start)
        a32, curve32 = ocean.adam(jax, loss32, jnp.asarray(start, jnp.float32))
    # Section 10's numbers: the loss falls by 1e3 or more, f32's amplitudes within 1e-3
    # relative. Measured on the CPU: a fall of 2.6e8 and 1.2e-4 relative, both precisions.
    assert curve[0] / curve[-1] >= 1e3, curve[-1]
    assert _rel(a, true) < 1e-3 and _rel(a32, true) < 1e-3, (_rel(a, true), _rel(a32, true))
    assert curve32[0] / curve32[-1] >= 1e3


def _fit_bfgs(kind):
    jax = _jax()
    dev = _device(jax, kind)
    loss, _, _, true, start = _fit_setup(jax, dev)
    with jax.default_device(dev):
        a, f, nit = ocean.bfgs(jax, loss, start)
    # A noise-free target: an exact fit exists. Measured 4.5e-11 relative in 14 iterations.
    assert _rel(a, true) < 1e-6, (_rel(a, true), f, nit)


def test_surface_jit_cpu():
    _surface_jit("cpu")


def test_fit_gradient_cpu():
    _fit_gradient("cpu")


def test_fit_adam_cpu():
    _fit_adam("cpu")


def test_fit_bfgs_cpu():
    _fit_bfgs("cpu")


def test_surface_jit_cuda():
    _surface_jit("gpu")


def test_fit_gradient_cuda():
    _fit_gradient("gpu")


def test_fit_bfgs_cuda():
    _fit_bfgs("gpu")
