"""Small checks that turn bad input into a ``ValueError`` naming the parameter.

Every public constructor in rsocl validates through these helpers so that
messages look the same everywhere: the parameter's name, its value and the
allowed range.
"""

from __future__ import annotations

import contextlib
import difflib
import math
import numbers
import os
from pathlib import Path

import numpy as np

__all__ = [
    "positive",
    "non_negative",
    "finite",
    "in_range",
    "positive_int",
    "choice",
    "finite_array",
    "grid_shape",
    "reading",
    "cause",
    "unknown_keys",
    "existing_file",
]


def finite(name: str, value) -> float:
    """Return ``value`` as a float, or raise if it is not a finite real number (a 0-d real NumPy
    array counts as its one value)."""
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf":
        value = value.item()
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a finite real number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value


def positive(name: str, value, unit: str = "") -> float:
    """A finite number ``> 0``."""
    value = finite(name, value)
    if value <= 0:
        raise ValueError(f"{name} must be > 0{' ' + unit if unit else ''}, got {value!r}")
    return value


def non_negative(name: str, value, unit: str = "") -> float:
    """A finite number ``>= 0``."""
    value = finite(name, value)
    if value < 0:
        raise ValueError(f"{name} must be >= 0{' ' + unit if unit else ''}, got {value!r}")
    return value


def in_range(name: str, value, low: float, high: float) -> float:
    """A finite number in the closed interval ``[low, high]``."""
    value = finite(name, value)
    if not low <= value <= high:
        raise ValueError(f"{name} must be in [{low}, {high}], got {value!r}")
    return value


def positive_int(name: str, value, maximum: int | None = None) -> int:
    """An integer ``>= 1`` (and ``<= maximum`` when given)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    value = int(value)
    if value < 1 or (maximum is not None and value > maximum):
        upper = f" and <= {maximum}" if maximum is not None else ""
        raise ValueError(f"{name} must be an integer >= 1{upper}, got {value!r}")
    return value


def grid_shape(name: str, shape) -> tuple:
    """``(m, n)``: rows and columns, each an integer >= 1."""
    try:
        m, n = shape
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be (m, n) rows and columns, got {shape!r}") from None
    return positive_int(f"{name}[0] (rows m)", m), positive_int(f"{name}[1] (columns n)", n)


def choice(name: str, value, allowed) -> str:
    """One of a fixed set of strings."""
    if value not in allowed:
        raise ValueError(f"{name} must be one of {sorted(allowed)}, got {value!r}")
    return value


def unknown_keys(name: str, table, known, what: str = "config key") -> None:
    """Refuse (``ValueError``) a ``table`` with keys not in ``known``.

    The message names ``name``, each unknown key with the closest known one when one is close
    (``difflib.get_close_matches``: ``'adress'`` -> did you mean ``'address'``?) and the known
    keys; ``what`` says what the keys are (``"config key"``, ``"sensor option"``).

    Examples
    --------
    >>> unknown_keys("v4l2 /dev/video0", {"adress": 2}, ["address", "buffers"])
    Traceback (most recent call last):
    ...
    ValueError: v4l2 /dev/video0: unknown config key 'adress' (did you mean 'address'?); known: ['address', 'buffers']
    """
    known = sorted(str(key) for key in known)
    unknown = sorted((key for key in table if key not in known), key=str)
    if unknown:
        named = []
        for key in unknown:
            close = difflib.get_close_matches(str(key), known, n=1)
            named.append(f"{key!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
        raise ValueError(f"{name}: unknown {what}{'s' if len(named) > 1 else ''} {', '.join(named)}; known: {known}")


def real_dtype(name: str, dtype) -> np.dtype:
    """``float32`` or ``float64`` (a name, a NumPy type or dtype); ``None`` is refused, not read as float64."""
    try:
        dt = None if dtype is None else np.dtype(dtype)
    except (TypeError, ValueError):
        dt = None
    if dt is None or dt.name not in ("float32", "float64"):
        raise ValueError(f"{name} must be 'float32' or 'float64', got {dtype!r}")
    return dt


def finite_array(name: str, array) -> np.ndarray:
    """A real array with no NaN or inf; returned as a NumPy array (no copy when possible)."""
    try:
        array = np.asarray(array)
    except ValueError as exc:  # a ragged nesting of lists
        raise ValueError(f"{name} must be a rectangular array of numbers: {exc}") from None
    if array.dtype.kind not in "biuf":
        raise ValueError(f"{name} must be a real-valued array, got dtype {array.dtype}")
    if array.dtype.kind == "f" and not np.all(np.isfinite(array)):
        bad = int(np.count_nonzero(~np.isfinite(array)))
        raise ValueError(f"{name} contains {bad} NaN or inf value(s); all values must be finite")
    return array


def cause(exc: BaseException) -> str:
    """``"TypeName: first line of the message"`` of ``exc`` (libraries such as h5py write several lines)."""
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


@contextlib.contextmanager
def reading(name: str, path, what: str):
    """Context manager around a library's read of file ``path``: a failure to parse it (empty,
    truncated or corrupt, not the format its suffix says, a folder) becomes a one-line
    ``ValueError`` naming the parameter ``name``, the file and ``what`` it was read as, with the
    cause's first line. ``MemoryError`` (and ``KeyboardInterrupt``) pass unchanged.

    Examples
    --------
    >>> with reading("--scene", "empty.npz", "a NumPy .npz archive"):     # doctest: +SKIP
    ...     archive = np.load("empty.npz")
    ValueError: --scene: cannot read 'empty.npz' as a NumPy .npz archive (EOFError: No data left in file)
    """
    try:
        yield
    except MemoryError:
        raise
    except Exception as exc:  # noqa: BLE001 - zipfile, EOFError, OSError, PIL's SyntaxError, imageio's, ...
        raise ValueError(f"{name}: cannot read {str(path)!r} as {what} ({cause(exc)})") from None


def existing_file(name: str, path, what: str) -> Path:
    """``path`` as a :class:`~pathlib.Path`, or ``FileNotFoundError`` naming ``name`` and ``what`` the file
    should be when nothing is there, ``ValueError`` when a directory (or another non-file) is."""
    path = Path(os.fspath(path))
    prefix = f"{name}: " if name else ""
    if not path.exists():
        raise FileNotFoundError(f"{prefix}{what} {str(path)!r} does not exist")
    if path.is_dir():
        store = " (a Zarr store of a tiled run: rsocl.scale.load_store reads it)" if path.suffix == ".zarr" else ""
        raise ValueError(f"{prefix}{str(path)!r} is a directory, not a {what}{store}")
    if not path.is_file():
        raise ValueError(f"{prefix}{str(path)!r} is not a regular file (expected a {what})")
    return path
