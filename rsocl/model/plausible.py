"""Plausibility of a rig before it is built: times in the right unit, sizes that fit this machine.

Times in rsocl are seconds. An exposure above :data:`T_E_PLAUSIBLE` or a row time above
:data:`T_R_PLAUSIBLE` is far outside what rolling-shutter sensors do and most often a value in µs
given as seconds: it gets a one-line warning naming the parameter. An exposure spanning more than
:data:`MAX_WINDOW` sub-frames is refused (every kernel loops over an exposure's sub-frames for
each pixel). A rig whose own arrays (row maps, exposure windows: :data:`RIG_BYTES_PER_PIXEL` per
camera and pixel) exceed the host memory is refused before they are allocated
(:func:`rsocl.common.memory.check_host_memory`, the one host-memory check).
"""

from __future__ import annotations

import math
import warnings

from rsocl.common.memory import check_host_memory

__all__ = [
    "T_E_PLAUSIBLE",
    "T_R_PLAUSIBLE",
    "MAX_WINDOW",
    "check_window_us",
    "RIG_BYTES_PER_PIXEL",
    "warn_unlikely_times",
    "warn_unlikely_times_us",
    "FLOAT32_SCALES",
    "warn_float32_scale",
    "check_window",
    "check_rig_memory",
]

#: Longest exposure ``t_e`` (seconds) taken without a warning.
T_E_PLAUSIBLE = 1.0
#: Longest row readout time ``t_r`` (seconds) taken without a warning.
T_R_PLAUSIBLE = 1e-3
#: Most sub-frames one exposure may span, ``t_e / dt``.
MAX_WINDOW = 2**20
#: Host bytes a :class:`~rsocl.model.rig.Rig` keeps per camera and reference pixel: its row map
#: (float64) and exposure windows (int32 index, float64 fraction).
RIG_BYTES_PER_PIXEL = 20


#: Longest trigger offset ``t_a`` and frame period ``t_d`` (seconds) taken without a warning: each adds
#: ``t / dt`` sub-frames to the datacube.
T_A_PLAUSIBLE = T_D_PLAUSIBLE = 1.0
#: The shortest ``t_e``, ``t_r``, ``t_a``, ``t_d`` (seconds) a reading of an implausible value in µs or ms may give.
SHORTEST = {"t_e": 1e-6, "t_r": 1e-7, "t_a": 0.0, "t_d": 1e-4}


def _in_us(name: str, seconds: float) -> str:
    """``"did you mean 180 µs (t_e=0.00018)?"``: the value read in µs, or else in ms, whichever lands in the
    plausible range of ``name`` (``t_r = 0.035``: 35 µs given in ms); ``""`` where neither does."""
    highest = {"t_e": T_E_PLAUSIBLE, "t_r": T_R_PLAUSIBLE, "t_a": T_A_PLAUSIBLE, "t_d": T_D_PLAUSIBLE}[name]
    for unit, factor in (("µs", 1e-6), ("ms", 1e-3)):
        if SHORTEST[name] <= seconds * factor <= highest:
            return f": did you mean {seconds:g} {unit} ({name}={seconds * factor:g})?"
    return ""


def warn_unlikely_times(name: str, t_e: float, t_r: float, t_a: float = 0.0, t_d: float | None = None) -> None:
    """Warn (``UserWarning``, one line naming ``name.t_e``, ``.t_r``, ``.t_a`` or ``.t_d``) when ``t_e`` (seconds)
    is above :data:`T_E_PLAUSIBLE`, ``t_r`` above :data:`T_R_PLAUSIBLE`, the trigger offset ``t_a`` above
    :data:`T_A_PLAUSIBLE` or the frame period ``t_d`` above :data:`T_D_PLAUSIBLE`.

    Examples
    --------
    >>> warn_unlikely_times("camera", 180.0, 35e-6)     # doctest: +SKIP
    UserWarning: camera t_e = 180 s is longer than 1 s; times are in seconds: did you mean 180 µs (t_e=0.00018)?
    """
    said = (
        ("t_e", t_e, T_E_PLAUSIBLE, f"{T_E_PLAUSIBLE:g} s"),
        ("t_r", t_r, T_R_PLAUSIBLE, f"{T_R_PLAUSIBLE * 1e3:g} ms per row"),
        ("t_a", t_a, T_A_PLAUSIBLE, f"{T_A_PLAUSIBLE:g} s (the trigger offset)"),
        ("t_d", t_d, T_D_PLAUSIBLE, f"{T_D_PLAUSIBLE:g} s (the frame period)"),
    )
    for key, value, highest, words in said:
        if value is not None and value > highest:
            warnings.warn(
                f"{name} {key} = {value:g} s is longer than {words}; times are in seconds{_in_us(key, value)}",
                UserWarning,
                stacklevel=3,
            )


