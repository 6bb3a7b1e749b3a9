"""The other sides of benches/gpu.rs's tile GEMM section, on the same GPU in the same device
call, on the same inputs (the Rust side writes them): cuBLAS SGEMM through PyTorch
(`torch.matmul`, TF32 off: a true fp32 product) and NVIDIA Warp's tile GEMM (the kernel of
Warp's example_tile_matmul.py: tile_zeros, a k-loop of tile_load / tile_matmul, tile_store,
launched with wp.launch_tiled), with the same tile sizes and block size as ours.

    python3 benches/py/tile_gemm.py DIR M N K TILE_M TILE_N TILE_K BLOCK_DIM [TM16 TN16 TK16]

With the fp16 tile sizes, also the fp16 sides: A and B rounded to float16 (to nearest even, as
the Rust side rounds them), cuBLAS through `torch.matmul` on half tensors (f32 accumulation:
reduced-precision reductions off) and Warp's tile GEMM of float16 tiles into a float32
accumulator, errors against the float64 product of the float16 values (keys `torch16_*`,
`warp16_*`).

DIR holds a.f32 (M x K) and b.f32 (K x N), row-major little-endian float32, and idx.i64
(the sampled entries: S row indices, then S column indices). For each side: the median time of
timed repetitions after a warm-up (host clock around the call, the device synchronised, as the
Rust side times), and the error on the sampled entries, max |c - c64| / sum_p |a_ip b_pj|, c64
the float64 product of the same inputs. Warp's side also reports its cold compile (an empty
kernel cache). A side that cannot run (no torch, no Warp) reports why. One JSON object on the
last line.

Run on the GPU machine with Warp unpacked by ../shared/tools/warp-bundle:
    PYTHONPATH=/root/warp-lang python3 benches/py/tile_gemm.py ...
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
M, N, K, TM, TN, TK, BLOCK_DIM = (int(x) for x in sys.argv[2:9])
FP16 = len(sys.argv) >= 12
if FP16:
    TM16, TN16, TK16 = (int(x) for x in sys.argv[9:12])
A = np.fromfile(os.path.join(d, "a.f32"), dtype="<f4").reshape(M, K)
B = np.fromfile(os.path.join(d, "b.f32"), dtype="<f4").reshape(K, N)
idx = np.fromfile(os.path.join(d, "idx.i64"), dtype="<i8")
II, JJ = idx[: idx.size // 2], idx[idx.size // 2 :]

# The float64 reference on the sampled entries, and the magnitudes sum |a||b| the errors are
# relative to (in chunks: S x K doubles at a time would be large for big samples).
REF = np.empty(II.size)
MAG = np.empty(II.size)
for s in range(0, II.size, 512):
    a = A[II[s : s + 512]].astype(np.float64)
    b = B[:, JJ[s : s + 512]].astype(np.float64).T
    REF[s : s + 512] = np.einsum("sk,sk->s", a, b)
    MAG[s : s + 512] = np.einsum("sk,sk->s", np.abs(a), np.abs(b))


def reference(A, B):
    """The float64 products and magnitudes sum |a||b| of the sampled entries."""
    ref = np.empty(II.size)
    mag = np.empty(II.size)
    for s in range(0, II.size, 512):
        a = A[II[s : s + 512]].astype(np.float64)
        b = B[:, JJ[s : s + 512]].astype(np.float64).T
        ref[s : s + 512] = np.einsum("sk,sk->s", a, b)
        mag[s : s + 512] = np.einsum("sk,sk->s", np.abs(a), np.abs(b))
    return ref, mag


def error(c, ref=None, mag=None):
    ref = REF if ref is None else ref
    mag = MAG if mag is None else mag
    err = np.abs(c[II, JJ].astype(np.float64) - ref)
    return float(np.max(np.where(mag > 0, err / np.where(mag > 0, mag, 1), err)))


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


out = {"m": M, "n": N, "k": K}

try:
    import torch

    torch.backends.cuda.matmul.allow_tf32 = False
    torch.backends.cudnn.allow_tf32 = False
    dev = torch.device("cuda:0")
    ta = torch.from_numpy(A).to(dev)
    tb = torch.from_numpy(B).to(dev)
    tc = torch.empty((M, N), dtype=torch.float32, device=dev)
    out["torch_ms"] = median_ms(lambda: torch.matmul(ta, tb, out=tc), torch.cuda.synchronize)
    out["torch_err"] = error(tc.cpu().numpy())
    out["torch"] = torch.__version__
    out["torch_tf32"] = bool(torch.backends.cuda.matmul.allow_tf32)
    del ta, tb, tc
    torch.cuda.empty_cache()
except Exception as e:  # noqa: BLE001 (any failure of this side is reported, not fatal)
    out["torch_error"] = f"{type(e).__name__}: {e}"

try:
    import warp as wp

    wp.config.quiet = True
    # An empty kernel cache: the first launch below compiles, and is timed as the cold compile.
    wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="warp-tile-gemm-")
    atexit.register(shutil.rmtree, wp.config.kernel_cache_dir, ignore_errors=True)
    wp.init()
    wp.set_module_options({"enable_backward": False})

    TILE_M, TILE_N, TILE_K = wp.constant(TM), wp.constant(TN), wp.constant(TK)

    @wp.kernel
    def tile_gemm(A: wp.array2d(dtype=wp.float32), B: wp.array2d(dtype=wp.float32), C: wp.array2d(dtype=wp.float32)):
        i, j = wp.tid()
        acc = wp.tile_zeros(shape=(TILE_M, TILE_N), dtype=wp.float32)
        count = (A.shape[1] + TILE_K - 1) // TILE_K
        for k in range(0, count):
            a = wp.tile_load(A, shape=(TILE_M, TILE_K), offset=(i * TILE_M, k * TILE_K))
            b = wp.tile_load(B, shape=(TILE_K, TILE_N), offset=(k * TILE_K, j * TILE_N))
            wp.tile_matmul(a, b, acc)
        wp.tile_store(C, acc, offset=(i * TILE_M, j * TILE_N))

    with wp.ScopedDevice("cuda:0"):
        wa = wp.array(A, dtype=wp.float32)
        wb = wp.array(B, dtype=wp.float32)
        wc = wp.zeros((M, N), dtype=wp.float32)
        grid = ((M + TM - 1) // TM, (N + TN - 1) // TN)

        def launch():
            wp.launch_tiled(tile_gemm, dim=grid, inputs=[wa, wb, wc], block_dim=BLOCK_DIM)

        t = time.perf_counter()
        launch()
        wp.synchronize()
        out["warp_first_ms"] = (time.perf_counter() - t) * 1e3
        out["warp_ms"] = median_ms(launch, wp.synchronize)
        out["warp_err"] = error(wc.numpy())
        out["warp"] = wp.__version__
except Exception as e:  # noqa: BLE001
    out["warp_error"] = f"{type(e).__name__}: {e}"

if FP16:
    A16, B16 = A.astype(np.float16), B.astype(np.float16)
    REF16, MAG16 = reference(A16, B16)

    try:
        import torch

        # f32 accumulation in cuBLAS's half GEMM (the default allows reduced-precision sums).
        torch.backends.cuda.matmul.allow_fp16_reduced_precision_reduction = False
        dev = torch.device("cuda:0")
        ta = torch.from_numpy(A16).to(dev)
        tb = torch.from_numpy(B16).to(dev)
        tc = torch.empty((M, N), dtype=torch.float16, device=dev)
        out["torch16_ms"] = median_ms(lambda: torch.matmul(ta, tb, out=tc), torch.cuda.synchronize)
        out["torch16_err"] = error(tc.float().cpu().numpy(), REF16, MAG16)
        del ta, tb, tc
        torch.cuda.empty_cache()
    except Exception as e:  # noqa: BLE001
        out["torch16_error"] = f"{type(e).__name__}: {e}"

    try:
        import warp as wp

        T16M, T16N, T16K = wp.constant(TM16), wp.constant(TN16), wp.constant(TK16)

        @wp.kernel
        def tile_gemm16(A: wp.array2d(dtype=wp.float16), B: wp.array2d(dtype=wp.float16), C: wp.array2d(dtype=wp.float32)):
            i, j = wp.tid()
            acc = wp.tile_zeros(shape=(T16M, T16N), dtype=wp.float32)
            count = (A.shape[1] + T16K - 1) // T16K
            for k in range(0, count):
                a = wp.tile_load(A, shape=(T16M, T16K), offset=(i * T16M, k * T16K))
                b = wp.tile_load(B, shape=(T16K, T16N), offset=(k * T16K, j * T16N))
                wp.tile_matmul(a, b, acc)
            wp.tile_store(C, acc, offset=(i * T16M, j * T16N))

        with wp.ScopedDevice("cuda:0"):
            wa = wp.array(A16, dtype=wp.float16)
            wb = wp.array(B16, dtype=wp.float16)
            wc = wp.zeros((M, N), dtype=wp.float32)
            grid = ((M + TM16 - 1) // TM16, (N + TN16 - 1) // TN16)

            def launch16():
                wp.launch_tiled(tile_gemm16, dim=grid, inputs=[wa, wb, wc], block_dim=BLOCK_DIM)

            t = time.perf_counter()
            launch16()
            wp.synchronize()
            out["warp16_first_ms"] = (time.perf_counter() - t) * 1e3
            out["warp16_ms"] = median_ms(launch16, wp.synchronize)
            out["warp16_err"] = error(wc.numpy(), REF16, MAG16)
    except Exception as e:  # noqa: BLE001
        out["warp16_error"] = f"{type(e).__name__}: {e}"

print(json.dumps(out))
