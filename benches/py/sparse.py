"""Warp's and CuPy's side of benches/sparse.rs: one matrix, written by the Rust side into a
directory, timed on the same GPU in the same run.

Files in --dir (little-endian, raw): offsets.i32 (nrow + 1 block-row starts), columns.i32
(a block column per stored block), values.f64 (the blocks, each R x R row-major), x.f64 (the
random vector of R * nrow scalars, also the right-hand side of the solves). The f32 cases
round values and x to f32, as the Rust side does.

For each dtype (--dtypes f32,f64):
- mv, y = A x: Warp 1.19's `bsr_mv` on `bsr_from_triplets` of the same blocks (no pruning:
  the same structure), and cuSPARSE's SpMV through CuPy (`csr_matrix @ x`; a 3 x 3 block
  matrix expanded to a scalar CSR of 9 entries per block). GPU milliseconds between CUDA
  events, median of --reps after a warm-up: around one call (`*_mv_ms`: the events also hold
  the host's dispatch of the call, Python's included, for which the GPU waits), and around
  50 calls queued back to back, per call (`*_mv_b2b_ms`: the device's time once the host
  queues faster than the GPU runs). The error is max |y - y_ref| / max |y_ref| with y_ref the
  f64 product on the host (numpy).
- CG (--cg 1), b = x, from x0 = 0 to rtol (|r| <= rtol |b|) with point Jacobi: Warp's
  `warp.optim.linear.cg(check_every=0)` with `preconditioner(A, "diag")`, and CuPy's
  `cupyx.scipy.sparse.linalg.cg` with M = diag(1 / a_ii) as a LinearOperator. Wall
  milliseconds of the whole call (allocation and graph capture included, as the Rust side's),
  synchronised, median of --cg-reps after a warm-up; iterations; the true residual
  |b - A x| / |b| in f64 on the host against the f64 matrix.

A side that cannot run (no warp, no cupy, an error) leaves its keys out and puts the reason
under "<side>_error". Prints one JSON object on its last line.

    PYTHONPATH=<warp> python3 benches/py/sparse.py --dir D --block 1 --nrow N [--cg 1]
"""

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

ap = argparse.ArgumentParser()
ap.add_argument("--dir", required=True)
ap.add_argument("--block", type=int, default=1)
ap.add_argument("--nrow", type=int, required=True)
ap.add_argument("--dtypes", default="f32,f64")
ap.add_argument("--reps", type=int, default=15)
ap.add_argument("--cg", type=int, default=0)
ap.add_argument("--cg-reps", type=int, default=3)
ap.add_argument("--rtol", type=float, default=1e-6)
ap.add_argument("--maxiter", type=int, default=20000)
args = ap.parse_args()

R = args.block
# Calls per timing of the back-to-back figures (the Rust side's BATCH).
BATCH = 50
NROW = args.nrow
N = NROW * R


def load(name, dtype):
    return np.fromfile(os.path.join(args.dir, name), dtype=dtype)


offsets = load("offsets.i32", np.int32)
columns = load("columns.i32", np.int32)
values = load("values.f64", np.float64)
x64 = load("x.f64", np.float64)
NNZ = len(columns)
assert len(offsets) == NROW + 1 and offsets[-1] == NNZ, "offsets"
assert len(values) == NNZ * R * R and len(x64) == N, "values or x"

# The scalar CSR (R = 3: 9 entries per block, a block's entries in its row's order): the
# host reference and CuPy's matrix.
if R == 1:
    s_off, s_col, s_val = offsets, columns, values
