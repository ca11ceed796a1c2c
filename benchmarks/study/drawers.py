"""Work left to forked processes on the idle cores while this process goes on: a
report's figures (:func:`benchmarks.study.plots.save_figure`), each drawn and written by
a child that holds the figure as it was at the fork, or the figures of every sweep point
of one kind (:func:`benchmarks.study.plots.line_figures`) by one child, while the report
makes the next ones (the drawing is most of a figure's time)."""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from benchmarks.exceptions import ResultsError


class _Drawers:
    """The forked processes of a :func:`drawing_aside`: at most ``processes`` at a time,
    and the names of those that failed."""

    def __init__(self, processes: int) -> None:
        import multiprocessing

        self.context = multiprocessing.get_context("fork")
        self.processes = processes
        self.running: list[Any] = []
        self.failed: list[str] = []

    def start(self, job: Callable[..., None], args: tuple[Any, ...], name: str) -> bool:
        """Start ``job(*args)`` in a new process if fewer than ``processes`` run."""
        for child in [c for c in self.running if not c.is_alive()]:
            self.join(child)
        if len(self.running) >= self.processes:
            return False
        child = self.context.Process(target=_alone, args=(job, args), name=name)
        child.start()
        self.running.append(child)
        return True

    def join(self, child: Any) -> None:
        """Wait for a process and note its failure."""
        child.join()
        self.running.remove(child)
        if child.exitcode:
            self.failed.append(f"{child.name} (exit code {child.exitcode})")


#: The drawers of the :func:`drawing_aside` in effect (empty: none).
_aside: list[_Drawers] = []


def _alone(job: Callable[..., None], args: tuple[Any, ...]) -> None:
    """``job(*args)`` in a drawer, which forks no drawer of its own (a job of several
    figures draws them all)."""
    import signal

    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # (the command's handler is not ours)
    # a Ctrl-C is the command's to handle (it ends the drawers): here it printed a
    # KeyboardInterrupt traceback of the drawer's own over the command's last lines
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _aside.clear()
    job(*args)


def runnable_tasks() -> int:
    """The tasks running or ready to run on this machine now, this process included (the
    kernel's count in ``/proc/loadavg``; unknown: as many as the cores)."""
    try:
        return int(Path("/proc/loadavg").read_text().split()[3].split("/")[0])
    except (OSError, IndexError, ValueError):
        return os.cpu_count() or 1


def idle_cores() -> int:
    """The cores this process may run on that no task runs on now (a count of this
    instant, not the load average: that one lags a minute behind the machine and this
    process), at most all but one."""
    if not hasattr(os, "sched_getaffinity"):
        return 0
    cores = len(os.sched_getaffinity(0))
    return max(0, min(cores - 1, cores - runnable_tasks()))


def started(job: Callable[..., None], args: tuple[Any, ...], name: str) -> bool:
    """Whether ``job(*args)`` (named ``name``: a figure's file) was started in a forked
    process of the :func:`drawing_aside` in effect (False: none, or every one of its
    processes busy; the caller does the job itself)."""
    return bool(_aside) and _aside[0].start(job, args, name)


@contextmanager
def drawing_aside(out_dir: Path) -> Iterator[None]:
    """Within it, :func:`started` forks a process for a job while fewer than
    :func:`idle_cores` (counted on entering) run; on leaving, it waits for them. Nothing
    is forked when no core is idle (a child would only take this process's core: the
    same work, and its own start), outside Linux (as the runner's pool: fork is not safe
    with macOS's system libraries) and while another thread runs (a fork copies the
    calling thread only: a lock another thread held would stay locked in the child).

    Raises:
        ResultsError: A process failed (``out_dir``, the job's name and its exit code;
            its traceback is on stderr).
    """
    idle = idle_cores()
    if (_aside or not idle or not sys.platform.startswith("linux")
            or threading.active_count() > 1):
        yield
        return
    drawers = _Drawers(idle)
    _aside.append(drawers)
    try:
        yield
    finally:
        _aside.clear()
        while drawers.running:
            drawers.join(drawers.running[0])
    if drawers.failed:
        raise ResultsError(str(out_dir), "drawing a figure failed: "
                           f"{', '.join(drawers.failed)}; its error is printed above")
