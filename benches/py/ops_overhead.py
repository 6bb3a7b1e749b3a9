"""What one op call costs: warp-lang's `axpy` op (`out = a x + y`, f32) called from PyTorch and
JAX, against the framework's own expression and NVIDIA Warp's documented paths, in one process
on one machine.

    PYTHONPATH=<dir with warp_sim.abi3.so>:<Warp> python3 benches/py/ops_overhead.py [--json F]

Rows (each prints SKIPPED with the reason when its framework, Warp or a GPU is missing):

- host time per call: 10,000 calls in a Python loop, then one synchronisation; the median of
  5 repeats, at 1 Ki elements (overhead-bound), on `cuda:0` and on the CPU;
- forward + backward per step (`loss = out.sum()`, gradients of x and y), 1 Ki, `cuda:0`;
- GPU time per call at 16 Mi elements (bandwidth-bound): CUDA events around 200 calls for
  torch-side rows, the host clock around 200 calls and one `block_until_ready` for JAX rows.
  Equal times across a framework's rows are the evidence that no path copies.

Every row's result is checked against the framework's own `a * x + y` (f32: a fused
multiply-add and a separate multiply and add differ by at most one rounding of the product,
about 6e-8 of the largest value); the largest error, relative to the largest value, is
printed beside the time.
"""

import argparse
import json
import os
import statistics
import sys
import time

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

A = 2.5
CALLS = 10_000
REPEATS = 5
SMALL = 1 << 10
LARGE = 1 << 24
EVENT_CALLS = 200

ROWS = []


def row(group, name, value, unit, err=None, note=""):
    ROWS.append(dict(group=group, name=name, value=value, unit=unit, err=err, note=note))
    e = "" if err is None else "max rel err %.1e" % err
    v = "SKIPPED" if value is None else "%10.2f %s" % (value, unit)
    print("%-34s %-42s %-18s %s %s" % (group, name, v, e, note), flush=True)


def skipped(group, name, why):
    row(group, name, None, "", note="(%s)" % why)


def rel_err(got, want):
    import numpy as np

    got, want = np.asarray(got, dtype=np.float64), np.asarray(want, dtype=np.float64)
    # Relative to the largest value: elementwise, a cancelling a*x + y near 0 would make the
    # one rounding that separates a fused multiply-add from a multiply and an add look large.
    return float(np.max(np.abs(got - want)) / max(np.max(np.abs(want)), 1e-30)) if want.size else 0.0


def per_call_us(call, sync):
    """Median over REPEATS of (CALLS calls, then one sync) / CALLS, in microseconds."""
    call()
    sync()
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        for _ in range(CALLS):
            call()
        sync()
        times.append((time.perf_counter() - t0) / CALLS * 1e6)
    return statistics.median(times)


# ------------------------------------------------------------------------------------------
# PyTorch


