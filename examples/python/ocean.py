"""The ocean scene: a surface displaced by a sum of Gerstner waves, its positions and analytic
normals computed by a warp-lang kernel made a Python op (`warp_sim.ocean`, f32, and
`warp_sim.ocean64`, f64), driven from JAX (under `jax.jit`) or NumPy.

    python3 examples/python/ocean.py [--backend jax|numpy] [--n N] [--waves M] [--frames F]
                                     [--out DIR] [--fit]

What it prints and writes:

- every 10th frame as a PNG in DIR (the height field coloured by height, shaded by the kernel's
  normals);
- the error table: the ops against the closed form evaluated by NumPy in float64 (largest
  position error and largest normal angle, beside the float32 bound; float64 within 1e-12);
- the convergence of finite-difference normals (`warp_sim.fd_normals64` on the displaced grid)
  to the analytic ones: halving the grid step divides the error by about 4;
- the time per frame of the op under `jax.jit`, of the same closed form in `jax.numpy` under
  `jax.jit`, of the op through NumPy and of the closed form in NumPy;
- with --fit: the wave amplitudes recovered from the surface at four times, by `jax.grad`
  through `warp_sim.ocean64.jax` (Adam, then BFGS), with the loss curve as CSV and SVG.

The model and the kernel are in src/ocean.rs. `warp_sim` is imported from PYTHONPATH, else
from this directory (where the build copies warp_sim.abi3.so).
"""

import argparse
import math
import os
import struct
import sys
import time
import zlib

import numpy as np

sys.path.append(os.path.dirname(os.path.abspath(__file__)))
import warp_sim as ws  # noqa: E402

# Deep-water dispersion's gravity: the same value as the kernel's.
GRAVITY = 9.81
# The side of the square patch of sea, in metres.
EXTENT = 64.0
# Frames per second of simulated time.
FPS = 30.0
# The largest float32 rounding of one operation (2^-23).
EPS32 = float(np.finfo(np.float32).eps)


# ----------------------------------------------------------------------------- the scene


def make_waves(m, seed=0, extent=EXTENT):
    """`m` waves as float64 NumPy arrays: amplitude, unit direction (m, 2), wavelength, phase.
    Wavelengths are log-uniform in [extent/16, extent/2], directions within 60 degrees of a
    wind along x1, and amplitudes give each wave a slope a k of at most 0.5/m (the sum stays
    gentle however many waves there are)."""
    rng = np.random.default_rng(seed)
    wavelength = np.exp(rng.uniform(np.log(extent / 16), np.log(extent / 2), m))
    angle = rng.uniform(-np.pi / 3, np.pi / 3, m)
    direction = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    amp = 0.5 / m * wavelength / (2 * np.pi) * rng.uniform(0.5, 1.0, m)
    phase = rng.uniform(0, 2 * np.pi, m)
    return dict(amp=amp, dir=direction, wavelength=wavelength, phase=phase)


def make_grid(n, extent=EXTENT):
    """The rest grid, (n, n, 2) float64: rest[i, j] = (x1_i, x2_j) on [0, extent]^2."""
    x = np.linspace(0.0, extent, n)
    return np.stack(np.meshgrid(x, x, indexing="ij"), axis=-1)


