"""The regularizer contract: a proximal denoiser on device arrays.

A regularizer is the ``theta = denoise(f - b, weight = lam / eta)`` step of the
ADMM in docs/model.md (Eq. 13): given a ``pyopencl.array.Array`` of shape
``(T, m, n)`` and a weight, it returns the denoised array, on the device, with
the same shape and dtype. A batch of sets, ``(B, T, m, n)``, takes one weight per set
(or one for all) and is denoised set by set, each as if alone. Subclasses declare their
options and implement one hook, :meth:`Regularizer._denoise`; one that sets ``batched = True``
takes the whole batch in that hook (in one launch per pass), the others get one set at a time.
"""

from __future__ import annotations

import functools
import numbers
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from rsocl.common.hints import ArrayLike, DTypeLike, PerSet
from rsocl.device import pool

if TYPE_CHECKING:
    import pyopencl.array as cla

__all__ = ["Option", "Regularizer"]


def _kind(default: object) -> type | None:
    """The type an option with ``default`` converts its values to: bool, int, float or str (None: none)."""
    if isinstance(default, (bool, np.bool_)):
        return bool
    if isinstance(default, numbers.Integral):
        return int
    if isinstance(default, numbers.Real):
        return float
    if isinstance(default, str):
        return str
    return None


@dataclass(frozen=True)
class Option:
    """One option of a regularizer: default value, unit and meaning.

    The default's type (bool, int, float or str) is the type every value given for the option is
    converted to (:meth:`convert`); a value given for an option with another default (None) is
    refused with a ValueError naming it, and :func:`rsocl.testing.check_regularizer` fails on one.
    ``minimum`` and ``maximum`` bound a number's values, the default's included (:meth:`check`).
    """

    default: object
    unit: str = ""
    doc: str = ""
    minimum: float | None = None
    maximum: float | None = None

    def convert(self, name: str, value: Any) -> Any:
        """``value`` converted to the default's type and range-checked; ValueError naming ``name``."""
        kind = _kind(self.default)
        if kind is bool:
            if isinstance(value, str):
                if value.lower() not in ("1", "0", "true", "false", "yes", "no"):
                    raise ValueError(f"option {name} must be a boolean, got {value!r}")
                value = value.lower() in ("1", "true", "yes")
            try:
                return bool(value)
            except (TypeError, ValueError):
                raise ValueError(f"option {name} must be a boolean, got {value!r}") from None
        if kind in (int, float):
            return self._number(name, value, kind)
        if kind is str:
            try:
                return str(value)
            except Exception:
                raise ValueError(f"option {name} must be a string, got a {type(value).__name__}") from None
        raise ValueError(
            f"option {name} has a default of type {type(self.default).__name__}; an Option's default must be "
            f"a bool, int, float or str"
        )

    def check(self, name: str) -> None:
        """Check the declaration of the option ``name``: each bound a real number or None, ``minimum <=
        maximum``, and a number default within them; ValueError naming ``name`` and what is allowed."""
        for which in ("minimum", "maximum"):
            bound = getattr(self, which)
            real = isinstance(bound, numbers.Real) and not isinstance(bound, (bool, np.bool_))
            if bound is not None and not (real and not np.isnan(bound)):
                raise ValueError(f"option {name!r}: {which} must be a real number or None, got {bound!r}")
        if self.minimum is not None and self.maximum is not None and self.minimum > self.maximum:
            raise ValueError(
                f"option {name!r}: the range is empty: minimum {self.minimum!r} > maximum {self.maximum!r}"
            )
        if _kind(self.default) in (int, float):
            try:
                self.convert(name, self.default)
            except ValueError as exc:
                raise ValueError(
                    f"option {name!r}: the default {self.default!r} is not a value it accepts ({exc})"
                ) from None

    def _number(self, name: str, value: Any, kind: type) -> int | float:
        """``value`` as a finite ``kind`` (int or float) in ``[minimum, maximum]``; ValueError naming ``name``."""
        low = -np.inf if self.minimum is None else self.minimum
        high = np.inf if self.maximum is None else self.maximum
        what = f"{'an integer' if kind is int else 'a number'} in [{low}, {high}]"
        try:
            number = float(value)
        except OverflowError:  # an int too large for a float
            raise ValueError(f"option {name} must be {what}, got {value!r}") from None
        except (TypeError, ValueError):
            raise ValueError(f"option {name} must be {what}, got {value!r}") from None
        if not np.isfinite(number):
            raise ValueError(f"option {name} must be finite, {what}, got {value!r}")
        if kind is int:
            if not number.is_integer():
                raise ValueError(f"option {name} must be an integer, got {value!r}")
            exact = isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
            number = int(value) if exact else int(number)
        if not low <= number <= high:
            raise ValueError(f"option {name} must be in [{low}, {high}], got {value!r}")
        return number


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
        Options that :func:`rsocl.solver.crossval.tune_parameters` may choose from the data,
        with their coarse candidate values (positive, log spaced); empty: only ``lam`` is tuned.
    one_snapshot : dict of str -> float
        Values of tunable options for a rig of one camera: the search then sets them instead of
        choosing them (:func:`rsocl.solver.pipeline.tune`), because held-out pixels are predicted
        across space alone (one frame) or from frames far apart in time (several), and the criterion
        cannot rank priors in time. With one snapshot per pixel, when they leave only ``lam`` unset,
        ``lam`` keeps its default and nothing is searched. Measured per regularizer
        (docs/regularizer_defaults.md); empty: searched as always.

    per_set_options : tuple of str
        Options whose value may differ from set to set of one batch (:meth:`for_sets`); empty: none.
    batched : bool
        True when ``_denoise`` takes a batch ``(B, T, m, n)`` with a float64 array of ``B``
        weights itself; otherwise :meth:`denoise` hands it one set at a time.
    fuses_dual : bool
        True when the instance has ``denoise_and_update(u, weight, theta, b, f, dual)``: the
        denoiser's output and the ADMM's next dual update in its own launches (see
        :class:`rsocl.solver.admm.ADMM`).
    local : bool
        True (default) when a pixel's output depends only on pixels near it in space, so that tiles
        with halos (:mod:`rsocl.scale`) reproduce a run in one piece; False for a transform over the
        whole frame (a global DCT, a periodized wavelet), which a tiled run refuses.

    Subclasses implement ``_denoise(x, weight, out)``; they may override
    :meth:`workspace_bytes` so the solver can check memory before running.
    """

    name = "base"
    options: dict = {}
    dtypes = ("float32", "float64")
    recommended: dict = {}
    batched = False
    local = True
    tunable: dict = {}
    one_snapshot: dict = {}
    per_set_options: tuple = ()

    @property
    def fuses_dual(self) -> bool:
        """Whether the instance has a fused ``denoise_and_update`` (see the class attributes)."""
        return False

    def __init__(self, **options: Any) -> None:
        self.check_options()
        unknown = sorted(set(options) - set(self.options))
        if unknown:
            raise ValueError(
                f"unknown option(s) {unknown} for regularizer {self.name!r}; known: {sorted(self.options)}"
            )
        self.values = {key: opt.default for key, opt in self.options.items()}
        for key, value in options.items():
            self.values[key] = self.options[key].convert(key, value)
        self._given = frozenset(options)  # the options the caller set: kept; the parameter search may choose others

    @property
    def in_use(self) -> threading.RLock:
        """The lock a reconstruction holds while it runs with this instance, whose device buffers and
        launch settings are cached on it: threads sharing one instance take turns (correct results);
        an instance per thread, or a regularizer given by name, runs them side by side."""
        return self.__dict__.setdefault("_in_use", threading.RLock())

    def __getattr__(self, key):
        values = self.__dict__.get("values", {})
        if key in values:
            return values[key]
        raise AttributeError(key)

    @classmethod
    def check_options(cls) -> None:
        """Check the class's declared :attr:`options`: each an :class:`Option` whose declaration is valid
        (:meth:`Option.check`); ValueError naming the regularizer and the option."""
        for key, opt in cls.options.items():
            try:
                if not isinstance(opt, Option):
                    raise ValueError(f"option {key!r} must be declared as rsocl.solver.regularizer.Option, got {opt!r}")
                opt.check(key)
            except ValueError as exc:
                raise ValueError(f"regularizer {cls.name!r} ({cls.__module__}.{cls.__qualname__}): {exc}") from None

    @classmethod
    def for_sets(cls, instances: list) -> Regularizer | None:
        """One regularizer that denoises set ``i`` of a batch of ``len(instances)`` sets as ``instances[i]``
        does alone, or None when there is none: when they are not all of this class, or differ in an
        option outside :attr:`per_set_options`. Instances with equal options give the first of them.

        >>> from rsocl_plugins.tv import TV
        >>> TV.for_sets([TV(temporal_weight=1.0), TV(temporal_weight=3.0)]).temporal_weights(2)
        array([1., 3.])
        """
        if not instances or any(type(r) is not cls for r in instances):
            return None
        first = instances[0]
        if all(r.values == first.values for r in instances):
            return first
        fixed = [{k: v for k, v in r.values.items() if k not in cls.per_set_options} for r in instances]
        if any(f != fixed[0] for f in fixed):
            return None
        return cls._for_sets(instances)

    @classmethod
    def _for_sets(cls, instances: list) -> Regularizer | None:
        """:meth:`for_sets` of instances that differ only in :attr:`per_set_options`: a subclass that lists
        such options makes the one instance here (None: it cannot for these values)."""
        return None

    def fuses_dual_on(self, device) -> bool:
        """Whether an ADMM on ``device`` (an rsocl Device) leaves its dual update to ``denoise_and_update``
        (default: :attr:`fuses_dual`; a regularizer may keep separate passes where they are faster)."""
        return bool(self.fuses_dual)

    def deferred_primal_on(self, device) -> dict | None:
        """The program definitions under which a call bound with ``bind(..., dual, defer=True)`` on
        ``device`` leaves its last launch to the ADMM's projection, or None (default) where it does not.

        Such a call ends before its output: its last step (``theta = u + d(p)`` and the dual update, as
        ``tv_primal_update`` of ``kernels/tv.cl``, from the final dual ``p`` in that file's layout) is
        made by the next projection (``kernels/admm.cl``, built with ``tv.cl`` and these definitions),
        and the bound call's ``deferred`` holds ``(p, steps)`` and its ``finish()`` enqueues the step
        where the output is read first. rsocl's TV does so on its plain path on a GPU."""
        return None

    def workspace_bytes(self, shape: tuple[int, ...], dtype: DTypeLike, device=None) -> int:
        """Device memory (bytes) the denoiser allocates for an input of ``shape`` and ``dtype`` on
        ``device`` (an rsocl Device; None: any, for a regularizer whose workspace does not depend on it)."""
        return 0

    def denoise(self, x: cla.Array, weight: PerSet | ArrayLike, out: cla.Array | None = None) -> cla.Array:
        """Denoise the device array ``x`` with strength ``weight`` (>= 0); returns a device array.

        ``x`` is ``(T, m, n)``, or a batch ``(B, T, m, n)`` with ``weight`` one number or one per set.
        ``weight = 0`` returns a copy of ``x`` (of that set). ``out`` (same shape and dtype) is
        written and returned when given; whether it may be ``x`` itself is the
        regularizer's to say.
        """
        import pyopencl as cl

        weights, out = self._checked(x, weight, out)
        if not np.any(weights):  # the identity: a copy, none where out is x
            if not pool.same_memory(out, x):
                # the ignore: pyopencl's stub types an Array's queue and data as optional; an allocated array has both
                cl.enqueue_copy(x.queue, out.data, x.data)  # type: ignore[arg-type]
            return out
        try:
            if x.ndim == 3:
                return self._denoise(x, float(weights[0]), out)
            if self.batched:
                return self._denoise(x, weights, out)
            return self._set_by_set(x, weights, out)
        except ValueError as exc:
            raise ValueError(f"{self!r}: {exc}") from exc
        except (RuntimeError, TypeError, AttributeError, LookupError, cl.Error) as exc:
            if isinstance(exc, cl.MemoryError):  # the device's memory, not the plugin: the caller's to handle
                raise
            raise self._failed(exc) from exc

    def _failed(self, exc: BaseException) -> ValueError:
        """A PluginError (a ValueError) on one line: ``exc`` raised by this regularizer's ``_denoise``, with
        the regularizer's name, class and distribution (a build log is cut after 600 characters)."""
        from rsocl.common.registry import PluginError, origin

        cls = type(self)
        where = origin("rsocl.regularizers", cls)
        cause = " ".join(f"{type(exc).__name__}: {exc}".split())
        cause = cause if len(cause) <= 600 else cause[:600] + " ..."
        return PluginError(
            f"regularizer {self.name!r} ({cls.__module__}.{cls.__qualname__}{' from ' + where if where else ''}) "
            f"failed in _denoise: {cause}"
        )

    def _checked(self, x, weight, out):
        """``denoise``'s arguments checked: ``(weights, out)``, the weights one per set (float64) and ``out``
        allocated when None."""
        import pyopencl.array as cla

        if not isinstance(x, cla.Array):
            raise ValueError(f"{self.name}: x must be a pyopencl.array.Array, got {type(x).__name__}")
        if x.ndim not in (3, 4) or x.size == 0:
            raise ValueError(f"{self.name}: x must have shape (T, m, n) or a batch (B, T, m, n), got {x.shape}")
        if np.dtype(x.dtype).name not in self.dtypes:
            raise ValueError(f"{self.name}: dtype {x.dtype} not supported; supported: {list(self.dtypes)}")
        weights = self.check_weights(weight, x.shape[0] if x.ndim == 4 else None)
        if out is None:
            out = cla.empty_like(x)
        elif out.shape != x.shape or out.dtype != x.dtype:
            raise ValueError(f"{self.name}: out must match x ({x.shape}, {x.dtype}), got {out.shape}, {out.dtype}")
        return weights, out

    def bind(
        self, x: cla.Array, weight: PerSet | ArrayLike, out: cla.Array, dual: tuple | None = None
    ) -> Callable[[], Any]:
        """``denoise(x, weight, out=out)`` as a call without arguments, for a loop that makes it many times
        on the same arrays (their contents may change between calls, not the arrays or ``weight``).

        With ``dual = (b, f, on)`` the call is ``denoise_and_update(x, weight, out, b, f, on)`` (a regularizer
        with :attr:`fuses_dual`). This default binds the call as it is; a regularizer may check its
        arguments and prepare its launches once here instead of on every call.

        Examples
        --------
        >>> import numpy as np, pyopencl.array as cla, rsocl
        >>> from rsocl_plugins.tv import TV
        >>> queue = rsocl.get_device().queue
        >>> x = cla.to_device(queue, np.ones((3, 4, 4), np.float32))
        >>> out = cla.empty_like(x)
        >>> run = TV().bind(x, 0.1, out)
        >>> run(); float(out.get().max())
        1.0
        """
        if dual is None:
            return functools.partial(self.denoise, x, weight, out)
        return functools.partial(self.denoise_and_update, x, weight, out, *dual)

    def check_weights(self, weight: PerSet | ArrayLike, sets: int | None = None) -> np.ndarray:
        """``weight`` as a float64 array (one value, or ``sets`` values for a batch), each finite and >= 0."""
        w = np.asarray(weight, dtype=np.float64) if not isinstance(weight, str) else None
        if w is None or w.ndim > 1 or (w.ndim == 1 and (sets is None or w.shape != (sets,))):
            per = "a number" if sets is None else f"a number or one per set ({sets} values)"
            raise ValueError(f"{self.name}: weight must be {per}, got {weight!r}")
        if not (np.all(np.isfinite(w)) and np.all(w >= 0)):
            raise ValueError(f"{self.name}: weight must be finite and >= 0, got {weight!r}")
        return np.broadcast_to(w, (1 if sets is None else sets,)).copy()

    def _set_by_set(self, x, weights, out):
        """A batch through ``_denoise`` one set at a time, in a ``(T, m, n)`` work array pair."""
        import pyopencl as cl
        import pyopencl.array as cla

        one = cla.empty(x.queue, x.shape[1:], x.dtype)
        done = cla.empty_like(one)
        for i, w in enumerate(weights):
            span = dict(byte_count=one.nbytes)
            cl.enqueue_copy(x.queue, one.data, x.base_data, src_offset=x.offset + i * one.nbytes, **span)
            result = self._denoise(one, float(w), done) if w > 0 else one
            cl.enqueue_copy(x.queue, out.base_data, result.data, dst_offset=out.offset + i * one.nbytes, **span)
        return out

    def _denoise(self, x, weight, out):  # pragma: no cover - abstract
        raise NotImplementedError(f"{type(self).__name__} does not implement _denoise")

    def __repr__(self):
        opts = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        return f"{type(self).__name__}({opts})"
