"""``hexapod-bench perf dynamics``: Pinocchio and the compiled model on the same states,
in one table, with their accelerations compared."""

from __future__ import annotations

import pytest

from benchmarks.cli import main as cli_main
from benchmarks.perf import dynamics


def test_the_table_has_every_method_and_they_agree(capsys: pytest.CaptureFixture[str]
                                                   ) -> None:
    figures = dynamics.dynamics_figures(n=20, repeats=2)
    methods = [f.method for f in figures]
    assert methods[0] == "pinocchio constraintDynamics"
    assert {"compiled single", "compiled batch of 20"} <= set(methods)
    for f in figures:
        assert f.median_us > 0
        assert f.max_relative_error < 1e-9
    text = dynamics.format_dynamics(figures, 20)
    assert "compiled batch of 20" in text and "speed-up" in text


def test_wired_in_the_cli(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["perf", "dynamics", "-n", "10", "--repeats", "1"]) == 0
    out = capsys.readouterr().out
    assert "pinocchio constraintDynamics" in out and "DynamicModel.forward_batch" in out


def test_energy_drift_table_shrinks_with_the_step() -> None:
    rows = dynamics.energy_drift(steps=(2e-2, 1e-2), n=2)
    (dt1, drift1, ortho1), (dt2, drift2, ortho2) = rows
    assert (dt1, dt2) == (2e-2, 1e-2)
    assert drift2 < drift1 < 1e-8       # RK4: fourth order, tiny at these steps
    assert max(ortho1, ortho2) < 1e-8
    assert "classical RK4" in dynamics.format_energy(rows)
