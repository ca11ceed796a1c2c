"""``hexapod-bench warm`` steps every controller of a built-in scenario as ``run`` would:
with its options resolved (a file-wide ``[controller_options]`` key given only to the
controllers that declare it). It passed ``payload-saturation``'s ``adaptive_gain`` to the
force laws, whose every warm-up trial then failed ("no such option") and built nothing."""

from __future__ import annotations

import logging

import pytest

from benchmarks.study.scenario import load_scenario
from benchmarks.warm import warm_scenario


@pytest.mark.slow  # (1.5 s with a warm cache; minutes on a cold one)
def test_warm_steps_every_unit_with_the_options_run_gives_it(
        caplog: pytest.LogCaptureFixture) -> None:
    assert load_scenario("payload-saturation").controller_options  # (the case in point)
    with caplog.at_level(logging.WARNING):
        result = warm_scenario("payload-saturation")
    assert result.units == 13 * 6  # thirteen controllers, six payloads
    # the project's study and simulator loggers (a failed unit, a failed trial); the
    # kernels' "compiling ..." notice of a cold cache is not a failure
    failures = [r.getMessage() for r in caplog.records if r.name.startswith("benchmarks")]
    assert not failures, failures


def test_warm_logs_a_scenario_whose_controllers_fail_their_check(
        caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch) -> None:
    """A scenario whose controllers' check fails is logged and skipped (0 units), as a
    failed unit is: the other scenarios still warm."""
    import benchmarks.study.scenario_checks as checks

    def refuse(*_args: object, **_kwargs: object) -> None:
        raise ValueError("controller 'x': no such option 'y'")

    monkeypatch.setattr(checks, "check_controllers", refuse)
    with caplog.at_level(logging.WARNING):
        result = warm_scenario("quick")
    assert result.units == 0
    assert any("no such option 'y'" in r.getMessage() for r in caplog.records)
