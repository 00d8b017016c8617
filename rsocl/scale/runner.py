"""Running tile tasks: on Dask's local scheduler, on a dask.distributed cluster, or in this process.

* Default: Dask's local (threaded) scheduler, nothing to start. It runs one task at a time:
  this process has one device, each task keeps it busy (a kernel uses every compute unit), and
  two solvers must not launch on one device at once.
* ``scheduler="ADDRESS"`` (or the ``RSOCL_SCHEDULER`` environment variable): a running
  ``dask.distributed`` scheduler. It is connected to before anything is computed; an
  unreachable address is a ValueError naming ``scheduler`` (or ``RSOCL_SCHEDULER``, where that gave
  it). Its workers must be able to import rsocl and, for file inputs and Zarr output, see the same
  paths. A worker of several threads runs one task at a time all the same (:data:`ONE_TASK`): a tile
  is sized to have the device to itself, and the warnings a task raises are noted as its own.
* ``workers=N``: a ``LocalCluster`` of ``N`` worker processes (one thread each) on 127.0.0.1,
  closed at the end; ``N`` is at most :func:`max_workers`, :data:`WORKERS_PER_CORE` per CPU core
  this process may run on (each worker is a Python process with its own OpenCL context).
* Without Dask installed, the tasks run in this process, one after another.

A task that raises is retried (``retries`` more times: Dask's own retries on a cluster, a loop
here otherwise); a task still failing is reported as a :class:`Failure` with its tile, set and
cause, and the other tasks' results are kept. A cluster worker that dies (killed, out of
memory) has its task run again on another worker by Dask.
"""

from __future__ import annotations

import contextlib
import logging
import numbers
import os
import signal
import threading
import uuid
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from rsocl.scale.work import solve_tile

__all__ = [
    "SCHEDULER_ENV",
    "RETRIES",
    "WORKERS_PER_CORE",
    "Failure",
    "Engine",
    "have_dask",
    "max_workers",
    "non_negative_int",
]

#: Environment variable read when no ``scheduler`` is given.
SCHEDULER_ENV = "RSOCL_SCHEDULER"
#: Extra attempts of a failing task (a tile), by default.
RETRIES = 2
#: Seconds allowed to reach a scheduler.
CONNECT_TIMEOUT = 10
#: Local worker processes allowed per CPU core: more only queue for the cores (each task keeps
#: its device busy), while each one costs a process, a Dask worker and an OpenCL context.
WORKERS_PER_CORE = 4


