"""A multi-frame capture (cameras with ``frames`` > 1, period ``t_d``) as a stream of overlapping time windows.

Window ``w`` holds frames ``k0 .. k0 + window - 1`` of every camera (``k0 = w * (window - overlap)``):
its rig (:meth:`rsocl.model.rig.Rig.frames_window`) is the capture's rig with each camera's trigger
offset moved to ``t_a + k0*t_d`` and ``window`` frames, so every exposure keeps its absolute start
``t_a + r*t_r + k*t_d`` and the window's sub-frames are those of the whole capture (time 0 is the
same). Each window is an
ordinary (tiled) reconstruction that models only the sub-frames its exposures touch
(:meth:`rsocl.model.rig.Rig.sampled_range`), so the device memory of a window does not grow with the
length of the capture; the host holds the assembled datacube, one window's result on the capture's
grid while it is placed, and each window's own sub-frames. Where windows overlap (readout
continuous: ``t_d`` close to the readout time, so consecutive frames' exposures abut), each
sub-frame is taken from the window
it lies deepest inside (farthest from that window's first and last modelled sub-frame), where
both neighbouring frames constrain it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rsocl.common import validation as check
from rsocl.model.rig import Rig

__all__ = ["default_overlap", "frame_windows", "window_channels", "reconstruct_stream", "StreamResult"]


def _frames(rig: Rig) -> int:
    counts = {cam.frames for cam in rig.cameras}
    if len(counts) != 1:
        raise ValueError(
            f"rig: every camera must capture the same number of frames for a stream, got "
            f"{[cam.frames for cam in rig.cameras]}"
        )
    return counts.pop()


def default_overlap(window: int) -> int:
    """Frames consecutive windows of ``window`` frames share by default: 1, or 0 for windows of one frame."""
    return min(1, int(window) - 1)


def frame_windows(frames: int, window=None, overlap=None) -> list:
    """``[(k0, k1), ...]``: frames ``k0..k1-1`` of each window, covering ``0..frames-1``.

    ``1 <= window <= frames`` and ``0 <= overlap < window`` (ValueErrors name them); the last
    window ends at the last frame (it may overlap its neighbour by more). Defaults: ``window``
    2 frames (1 for a capture of one frame), ``overlap`` 1 frame (0 for windows of one frame).
    """
    window = min(2, int(frames)) if window is None else check.positive_int("window", window, maximum=frames)
    overlap = default_overlap(window) if overlap is None else overlap
    try:
        ok = int(overlap) == float(overlap) and 0 <= int(overlap) < window
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"overlap must be a whole number of frames in [0, window - 1 = {window - 1}], got {overlap!r}")
    step = window - int(overlap)
    starts = list(range(0, max(frames - window, 0) + 1, step))
    if starts[-1] + window < frames:
        starts.append(frames - window)
    return [(k0, k0 + window) for k0 in starts]


def window_channels(rig: Rig, k0: int, k1: int) -> list:
    """Indices of the snapshots (camera-major channels) of frames ``k0..k1-1``."""
    return [i for i, (_, k) in enumerate(rig.channels) if k0 <= k < k1]


@dataclass
class StreamResult:
    """A stream: ``datacube`` ``(T, m, n)`` on the capture's sub-frame grid; ``windows`` ``[(k0, k1)]``;
    ``spans`` the sub-frames each window modelled; ``owner[s]`` the window sub-frame ``s`` comes from
    (where no exposure reaches, the window with the nearest modelled sub-frame, which it holds:
    :mod:`rsocl.solver.held`); ``results`` each window's :class:`rsocl.scale.TiledResult`, whose
    ``datacube`` holds the sub-frames ``spans[w]`` it modelled (so the results together take about the
    memory of ``datacube``, not of every window's grid from time 0); ``params`` the stream's: the first
    window's settings (every window runs with them), with the capture's ``solved_subframes`` (the
    windows' spans together) and ``saturated_pixels`` (snapshot pixels of the whole capture at or above
    ``saturation``)."""

    datacube: np.ndarray
    rig: Rig
    windows: list
    spans: list
    owner: np.ndarray
    results: list = field(default_factory=list)
    params: dict = field(default_factory=dict)


def reconstruct_stream(snapshots, rig: Rig, *, window=None, overlap=None, tile=None, progress=False, **kwargs):
    """Reconstruct a multi-frame capture window by window (each window tiled and run as Dask tasks).

    Parameters
    ----------
    snapshots : array_like, shape (K, m, n)
        Every camera's frames, camera-major (``rig.channels``).
    rig : Rig
        Cameras with the same ``frames`` (>= 1) each.
    window : int or None
        Frames per window, ``1..frames`` (None: 2, or 1 for a capture of one frame).
    overlap : int or None
        Frames shared by consecutive windows, ``0..window-1`` (1 when the readout is continuous;
        None: 1, or 0 for windows of one frame).
    tile : (int, int) or None
        Tile of each window (None: the whole grid, one task per window).
    **kwargs
        As :func:`rsocl.scale.reconstruct_tiled` (``halo``, ``iterations``, ``scheduler``,
        ``tune``, ...), except ``out``: the windows are assembled in memory and no Zarr store
        is written (save ``StreamResult.datacube``, e.g. with
        :func:`rsocl.files.hdf5.save_reconstruction`). With ``tune`` (the default) the first
        window chooses the unset parameters and every later window runs with that choice (one
        capture, one setting).
    """
    from rsocl.scale.tiled import reconstruct_tiled

    if kwargs.get("out") is not None:
        raise ValueError(
            f"out: a stream of frame windows is assembled in memory (StreamResult.datacube) and "
            f"writes no Zarr store, got out={kwargs['out']!r}; leave out out and save the result "
            f"(e.g. rsocl.files.hdf5.save_reconstruction)"
        )
    if not isinstance(rig, Rig):
        raise ValueError(f"rig must be an rsocl.Rig, got {type(rig).__name__}")
    g = check.finite_array("g", snapshots)
    if g.shape != (rig.n_channels,) + rig.shape:
        raise ValueError(f"g must have shape (K, m, n) = {(rig.n_channels,) + rig.shape}, got {g.shape}")
    windows = frame_windows(_frames(rig), window, overlap)
    rigs = [rig.frames_window(k0, k1) for k0, k1 in windows]
    spans = [r.sampled_range() for r in rigs]
    T = rig.T
    s = np.arange(T)
    depth = np.stack([np.minimum(s - span.start, span.stop - 1 - s) for span in spans])  # < 0 outside a span
    owner = depth.argmax(axis=0)
    tile = rig.shape if tile is None else tile
    datacube: np.ndarray | None = None
    results: list = []
    for w, ((k0, k1), sub) in enumerate(zip(windows, rigs)):
        if progress:
            print(
                f"window {w + 1}/{len(windows)}: frames {k0}..{k1 - 1}, sub-frames {spans[w].start}.."
                f"{spans[w].stop - 1}",
                flush=True,
            )
        result = reconstruct_tiled(g[window_channels(rig, k0, k1)], sub, tile=tile, progress=progress, **kwargs)
        if not results and result.tuning is not None:
            kwargs["tune"] = result.tuning  # the first window's choice, for every later window
        elif not results:
            kwargs["tune"] = False  # nothing was left to choose
        cube = np.asarray(result.datacube)
        if datacube is None:
            datacube = np.zeros((T,) + rig.shape, dtype=cube.dtype)
        mine = np.nonzero(owner == w)[0]
        datacube[mine] = cube[np.minimum(mine, cube.shape[0] - 1)]  # past the window's T: its last, held
        result.datacube = cube[spans[w]].copy()  # kept: its own sub-frames, not the capture's up to its end
        del cube
        results.append(result)
    assert datacube is not None  # frame_windows gives at least one window
    saturation = kwargs.get("saturation")
    params = dict(
        results[0].params,
        solved_subframes=[min(span.start for span in spans), max(span.stop for span in spans)],
        saturated_pixels=0 if saturation is None else int(np.count_nonzero(g >= saturation)),
    )
    return StreamResult(datacube, rig, windows, [(s.start, s.stop) for s in spans], owner, results, params)
