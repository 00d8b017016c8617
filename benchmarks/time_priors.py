"""Priors that use time differently from TV's first temporal difference, measured before building them.

The TV regularizer of rsocl penalizes ``|(w d_t, d_y, d_x) x|`` with one temporal weight ``w``
for the whole image. This script measures, with the NumPy reference maths (the test oracle:
exact data step, Chambolle's projection, ADMM, start from interp3d), three alternatives on
scenes of ``benchmarks/quality_scenes.py``:

- **a temporal weight that varies over the image**, ``w(y, x)`` large where a pixel moves little.
  The map comes from the ground truth (its mean ``|d_t x|`` per pixel), so the row is an upper
  bound of what any map estimated from the snapshots could reach;
- **second-order temporal smoothness** (a TGV-like term in time): ``|(a d_tt, b d_t, d_y, d_x) x|``,
  which favours intensities that ramp linearly in time over ones that stay constant;
- **a warm-started TV dual**: the dual of the TV projection kept from one ADMM iteration to the
  next, with 2 or 3 Chambolle iterations per ADMM iteration instead of 10 from zero (a third to a
  fifth of the TV work).

PSNR in dB (peak 1), 64x64 paper array, 200 ADMM iterations, ``lam = 0.1``, ``eta = 0.2``. Writes
``docs/time_priors.md``; runs are cached (``--cache``), so an interrupted run resumes.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from case_cache import Cache  # noqa: E402
from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import available, make_scene  # noqa: E402

SCENES = ("builtin", "builtin-fast", "runner40@0.5", "runner40@1", "traffic48@1")
#: Method name -> description for the page. ``tv W``: rsocl's TV maths with temporal weight W.
METHODS = {
    "interp3d": "interp3d (no solver)",
    "tv 1": "TV, temporal weight 1",
    "tv 3": "TV, temporal weight 3",
    "tv 10": "TV, temporal weight 10",
    "map": "TV, temporal weight map from the truth (best uniform weight w0 at the median motion, "
    "w0 * median / (motion + 0.1 median), clipped to [w0/3, 30])",
    "tt 30 0": "second order in time: a = 30, b = 0",
    "tt 3 10": "second order in time: a = 3, b = 10",
    "warm 2": "TV (best uniform weight), dual kept across ADMM iterations, 2 Chambolle iterations",
    "warm 3": "TV (best uniform weight), dual kept across ADMM iterations, 3 Chambolle iterations",
}


def gradient(u, a, b, w):
    """``K u`` of ``K = (a d_tt, b w(y, x) d_t, d_y, d_x)`` (zero where a difference leaves the cube)."""
    g = np.zeros((4,) + u.shape)
    if a:
        g[0, 1:-1] = a * (u[2:] - 2 * u[1:-1] + u[:-2])
    g[1, :-1] = b * w * np.diff(u, axis=0)
    g[2, :, :-1] = np.diff(u, axis=1)
    g[3, :, :, :-1] = np.diff(u, axis=2)
    return g


def gradient_adjoint(p, a, b, w):
    """``K^T p`` for :func:`gradient`'s ``K``."""
    d = np.zeros(p.shape[1:])
    if a:
        q = a * p[0, 1:-1]
        d[2:] += q
        d[1:-1] -= 2 * q
        d[:-2] += q
    q = b * w * p[1, :-1]
    d[:-1] -= q
    d[1:] += q
    d[:, :-1] -= p[2, :, :-1]
    d[:, 1:] += p[2, :, :-1]
    d[:, :, :-1] -= p[3, :, :, :-1]
    d[:, :, 1:] += p[3, :, :, :-1]
    return d


def denoise(image, weight, iterations, a, b, w, p):
    """Chambolle's projection for ``min ½|x - image|² + weight |K x|``, updating the dual ``p`` in place.

    ``iterations`` counts as rsocl's TV does (``iterations - 1`` dual updates, then the primal):
    from ``p = 0`` and with ``a = 0`` this is :func:`rsocl.model.reference.tv_chambolle`.

    The step ``tau = 2 / |K|²`` with ``|K|² <= 16 a² + 4 max(b w)² + 8``: for ``a = 0`` and a
    uniform ``w`` it is scikit-image's step ``1 / (2 (2 + (b w)²))`` (rsocl's TV with ``step=1``).
    """
    tau = 1.0 / (8.0 * a * a + 2.0 * float(np.max(b * w)) ** 2 + 4.0)
    for i in range(iterations):
        out = image + gradient_adjoint(p, a, b, w)
        if i == iterations - 1:
            return out
        g = gradient(out, a, b, w)
        p[:] = (p - tau * g) / (1.0 + np.sqrt((g**2).sum(axis=0)) * (tau / weight))
    return image + gradient_adjoint(p, a, b, w)


