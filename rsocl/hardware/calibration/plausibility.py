"""Whether a registration is one a camera can have: marker pairing, orientation, distortion, fit check.

Four markers fit a homography *exactly*, whatever their pairing: the reprojection error is then
always 0 and checks nothing. What does tell a wrong pairing from a right one is geometry that
no camera viewing a flat target changes:

* **orientation** (:mod:`~rsocl.hardware.calibration.pairing`): a homography keeps the turning
  sense of every triangle of markers a camera sees; a mirror reverses all of them. Two markers
  swapped reverse some triangles and not others;
* **rotation**: markers paired a cyclic shift apart fit a camera turned by their spacing; only
  the rig file's nominal angle tells it apart, so the measured rotation must stay near it;
* **distortion**: a camera in front of a flat target stretches the reference grid about evenly.
  A wrong pairing fitted exactly needs a strong perspective: the local scale changes by large
  factors across the grid, or one direction is stretched far more than the other.

With five or more markers the fit is over-determined. Its residuals give the homography's error over
the reference grid (:func:`grid_error`: the markers' scatter carried through the fit to the grid, to
first order). The leave-one-out error (each marker predicted by the homography of the others) points at
a misplaced marker, but its size depends on how far the others extrapolate to the marker left out: with
five markers, four fitted exactly amplify their detection errors many times (measured: 14 to 180 times
the grid's rms error, against 2 to 9 times with six or nine markers). The fit is judged by its rms
reprojection error (:func:`check_fit`): detected markers are placed to a small fraction of a pixel
(docs/implementation_notes.md), a wrong pairing is off by pixels. :func:`pairing_alternatives` then
says which other pairing fits (a mirror image, an order that starts at another marker).
"""

from __future__ import annotations

import numpy as np

from rsocl.hardware.calibration._common import _homography, _points, _shape
from rsocl.hardware.calibration.pairing import check_pairing, flipped_triangles

__all__ = [
    "MAX_SCALE_RATIO",
    "MAX_ANISOTROPY",
    "MAX_TURN",
    "flipped_triangles",
    "check_pairing",
    "check_registration",
    "check_rotation",
    "leave_one_out_errors",
    "grid_error",
    "fit_summary",
    "MAX_RMS",
    "check_fit",
    "pairing_alternatives",
    "fit_refusal",
    "pairing_hint",
]

#: Largest rms reprojection error, sensor pixels, of a fit of five or more markers: several times what
#: the centroids of :func:`~rsocl.hardware.calibration.detect_markers` allow, well below a wrong pairing's.
MAX_RMS = 1.0

#: Largest ratio of the local scale (sensor pixels per reference pixel) between two corners of the grid.
MAX_SCALE_RATIO = 3.0
#: Largest ratio of the stretch along two directions at one point of the grid.
MAX_ANISOTROPY = 3.0
#: Largest difference, degrees, between the measured rotation and the rig file's nominal one.
MAX_TURN = 45.0


def _jacobians(H, points) -> np.ndarray:
    """``(N, 2, 2)`` derivative of the homography's map at ``points``."""
    q = np.column_stack([points, np.ones(len(points))]) @ H.T
    w = q[:, 2]
    image = q[:, :2] / w[:, None]
    return (H[None, :2, :2] - image[:, :, None] * H[None, 2:3, :2]) / w[:, None, None]


