"""The ops of `warp_sim` on NumPy arrays (CPU): forward against closed forms, `vjp_numpy`
against closed-form gradients and central differences, the no-copy trace, and every bad-input
message the NumPy path can produce. Run through run.py (CI runs it)."""

import sys

import numpy as np
import warp_sim as ws
from _harness import raises

RNG = np.random.default_rng(36)
K = 1.75


def energy_closed(x, k):
    """The kernel's energy, written again in NumPy."""
    return 0.5 * k * (x * x).sum(axis=1) + np.sin(x[:, 0]) * x[:, 1] + x[:, 2] ** 3 / 3.0


def energy_grad_closed(x, k, g):
    """d(sum(g * e))/dx in closed form."""
    gx = np.empty_like(x)
    gx[:, 0] = k * x[:, 0] + np.cos(x[:, 0]) * x[:, 1]
    gx[:, 1] = k * x[:, 1] + np.sin(x[:, 0])
    gx[:, 2] = k * x[:, 2] + x[:, 2] ** 2
    return gx * g[:, None]


def test_module_layout():
    # The helper is installed as a submodule of the extension (`warp_sim._warp_lang`, or
    # `warp_sim.warp_sim._warp_lang` inside the package a maturin wheel installs) and each
    # op is its Op.
    helper = ws._warp_lang.__name__
    assert helper.endswith("warp_sim._warp_lang") and sys.modules[helper] is ws._warp_lang, helper
    assert isinstance(ws.energy, ws._warp_lang.Op)
    assert isinstance(ws.axpy, ws._warp_lang.Op)
    # The interop functions are still there.
    for f in ("integrate_", "ramp", "as_vec3", "energy_forward"):
        assert hasattr(ws, f), f


def test_spec():
    spec = ws.energy.spec
    assert spec["name"] == "energy" and spec["kind"] == "kernel"
    roles = [(p["name"], p["role"], p["dtype"], p["rank"], p["element"]) for p in spec["params"]]
    assert roles == [
        ("x", "input", "float64", 1, [3]),
        ("k", "scalar", "float64", 0, []),
        ("e", "output", "float64", 1, []),
    ], roles
    assert [p["differentiable"] for p in spec["params"]] == [True, False, True]
    assert "energy(x: Array<DVec3, 1>" in repr(ws.energy)
    assert [p["name"] for p in ws.axpy.spec["params"]] == ["a", "x", "y", "out"]


def test_energy_forward():
    x = RNG.normal(size=(257, 3))
    e = ws.energy.numpy(x, K)
    assert e.shape == (257,) and e.dtype == np.float64
    # The same formula in f64: only sin's last bits and the order of the adds may differ.
    np.testing.assert_allclose(e, energy_closed(x, K), rtol=1e-12, atol=1e-12)
    # Keywords, and the dispatching call (NumPy -> .numpy).
    np.testing.assert_array_equal(ws.energy.numpy(k=K, x=x), e)
    np.testing.assert_array_equal(ws.energy(x, K), e)
    # A NumPy scalar and an int for the static float.
    np.testing.assert_array_equal(ws.energy.numpy(x, np.float64(K)), e)
    np.testing.assert_allclose(ws.energy.numpy(x, 2), energy_closed(x, 2.0), rtol=1e-12, atol=1e-12)


def test_energy_strided_input():
    # A row-strided view goes through DLPack as it is (no copy) and gives the same values.
    base = RNG.normal(size=(40, 3))
    view = base[::3]
    e = ws.energy.numpy(view, K)
    assert ws.energy._trace_addresses()["x"] == view.ctypes.data
    np.testing.assert_array_equal(e, ws.energy.numpy(view.copy(), K))


def test_energy_no_copy():
    x = RNG.normal(size=(16, 3))
    e = ws.energy.numpy(x, K)
    trace = ws.energy._trace_addresses()
    # The kernel read x's memory and wrote e's own: no copy either way.
    assert trace["x"] == x.ctypes.data, (trace, x.ctypes.data)
    assert trace["e"] == e.ctypes.data, (trace, e.ctypes.data)


def test_energy_vjp_closed_form():
    x = RNG.normal(size=(64, 3))
    g = RNG.normal(size=64)
    (gx,) = ws.energy.vjp_numpy((x, K), g)
    assert gx.shape == x.shape and gx.dtype == np.float64
    # Each thread owns its row's gradient: only cos/sin's last bits differ.
    np.testing.assert_allclose(gx, energy_grad_closed(x, K, g), rtol=1e-12, atol=1e-12)
    # The cotangent was copied, not consumed: the caller's g is unchanged.
    assert np.all(g != 0)


