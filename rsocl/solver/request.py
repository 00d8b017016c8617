"""A reconstruction request: what to reconstruct and how, checked once.

:func:`make_request` is the preamble :func:`rsocl.reconstruct`,
:func:`rsocl.solver.sets.reconstruct_sets` and :func:`rsocl.scale.reconstruct_tiled` share: it
checks the solver settings, makes the configured regularizer, settles ``lam`` and ``eta`` for
the rig (:meth:`~rsocl.solver.problem.Settings.settled_for`), checks ``tune`` and ``blend``, and
keeps what the caller fixed apart from what is left to choose. The :class:`Request` then goes
through :func:`rsocl.solver.pipeline.prepare`, :func:`~rsocl.solver.pipeline.tune` and
:func:`~rsocl.solver.pipeline.run`; :func:`run_params` is the ``params`` record of every run.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from rsocl.common.hints import Callback, DTypeLike, Options, PerSet
from rsocl.common.registry import load
from rsocl.device.context import Device
from rsocl.model.curvature import default_scale
from rsocl.model.rig import Rig
from rsocl.solver.checks import check_blend
from rsocl.solver.crossval import SearchSpace, Tuning
from rsocl.solver.ladder import DEFAULT_QUALITY, Rung, check_iterations, rung
from rsocl.solver.problem import Settings, check_settings, check_weight_ratio
from rsocl.solver.regularizer import Regularizer
from rsocl.solver.tuning_check import check_tuning

__all__ = [
    "Given",
    "Request",
    "make_request",
    "make_regularizer",
    "check_tune",
    "check_blend",
    "chosen_options",
    "first_value",
    "run_params",
]


def make_regularizer(
    regularizer: str | Regularizer, options: Options | None = None, tv_iterations: int | None = None
) -> Regularizer:
    """A regularizer instance from a registry name (with options) or an instance (without).

    Parameters
    ----------
    regularizer : str or Regularizer
        Registry name (``"tv"``) or an instance (returned as it is).
    options : dict or None
        Options of a named regularizer (values as the option converts them, e.g. strings).
    tv_iterations : int or None
        The inner iterations of an iterative denoiser (its ``iterations`` option).

    Raises
    ------
    ValueError
        On an unknown name or option, options given with an instance, or ``tv_iterations`` that
        the regularizer has no use for or that disagrees with ``options['iterations']``.

    Examples
    --------
    >>> make_regularizer("tv", {"fused": "2"}).fused
    2
    """
    options = dict(options or {})
    if isinstance(regularizer, Regularizer):
        if options:
            raise ValueError("regularizer_options apply to a regularizer given by name, not to an instance")
        if tv_iterations is not None and tv_iterations != getattr(regularizer, "iterations", None):
            raise ValueError(
                f"tv_iterations applies to a regularizer given by name; the instance {regularizer!r} "
                "keeps its own options (set its 'iterations' when making it)"
            )
        return regularizer
    if not isinstance(regularizer, str):
        raise ValueError(f"regularizer must be a name or a Regularizer, got {regularizer!r}")
    cls = load("rsocl.regularizers", regularizer)
    if tv_iterations is not None:
        if "iterations" not in getattr(cls, "options", {}):
            raise ValueError(f"tv_iterations applies to iterative denoisers; {regularizer!r} has no 'iterations'")
        if "iterations" in options:
            made = cls(**options)
            if made.iterations != tv_iterations:
                raise ValueError(
                    f"tv_iterations = {tv_iterations!r} and regularizer_options['iterations'] = "
                    f"{options['iterations']!r} disagree; give the inner iterations once"
                )
            return made
        options["iterations"] = cls.options["iterations"].convert("tv_iterations", tv_iterations)  # named so
    return cls(**options)


def chosen_options(tuning: Tuning) -> dict:
    """The regularizer options a :class:`~rsocl.solver.crossval.Tuning` chose (its ``chosen`` without ``lam``)."""
    return {k: v for k, v in tuning.chosen.items() if k != "lam"}


def check_tune(tune: bool | Tuning, reg: Regularizer | None = None, lam_given: bool = False) -> bool | Tuning:
    """``tune`` checked: ``True``/``False`` (a bool), or an earlier :class:`Tuning` to run with; with
    ``reg`` (the regularizer to run), a Tuning is checked by
    :func:`~rsocl.solver.tuning_check.check_tuning` (options ``reg`` has, in their ranges; ``chosen['lam']``
    unless ``lam_given``; ``blend``) and returned as checked."""
    if isinstance(tune, Tuning):
        return tune if reg is None else check_tuning(tune, reg, lam_given)
    if isinstance(tune, (bool, np.bool_)):
        return bool(tune)
    raise ValueError(f"tune must be True, False or an rsocl.solver.crossval.Tuning, got {tune!r}")


def first_value(value: Any) -> Any:
    """The first set's value of a per-set tuple, else the value."""
    return value[0] if isinstance(value, tuple) else value


