"""``hexapod-bench perf study``: both engines on the same trials, in one table, with their
rows compared."""

from __future__ import annotations

import time

import pytest

from benchmarks.perf import study


@pytest.mark.slow
def test_the_table_has_both_engines_and_equal_rows(capsys: pytest.CaptureFixture[str]) -> None:
    assert study.main(["--trials", "6", "--repeats", "1"]) == 0
    out = capsys.readouterr().out
    assert "6 trials per controller in one batch" in out
    rows = [line.split("|")[1:-1] for line in out.splitlines()
            if line.startswith("| leg-")]
    assert [r[0].strip() for r in rows] == ["leg-direction", "leg-edge"]
    for r in rows:
        steps, per_trial, batched = int(r[1]), float(r[2]), float(r[3])
        assert steps > 6 and per_trial > 0 and batched > 0
        assert r[-2].strip() == "5"  # seed 003's kinematic study: the engine's goal
        assert r[-1].strip() == "yes"


def test_bad_options_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        study.main(["--trials", "0"])
    assert "--trials: at least 1, got 0" in capsys.readouterr().err


@pytest.mark.slow
def test_the_breakdown_accounts_for_the_whole_run(capsys: pytest.CaptureFixture[str]) -> None:
    assert study.main(["--trials", "4", "--repeats", "1", "--breakdown"]) == 0
    out = capsys.readouterr().out
    table = out.split("# Where the time goes")[1]
    rows = {line.split("|")[1].strip(): [float(x) for x in line.split("|")[2:-1]]
            for line in table.splitlines() if line.startswith("| ") and "stage" not in line}
    assert set(rows) == {label for label, _, _ in study.STAGES} | {
        "other (the engine's numpy bookkeeping, rows)", "total"}
    for c in range(2):
        parts = sum(v[c] for k, v in rows.items() if k != "total")
        assert parts == pytest.approx(rows["total"][c], abs=0.02 * len(rows))
        assert all(v[c] >= 0 for k, v in rows.items() if not k.startswith("other"))
        assert rows["controller step_batch"][c] > 0 and rows["observation (C)"][c] > 0


def test_trial_steps_count_the_periods_the_loop_stepped() -> None:
    """A fixed-duration task steps a converged trial to its end, whatever period its row's
    ``steps`` names; the count of a 3-trial run equals the rows the controller stepped."""
    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.sim import run_trials
    from benchmarks.study.calibration import calibration_hook
    from benchmarks.study.scenario import load_scenario
    from controllers.tracking import TrackingController

    sc = load_scenario("paccot2008-tracking").with_overrides(
        trials=3, controllers=["leg-edge-ctc"], max_steps=40).expand()[0]
    assert sc.task.fixed_duration
    stepped = [0]
    original = TrackingController.step_batch

    def counting(self: TrackingController, observations: object) -> object:
        stepped[0] += len(observations)  # type: ignore[arg-type]
        return original(self, observations)  # type: ignore[arg-type]

    TrackingController.step_batch = counting  # type: ignore[method-assign,assignment]
    try:
        rows = [r.row for r in run_trials(sc, 0, [0, 1, 2], 0,
                                          calibrate=calibration_hook(sc), engine="batched")]
    finally:
        TrackingController.step_batch = original  # type: ignore[method-assign]
    assert study.trial_steps(sc, rows) == stepped[0]


@pytest.mark.slow
def test_some_controllers_of_a_dynamic_study_and_its_world_stage(
        capsys: pytest.CaptureFixture[str]) -> None:
    """``--controllers`` times only the named ones (by name or label, in the order given);
    the breakdown of a dynamic study gives the dynamic world's period its own
    row, a part of the total (a kinematic study's is zero: the test above)."""
    assert study.main(["--scenario", "paccot2008-tracking", "--trials", "2", "--repeats",
                       "1", "--controllers", "vision-ctc,computed-torque",
                       "--breakdown"]) == 0
    out = capsys.readouterr().out
    lines = [line.split("|") for line in out.split("# Where")[0].splitlines()
             if line.startswith("| ") and "controller" not in line]
    assert [cells[1].strip() for cells in lines] == ["vision-ctc", "computed-torque"]
    assert [cells[-3].strip() for cells in lines] == ["-", "-"]  # (no goal of its own)
    table = out.split("# Where the time goes")[1]
    assert "| stage | vision-ctc | computed-torque |" in table
    rows = {line.split("|")[1].strip(): [float(x) for x in line.split("|")[2:-1]]
            for line in table.splitlines() if line.startswith("| ") and "stage" not in line}
    world = rows["dynamic world period (C)"]
    assert all(0 < w < t for w, t in zip(world, rows["total"], strict=True))
    assert rows["forward kinematics (C)"] == [0.0, 0.0]  # (the dynamic world has none)


@pytest.mark.slow
def test_a_tracking_wrapper_s_reset_and_step_are_the_controller_s(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """A trajectory task's controller is the tracking wrapper around the law: its reset
    (the goals of every period, 0.3 s of CPU more here) is the controller's reset, not the
    engine's bookkeeping. Measured against the same run without the extra 0.3 s, so that
    the machine's own bookkeeping time (0.1 to 0.17 s of CPU on 2-core machines) is not
    compared with a fixed bound."""
    import controllers.tracking as tracking

    def stages() -> dict[str, float]:
        """CPU [us] of each stage over the run's trial-steps."""
        assert study.main(["--scenario", "paccot2008-tracking", "--trials", "2",
                           "--repeats", "1", "--controllers", "leg-edge",
                           "--breakdown"]) == 0
        head, table = capsys.readouterr().out.split("# Where the time goes")
        steps = int(next(line for line in head.splitlines()
                         if line.startswith("| leg-edge")).split("|")[2])
        return {line.split("|")[1].strip(): float(line.split("|")[2]) * steps
                for line in table.splitlines()
                if line.startswith("| ") and "stage" not in line}

    before = stages()
    real = tracking.tracking_plans

    def slow(*args: object, **kwargs: object) -> object:
        t0 = time.process_time()
        while time.process_time() - t0 < 0.3:
            pass
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(tracking, "tracking_plans", slow)
    after = stages()
    reset, other = "trial set-up: controller reset", "other (the engine's numpy bookkeeping, rows)"
    assert after[reset] - before[reset] >= 0.3e6 * 0.8
    assert after[other] - before[other] < 0.3e6 / 2


def test_an_unknown_controller_is_refused() -> None:
    from benchmarks.exceptions import BenchmarkError

    with pytest.raises(BenchmarkError, match="no-such-law"):
        study.main(["--controllers", "no-such-law"])


def test_the_world_asked_for_by_the_refusal_is_an_option(
        capsys: pytest.CaptureFixture[str]) -> None:
    """A force law on a kinematic scenario was refused with '(or run with --world
    dynamic)', an option perf study did not take."""
    from benchmarks.exceptions import ScenarioError

    with pytest.raises(ScenarioError, match="--world dynamic"):
        study.main(["--scenario", "quick", "--controllers", "computed-torque", "--trials",
                    "2", "--repeats", "1"])
    assert study.main(["--scenario", "quick", "--controllers", "computed-torque", "--world",
                       "dynamic", "--trials", "2", "--repeats", "1"]) in (0, None)
    assert "| computed-torque |" in capsys.readouterr().out