def test_energy_vjp_central_differences():
    # f64 central differences of a smooth function with values of order 1: truncation about
    # eps^2 |f'''| ~ 1e-12, rounding about 1e-16 / eps ~ 1e-10, so atol 1e-7 / rtol 1e-6 leave
    # three orders of margin and still catch a wrong term (design §6).
    eps, atol, rtol = 1e-6, 1e-7, 1e-6
    x = RNG.normal(size=(6, 3))
    g = RNG.normal(size=6)
    (gx,) = ws.energy.vjp_numpy((x,), (g,), k=K)
    fd = np.zeros_like(x)
    for i in range(x.shape[0]):
        for c in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, c] += eps
            xm[i, c] -= eps
            fd[i, c] = (g @ ws.energy.numpy(xp, K) - g @ ws.energy.numpy(xm, K)) / (2 * eps)
    np.testing.assert_allclose(gx, fd, rtol=rtol, atol=atol)


def test_axpy_forward_and_vjp():
    n = 1000
    x = RNG.normal(size=n).astype(np.float32)
    y = RNG.normal(size=n).astype(np.float32)
    out = ws.axpy.numpy(2.5, x, y)
    assert out.dtype == np.float32
    # f32: a fused multiply-add and a separate multiply and add differ by at most one
    # rounding of the product (2^-24 relative); 1e-6 relative with a small atol allows it.
    np.testing.assert_allclose(out, np.float32(2.5) * x + y, rtol=1e-6, atol=1e-6)
    g = RNG.normal(size=n).astype(np.float32)
    gx, gy = ws.axpy.vjp_numpy((2.5, x, y), g)
    # The adjoint: gx = a g (one f32 product, exact as NumPy's), gy = g (a copy).
    np.testing.assert_array_equal(gx, np.float32(2.5) * g)
    np.testing.assert_array_equal(gy, g)
    trace = ws.axpy._trace_addresses()
    assert trace["grad:x"] == gx.ctypes.data and trace["grad:y"] == gy.ctypes.data
    assert trace["x"] == x.ctypes.data and trace["y"] == y.ctypes.data


def test_empty():
    # A call over no element launches nothing (a launch of zero threads is an error in
    # warp-lang) and returns empty outputs; its gradients are empty too.
    e = ws.energy.numpy(np.zeros((0, 3)), K)
    assert e.shape == (0,)
    (gx,) = ws.energy.vjp_numpy((np.zeros((0, 3)), K), np.zeros(0))
    assert gx.shape == (0, 3)


# ---- bad input (design §13): each message names the op, the parameter and the values.


def test_error_dtype():
    x32 = RNG.normal(size=(4, 3)).astype(np.float32)
    raises(TypeError, lambda: ws.energy.numpy(x32, K), "energy", "'x' (0)", "float32", "float64", "DVec3")
    xs = RNG.normal(size=4)
    raises(TypeError, lambda: ws.axpy.numpy(1.0, xs, xs), "axpy", "'x' (1)", "float64", "float32")


def test_error_shape():
    raises(ValueError, lambda: ws.energy.numpy(np.zeros((5, 2)), K), "energy", "'x' (0)", "[5, 2]", "(d0, 3)")
    raises(ValueError, lambda: ws.energy.numpy(np.zeros(5), K), "energy", "'x' (0)", "[5]", "(d0, 3)")
    raises(ValueError, lambda: ws.energy.numpy(np.zeros((2, 5, 3)), K), "energy", "'x' (0)", "[2, 5, 3]")


def test_error_short_input():
    # x and y of different lengths: the launch is x's length (the default rule: the first
    # input array) and axpy declares no rule tying y to it, so the kernel's bounds check
    # (on the CPU, at the call) names the kernel, the argument and the index.
    x = np.zeros(8, np.float32)
    y = np.zeros(5, np.float32)
    raises(RuntimeError, lambda: ws.axpy.numpy(1.0, x, y), "axpy", "`y`", "[5]", "out of bounds")


def test_error_trailing_strides():
    # A transposed (3, n) array has shape (n, 3) but its components are not adjacent.
    xt = np.zeros((3, 5)).T
    raises(ValueError, lambda: ws.energy.numpy(xt, K), "energy", "'x'", "trailing")


def test_error_read_only():
    x = np.zeros((4, 3))
    x.setflags(write=False)
    raises(ValueError, lambda: ws.energy.numpy(x, K), "energy", "'x' (0)")


def test_error_not_an_array():
    raises(TypeError, lambda: ws.energy.numpy([[0.0, 0.0, 0.0]], K), "energy", "'x' (0)", "list", "NumPy array")