def closed_form(xp, rest, amp, direction, wavelength, phase, t, q):
    """P and N of the model (src/ocean.rs) in array library `xp` (NumPy or jax.numpy), in the
    arrays' own precision, with the waves on a trailing axis."""
    x1, x2 = rest[..., 0:1], rest[..., 1:2]
    d1, d2 = direction[:, 0], direction[:, 1]
    k = 2 * np.pi / wavelength
    omega = xp.sqrt(GRAVITY * k)
    theta = k * (d1 * x1 + d2 * x2) - omega * t + phase
    s, c = xp.sin(theta), xp.cos(theta)
    qa = q * amp / (k * amp.sum())
    qak = q * amp / amp.sum()
    p = xp.stack(
        [rest[..., 0] - (qa * d1 * s).sum(-1), (amp * c).sum(-1), rest[..., 1] - (qa * d2 * s).sum(-1)], axis=-1
    )
    t1 = xp.stack([1 - (qak * d1 * d1 * c).sum(-1), -(amp * k * d1 * s).sum(-1), -(qak * d2 * d1 * c).sum(-1)], axis=-1)
    t2 = xp.stack([-(qak * d1 * d2 * c).sum(-1), -(amp * k * d2 * s).sum(-1), 1 - (qak * d2 * d2 * c).sum(-1)], axis=-1)
    nrm = xp.cross(t2, t1)
    return p, nrm / xp.linalg.norm(nrm, axis=-1, keepdims=True)


def op_args(rest, w, t, dtype):
    """The op's array arguments in its parameter order, as NumPy arrays of `dtype`."""
    cast = lambda a: np.ascontiguousarray(a, dtype=dtype)  # noqa: E731
    return (cast(rest), cast(w["amp"]), cast(w["dir"]), cast(w["wavelength"]), cast(w["phase"]), cast([t]))


def angle(a, b):
    """The angle between unit vectors, accurate at small angles (arccos of the dot is not)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(-1))


def f32_bounds(rest, w, ts):
    """The float32 bounds on the position error and the normal angle: the rounding of sin and
    cos at the largest phase, M max(a) (max|theta| + 1) 4 eps32 for positions, and the same
    with the slopes a k for the normals' tangents (radians)."""
    k = 2 * np.pi / w["wavelength"]
    reach = np.abs(rest).max() * np.sqrt(2)
    theta = (k * reach + np.sqrt(GRAVITY * k) * max(abs(t) for t in ts) + np.abs(w["phase"])).max()
    m = len(k)
    return m * w["amp"].max() * (theta + 1) * 4 * EPS32, m * (w["amp"] * k).max() * (theta + 1) * 4 * EPS32


def errors(rest, w, ts, q):
    """Largest position error and normal angle over the times `ts` of `ocean` (f32) and
    `ocean64` (f64), through NumPy, against the closed form in float64 of the same inputs
    (the f32 op's inputs rounded to float32 first, so that only its arithmetic is measured)."""
    out = {}
    for name, op, dt in (("ocean (f32)", ws.ocean, np.float32), ("ocean64 (f64)", ws.ocean64, np.float64)):
        ep = ea = 0.0
        for t in ts:
            args = op_args(rest, w, t, dt)
            p, n = op.numpy(*args, q)
            exact = closed_form(np, *(a.astype(np.float64) for a in args[:5]), np.float64(args[5][0]), float(dt(q)))
            ep = max(ep, float(np.abs(p - exact[0]).max()))
            ea = max(ea, float(angle(n.astype(np.float64), exact[1]).max()))
        out[name] = (ep, ea)
    return out


def fd_convergence(w, q, t, sizes):
    """The largest angle between `fd_normals64`'s normals of the displaced grid and the
    analytic ones (`ocean64`), for each grid size in `sizes` (each step half the last)."""
    errs = []
    for n in sizes:
        args = op_args(make_grid(n), w, t, np.float64)
        p, n_exact = ws.ocean64.numpy(*args, q)
        errs.append(float(angle(ws.fd_normals64.numpy(p), n_exact).max()))
    return errs


# The grids of the convergence study, whatever --n is: from 257 points (16 a shortest
# wavelength) on, the ratios are within 0.1 of 4 at every time tried; from 129 they may
# still be 4.6.
FD_SIZES = (257, 513, 1025, 2049)


# ----------------------------------------------------------------------------- pictures


