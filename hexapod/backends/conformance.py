"""Check a backend against the simulated robot: the test a backend of your own should pass.

:func:`check_backend` drives a backend and :class:`~hexapod.backends.sim.SimulatedRobot`
with the same commands and compares what they measure, period by period:

1. a smooth motion well inside the limits (the measured lengths must agree within
   ``tolerance``: a backend with lag or quantisation needs a looser one). A period the
   backend reports missed (``BackendStep.missed_period``: the host was late, so the
   lengths were read before the motion ended) is not compared; the simulator restarts
   from the measured lengths and the report counts it. More than a quarter of the
   periods missed is a problem (too little was compared);
2. a command beyond the speed limit (the backend must clamp it: no leg may move
   faster than the limit, and the step must report the leg clamped);
3. a push into a stroke end (no measured length may leave the stroke);
4. a NaN command (no leg may move, the step reports it clamped);
5. ``halt()`` then ``close()`` (must not raise).

A backend that raises during the checks (its link, its robot or its own code) fails
the check with the exception named; ``halt()`` and ``close()`` are called whatever
happens, a Ctrl-C included.

Use it in your own test suite::

    from hexapod.backends.conformance import check_backend

    def test_my_robot_behaves_like_the_simulator():
        report = check_backend(lambda g, q: MyRobot.open("", g, q), deltalab())
        assert report.ok, report.problems
"""

from __future__ import annotations

import gc
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hexapod.backends.base import Backend, halt_and_close
from hexapod.backends.sim import SimulatedRobot
from hexapod.geometry import HexapodGeometry
from hexapod.plausible import reading_problem

#: ``(geometry, start lengths) -> an opened backend`` (its ``reset`` already done).
BackendFactory = Callable[[HexapodGeometry, np.ndarray], Backend]


@dataclass
class ConformanceReport:
    """What :func:`check_backend` found.

    Attributes:
        periods: Periods driven.
        max_deviation: Largest absolute difference between the measured and the simulated lengths
            over the smooth motion [m].
        missed_periods: Periods of the smooth motion the backend reported missed (not
            compared).
        problems: One line per failed check (empty when the backend conforms).
    """

    periods: int = 0
    max_deviation: float = 0.0
    missed_periods: int = 0
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when every check passed."""
        return not self.problems


class _BadReadingError(Exception):
    """A reading that cannot be the robot's legs (ends the checks that read lengths)."""


def _read(lengths: Any, stage: str, geometry: HexapodGeometry) -> np.ndarray:
    """``lengths`` as an array, or :class:`_BadReadingError` naming the stage and why they
    cannot be legs of ``geometry`` (:func:`hexapod.plausible.reading_problem`: not a
    number, out of any leg's reach, millimetres for metres: a comparison with NaN is
    false, and such a reading passed)."""
    problem = reading_problem(lengths, geometry.stroke)
    if problem is not None:
        raise _BadReadingError(f"{stage}: {problem}")
    return np.asarray(lengths, float)