def test_error_scalars():
    x = np.zeros((4, 3))
    raises(TypeError, lambda: ws.energy.numpy(x, "1.0"), "energy", "'k' (1)", "str", "float64")
    raises(TypeError, lambda: ws.energy.numpy(x, np.zeros(2)), "energy", "'k' (1)", "ndarray")
    xs = np.zeros(4, np.float32)
    raises(ValueError, lambda: ws.axpy.numpy(True, xs, xs), "axpy", "'a'", "true", "float32")


def affine_closed(m, b, x):
    """`affine`'s y = m x + b for each row of x, m given row-major."""
    return x @ np.asarray(m, dtype=np.float64).reshape(3, 3).T + np.asarray(b, dtype=np.float64)


def test_affine_matrix_and_vector_values():
    x = RNG.normal(size=(33, 3))
    m = RNG.normal(size=(3, 3))
    b = RNG.normal(size=3)
    want = affine_closed(m, b, x)
    # Nested or flat, lists, tuples or NumPy arrays: the same components, row-major. f64 with
    # three products a row: only the order of two adds may differ from NumPy's matmul.
    for mm, bb in ((m, b), (m.tolist(), tuple(b)), (m.ravel().tolist(), list(b)), (m.ravel(), b.tolist())):
        np.testing.assert_allclose(ws.affine.numpy(mm, bb, x), want, rtol=1e-13, atol=1e-13)
    # Row i, column j is m[i][j]: one nonzero entry, no rounding at all.
    e = np.zeros((3, 3))
    e[0, 2] = 2.0
    y = ws.affine.numpy(e, (0, 0, 1), x)
    assert (y[:, 0] == 2 * x[:, 2]).all() and (y[:, 1] == 0).all() and (y[:, 2] == 1).all()
    # Integers are values of a float64 matrix too.
    np.testing.assert_array_equal(ws.affine.numpy([[1, 0, 0], [0, 1, 0], [0, 0, 1]], [0, 0, 0], x), x)
    spec = {p["name"]: p for p in ws.affine.spec["params"]}
    assert (spec["m"]["role"], spec["m"]["element"], spec["m"]["type"]) == ("scalar", [3, 3], "DMat3")
    assert spec["b"]["element"] == [3] and "a static DVec3" in spec["b"]["describe"]


def test_affine_vjp_transposes_the_matrix():
    x = RNG.normal(size=(20, 3))
    m = RNG.normal(size=(3, 3))
    ct = RNG.normal(size=(20, 3))
    (gx,) = ws.affine.vjp_numpy((m, np.ones(3), x), ct)
    # dy/dx = m: the gradient is ct m (m^T ct per row).
    np.testing.assert_allclose(gx, ct @ m, rtol=1e-13, atol=1e-13)


def test_error_vector_values():
    x = np.zeros((4, 3))
    eye = np.eye(3)
    raises(ValueError, lambda: ws.affine.numpy(eye, [1.0, 2.0], x), "affine", "'b'", "2 numbers", "DVec3", "3 numbers")
    raises(ValueError, lambda: ws.affine.numpy(np.eye(4), [0, 0, 0], x), "affine", "'m'", "16 numbers", "DMat3")
    raises(ValueError, lambda: ws.affine.numpy(eye, 1.0, x), "affine", "'b'", "1 number;", "DVec3")
    raises(TypeError, lambda: ws.affine.numpy(eye, ["a", 0, 0], x), "affine", "'b'", "str")


def test_error_arguments():
    x = np.zeros((4, 3))
    raises(TypeError, lambda: ws.energy.numpy(x, K, 3), "energy takes 2 arguments (3 given)", "energy(x: Array<DVec3")
    raises(TypeError, lambda: ws.energy.numpy(x), "energy missing 1 required argument: 'k'", "k: a static float64")
    raises(TypeError, lambda: ws.energy.numpy(x, K, kk=1), "energy got an unexpected keyword argument 'kk'")
    raises(TypeError, lambda: ws.energy.numpy(x, K, x=x), "energy got multiple values for argument 'x'")


def test_error_cotangents():
    x = np.zeros((4, 3))
    raises(ValueError, lambda: ws.energy.vjp_numpy((x, K), np.ones(3)), "energy", "output 'e'", "(3,)", "(4,)")
    raises(TypeError, lambda: ws.energy.vjp_numpy((x, K), (np.ones(4), np.ones(4))), "energy", "2 cotangents", "1 outputs")


def test_error_native_gradient_for_scalar():
    # The native check behind the helper: a gradient for a parameter that has none.
    xs = np.zeros(4, np.float32)
    args = [1.0, xs, xs, np.zeros(4, np.float32)]
    raises(ValueError, lambda: ws.axpy._native._backward(None, args, [xs, None, None, None]), "axpy", "'a' (0)", "no gradient")


def test_error_native_argument_count():
    raises(TypeError, lambda: ws.axpy._native._forward(None, [1.0]), "axpy", "4 arguments", "a, x, y, out")