def check_registration(reference_points, sensor_points, H, shape, *, mirrored=False) -> None:
    """Refuse a registration no camera can have (see the module docstring).

    Parameters
    ----------
    reference_points, sensor_points : array_like, shape (N, 2)
        The markers, paired by order, ``(x, y)`` pixels (N >= 4).
    H : array_like, shape (3, 3)
        The homography fitted to them, reference -> sensor.
    shape : (int, int)
        ``(m, n)`` of the reference grid, pixels.
    mirrored : bool
        The camera sees the target in a mirror (a beam splitter).

    Raises
    ------
    ValueError
        One line naming the markers whose triangles turn the wrong way (a wrong pairing, or a
        mirror), or the distortion (scale ratio across the grid, anisotropy) and its limit.

    Examples
    --------
    >>> ref = [[0, 0], [10, 0], [10, 10], [0, 10]]
    >>> check_registration(ref, [[0, 0], [50, 0], [50, 10], [0, 10]], np.diag([5.0, 1, 1]), (11, 11))
    Traceback (most recent call last):
    ...
    ValueError: the homography stretches the grid 5.0x more along one direction than the other ...
    """
    ref = _points("reference_points", reference_points, minimum=4)
    sensor = _points("sensor_points", sensor_points, minimum=4)
    H = _homography("H", H)
    m, n = _shape(shape)
    check_pairing(ref, sensor, mirrored=mirrored)
    corners = np.array([[0, 0], [n - 1, 0], [n - 1, m - 1], [0, m - 1], [(n - 1) / 2, (m - 1) / 2]], float)
    singular = np.linalg.svd(_jacobians(H, corners), compute_uv=False)
    scale = np.sqrt(singular[:, 0] * singular[:, 1])
    ratio = float(scale.max() / max(scale.min(), 1e-300))
    if ratio > MAX_SCALE_RATIO:
        raise ValueError(
            f"the homography magnifies one corner of the grid {ratio:.1f}x as much as another "
            f"(at most {MAX_SCALE_RATIO:g} for a camera facing a flat target): the markers are "
            "probably paired wrongly; check their order (--markers-ref, the 'markers' array)"
        )
    stretch = float((singular[:, 0] / np.maximum(singular[:, 1], 1e-300)).max())
    if stretch > MAX_ANISOTROPY:
        raise ValueError(
            f"the homography stretches the grid {stretch:.1f}x more along one direction than "
            f"the other (at most {MAX_ANISOTROPY:g} for a camera facing a flat target): the markers "
            "are probably paired wrongly; check their order (--markers-ref, the 'markers' array)"
        )


def check_rotation(H, shape, nominal, *, key="angle", limit=MAX_TURN) -> float:
    """The rotation of ``H`` (degrees, the turn nearest ``nominal``); a ValueError naming ``key`` when it is
    more than ``limit`` degrees from the ``nominal`` one: markers paired a cyclic shift apart fit a camera
    turned by a multiple of their spacing, which only the rig file's nominal angle tells apart."""
    from rsocl.hardware.calibration.homography import homography_angle

    turn = (homography_angle(H, shape) - nominal + 180.0) % 360.0 - 180.0
    if abs(turn) > limit:
        raise ValueError(
            f"the markers give a rotation of {nominal + turn:.1f}°, {abs(turn):.0f}° from the rig "
            f"file's {key} = {nominal:g}° (at most {limit:g}°): the markers are paired a turn apart (their "
            f"order shifted), or {key} is wrong; check the markers' order or correct {key}"
        )
    return nominal + turn


def leave_one_out_errors(reference_points, sensor_points):
    """Each marker's distance, sensor pixels, from where the homography of the *other* markers puts it.

    ``(N,)`` float64 for ``N >= 5`` markers, NaN for a marker whose others cannot fit one (three of
    four on a line: the centre of a square's corners, left out with a corner); None for 4 (the others
    are too few to fit).
    """
    from rsocl.hardware.calibration.homography import estimate_homography, project_points

    ref = _points("reference_points", reference_points, minimum=4)
    sensor = _points("sensor_points", sensor_points, minimum=4)
    if len(ref) < 5:
        return None
    out = np.empty(len(ref))
    for k in range(len(ref)):
        keep = np.arange(len(ref)) != k
        try:
            H = estimate_homography(ref[keep], sensor[keep])
        except ValueError:  # the others are degenerate: this marker cannot be checked
            out[k] = np.nan
            continue
        out[k] = float(np.hypot(*(project_points(H, ref[k : k + 1])[0] - sensor[k])))
    return out


def _parameter_jacobians(H, points) -> np.ndarray:
    """``(2N, 8)`` derivative of the mapped ``points`` (every x, then every y) by ``H``'s entries but ``H[2, 2]``."""
    x, y = points[:, 0], points[:, 1]
    q = np.column_stack([points, np.ones(len(points))]) @ H.T
    w = q[:, 2]
    X, Y = q[:, 0] / w, q[:, 1] / w
    zero, one = np.zeros_like(x), np.ones_like(x)
    dX = np.column_stack([x, y, one, zero, zero, zero, -X * x, -X * y]) / w[:, None]
    dY = np.column_stack([zero, zero, zero, x, y, one, -Y * x, -Y * y]) / w[:, None]
    return np.vstack([dX, dY])


