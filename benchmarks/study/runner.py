"""Run studies: chunks of trials sent to an executor, results streamed to disk, resumable.

Every trial is seeded from (scenario seed, trial index), so results do not
depend on the executor (in-process, process pool, Dask), the worker count or
the chunking. Results stream to ``DIR/results.jsonl`` (one JSON object per
trial, flushed as chunks complete); an interrupted run loses nothing already
written and ``resume=True`` finishes it without redoing finished trials.
"""

from __future__ import annotations

import contextlib
import logging
import os
import platform
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import ClusterError, ResultsError
from benchmarks.study.results import (
    LOCK_FILE,
    RESULTS_FILE,
    TRIALS_DIR,
    ResultsWriter,
    completed_keys,
    deduplicate,
    read_results,
    run_lock,
    trial_key,
)
from benchmarks.study.scenario import Scenario

#: The results-directory names are re-exported from :mod:`benchmarks.study.results`.
__all__ = [
    "LOCK_FILE", "RESULTS_FILE", "TRIALS_DIR", "ResultsWriter", "WorkUnit", "backend_factory",
    "completed_keys", "deduplicate", "execute", "machine_info", "plan", "read_results",
    "run_lock", "run_units", "trial_key",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class WorkUnit:
    """A chunk of trials of one scenario point and one controller.

    Attributes:
        scenario: The expanded scenario (one sweep point).
        point: Index of the sweep point within its scenario.
        controller_index: Index into ``scenario.controllers``.
        trials: Trial indices.
        record_trials: Trials below this index keep their time series.
        backend: Backend spec (``"sim"``, ``"emulator"``, ``"serial:URL"``, a plugin's).
        engine: ``"batched"`` (default) or ``"per-trial"`` (:func:`benchmarks.sim.run_trials`).
    """

    scenario: Scenario
    point: int
    controller_index: int
    trials: tuple[int, ...]
    record_trials: int = 2
    backend: str = "sim"
    engine: str = "batched"

    @property
    def controller(self) -> str:
        """The controller label."""
        return self.scenario.controllers[self.controller_index].label

def plan(scenarios: list[Scenario], chunk_size: int = 25, record_trials: int = 2,
         done: set[tuple[str, int, str, int]] | None = None, backend: str = "sim",
         engine: str = "batched") -> list[WorkUnit]:
    """Split studies into work units, leaving out trials already done."""
    done = done or set()
    units = []
    for sc in scenarios:
        for p, point in enumerate(sc.expand()):
            for c, spec in enumerate(point.controllers):
                todo = [k for k in range(point.trials)
                        if (point.name, p, spec.label, k) not in done]
                for a in range(0, len(todo), chunk_size):
                    units.append(WorkUnit(point, p, c, tuple(todo[a:a + chunk_size]),
                                          record_trials, backend, engine))
    return units


def backend_factory(spec: str) -> Callable[..., Any] | None:
    """Build the per-trial backend factory of a ``--backend`` spec.

    ``"sim"``: None (exact integration in the simulator, vectorised over trials).
    Anything else is a spec of :mod:`hexapod.backends.registry` (``emulator``,
    ``serial:URL``, a plugin's ``NAME[:ARGS]`` or ``module:attr[:ARGS]``): every trial
    opens its backend at the trial's start lengths and closes it at the end.

    Raises:
        UnknownBackendError: An unknown name (with the close one).
        BackendPluginError: A ``module:attr`` that cannot be imported or is no backend.
    """
    if spec == "sim":
        return None
    from hexapod.backends.registry import backends

    backends.check(spec)

    def factory(geometry: Any, lengths: np.ndarray) -> Any:
        return backends.open(spec, geometry, lengths)

    return factory


def execute(unit: WorkUnit, on_step: Callable[..., None] | None = None
            ) -> tuple[list[dict[str, Any]], list[tuple[str, dict[str, Any]]]]:
    """Run one work unit (in any process). Returns the rows and the recorded series.

    Args:
        unit: The work unit.
        on_step: Optional ``(trial, rotation, translation, edge_visible)`` callback at
            every period (the live viewer; in-process only).
    """
    from benchmarks.sim import run_trials
    from benchmarks.study.calibration import calibration_hook
    from benchmarks.study.records import trial_record

    sc = unit.scenario
    results = run_trials(sc, unit.controller_index, list(unit.trials), unit.record_trials,
                         backend_factory=backend_factory(unit.backend),
                         calibrate=_calibration(sc, calibration_hook), on_step=on_step,
                         engine=unit.engine)
    rows, records = [], []
    for res in results:
        row = dict(res.row)
        row["point"] = unit.point
        row["backend"] = unit.backend
        rows.append(row)
        if res.series is not None:
            name = f"{sc.name}__p{unit.point}__{unit.controller}__{row['trial']:05d}.npz"
            records.append((name, trial_record(sc, unit, row, res.series)))
    return rows, records

#: The last scenario point and its calibration hook (:func:`_calibration`).
_hook: list[Any] = [None, None]


def _calibration(sc: Scenario, hook: Callable[[Scenario], Any]) -> Any:
    """The calibration hook of a scenario point, the same object for every unit of the
    same point (so that :func:`benchmarks.sim.stepper.point_trials` draws its trials once)."""
    if _hook[0] is not sc:
        _hook[:] = [sc, hook(sc)]
    return _hook[1]


def _iter_inline(units: list[WorkUnit]) -> Iterator[tuple[WorkUnit, Any]]:
    for u in units:
        yield u, execute(u)


def _worker_start() -> None:
    """A pool worker's start: it lets go of the run's lock (inherited through the fork)
    and, on Linux, is sent SIGTERM when the run's process ends, however it ends (killed,
    SIGTERM to it alone): orphaned workers held the directory's lock, and a resume was
    refused naming a process that no longer existed."""
    from benchmarks.study.results import release_inherited_locks

    release_inherited_locks()
    # the run's SIGTERM handler (benchmarks.termination) is not the worker's: SIGTERM,
    # from the run or from its death, ends the worker
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    from hexapod.parent import end_with_parent

    end_with_parent()


def _iter_pool(units: list[WorkUnit], workers: int,
               meanwhile: Callable[[], None] | None = None
               ) -> Iterator[tuple[WorkUnit, Any]]:
    """Run the units in a pool of ``workers`` processes, one unit per worker at a time:
    a worker that finishes a unit gets the next one of the same sweep point and
    controller while there is one (:func:`_take`), so that it builds each controller's
    compiled kernels once, not every worker every controller's."""
    import multiprocessing as mp

    ctx = mp.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                             initializer=_worker_start) as pool:
        queue = list(units)
        running: dict[Future[Any], WorkUnit] = {}

        def submit(after: WorkUnit | None) -> None:
            u = _take(queue, after, {_group(r) for r in running.values()})
            running[pool.submit(execute, u)] = u

        beside: threading.Thread | None = None
        try:
            while queue and len(running) < workers:
                submit(None)
            while running:
                if meanwhile is not None and beside is None:
                    # a thread, so that this one keeps collecting and submitting units;
                    # started after the first submit: the pool forks all its workers then,
                    # and never again, so no worker is forked with this thread running
                    beside = threading.Thread(target=_quietly, args=(meanwhile,),
                                              name="meanwhile", daemon=True)
                    beside.start()
                finished, _ = wait(running, return_when=FIRST_COMPLETED)
                for fut in finished:
                    u = running.pop(fut)
                    if queue:  # the idle worker is the one that ran u: its next unit
                        submit(u)
                    yield u, fut.result()
        except BaseException:
            for fut in running:
                fut.cancel()
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        finally:
            if beside is not None:
                beside.join()


