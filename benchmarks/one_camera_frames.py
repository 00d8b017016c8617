"""TV's temporal weight for one camera of several frames: the hold-out search against the one-camera preset.

A rig of one camera that takes ``F`` frames (``frames``, ``t_d``) has ``F`` snapshots per pixel, far apart
in time. The self-tuned default either searches TV's temporal weight with ``lam`` on held-out snapshot
pixels (``searched``: a TV instance whose ``one_snapshot`` is empty, as for a rig of several cameras)
or sets it to the one-camera preset, ``one_snapshot = {"temporal_weight": 10}``, and searches ``lam``
alone (``preset``). Both run the default rung (``balanced``) from the interpolation. Cases: ``F`` = 2, 3
and 5 frames; three geometries (0° on 32x32 with ``t_e = 2.5 t_r``, 90° on 24x40 with ``t_e = 5.14 t_r``,
33° on 32x32 with ``t_e = 2.5 t_r``; ``t_r = dt = 35 µs``, frames ``1.5`` readouts apart); scenes of
``benchmarks/quality_scenes.py`` (the built-in scene at three speeds, Runner and Traffic at 1 frame per
sub-frame where ``../shared/data`` has them), noiseless and with Poisson noise (1000 photo-electrons at full
scale, 1 % read noise). PSNR in dB (peak 1) over the whole datacube, as the difference to ``interp3d``'s.
Writes ``docs/one_camera_frames.md``: the measurement behind ``rsocl.solver.pipeline``'s use of the preset
for every one-camera rig.

    python benchmarks/one_camera_frames.py [--out docs/one_camera_frames.md]
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

import rsocl
from rsocl.analysis.metrics import psnr

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import available, case_data  # noqa: E402

T_R = 35e-6
FRAMES = (2, 3, 5)
#: (angle in degrees, (m, n), t_e in units of t_r)
GEOMETRIES = ((0.0, (32, 32), 2.5), (90.0, (24, 40), 5.14), (33.0, (32, 32), 2.5))
SCENES = ("builtin", "builtin-slow", "builtin-fast", "runner40@1", "traffic48@1")
NOISE = (None, 1000.0)


def one_camera(frames, angle, shape, t_e) -> rsocl.Rig:
    """A rig of one camera taking ``frames`` frames 1.5 readouts apart (``t_e`` in units of ``t_r``)."""
    t_d = (1.5 * max(shape) + 2 + t_e) * T_R
    return rsocl.Rig([rsocl.Camera(angle=angle, t_e=t_e * T_R, t_r=T_R, frames=frames, t_d=t_d)], shape)


def searched_tv():
    """TV at its defaults with no one-camera preset: its temporal weight is searched as for several cameras."""
    from rsocl_plugins.tv import TV

    reg = TV()
    reg.one_snapshot = {}
    return reg


def case(rig, scene, photons) -> tuple:
    """``(interp3d dB, searched - interp3d dB, searched's weight, preset - interp3d dB)`` of one case."""
    truth, g = case_data(scene, rig, photons)
    base = psnr(rsocl.interp3d(g, rig), truth)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        searched = rsocl.reconstruct(g, rig, searched_tv())
        preset = rsocl.reconstruct(g, rig)
    weight = searched.params["tuning"]["chosen"].get("temporal_weight")
    return base, psnr(searched.datacube, truth) - base, weight, psnr(preset.datacube, truth) - base


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(DOCS / "one_camera_frames.md"))
    args = parser.parse_args(argv)
    scenes = [s for s in SCENES if available(s)]
    lines = header_lines("TV's temporal weight for one camera of several frames", argv=argv)
    lines += [
        __doc__.split("\n\n")[1].replace("\n", " "),
        "",
        "| frames | angle | grid | t_e / t_r | scene | noise | interp3d dB | searched (weight) | preset |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    rows = []
    for frames in FRAMES:
        for angle, shape, t_e in GEOMETRIES:
            rig = one_camera(frames, angle, shape, t_e)
            for scene in scenes:
                for photons in NOISE:
                    base, searched, weight, preset = case(rig, scene, photons)
                    rows.append((frames, searched, preset))
                    noise = "none" if photons is None else f"poisson {photons:g}"
                    lines.append(
                        f"| {frames} | {angle:g}° | {shape[0]}x{shape[1]} | {t_e:g} | {scene} | {noise} | {base:.2f} | "
                        f"{searched:+.2f} ({weight:.3g}) | {preset:+.2f} |"
                    )
                    print(lines[-1], flush=True)
    lines += ["", "Per number of frames (dB against interp3d; `below`: cases under interp3d):", ""]
    lines += ["| frames | cases | searched: mean, worst, below | preset: mean, worst, below | preset >= searched |"]
    lines += ["|---|---|---|---|---|"]
    for frames in FRAMES:
        s = np.array([r[1] for r in rows if r[0] == frames])
        p = np.array([r[2] for r in rows if r[0] == frames])
        lines.append(
            f"| {frames} | {len(s)} | {s.mean():+.2f}, {s.min():+.2f}, {int((s < 0).sum())} | "
            f"{p.mean():+.2f}, {p.min():+.2f}, {int((p < 0).sum())} | {int((p >= s - 0.005).sum())} |"
        )
    write_page(args.out, lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
