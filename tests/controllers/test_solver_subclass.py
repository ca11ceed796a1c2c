"""A solver plugin that extends a built-in solver's ``solve`` is called for every row:
the compiled shortcut of the class it extends (``core_acceptance``) does not pass over
its code (docs/plugins.md, "Adding a solver")."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.sim import run_trials
from benchmarks.study.scenario import parse_scenario
from controllers.solvers.limit_qp import LimitQPSolver
from controllers.solvers.pseudo_inverse import DampedPseudoInverse
from tests.benchmarks.plugins import SlowLegZeroQP

SLOW = "tests.benchmarks.plugins:LegEdgeSlowLegZero"


def test_a_subclass_with_its_own_solve_or_finish_loses_the_shortcut() -> None:
    class OwnFinish(DampedPseudoInverse):
        def finish(self, qdot: np.ndarray) -> np.ndarray:
            return qdot

    class Declared(LimitQPSolver):
        core_acceptance = "bounds"

        def solve(self, *args: object) -> object:
            return super().solve(*args)  # type: ignore[arg-type]

    class Settings(LimitQPSolver):  # nothing of the solve changed: the shortcut stays
        threshold = 1e-5

    assert (SlowLegZeroQP.core_acceptance, OwnFinish.core_acceptance) == ("none", "none")
    assert Declared.core_acceptance == LimitQPSolver.core_acceptance == "bounds"
    assert Settings.core_acceptance == "bounds"
    assert DampedPseudoInverse.core_acceptance == "core"


@pytest.mark.parametrize("engine", ["batched", "per-trial"])
def test_the_plugins_own_limit_holds_on_every_row(engine: str) -> None:
    sc = parse_scenario({"name": "slow-leg", "seed": 1, "trials": 3, "task": {"max_steps": 150},
                         "controllers": [{"name": SLOW, "adaptive_gain": [5.0, 1.0, 30.0]}]})
    results = run_trials(sc, 0, [0, 1, 2], record_trials=3, engine=engine)
    fastest = max(float(np.abs(r.series["velocities"][:, 0]).max())  # type: ignore[index]
                  for r in results)
    # the cap binds and holds (with the compiled shortcut of LimitQPSolver, leg 0 reached
    # 36 mm/s where the unconstrained twist cleared the class's own bounds)
    assert fastest == pytest.approx(SlowLegZeroQP.CAP, rel=1e-9)
