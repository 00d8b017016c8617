"""Running the ADMM iterations of a staged problem, and collecting the result.

:func:`run_iterations` books each iteration's residual (and PSNR with a ground truth) in a history, drives the
progress bar, the callback and the ``tol`` stop, raises on divergence and warns when the run ends unstable though
bounded; :func:`collect` reads the estimate back with what the run's ``params`` record about the data. For a batch
of sets every record is one value per set, and each set stops on its own under ``tol`` or ``iterations="auto"``: its
estimate is kept from the iteration at which it met the criterion, its later records are NaN, and the batch runs
until every set has stopped, so each set's result is its single-set run's.
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from rsocl.device.reduction import sum_sq_diff
from rsocl.solver.held import hold
from rsocl.solver.ladder import auto_settled
from rsocl.solver.stop import check_stop

__all__ = ["run_iterations", "collect"]


#: A run whose residual exceeds this many times the smallest one it had so far (or than 1, the
#: residual of a zero estimate, if that is larger) has diverged, though still finite.
GROWTH = 1e3
#: A run whose residual, over its first this many iterations (or all of a shorter run of at least 2),
#: stays within :data:`STALL_TOL` of its first value (which is above 0) with an ``eta`` above 4 times the
#: data term's largest curvature ``psi`` never moved: it raises. With a smaller ``eta`` (GAP's 0 among
#: them) the data step moves the estimate, and a residual that stays put is a fixed point: a result.
STALL_ITERATIONS = 10
#: Relative change of the residual under which a run counts as not moving.
STALL_TOL = 1e-6
#: A run that ends with a residual above 1 (its estimate explains the snapshots worse than zeros do)
#: and this many times the smallest residual it had is unstable though bounded: it gets a warning.
END_GROWTH = 10.0
#: A run with an ``eta`` above this many times the data term's largest curvature ``psi`` that ends with a
#: residual above :data:`FAR_RESIDUAL` moved too little to fit the data (the data step moves the estimate
#: by about ``psi / eta`` per iteration): it gets a warning. A run from a start that already fits the
#: snapshots ends below it, however little it moved.
FAR_ETA = 100.0
#: See :data:`FAR_ETA`: half of the snapshots' norm left unexplained.
FAR_RESIDUAL = 0.5


class _History:
    """Per-iteration records of a run; :meth:`record` says when the run should stop."""

    def __init__(self, solver, staged, settings, total_size, bar, auto=False):
        self.solver, self.staged, self.settings, self.bar, self.auto = solver, staged, settings, bar, auto
        self.total_size = total_size
        self.values = {"residual": [], "time": []}
        self.lowest = None
        self.stopped = None  # per set of a batch: the iteration at which it stopped (-1: running)
        self.kept: dict = {}  # a stopped set's estimate (host copy) at that iteration
        if staged.truth is not None:
            self.values["psnr"] = []
        self.start = time.perf_counter()

    def _grown(self, residual):
        """Where ``residual`` (one per set) is not finite or beyond :data:`GROWTH` times the smallest so far:
        a bool for one set's float (in plain Python: it runs every iteration), else a bool array."""
        if isinstance(residual, float):
            finite, lowest = math.isfinite(residual), self.lowest
            if lowest is None:
                self.lowest = residual if finite else math.inf
                return not finite
            if residual < lowest:  # as np.fmin: a NaN leaves the smallest as it is
                self.lowest = residual
            return not finite or residual > GROWTH * max(lowest, 1.0)
        residual = np.asarray(residual, dtype=np.float64)
        bad = ~np.isfinite(residual)
        if self.lowest is not None:
            bad |= residual > GROWTH * np.maximum(self.lowest, 1.0)
            self.lowest = np.fmin(self.lowest, residual)
        else:
            self.lowest = np.where(np.isfinite(residual), residual, np.inf)
        return bad

    def _hint(self) -> str:
        if self.settings.projection == "paper":
            psi = float(self.staged.op.psi.max())
            return (
                " The paper's diagonal step (projection='paper') is stable only when eta is large "
                f"against psi (max psi = {psi:.3g}); use projection='exact' or raise eta."
            )
        return " Check lam, eta and the data scale."

    def check_end(self):
        """Warn when the last residual (per set) is above 1 and :data:`END_GROWTH` times the smallest:
        the run stayed finite and below :data:`GROWTH` but ended far from the data."""
        if not self.values["residual"]:
            return
        last = self._last()
        lowest = np.atleast_1d(np.asarray(self.lowest, dtype=np.float64))
        bad = (last > 1.0) & (last > END_GROWTH * lowest)
        if not bad.any():
            return
        where = f" in set(s) {np.flatnonzero(bad).tolist()}" if np.ndim(self.values["residual"][-1]) else ""
        warnings.warn(
            f"ADMM ended unstable{where}: the last residual {_listed(last[bad], 4)} is above 1 "
            "(the snapshots are fitted worse than by zeros) and more than "
            f"{END_GROWTH:g} times the smallest of the run, {_listed(lowest[bad], 4)}; "
            f"the result does not reconstruct the data.{self._hint()}",
            RuntimeWarning,
            stacklevel=4,
        )

    def check_far(self):
        """Warn when a set's ``eta`` is above :data:`FAR_ETA` times ``psi`` and its last residual is above
        :data:`FAR_RESIDUAL`: the run stayed far from the data because its data step barely moved."""
        if not self.values["residual"]:
            return
        last = self._last()
        if not np.any(last > FAR_RESIDUAL):  # psi (a launch and a read) only for a run that ended far
            return
        psi = float(np.max(self.staged.op.psi))
        eta = np.atleast_1d(np.asarray(self.solver.eta, dtype=np.float64))
        far = (eta > FAR_ETA * psi) & (last > FAR_RESIDUAL)
        if not far.any():
            return
        where = f" in set(s) {np.flatnonzero(far).tolist()}" if np.ndim(self.values["residual"][-1]) else ""
        warnings.warn(
            f"ADMM ended far from the data{where}: the residual is {_listed(last[far], 4)} after "
            f"{self._ran(far)} iterations with eta = {_listed(eta[far], 6)}, over "
            f"{FAR_ETA:g} times the data term's curvature (psi up to {psi:.3g}): each iteration moves the "
            f"estimate by about psi/eta; choose eta up to about 4 psi = {4 * psi:.3g} (leave eta and lam out "
            "for the defaults)",
            RuntimeWarning,
            stacklevel=4,
        )

    def _ran(self, which) -> str:
        """The iterations the sets ``which`` (a bool per set) ran, each to its own stop: ``"12"`` or ``"[2, 26]"``."""
        ran = np.full(np.shape(which), len(self.values["residual"]))
        if self.stopped is not None:
            ran = np.where(self.stopped >= 0, self.stopped + 1, ran)
        ran = np.atleast_1d(ran)[np.atleast_1d(which)].tolist()
        return str(ran[0]) if len(set(ran)) == 1 else str(ran)

    def _last(self) -> np.ndarray:
        """Each set's last booked residual (one value for one set), float64."""
        if self.stopped is not None:
            return np.array([self.values["residual"][row][i] for i, row in enumerate(self.stopped)], dtype=np.float64)
        return np.atleast_1d(np.asarray(self.values["residual"][-1], dtype=np.float64))

    def check_stall(self, final=False):
        """Raise ``FloatingPointError`` when the residual (per set) has not moved by :data:`STALL_TOL` from
        its first value over :data:`STALL_ITERATIONS` records (``final``: over a shorter whole run of >= 2)
        and that set's ``eta`` is above 4 ``psi`` (:data:`STALL_ITERATIONS`)."""
        count = len(self.values["residual"])
        if count != STALL_ITERATIONS and not (final and 2 <= count < STALL_ITERATIONS):
            return
        res = np.asarray(self.values["residual"], dtype=np.float64)
        first = res[0]
        # a set of a batch that stopped (tol, auto) has NaN records after its stop: its own records decide,
        # as they would in its single-set run (which checks a shorter whole run of >= 2 at its end)
        booked = ~np.isnan(res)
        moved = booked & (np.abs(res - first) > STALL_TOL * first)
        still = ~np.any(moved, axis=0) & (np.sum(booked, axis=0) >= 2) & (first > 0)
        if not np.any(still):  # psi (a launch and a read) only for a residual that stood still
            return
        psi = float(np.max(self.staged.op.psi))
        # the fault named below: eta far above the curvature; with a smaller eta a still residual is a fixed point
        still &= np.asarray(self.solver.eta, dtype=np.float64) > 4 * psi
        if not np.any(still):
            return
        count = int(np.max(np.atleast_1d(np.sum(booked, axis=0))[np.atleast_1d(still)]))
        where = f" in set(s) {np.flatnonzero(still).tolist()}" if np.ndim(first) else ""

        def shown(values):
            return ", ".join(f"{float(v):.6g}" for v in np.atleast_1d(values))

        low = f"from about psi/2 = {psi / 2:.3g} " if self.settings.projection == "paper" else ""
        raise FloatingPointError(
            f"ADMM never moved{where}: the residual stayed at [{shown(np.atleast_1d(first)[np.atleast_1d(still)])}] "
            f"over {count} iterations with eta = {shown(self.solver.eta)} and lam = {shown(self.solver.lam)}: an eta "
            f"far above the data term's curvature (psi up to {psi:.3g}) leaves the data step at zero; choose eta "
            f"{low}up to about 4 psi = {4 * psi:.3g} (leave eta and lam out for the defaults)"
        )

    def _diverged(self, it, residual, bad):
        hint = self._hint()
        lowest = self.lowest
        why = f" (more than {GROWTH:g} times the smallest residual so far, or than 1, the residual of a zero estimate)"
        if np.ndim(residual):
            sets = np.flatnonzero(bad).tolist()
            return FloatingPointError(
                f"ADMM diverged at iteration {it + 1} in set(s) {sets}: the residuals are "
                f"{np.asarray(residual)[sets].tolist()}{why}, the smallest so far "
                f"{np.asarray(lowest)[sets].tolist()}.{hint}"
            )
        return FloatingPointError(
            f"ADMM diverged at iteration {it + 1}: the residual is {residual}{why}, the "
            f"smallest so far {float(lowest):.3g}.{hint}"
        )

    def _psnr(self):
        staged, solver = self.staged, self.solver
        sets = solver.sets if solver.batched else None
        mse = sum_sq_diff(solver.theta, staged.truth, sets=sets)
        if staged.held:
            mse = mse + staged.held(solver.theta)
        mse = mse / self.total_size
        with np.errstate(divide="ignore"):
            db = 10 * np.log10(np.asarray(staged.data_range, dtype=np.float64) ** 2 / np.asarray(mse))
        return np.where(np.asarray(mse) > 0, db, math.inf) if sets else (float(db) if mse > 0 else math.inf)

    def blend(self, alpha):
        """Move the estimate towards the run's start by ``alpha`` and book the result as the last record."""
        self.solver.blend_towards(self.staged.x0, alpha)
        self.rebook()

    def rebook(self):
        """Book the estimate as it is now as the last record (its residual, and PSNR with a truth); for a
        batch whose sets stopped at different iterations, each set's own last record."""
        for key, value in (("residual", self.solver.residual), ("psnr", self._psnr)):
            if key not in self.values:
                continue
            if self.stopped is None:
                self.values[key][-1] = value()
                continue
            now = np.asarray(value(), dtype=np.float64)
            for i, row in enumerate(self.stopped):
                booked = np.array(self.values[key][row], dtype=np.float64)
                booked[i] = now[i]
                self.values[key][row] = booked

    def record(self, it, residual) -> bool:
        """Book iteration ``it``'s residual (one per set for a batch); True when the run should stop after it.
        Raises :class:`~rsocl.solver.stop.Stopped` where the thread's stop event is set."""
        check_stop()
        if self.stopped is not None:  # the sets that stopped before are not booked (NaN) nor checked
            residual = np.where(self.stopped >= 0, np.nan, residual)
        bad = self._grown(residual)
        if self.stopped is not None:
            bad = bad & (self.stopped < 0)
        if bad.any() if isinstance(bad, np.ndarray) else bad:
            raise self._diverged(it, residual, bad)
        values, settings = self.values, self.settings
        values["residual"].append(residual)
        self.check_stall()
        elapsed = time.perf_counter() - self.start
        one = isinstance(residual, float) or not np.ndim(residual)
        values["time"].append(elapsed if one else np.full(np.shape(residual), elapsed))
        if self.staged.truth is not None:
            psnr = self._psnr()
            values["psnr"].append(psnr if self.stopped is None else np.where(self.stopped >= 0, np.nan, psnr))
        if self.bar is not None:
            self.bar.update(1)
            extra = {"psnr": f"{np.nanmin(values['psnr'][-1]):.2f}"} if "psnr" in values else {}
            self.bar.set_postfix(residual=f"{np.nanmax(residual):.3g}", **extra)
        if settings.callback is not None and settings.callback(it, residual, self.solver.theta):
            return True
        if settings.tol is None and not self.auto:
            return False
        met = auto_settled(values["residual"]) if self.auto else False
        if settings.tol is not None and it > 0:
            change = np.abs(np.asarray(values["residual"][-2]) - residual)
            met = met | (change <= settings.tol * np.maximum(residual, np.finfo(float).tiny))
        return bool(met) if np.ndim(met) == 0 else self._stop_sets(it, met)

    def _stop_sets(self, it, met) -> bool:
        """Keep the estimates of the sets of a batch that met the stop criterion at iteration ``it`` for the
        first time (:meth:`restore` puts them back); True when every set has stopped."""
        if self.stopped is None:
            self.stopped = np.full(np.shape(met), -1)
        new = np.flatnonzero(met & (self.stopped < 0))
        if new.size and not np.all((self.stopped >= 0) | met):  # others run on: keep these estimates
            theta = self.solver.theta
            for i in new:
                self.kept[int(i)] = theta[int(i)].get()
        self.stopped[new] = it
        return bool(np.all(self.stopped >= 0))

    def restore(self):
        """Put back the kept estimates of the sets of a batch that stopped before the last ones."""
        theta = self.solver.theta if self.kept else None
        for i, kept in self.kept.items():
            theta[i].set(kept)
        self.kept = {}


