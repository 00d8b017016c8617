"""What the self-tuned default's parameter search costs on a rig, measured before the real run.

The search (:func:`rsocl.solver.pipeline.tune`) runs short ADMM runs of its candidates on held-out
folds of the snapshots; on a large frame only on a central block (:class:`rsocl.solver.ladder.Crop`).
Its work depends on the rig, the rung and the iterations, and only a little on the scene (how many
candidates the refinement adds), so :func:`search_seconds` times it on the built-in scene
(:func:`rsocl.model.scenes.builtin_scene`) seen by the rig, or by the block the search would cut:
a 1024x1280 frame costs the 48x48 block's search, never a datacube of the whole frame.
How close that comes to the search of a real run: ``docs/plan_search.md``.
"""

from __future__ import annotations

import time

from rsocl.common import validation as check
from rsocl.model.rig import Rig
from rsocl.model.scenes import builtin_scene
from rsocl.solver.ladder import DEFAULT_QUALITY, rung

__all__ = ["search_seconds", "WARM_ITERATIONS"]

#: Iterations of the untimed first search, which builds every program the timed one launches (a
#: candidate runs at least 10 iterations per fold whatever the run's count, so this is the cheapest).
WARM_ITERATIONS = 10


def search_seconds(
    rig: Rig,
    *,
    iterations: int = 200,
    regularizer="tv",
    regularizer_options=None,
    dtype="float32",
    device=None,
    quality: str = DEFAULT_QUALITY,
) -> float:
    """Wall time of the parameter search of ``rsocl.reconstruct(g, rig, ...)`` (the self-tuned default), seconds.

    The search of the ``quality`` rung, for a final run of ``iterations``, on the snapshots of the
    built-in scene seen by ``rig`` (on a frame the rung crops, by the central block the search cuts,
    with ``rig``'s own ``lam`` and ``eta``), staging included, timed after an untimed search of
    :data:`WARM_ITERATIONS` that builds the programs. What a run without a search (nothing left to
    choose) spends: about 0.

    Parameters
    ----------
    rig : Rig
    iterations : int
        ADMM iterations of the final run (the search runs a share of them per candidate), >= 1.
    regularizer, regularizer_options : str or Regularizer, dict or None
        As :func:`rsocl.reconstruct`: the search chooses the options a name leaves unset.
    dtype : {"float32", "float64"}
    device : str, Device or None
    quality : {"fast", "balanced", "best"}
        The rung (:mod:`rsocl.solver.ladder`).

    Returns
    -------
    float
        Seconds.

    Raises
    ------
    ValueError
        As :func:`rsocl.reconstruct` for the same arguments, naming the parameter.

    Examples
    --------
    >>> import rsocl
    >>> seconds = search_seconds(rsocl.Rig.paper_array(4, (16, 16)), iterations=20)
    >>> seconds > 0
    True
    """
    from rsocl.model.simulate import simulate
    from rsocl.solver.pipeline import prepare, tune_with
    from rsocl.solver.problem import check_problem
    from rsocl.solver.request import make_request

    iterations = check.positive_int("iterations", iterations)
    step = rung(quality)
    search, box = step.search_for(rig.shape)
    cut = rig if box is None else rig.crop(box)

    def request(n):  # the whole rig's request: its lam and eta, as the search of a real run has
        return make_request(
            rig,
            regularizer,
            regularizer_options=regularizer_options,
            iterations=n,
            dtype=dtype,
            device=device,
            quality=quality,
        )

    warm = request(min(WARM_ITERATIONS, iterations))
    g = simulate(builtin_scene(cut.shape, cut.T), cut, device=device, dtype=dtype)
    problem = check_problem(g, cut)
    tune_with(prepare(warm, problem), search)
    timed = request(iterations)
    start = time.perf_counter()
    tune_with(prepare(timed, problem), search)
    return time.perf_counter() - start
