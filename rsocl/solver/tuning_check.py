"""The check of an earlier choice given as ``tune=Tuning(...)``: what it holds must run as it says.

:func:`check_tuning` is what :func:`rsocl.solver.request.check_tune` applies to a
:class:`~rsocl.solver.crossval.Tuning` before any device work: its ``chosen`` options are ones the
regularizer has, in their ranges (the regularizer's own checks), ``chosen["lam"]`` is a finite
number >= 0 (required unless the caller fixes ``lam``), and its ``blend`` is None or in [0, 1].
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING

from rsocl.common import validation as check
from rsocl.solver.regularizer import Regularizer

if TYPE_CHECKING:
    from rsocl.solver.crossval import Tuning

__all__ = ["check_tuning"]


def check_tuning(tuning: Tuning, reg: Regularizer, lam_given: bool = False) -> Tuning:
    """``tuning`` checked for a run with the regularizer ``reg``: ``tuning`` itself, or a copy with
    ``chosen["lam"]`` and ``blend`` as Python floats where they were other numbers (the options as given;
    ``reg``'s kind converts them when it is made).

    Parameters
    ----------
    tuning : rsocl.solver.crossval.Tuning
        The earlier choice (e.g. ``Tuning.from_params(result.params["tuning"])``).
    reg : Regularizer
        The regularizer the run uses; every option in ``chosen`` must be one of its options, and is
        checked by making ``reg``'s kind with it.
    lam_given : bool
        Whether the caller fixes ``lam``; otherwise ``chosen`` must hold it.

    Raises
    ------
    ValueError
        Naming ``tune.chosen``, ``tune.chosen[<name>]`` or ``tune.blend`` and what each must be.
    """
    chosen = tuning.chosen
    if not isinstance(chosen, Mapping):
        raise ValueError(f"tune.chosen must be a dict of 'lam' and regularizer options, got {chosen!r}")
    options = {k: v for k, v in chosen.items() if k != "lam"}
    foreign = sorted(set(options) - set(reg.values), key=str)
    if foreign:
        raise ValueError(
            f"tune: the earlier Tuning chose {foreign}, options {reg.name!r} does not have "
            f"(it has {sorted(reg.values)}); pass tune=True to choose for {reg.name!r}, or "
            "tune=False for its fixed defaults"
        )
    for name, value in options.items():
        _made(reg, {name: value}, f"tune.chosen[{name!r}] = {value!r}")
    _made(reg, options, f"tune.chosen's options {options}")
    checked = dict(chosen)
    if "lam" in chosen:
        checked["lam"] = check.non_negative("tune.chosen['lam']", chosen["lam"])
    elif not lam_given:
        raise ValueError(
            f"tune.chosen must hold 'lam' (a finite number >= 0) when lam is not given, got {dict(chosen)!r}; "
            "give lam, or pass the record of a tuned run (Tuning.from_params(result.params['tuning']))"
        )
    blend = tuning.blend
    if blend is not None:
        try:
            blend = check.in_range("tune.blend", blend, 0.0, 1.0)
        except ValueError:
            raise ValueError(f"tune.blend must be in [0, 1] or None, got {blend!r}") from None
    if type(checked.get("lam", 0.0)) is type(chosen.get("lam", 0.0)) and type(blend) is type(tuning.blend):
        return tuning
    return replace(tuning, chosen=checked, blend=blend)


def _made(reg: Regularizer, options: dict, what: str) -> None:
    """Make ``reg``'s kind with ``options`` over its values, so its own checks see them; ValueError
    naming ``what`` when they refuse."""
    try:
        type(reg)(**{**reg.values, **options})
    except ValueError as exc:
        raise ValueError(f"{what} is not an option value {reg.name!r} takes: {exc}") from None
