"""The ops of `warp_sim` as `torch.autograd.Function`s, on CPU and CUDA tensors:
`gradcheck` in f64, closed-form gradients, an `nn.Module` trained through an op, the stream
test (the op runs on torch's current stream and synchronises nothing), the no-copy trace
against `data_ptr()`, and the bad-input messages only torch can produce. Without PyTorch every
test prints SKIPPED (CI); without a GPU the CUDA ones do. Run through run.py."""

import math

import warp_sim as ws
from _harness import Skip, raises

K = 1.75
# gradcheck's tolerances (design §6): f64 central differences of smooth kernels with values
# of order 1 have truncation error about eps^2 |f'''| ~ 1e-12 and rounding about
# 1e-16 / eps ~ 1e-10, so atol 1e-7 leaves three orders of margin and still catches a wrong term.
GRADCHECK = dict(eps=1e-6, atol=1e-7, rtol=1e-6)
# About half a second of GPU time at ~2 GHz: far longer than the host's work between queuing
# the sleep and the op returning (a DLPack import and one launch, microseconds to milliseconds).
SLEEP_CYCLES = 1_000_000_000


def _torch():
    try:
        import torch
    except ImportError:
        raise Skip("torch", "PyTorch not installed")
    return torch


def _cuda(torch):
    if not torch.cuda.is_available():
        raise Skip("cuda", "no CUDA device (torch.cuda.is_available() is False)")
    return torch.device("cuda:0")


def _energy_closed(torch, x, k):
    return 0.5 * k * (x * x).sum(dim=1) + torch.sin(x[:, 0]) * x[:, 1] + x[:, 2] ** 3 / 3.0


def _energy_grad_closed(torch, x, k, g):
    gx = torch.empty_like(x)
    gx[:, 0] = k * x[:, 0] + torch.cos(x[:, 0]) * x[:, 1]
    gx[:, 1] = k * x[:, 1] + torch.sin(x[:, 0])
    gx[:, 2] = k * x[:, 2] + x[:, 2] ** 2
    return gx * g[:, None]


def _gradcheck(torch, dev):
    gen = torch.Generator().manual_seed(1)
    x = torch.randn(7, 3, dtype=torch.float64, generator=gen).to(dev).requires_grad_()
    assert torch.autograd.gradcheck(lambda x: ws.energy.torch(x, K), (x,), **GRADCHECK)


def _closed_form(torch, dev):
    gen = torch.Generator().manual_seed(2)
    x = torch.randn(300, 3, dtype=torch.float64, generator=gen).to(dev).requires_grad_()
    g = torch.randn(300, dtype=torch.float64, generator=gen).to(dev)
    e = ws.energy.torch(x, K)
    assert e.device == x.device and e.dtype == torch.float64 and e.requires_grad
    xd = x.detach()
    # Same formula in f64: only sin/cos's last bits and the order of the adds differ.
    torch.testing.assert_close(e.detach(), _energy_closed(torch, xd, K), rtol=1e-12, atol=1e-12)
    e.backward(g)
    torch.testing.assert_close(x.grad, _energy_grad_closed(torch, xd, K, g), rtol=1e-12, atol=1e-12)
    # The dispatching call takes torch tensors to .torch.
    torch.testing.assert_close(ws.energy(xd, K), e.detach(), rtol=0, atol=0)


def _trace(torch, dev):
    gen = torch.Generator().manual_seed(3)
    x = torch.randn(1000, dtype=torch.float32, generator=gen).to(dev).requires_grad_()
    y = torch.randn(1000, dtype=torch.float32, generator=gen).to(dev).requires_grad_()
    out = ws.axpy.torch(2.5, x, y)
    trace = ws.axpy._trace_addresses()
    # The kernel read the tensors' own memory and wrote the output's: nothing was copied.
    assert trace["x"] == x.data_ptr() and trace["y"] == y.data_ptr(), trace
    assert trace["out"] == out.data_ptr(), trace
    g = torch.randn(1000, dtype=torch.float32, generator=gen).to(dev)
    out.backward(g)
    trace = ws.axpy._trace_addresses()
    # The backward reads the saved inputs in place too.
    assert trace["x"] == x.data_ptr() and trace["out"] == out.data_ptr(), trace
    # axpy's adjoint: x.grad = a g (one f32 product, as torch's), y.grad = g.
    torch.testing.assert_close(x.grad, 2.5 * g, rtol=0, atol=0)
    torch.testing.assert_close(y.grad, g, rtol=0, atol=0)


