"""Warp's side of benches/geometry.rs: NVIDIA Warp's Mesh and Bvh timed on the same GPU, in the
same device call, with the same workloads (shared/DESIGN.md's method), so the Rust bench can
print ratios.

- Mesh: a torus (R = 1, r = 0.4) on a 500 x 200 grid of quads, 200K triangles: build (BVH) and
  refit.
- 1M query points uniform in [-2, 2]^2 x [-1, 1]: mesh_query_point (signed by three
  axis-aligned rays), mesh_query_point_sign_normal (signed by the angle-weighted pseudonormal,
  warp-lang's method), mesh_query_point_sign_parity (its defaults: one ray) and
  mesh_query_point_no_sign, max_dist 10; the mean distance is printed as a check.
- 1M rays from points on the radius-3 sphere aimed at random points of the torus's box:
  mesh_query_ray, max_t 100; the hit fraction is printed (about 80%).
- Bvh of 1M boxes, centres uniform in 10^3, half extents U[0.025, 0.075]: build, refit, and a
  bvh_query_aabb per box counting the overlapping boxes (about 7.9 each).

Medians of timed repetitions after a warm-up (compilation excluded). The geometry is generated
here with the same formulas as the Rust side (benches/geometry.rs); the random points come
from NumPy, so only the distributions, not the points, are shared. Prints one JSON object on
its last line.

Run on the GPU machine with Warp unpacked by ../shared/tools/warp-bundle:
    PYTHONPATH=/root/warp-lang python3 benches/py/warp_mesh.py [N]
"""

import json
import statistics
import sys
import time

import numpy as np
import warp as wp

N = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
REPS = 9

wp.config.quiet = True
wp.init()


def torus(nu=500, nv=200, big=1.0, small=0.4):
    """A closed torus: nu x nv vertices, two triangles per quad, outward normals (counter-
    clockwise seen from outside)."""
    u = np.arange(nu) * (2 * np.pi / nu)
    v = np.arange(nv) * (2 * np.pi / nv)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    x = (big + small * np.cos(vv)) * np.cos(uu)
    y = (big + small * np.cos(vv)) * np.sin(uu)
    z = small * np.sin(vv)
    points = np.stack([x, y, z], axis=-1).reshape(-1, 3).astype(np.float32)
    idx = []
    for i in range(nu):
        for j in range(nv):
            a = i * nv + j
            b = ((i + 1) % nu) * nv + j
            c = ((i + 1) % nu) * nv + (j + 1) % nv
            d = i * nv + (j + 1) % nv
            idx += [a, b, c, a, c, d]
    return points, np.array(idx, dtype=np.int32)