def grid_error(reference_points, sensor_points, H, shape, *, lattice=33):
    """The homography's error over the reference grid, estimated from the residuals of its markers.

    The markers' scatter per coordinate, ``sigma**2 = sum(residual**2) / (2 N - 8)`` (sensor pixels), is
    carried through the least-squares fit of ``H``'s eight parameters to where ``H`` maps a lattice of
    ``lattice x lattice`` reference points spanning the grid (first order). Synthetic cameras (disc markers
    through known homographies, blur, noise) put it at 0.23 to 2.1 times the true rms error for five
    markers (two degrees of freedom; median 0.94) and 0.5 to 2.4 times for six or nine (5 % and 95 %
    points of 60 cameras each).

    Parameters
    ----------
    reference_points, sensor_points : array_like, shape (N, 2)
        The markers, paired by order, ``(x, y)`` pixels.
    H : array_like, shape (3, 3)
        The homography fitted to them, reference -> sensor.
    shape : (int, int)
        ``(m, n)`` of the reference grid, pixels.
    lattice : int
        Points per side of the lattice the rms is taken over.

    Returns
    -------
    float or None
        The rms over the grid of the expected distance, sensor pixels, between where ``H`` and the true
        homography map a reference point; None for four markers (they leave no residual).
    """
    ref = _points("reference_points", reference_points, minimum=4)
    sensor = _points("sensor_points", sensor_points, minimum=4)
    H = _homography("H", H)
    H = H / H[2, 2]
    m, n = _shape(shape)
    N = len(ref)
    if N < 5:
        return None
    q = np.column_stack([ref, np.ones(N)]) @ H.T
    sigma2 = float(np.sum((q[:, :2] / q[:, 2:] - sensor) ** 2)) / (2 * N - 8)
    markers = _parameter_jacobians(H, ref)
    scale = np.linalg.norm(markers, axis=0)
    scale[scale == 0] = 1.0
    x, y = np.meshgrid(np.linspace(0, n - 1, lattice), np.linspace(0, m - 1, lattice))
    grid = _parameter_jacobians(H, np.column_stack([x.ravel(), y.ravel()]))
    spread = (grid / scale) @ np.linalg.pinv(markers / scale)  # how each marker coordinate moves the grid
    return float(np.sqrt(sigma2 * np.sum(spread**2) / x.size))


def fit_summary(registration, shape=None) -> str:
    """What the markers say about a :class:`~rsocl.hardware.calibration.CameraRegistration`'s fit.

    Four markers: that they fit exactly and cannot check it (nor a mirror image, on a target with a
    mirror symmetry). Five or more: the rms reprojection error, the homography's error over a reference
    grid of ``shape`` ``(m, n)`` when given (:func:`grid_error`), and the largest leave-one-out error
    (one misplaced marker raises every marker's, since the homography of the others includes it).
    """
    N = len(registration.reference_points)
    loo = leave_one_out_errors(registration.reference_points, registration.sensor_points)
    if loo is None:
        return (
            f"{N} markers fit a homography exactly, so they cannot check it (no rms), nor, on a target as "
            "symmetric as a rectangle, whether the camera sees it in a mirror (--mirrored); 5 or more markers "
            "give a leave-one-out check"
        )
    fit = f"{N} markers: rms reprojection {registration.rms_error:.3f} px"
    if shape is not None:
        error = grid_error(registration.reference_points, registration.sensor_points, registration.homography, shape)
        fit += f", so the homography is off by about {error:.3f} px rms over the grid ({2 * N - 8} degrees of freedom)"
    unchecked = np.flatnonzero(np.isnan(loo)).tolist()
    if len(unchecked) == N:
        return fit + "; no leave-one-out check (the others of every marker have three on a line)"
    note = f" (markers {unchecked} not checked: their others have three on a line)" if unchecked else ""
    return (
        f"{fit}; leave-one-out largest {float(np.nanmax(loo)):.3f} px{note}, each marker from the homography "
        f"of the other {N - 1} (an extrapolation, larger than the error over the grid)"
    )


def check_fit(registration, *, limit=MAX_RMS):
    """The rms reprojection error of a registration of five or more markers when it exceeds ``limit``.

    Parameters
    ----------
    registration : CameraRegistration
        The fit (:func:`~rsocl.hardware.calibration.register_camera`).
    limit : float
        Largest rms reprojection error, sensor pixels (default :data:`MAX_RMS`).

    Returns
    -------
    float or None
        The rms error (sensor pixels) of a fit above ``limit``; None for a fit within it, and for four
        markers (they fit exactly and cannot check it).
    """
    if len(registration.reference_points) < 5:
        return None
    rms = registration.rms_error
    return rms if rms > limit else None


