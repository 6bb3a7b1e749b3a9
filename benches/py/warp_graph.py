"""Warp's side of benches/graph.rs: NVIDIA Warp's launch paths timed on the same GPU in the
same device call, with the same step loop, so the Rust bench can print ratios.

The substep: five pairs of `v -= k x dt; x += v dt` over 1024 oscillators; the loop runs
1000 substeps (10,000 kernels). Timed, each as microseconds per kernel from the start of the
loop until the GPU has finished (wp.synchronize), medians of 7 after a warm-up:
- plain: wp.launch for every kernel;
- launch objects: wp.launch(..., record_cmd=True) once per kernel of a pair, then .launch();
- graph of a substep: one captured substep replayed 1000 times with wp.capture_launch;
- one graph: all 10,000 launches captured, replayed once;
- capture_while: the substep and a counter kernel in a wp.capture_while body, looping until
  the counter reaches zero (11 kernels an iteration, counted as such);
- host cost per launch: 200 launches of one kernel from an idle GPU, plain and wp.Launch.
One JSON object on the last line.

Run on the GPU machine with Warp unpacked by ../shared/tools/warp-bundle:
    PYTHONPATH=/root/warp-lang python3 benches/py/warp_graph.py
"""

import json
import statistics
import time

import numpy as np
import warp as wp

N = 1024
SUBSTEPS = 1000
PAIRS = 5
KERNELS = SUBSTEPS * 2 * PAIRS
K = 40.0
DT = 1e-4
REPS = 7

wp.config.quiet = True
wp.init()
dev = wp.get_device("cuda:0")


@wp.kernel
def velocity(x: wp.array(dtype=float), v: wp.array(dtype=float), k: float, dt: float):
    i = wp.tid()
    v[i] = v[i] - k * x[i] * dt


@wp.kernel
def position(x: wp.array(dtype=float), v: wp.array(dtype=float), dt: float):
    i = wp.tid()
    x[i] = x[i] + v[i] * dt


@wp.kernel
def count_down(counter: wp.array(dtype=int), cond: wp.array(dtype=int)):
    c = counter[0] - 1
    counter[0] = c
    cond[0] = wp.where(c > 0, 1, 0)


x0 = (0.5 + (np.arange(N) % 7) * 0.1).astype(np.float32)
x = wp.array(x0, dtype=float, device=dev)
v = wp.zeros(N, dtype=float, device=dev)
wp.load_module(device=dev)


def substep():
    for _ in range(PAIRS):
        wp.launch(velocity, N, inputs=[x, v, K, DT], device=dev)
        wp.launch(position, N, inputs=[x, v, DT], device=dev)


def timed(run, kernels=KERNELS):
    run()
    wp.synchronize()
    ts = []
    for _ in range(REPS):
        wp.synchronize()
        t = time.perf_counter()
        run()
        wp.synchronize()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts) * 1e6 / kernels


def plain():
    for _ in range(SUBSTEPS):
        substep()


out = {}
out["plain_us"] = timed(plain)

vel = wp.launch(velocity, N, inputs=[x, v, K, DT], device=dev, record_cmd=True)
pos = wp.launch(position, N, inputs=[x, v, DT], device=dev, record_cmd=True)


def objects():
    for _ in range(SUBSTEPS * PAIRS):
        vel.launch()
        pos.launch()


out["launch_object_us"] = timed(objects)


def host_cost(launch):
    # Host microseconds per launch when the GPU keeps up: 200 launches from an idle GPU.
    ts = []
    for _ in range(16):
        wp.synchronize()
        t = time.perf_counter()
        for _ in range(200):
            launch()
        ts.append((time.perf_counter() - t) * 1e6 / 200)
    wp.synchronize()
    return statistics.median(ts[1:])


out["host_plain_us"] = host_cost(lambda: wp.launch(velocity, N, inputs=[x, v, K, DT], device=dev))
out["host_launch_object_us"] = host_cost(vel.launch)

with wp.ScopedCapture(device=dev) as cap:
    substep()
one = cap.graph


def replays():
    for _ in range(SUBSTEPS):
        wp.capture_launch(one)


out["graph_substep_us"] = timed(replays)

with wp.ScopedCapture(device=dev) as cap:
    plain()
whole = cap.graph
out["graph_all_us"] = timed(lambda: wp.capture_launch(whole))

counter = wp.zeros(1, dtype=int, device=dev)
cond = wp.zeros(1, dtype=int, device=dev)


def body():
    substep()
    wp.launch(count_down, 1, inputs=[counter, cond], device=dev)


try:
    with wp.ScopedCapture(device=dev) as cap:
        wp.capture_while(cond, body)
    loop = cap.graph

    def adaptive():
        counter.fill_(SUBSTEPS)
        cond.fill_(1)
        wp.capture_launch(loop)

    # Per kernel of the 11 an iteration runs (the fills are two more operations, not counted).
    out["capture_while_us"] = timed(adaptive, SUBSTEPS * (2 * PAIRS + 1))
    out["capture_while_iterations"] = int(SUBSTEPS - counter.numpy()[0])
except Exception as e:  # noqa: BLE001 (reported, not fatal)
    out["capture_while_error"] = str(e)

out["x_mean"] = float(x.numpy().mean())
out["warp"] = wp.__version__
print(json.dumps(out))
