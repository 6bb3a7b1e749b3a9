"""Tests of the warp_sim example module's interop functions: zero-copy round trips through DLPack with NumPy (CPU),
PyTorch (CPU and CUDA) and JAX (where installed), in-place kernels, and a Tape wrapped in a
torch.autograd.Function checked by torch.autograd.gradcheck.

Run from the repository root after building the module (see examples/python/Cargo.toml):
    python3 examples/python/test_warp_torch.py
Each part that lacks its framework or a GPU prints SKIPPED; any failure raises (exit status 1).
"""

import os
import sys

# JAX would otherwise take most of the GPU's memory at its first use.
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import warp_sim as wt  # noqa: E402

passed = []


def check(name, cond, detail=""):
    if not cond:
        raise AssertionError(f"{name}: {detail}")
    passed.append(name)
    print(f"ok   {name} {detail}")


def skipped(name, why):
    print(f"SKIPPED {name}: {why}")


def expected_integrate(x, v, dt):
    """One Euler step in float64 (the kernel's f32 result is within 1 ulp of it per op)."""
    out_x, out_v = [], []
    for p, q in zip(x, v):
        q2 = [q[0], q[1], q[2] - 9.81 * dt]
        out_v.append(q2)
        out_x.append([p[k] + q2[k] * dt for k in range(3)])
    return out_x, out_v


# ---------------------------------------------------------------- NumPy (CPU) -------------
def numpy_tests():
    try:
        import numpy as np
    except ImportError:
        skipped("numpy", "numpy not installed")
        return
    # A warp-lang array handed to NumPy: same address, the kernel's values.
    a = wt.ramp(1000, 1.0, 0.5, "cpu")
    n = np.from_dlpack(a)
    check("numpy.export.zero_copy", n.__array_interface__["data"][0] == a.ptr,
          f"numpy {n.__array_interface__['data'][0]:#x} == warp {a.ptr:#x}")
    check("numpy.export.values", np.array_equal(n, 1.0 + 0.5 * np.arange(1000, dtype=np.float32)))
    # A NumPy array taken by a kernel in place (import), and the same memory back (round trip).
    rng = np.random.default_rng(1)
    x = rng.standard_normal((257, 3)).astype(np.float32)
    v = rng.standard_normal((257, 3)).astype(np.float32)
    x0, v0 = x.copy(), v.copy()
    wt.integrate_(x, v, 0.01)
    ex, ev = expected_integrate(x0.astype(np.float64), v0.astype(np.float64), 0.01)
    # f32: two roundings per coordinate on values of order 1: 1e-6 absolute is a few ulps.
    err = max(np.abs(x - np.array(ex)).max(), np.abs(v - np.array(ev)).max())
    check("numpy.in_place.values", err < 1e-6, f"max error {err:.2e} (tolerance 1e-6)")
    back = np.from_dlpack(wt.as_vec3(x))
    check("numpy.round_trip.zero_copy",
          back.__array_interface__["data"][0] == x.__array_interface__["data"][0]
          and back.shape == (257, 3))
    # Mismatches are ValueErrors naming them.
    try:
        wt.integrate_(np.zeros((4, 2), np.float32), np.zeros((4, 2), np.float32), 0.1)
        check("numpy.bad_shape.error", False, "no error")
    except ValueError as e:
        check("numpy.bad_shape.error", "trailing axes" in str(e), str(e))
    try:
        wt.integrate_(np.zeros((4, 3), np.float64), np.zeros((4, 3), np.float32), 0.1)
        check("numpy.bad_dtype.error", False, "no error")
    except ValueError as e:
        check("numpy.bad_dtype.error", "float64" in str(e), str(e))