def _training(torch, dev):
    torch.manual_seed(0)

    class Net(torch.nn.Module):
        """Positions from a linear layer; the loss is their mean energy through the op."""

        def __init__(self):
            super().__init__()
            self.lin = torch.nn.Linear(4, 3, dtype=torch.float64)

        def forward(self, z):
            return ws.energy.torch(self.lin(z), K).mean()

    net = Net().to(dev)
    z = (0.5 * torch.randn(64, 4, dtype=torch.float64)).to(dev)
    opt = torch.optim.Adam(net.parameters(), lr=0.05)
    losses = []
    for _ in range(50):
        opt.zero_grad()
        loss = net(z)
        loss.backward()
        opt.step()
        losses.append(loss.item())
    # The energy's minimum near the origin is 0 (positive definite there for K > 1); Adam
    # from positions of order 0.5 gets well below a quarter of the start in 50 steps.
    assert losses[-1] < 0.25 * losses[0], losses
    assert all(math.isfinite(v) for v in losses), losses
    # The layer's parameters received gradients through the op.
    assert net.lin.weight.grad is not None and float(net.lin.weight.grad.abs().sum()) > 0


def test_gradcheck_cpu():
    torch = _torch()
    _gradcheck(torch, torch.device("cpu"))


def test_closed_form_cpu():
    torch = _torch()
    _closed_form(torch, torch.device("cpu"))


def test_trace_addresses_cpu():
    torch = _torch()
    _trace(torch, torch.device("cpu"))


def test_training_cpu():
    torch = _torch()
    _training(torch, torch.device("cpu"))


def test_strided_input_cpu():
    # A row-strided view goes in without a copy; its gradient has the view's layout and
    # flows back to the base's rows.
    torch = _torch()
    gen = torch.Generator().manual_seed(4)
    base = torch.randn(10, 3, dtype=torch.float64, generator=gen).requires_grad_()
    x = base[::2]
    e = ws.energy.torch(x, K)
    assert ws.energy._trace_addresses()["x"] == x.data_ptr()
    g = torch.randn(5, dtype=torch.float64, generator=gen)
    e.backward(g)
    want = torch.zeros_like(base)
    want[::2] = _energy_grad_closed(torch, x.detach(), K, g)
    torch.testing.assert_close(base.grad, want, rtol=1e-12, atol=1e-12)


def test_empty_cpu():
    torch = _torch()
    x = torch.zeros(0, 3, dtype=torch.float64, requires_grad=True)
    e = ws.energy.torch(x, K)
    assert e.shape == (0,)
    e.sum().backward()
    assert x.grad.shape == (0, 3)


def test_errors_cpu():
    torch = _torch()
    x32 = torch.zeros(4, 3)
    raises(TypeError, lambda: ws.energy.torch(x32, K), "energy", "'x' (0)", "float32", "float64")
    raises(ValueError, lambda: ws.energy.torch(torch.zeros(4, 2, dtype=torch.float64), K), "energy", "'x' (0)", "[4, 2]")
    raises(TypeError, lambda: ws.energy.torch([[0.0, 0.0, 0.0]], K), "energy", "'x' (0)", "list", "torch.Tensor")
    raises(TypeError, lambda: ws.energy.torch(torch.zeros(4, 3, dtype=torch.float64)), "energy missing 1 required argument: 'k'")
    # An expanded (overlapping) input: DLPack import refuses it, naming op and parameter.
    xe = torch.zeros(1, 3, dtype=torch.float64).expand(4, 3)
    raises(ValueError, lambda: ws.energy.torch(xe, K), "energy", "'x'")


def test_gradcheck_cuda():
    torch = _torch()
    _gradcheck(torch, _cuda(torch))


def test_closed_form_cuda():
    torch = _torch()
    _closed_form(torch, _cuda(torch))


def test_trace_addresses_cuda():
    torch = _torch()
    _trace(torch, _cuda(torch))


def test_training_cuda():
    torch = _torch()
    _training(torch, _cuda(torch))


def test_stream_cuda():
    # The op must run on torch's current stream: on a side stream, after a sleep and a fill
    # queued there, it reads the filled values only if it is ordered after them (on any other
    # stream it would read zeros), and it must return while the sleep still runs (no
    # synchronisation of the stream or the device).
    torch = _torch()
    dev = _cuda(torch)
    n = 4096
    # Warm-up outside the measured call: the kernel's compile and load and this thread's
    # first launch (which may synchronise) happen here.
    ws.energy.torch(torch.zeros(n, 3, dtype=torch.float64, device=dev), K)
    torch.cuda.synchronize(dev)
    side = torch.cuda.Stream(device=dev)
    with torch.cuda.stream(side):
        x = torch.zeros(n, 3, dtype=torch.float64, device=dev)
        torch.cuda._sleep(SLEEP_CYCLES)
        x.fill_(1.0)
        e = ws.energy.torch(x, K)
        still_running = not side.query()
        # The backward runs on the forward's stream too (autograd's rule); a gradient of ones.
        xg = x.clone().requires_grad_()
        ws.energy.torch(xg, K).sum().backward()
    side.synchronize()
    # In debug mode (a debug build's default) every launch waits for its kernel, on the
    # caller's stream alone: the ordering is still checked below.
    assert still_running or ws._warp_lang._DEBUG, "the op's call waited for the stream's earlier work"
    want = 0.5 * K * 3 + math.sin(1.0) + 1.0 / 3.0
    torch.testing.assert_close(e.cpu(), torch.full((n,), want, dtype=torch.float64), rtol=1e-12, atol=1e-12)
    g_row = torch.tensor([K + math.cos(1.0), K + math.sin(1.0), K + 1.0], dtype=torch.float64)
    torch.testing.assert_close(xg.grad.cpu(), g_row.expand(n, 3), rtol=1e-12, atol=1e-12)


