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
