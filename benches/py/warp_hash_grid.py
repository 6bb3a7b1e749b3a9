"""Warp's side of benches/spatial.rs: NVIDIA Warp's HashGrid timed on the same GPU, in the
same device call, with the same workload, so the Rust bench can print ratios.

1M points uniform in a 10^3 box, a 128^3 grid, radius 0.2: the grid build, and a count of
the neighbours within the radius, a thread per point in point order and in the grid's cell
order (hash_grid_point_id). Then Warp's (single-threaded) CPU backend at the same density
with 100K points in a box of side 10 * 0.1^(1/3): build and point-order count. Medians of
timed repetitions after a warm-up (compilation excluded). Prints one JSON object on its last
line.

Run on the GPU machine with Warp unpacked by ../shared/tools/warp-bundle:
    PYTHONPATH=/root/warp-lang python3 benches/py/warp_hash_grid.py [N]
"""

import json
import statistics
import sys
import time

import numpy as np
import warp as wp

N = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
RADIUS = 0.2
DIM = 128
REPS = 9

wp.config.quiet = True
wp.init()


@wp.kernel
def count_point_order(grid: wp.uint64, x: wp.array(dtype=wp.vec3), r: float, out: wp.array(dtype=int)):
    i = wp.tid()
    p = x[i]
    c = int(0)
    for j in wp.hash_grid_query(grid, p, r):
        if wp.length(p - x[j]) <= r:
            c += 1
    out[i] = c


@wp.kernel
def count_cell_order(grid: wp.uint64, x: wp.array(dtype=wp.vec3), r: float, out: wp.array(dtype=int)):
    i = wp.hash_grid_point_id(grid, wp.tid())
    p = x[i]
    c = int(0)
    for j in wp.hash_grid_query(grid, p, r):
        if wp.length(p - x[j]) <= r:
            c += 1
    out[i] = c


def median_ms(fn):
    fn()
    wp.synchronize()
    times = []
    for _ in range(REPS):
        wp.synchronize()
        t = time.perf_counter()
        fn()
        wp.synchronize()
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times)


def event_ms(fn):
    """GPU milliseconds between CUDA events around `fn` (median of REPS after a warm-up): the
    device's share of a call, without the host's synchronisation."""
    fn()
    times = []
    for _ in range(REPS):
        a, b = wp.Event(enable_timing=True), wp.Event(enable_timing=True)
        wp.record_event(a)
        fn()
        wp.record_event(b)
        wp.synchronize_event(b)
        times.append(wp.get_event_elapsed_time(a, b))
    return statistics.median(times)


rng = np.random.default_rng(1)
points = wp.array(rng.random((N, 3), dtype=np.float32) * 10.0, dtype=wp.vec3)
counts = wp.zeros(N, dtype=int)
grid = wp.HashGrid(DIM, DIM, DIM)

build = median_ms(lambda: grid.build(points, RADIUS))
build_events = event_ms(lambda: grid.build(points, RADIUS))
point = median_ms(lambda: wp.launch(count_point_order, N, inputs=[grid.id, points, RADIUS, counts]))
mean_point = float(counts.numpy().mean())
cell = median_ms(lambda: wp.launch(count_cell_order, N, inputs=[grid.id, points, RADIUS, counts]))
mean_cell = float(counts.numpy().mean())
# Warp's CPU backend at the same density (fewer repetitions: a count takes ~0.2 s). Skipped
# where Warp has no CPU compiler (warp-bundle leaves warp-clang out): the Rust side then quotes
# DESIGN.md's figures.
cpu = {}
try:
    NC = N // 10
    cpu_points = wp.array(rng.random((NC, 3), dtype=np.float32) * (10.0 * 0.1 ** (1.0 / 3.0)),
                          dtype=wp.vec3, device="cpu")
    cpu_counts = wp.zeros(NC, dtype=int, device="cpu")
    cpu_grid = wp.HashGrid(DIM, DIM, DIM, device="cpu")
    REPS = 5
    cpu["cpu_build_ms"] = median_ms(lambda: cpu_grid.build(cpu_points, RADIUS))
    cpu["cpu_query_point_order_ms"] = median_ms(lambda: wp.launch(
        count_point_order, NC, inputs=[cpu_grid.id, cpu_points, RADIUS, cpu_counts], device="cpu"))
    cpu["cpu_n"] = NC
    cpu["cpu_mean_neighbours"] = float(cpu_counts.numpy().mean())
except Exception as e:  # noqa: BLE001 (any failure of the optional part)
    print(f"Warp CPU side skipped: {e}", file=sys.stderr)

print(json.dumps({
    "warp": wp.config.version,
    "n": N,
    "build_ms": build,
    "build_events_ms": build_events,
    "query_point_order_ms": point,
    "query_cell_order_ms": cell,
    "mean_neighbours_point_order": mean_point,
    "mean_neighbours_cell_order": mean_cell,
    **cpu,
}))