def admm(rig, g, x0, *, a=0.0, b=1.0, w=1.0, inner=10, warm=False, iterations=200, lam=0.1, eta=0.2):
    """The reference ADMM of docs/model.md with :func:`denoise` as its prior step; returns theta."""
    from rsocl.model.reference import project

    theta, dual = np.asarray(x0, np.float64).copy(), np.zeros((rig.T,) + rig.shape)
    p = np.zeros((4,) + theta.shape)
    for _ in range(iterations):
        f = project(rig, theta + dual, g, eta)
        if not warm:
            p[:] = 0.0
        theta = denoise(f - dual, lam / eta, inner, a, b, w, p)
        dual -= f - theta
    return theta


def run(scene, method, best_weight=None):
    """PSNR (dB) of ``method`` on ``scene`` (the 64x64 paper array)."""
    import rsocl
    from rsocl.analysis.metrics import psnr
    from rsocl.model.interpolation import interp3d
    from rsocl.model.simulate import simulate

    rig = rsocl.Rig.paper_array(4, (64, 64), t_e=0.18e-3, t_r=35e-6)
    truth = make_scene(scene, rig.shape, rig.T)
    g = simulate(truth, rig)
    x0 = interp3d(g, rig)
    kind, *values = method.split()
    if kind == "interp3d":
        x = x0
    elif kind == "tv":
        x = admm(rig, g, x0, b=float(values[0]))
    elif kind == "map":
        motion = np.mean(np.abs(np.diff(truth, axis=0)), axis=0)
        median = float(np.median(motion[motion > 0])) if np.any(motion > 0) else 1.0
        w = np.clip(best_weight * median / (motion + 0.1 * median), best_weight / 3, 30.0)
        x = admm(rig, g, x0, w=w)
    elif kind == "tt":
        x = admm(rig, g, x0, a=float(values[0]), b=float(values[1]))
    else:  # warm N
        x = admm(rig, g, x0, b=best_weight, inner=int(values[0]), warm=True)
    return psnr(x, truth)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--workers", type=int, default=2, help="processes")
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "rsocl-time-priors.json")
    parser.add_argument("--out", type=Path, default=DOCS / "time_priors.md")
    args = parser.parse_args(argv)
    scenes = [s for s in args.scenes if available(s)]
    done = Cache(args.cache)

    def batch(jobs):
        with ProcessPoolExecutor(args.workers) as pool:
            futures = {key: pool.submit(run, *job) for key, job in jobs.items() if key not in done}
            for key, future in futures.items():
                done.put(key, future.result())
                print(key, f"{done[key]:.2f} dB", flush=True)

    batch({f"{s}|{m}": (s, m) for s in scenes for m in ("interp3d", "tv 1", "tv 3", "tv 10")})
    best = {s: max((1, 3, 10), key=lambda w: done[f"{s}|tv {w}"]) for s in scenes}
    batch({f"{s}|{m}": (s, m, best[s]) for s in scenes for m in METHODS if not m.startswith(("interp", "tv "))})

    page = header_lines(
        "Priors that use time differently: measured before building", None, None if argv is None else [__file__, *argv]
    )
    page += [
        __doc__.split("\n\n", 1)[1].split("\n\nPSNR")[0],
        "",
        "PSNR in dB (peak 1), 64x64 paper array (4 cameras, t_e = 180 µs, t_r = 35 µs), noiseless, "
        "NumPy reference maths (float64), 200 ADMM iterations, lam = 0.1, eta = 0.2, start from interp3d. "
        "Each row's last column: the row's PSNR minus the best of the three uniform TV weights.",
        "",
    ]
    page += [
        "| method | " + " | ".join(scenes) + " | change vs best uniform TV (dB) |",
        "|---|" + "---|" * (len(scenes) + 1),
    ]
    for method, text in METHODS.items():
        values = [done[f"{s}|{method}"] for s in scenes]
        delta = [v - done[f"{s}|tv {best[s]}"] for v, s in zip(values, scenes)]
        change = "" if method.startswith("tv ") else f"{min(delta):+.2f} to {max(delta):+.2f}"
        page.append(f"| {text} | " + " | ".join(f"{v:.2f}" for v in values) + f" | {change} |")
    page += ["", "Best uniform weight per scene: " + ", ".join(f"{s} {best[s]}" for s in scenes) + "."]
    write_page(args.out, page)


if __name__ == "__main__":
    main()