def warn_unlikely_times_us(t_e_us: float, t_r_us: float) -> bool:
    """:func:`warn_unlikely_times` for the command line's ``--t-e-us`` and ``--t-r-us`` (µs): one line naming
    the option, in µs. Returns whether it warned (the rig's cameras, in seconds, would then say it again).

    Examples
    --------
    >>> warn_unlikely_times_us(180.0, 5000.0)     # doctest: +SKIP
    UserWarning: --t-r-us 5000 µs is 5 ms per row, longer than 1 ms: a rolling-shutter sensor reads a row in µs
    """
    said = False
    if t_e_us > T_E_PLAUSIBLE * 1e6:
        warnings.warn(
            f"--t-e-us {t_e_us:g} µs is {t_e_us * 1e-6:g} s, longer than {T_E_PLAUSIBLE:g} s: is it the exposure "
            "in µs?",
            UserWarning,
            stacklevel=3,
        )
        said = True
    if t_r_us > T_R_PLAUSIBLE * 1e6:
        warnings.warn(
            f"--t-r-us {t_r_us:g} µs is {t_r_us * 1e-3:g} ms per row, longer than {T_R_PLAUSIBLE * 1e3:g} ms: "
            "a rolling-shutter sensor reads a row in µs",
            UserWarning,
            stacklevel=3,
        )
        said = True
    return said


#: ``(low, high)``: the largest snapshot magnitude float32 runs without a warning: beyond it the squares
#: the solver forms (TV's gradient norms) overflow or flush to zero. float64 holds 1e-30 to 1e19 and beyond.
FLOAT32_SCALES = (1e-15, 1e17)


def warn_float32_scale(g, dtype) -> None:
    """Warn (``UserWarning``, one line) when a float32 run's snapshots ``g`` peak outside :data:`FLOAT32_SCALES`."""
    import numpy as np

    if np.dtype(dtype) != np.float32:
        return
    peak = float(np.max(np.abs(g))) if np.size(g) else 0.0
    low, high = FLOAT32_SCALES
    if peak > high or 0.0 < peak < low:
        warnings.warn(
            f"g: the snapshots' largest magnitude {peak:.3g} is outside [{low:g}, {high:g}], where float32 "
            "holds the squares the solver forms (TV's gradient norms overflow or flush to 0): use "
            "dtype='float64' (--dtype float64), or scale g and lam toward data in [0, 1]",
            UserWarning,
            stacklevel=5,
        )


def check_window(name: str, t_e: float, dt: float) -> None:
    """Refuse an exposure ``t_e`` (seconds) of more than :data:`MAX_WINDOW` sub-frames of ``dt``, naming ``name``."""
    span = t_e / dt
    if span > MAX_WINDOW:
        key = name.rsplit(".", 1)[-1]
        hint = _in_us(key if key in SHORTEST else "t_e", t_e) if t_e > T_E_PLAUSIBLE else ""
        hint = hint or ": choose a longer dt (t_r unless given)"
        count = f"{span:,.0f}" if span < 1e12 else f"{span:.3g}"
        raise ValueError(
            f"{name} = {t_e:g} s is {count} sub-frames of dt = {dt:g} s, more than the "
            f"{MAX_WINDOW:,} one exposure may span (rsocl.model.plausible.MAX_WINDOW); times are in "
            f"seconds{hint}"
        )


def check_window_us(t_e: float, dt: float) -> None:
    """Refuse ``--t-e-us t_e`` spanning more sub-frames of ``dt`` µs than one exposure may (:data:`MAX_WINDOW`):
    a ValueError naming the option, in the µs the command line gives."""
    if t_e / dt > MAX_WINDOW:
        raise ValueError(
            f"--t-e-us {t_e:g} µs is {math.ceil(t_e / dt):,} sub-frames of {dt:g} µs, more than the "
            f"{MAX_WINDOW:,} one exposure may span; give the exposure in µs (or a longer --dt-us)"
        )


def check_rig_memory(cameras: int, shape, option: str, hint: str = "choose a smaller grid") -> None:
    """Refuse, naming ``option``, a rig of ``cameras`` cameras on ``shape`` (rows, columns) pixels whose
    row maps and exposure windows alone (:data:`RIG_BYTES_PER_PIXEL`) exceed the host memory, before
    it is built."""
    m, n = shape
    check_host_memory(
        cameras * m * n * RIG_BYTES_PER_PIXEL,
        option,
        f"a rig of {cameras} camera(s) on {m} x {n} pixels ({RIG_BYTES_PER_PIXEL} bytes per camera "
        "and pixel: row maps and exposure windows)",
        hint,
    )