def _listed(values, digits: int) -> str:
    """``values`` rounded to ``digits`` decimals: one value as a number, several as a list."""
    return f"{r[0]:g}" if len(r := np.round(np.atleast_1d(values), digits).tolist()) == 1 else str(r)


def run_iterations(solver, staged, settings, *, progress=False, blend=None, auto=False, fix=None) -> dict:
    """Run up to ``settings.iterations`` ADMM steps; the history as a dict of arrays.

    With ``auto`` the run stops once its residual has settled (:func:`rsocl.solver.ladder.auto_stop`);
    ``fix(solver)``, when given, changes the estimate last (the static-part fix), and the last record
    is that of the estimate it leaves.

    With nothing to look at ``theta`` between iterations (no callback, no truth, no tol), the
    residuals stay on the device (each computed in the next iteration's projection) and are read a
    group at a time (:func:`_run_pipelined`) while the device runs the next group: the host never
    waits on an idle device, and a divergence is raised a group or two after the iteration that
    diverged. With ``blend`` below 1 the estimate is then moved back towards the run's start
    ``staged.x0`` (:meth:`~rsocl.solver.admm.ADMM.blend_towards`), and the last record's residual
    and PSNR are those of the returned estimate.
    """
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(
            total=settings.iterations,
            desc=f"ADMM-{solver.regularizer.name}",
            unit="it",
            leave=False,
            mininterval=0.5,
            disable=None,
        )
    rig = staged.op.rig
    history = _History(solver, staged, settings, rig.T * rig.shape[0] * rig.shape[1], bar, auto)
    if solver.batched and bar is not None:
        bar.set_description(f"ADMM-{solver.regularizer.name}, {solver.sets} sets")
    pipelined = settings.callback is None and staged.truth is None and settings.tol is None and not auto
    staged.op.queue.finish()
    history.start = time.perf_counter()
    try:
        if pipelined:
            _run_pipelined(solver, history, settings.iterations)
        else:
            for it in range(settings.iterations):
                solver.step()
                if history.record(it, solver.residual_async().result()):
                    break
        history.restore()
        history.check_stall(final=True)
        history.check_end()
        history.check_far()
        if blend is not None and blend < 1 and history.values["residual"]:
            history.blend(blend)
        if fix is not None and history.values["residual"] and fix(solver):
            history.rebook()
    finally:
        if bar is not None:
            bar.close()
    return {k: np.asarray(v) for k, v in history.values.items()}


