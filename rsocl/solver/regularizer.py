"""The regularizer contract: a proximal denoiser on device arrays.

A regularizer is the ``theta = denoise(f - b, weight = lam / eta)`` step of the
ADMM in MODEL.md (Eq. 13): given a ``pyopencl.array.Array`` of shape
``(T, m, n)`` and a weight, it returns the denoised array, on the device, with
the same shape and dtype. Subclasses declare their options and implement one
hook, :meth:`Regularizer._denoise`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Option", "Regularizer"]


@dataclass(frozen=True)
class Option:
    """One option of a regularizer: default value, unit and meaning."""

    default: object
    unit: str = ""
    doc: str = ""
    minimum: float | None = None
    maximum: float | None = None

    def convert(self, name: str, value):
        kind = type(self.default)
        if kind is bool:
            if isinstance(value, str):
                if value.lower() not in ("1", "0", "true", "false", "yes", "no"):
                    raise ValueError(f"option {name} must be a boolean, got {value!r}")
                value = value.lower() in ("1", "true", "yes")
            return bool(value)
        if kind in (int, float):
            try:
                number = kind(float(value)) if kind is int else float(value)
            except (TypeError, ValueError):
                raise ValueError(f"option {name} must be a number, got {value!r}") from None
            if kind is int and float(value) != number:
                raise ValueError(f"option {name} must be an integer, got {value!r}")
            if not np.isfinite(number):
                raise ValueError(f"option {name} must be finite, got {value!r}")
            low = -np.inf if self.minimum is None else self.minimum
            high = np.inf if self.maximum is None else self.maximum
            if not low <= number <= high:
                raise ValueError(f"option {name} must be in [{low}, {high}], got {value!r}")
            return number
        return kind(value)


class Regularizer:
    """Base class of rsocl regularizers.

    Class attributes
    ----------------
    name : str
        The registry name (``"tv"``, ...).
    options : dict of str -> Option
        Declared options with defaults and units.
    dtypes : tuple of str
        Supported device dtypes.
    recommended : dict
        Optional ``lam``/``eta`` that :func:`rsocl.solver.reconstruct` uses when the caller
        gives none (measured for this regularizer; data in [0, 1]).
    tunable : dict of str -> tuple of float
        Options that :func:`rsocl.solver.tuning.tune_parameters` may choose from the data,
        with their coarse candidate values (positive, log spaced); empty: only ``lam`` is tuned.

    Subclasses implement ``_denoise(x, weight, out)``; they may override
    :meth:`workspace_bytes` so the solver can check memory before running.
    """

    name = "base"
    options: dict = {}
    dtypes = ("float32", "float64")
    recommended: dict = {}
    tunable: dict = {}

    def __init__(self, **options):
        unknown = sorted(set(options) - set(self.options))
        if unknown:
            raise ValueError(f"unknown option(s) {unknown} for regularizer {self.name!r}; "
                             f"known: {sorted(self.options)}")
        self.values = {key: opt.default for key, opt in self.options.items()}
        for key, value in options.items():
            self.values[key] = self.options[key].convert(key, value)

    def __getattr__(self, key):
        values = self.__dict__.get("values", {})
        if key in values:
            return values[key]
        raise AttributeError(key)

    def workspace_bytes(self, shape, dtype) -> int:
        """Device memory (bytes) the denoiser allocates for an input of ``shape`` and ``dtype``."""
        return 0

    def denoise(self, x, weight: float, out=None):
        """Denoise the device array ``x`` with strength ``weight`` (>= 0); returns a device array.

        ``weight = 0`` returns a copy of ``x``. ``out`` (same shape and dtype) is
        written and returned when given; whether it may be ``x`` itself is the
        regularizer's to say.
        """
        import pyopencl.array as cla

        if not isinstance(x, cla.Array):
            raise ValueError(f"{self.name}: x must be a pyopencl.array.Array, got {type(x).__name__}")
        if x.ndim != 3:
            raise ValueError(f"{self.name}: x must have shape (T, m, n), got {x.shape}")
        if np.dtype(x.dtype).name not in self.dtypes:
            raise ValueError(f"{self.name}: dtype {x.dtype} not supported; supported: {list(self.dtypes)}")
        weight = float(weight)
        if not (np.isfinite(weight) and weight >= 0):
            raise ValueError(f"{self.name}: weight must be finite and >= 0, got {weight!r}")
        if out is None:
            out = cla.empty_like(x)
        elif out.shape != x.shape or out.dtype != x.dtype:
            raise ValueError(f"{self.name}: out must match x ({x.shape}, {x.dtype}), got {out.shape}, {out.dtype}")
        if weight == 0:
            import pyopencl as cl

            cl.enqueue_copy(x.queue, out.data, x.data)
            return out
        try:
            return self._denoise(x, weight, out)
        except ValueError as exc:
            raise ValueError(f"{self!r}: {exc}") from exc

    def _denoise(self, x, weight, out):  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self):
        opts = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        return f"{type(self).__name__}({opts})"
