"""The other sides of benches/gpu.rs's tile FFT section, on the same GPU in the same run, on the
same signals (the Rust side writes them): cuFFT through CuPy (`cupy.fft.fft` along the last
axis of a ROWS x N complex64 array: one batched C2C plan, cached after the warm-up), and NVIDIA
Warp's tiles (`wp.tile_fft`, M signals a block, launched with wp.launch_tiled with the same
block size as ours: Warp's example_tile_fft at scale).

    python3 benches/py/tile_fft.py DIR ROWS N M BLOCK_DIM

DIR holds x.c64 (ROWS x N complex values, float32 pairs, little-endian) and idx.i64 (the rows
checked against float64). For each side: the median time of timed repetitions after a warm-up
(host clock around the call, the device synchronised, as the Rust side times), and on the
checked rows the error max_k |y_k - Y_k| / max_k |Y_k|, Y the float64 FFT of the same inputs
(numpy's, which is within a few float64 ulps of the DFT). Warp's side also reports its first
launch with an empty kernel cache (its compile). A side that cannot run says why. One JSON
object on the last line.

Run on the GPU machine with Warp unpacked by ../shared/tools/warp-bundle:
    PYTHONPATH=/root/warp-lang python3 benches/py/tile_fft.py ...
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
ROWS, N, M, BLOCK_DIM = (int(x) for x in sys.argv[2:6])
X = np.fromfile(os.path.join(d, "x.c64"), dtype="<c8").reshape(ROWS, N)
IDX = np.fromfile(os.path.join(d, "idx.i64"), dtype="<i8")
Y64 = np.fft.fft(X[IDX].astype(np.complex128), axis=-1)


def error(y):
    """The worst relative error of the spectra `y` (ROWS x N complex) on the checked rows."""
    ys = y[IDX].astype(np.complex128)
    err = np.max(np.abs(ys - Y64), axis=1) / np.max(np.abs(Y64), axis=1)
    # A NaN must show, not vanish in max.
    return float(np.nan if np.isnan(err).any() else np.max(err))


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


out = {"rows": ROWS, "n": N}

try:
    import cupy as cp

    cx = cp.asarray(X)
    res = {}

    def cufft():
        res["y"] = cp.fft.fft(cx, axis=-1)

    out["cufft_ms"] = median_ms(cufft, cp.cuda.Device(0).synchronize)
    out["cufft_err"] = error(cp.asnumpy(res["y"]))
    out["cupy"] = cp.__version__
    del cx, res
    cp.get_default_memory_pool().free_all_blocks()
except Exception as e:  # noqa: BLE001 (any failure of this side is reported, not fatal)
    out["cufft_error"] = f"{type(e).__name__}: {e}"

try:
    import warp as wp

    wp.config.quiet = True
    # An empty kernel cache: the first launch below compiles, and is timed as the cold compile.
    wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="warp-tile-fft-")
    atexit.register(shutil.rmtree, wp.config.kernel_cache_dir, ignore_errors=True)
    wp.init()
    wp.set_module_options({"enable_backward": False})

    TILE_M = wp.constant(M)
    TILE_N = wp.constant(N)

    @wp.kernel
    def fft_rows(x: wp.array2d(dtype=wp.vec2f), y: wp.array2d(dtype=wp.vec2f)):
        i = wp.tid()
        a = wp.tile_load(x, shape=(TILE_M, TILE_N), offset=(i * TILE_M, 0))
        wp.tile_fft(a)
        wp.tile_store(y, a, offset=(i * TILE_M, 0))

    with wp.ScopedDevice("cuda:0"):
        wx = wp.array(X.view(np.float32).reshape(ROWS, N, 2), dtype=wp.vec2f)
        wy = wp.zeros((ROWS, N), dtype=wp.vec2f)

        def launch():
            wp.launch_tiled(fft_rows, dim=[ROWS // M], inputs=[wx, wy], block_dim=BLOCK_DIM)

        t = time.perf_counter()
        launch()
        wp.synchronize()
        out["warp_first_ms"] = (time.perf_counter() - t) * 1e3
        out["warp_ms"] = median_ms(launch, wp.synchronize)
        out["warp_err"] = error(wy.numpy().reshape(ROWS, N, 2).astype(np.float32).view(np.complex64).reshape(ROWS, N))
        out["warp"] = wp.__version__
except Exception as e:  # noqa: BLE001
    out["warp_error"] = f"{type(e).__name__}: {e}"

print(json.dumps(out))
