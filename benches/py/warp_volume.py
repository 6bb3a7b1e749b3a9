"""Warp's side of benches/volume.rs: NVIDIA Warp's Volume and MarchingCubes timed on the same
GPU, in the same device call, with the same workloads, so the Rust bench can print ratios.

- A sparse SDF over a 256^3 index box (voxel size 1/128, origin -1): the leaves (8^3 tiles)
  whose centres lie within 16 voxels of a torus (R = 0.6, r = 0.25, axis y), allocated by
  tiles with background 0.1, every voxel of them storing the torus's exact SDF.
- 1M points uniform in the band |sdf| < 0.05: world_to_index then a trilinear
  volume_sample_f; the mean sampled value is printed as a check.
- Allocation from 1M points: allocate_by_voxels from 1M world points uniform in the band
  (voxel size 1/128), an OnIndex grid; its active voxel count is printed.
- Marching cubes of the 256^3 dense torus SDF at threshold 0: triangle and vertex counts.

The tile set and the point distributions are made with the same formulas as the Rust side;
the random points come from NumPy, so only the distributions are shared. Medians of timed
repetitions after a warm-up (compilation excluded). One JSON object on the last line.

Run on the GPU machine with Warp unpacked by ../shared/tools/warp-bundle:
    PYTHONPATH=/root/warp-lang python3 benches/py/warp_volume.py [N]
"""

import json
import os
import statistics
import sys
import time

import numpy as np
import warp as wp

N = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
REPS = 9
RES = 256
H = 2.0 / RES
MAJOR, MINOR = 0.6, 0.25

wp.config.quiet = True
wp.init()


def torus_sdf_np(p):
    q0 = np.sqrt(p[..., 0] ** 2 + p[..., 2] ** 2) - MAJOR
    return np.sqrt(q0**2 + p[..., 1] ** 2) - MINOR


@wp.func
def torus_sdf(p: wp.vec3):
    q = wp.vec2(wp.length(wp.vec2(p[0], p[2])) - MAJOR, p[1])
    return wp.length(q) - MINOR


@wp.kernel
def fill_tiles(vol: wp.uint64, tiles: wp.array(dtype=wp.vec3i), h: float):
    t, v = wp.tid()
    o = tiles[t]
    i = o[0] + v // 64
    j = o[1] + (v // 8) % 8
    k = o[2] + v % 8
    p = wp.volume_index_to_world(vol, wp.vec3(float(i), float(j), float(k)))
    wp.volume_store_f(vol, i, j, k, torus_sdf(p))


@wp.kernel
def sample(vol: wp.uint64, pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    uvw = wp.volume_world_to_index(vol, pts[i])
    out[i] = wp.volume_sample_f(vol, uvw, wp.Volume.LINEAR)


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


def band_tiles():
    """Leaf origins of the 256^3 box whose centre is within 16 voxels of the surface (a leaf's
    centre is within 6.1 voxels of its corners, so every trilinear tap of a point within 6.4
    voxels, 0.05, of the surface lands in an allocated leaf)."""
    o = np.arange(0, RES, 8)
    a, b, c = np.meshgrid(o, o, o, indexing="ij")
    org = np.stack([a, b, c], axis=-1).reshape(-1, 3)
    centre = -1.0 + (org + 3.5) * H
    keep = np.abs(torus_sdf_np(centre)) < 16 * H
    return org[keep].astype(np.int32)


def band_points(n, band, rng):
    out = []
    got = 0
    while got < n:
        p = rng.uniform(-1.0, 1.0, size=(4 * n, 3))
        p[:, 1] *= 0.45
        p = p[np.abs(torus_sdf_np(p)) < band]
        out.append(p)
        got += len(p)
    return np.concatenate(out)[:n].astype(np.float32)


result = {}
rng = np.random.default_rng(5)
tiles_np = band_tiles()
tiles = wp.array(tiles_np, dtype=wp.vec3i)
result["tiles"] = int(len(tiles_np))


def build():
    v = wp.Volume.allocate_by_tiles(tiles, voxel_size=H, bg_value=0.1, translation=(-1.0, -1.0, -1.0))
    wp.launch(fill_tiles, dim=(len(tiles_np), 512), inputs=[v.id, tiles, H])
    return v


result["sdf_build_ms"] = median_ms(build)
vol = build()
pts = wp.array(band_points(N, 0.05, rng), dtype=wp.vec3)
out = wp.zeros(N, dtype=float)
result["sample_ms"] = median_ms(lambda: wp.launch(sample, dim=N, inputs=[vol.id, pts, out]))
result["mean_sample"] = float(out.numpy().mean())

alloc_pts = wp.array(band_points(N, 0.05, rng), dtype=wp.vec3)
holder = {}


def allocate():
    holder["v"] = wp.Volume.allocate_by_voxels(alloc_pts, voxel_size=H, translation=(-1.0, -1.0, -1.0))


result["allocate_voxels_ms"] = median_ms(allocate)
result["allocated_voxels"] = int(holder["v"].get_voxel_count())

g = (np.arange(RES) * (2.0 / (RES - 1)) - 1.0).astype(np.float64)
gx, gy, gz = np.meshgrid(g, g, g, indexing="ij")
field_np = torus_sdf_np(np.stack([gx, gy, gz], axis=-1)).astype(np.float32)
field = wp.array(field_np, dtype=float)
# Warp 1.19's MarchingCubes takes the device from the field.
mc = wp.MarchingCubes(RES, RES, RES)
result["mc_ms"] = median_ms(lambda: mc.surface(field, 0.0))
result["mc_triangles"] = int(len(mc.indices) // 3)
result["mc_vertices"] = int(len(mc.verts))

# A fixture for tests/suite/volume.rs: a small sphere SDF allocated and filled by Warp on the
# GPU (16^3 voxels of 1/8 from -1, radius 0.6, background 0.5), saved by Warp with ZIP, and
# Warp's own trilinear samples of it at 500 seeded points, written where the device call
# collects files ($OUT).
if os.environ.get("OUT"):

    @wp.kernel
    def fill_sphere(vol: wp.uint64):
        i, j, k = wp.tid()
        p = wp.volume_index_to_world(vol, wp.vec3(float(i), float(j), float(k)))
        wp.volume_store_f(vol, i, j, k, wp.length(p) - 0.6)

    small = wp.Volume.allocate_by_tiles(
        wp.array(np.array([[a, b, c] for a in (0, 8) for b in (0, 8) for c in (0, 8)], dtype=np.int32), dtype=wp.vec3i),
        voxel_size=0.125,
        bg_value=0.5,
        translation=(-1.0, -1.0, -1.0),
    )
    wp.launch(fill_sphere, dim=(16, 16, 16), inputs=[small.id])
    small.save_to_nvdb(os.path.join(os.environ["OUT"], "warp_gpu_sphere_zip.nvdb"), codec="zip")
    q = np.random.default_rng(9).uniform(-1.5, 17.5, size=(500, 3)).astype(np.float32)
    qs = wp.array(q, dtype=wp.vec3)
    vals = wp.zeros(500, dtype=float)

    @wp.kernel
    def sample_index(vol: wp.uint64, pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
        i = wp.tid()
        out[i] = wp.volume_sample_f(vol, pts[i], wp.Volume.LINEAR)

    wp.launch(sample_index, dim=500, inputs=[small.id, qs, vals])
    with open(os.path.join(os.environ["OUT"], "warp_gpu_sphere_samples.json"), "w") as f:
        json.dump({"uvw": q.tolist(), "linear": vals.numpy().tolist()}, f)

print(json.dumps(result))
