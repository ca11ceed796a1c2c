"""``hexapod-bench warm``: compile every C kernel the built-in scenarios use, once.

The controllers, the dynamic world and the vision pipeline evaluate CasADi functions
compiled to C (:mod:`hexapod.compiled`), cached under ``$HEXAPOD_CACHE_DIR``. The first
call of a kernel compiles it (seconds each, minutes for all of them). ``warm`` pays that
cost up front, visibly, by running one trial of two periods of every controller at every
sweep point of every built-in scenario (so exactly the kernels those studies build), in
``workers`` processes. On a warm cache it only loads the libraries. ``make test`` calls it
before the test suite, so that no test pays a compilation.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

log = logging.getLogger(__name__)

#: Periods each controller runs at each point: enough to reset and step once.
STEPS = 2


@dataclass(frozen=True)
class WarmResult:
    """What warming one scenario did.

    Attributes:
        scenario: The scenario's name.
        units: Controller x sweep-point units stepped.
        seconds: Wall time [s].
    """

    scenario: str
    units: int
    seconds: float


def cached_libraries() -> set[str]:
    """The file names of the shared libraries in the kernel cache."""
    from hexapod.compiled import cache_dir

    folder = cache_dir()
    return {p.name for p in folder.glob("*.so")} if folder.is_dir() else set()


def warm_scenario(name: str) -> WarmResult:
    """Run one trial of :data:`STEPS` periods of every unit of the built-in ``name`` (in
    the dynamic world :data:`hexapod.compiled.LANE_ROWS` trials: the computed-torque
    batches evaluate by lanes from that many rows, so their lane libraries are built too).

    A unit that fails (an emulator-only scenario without its emulator, say) is logged and
    skipped: warming builds kernels, it judges nothing.
    """
    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.study.runner import execute, plan
    from benchmarks.study.scenario import load_scenario
    from benchmarks.study.scenario_checks import check_controllers
    from hexapod.compiled import LANE_ROWS

    start = time.perf_counter()
    sc = load_scenario(name)
    trials = LANE_ROWS if sc.world == "dynamic" else 1
    # each controller with its options resolved as ``run`` resolves them (a file-wide
    # [controller_options] key given only to the controllers that declare it)
    try:
        sc, _ = check_controllers(sc.with_overrides(trials, None, None, STEPS, None))
    except Exception as exc:  # as a failed unit: logged, the other scenarios warmed
        log.warning("warm %s: %s", name, exc)
        return WarmResult(name, 0, time.perf_counter() - start)
    units = plan([sc], record_trials=0)
    for unit in units:
        try:
            execute(unit)
        except Exception as exc:  # warming builds kernels; the tests judge them
            log.warning("warm %s (%s): %s", name, unit.controller, exc)
    return WarmResult(name, len(units), time.perf_counter() - start)


def warm(names: list[str] | None = None, workers: int = 2,
         report: Callable[[WarmResult], None] | None = None) -> list[WarmResult]:
    """Warm the kernel cache with the built-in scenarios (all of them by default).

    Args:
        names: Scenario names (default: every built-in scenario).
        workers: Processes; concurrent compilations of one kernel are safe (each writes
            its own temporary files and renames atomically).
        report: Called with each scenario's result as it finishes.

    Returns:
        One result per scenario, in the order of ``names``.
    """
    from benchmarks.study.scenario import builtin_scenarios

    names = list(names or builtin_scenarios())
    results: list[WarmResult] = []
    if workers <= 1:
        for name in names:
            results.append(warm_scenario(name))
            if report is not None:
                report(results[-1])
        return results
    import multiprocessing as mp

    with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
        for res in pool.map(warm_scenario, names):
            results.append(res)
            if report is not None:
                report(res)
    return results
