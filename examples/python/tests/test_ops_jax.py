"""The ops of `warp_sim` as JAX functions through XLA's FFI (`op.jax`): forward against the
closed form under `jax.jit`, reverse mode through the kernel's adjoint (`jax.grad`,
`jax.vjp`, `jax.test_util.check_grads` in f64), `jax.vmap` over a leading batch axis (of the
forward and of the gradient), and the trace-time errors. The CPU tests run in CI (jax 0.10.2);
the CUDA ones need a GPU jaxlib (the GPU machine) and say SKIPPED elsewhere. Without JAX every
test prints SKIPPED. Run through run.py."""

import numpy as np
import warp_sim as ws
from _harness import jax_device as _device
from _harness import jax_x64 as _jax
from _harness import raises

K = 1.75
# check_grads' tolerances: f64 central differences of smooth kernels with values of order 1
# (step 1e-4 in check_grads' default for f64: truncation about eps^2 |f'''| ~ 1e-8, rounding
# 1e-16 / eps ~ 1e-12), so 1e-6 leaves two orders of margin and still catches a wrong term.
CHECK = dict(atol=1e-6, rtol=1e-6)




def _energy_closed(jnp, x, k):
    return 0.5 * k * (x * x).sum(axis=-1) + jnp.sin(x[..., 0]) * x[..., 1] + x[..., 2] ** 3 / 3.0


def _energy_grad_closed(x, k, g):
    gx = np.empty_like(x)
    gx[:, 0] = k * x[:, 0] + np.cos(x[:, 0]) * x[:, 1]
    gx[:, 1] = k * x[:, 1] + np.sin(x[:, 0])
    gx[:, 2] = k * x[:, 2] + x[:, 2] ** 2
    return gx * g[:, None]


def _forward_jit(kind):
    jax = _jax()
    import jax.numpy as jnp

    dev = _device(jax, kind)
    x = jax.device_put(np.random.default_rng(1).normal(size=(513, 3)), dev)
    e = jax.jit(lambda x: ws.energy.jax(x, K))(x)
    assert e.shape == (513,) and e.dtype == jnp.float64
    assert list(e.devices())[0] == dev
    # f64, the same formula: only sin's last bits and the order of the adds differ.
    np.testing.assert_allclose(np.asarray(e), np.asarray(_energy_closed(jnp, x, K)), rtol=1e-12, atol=1e-12)
    # The dispatching call takes JAX arrays to .jax; outside jit too.
    np.testing.assert_array_equal(np.asarray(ws.energy(x, K)), np.asarray(e))


def _grad_closed_form(kind):
    jax = _jax()
    dev = _device(jax, kind)
    rng = np.random.default_rng(2)
    x = rng.normal(size=(300, 3))
    g = rng.normal(size=300)
    xj, gj = jax.device_put(x, dev), jax.device_put(g, dev)
    loss = jax.jit(jax.grad(lambda x, g: (ws.energy.jax(x, K) * g).sum()))
    gx = np.asarray(loss(xj, gj))
    # Each thread owns its row's gradient: only cos/sin's last bits differ.
    np.testing.assert_allclose(gx, _energy_grad_closed(x, K, g), rtol=1e-12, atol=1e-12)
    # jax.vjp gives the same, and leaves the cotangent as it was (the adjoint reads a copy).
    e, vjp = jax.vjp(lambda x: ws.energy.jax(x, K), xj)
    (gx2,) = vjp(gj)
    np.testing.assert_array_equal(np.asarray(gx2), gx)
    np.testing.assert_array_equal(np.asarray(gj), g)


def _check_grads(kind):
    jax = _jax()
    from jax.test_util import check_grads

    dev = _device(jax, kind)
    x = jax.device_put(np.random.default_rng(3).normal(size=(7, 3)), dev)
    check_grads(lambda x: ws.energy.jax(x, K), (x,), order=1, modes=["rev"], **CHECK)
    check_grads(jax.jit(lambda x: ws.energy.jax(x, 0.5)), (x,), order=1, modes=["rev"], **CHECK)


def _vmap(kind):
    jax = _jax()
    import jax.numpy as jnp

    dev = _device(jax, kind)
    rng = np.random.default_rng(4)
    xb = jax.device_put(rng.normal(size=(5, 40, 3)), dev)
    f = lambda x: ws.energy.jax(x, K)  # noqa: E731
    eb = jax.jit(jax.vmap(f))(xb)
    assert eb.shape == (5, 40)
    for b in range(5):
        np.testing.assert_array_equal(np.asarray(eb[b]), np.asarray(f(xb[b])))
    # The gradient of a batched loss, and a batched gradient with an unbatched cotangent.
    g = jax.device_put(rng.normal(size=40), dev)
    gb = jax.jit(jax.vmap(jax.grad(lambda x: (f(x) * g).sum())))(xb)
    for b in range(5):
        np.testing.assert_allclose(
            np.asarray(gb[b]), _energy_grad_closed(np.asarray(xb[b]), K, np.asarray(g)), rtol=1e-12, atol=1e-12
        )
    # axpy: two batched operands and one unbatched, f32.
    a = 2.5
    xs = jax.device_put(rng.normal(size=(3, 100)).astype(np.float32), dev)
    y = jax.device_put(rng.normal(size=100).astype(np.float32), dev)
    out = jax.vmap(lambda x: ws.axpy.jax(a, x, y))(xs)
    # f32: a fused multiply-add differs from a multiply then an add by one rounding of the
    # product at most (2^-24 relative).
    np.testing.assert_allclose(np.asarray(out), np.float32(a) * np.asarray(xs) + np.asarray(y), rtol=1e-6, atol=1e-6)
    assert out.dtype == jnp.float32


