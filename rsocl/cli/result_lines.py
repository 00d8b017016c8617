"""The lines the ``rsocl`` subcommands print about a result: its quality against a ground truth and its
iterations' and search's times."""

from __future__ import annotations

import math

__all__ = ["truth_quality", "quality_line"]


def truth_quality(datacube, truth) -> str:
    """``PSNR .. dB, SSIM ..`` of ``datacube`` against the ground truth ``truth`` (both ``(T, m, n)``)."""
    from rsocl.analysis.metrics import psnr, ssim

    mean_ssim, _ = ssim(datacube, truth)
    shown = f"{mean_ssim:.3f}" if math.isfinite(mean_ssim) else "n/a (frames under 3 pixels a side)"
    return f"PSNR {psnr(datacube, truth):.2f} dB, SSIM {shown}"


def quality_line(result, truth):
    """``PSNR .. dB, SSIM .., N iterations in X s (search Y s of Z s total)`` (PSNR and SSIM only with a
    truth: :func:`truth_quality`): X the iterations' wall time, Y the search's, Z the whole run's."""
    import numpy as np

    seconds = float(np.nanmax(result.history["time"][-1]))
    total = result.seconds if result.seconds is not None else seconds
    search = result.search_seconds or 0.0
    text = f"{result.iterations} iterations in {seconds:.2f} s (search {search:.2f} s of {total:.2f} s total)"
    if truth is not None:
        text = f"{truth_quality(result.datacube, truth)}, " + text
    return text