def _group(unit: WorkUnit) -> tuple[str, int, int]:
    """A unit's scenario, sweep point and controller."""
    return unit.scenario.name, unit.point, unit.controller_index


def _take(queue: list[WorkUnit], after: WorkUnit | None,
          running: set[tuple[str, int, int]]) -> WorkUnit:
    """Remove and return the next unit for a worker that ran ``after``: the first one of
    ``after``'s group, else the first of a group no worker runs, else the first."""
    for i, u in enumerate(queue):
        if after is not None and _group(u) == _group(after):
            return queue.pop(i)
    for i, u in enumerate(queue):
        if _group(u) not in running:
            return queue.pop(i)
    return queue.pop(0)


def _quietly(job: Callable[[], None]) -> None:
    """Run ``job``, a preparation (the report's imports): a failure is logged, and met
    again with its error where what it prepares is needed."""
    try:
        job()
    except Exception:  # met again, with its error, where it matters (the report)
        log.debug("preparing beside the pool failed", exc_info=True)


def _iter_dask(units: list[WorkUnit], address: str, workers: int
               ) -> Iterator[tuple[WorkUnit, Any]]:
    """The units' results from Dask, its own log lines at errors only in this process
    while it runs unless ``--verbose`` (the logger's level restored after: a later run
    of the same process logs as it asks)."""
    quiet = logging.getLogger().getEffectiveLevel() > logging.INFO  # (not --verbose)
    with _loggers_at(logging.ERROR if quiet else None, "distributed"):
        yield from _dask_results(units, address, workers, quiet)


