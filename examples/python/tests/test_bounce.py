"""The computation op `bounce` (examples/python/src/bounce.rs): its gradient through every
framework against the pure-Rust one, and a short training run through it (train_bounce.py).

The reference is `ws.bounce_reference_gradient(v0, target)`: the Rust `bounce` example's tape
path (`Balls::gradient(Contact::Toi)`), loss `sum |x_final - target|^2` and `dloss/dv0`. Each
framework differentiates the same loss through `ws.bounce`: NumPy by `vjp_numpy` with the
cotangent `2 (x_final - target)`, JAX by `jax.grad`, torch by `torch.autograd.grad`.

Why 1e-12 relative to the largest component: both sides launch the same kernels (`step_toi`
and its adjoint, 100 steps) in the same order on the same device, so the only operations that
differ are the loss's seed, `2 (x_final - target)`, computed by the framework on one side and
by the adjoint of the Rust example's `distance_sq` on the other, and the op's extra copies
(the launch state, the output), whose adjoints add into zero. Doubling a difference is exact
in binary floating point, so the expected difference is zero (it is, bit for bit, on the CPU);
1e-12 leaves room for a framework that rounds the seed another way (a fused multiply-add), and
still fails at once on a wrong term: a missed reflection or a dropped step changes the
gradient at order 1.

The 64 balls are launched from 1 m at velocities in [1.5, 3] x [-2, 1] m/s: without the floor
each would be below y = -2.9 m at T = 1 s, so a final height above the floor proves it bounced.
The torch and CUDA tests SKIP without torch or a GPU. Run through run.py."""

import numpy as np
import warp_sim as ws
from _harness import Skip
from _harness import jax_device as _device
from _harness import jax_x64 as _jax

BALLS = 64
REL = 1e-12


def _case():
    """Launch velocities, targets (the landing points of other velocities: a loss of order 1),
    and the check that every ball bounced."""
    rng = np.random.default_rng(36)
    v0 = rng.uniform([1.5, -2.0], [3.0, 1.0], size=(BALLS, 2))
    target = ws.bounce.numpy(rng.uniform([1.5, -2.0], [3.0, 1.0], size=(BALLS, 2)))
    x = ws.bounce.numpy(v0)
    # Semi-implicit Euler's free flight from y = 1 over N = 100 steps of dt = 10 ms ends at
    # 1 + N dt vy + g dt^2 N (N + 1) / 2 = 1 + vy - 4.95 <= -2.95 m: above the floor means a bounce.
    assert (x[:, 1] > 0.0).all(), "a ball did not bounce"
    return v0, target


def _close(got, want, what):
    got, want = np.asarray(got), np.asarray(want)
    err = np.abs(got - want).max() / np.abs(want).max()
    assert err <= REL, "%s: gradient differs from the Rust tape's by %.3e relative (max |g| %.3e)" % (
        what,
        err,
        np.abs(want).max(),
    )
    return err


def test_gradient_numpy():
    v0, target = _case()
    loss, g_ref = ws.bounce_reference_gradient(v0, target)
    g_ref = np.array(np.from_dlpack(g_ref))
    x = ws.bounce.numpy(v0)
    assert abs(((x - target) ** 2).sum() - loss) <= REL * loss
    (g,) = ws.bounce.vjp_numpy((v0,), 2.0 * (x - target))
    _close(g, g_ref, "vjp_numpy")
    assert np.abs(g_ref).max() > 0.1



def _gradient_jax(kind):
    jax = _jax()
    dev = _device(jax, kind)
    v0, target = _case()
    # The reference on the op's device (from host arrays); its gradient comes back through
    # JAX's DLPack import, which also takes a GPU array.
    _, g_ref = ws.bounce_reference_gradient(v0, target, "cpu" if kind == "cpu" else "cuda:%d" % dev.id)
    g_ref = np.asarray(jax.numpy.from_dlpack(g_ref))
    vj, tj = jax.device_put(v0, dev), jax.device_put(target, dev)

    def loss(v):
        d = ws.bounce.jax(v) - tj
        return (d * d).sum()

    g = jax.grad(loss)(vj)
    assert list(g.devices())[0] == dev
    _close(np.asarray(g), g_ref, "jax.grad (%s)" % kind)
    _close(np.asarray(jax.jit(jax.grad(loss))(vj)), g_ref, "jit(jax.grad) (%s)" % kind)


def test_gradient_jax_cpu():
    _gradient_jax("cpu")


def test_gradient_jax_cuda():
    _gradient_jax("cuda")


def _torch():
    try:
        import torch
    except ImportError:
        raise Skip("torch", "PyTorch not installed")
    return torch


def _gradient_torch(kind):
    torch = _torch()
    if kind == "cuda" and not torch.cuda.is_available():
        raise Skip("cuda", "no CUDA device (torch.cuda.is_available() is False)")
    dev = torch.device("cuda:0" if kind == "cuda" else "cpu")
    v0, target = _case()
    v = torch.tensor(v0, device=dev, requires_grad=True)
    t = torch.tensor(target, device=dev)
    # The reference on the same device, from the tensors themselves.
    loss_ref, g_ref = ws.bounce_reference_gradient(v.detach(), t)
    g_ref = torch.from_dlpack(g_ref)
    assert g_ref.device == dev
    loss = ((ws.bounce.torch(v) - t) ** 2).sum()
    (g,) = torch.autograd.grad(loss, v)
    assert g.device == dev
    assert abs(float(loss.detach()) - loss_ref) <= REL * loss_ref
    _close(g.cpu().numpy(), g_ref.cpu().numpy(), "torch.autograd.grad (%s)" % kind)


def test_gradient_torch_cpu():
    _gradient_torch("cpu")


def test_gradient_torch_cuda():
    _gradient_torch("cuda")


# The short training run: 64 targets, 200 iterations. Measured (JAX, CPU, seeds 0-5): the loss
# fell 548x to 755x and the held-out mean distance went from 0.44 m to 1.6-2.1 cm, in under
# 1.1 s; 50x and 5 cm hold with a margin of 10x and 2x.
SHORT = dict(balls=64, iterations=200, lr=0.01, seed=0)
MIN_FALL = 50.0
MAX_HELD_OUT = 0.05


# JAX's and torch's runs start from the same weights and targets and take the same Adam steps
# through the same op: measured, their loss curves agree to 7e-14 relative over the 200
# iterations (rounding in the network's matrix products and in Adam's update, which the
# training does not amplify at this scale); 1e-9 fails on any difference in the method.
SAME_CURVE = 1e-9


def _train(framework, device):
    import train_bounce

    r = train_bounce.run(framework, device, **SHORT)
    assert r["fall"] >= MIN_FALL, "the loss fell only %.1fx (%s)" % (r["fall"], framework)
    assert r["held_out_after"] < MAX_HELD_OUT, "held-out mean distance %.4f m (%s)" % (
        r["held_out_after"],
        framework,
    )
    return np.array(r["losses"])


def test_train_jax():
    _jax()
    _train("jax", "cpu")


def test_train_torch():
    _torch()
    curve = _train("torch", "cpu")
    try:
        _jax()
    except Skip:
        return
    other = _train("jax", "cpu")
    err = (np.abs(curve - other) / other).max()
    assert err <= SAME_CURVE, "torch's and JAX's loss curves differ by %.3e relative" % err
