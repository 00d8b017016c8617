"""The settings every task of a tiled run gets, and the run's ``params`` record: in full once the
parameter search has chosen (:func:`tile_settings`), or the part known before it (:func:`known_params`),
which an existing store is checked against before the input is read."""

from __future__ import annotations

import numpy as np

from rsocl.device.context import Device
from rsocl.scale.tiles import TileGrid
from rsocl.scale.tuning_tile import tuning_crop
from rsocl.scale.work import TileSettings
from rsocl.solver.holdout import can_hold_out
from rsocl.solver.pipeline import Request, Tuning, applied_blend, run_params

__all__ = ["tile_settings", "known_params"]


def tile_settings(request: Request, tuning: Tuning | None, saturation) -> tuple[TileSettings, dict]:
    """Every task's :class:`~rsocl.scale.work.TileSettings` and the run's ``params``
    (:func:`~rsocl.solver.request.run_params`), with ``tuning``'s choice (None: as requested)."""
    reg, settled = request.settled(tuning)
    options = {**request.given.options, **request.tuned_options(tuning)}
    start = "zeros" if tuning is None else "interp3d"
    blend = applied_blend(tuning) if request.blend is None else request.blend
    device = request.device
    assert settled.lam is not None and settled.eta is not None  # a Request's settings are settled
    settings = TileSettings(
        request.name,
        options,
        settled.iterations,
        settled.lam,
        settled.eta,
        settled.tv_iterations,
        settled.projection,
        str(np.dtype(request.dtype)),
        saturation,
        device,
        start,
        blend,
        request.quality,
    )
    params = run_params(
        request,
        reg,
        settled,
        lam=settled.lam,
        eta=settled.eta,
        device=device.name if isinstance(device, Device) else device,
        saturation=saturation,
        tuning=tuning,
        blend=blend,
        start=start,
    )
    return settings, params


def known_params(request: Request, saturation, grid: TileGrid) -> dict:
    """The entries of :func:`tile_settings`'s ``params`` known before the search, as they will be.

    Without a search (``tune`` False, an earlier :class:`~rsocl.solver.crossval.Tuning`, or nothing left
    to choose) every entry is; with one, not the entries it may choose: ``lam`` (unless given), the
    ``blend`` (unless given), and the regularizer options the caller left unset (``regularizer_options``
    holds the given ones only); the ``start`` is the interpolation's where every block of ``grid`` the
    search may run on (:mod:`rsocl.scale.tuning_tile`) holds pixels out, else not known. Left out too:
    ``dtype`` (a store's own attribute), ``device`` and ``tuning`` (never compared).
    """
    searches = request.tune is True and request.search_space() is not None
    _, params = tile_settings(request, request.tune if isinstance(request.tune, Tuning) else None, saturation)
    unknown = {"dtype", "device", "tuning"}
    if searches:
        unknown |= {k for k, v in (("lam", request.given.lam), ("blend", request.blend)) if v is None}
        given = request.given.option_names(request.regularizer)
        params["regularizer_options"] = {k: v for k, v in params["regularizer_options"].items() if k in given}
        blocks = {tuning_crop(grid).outer_shape} | {tile.outer_shape for tile in grid}
        if all(can_hold_out(shape, request.rig.n_channels) for shape in blocks):
            params["start"] = "interp3d"  # the search chooses (a Tuning), and every tile starts from there
        else:
            unknown.add("start")  # a block without pixels to hold out: the search may choose nothing
    return {k: v for k, v in params.items() if k not in unknown}