def torch_rows(ws, wp):
    try:
        import torch
    except ImportError:
        skipped("torch", "all rows", "PyTorch not installed")
        return
    devices = [("cpu", torch.device("cpu"))]
    if torch.cuda.is_available():
        devices.insert(0, ("cuda:0", torch.device("cuda:0")))
    else:
        skipped("torch cuda:0", "all rows", "no CUDA device")
    gen = torch.Generator().manual_seed(12)
    for label, dev in devices:
        sync = (lambda: torch.cuda.synchronize(dev)) if dev.type == "cuda" else (lambda: None)
        x = torch.randn(SMALL, generator=gen).to(dev)
        y = torch.randn(SMALL, generator=gen).to(dev)
        want = A * x + y
        group = "torch %s, per call (1 Ki)" % label
        row(group, "torch eager a*x+y", per_call_us(lambda: A * x + y, sync), "us")
        out = ws.axpy.torch(A, x, y)
        row(group, "warp-lang op.torch", per_call_us(lambda: ws.axpy.torch(A, x, y), sync), "us", rel_err(out.cpu(), want.cpu()))
        if wp is None:
            skipped(group, "Warp from_torch + launch", "Warp not importable")
        else:
            warp_torch_call(wp, torch, dev, x, y, want, group, sync)
        if dev.type != "cuda":
            continue
        # forward + backward
        group = "torch %s, forward+backward (1 Ki)" % label
        xg, yg = x.clone().requires_grad_(), y.clone().requires_grad_()

        def step_eager():
            (A * xg + yg).sum().backward()

        def step_ours():
            ws.axpy.torch(A, xg, yg).sum().backward()

        row(group, "torch eager", per_call_us(step_eager, sync), "us")
        xg.grad = yg.grad = None
        ws.axpy.torch(A, xg, yg).sum().backward()
        e = max(rel_err(xg.grad.cpu(), torch.full((SMALL,), A)), rel_err(yg.grad.cpu(), torch.ones(SMALL)))
        row(group, "warp-lang op.torch", per_call_us(step_ours, sync), "us", e)
        if wp is not None:
            warp_torch_backward(wp, torch, dev, x, y, group, sync)
        # GPU time at 16 Mi
        group = "torch %s, GPU time per call (16 Mi)" % label
        xl = torch.randn(LARGE, device=dev)
        yl = torch.randn(LARGE, device=dev)
        row(group, "torch eager a*x+y", gpu_us(torch, lambda: A * xl + yl, sync), "us")
        row(group, "warp-lang op.torch", gpu_us(torch, lambda: ws.axpy.torch(A, xl, yl), sync), "us")
        if wp is not None:
            try:
                call = warp_torch_launcher(wp, torch, dev, xl, yl)
                row(group, "Warp from_torch + launch", gpu_us(torch, call, sync), "us")
            except Exception as exc:  # noqa: BLE001 - a row, not the run
                skipped(group, "Warp from_torch + launch", "%s: %s" % (type(exc).__name__, exc))


def gpu_us(torch, call, sync):
    call()
    sync()
    start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
    times = []
    for _ in range(REPEATS):
        start.record()
        for _ in range(EVENT_CALLS):
            call()
        end.record()
        sync()
        times.append(start.elapsed_time(end) / EVENT_CALLS * 1e3)
    return statistics.median(times)


_WARP_KERNEL = None


def warp_kernel(wp):
    global _WARP_KERNEL
    if _WARP_KERNEL is None:

        @wp.kernel
        def axpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float), out: wp.array(dtype=float)):
            i = wp.tid()
            out[i] = a * x[i] + y[i]

        _WARP_KERNEL = axpy
    return _WARP_KERNEL


def warp_torch_launcher(wp, torch, dev, x, y):
    """Warp's documented pattern: from_torch for each tensor, launch on torch's stream."""
    k = warp_kernel(wp)
    wdev = "cuda:0" if dev.type == "cuda" else "cpu"

    def call():
        out = torch.empty_like(x)
        stream = wp.stream_from_torch(dev) if dev.type == "cuda" else None
        wp.launch(
            k,
            dim=x.shape[0],
            inputs=[A, wp.from_torch(x), wp.from_torch(y), wp.from_torch(out)],
            device=wdev,
            stream=stream,
        )
        return out

    return call


def warp_torch_call(wp, torch, dev, x, y, want, group, sync):
    try:
        call = warp_torch_launcher(wp, torch, dev, x, y)
        out = call()
        sync()
        row(group, "Warp from_torch + launch", per_call_us(call, sync), "us", rel_err(out.cpu(), want.cpu()))
    except Exception as exc:  # noqa: BLE001
        skipped(group, "Warp from_torch + launch", "%s: %s" % (type(exc).__name__, exc))