def check_backend(factory: BackendFactory, geometry: HexapodGeometry, dt: float = 0.02,
                  tolerance: float = 1e-9, periods: int = 25) -> ConformanceReport:
    """Drive a backend and the simulated robot with the same commands and compare.

    Args:
        factory: Opens the backend under test at given start lengths.
        geometry: The robot (stroke and speed limit of both).
        dt: Control period [s].
        tolerance: Allowed absolute difference between the measured and the simulated
            lengths during the smooth motion [m].
        periods: Periods of the smooth motion.

    Returns:
        The :class:`ConformanceReport` (the backend is closed whatever happened).

    Python's garbage collector is off while the backend is driven (a full collection
    first): a collection pause of tens of milliseconds in this process, late in a long
    test session, stalls an emulator that runs in the same process and shows as a
    lagging platform.
    """
    report = ConformanceReport()
    q0 = np.full(6, geometry.q_mid)
    lo, hi = geometry.stroke
    vmax = geometry.max_speed
    robot = factory(geometry, q0)
    sim = SimulatedRobot(geometry, q0)
    collecting = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        try:
            q = _read(robot.measured_lengths(), "start", geometry)
            if not np.allclose(q, q0, atol=max(tolerance, 1e-12)):
                report.problems.append(f"start: measured {np.round(q * 1e3, 4).tolist()} mm, "
                                       f"expected {np.round(q0 * 1e3, 4).tolist()} mm")
            # 1. smooth motion inside the limits
            phases = np.arange(6) * np.pi / 3
            deviated = False
            for k in range(periods):
                v = 0.4 * vmax * np.sin(2 * np.pi * k / periods + phases)
                got = robot.step(v, dt)
                _read(got.lengths, f"smooth motion, period {k}", geometry)
                want = sim.step(v, dt)
                report.periods += 1
                if got.missed_period:  # read early: the simulator goes on from the reading
                    report.missed_periods += 1
                    sim.reset(np.asarray(got.lengths, float))
                    continue
                dev = float(np.max(np.abs(np.asarray(got.lengths) - want.lengths)))
                report.max_deviation = max(report.max_deviation, dev)
                if dev > tolerance and not deviated:  # the first, said; the largest over
                    deviated = True  # every period still measured (it stopped here)
                    leg = int(np.argmax(np.abs(np.asarray(got.lengths) - want.lengths)))
                    report.problems.append(f"smooth motion, period {k}: leg {leg} measured "
                                           f"{got.lengths[leg] * 1e3:.6f} mm, the simulator "
                                           f"{want.lengths[leg] * 1e3:.6f} mm")
            if report.missed_periods > periods / 4:
                report.problems.append(f"smooth motion: the host missed {report.missed_periods} "
                                       f"of its {periods} periods (only the others are "
                                       "compared): a longer period (dt) or a quieter machine")
            # 2. beyond the speed limit
            q_before = _read(robot.measured_lengths(), "speed limit", geometry)
            got = robot.step(np.full(6, 10 * vmax), dt)
            _read(got.lengths, "speed limit", geometry)
            report.periods += 1
            moved = np.abs(np.asarray(got.lengths) - q_before)
            if np.any(moved > vmax * dt * (1 + 1e-6) + tolerance):
                report.problems.append(f"speed limit: a leg moved {moved.max() * 1e3:.4f} mm in "
                                       f"one period, the limit allows {vmax * dt * 1e3:.4f} mm")
            if not np.all(np.asarray(got.clamped, bool)):
                report.problems.append("speed limit: a command 10x the limit was not reported "
                                       "clamped")
            # 3. into the upper stroke end
            for _ in range(int(np.ceil((hi - lo) / (vmax * dt))) + 2):
                got = robot.step(np.full(6, vmax), dt)
                report.periods += 1
                q = _read(got.lengths, "stroke", geometry)
                if np.any(q > hi + 1e-9 + tolerance) or np.any(q < lo - 1e-9 - tolerance):
                    report.problems.append(f"stroke: measured {np.round(q * 1e3, 4).tolist()} mm "
                                           f"outside [{lo * 1e3:g}, {hi * 1e3:g}] mm")
                    break
            # 4. a NaN command moves nothing
            q_before = _read(robot.measured_lengths(), "NaN command", geometry)
            v = np.full(6, -0.5 * vmax)
            v[2] = np.nan
            got = robot.step(v, dt)
            _read(got.lengths, "NaN command", geometry)
            report.periods += 1
            if abs(float(got.lengths[2]) - q_before[2]) > tolerance:
                report.problems.append("NaN command: leg 2 moved "
                                       f"{(got.lengths[2] - q_before[2]) * 1e3:.4f} mm")
            if not bool(np.asarray(got.clamped, bool)[2]):
                report.problems.append("NaN command: leg 2 was not reported clamped")
        except _BadReadingError as bad:  # the checks after it would compare garbage
            report.problems.append(str(bad))
        except Exception as exc:  # the robot, its link or the plugin (or the check
            # itself) failed: a failed check (it was a traceback, or a bad spec's exit code)
            report.problems.append(f"the check stopped after {report.periods} period(s): "
                                   f"{type(exc).__name__}: {exc}")
    finally:  # 5. halt, then close, whatever happened (a Ctrl-C included)
        if collecting:
            gc.enable()
        report.problems += halt_and_close(robot)
    return report