@dataclass(frozen=True)
class Given:
    """What the caller fixed: the regularizer as given (a registry name or an instance), the options
    of a named one, and ``lam`` (None: left to choose) and ``eta`` as checked (one value or one per set)."""

    regularizer: str | Regularizer
    options: dict = field(default_factory=dict)
    lam: float | tuple | None = None
    eta: float | tuple | None = None

    @property
    def name(self) -> str | None:
        """The registry name, when the regularizer was given by name."""
        return self.regularizer if isinstance(self.regularizer, str) else None

    def option_names(self, reg: Regularizer) -> set:
        """Names of the regularizer options the caller fixed: those given by name (``regularizer_options``),
        or those an instance was made with (every option of one whose class skipped the base ``__init__``).
        They are neither searched nor replaced by an earlier choice."""
        if self.name is not None:
            return set(self.options)
        return set(reg.__dict__.get("_given", reg.values))


@dataclass(frozen=True)
class Request:
    """What to reconstruct and how, checked (:func:`make_request`).

    Attributes
    ----------
    rig : Rig
        The rig the settings were settled for (the whole capture's, for a tiled run).
    regularizer : Regularizer
        The configured instance (the caller's options; the search's choice comes on top in
        :func:`rsocl.solver.pipeline.run`).
    settings : rsocl.solver.problem.Settings
        Checked and settled: ``lam`` and ``eta`` are never None (one value, or one per set).
    given : Given
        What the caller fixed.
    tune : bool or Tuning
        Search what is left unset (True), run an earlier choice (a Tuning), or the fixed defaults.
    blend : float or None
        The caller's blend (None: the search's choice).
    dtype : str or numpy dtype
        ``"float32"`` or ``"float64"``.
    device : str, Device or None
        OpenCL device spec.
    sets : int or None
        Sets of a batch the per-set values are for (None: one set, or no per-set values).
    progress : bool
        Progress bars.
    quality : str
        The rung of :mod:`rsocl.solver.ladder` the search and the run follow.
    auto : bool
        Whether the run stops when its residual has settled (``iterations="auto"``; ``settings.iterations``
        is then the cap).
    """

    rig: Rig
    regularizer: Regularizer
    settings: Settings
    given: Given
    tune: bool | Tuning = True
    blend: float | None = None
    dtype: DTypeLike = "float32"
    device: str | Device | None = None
    sets: int | None = None
    progress: bool = False
    quality: str = DEFAULT_QUALITY
    auto: bool = False

    @property
    def rung(self) -> Rung:
        """The :class:`~rsocl.solver.ladder.Rung` named by ``quality``."""
        return rung(self.quality)

    @property
    def name(self) -> str:
        """The regularizer's registry name (as given, else the instance's ``name``)."""
        return self.given.name or self.regularizer.name

    def with_options(self, options: Options) -> Regularizer:
        """The regularizer's kind with ``options`` over the caller's ones."""
        if self.given.name is None:
            return type(self.regularizer)(**{**self.regularizer.values, **options})
        return make_regularizer(self.given.name, {**self.given.options, **options}, self.settings.tv_iterations)

    def search_space(self) -> SearchSpace | None:
        """What the search chooses (:class:`~rsocl.solver.crossval.SearchSpace`; the ``lam`` candidates are
        the settled ``lam`` times the rung's ``lam_factors``, the options those the rung searches), or None
        when the caller left nothing to choose. For per-set values, the first set's. A ValueError where the
        largest candidate's ``lam / eta`` overflows (:func:`~rsocl.solver.problem.check_weight_ratio`)."""
        reg, search = self.regularizer, self.rung.search
        given = self.given.option_names(reg)
        tunable = {k: v for k, v in getattr(reg, "tunable", {}).items() if k not in given and search.options}
        lam0 = first_value(self.settings.lam)
        fixed_lam = self.given.lam
        if fixed_lam is None:
            lam = [lam0 * f for f in search.lam_factors] if lam0 > 0 else lam0
            if lam0 > 0:  # the largest candidate's lam / eta, as the settled lam's (Settings.for_batch)
                check_weight_ratio(max(lam), first_value(self.settings.eta), "lam (the search's largest candidate)")
        else:
            lam = first_value(fixed_lam)
        if (not tunable and np.isscalar(lam)) or (np.isscalar(lam) and lam == 0):
            return None  # nothing to choose; lam = 0 makes the regularizer's options moot
        fixed = {k: v for k, v in reg.values.items() if k in given}
        if fixed_lam is not None:
            fixed["lam"] = lam
        return SearchSpace(tunable, lam, fixed)

    @property
    def starts_from_interpolation(self) -> bool:
        """Whether the run starts from the ``interp3d`` interpolation when no ``x0`` is given: ``tune``
        is an earlier Tuning, or True with something left to choose."""
        if self.tune is False:
            return False
        return isinstance(self.tune, Tuning) or self.search_space() is not None

    def tuned_options(self, tuning: Tuning | None) -> dict:
        """The options ``tuning`` chose (None: none) that the caller did not fix."""
        if tuning is None:
            return {}
        given = self.given.option_names(self.regularizer)
        return {k: v for k, v in chosen_options(tuning).items() if k not in given}

    def settled(self, tuning: Tuning | None) -> tuple[Regularizer, Settings]:
        """``(regularizer, settings)`` to run with ``tuning`` (None: as requested): its chosen options and
        ``lam`` where the caller fixed none."""
        if tuning is None:
            return self.regularizer, self.settings
        reg = self.with_options(self.tuned_options(tuning))
        settings = self.settings
        if self.given.lam is None:
            settings = replace(settings, lam=tuning.chosen["lam"])
        return reg, settings

    def for_sets(self, part: slice) -> Request:
        """This request for the sets ``part`` of its per-set values (the caller's ``lam``/``eta`` cut and
        settled again, as a request for those sets alone)."""

        def cut(value):
            return value[part] if isinstance(value, tuple) else value

        given = replace(self.given, lam=cut(self.given.lam), eta=cut(self.given.eta))
        count = len(range(*part.indices(self.sets or 1)))
        settings = replace(self.settings, lam=given.lam, eta=given.eta)
        settings = settings.settled_for(self.regularizer, self.dtype, scale=default_scale(self.rig)).for_batch(count)
        return replace(self, given=given, settings=settings, sets=count)

    def with_tuning(self, tuning: Tuning) -> Request:
        """This request running ``tuning`` (an earlier choice, checked as ``tune`` is) instead of a search."""
        return replace(self, tune=check_tuning(tuning, self.regularizer, self.given.lam is not None))


