"""The one closed loop: plant -> camera -> controller batch -> plant, every period.

Every run of a controller goes through :func:`closed_loop`: the simulated studies (every
trial of a work unit as one batch, in either world, with geometric features or rendered
images, with or without a camera clock), a study on robots behind backends and the real
servo session (a batch of one). What differs between them is a component: the **plant**
(:class:`benchmarks.sim.plant.Plant`: it moves the rows, its encoders, its poses ``R``,
``t`` are what the camera sees), the **sensor** (``observe(rows, R, t)``: the camera's
:class:`~controllers.base.ObservationBatch`), the **clock**
(:class:`benchmarks.sim.clock.CameraClock`, or None: an image at every control instant),
the **controller batch** (``step_batch``: a trial's own crash is isolated to its row,
the controller's ``crashes``) and the **book** (:class:`LoopBook`: when a row is done,
what happens to a command, what is recorded; :class:`benchmarks.sim.book.Book` for a
study, :class:`benchmarks.robot.loop.ServoBook` for the servo session).

One period of the active rows: the book says which are done, the camera measures them
all, those not done with an image are stepped as one batch, the book accounts the
commands, the plant advances the rows still running (zero commands where none).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterable
from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from benchmarks.sim.clock import CameraClock
from controllers.base import CommandBatch, ObservationBatch


class LoopBook(Protocol):
    """What the loop asks of its book (see the module docstring).

    Attributes:
        active: (N,) rows still running (the loop ends when none is).
    """

    active: np.ndarray

    def check(self, step: int, idx: np.ndarray) -> np.ndarray:
        """(n,) which of the active rows ``idx`` are done at the start of ``step`` (they
        are measured, not stepped)."""
        ...

    def observed(self, step: int, idx: np.ndarray, obs: ObservationBatch) -> np.ndarray:
        """Account the camera's batch of ``idx``; returns the (n,) mask of rows with an
        image to step on (a book may end rows here by clearing ``active``)."""
        ...

    def commanded(self, step: int, rows: np.ndarray, commands: CommandBatch,
                  seconds: float, crashes: dict[int, BaseException]
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Account the commands of ``rows`` (the controller took ``seconds`` per row;
        ``crashes``: the rows, by position in ``rows``, whose trial's own instance raised,
        as :meth:`controllers.base.Controller.step_rows` isolates them); returns the (n,) masks
        of the commands applied and of the rows that end. Raises when the batch as a
        whole is refused (wrong shape or kind)."""
        ...

    def stopped(self, step: int, exc: Exception) -> BaseException:
        """The exception to raise when the controller's batch failed as a whole at
        ``step`` (``step_batch`` or :meth:`commanded` raised ``exc``): ``exc`` itself
        or one that says what it means for the rows."""
        ...

    def period(self, step: int, idx: np.ndarray, done: np.ndarray, obs: ObservationBatch,
               error_norm: np.ndarray, values: np.ndarray) -> None:
        """The period's outcome for ``idx`` (``done`` rows end at ``step``; ``values`` the
        commands, zeros where none), before the plant moves the others."""
        ...

    def advanced(self, step: int, run: np.ndarray, failures: dict[int, str]) -> None:
        """The plant moved rows ``run``; ``failures`` are rows whose world failed."""
        ...


def closed_loop(plant: Any, sensor: Any, clock: CameraClock | None, controller: Any,
                book: LoopBook, dt: float, offsets: np.ndarray,
                max_steps: int | None = None) -> int:
    """Run the loop (the module docstring's components; ``controller`` reset for every
    row) at control period ``dt`` [s] until the book ends every row or after periods
    ``0..max_steps`` (None: no bound); ``offsets`` (N, 6) [m] are the rows' encoder
    offsets (the plant's ``measured_lengths``). Returns the number of periods begun."""
    steps: Iterable[int] = itertools.count() if max_steps is None else range(max_steps + 1)
    begun = 0
    n_rows = len(book.active)
    for step in steps:
        idx = np.flatnonzero(book.active)
        n = len(idx)
        if n == 0:
            break
        begun = step + 1
        full = n == n_rows  # every row runs: the state arrays themselves, no copies
        done = book.check(step, idx)
        obs = (sensor.observe(idx, *((plant.R, plant.t) if full else (plant.R[idx],
                                                                     plant.t[idx])))
               if clock is None else clock.measure(step, idx, sensor.observe))
        seen = book.observed(step, idx, obs)
        done |= ~book.active[idx]
        every = not done.any() and bool(seen.all())  # the common case: no row copies
        rows = np.arange(n) if every else np.flatnonzero(~done & seen)
        values: np.ndarray | None = None
        norms: np.ndarray | None = None
        if len(rows):
            tr = idx if every else idx[rows]
            batch = replace(obs if every else obs.rows(rows), trials=tr,
                            t=np.full(len(rows), step * dt),
                            lengths=plant.measured_lengths(tr, offsets if full and every
                                                           else offsets[tr]),
                            q_dot=plant.measured_rates(tr))
            t0 = time.perf_counter()
            try:
                cmds = controller.step_batch(batch)
                seconds = (time.perf_counter() - t0) / len(rows)
                applied, ends = book.commanded(step, tr, cmds, seconds,
                                               getattr(controller, "crashes", None) or {})
            except Exception as exc:  # the batch as a whole: the book says what follows
                stopped = book.stopped(step, exc)
                if stopped is exc:
                    raise
                raise stopped from exc
            if every and applied.all() and not ends.any():  # every row moves: no selections
                norms = np.asarray(cmds.error_norm, dtype=float)
                values = np.array(cmds.values, dtype=float)  # (the plant may keep rows)
            else:
                values, norms = np.zeros((n, 6)), np.full(n, np.nan)
                norms[rows] = cmds.error_norm
                done[rows[ends]] = True
                values[rows[applied]] = cmds.values[applied]
        if values is None or norms is None:  # no row stepped: zeros, no error norms
            values, norms = np.zeros((n, 6)), np.full(n, np.nan)
        book.period(step, idx, done, obs, norms, values)
        run, moves = (idx, values) if not done.any() else (idx[~done], values[~done])
        if len(run):
            book.advanced(step, run, plant.advance(run, moves, dt))
    return begun
