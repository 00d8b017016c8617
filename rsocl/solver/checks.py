"""Checks of a reconstruction's arguments beyond one value's range: several together, a callback's signature."""

from __future__ import annotations

from rsocl.common import validation as check

__all__ = ["check_blend", "check_callback"]


def check_blend(blend: float | None, has_start: bool) -> float | None:
    """``blend`` checked in [0, 1] (None: the search's choice, passes). A value below 1 moves the result
    towards the run's start, so it needs one (``has_start``: ``x0`` given, or the interpolation a
    self-tuned run starts from); a run from zeros refuses it."""
    if blend is None:
        return None
    blend = check.in_range("blend", blend, 0.0, 1.0)
    if blend < 1 and not has_start:
        raise ValueError(
            f"blend = {blend:g} moves the result towards the run's start, and this run starts from "
            "zeros (tune=False, or nothing left to choose from the data): give the start as x0 (an "
            "array or 'interp3d'), or leave blend None"
        )
    return blend


def check_callback(callback) -> None:
    """Refuse, before any work, a ``callback`` that cannot be called as ``callback(iteration, residual, theta)``."""
    import inspect

    if not callable(callback):
        raise ValueError(f"callback must be callable, got {callback!r}")
    try:
        signature = inspect.signature(callback)
    except (TypeError, ValueError):  # a builtin without one: called as it is
        return
    try:
        signature.bind(0, 0.0, None)
    except TypeError as exc:
        raise ValueError(f"callback must take (iteration, residual, theta), got {callback!r} ({exc})") from None