def make_request(
    rig: Rig,
    regularizer: str | Regularizer = "tv",
    *,
    sets: int | None = None,
    x0_given: bool = False,
    iterations: int | str | None = None,
    lam: PerSet | None = None,
    eta: PerSet | None = None,
    tv_iterations: int | None = None,
    projection: str = "exact",
    tol: float | None = None,
    callback: Callback | None = None,
    dtype: DTypeLike = "float32",
    device: str | Device | None = None,
    regularizer_options: Options | None = None,
    tune: bool | Tuning = True,
    blend: float | None = None,
    progress: bool = False,
    quality: str = DEFAULT_QUALITY,
) -> Request:
    """Check what a reconstruction is asked to do, once, before any device work.

    Parameters
    ----------
    rig : Rig
    regularizer, regularizer_options, iterations, lam, eta, tv_iterations, projection, tol, callback, dtype,
    device, tune, blend, progress, quality
        As :func:`rsocl.reconstruct`.
    sets : int or None
        Sets of a batch (None: one set); per-set ``lam``/``eta`` are checked against it.
    x0_given : bool
        Whether the caller gives the start (an ``x0`` array or ``"interp3d"``): a ``blend`` below 1
        then has a start to move towards without the search.

    Returns
    -------
    Request

    Raises
    ------
    ValueError
        Naming the parameter, for any value out of its range or that contradicts another.

    Examples
    --------
    >>> from rsocl.model.rig import Rig
    >>> request = make_request(Rig.paper_array(4, (16, 16)), lam=0.05, tune=False)
    >>> request.settings.lam
    0.05
    """
    if not isinstance(rig, Rig):
        raise ValueError(f"rig must be an rsocl.Rig, got {type(rig).__name__}")
    tune = check_tune(tune)
    iterations, auto = check_iterations(iterations, quality)
    checked = check_settings(
        iterations=iterations,
        lam=lam,
        eta=eta,
        tv_iterations=tv_iterations,
        projection=projection,
        tol=tol,
        callback=callback,
    )
    reg = make_regularizer(regularizer, regularizer_options, checked.tv_iterations)
    tune = check_tune(tune, reg, lam_given=checked.lam is not None)
    given = Given(regularizer, dict(regularizer_options or {}), checked.lam, checked.eta)
    settings = checked.settled_for(reg, dtype, scale=default_scale(rig)).for_batch(sets)
    request = Request(rig, reg, settings, given, tune, None, dtype, device, sets, bool(progress), quality, auto)
    blend = check_blend(blend, x0_given or request.starts_from_interpolation)
    return replace(request, blend=blend)