def warp_torch_backward(wp, torch, dev, x, y, group, sync):
    """Warp's Tape inside a torch.autograd.Function (its documented PyTorch pattern)."""
    try:
        k = warp_kernel(wp)

        class Axpy(torch.autograd.Function):
            @staticmethod
            def forward(ctx, xt, yt):
                # Fresh gradient memory per call (the leaves' own .grad accumulates).
                ctx.gx, ctx.gy = torch.zeros_like(xt), torch.zeros_like(yt)
                ctx.x = wp.from_torch(xt, grad=ctx.gx)
                ctx.y = wp.from_torch(yt, grad=ctx.gy)
                out = torch.empty_like(xt)
                ctx.out = wp.from_torch(out, grad=torch.zeros_like(out))
                ctx.tape = wp.Tape()
                with ctx.tape:
                    wp.launch(k, dim=xt.shape[0], inputs=[A, ctx.x, ctx.y], outputs=[ctx.out], stream=wp.stream_from_torch(dev))
                return out

            @staticmethod
            def backward(ctx, g):
                ctx.out.grad = wp.from_torch(g.contiguous())
                ctx.tape.backward()
                return ctx.gx, ctx.gy

        xg, yg = x.clone().requires_grad_(), y.clone().requires_grad_()

        def step():
            Axpy.apply(xg, yg).sum().backward()

        step()
        sync()
        e = max(rel_err(xg.grad.cpu(), torch.full((SMALL,), A)), rel_err(yg.grad.cpu(), torch.ones(SMALL)))
        row(group, "Warp Tape in autograd.Function", per_call_us(step, sync), "us", e)
    except Exception as exc:  # noqa: BLE001
        skipped(group, "Warp Tape in autograd.Function", "%s: %s" % (type(exc).__name__, exc))


# ------------------------------------------------------------------------------------------
# JAX


def _warp_jax_kernel(wp):
    """Warp's jax_kernel: `warp.jax_kernel` in 1.19, `warp.jax_experimental` before."""
    if hasattr(wp, "jax_kernel"):
        return wp.jax_kernel
    from warp.jax_experimental import jax_kernel

    return jax_kernel


