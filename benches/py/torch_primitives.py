"""PyTorch's side of benches/spatial.rs's primitives section: torch.sort (key/value pairs:
a stable sort of the keys and a gather of the values), torch.cumsum and torch.sum on the
same GPU, in the same device call, at the sizes the Rust bench uses; and, where CuPy is
installed, CuPy's pairs sort on the same tensors (cupy.argsort, a stable sort that Thrust
runs as CUB's radix sort, and a gather of keys and values). Medians of timed repetitions
after a warm-up, CUDA events around each call. Prints one JSON object on its last line.

    python3 benches/py/torch_primitives.py [N ...]
"""

import json
import statistics
import sys

import torch

try:
    import cupy
except ImportError:  # the bench prints "-" for CuPy's columns
    cupy = None

SIZES = [int(a) for a in sys.argv[1:]] or [1 << 20, 1 << 24]
REPS = 15
dev = torch.device("cuda:0")


def median_ms(fn):
    fn()
    torch.cuda.synchronize()
    times = []
    for _ in range(REPS):
        a, b = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        a.record()
        fn()
        b.record()
        b.synchronize()
        times.append(a.elapsed_time(b))
    return statistics.median(times)


out = {"torch": torch.__version__, "sizes": {}}
g = torch.Generator(device=dev).manual_seed(1)
for n in SIZES:
    keys = torch.randint(0, 2**31 - 1, (n,), device=dev, dtype=torch.int32, generator=g)
    vals = torch.arange(n, device=dev, dtype=torch.int32)
    fkeys = torch.rand(n, device=dev, generator=g)

    def sort_pairs():
        k, idx = torch.sort(keys, stable=True)
        return k, vals[idx]

    def sort_f32_pairs():
        k, idx = torch.sort(fkeys, stable=True)
        return k, vals[idx]

    ints = torch.randint(0, 100, (n,), device=dev, dtype=torch.int32, generator=g)
    section = out["sizes"][str(n)] = {
        "sort_pairs_i32_ms": median_ms(sort_pairs),
        "sort_pairs_f32_ms": median_ms(sort_f32_pairs),
        "cumsum_i32_ms": median_ms(lambda: torch.cumsum(ints, 0, dtype=torch.int32)),
        "cumsum_f32_ms": median_ms(lambda: torch.cumsum(fkeys, 0)),
        "sum_f32_ms": median_ms(lambda: torch.sum(fkeys)),
    }
    if cupy is not None:
        # The same memory through DLPack; CuPy's work goes on PyTorch's current stream, which
        # the events time. A CuPy that fails is reported, and PyTorch's figures still count.
        try:
            with cupy.cuda.ExternalStream(torch.cuda.current_stream().cuda_stream):
                ck, cf, cv = (cupy.from_dlpack(t) for t in (keys, fkeys, vals))

                def cupy_pairs(k):
                    idx = cupy.argsort(k)
                    return k[idx], cv[idx]

                section["cupy_sort_pairs_i32_ms"] = median_ms(lambda: cupy_pairs(ck))
                section["cupy_sort_pairs_f32_ms"] = median_ms(lambda: cupy_pairs(cf))
            out["cupy"] = cupy.__version__
        except Exception as e:  # noqa: BLE001 - any CuPy failure only drops its columns
            out["cupy_error"] = repr(e)
print(json.dumps(out))
