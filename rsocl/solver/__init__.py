"""Layer 5, the solver: the regularizer contract, the ADMM iteration on the device,
:func:`~rsocl.solver.reconstruct.reconstruct` (what a user runs) and the memory/time planner.

A run is a :class:`~rsocl.solver.request.Request` (:func:`~rsocl.solver.request.make_request`: what
to reconstruct and how, checked once) through :mod:`rsocl.solver.pipeline`'s ``prepare`` -> ``tune``
-> ``run``; :mod:`rsocl.solver.sets` runs many sets in batches, :mod:`rsocl.solver.memory` counts
the device memory of every run, :mod:`rsocl.solver.crossval` is the parameter search on the hold-out
patterns of :mod:`rsocl.solver.holdout`. The measurements behind the defaults: ``docs/solver-notes.md``.

Imports the layers below it (common, device, model, analysis).
"""