def run_params(
    request: Request,
    reg: Regularizer,
    settings: Settings,
    *,
    lam: PerSet | None,
    eta: PerSet | None,
    device: str | None,
    saturation: float | None,
    tuning: Tuning | None,
    blend: float,
    start: str,
) -> dict:
    """The ``params`` record of a run (every path's: one set, a batch, tiles), JSON-ready.

    Parameters
    ----------
    request : Request
    reg, settings
        The regularizer and settings the run used (:meth:`Request.settled`).
    lam, eta : float or list of float
        As the run used them (one value, or one per set).
    device : str or None
        The device's name (or the spec every task opens).
    saturation : float or None
    tuning : Tuning or None
        The choice, recorded with :meth:`~rsocl.solver.crossval.Tuning.as_params`.
    blend : float
    start : str
        ``"x0"``, ``"interp3d"`` or ``"zeros"``.
    """
    return {
        "regularizer": request.name,
        "regularizer_options": dict(reg.values),
        "iterations": settings.iterations,
        "quality": request.quality,
        "auto_iterations": request.auto,
        "lam": lam,
        "eta": eta,
        "projection": settings.projection,
        "dtype": np.dtype(request.dtype).name,
        "device": device,
        "tol": settings.tol,
        "saturation": saturation,
        "tuning": None if tuning is None else tuning.as_params(),
        "blend": blend,
        "start": start,
    }
