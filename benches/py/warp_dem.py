"""Warp's side of `cargo run --release --example dem -- --preset warp --compare-warp`: NVIDIA
Warp's own example_dem (warp/examples/core/example_dem.py, as shipped with Warp) timed on the
same GPU in the same device call, so the Rust example can print a ratio against a measured
figure instead of a quoted one.

Its frame is what Example.step() does without its ScopedTimer: the hash grid built once, then
the graph Warp captured of 64 substeps (forces, integrate) replayed. A warm-up of 3 frames
(compilation, first replays), then FRAMES timed frames between two synchronisations. Prints
one line: `warp_dem_ms_per_frame <ms> particles <n> finite <0|1>`.

Run on the GPU machine with Warp importable (PYTHONPATH pointing at an unpacked Warp):
    python3 benches/py/warp_dem.py [FRAMES]
"""

import sys
import time

import numpy as np
import warp as wp

FRAMES = int(sys.argv[1]) if len(sys.argv) > 1 else 100

wp.config.quiet = True
wp.init()

from warp.examples.core import example_dem  # noqa: E402  (after wp.init: the module defines kernels)


def frame(ex):
    ex.grid.build(ex.x, ex.grid_cell_size)
    wp.capture_launch(ex.graph)


ex = example_dem.Example(stage_path=None)
for _ in range(3):
    frame(ex)
wp.synchronize()
t = time.perf_counter()
for _ in range(FRAMES):
    frame(ex)
wp.synchronize()
ms = (time.perf_counter() - t) * 1e3 / FRAMES
x = ex.x.numpy()
print(f"warp_dem_ms_per_frame {ms:.4f} particles {len(x)} finite {int(np.isfinite(x).all())}")