def write_png(path, rgb):
    """An 8-bit RGB PNG of `rgb` (h, w, 3) uint8: signature, IHDR, one zlib IDAT, IEND."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))  # filter type 0 per row

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 6)))
        f.write(chunk(b"IEND", b""))


SUN = np.array([0.4, 1.0, 0.3]) / np.linalg.norm([0.4, 1.0, 0.3])
DEEP, CREST = np.array([10.0, 40.0, 90.0]), np.array([120.0, 200.0, 230.0])


def shade(pos, normal, amp_sum):
    """The height field seen from above (x1 right, x2 down): coloured from deep blue to pale
    crest by height, lit by a fixed sun (Lambert, with some ambient light)."""
    h = np.clip(0.5 + 0.5 * pos[..., 1] / amp_sum, 0, 1)[..., None]
    lit = 0.35 + 0.65 * np.clip((normal * SUN).sum(-1), 0, 1)[..., None]
    rgb = ((1 - h) * DEEP + h * CREST) * lit
    return np.clip(rgb, 0, 255).astype(np.uint8).transpose(1, 0, 2)


def write_svg(path, curves, title):
    """A log-scale line chart of `curves` ({label: values}), written by hand."""
    width, height, pad = 640, 400, 60
    colours = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"]
    allv = np.concatenate([np.asarray(v, dtype=float) for v in curves.values()])
    allv = allv[allv > 0]
    lo, hi = math.floor(math.log10(allv.min())), math.ceil(math.log10(allv.max()))
    steps = max(len(v) for v in curves.values()) - 1
    def sx(k):
        return pad + (width - 2 * pad) * k / max(steps, 1)

    def sy(v):
        return height - pad - (height - 2 * pad) * (math.log10(max(v, 10.0**lo)) - lo) / max(hi - lo, 1)

    out = [
        '<svg xmlns="http://www.w3.org/2000/svg" width="%d" height="%d" font-family="sans-serif" font-size="12">'
        % (width, height),
        '<rect width="100%" height="100%" fill="white"/>',
        '<text x="%d" y="24" font-size="15">%s</text>' % (pad, title),
        '<line x1="%d" y1="%d" x2="%d" y2="%d" stroke="black"/>' % (pad, height - pad, width - pad, height - pad),
        '<line x1="%d" y1="%d" x2="%d" y2="%d" stroke="black"/>' % (pad, pad, pad, height - pad),
        '<text x="%d" y="%d" text-anchor="middle">step</text>' % (width // 2, height - 20),
    ]
    for e in range(lo, hi + 1):
        y = sy(10.0**e)
        out.append('<line x1="%d" y1="%.1f" x2="%d" y2="%.1f" stroke="#ddd"/>' % (pad, y, width - pad, y))
        out.append('<text x="%d" y="%.1f" text-anchor="end">1e%d</text>' % (pad - 6, y + 4, e))
    for k in range(0, steps + 1, max(1, steps // 6)):
        out.append('<text x="%.1f" y="%d" text-anchor="middle">%d</text>' % (sx(k), height - pad + 16, k))
    for c, (label, values) in enumerate(curves.items()):
        pts = " ".join("%.1f,%.1f" % (sx(k), sy(v)) for k, v in enumerate(values))
        out.append('<polyline fill="none" stroke="%s" stroke-width="1.5" points="%s"/>' % (colours[c % 4], pts))
        out.append(
            '<text x="%d" y="%d" fill="%s">%s</text>' % (width - pad - 150, pad + 16 * (c + 1), colours[c % 4], label)
        )
    out.append("</svg>")
    with open(path, "w") as f:
        f.write("\n".join(out) + "\n")


# ----------------------------------------------------------------------------- timing


def median_time(fn, frames, warmup=5):
    """The median seconds of `fn(t)` over `frames` frame times, after `warmup` calls."""
    for k in range(warmup):
        fn(k / FPS)
    ts = []
    for k in range(frames):
        start = time.perf_counter()
        fn(k / FPS)
        ts.append(time.perf_counter() - start)
    return float(np.median(ts))


def timings(rest, w, q, frames, jax):
    """Seconds per frame (positions and normals of the whole grid, float32) of each way."""
    args = op_args(rest, w, 0.0, np.float32)
    rows = []
    if jax is not None:
        import jax.numpy as jnp

        dev_args = [jnp.asarray(a) for a in args[:5]]
        op_jit = jax.jit(lambda r, a, d, l, p, t: ws.ocean.jax(r, a, d, l, p, t, q))
        cf_jit = jax.jit(lambda r, a, d, l, p, t: closed_form(jnp, r, a, d, l, p, t[0], np.float32(q)))

        def run(f):
            return lambda t: jax.block_until_ready(f(*dev_args, jnp.asarray([t], jnp.float32)))

        rows.append(("op ocean, jax.jit (%s)" % jax.devices()[0].platform, median_time(run(op_jit), frames)))
        rows.append(("closed form, jax.numpy under jax.jit", median_time(run(cf_jit), frames)))
    op_np = lambda t: ws.ocean.numpy(*args[:5], np.array([t], np.float32), q)  # noqa: E731
    rows.append(("op ocean, NumPy (CPU)", median_time(op_np, frames)))
    cf_np = lambda t: closed_form(np, *args[:5], np.float32(t), q)  # noqa: E731
    rows.append(("closed form, NumPy (float32)", median_time(cf_np, frames)))
    return rows


# ----------------------------------------------------------------------------- the fit

FIT_TIMES = (0.0, 0.7, 1.4, 2.1)
FIT_Q = 0.3


def fit_problem(n=32, m=8, seed=7):
    """The fit of section 10: `m` waves of known direction, wavelength and phase; their
    amplitudes are the unknowns. Returns (rest, waves, true amplitudes, start)."""
    w = make_waves(m, seed=seed)
    return make_grid(n), w, w["amp"].copy(), 0.5 * w["amp"]


def fit_loss(jax, op, rest, w, targets, dtype, closed=False):
    """The mean squared position error over FIT_TIMES as a function of the amplitudes, through
    `op.jax` (or, with `closed`, the closed form in jax.numpy)."""
    import jax.numpy as jnp

    r, d, lam, ph = (jnp.asarray(w[k] if k != "rest" else rest, dtype) for k in ("rest", "dir", "wavelength", "phase"))
    ts = [jnp.asarray([t], dtype) for t in FIT_TIMES]
    tg = [jnp.asarray(p, dtype) for p in targets]

    def loss(amp):
        total = 0.0
        for t, target in zip(ts, tg):
            if closed:
                p = closed_form(jnp, r, amp, d, lam, ph, t[0], FIT_Q)[0]
            else:
                p = op.jax(r, amp, d, lam, ph, t, FIT_Q)[0]
            total = total + jnp.mean(jnp.sum((p - target) ** 2, axis=-1))
        return total / len(ts)

    return loss


def fit_targets(rest, w):
    return [closed_form(np, rest, w["amp"], w["dir"], w["wavelength"], w["phase"], t, FIT_Q)[0] for t in FIT_TIMES]


def adam(jax, loss, x0, steps=300, lr=0.05, decay=0.97, b1=0.9, b2=0.999, eps=1e-12):
    """Adam in jax.numpy (no optax). The learning rate decays geometrically per step, so that
    the iterate settles instead of hovering at the fixed step's scale (without the decay,
    amplitudes stall near 1e-2 relative). Returns (x, losses)."""
    import jax.numpy as jnp

    vg = jax.jit(jax.value_and_grad(loss))
    x, m, v = jnp.asarray(x0), jnp.zeros_like(x0), jnp.zeros_like(x0)
    losses = []
    for k in range(1, steps + 1):
        f, g = vg(x)
        losses.append(float(f))
        m = b1 * m + (1 - b1) * g
        v = b2 * v + (1 - b2) * g * g
        step = lr * decay**k * (m / (1 - b1**k)) / (jnp.sqrt(v / (1 - b2**k)) + eps)
        x = x - step
    losses.append(float(vg(x)[0]))
    return np.asarray(x), losses


def bfgs(jax, loss, x0):
    """jax.scipy.optimize.minimize's BFGS from `x0`. Returns (x, loss, iterations). The
    gradient tolerance is an option: `tol` does not reach BFGS, whose default gtol (1e-5 on
    this loss of order 1e-2) stops at amplitudes within about 1e-5 relative."""
    from jax.scipy.optimize import minimize

    res = jax.jit(lambda x: minimize(loss, x, method="BFGS", options=dict(gtol=1e-10)))(x0)
    return np.asarray(res.x), float(res.fun), int(res.nit)


def run_fit(jax, out_dir):
    """The fit: the start's gradient against the closed form's, Adam (f64 and f32), BFGS."""
    import jax.numpy as jnp

    rest, w, true, start = fit_problem()
    targets = fit_targets(rest, w)
    loss64 = fit_loss(jax, ws.ocean64, rest, w, targets, jnp.float64)
    loss_cf = fit_loss(jax, None, rest, w, targets, jnp.float64, closed=True)
    g_op = np.asarray(jax.jit(jax.grad(loss64))(jnp.asarray(start)))
    g_cf = np.asarray(jax.jit(jax.grad(loss_cf))(jnp.asarray(start)))
    print("\nfit: %d waves, amplitudes unknown, %d^2 grid, %d times, Q = %g, start at half" % (
        len(true), rest.shape[0], len(FIT_TIMES), FIT_Q))
    print("  gradient at the start vs jax.grad of the jax.numpy closed form: max relative %.2e"
          % (np.abs(g_op - g_cf).max() / np.abs(g_cf).max()))
    t0 = time.perf_counter()
    a64, curve64 = adam(jax, loss64, jnp.asarray(start))
    t_adam = time.perf_counter() - t0
    loss32 = fit_loss(jax, ws.ocean, rest, w, targets, jnp.float32)
    a32, curve32 = adam(jax, loss32, jnp.asarray(start, jnp.float32))
    rel = lambda a: float(np.abs(a - true).max() / np.abs(true).max())  # noqa: E731
    print("  Adam, 300 steps (f64): loss %.3e -> %.3e (fell %.1e), amplitudes within %.1e relative, %.1f s"
          % (curve64[0], curve64[-1], curve64[0] / curve64[-1], rel(a64), t_adam))
    print("  Adam, 300 steps (f32, op ocean): loss %.3e -> %.3e, amplitudes within %.1e relative"
          % (curve32[0], curve32[-1], rel(a32)))
    t0 = time.perf_counter()
    ab, fb, nit = bfgs(jax, loss64, jnp.asarray(start))
    print("  BFGS (f64): %d iterations, loss %.3e, amplitudes within %.1e relative, %.1f s"
          % (nit, fb, rel(ab), time.perf_counter() - t0))
    csv = os.path.join(out_dir, "ocean_fit.csv")
    with open(csv, "w") as f:
        f.write("step,loss_f64,loss_f32\n")
        for k, (a, b) in enumerate(zip(curve64, curve32)):
            f.write("%d,%.17g,%.9g\n" % (k, a, b))
    svg = os.path.join(out_dir, "ocean_fit.svg")
    write_svg(svg, {"Adam, ocean64": curve64, "Adam, ocean (f32)": curve32},
              "Amplitude fit through ws.ocean64.jax: mean squared position error")
    print("  loss curve: %s, %s" % (csv, svg))
    return dict(grad_rel=float(np.abs(g_op - g_cf).max() / np.abs(g_cf).max()), adam_fall=curve64[0] / curve64[-1],
                adam_rel=rel(a64), adam32_rel=rel(a32), bfgs_rel=rel(ab), bfgs_iters=nit)


# ----------------------------------------------------------------------------- main


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--backend", choices=["jax", "numpy"], default="jax", help="what calls the op per frame")
    parser.add_argument("--n", type=int, default=128, help="grid points per side")
    parser.add_argument("--waves", type=int, default=16)
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--steepness", type=float, default=0.6)
    parser.add_argument("--out", default="ocean_out", help="directory for the PNGs (and the fit's CSV and SVG)")
    parser.add_argument("--fit", action="store_true", help="also fit the amplitudes through ocean64 (JAX)")
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)

    jax = None
    try:
        import jax

        jax.config.update("jax_enable_x64", True)
    except ImportError:
        if args.backend == "jax" or args.fit:
            parser.error("--backend jax and --fit need JAX (pip install jax)")
        jax = None

    rest, w, q = make_grid(args.n), make_waves(args.waves), args.steepness
    ts = [k / FPS for k in range(args.frames)]
    print("ocean: %d^2 grid over %g m, %d waves, Q = %g, %d frames, backend %s%s" % (
        args.n, EXTENT, args.waves, q, args.frames, args.backend,
        " (%s)" % jax.devices()[0].platform if jax is not None and args.backend == "jax" else ""))

    # Frames: the f32 op through the chosen framework; every 10th saved.
    if args.backend == "jax":
        import jax.numpy as jnp

        dev_args = [jnp.asarray(a) for a in op_args(rest, w, 0.0, np.float32)[:5]]
        frame_fn = jax.jit(lambda *a: ws.ocean.jax(*a, q))
        frame = lambda t: [np.asarray(x) for x in frame_fn(*dev_args, jnp.asarray([t], jnp.float32))]  # noqa: E731
    else:
        host_args = op_args(rest, w, 0.0, np.float32)[:5]
        frame = lambda t: ws.ocean.numpy(*host_args, np.array([t], np.float32), q)  # noqa: E731
    saved = []
    for k, t in enumerate(ts):
        p, n = frame(t)
        if k % 10 == 0:
            path = os.path.join(args.out, "ocean_%04d.png" % k)
            write_png(path, shade(p, n, w["amp"].sum()))
            saved.append(path)
    print("frames: %d PNGs in %s" % (len(saved), args.out))

    # (a) Error against the closed form (the saved frames' times; NumPy f64).
    b_pos, b_ang = f32_bounds(rest, w, ts)
    print("\nerror against the closed form in NumPy float64 (max over the %d saved frames):" % len(ts[::10]))
    print("  %-14s %14s %14s" % ("op", "max |P - P*|", "max angle (rad)"))
    errs = errors(rest, w, ts[::10], q)
    for name, (ep, ea) in errs.items():
        print("  %-14s %14.3e %14.3e" % (name, ep, ea))
    print("  %-14s %14.3e %14.3e" % ("f32 bound", b_pos, b_ang))
    print("  %-14s %14.3e %14.3e" % ("f64 bound", 1e-12, 1e-12))

    # (b) Finite-difference normals: second order in the grid step.
    sizes = FD_SIZES
    fd = fd_convergence(w, q, ts[-1], sizes)
    print("\nfinite-difference normals (fd_normals64) against the analytic ones (ocean64), t = %.3f s:" % ts[-1])
    for k, (n, e) in enumerate(zip(sizes, fd)):
        ratio = "" if k == 0 else "   ratio %.3f" % (fd[k - 1] / e)
        print("  %5d^2 grid, step %.4f m: max angle %.3e rad%s" % (n, EXTENT / (n - 1), e, ratio))

    # Time per frame.
    print("\ntime per frame (median of %d after 5 warm-up, float32, %d^2 points, %d waves):" % (
        args.frames, args.n, args.waves))
    for label, s in timings(rest, w, q, args.frames, jax):
        print("  %-42s %10.3f ms" % (label, s * 1e3))

    if args.fit:
        run_fit(jax, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
