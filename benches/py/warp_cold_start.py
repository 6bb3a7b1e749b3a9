"""Warp's side of benches/cold_start.rs: the time to a first result in a fresh process, for
the autodiff example's seed function with its derivative (one module: forward and backward),
with the kernel cache directory given (empty: cold; filled by a previous run: warm).

Prints one JSON object, in milliseconds: `import warp` (`import_ms`), `wp.init()` (`init_ms`),
loading the module on cuda:0 (`load_ms`: NVRTC for forward and backward together when cold, a
cache read when warm, and the module load: what warp-lang's `kernel_loading_ms` measures),
from after `wp.init()` to the derivative on the host (`after_init_ms`: the load, the launches
and the copies), from the start of the script to it (`first_result_ms`), and the value.

    PYTHONPATH=/root/warp-lang python3 benches/py/warp_cold_start.py CACHE_DIR
"""

import json
import sys
import time

t0 = time.perf_counter()
import warp as wp  # noqa: E402

t_import = time.perf_counter()
wp.config.kernel_cache_dir = sys.argv[1]
wp.config.quiet = True
wp.init()
t_init = time.perf_counter()


@wp.kernel
def seed(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    v = x[i]
    y[i] = wp.sin(v * v) * wp.log(v) + v * v * v / wp.sqrt(wp.float64(1.0) - v * v)


t1 = time.perf_counter()
wp.load_module(device="cuda:0")
t_load = time.perf_counter()
x = wp.array([0.5], dtype=wp.float64, requires_grad=True, device="cuda:0")
y = wp.zeros(1, dtype=wp.float64, requires_grad=True, device="cuda:0")
tape = wp.Tape()
with tape:
    wp.launch(seed, 1, inputs=[x, y], device="cuda:0")
tape.backward(y)
g = float(x.grad.numpy()[0])
t2 = time.perf_counter()
print(
    json.dumps(
        {
            "first_result_ms": (t2 - t0) * 1e3,
            "after_init_ms": (t2 - t1) * 1e3,
            "import_ms": (t_import - t0) * 1e3,
            "init_ms": (t_init - t_import) * 1e3,
            "load_ms": (t_load - t1) * 1e3,
            "grad": g,
        }
    )
)
