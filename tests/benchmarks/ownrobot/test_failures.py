"""Failures in the user's terms: one line per cause with its count, no traceback unless -v,
the report in full, a non-zero exit code when every trial failed."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from benchmarks.study.failures import (
    RepeatedWarnings,
    every_trial_failed,
    failure_summary,
    user_message,
)
from hexapod.exceptions import WorkspaceError
from tests.benchmarks.ownrobot.robots import BLIND_CAMERA, CRASH, own_robot, run_cli, write_study

CAMERA_CAUSE = "the camera sees no leg edge at the goal pose"


@pytest.mark.slow
def test_blind_camera_failures_once_per_cause(tmp_path: Path) -> None:
    """leg-edge cannot run with a camera that sees no leg; model-based can: the run goes
    on, the leg-edge failures are one cause counted, no traceback; leg-edge failed every
    one of its trials: exit code 3."""
    own_robot().to_toml(tmp_path / "robot.toml")
    (tmp_path / "camera.toml").write_text(BLIND_CAMERA)
    study = write_study(tmp_path, camera="camera.toml", trials=3,
                        controllers='["leg-edge", "model-based"]')
    out = tmp_path / "out"
    res = run_cli("run", str(study), "--out", str(out), "--no-progress")
    text = res.stdout + res.stderr
    assert res.returncode == 3, text
    assert "hexapod-bench: error: leg-edge (own) failed all its 3 trials" in res.stderr
    assert "Traceback" not in text
    assert text.count(CAMERA_CAUSE) == 2, text  # the first warning, then the summary line
    assert "3 of 6 trials failed" in text and "3 x (leg-edge 3): " + CAMERA_CAUSE in text
    report = (out / "report.md").read_text()
    section = report[report.index("## Failures"):]
    assert "**3 trial(s)** (leg-edge: 3; sweep points: own/p0)" in section
    assert "hexapod-bench check shows what it sees" in section  # the cause in full
    assert "first: own/p0/leg-edge/trial 0: ContextError: leg-edge: context field" in section


@pytest.mark.slow
def test_every_trial_failed_exits_non_zero_and_traceback_only_with_v(tmp_path: Path) -> None:
    own_robot().to_toml(tmp_path / "robot.toml")
    study = write_study(tmp_path, controllers=f'["{CRASH}"]')
    res = run_cli("run", str(study), "--out", str(tmp_path / "a"), "--no-progress")
    text = res.stdout + res.stderr
    assert res.returncode == 1, text
    assert "hexapod-bench: error: every trial failed" in res.stderr
    assert "2 of 2 trials failed" in text
    assert "RuntimeError: deliberate bug for the test" in text
    assert "Traceback" not in text
    res = run_cli("-v", "run", str(study), "--out", str(tmp_path / "b"), "--no-progress")
    assert res.returncode == 1
    assert "Traceback (most recent call last)" in res.stderr
    assert res.stderr.count("traceback of trial own/") == 2  # one per trial


def test_workspace_error_in_the_users_terms() -> None:
    text = user_message(WorkspaceError("own", 0, 2016, 0.06, 0.1745329, 0.005))
    assert text.startswith("no start or goal pose: only 0 of 2016 random poses (within 60 mm "
                           "and 10 deg of the home pose) keep every leg 5 mm inside its stroke")
    assert "stroke_mm in the robot file" in text and "[task] max_translation_mm" in text


def test_a_large_map_summarises_each_cause_once() -> None:
    rows = [{"scenario": "map", "point": p, "controller": c, "trial": k,
             "failure": "WorkspaceError: ...", "cause": "no start or goal pose"}
            for p in range(40) for c in ("leg-edge", "model-based") for k in range(5)]
    rows += [{"scenario": "map", "point": 0, "controller": "leg-edge", "trial": 9,
              "failure": "not converged within 600 steps"}]
    lines = failure_summary(rows)
    assert lines == ["400 of 401 trials failed (did not run to their end):",
                     "  400 x (leg-edge 200, model-based 200; 40 sweep points): "
                     "no start or goal pose"]
    assert not every_trial_failed(rows)
    assert every_trial_failed(rows[:-1])


def test_repeated_warnings_pass_once_and_are_counted(caplog: pytest.LogCaptureFixture) -> None:
    log = logging.getLogger("tests.repeated")
    filt = RepeatedWarnings()
    caplog.handler.addFilter(filt)
    try:
        with caplog.at_level(logging.INFO):
            for point in range(10):  # the same warnings at every point of a sweep
                for leg in (3, 4):
                    log.warning("calibration: leg %d is ill-conditioned (ratio %.3f)", leg,
                                0.011 + 1e-4 * point)
            log.info("an info line passes")
            log.info("an info line passes")
    finally:
        caplog.handler.removeFilter(filt)
    messages = [r.getMessage() for r in caplog.records]
    assert messages == ["calibration: leg 3 is ill-conditioned (ratio 0.011)",
                        "calibration: leg 4 is ill-conditioned (ratio 0.011)",
                        "an info line passes", "an info line passes"]
    assert filt.repeats() == [
        "9 more warning(s) like: calibration: leg 3 is ill-conditioned (ratio 0.011)",
        "9 more warning(s) like: calibration: leg 4 is ill-conditioned (ratio 0.011)"]


def test_repeated_warnings_on_several_handlers_count_each_record_once() -> None:
    log = logging.getLogger("tests.repeated.two")
    log.propagate = False
    filt = RepeatedWarnings()
    seen: list[list[str]] = [[], []]
    handlers = []
    for k in range(2):
        h = logging.Handler()
        h.emit = lambda record, k=k: seen[k].append(record.getMessage())  # type: ignore
        h.addFilter(filt)
        log.addHandler(h)
        handlers.append(h)
    try:
        for _ in range(5):
            log.warning("the same warning")
    finally:
        for h in handlers:
            log.removeHandler(h)
    assert seen == [["the same warning"], ["the same warning"]]
    assert filt.repeats() == ["4 more warning(s) like: the same warning"]