def jax_rows(ws, wp):
    try:
        import jax
    except ImportError:
        skipped("jax", "all rows", "JAX not installed")
        return
    import numpy as np

    platforms = []
    try:
        if jax.devices("gpu"):
            platforms.append(("cuda:0", jax.devices("gpu")[0]))
    except RuntimeError:
        skipped("jax cuda:0", "all rows", "no GPU backend in this jaxlib")
    platforms.append(("cpu", jax.devices("cpu")[0]))
    rng = np.random.default_rng(12)
    for label, dev in platforms:
        x = jax.device_put(rng.normal(size=SMALL).astype(np.float32), dev)
        y = jax.device_put(rng.normal(size=SMALL).astype(np.float32), dev)
        want = np.float32(A) * np.asarray(x) + np.asarray(y)
        group = "jax %s, per call (1 Ki)" % label
        plain = jax.jit(lambda x, y: A * x + y)
        ours = jax.jit(lambda x, y: ws.axpy.jax(A, x, y))
        last = {}

        def runner(f):
            def call():
                last["v"] = f(x, y)

            return call

        def sync():
            last["v"].block_until_ready()

        row(group, "jax.jit a*x+y", per_call_us(runner(plain), sync), "us", rel_err(plain(x, y), want))
        row(group, "warp-lang op.jax under jit", per_call_us(runner(ours), sync), "us", rel_err(ours(x, y), want))
        warp_jax = None
        if wp is None:
            skipped(group, "Warp jax_kernel", "Warp not importable")
        elif label != "cuda:0":
            skipped(group, "Warp jax_kernel", "Warp's jax_kernel runs on GPUs only")
        else:
            try:
                jax_kernel = _warp_jax_kernel(wp)
                jk = jax_kernel(warp_kernel(wp), num_outputs=1)
                warp_jax = jax.jit(lambda x, y: jk(A, x, y)[0])
                row(group, "Warp jax_kernel under jit", per_call_us(runner(warp_jax), sync), "us", rel_err(warp_jax(x, y), want))
            except Exception as exc:  # noqa: BLE001
                warp_jax = None
                skipped(group, "Warp jax_kernel under jit", "%s: %s" % (type(exc).__name__, exc))
        # In-graph: a 100-step lax.scan of each, per step.
        group = "jax %s, inside a 100-step scan (1 Ki)" % label

        def scanned(f):
            def body(c, _):
                return f(x, c) * np.float32(0.5), None

            return jax.jit(lambda y: jax.lax.scan(body, y, None, length=100)[0])

        for name, f in [("jax.jit a*x+y", lambda x, y: A * x + y), ("warp-lang op.jax", lambda x, y: ws.axpy.jax(A, x, y))] + (
            [("Warp jax_kernel", lambda x, y: jk(A, x, y)[0])] if warp_jax is not None else []
        ):
            g = scanned(f)
            g(y).block_until_ready()
            times = []
            for _ in range(REPEATS):
                t0 = time.perf_counter()
                for _ in range(100):
                    v = g(y)
                v.block_until_ready()
                times.append((time.perf_counter() - t0) / 100 / 100 * 1e6)
            row(group, name, statistics.median(times), "us/step")
        # forward + backward
        group = "jax %s, forward+backward (1 Ki)" % label
        for name, f in [("jax.jit", lambda x, y: A * x + y), ("warp-lang op.jax", lambda x, y: ws.axpy.jax(A, x, y))]:
            g = jax.jit(jax.grad(lambda x, y: f(x, y).sum(), argnums=(0, 1)))
            gx, gy = g(x, y)
            e = max(rel_err(gx, np.full(SMALL, A)), rel_err(gy, np.ones(SMALL)))

            def call(g=g):
                last["v"] = g(x, y)[0]

            row(group, name, per_call_us(call, sync), "us", e)
        if warp_jax is not None:
            try:
                jkb = _warp_jax_kernel(wp)(warp_kernel(wp), num_outputs=1, enable_backward=True)
                g = jax.jit(jax.grad(lambda x, y: jkb(A, x, y)[0].sum(), argnums=(0, 1)))
                gx, gy = g(x, y)
                e = max(rel_err(gx, np.full(SMALL, A)), rel_err(gy, np.ones(SMALL)))

                def callw(g=g):
                    last["v"] = g(x, y)[0]

                row(group, "Warp jax_kernel(enable_backward)", per_call_us(callw, sync), "us", e)
            except Exception as exc:  # noqa: BLE001
                skipped(group, "Warp jax_kernel(enable_backward)", "%s: %s" % (type(exc).__name__, exc))
        if label != "cuda:0":
            continue
        group = "jax %s, GPU time per call (16 Mi)" % label
        xl = jax.device_put(rng.normal(size=LARGE).astype(np.float32), dev)
        yl = jax.device_put(rng.normal(size=LARGE).astype(np.float32), dev)
        for name, f in [("jax.jit a*x+y", plain), ("warp-lang op.jax", ours)] + ([("Warp jax_kernel", warp_jax)] if warp_jax else []):
            f(xl, yl).block_until_ready()
            times = []
            for _ in range(REPEATS):
                t0 = time.perf_counter()
                for _ in range(EVENT_CALLS):
                    v = f(xl, yl)
                v.block_until_ready()
                times.append((time.perf_counter() - t0) / EVENT_CALLS * 1e6)
            row(group, name, statistics.median(times), "us")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", help="write the rows here as JSON")
    args = parser.parse_args()
    import warp_sim as ws

    try:
        import warp as wp

        wp.config.quiet = True
        wp.init()
    except Exception as exc:  # noqa: BLE001
        print("Warp: not importable (%s); its rows are SKIPPED" % exc)
        wp = None
    versions = {"python": sys.version.split()[0]}
    for mod in ("torch", "jax", "warp"):
        try:
            versions[mod] = __import__(mod).__version__
        except Exception:  # noqa: BLE001
            versions[mod] = None
    print("versions:", versions)
    torch_rows(ws, wp)
    jax_rows(ws, wp)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(dict(versions=versions, rows=ROWS), f, indent=1)


if __name__ == "__main__":
    main()