def _run_pipelined(solver, history, iterations):
    """The iterations of a run that does not look at each residual: every iteration's residual goes to
    a device slot, computed by the next iteration's projection (the last one's by a launch of its
    own); the slots are read in one copy every ``solver.residuals.slots`` iterations, and each copy is
    waited for only after the next group of iterations is enqueued."""
    slots = solver.residuals.slots
    pending = None  # (first iteration, residuals on their way)

    def read(last):  # the residuals of the group that ends with iteration `last` are in their slots
        nonlocal pending
        current = (last - last % slots, solver.read_residuals(last % slots + 1))
        if pending is not None:
            _book(history, *pending)
        pending = current

    for it in range(iterations):
        solver.step(residual_slot=None if it == 0 else (it - 1) % slots)
        if it > 0 and it % slots == 0:
            read(it - 1)
    if iterations > 0:
        solver.residual_into((iterations - 1) % slots)
        read(iterations - 1)
    if pending is not None:
        _book(history, *pending)


def _book(history, first, pending):
    for i, residual in enumerate(pending.result()):
        history.record(first + i, residual)


def collect(solver, staged, problem) -> tuple:
    """``(datacube, record)``: the estimate read back (sub-frames outside the solved ones hold the
    nearest solved one: :mod:`rsocl.solver.held`), checked finite, and what the run's ``params`` add
    about the data: ``saturated_pixels`` (one count per set for a batch), ``solved_subframes`` and,
    for a batch, ``sets``."""
    solved, rig = staged.solved, problem.rig
    batch = () if problem.batch is None else (problem.batch,)
    datacube = hold(solver.theta.get(), solved, rig.T)
    finite = np.isfinite(datacube).reshape(problem.batch or 1, -1).all(axis=1)
    if not finite.all():
        where = "" if not batch else f" in set(s) {np.flatnonzero(~finite).tolist()}"
        raise FloatingPointError(f"the reconstruction produced NaN or inf{where}; check lam/eta and the data scale")
    valid = problem.valid
    sets = problem.batch or 1
    saturated = np.zeros(sets, int) if valid is None else (~valid).reshape(sets, -1).sum(axis=1)
    record = {
        "saturated_pixels": saturated.tolist() if batch else int(saturated.sum()),
        "solved_subframes": [solved.start, solved.stop],
    }
    if batch:
        record["sets"] = problem.batch
    return datacube, record