def pairing_alternatives(reference_points, sensor_points):
    """The other pairings of markers ordered around their centre, best fit first.

    The markers of :func:`~rsocl.hardware.calibration.detect_markers` come in a cyclic order; a wrong
    start (a turn) or a wrong sense (a mirror) pairs them wrongly. This fits every start in both senses.

    Parameters
    ----------
    reference_points, sensor_points : array_like, shape (N, 2)
        The markers as paired, ``(x, y)`` pixels, N >= 5.

    Returns
    -------
    list of (float, bool, int, ndarray)
        ``(rms, reversed, start, H)``: the rms reprojection error (sensor pixels) of the homography
        ``H`` fitted to ``sensor_points[order]``, whether ``order`` turns the other way
        (``[start, start - 1, ...]``) or the same way (``[start, start + 1, ...]``), sorted by rms;
        the pairing as given (``start`` 0, same way) is left out.
    """
    from rsocl.hardware.calibration.homography import estimate_homography, reprojection_error

    ref = _points("reference_points", reference_points, minimum=5)
    sensor = _points("sensor_points", sensor_points, minimum=5)
    N = len(ref)
    out = []
    for turned in (False, True):
        for start in range(N):
            if not turned and start == 0:
                continue
            order = (start - np.arange(N)) % N if turned else (start + np.arange(N)) % N
            try:
                H = estimate_homography(ref, sensor[order])
                rms = float(np.sqrt(np.mean(reprojection_error(H, ref, sensor[order]) ** 2)))
            except ValueError:  # a degenerate pairing: no homography
                continue
            out.append((rms, turned, start, H))
    return sorted(out, key=lambda item: item[0])


def fit_refusal(registration, rms, shape, *, camera, key="angle", mirrored=False, limit=MAX_RMS) -> str:
    """One line on a fit whose rms error ``rms`` (sensor pixels) exceeds ``limit``, naming the pairing that
    fits instead (:func:`pairing_hint`) and the options of ``rsocl calibrate`` that give it.

    ``camera`` is the camera's index, ``key`` the rig file key that states its rotation (``angle`` or
    ``homography``), ``mirrored`` whether ``--mirrored`` names it, ``shape`` the reference grid ``(m, n)``.
    """
    text = (
        f"the markers fit a homography with rms reprojection {rms:.3f} px, more than {limit:g} px (detected "
        "markers are placed to a fraction of a pixel): they are paired wrongly, or the target is not flat"
    )
    hint = pairing_hint(
        registration.reference_points, registration.sensor_points, shape, camera=camera, key=key, mirrored=mirrored
    )
    return text + (hint or "; check the markers' order (--markers-ref, the 'markers' array, --identify)")


def pairing_hint(reference_points, sensor_points, shape, *, camera, key="angle", mirrored=False, limit=MAX_RMS):
    """``"; they fit a mirror image (...): give --mirrored C ..."``: the pairing of five or more markers in
    cyclic order that fits within ``limit`` (sensor pixels) instead, and the options that give it; None
    when none does (arguments as :func:`fit_refusal`'s)."""
    from rsocl.hardware.calibration.homography import estimate_homography, homography_angle, reprojection_error

    if len(reference_points) < 5:
        return None
    alternatives = pairing_alternatives(reference_points, sensor_points)
    try:
        H0 = estimate_homography(reference_points, sensor_points)
        given = float(np.sqrt(np.mean(reprojection_error(H0, reference_points, sensor_points) ** 2)))
    except ValueError:  # the pairing as given fits no homography
        given = float("inf")
    if not alternatives or alternatives[0][0] > min(limit, given / 2):
        return None
    best, turned, _, H = alternatives[0]
    angle = homography_angle(H, shape)
    fits = f"rms {best:.3f} px, rotation {angle:.0f}°"
    if turned and not mirrored:
        return (
            f"; they fit a mirror image ({fits}): camera {camera} sees the target mirrored: give --mirrored "
            f"{camera}, with camera[{camera}].angle = {angle:.0f} (it starts the markers' order) or --identify largest"
        )
    if turned:
        return f"; they fit unmirrored ({fits}): camera {camera} sees no mirror; leave it out of --mirrored"
    return (
        f"; they fit in an order that starts at another marker ({fits}): the rig file's camera[{camera}].{key} "
        f"starts the order; give camera[{camera}].angle = {angle:.0f}, or --identify largest"
    )