# ---------------------------------------------------------------- PyTorch -----------------
def torch_tests():
    try:
        import torch
    except ImportError:
        skipped("torch", "PyTorch not installed")
        return

    class WarpEnergy(torch.autograd.Function):
        """e_i = k/2 |x_i|^2 + sin(x_i.x) x_i.y + x_i.z^3/3, forward and backward by warp-lang."""

        @staticmethod
        def forward(ctx, x, k):
            stream = torch.cuda.current_stream(x.device).cuda_stream if x.is_cuda else None
            e, tape = wt.energy_forward(x.detach(), k, stream=stream)
            ctx.tape = tape
            return torch.from_dlpack(e)

        @staticmethod
        def backward(ctx, grad_e):
            return torch.from_dlpack(ctx.tape.backward(grad_e.contiguous())), None

    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    if len(devices) == 1:
        skipped("torch.cuda", "no CUDA device")
    for dev in devices:
        wdev = "cpu" if dev == "cpu" else f"cuda:{torch.cuda.current_device()}"
        stream = torch.cuda.current_stream().cuda_stream if dev == "cuda" else None
        # Export: a warp-lang array as a tensor, same address.
        a = wt.ramp(1 << 20, -3.0, 0.25, wdev, stream=stream)
        t = torch.from_dlpack(a)
        check(f"torch.{dev}.export.zero_copy", t.data_ptr() == a.ptr and t.device.type == dev,
              f"tensor {t.data_ptr():#x} == array {a.ptr:#x}")
        ref = -3.0 + 0.25 * torch.arange(1 << 20, dtype=torch.float64, device=dev)
        err = (t.double() - ref).abs().max().item()
        # f32 of values up to 2.6e5: half an ulp is 0.0078; the kernel rounds once or twice.
        check(f"torch.{dev}.export.values", err <= 0.016, f"max error {err:.3g} (tolerance 0.016)")
        # Import: a kernel updates PyTorch's memory in place, on PyTorch's stream and on
        # warp-lang's (ordered by DLPack's stream protocol, then waited for).
        for s in ([stream, None] if dev == "cuda" else [None]):
            g = torch.Generator(device=dev).manual_seed(3)
            x = torch.randn(100_003, 3, device=dev, generator=g)
            v = torch.randn(100_003, 3, device=dev, generator=g)
            x0, v0, ptr = x.clone(), v.clone(), x.data_ptr()
            wt.integrate_(x, v, 0.01, stream=s)
            v1 = v0.double() + torch.tensor([0.0, 0.0, -9.81 * 0.01], dtype=torch.float64, device=dev)
            x1 = x0.double() + v1 * 0.01
            err = max((x.double() - x1).abs().max().item(), (v.double() - v1).abs().max().item())
            how = "torch stream" if s is not None else "warp stream"
            # f32 values of order 1-5 (randn): a few roundings: 2e-6 absolute.
            check(f"torch.{dev}.in_place.values ({how})", err < 2e-6 and x.data_ptr() == ptr,
                  f"max error {err:.2e} (tolerance 2e-6), same address")
        back = torch.from_dlpack(wt.as_vec3(x))
        check(f"torch.{dev}.round_trip.zero_copy", back.data_ptr() == x.data_ptr()
              and back.shape == x.shape and torch.equal(back, x))
        # Autograd through the Tape: gradcheck's finite differences against our backward.
        xg = torch.randn(17, 3, dtype=torch.float64, device=dev, requires_grad=True)
        ok = torch.autograd.gradcheck(lambda x: WarpEnergy.apply(x, 2.5), (xg,), eps=1e-6,
                                      atol=1e-6, rtol=1e-5)
        check(f"torch.{dev}.gradcheck", ok, "(float64, eps 1e-6, atol 1e-6, rtol 1e-5)")
        # And against the closed form of the gradient.
        e = WarpEnergy.apply(xg, 2.5)
        e.sum().backward()
        p = xg.detach()
        closed = 2.5 * p.clone()
        closed[:, 0] += torch.cos(p[:, 0]) * p[:, 1]
        closed[:, 1] += torch.sin(p[:, 0])
        closed[:, 2] += p[:, 2] ** 2
        err = (xg.grad - closed).abs().max().item()
        check(f"torch.{dev}.grad.closed_form", err < 1e-12, f"max error {err:.2e} (f64: 1e-12)")


# ---------------------------------------------------------------- JAX ---------------------
def jax_tests():
    try:
        import jax
        import jax.numpy as jnp
    except ImportError:
        skipped("jax", "JAX not installed")
        return
    gpu = [d for d in jax.devices() if d.platform == "gpu"]
    dev = gpu[0] if gpu else jax.devices("cpu")[0]
    wdev = f"cuda:{dev.id}" if gpu else "cpu"
    a = wt.ramp(4096, 0.0, 1.0, wdev)
    j = jax.dlpack.from_dlpack(a)
    ptr = j.unsafe_buffer_pointer()
    check(f"jax.{dev.platform}.export.zero_copy", ptr == a.ptr, f"{ptr:#x} == {a.ptr:#x}")
    check(f"jax.{dev.platform}.export.values",
          bool(jnp.all(j == jnp.arange(4096, dtype=jnp.float32))))
    # A JAX array's memory seen by warp-lang (read through the round trip).
    x = jnp.arange(12, dtype=jnp.float32).reshape(4, 3)
    back = wt.as_vec3(x)
    check(f"jax.{dev.platform}.import.zero_copy", back.ptr == x.unsafe_buffer_pointer())


numpy_tests()
torch_tests()
jax_tests()
print(f"{len(passed)} checks passed")
