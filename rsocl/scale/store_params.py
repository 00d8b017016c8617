"""Which parameters of a stored reconstruction differ from a run's: every one, for a store to be resumed,
or those the run knows before its parameter search (:func:`rsocl.scale.store.check_store`)."""

from __future__ import annotations

__all__ = ["NOT_COMPARED", "differing_params"]

#: parameters that may differ in a resumed store: the device, and the tuning record (its timing;
#: the values it chose are compared as ``lam`` and ``regularizer_options``)
NOT_COMPARED = ("device", "tuning")


def differing_params(stored: dict, run: dict, known_only: bool = False) -> list[str]:
    """``params.KEY`` for each parameter but :data:`NOT_COMPARED` in which ``stored`` (a store's ``params``)
    and ``run`` (a run's) differ, sorted.

    With ``known_only``, ``run`` holds only what the run knows yet: only its keys are compared, and of a
    dict (``regularizer_options``) only the entries it holds, each named ``params.KEY.ENTRY``.
    """
    keys = sorted(run) if known_only else sorted(set(stored) | set(run))
    differ = []
    for key in (k for k in keys if k not in NOT_COMPARED):
        old, new = stored.get(key), run.get(key)
        if known_only and isinstance(old, dict) and isinstance(new, dict):
            differ += [f"params.{key}.{entry}" for entry in sorted(new) if old.get(entry) != new[entry]]
        elif old != new:
            differ.append(f"params.{key}")
    return differ
