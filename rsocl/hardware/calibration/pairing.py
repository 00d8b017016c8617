"""Whether markers are paired as a camera can see them: the turning sense of their triangles.

A homography keeps the turning sense (clockwise or not) of every triangle of points on one side
of its horizon, which holds for all the markers a camera sees; a mirror reverses every one.
Markers paired wrongly (two swapped) reverse some triangles and not others, so the pairing is
refused before any homography is fitted to it (four markers would fit exactly, whatever the
pairing). Used by :func:`~rsocl.hardware.calibration.register_camera` and
:mod:`~rsocl.hardware.calibration.plausibility`.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from rsocl.hardware.calibration._common import _points

__all__ = ["flipped_triangles", "check_pairing"]

#: Triangles thinner than this fraction of the markers' extent squared have no reliable turning sense.
_THIN = 1e-2


def _turns(points, triples) -> np.ndarray:
    a, b, c = (points[list(idx)] for idx in zip(*triples))
    u, v = b - a, c - a
    cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    extent = float(np.ptp(points, axis=0).max()) ** 2
    return np.where(np.abs(cross) < _THIN * max(extent, 1e-300), 0.0, np.sign(cross))


def flipped_triangles(reference_points, sensor_points, *, mirrored=False):
    """The marker triangles that turn the other way on the sensor than on the reference.

    Parameters
    ----------
    reference_points, sensor_points : array_like, shape (N, 2)
        The same markers, paired by order, ``(x, y)`` pixels.
    mirrored : bool
        The camera sees the target in a mirror: every triangle is expected to turn the other way.

    Returns
    -------
    (flipped, checked) : (list of (int, int, int), int)
        The triangles (marker indices) that break the expectation, and how many triangles were
        thick enough to check.
    """
    ref = _points("reference_points", reference_points, minimum=3)
    sensor = _points("sensor_points", sensor_points, minimum=3)
    if ref.shape != sensor.shape:
        raise ValueError(
            f"reference_points and sensor_points must hold the same markers, got {len(ref)} and {len(sensor)} points"
        )
    triples = list(combinations(range(len(ref)), 3))
    a, b = _turns(ref, triples), _turns(sensor, triples)
    expected = -1.0 if mirrored else 1.0
    checked = (a != 0) & (b != 0)
    flipped = [t for t, ok, s in zip(triples, checked, a * b) if ok and s != expected]
    return flipped, int(checked.sum())


def _suspects(flipped) -> list:
    """The markers in the most flipped triangles."""
    counts: dict = {}
    for triple in flipped:
        for k in triple:
            counts[k] = counts.get(k, 0) + 1
    top = max(counts.values())
    return sorted(k for k, n in counts.items() if n == top)


def check_pairing(reference_points, sensor_points, *, mirrored=False) -> None:
    """Refuse markers paired as no camera sees them (see the module docstring).

    Parameters
    ----------
    reference_points, sensor_points : array_like, shape (N, 2)
        The same markers, paired by order, ``(x, y)`` pixels.
    mirrored : bool
        The camera sees the target in a mirror (a beam splitter).

    Raises
    ------
    ValueError
        One line naming the markers (index and reference position) whose triangles turn the
        wrong way, or saying that all of them do (a mirror, or its absence).

    Examples
    --------
    >>> ref = [[0, 0], [10, 0], [10, 10], [0, 10]]
    >>> check_pairing(ref, [[0, 0], [10, 0], [0, 10], [10, 10]])
    Traceback (most recent call last):
    ...
    ValueError: markers 2 (10,10) and 3 (0,10) look swapped: ...
    """
    ref = _points("reference_points", reference_points, minimum=3)
    flipped, checked = flipped_triangles(ref, sensor_points, mirrored=mirrored)
    if not flipped:
        return
    if len(flipped) == checked:
        raise ValueError(
            f"every triangle of the {len(ref)} markers turns the other way on the sensor: the "
            + (
                "camera sees the target unmirrored, not in a mirror as --mirrored says"
                if mirrored
                else "camera sees the target mirrored (a beam splitter: give "
                "--mirrored for it), or the markers are listed in the opposite turning sense"
            )
        )
    names = [f"{k} ({ref[k, 0]:g},{ref[k, 1]:g})" for k in _suspects(flipped)]
    who = (
        f"markers {', '.join(names[:-1])} and {names[-1]} look swapped"
        if len(names) > 1
        else f"marker {names[0]} looks misplaced"
    )
    shown = ", ".join(str(t) for t in flipped[:4]) + (", ..." if len(flipped) > 4 else "")
    raise ValueError(
        f"{who}: the marker triangles {shown} turn the other way on the sensor than on the "
        "reference, which no camera does; check the markers' order (--markers-ref, the "
        "'markers' array, --identify)"
    )