def _dask_results(units: list[WorkUnit], address: str, workers: int, quiet: bool
                  ) -> Iterator[tuple[WorkUnit, Any]]:
    distributed = _distributed()
    Client, LocalCluster, as_completed = (distributed.Client, distributed.LocalCluster,
                                          distributed.as_completed)
    cluster = None
    if address == "local":
        with _sigint_ignored(), _cluster_quiet(quiet):  # Ctrl-C is this process's
            # (a dashboard on a free port: None still took 8787, warning when in use)
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", host="127.0.0.1")
        client = Client(cluster)
    else:
        client = connect(address)
    stopping: contextlib.AbstractContextManager[None] = contextlib.nullcontext()
    try:
        futures = {client.submit(execute, u, pure=False): u for u in units}
        for fut in as_completed(futures):
            try:
                result = fut.result()
            except Exception as exc:
                if _cluster_failure(exc):  # (a trial's own error is a row, not this)
                    raise ClusterError(exc) from None
                raise
            yield futures[fut], result
    except BaseException:  # (Ctrl-C: the run stops; see _silent_while_stopping)
        if quiet:
            stopping = _silent_while_stopping()
        raise
    finally:
        with stopping:
            client.close()
            if cluster is not None:
                cluster.close()


#: How long a run waits for a Dask scheduler to answer [s].
CONNECT_TIMEOUT_S = 10


def _distributed() -> Any:
    """The ``dask.distributed`` module.

    Raises:
        ResultsError: Dask is not installed (naming ``--dask`` and the extra to install).
    """
    try:
        import dask.distributed
    except ImportError as exc:
        raise ResultsError("--dask", "Dask is not installed: pip install 'hexapod-vs[dask]'"
                           ) from exc
    return dask.distributed


def connect(address: str) -> Any:
    """A Dask client of the scheduler at ``address``.

    Raises:
        ResultsError: A malformed address, or no scheduler answering within
            :data:`CONNECT_TIMEOUT_S` (naming ``--dask``).
    """
    Client = _distributed().Client
    try:
        return Client(address, timeout=CONNECT_TIMEOUT_S)
    except (ValueError, TypeError, OSError, TimeoutError) as exc:
        raise ResultsError("--dask", f"no Dask scheduler at {address!r} ({type(exc).__name__}: "
                           f"{exc}); give a running scheduler's address, tcp://HOST:PORT, or "
                           "'local' for a cluster of this machine") from None


def dask_workers(address: str, workers: int) -> int:
    """The threads a Dask run has to work with: ``workers`` for ``local``, else the
    scheduler's workers' threads now (at least 1).

    Raises:
        ResultsError: As :func:`connect`.
    """
    if address == "local":
        return workers
    client = connect(address)
    try:
        return max(1, sum(client.nthreads().values()))
    finally:
        client.close()


def _cluster_failure(exc: BaseException) -> bool:
    """Whether Dask raised ``exc`` for its cluster (a scheduler gone, a unit's workers
    killed: ``KilledWorker``, a closed connection, the futures cancelled) rather than a
    unit's own code (whose ``OSError``, a worker without the scenario's files, is said as
    it is: a resume would meet it again)."""
    import asyncio
    from concurrent.futures import CancelledError

    return (type(exc).__module__.split(".")[0] == "distributed"
            or isinstance(exc, (CancelledError, asyncio.CancelledError)))