else:
    # Scalar row R r + i holds, for each block k of block row r in order, its row i: entry
    # (k, i, j) goes to s_off[R r + i] + R (k - offsets[r]) + j (a scatter, no sort).
    nb = np.diff(offsets).astype(np.int64)
    s_off = np.concatenate([[0], np.cumsum(np.repeat(nb * R, R))]).astype(np.int64)
    brow = np.repeat(np.arange(NROW, dtype=np.int64), nb)
    kin = np.arange(NNZ, dtype=np.int64) - offsets[:-1].astype(np.int64)[brow]
    i, j = np.meshgrid(np.arange(R), np.arange(R), indexing="ij")
    dest = (s_off[(brow * R)[:, None, None] + i[None]] + (R * kin)[:, None, None] + j[None]).reshape(-1)
    s_col = np.empty(NNZ * R * R, dtype=np.int32)
    s_val = np.empty(NNZ * R * R, dtype=np.float64)
    s_col[dest] = (columns.astype(np.int64)[:, None, None] * R + j[None]).reshape(-1)
    s_val[dest] = values
    s_off = s_off.astype(np.int32)
    del brow, kin, dest


def csr_mv(vals, x):
    """y = A x in f64 on the host (rows are never empty here)."""
    return np.add.reduceat(vals * x[s_col], s_off[:-1].astype(np.int64))


y_ref = csr_mv(s_val, x64)
y_scale = float(np.abs(y_ref).max())
b_norm = float(np.linalg.norm(x64))
diag = np.zeros(N)
rows_of = np.repeat(np.arange(N), np.diff(s_off))
on_diag = s_col == rows_of
diag[rows_of[on_diag]] = s_val[on_diag]
del rows_of, on_diag


def mv_err(y):
    return float(np.abs(np.asarray(y, dtype=np.float64).reshape(-1) - y_ref).max() / y_scale)


def true_residual(x):
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    return float(np.linalg.norm(x64 - csr_mv(s_val, x)) / b_norm)


out = {"nrow": NROW, "block": R, "nnz": NNZ}
dtypes = [d for d in args.dtypes.split(",") if d]
for d in dtypes:
    out[d] = {}
np_t = {"f32": np.float32, "f64": np.float64}

# ---- Warp ----
try:
    import warp as wp
    import warp.sparse as wsp
    from warp.optim.linear import cg as warp_cg
    from warp.optim.linear import preconditioner as warp_preconditioner

    wp.config.quiet = True
    wp.init()
    out["warp"] = wp.config.version
    dev = "cuda:0"

    def events_ms(fn, reps):
        fn()
        wp.synchronize()
        times = []
        for _ in range(reps):
            a, b = wp.Event(enable_timing=True), wp.Event(enable_timing=True)
            wp.record_event(a)
            fn()
            wp.record_event(b)
            wp.synchronize_event(b)
            times.append(wp.get_event_elapsed_time(a, b))
        return statistics.median(times)

    rows_blocks = np.repeat(np.arange(NROW, dtype=np.int32), np.diff(offsets))
    for d in dtypes:
        sec = out[d]
        try:
            s = wp.float32 if d == "f32" else wp.float64
            if R == 1:
                bt, vt = s, s
                vals = values.astype(np_t[d])
                xv = x64.astype(np_t[d])
            else:
                bt = wp.types.matrix((R, R), s)
                vt = wp.types.vector(R, s)
                vals = values.astype(np_t[d]).reshape(NNZ, R, R)
                xv = x64.astype(np_t[d]).reshape(NROW, R)
            A = wsp.bsr_from_triplets(
                NROW,
                NROW,
                wp.array(rows_blocks, dtype=wp.int32, device=dev),
                wp.array(columns, dtype=wp.int32, device=dev),
                wp.array(vals, dtype=bt, device=dev),
                prune_numerical_zeros=False,
            )
            x = wp.array(xv, dtype=vt, device=dev)
            y = wp.zeros(NROW, dtype=vt, device=dev)
            try:
                sec["warp_nnz"] = int(A.nnz_sync())
            except AttributeError:  # (older Warp: the host count is exact after a sync)
                sec["warp_nnz"] = int(A.nnz)
            sec["warp_mv_ms"] = events_ms(lambda: wsp.bsr_mv(A, x, y, alpha=1.0, beta=0.0), args.reps)
            sec["warp_mv_b2b_ms"] = events_ms(
                lambda: [wsp.bsr_mv(A, x, y, alpha=1.0, beta=0.0) for _ in range(BATCH)], args.reps
            ) / BATCH
            sec["warp_mv_err"] = mv_err(y.numpy())
            if args.cg:
                M = warp_preconditioner(A, "diag")
                xs = wp.zeros(NROW, dtype=vt, device=dev)

                def solve():
                    xs.zero_()
                    wp.synchronize()
                    t = time.perf_counter()
                    res = warp_cg(A, x, xs, tol=args.rtol, maxiter=args.maxiter, M=M, check_every=0)
                    wp.synchronize()
                    return (time.perf_counter() - t) * 1e3, res

                solve()
                runs = [solve() for _ in range(args.cg_reps)]
                sec["warp_cg_ms"] = statistics.median(r[0] for r in runs)
                it = runs[-1][1][0]
                sec["warp_cg_iters"] = int(it.numpy()[0]) if hasattr(it, "numpy") else int(it)
                sec["warp_cg_resid"] = true_residual(xs.numpy())
            del A, x, y
        except Exception as e:  # noqa: BLE001 - any failure drops this dtype's Warp keys
            sec["warp_error"] = f"{type(e).__name__}: {e}"
