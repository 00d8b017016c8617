"""Layer 7, an app: ``rsocl bench``, the speed/quality trade-off measured over sweeps of settings.

Modules: :mod:`~rsocl.bench.point` (one setting), :mod:`~rsocl.bench.measure` (one run),
:mod:`~rsocl.bench.memory`, the interpolation baseline :func:`rsocl.model.interpolation.interp3d`,
:mod:`~rsocl.bench.analysis` (Pareto front, picks), :mod:`~rsocl.bench.report` and
:mod:`~rsocl.bench.plots` (CSV, Markdown, PNG), :mod:`~rsocl.bench.run` (the sweep).
"""