def max_workers() -> int:
    """The most worker processes of a local cluster: :data:`WORKERS_PER_CORE` times the CPU cores
    this process may run on (its affinity mask where the platform has one, else ``os.cpu_count()``)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return WORKERS_PER_CORE * max(1, cores)


def have_dask() -> bool:
    """Whether ``dask`` and ``distributed`` are importable."""
    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class Failure:
    """A task that failed on every attempt: ``label`` names its tile and set, ``cause`` the last error."""

    set_index: int | None
    index: tuple
    label: str
    attempts: int
    cause: str

    def __str__(self):
        return f"{self.label} failed after {self.attempts} attempt(s): {self.cause}"


def _check_address(address, name="scheduler"):
    """ValueError naming ``name`` (``scheduler``, or the environment variable that gave it) unless ``address``
    parses as a scheduler address (``tcp://host:port``, ``host:port``, another dask scheme). Checked before any
    connection: a ``distributed.Client`` that fails in its constructor on a malformed address spends 20 s
    closing itself when it is collected."""
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        if not isinstance(address, str):
            raise TypeError(f"a {type(address).__name__}")
        scheme, location = parse_address(address)
        if scheme in ("tcp", "tls", "ws", "wss"):
            parse_host_port(location)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"{name} must be the address of a dask.distributed scheduler, tcp://host:port (or "
            f"host:port), got {address!r} ({exc})"
        ) from None


@contextlib.contextmanager
def _sigint_ignored():
    """SIGINT ignored while the block runs (in the main thread; elsewhere the block runs as it is).

    Processes started in the block inherit the ignored disposition (an ignored signal stays ignored
    across ``exec``, and Python then installs no handler of its own): a local cluster's worker processes
    never receive the terminal's Ctrl-C, which reaches the whole process group, so only this process
    ends the run, in one line, closing the cluster itself. A Ctrl-C while the cluster starts (seconds) is
    not seen.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _cause(exc) -> str:
    return f"{type(exc).__name__}: {exc}"


def _attempts(job, payload, settings, retries, stop=None):
    """``solve_tile`` tried up to ``retries + 1`` times: the Piece, or a Failure; None once ``stop`` (a
    ``threading.Event``) is set: the run in progress ends at its next booking
    (:func:`rsocl.solver.stop.stopping`) and no attempt follows."""
    from rsocl.solver.stop import Stopped, stopping

    for _attempt in range(retries + 1):
        if stop is not None and stop.is_set():
            return None
        try:
            with stopping(stop):
                return solve_tile(job, payload, settings)
        except Stopped:
            return None
        except Exception as exc:  # noqa: BLE001 - any cause is reported with the tile
            last = exc
    return Failure(job.set_index, job.tile.index, job.label, retries + 1, _cause(last))


#: Held by a cluster worker's task while it runs: one task at a time per worker process, whatever its threads
#: (``dask worker`` starts one per core). Each tile's size was chosen for a device of its own, and
#: ``warnings.catch_warnings``, which notes a task's warnings, swaps process-wide state that two threads
#: inside it at once would leave swapped (every later warning of the worker lost).
ONE_TASK = threading.Lock()


def _solve_noting_warnings(job, payload, settings):
    """``solve_tile`` on a cluster's worker: ``(piece, warned)``, ``warned`` the ``(category, message)`` of each
    warning the task raised, which the client raises again (a worker's own stderr shows them raw, once per
    task). Tasks of one worker process run one at a time (:data:`ONE_TASK`)."""
    with ONE_TASK, warnings.catch_warnings(record=True) as caught:  # the worker's filters apply, as to stderr
        piece = solve_tile(job, payload, settings)
    return piece, tuple(dict.fromkeys((w.category, str(w.message)) for w in caught))


class Engine:
    """Where the tasks run; a context manager that starts (and stops) what it needs.

    Parameters
    ----------
    scheduler : str or None
        Address of a running ``dask.distributed`` scheduler (``tcp://host:port``); None reads
        ``RSOCL_SCHEDULER``, and an empty value means none.
    workers : int or None
        Start a ``LocalCluster`` of this many worker processes on 127.0.0.1: 1 to
        :func:`max_workers` (4 per CPU core).
    """

    def __init__(self, scheduler=None, workers=None):
        name = "scheduler"  # what the messages name: the argument, or the environment variable the user set
        if scheduler is None:
            scheduler = os.environ.get(SCHEDULER_ENV) or None
            name = SCHEDULER_ENV if scheduler is not None else name
        if workers is not None:
            cap = max_workers()
            if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or not 1 <= workers <= cap:
                raise ValueError(
                    f"workers must be an integer in [1, {cap}] (a local cluster of at most "
                    f"{WORKERS_PER_CORE} worker processes per CPU core, {cap // WORKERS_PER_CORE} "
                    f"core(s) here), got {workers!r}"
                )
            workers = int(workers)
        if scheduler is not None and workers is not None:
            if name == SCHEDULER_ENV:
                raise ValueError(
                    f"workers asks for a local cluster of {workers} while {SCHEDULER_ENV}={scheduler!r} names a "
                    f"running one: unset {SCHEDULER_ENV}, or leave out workers"
                )
            raise ValueError(
                f"give scheduler (a running cluster, here {scheduler!r}) or workers (a local "
                f"cluster of {workers}), not both"
            )
        if (scheduler is not None or workers is not None) and not have_dask():
            what = name if scheduler is not None else "workers"
            raise ValueError(f"{what}: running on a Dask cluster needs dask[distributed]: pip install 'rsocl[dask]'")
        if scheduler is not None:
            _check_address(scheduler, name)
        self.scheduler, self.workers, self._name = scheduler, workers, name
        self.mode = "distributed" if scheduler or workers else ("local" if have_dask() else "process")
        self.client = self.cluster = None

    # ------------------------------------------------------------------ start / stop
    def __enter__(self):
        if self.mode != "distributed":
            return self
        from distributed import Client, LocalCluster

        if self.workers is not None:
            with _sigint_ignored():  # the workers started here never see the terminal's Ctrl-C
                self.cluster = LocalCluster(
                    n_workers=self.workers,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address="127.0.0.1:0",
                    silence_logs=logging.ERROR,
                )
            self.client = Client(self.cluster)
        else:
            try:
                self.client = Client(self.scheduler, timeout=f"{CONNECT_TIMEOUT}s")
            except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, ValueError on a bad address
                unset = f"unset {SCHEDULER_ENV}" if self._name == SCHEDULER_ENV else "leave scheduler unset"
                raise ValueError(
                    f"{self._name}: cannot reach a dask.distributed scheduler at {self.scheduler!r} "
                    f"({_cause(exc)}); start one (dask scheduler) or {unset} for the local scheduler"
                ) from None
        return self

    def __exit__(self, kind, *exc):
        quiet = contextlib.nullcontext()
        if self.mode == "distributed" and kind is not None and not issubclass(kind, Exception):
            from distributed.utils import silence_logging_cmgr

            # interrupted (Ctrl-C, SIGTERM): what the scheduler says of the tasks cut short is not news
            quiet = silence_logging_cmgr(logging.CRITICAL)
        with quiet:
            if self.client is not None:
                self.client.close()
            if self.cluster is not None:
                self.cluster.close()
        self.client = self.cluster = None
        return False

    @property
    def description(self) -> str:
        if self.mode == "process":
            return "this process"
        if self.mode == "local":
            return "Dask's local scheduler"
        if self.workers is not None:
            return f"a LocalCluster of {self.workers} worker processes"
        return f"the dask.distributed scheduler at {self.scheduler}"

    # ------------------------------------------------------------------ running
    def run(self, jobs, payload, settings, *, retries=RETRIES, progress=False, desc="tiles"):
        """Run every job; ``(pieces, failures)`` in completion order."""
        retries = non_negative_int("retries", retries)
        bar = None
        if progress:
            from tqdm.auto import tqdm

            bar = tqdm(total=len(jobs), desc=desc, unit="task", disable=None)
        try:
            if self.mode == "distributed":
                return self._run_distributed(jobs, payload, settings, retries, bar)
            if self.mode == "local":
                return self._run_local(jobs, payload, settings, retries, bar)
            return self._split(_tick(bar, _attempts(job, payload, settings, retries)) for job in jobs)
        finally:
            if bar is not None:
                bar.close()

    @staticmethod
    def _split(outcomes):
        pieces, failures = [], []
        for outcome in outcomes:
            if outcome is not None:  # None: a task stopped by an interrupt (:func:`_attempts`)
                (failures if isinstance(outcome, Failure) else pieces).append(outcome)
        return pieces, failures

    def _run_local(self, jobs, payload, settings, retries, bar):
        import dask
        from dask.callbacks import Callback

        token, stop = uuid.uuid4().hex[:8], threading.Event()
        tasks = [
            dask.delayed(_attempts, pure=False)(
                job, payload, settings, retries, stop, dask_key_name=f"rsocl-tile-{token}-{i}"
            )
            for i, job in enumerate(jobs)
        ]

        class Bar(Callback):
            def _posttask(self, key, result, dsk, state, worker_id):
                if bar is not None and str(key).startswith("rsocl-tile-"):
                    bar.update(1)

        # the task's thread is rsocl's: an interrupt of this (main) thread stops the task in progress and
        # waits for it, so that what the store holds is settled before the interrupt is said
        name = f"rsocl-tiles-{token}"
        pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)
        try:
            with Bar():
                outcomes = dask.compute(*tasks, scheduler="threads", pool=pool)
        except BaseException:
            stop.set()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
            for thread in threading.enumerate():  # one the interrupt came upon before the pool booked it too
                if thread.name.startswith(name):
                    thread.join()
        return self._split(outcomes)

    def _run_distributed(self, jobs, payload, settings, retries, bar):
        from distributed import as_completed

        client = self.client
        shared = client.scatter(payload, broadcast=True, hash=False)
        token = uuid.uuid4().hex[:8]
        futures = {
            client.submit(
                _solve_noting_warnings,
                job,
                shared,
                settings,
                key=f"rsocl-tile-{token}-{i}",
                retries=retries,
                pure=False,
            ): job
            for i, job in enumerate(jobs)
        }
        pieces, failures, said = [], [], {}
        for future in as_completed(futures):
            job = futures[future]
            try:
                piece, warned = future.result()
                pieces.append(piece)
                said.update(dict.fromkeys(warned))
            except Exception as exc:  # noqa: BLE001 - reported with the tile
                failures.append(Failure(job.set_index, job.tile.index, job.label, retries + 1, _cause(exc)))
            _tick(bar, None)
        for category, message in said:  # in this process, once each, where the caller shows warnings
            warnings.warn(message, category, stacklevel=4)
        return pieces, failures


def _tick(bar, value):
    if bar is not None:
        bar.update(1)
    return value


def non_negative_int(name, value) -> int:
    """``value`` as an int >= 0; ValueError naming ``name``."""
    try:
        ok = int(value) == float(value) and int(value) >= 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"{name} must be a whole number >= 0, got {value!r}")
    return int(value)