@contextlib.contextmanager
def _silent_while_stopping() -> Iterator[None]:
    """Dask's and its event loop's log lines off while an interrupted run closes its
    client and cluster: cancelling the futures in flight, Dask logged an error of its own
    code with a traceback (``distributed.utils.sync``'s cancel callback: "cannot access
    free variable 'future'") and "Couldn't gather keys", which said nothing to a user who
    pressed Ctrl-C and looked like a crash; the run's own message says how it stopped."""
    with _loggers_at(logging.CRITICAL + 1, "distributed", "tornado"):
        yield


@contextlib.contextmanager
def _loggers_at(level: int | None, *names: str) -> Iterator[None]:
    """The loggers ``names`` at ``level`` in the block (None: as they are), each one's own
    level restored after."""
    loggers = [logging.getLogger(name) for name in names]
    levels = [lg.level for lg in loggers]
    try:
        for lg in loggers if level is not None else ():
            lg.setLevel(level)  # type: ignore[arg-type]
        yield
    finally:
        for lg, before in zip(loggers, levels, strict=True):
            lg.setLevel(before)


@contextlib.contextmanager
def _cluster_quiet(quiet: bool) -> Iterator[None]:
    """With ``quiet``, the local cluster's processes started in the block log nothing
    below critical (they read ``DASK_LOGGING__DISTRIBUTED`` from the environment, set for
    the block only: a later ``--verbose`` run of the same process, and the processes it
    starts, see the user's own). Its scheduler's and nannies' INFO lines, and their
    warnings while the run stops its cluster, said nothing to a user of the study, and a
    worker whose heartbeat met the scheduler already closed after a Ctrl-C printed an
    error with its traceback over the run's message (once in four runs of the
    interrupted-run test). A worker's real failure reaches this process as its unit's
    error (:class:`~benchmarks.exceptions.ClusterError`); ``--verbose`` shows them all."""
    key = "DASK_LOGGING__DISTRIBUTED"
    before = os.environ.get(key)
    if quiet and before is None:
        os.environ[key] = "critical"
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(key, None)


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while the block starts processes, which inherit that: a Ctrl-C in
    the terminal reaches every process of its group, and a local Dask cluster's workers
    printed a traceback each while this process stopped them in order (main thread only;
    a Ctrl-C during the block is lost, as it would be by then in the cluster's start)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def run_units(units: list[WorkUnit], out_dir: Path, workers: int = 1,
              dask: str | None = None,
              progress: Callable[[WorkUnit], None] | None = None,
              meanwhile: Callable[[], None] | None = None) -> int:
    """Execute work units and stream their results to ``out_dir``.

    Args:
        units: From :func:`plan`.
        out_dir: Results directory.
        workers: Processes (1: in-process).
        dask: Dask scheduler address, or ``"local"`` for a local cluster.
        progress: Called after each finished unit.
        meanwhile: Called once, in a thread of this process, while the pool's workers
            run (``run`` imports the report's drawing modules then, instead of after the
            trials); not called in-process or with Dask. Its failure is logged (debug).

    Returns:
        Number of rows written.

    Raises:
        DirectoryLockedError: Another process is writing into ``out_dir``.
    """
    with run_lock(out_dir):
        return _run_units(units, out_dir, workers, dask, progress, meanwhile)


def _run_units(units: list[WorkUnit], out_dir: Path, workers: int, dask: str | None,
               progress: Callable[[WorkUnit], None] | None,
               meanwhile: Callable[[], None] | None = None) -> int:
    writer = ResultsWriter(out_dir)
    count = 0
    try:
        if dask:
            it = _iter_dask(units, dask, workers)
        elif workers > 1:
            it = _iter_pool(units, workers, meanwhile)
        else:
            it = _iter_inline(units)
        for unit, (rows, records) in it:
            writer.write(rows, records)
            count += len(rows)
            if progress is not None:
                progress(unit)
    finally:
        writer.close()
    return count

def machine_info() -> dict[str, str]:
    """CPU, Python and library versions for the report."""
    import importlib.metadata as md

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    info = {"cpu": cpu, "cores": str(os.cpu_count()), "python": platform.python_version(),
            "platform": platform.platform()}
    for pkg in ("hexapod-vs", "pin", "casadi", "osqp", "numpy", "opencv-python-headless",
                "meshcat", "pyserial", "dask"):
        try:
            info[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            info[pkg] = "not installed"
    return info