def _axpy_grads(kind):
    jax = _jax()
    dev = _device(jax, kind)
    rng = np.random.default_rng(5)
    x = jax.device_put(rng.normal(size=1000).astype(np.float32), dev)
    y = jax.device_put(rng.normal(size=1000).astype(np.float32), dev)
    g = rng.normal(size=1000).astype(np.float32)
    _, vjp = jax.vjp(lambda x, y: ws.axpy.jax(2.5, x, y), x, y)
    gx, gy = vjp(jax.device_put(g, dev))
    # The adjoint: gx = a g (one f32 product, exact as NumPy's), gy = g.
    np.testing.assert_array_equal(np.asarray(gx), np.float32(2.5) * g)
    np.testing.assert_array_equal(np.asarray(gy), g)


def _affine(kind):
    # A matrix and a vector value under jit: array attributes, row-major; jax.grad through
    # the adjoint (m^T ct); one jitted function per set of values.
    jax = _jax()
    dev = _device(jax, kind)
    rng = np.random.default_rng(5)
    x, m, b = rng.normal(size=(65, 3)), rng.normal(size=(3, 3)), rng.normal(size=3)
    xj = jax.device_put(x, dev)
    y = jax.jit(lambda x: ws.affine.jax(m, b, x))(xj)
    np.testing.assert_allclose(np.asarray(y), x @ m.T + b, rtol=1e-13, atol=1e-13)
    y2 = jax.jit(lambda x: ws.affine.jax(m.tolist(), tuple(b), x))(xj)
    np.testing.assert_array_equal(np.asarray(y2), np.asarray(y))
    ct = rng.normal(size=(65, 3))
    gx = jax.grad(lambda x: (ws.affine.jax(m, b, x) * ct).sum())(xj)
    np.testing.assert_allclose(np.asarray(gx), ct @ m, rtol=1e-13, atol=1e-13)
    # A traced matrix is refused at trace time, naming the parameter.
    raises(TypeError, lambda: jax.jit(lambda m, x: ws.affine.jax(m, b, x))(m, xj), "affine", "'m'", "static")


def test_affine_values_cpu():
    _affine("cpu")


def test_affine_values_cuda():
    _affine("cuda")


def test_forward_jit_cpu():
    _forward_jit("cpu")


def test_grad_closed_form_cpu():
    _grad_closed_form("cpu")


def test_check_grads_cpu():
    _check_grads("cpu")


def test_vmap_cpu():
    _vmap("cpu")


def test_axpy_grads_cpu():
    _axpy_grads("cpu")


def test_empty_cpu():
    jax = _jax()
    import jax.numpy as jnp

    x = jnp.zeros((0, 3), jnp.float64)
    e = jax.jit(lambda x: ws.energy.jax(x, K))(x)
    assert e.shape == (0,)
    gx = jax.grad(lambda x: ws.energy.jax(x, K).sum())(x)
    assert gx.shape == (0, 3)


def test_errors_cpu():
    jax = _jax()
    import jax.numpy as jnp

    x = jnp.ones((4, 3), jnp.float64)
    raises(TypeError, lambda: ws.energy.jax(x.astype(jnp.float32), K), "energy", "'x'", "float32", "float64")
    raises(ValueError, lambda: ws.energy.jax(jnp.ones((4, 2)), K), "energy", "'x'", "[4, 2]", "(d0, 3)")
    # A traced scalar: scalars are static attributes.
    raises(TypeError, lambda: jax.jit(lambda k: ws.energy.jax(x, k))(1.0), "energy", "'k'", "static")
    raises(TypeError, lambda: ws.energy.jax(x), "energy", "missing", "'k'")
    # f64 with jax_enable_x64 off names the flag.
    jax.config.update("jax_enable_x64", False)
    try:
        raises(TypeError, lambda: ws.energy.jax(np.ones((4, 3)), 3.0), "energy", "jax_enable_x64")
    finally:
        jax.config.update("jax_enable_x64", True)


def test_forward_jit_cuda():
    _forward_jit("gpu")


def test_grad_closed_form_cuda():
    _grad_closed_form("gpu")


def test_check_grads_cuda():
    _check_grads("gpu")


def test_vmap_cuda():
    _vmap("gpu")


def test_axpy_grads_cuda():
    _axpy_grads("gpu")


def test_command_buffer_cuda():
    # A jitted loop of many op calls, which XLA may record into a CUDA graph (command buffer):
    # the op's graph target says it can be captured, and the result must not change.
    jax = _jax()
    dev = _device(jax, "gpu")
    rng = np.random.default_rng(6)
    x = jax.device_put(rng.normal(size=4096).astype(np.float32), dev)
    y = jax.device_put(rng.normal(size=4096).astype(np.float32), dev)

    @jax.jit
    def many(x, y):
        for _ in range(16):
            y = ws.axpy.jax(0.5, x, y)
        return y

    want = np.asarray(y)
    for _ in range(16):
        want = np.float32(0.5) * np.asarray(x) + want
    for _ in range(3):
        np.testing.assert_allclose(np.asarray(many(x, y)), want, rtol=1e-5, atol=1e-5)