except Exception as e:  # noqa: BLE001 - no Warp: its rows say why
    out["warp_error"] = f"{type(e).__name__}: {e}"

# ---- CuPy (cuSPARSE) ----
try:
    import cupy as cp
    import cupyx.scipy.sparse as csp
    import cupyx.scipy.sparse.linalg as csl

    out["cupy"] = cp.__version__

    def cupy_events_ms(fn, reps):
        fn()
        cp.cuda.Device().synchronize()
        times = []
        for _ in range(reps):
            a, b = cp.cuda.Event(), cp.cuda.Event()
            a.record()
            fn()
            b.record()
            b.synchronize()
            times.append(cp.cuda.get_elapsed_time(a, b))
        return statistics.median(times)

    for d in dtypes:
        sec = out[d]
        try:
            t = np_t[d]
            A = csp.csr_matrix(
                (cp.asarray(s_val.astype(t)), cp.asarray(s_col), cp.asarray(s_off)), shape=(N, N)
            )
            x = cp.asarray(x64.astype(t))
            box = {}

            def mv():
                box["y"] = A @ x

            sec["cupy_mv_ms"] = cupy_events_ms(mv, args.reps)
            sec["cupy_mv_b2b_ms"] = cupy_events_ms(lambda: [mv() for _ in range(BATCH)], args.reps) / BATCH
            sec["cupy_mv_err"] = mv_err(cp.asnumpy(box["y"]))
            if args.cg:
                dinv = cp.asarray((1.0 / diag).astype(t))
                M = csl.LinearOperator((N, N), matvec=lambda v: dinv * v, dtype=t)
                count = [0]

                def cb(_xk):
                    count[0] += 1

                # CuPy renamed `tol` to `rtol` (as SciPy did); take whichever it has.
                import inspect

                key = "rtol" if "rtol" in inspect.signature(csl.cg).parameters else "tol"

                def solve():
                    count[0] = 0
                    cp.cuda.Device().synchronize()
                    t0 = time.perf_counter()
                    xs, _info = csl.cg(A, x, maxiter=args.maxiter, M=M, callback=cb, **{key: args.rtol})
                    cp.cuda.Device().synchronize()
                    return (time.perf_counter() - t0) * 1e3, xs, count[0]

                solve()
                runs = [solve() for _ in range(args.cg_reps)]
                sec["cupy_cg_ms"] = statistics.median(r[0] for r in runs)
                sec["cupy_cg_iters"] = runs[-1][2]
                sec["cupy_cg_resid"] = true_residual(cp.asnumpy(runs[-1][1]))
            del A, x, box
        except Exception as e:  # noqa: BLE001 - any failure drops this dtype's CuPy keys
            sec["cupy_error"] = f"{type(e).__name__}: {e}"
except Exception as e:  # noqa: BLE001 - no CuPy: its rows say why
    out["cupy_error"] = f"{type(e).__name__}: {e}"

sys.stdout.flush()
print(json.dumps(out))