def test_devices_cuda():
    torch = _torch()
    dev = _cuda(torch)
    x = torch.zeros(8, dtype=torch.float32)
    y = torch.zeros(8, dtype=torch.float32, device=dev)
    raises(ValueError, lambda: ws.axpy.torch(1.0, x, y), "axpy", "'x' is on cpu", "'y' on cuda:0")


def _torch_op(torch, dev):
    """`op.torch_op`: a torch.library custom op, checked by torch's own opcheck (schema, fake
    tensor, autograd registration) and run under torch.compile(fullgraph=True): the same
    values and gradients as the autograd.Function path."""
    gen = torch.Generator().manual_seed(5)
    x = torch.randn(50, 3, dtype=torch.float64, generator=gen).to(dev)
    g = torch.randn(50, dtype=torch.float64, generator=gen).to(dev)
    xa = x.clone().requires_grad_()
    ws.energy.torch(xa, K).backward(g)
    xb = x.clone().requires_grad_()
    e = ws.energy.torch_op(xb, K)
    e.backward(g)
    # The same kernels on the same inputs: bit for bit.
    torch.testing.assert_close(e.detach(), ws.energy.torch(x, K), rtol=0, atol=0)
    torch.testing.assert_close(xb.grad, xa.grad, rtol=0, atol=0)
    ns = [n for n in dir(torch.ops) if n.startswith("warp_lang_")]
    assert ns, dir(torch.ops)
    overload = getattr(getattr(torch.ops, ns[0]), "energy").default
    torch.library.opcheck(overload, (x.clone().requires_grad_(), K))

    # warp_sim was imported before torch here, so each op registers with torch.library at its
    # first torch_op call, which must be outside the compiled function.
    ws.axpy.torch_op(1.0, x[:, 0].float(), x[:, 1].float())

    @torch.compile(fullgraph=True)
    def loss(x, y):
        return (ws.energy.torch_op(x, K) * g).sum() + ws.axpy.torch_op(2.0, y, y).sum()

    xc = x.clone().requires_grad_()
    y = torch.randn(100, dtype=torch.float32, generator=gen).to(dev).requires_grad_()
    val = loss(xc, y)
    val.backward()
    torch.testing.assert_close(xc.grad, xa.grad, rtol=0, atol=0)
    # axpy(2, y, y) = 3y: d/dy = 3 exactly in f32.
    torch.testing.assert_close(y.grad, torch.full_like(y, 3.0), rtol=0, atol=0)


def _affine(torch, dev):
    # A matrix and a vector value: through the autograd.Function (nested lists, a NumPy
    # array) and through torch_op (float[] in its schema), with torch.library.opcheck; the
    # gradient is m^T ct per row.
    import numpy as np

    gen = torch.Generator().manual_seed(9)
    x = torch.randn(40, 3, dtype=torch.float64, generator=gen).to(dev)
    m = torch.randn(3, 3, dtype=torch.float64, generator=gen)
    b = [0.5, -1.0, 2.0]
    ct = torch.randn(40, 3, dtype=torch.float64, generator=gen).to(dev)
    want = x @ m.to(dev).T + torch.tensor(b, dtype=torch.float64, device=dev)
    xa = x.clone().requires_grad_()
    y = ws.affine.torch(m.tolist(), b, xa)
    torch.testing.assert_close(y, want, rtol=1e-13, atol=1e-13)
    y.backward(ct)
    torch.testing.assert_close(xa.grad, ct @ m.to(dev), rtol=1e-13, atol=1e-13)
    xb = x.clone().requires_grad_()
    yb = ws.affine.torch_op(np.asarray(m), b, xb)
    yb.backward(ct)
    torch.testing.assert_close(yb.detach(), y.detach(), rtol=0, atol=0)
    torch.testing.assert_close(xb.grad, xa.grad, rtol=0, atol=0)
    ns = [n for n in dir(torch.ops) if n.startswith("warp_lang_")]
    overload = getattr(getattr(torch.ops, ns[0]), "affine").default
    torch.library.opcheck(overload, (m.ravel().tolist(), b, x.clone().requires_grad_()))


def test_affine_values_cpu():
    torch = _torch()
    _affine(torch, torch.device("cpu"))


def test_affine_values_cuda():
    torch = _torch()
    _affine(torch, _cuda(torch))


def test_torch_op_cpu():
    torch = _torch()
    _torch_op(torch, torch.device("cpu"))


def test_torch_op_cuda():
    torch = _torch()
    _torch_op(torch, _cuda(torch))
