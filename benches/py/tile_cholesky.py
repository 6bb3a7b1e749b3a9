"""The other sides of benches/gpu.rs's tile Cholesky section, on the same GPU in the same run, on
the same systems (the Rust side writes them): cuSOLVER's batched Cholesky factor and solve
through PyTorch (`torch.linalg.cholesky` then `torch.cholesky_solve`, batched potrf + potrs),
and NVIDIA Warp's tiles (`wp.tile_cholesky` then `wp.tile_cholesky_solve`, one system per block,
launched with wp.launch_tiled with the same block size as ours).

    python3 benches/py/tile_cholesky.py DIR BATCH N BLOCK_DIM

DIR holds a.f32 (BATCH x N x N, each system's matrix row-major), y.f32 (BATCH x N), and
idx.i64 (the systems checked against float64), little-endian. For each side: the median time of
timed repetitions after a warm-up (host clock around the call, the device synchronised, as the
Rust side times: factor and solve together), and on the checked systems the forward error
max |x - x64|_inf / |x64|_inf and the backward error max |A x - y|_inf / (|A|_inf |x|_inf +
|y|_inf), x64 the float64 solution of the same inputs. Warp's side also reports its first
launch with an empty kernel cache (its compile). A side that cannot run says why. One JSON
object on the last line.

Run on the GPU machine with Warp unpacked by ../shared/tools/warp-bundle:
    PYTHONPATH=/root/warp-lang python3 benches/py/tile_cholesky.py ...
"""

import atexit
import json
import os
import shutil
import statistics
import sys
import tempfile
import time

import numpy as np

REPS = 15  # as the Rust side (benches/common: REPS)

d = sys.argv[1]
BATCH, N, BLOCK_DIM = (int(x) for x in sys.argv[2:5])
A = np.fromfile(os.path.join(d, "a.f32"), dtype="<f4").reshape(BATCH, N, N)
Y = np.fromfile(os.path.join(d, "y.f32"), dtype="<f4").reshape(BATCH, N)
IDX = np.fromfile(os.path.join(d, "idx.i64"), dtype="<i8")

A64 = A[IDX].astype(np.float64)
Y64 = Y[IDX].astype(np.float64)
X64 = np.linalg.solve(A64, Y64[..., None])[..., 0]


def errors(x):
    """Forward and backward errors of the solutions `x` (BATCH x N) on the checked systems."""
    xs = x[IDX].astype(np.float64)
    fwd = np.max(np.abs(xs - X64), axis=1) / np.max(np.abs(X64), axis=1)
    res = np.max(np.abs(np.einsum("sij,sj->si", A64, xs) - Y64), axis=1)
    an = np.max(np.sum(np.abs(A64), axis=2), axis=1)
    bwd = res / (an * np.max(np.abs(xs), axis=1) + np.max(np.abs(Y64), axis=1))
    # A NaN (a failed factor) must show, not vanish in max.
    f = float(np.nan if np.isnan(fwd).any() else np.max(fwd))
    b = float(np.nan if np.isnan(bwd).any() else np.max(bwd))
    return f, b


def median_ms(fn, sync):
    fn()
    sync()
    times = []
    for _ in range(REPS):
        sync()
        t = time.perf_counter()
        fn()
        sync()
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times)


out = {"batch": BATCH, "n": N}

try:
    import torch

    dev = torch.device("cuda:0")
    ta = torch.from_numpy(A).to(dev)
    ty = torch.from_numpy(Y).to(dev).unsqueeze(-1)
    res = {}

    def torch_solve():
        L = torch.linalg.cholesky(ta)
        res["x"] = torch.cholesky_solve(ty, L)

    out["torch_ms"] = median_ms(torch_solve, torch.cuda.synchronize)
    out["torch_err"], out["torch_berr"] = errors(res["x"].squeeze(-1).cpu().numpy())
    out["torch"] = torch.__version__
    del ta, ty, res
    torch.cuda.empty_cache()
except Exception as e:  # noqa: BLE001 (any failure of this side is reported, not fatal)
    out["torch_error"] = f"{type(e).__name__}: {e}"

try:
    import warp as wp

    wp.config.quiet = True
    # An empty kernel cache: the first launch below compiles, and is timed as the cold compile.
    wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="warp-tile-chol-")
    atexit.register(shutil.rmtree, wp.config.kernel_cache_dir, ignore_errors=True)
    wp.init()
    wp.set_module_options({"enable_backward": False})

    TILE = wp.constant(N)

    @wp.kernel
    def chol_solve(A: wp.array2d(dtype=wp.float32), Y: wp.array1d(dtype=wp.float32), X: wp.array1d(dtype=wp.float32)):
        i = wp.tid()
        a = wp.tile_load(A, shape=(TILE, TILE), offset=(i * TILE, 0))
        y = wp.tile_load(Y, shape=TILE, offset=i * TILE)
        l = wp.tile_cholesky(a)
        x = wp.tile_cholesky_solve(l, y)
        wp.tile_store(X, x, offset=i * TILE)

    with wp.ScopedDevice("cuda:0"):
        wa = wp.array(A.reshape(BATCH * N, N), dtype=wp.float32)
        wy = wp.array(Y.reshape(BATCH * N), dtype=wp.float32)
        wx = wp.zeros(BATCH * N, dtype=wp.float32)

        def launch():
            wp.launch_tiled(chol_solve, dim=[BATCH], inputs=[wa, wy, wx], block_dim=BLOCK_DIM)

        t = time.perf_counter()
        launch()
        wp.synchronize()
        out["warp_first_ms"] = (time.perf_counter() - t) * 1e3
        out["warp_ms"] = median_ms(launch, wp.synchronize)
        out["warp_err"], out["warp_berr"] = errors(wx.numpy().reshape(BATCH, N))
        out["warp"] = wp.__version__
except Exception as e:  # noqa: BLE001
    out["warp_error"] = f"{type(e).__name__}: {e}"

print(json.dumps(out))