@wp.kernel
def query_point(mesh: wp.uint64, pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_point(mesh, pts[i], 10.0)
    d = float(0.0)
    if q.result:
        d = wp.length(pts[i] - wp.mesh_eval_position(mesh, q.face, q.u, q.v)) * q.sign
    out[i] = d


@wp.kernel
def query_point_sign_normal(mesh: wp.uint64, pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_point_sign_normal(mesh, pts[i], 10.0)
    d = float(0.0)
    if q.result:
        d = wp.length(pts[i] - wp.mesh_eval_position(mesh, q.face, q.u, q.v)) * q.sign
    out[i] = d


@wp.kernel
def query_point_sign_parity(mesh: wp.uint64, pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_point_sign_parity(mesh, pts[i], 10.0)
    d = float(0.0)
    if q.result:
        d = wp.length(pts[i] - wp.mesh_eval_position(mesh, q.face, q.u, q.v)) * q.sign
    out[i] = d


@wp.kernel
def query_point_no_sign(mesh: wp.uint64, pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, pts[i], 10.0)
    d = float(0.0)
    if q.result:
        d = wp.length(pts[i] - wp.mesh_eval_position(mesh, q.face, q.u, q.v))
    out[i] = d


@wp.kernel
def query_ray(mesh: wp.uint64, start: wp.array(dtype=wp.vec3), dirs: wp.array(dtype=wp.vec3),
              out: wp.array(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_ray(mesh, start[i], dirs[i], 100.0)
    t = float(-1.0)
    if q.result:
        t = q.t
    out[i] = t


@wp.kernel
def count_overlaps(bvh: wp.uint64, lo: wp.array(dtype=wp.vec3), hi: wp.array(dtype=wp.vec3),
                   out: wp.array(dtype=int)):
    i = wp.tid()
    q = wp.bvh_query_aabb(bvh, lo[i], hi[i])
    b = int(0)
    c = int(0)
    while wp.bvh_query_next(q, b):
        c += 1
    out[i] = c


def median_ms(fn, reps=REPS):
    fn()
    wp.synchronize()
    times = []
    for _ in range(reps):
        wp.synchronize()
        t = time.perf_counter()
        fn()
        wp.synchronize()
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times)


rng = np.random.default_rng(2)
pts_np, idx_np = torus()
points = wp.array(pts_np, dtype=wp.vec3)
indices = wp.array(idx_np, dtype=int)
res = {"warp": wp.config.version, "n": N, "triangles": len(idx_np) // 3}

res["mesh_build_ms"] = median_ms(lambda: wp.Mesh(points=points, indices=indices))
mesh = wp.Mesh(points=points, indices=indices)
res["mesh_refit_ms"] = median_ms(mesh.refit)

q_np = (rng.random((N, 3)) * np.array([4.0, 4.0, 2.0]) - np.array([2.0, 2.0, 1.0])).astype(np.float32)
qp = wp.array(q_np, dtype=wp.vec3)
dist = wp.zeros(N, dtype=float)
res["query_point_ms"] = median_ms(lambda: wp.launch(query_point, N, inputs=[mesh.id, qp, dist]))
res["signed_inside_fraction"] = float((dist.numpy() < 0).mean())
res["query_point_sign_normal_ms"] = median_ms(
    lambda: wp.launch(query_point_sign_normal, N, inputs=[mesh.id, qp, dist])
)
res["sign_normal_inside_fraction"] = float((dist.numpy() < 0).mean())
res["query_point_sign_parity_ms"] = median_ms(
    lambda: wp.launch(query_point_sign_parity, N, inputs=[mesh.id, qp, dist])
)
res["sign_parity_inside_fraction"] = float((dist.numpy() < 0).mean())
res["query_point_no_sign_ms"] = median_ms(lambda: wp.launch(query_point_no_sign, N, inputs=[mesh.id, qp, dist]))
res["mean_distance"] = float(dist.numpy().mean())

# Rays: starts on the radius-3 sphere, aimed at points uniform in the torus's box.
s = rng.normal(size=(N, 3))
s = (3.0 * s / np.linalg.norm(s, axis=1, keepdims=True)).astype(np.float32)
target = (rng.random((N, 3)) * np.array([2.8, 2.8, 0.8]) - np.array([1.4, 1.4, 0.4])).astype(np.float32)
d = target - s
d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
rs, rd = wp.array(s, dtype=wp.vec3), wp.array(d, dtype=wp.vec3)
ts = wp.zeros(N, dtype=float)
res["query_ray_ms"] = median_ms(lambda: wp.launch(query_ray, N, inputs=[mesh.id, rs, rd, ts]))
res["ray_hit_fraction"] = float((ts.numpy() >= 0).mean())

# A Bvh of 1M boxes.
c = rng.random((N, 3)) * 10.0
h = rng.random((N, 3)) * 0.05 + 0.025
lo = wp.array((c - h).astype(np.float32), dtype=wp.vec3)
hi = wp.array((c + h).astype(np.float32), dtype=wp.vec3)
res["bvh_build_ms"] = median_ms(lambda: wp.Bvh(lo, hi))
bvh = wp.Bvh(lo, hi)
res["bvh_refit_ms"] = median_ms(bvh.refit)
counts = wp.zeros(N, dtype=int)
res["bvh_query_aabb_ms"] = median_ms(lambda: wp.launch(count_overlaps, N, inputs=[bvh.id, lo, hi, counts]))
res["bvh_mean_overlaps"] = float(counts.numpy().mean())

print(json.dumps(res))
