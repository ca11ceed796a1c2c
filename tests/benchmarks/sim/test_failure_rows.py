"""Failures that say what failed: a crash keeps its step, the last errors and the
exception; a failed batch is reported as such and not rerun; a command of the wrong shape
names the controller and the shapes; a controller that fails all its trials makes the
run exit with its own code."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main
from benchmarks.study.runner import plan, read_results, run_units
from benchmarks.study.scenario import parse_scenario
from controllers.base import CommandBatch, ControllerContext, ObservationBatch
from tests.benchmarks import plugins

JOINTS = "tests.benchmarks.plugins:ProportionalJoints"
AT_STEP = "tests.benchmarks.plugins:CrashAtStep"
WRONG = "tests.benchmarks.plugins:WrongShape"
BATCH = "tests.benchmarks.plugins:CrashingBatch"
NAN = "tests.benchmarks.plugins:NaNAtStep"
RESET = "tests.benchmarks.sim.test_failure_rows:ResetFailsWithTrialOne"

#: The sizes of the batches :class:`ResetFailsWithTrialOne` was reset with.
RESETS: list[int] = []


class ResetFailsWithTrialOne(plugins.ProportionalJoints):
    """A batch controller whose ``reset_batch`` raises for any batch that holds the
    second trial (its goal is told apart by its lengths, as the first reset sees them)."""

    name = "test-reset-fails"
    bad_goal: np.ndarray | None = None

    def reset_batch(self, contexts: list[ControllerContext]) -> None:
        RESETS.append(len(contexts))
        goals = np.array([np.asarray(c.goal.lengths) for c in contexts])
        if ResetFailsWithTrialOne.bad_goal is None:
            ResetFailsWithTrialOne.bad_goal = goals[1]
        if any(np.array_equal(g, ResetFailsWithTrialOne.bad_goal) for g in goals):
            raise RuntimeError("deliberate reset failure")
        self.goals = goals

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        err = observations.lengths - self.goals[observations.trials]
        out = CommandBatch.zeros(len(err))
        out.velocities[:] = -self.gain * err
        out.error_norm[:] = np.linalg.norm(err, axis=1)
        return out


def _scenario(controllers: list[object], trials: int = 4) -> object:
    return parse_scenario({
        "name": "failures", "seed": 3, "trials": trials, "controllers": controllers,
        "task": {"max_steps": 100, "position_tolerance_mm": 0.5,
                 "orientation_tolerance_deg": 0.05}}, "failures.toml")


def _rows(tmp_path: Path, controllers: list[object], trials: int = 4,
          engine: str = "batched") -> list[dict]:
    run_units(plan([_scenario(controllers, trials)], chunk_size=trials, record_trials=0,
                   engine=engine), tmp_path)
    return read_results(tmp_path)


@pytest.mark.parametrize("engine", ["batched", "per-trial"])
def test_a_non_finite_command_names_the_controller_and_the_step_on_one_line(
        engine: str, tmp_path: Path) -> None:
    """It said 'controller returned an invalid command array([...' over several lines
    (the failure summary then grouped it trial by trial)."""
    rows = _rows(tmp_path, [NAN], engine=engine)
    for r in rows:
        assert r["failure"].startswith(f"controller {NAN!r} returned a non-finite command for "
                                       "leg 2 (nan) at step 3: ["), r["failure"]
        assert "\n" not in r["failure"]
        # the cause, without the step and the other legs' values: one kind for the report
        assert r["cause"] == f"controller {NAN!r} returned a non-finite command for leg 2 (nan)"


@pytest.mark.parametrize("engine", ["batched", "per-trial"])
def test_a_refusal_is_a_zero_command_whatever_velocities_it_carries(
        engine: str, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    moving = "tests.benchmarks.plugins:RefusesMoving"
    still = "tests.benchmarks.plugins:RefusesStill"
    with caplog.at_level("WARNING", logger="benchmarks.sim.book"):
        rows = _rows(tmp_path, [moving, still], trials=2, engine=engine)
    by = {(r["controller"], r["trial"]): r for r in rows}
    for k in range(2):
        m, s = by[(moving, k)], by[(still, k)]
        assert m["failure"] == "controller refused to move: I refuse" == s["failure"]
        assert m["steps"] == s["steps"]
        # the robot did not move: the same final errors as with the zero command
        assert m["final_position_error_mm"] == s["final_position_error_mm"] > 1.0
    warned = [r.getMessage() for r in caplog.records if "non-zero command" in r.getMessage()]
    assert warned and f"controller {moving!r} refused trial" in warned[0]


@pytest.mark.parametrize("engine", ["batched", "per-trial"])
def test_a_crash_keeps_its_step_errors_and_exception(engine: str, tmp_path: Path) -> None:
    rows = _rows(tmp_path, [{"name": AT_STEP, "crash_step": 20, "gain": 0.5}], engine=engine)
    assert len(rows) == 4
    for r in rows:
        assert r["steps"] == 20, r
        assert r["failure"] == (f"{AT_STEP} failed at step 20: RuntimeError: deliberate "
                                "crash at call 21")
        assert r["cause"] == "RuntimeError: deliberate crash at call 21"
        assert r["final_position_error_mm"] is not None and r["final_position_error_mm"] > 0


@pytest.mark.parametrize("engine", ["batched", "per-trial"])
def test_a_wrong_shape_names_the_controller_and_the_shapes(engine: str,
                                                           tmp_path: Path) -> None:
    rows = _rows(tmp_path, [WRONG], engine=engine)
    name = "test-wrong-shape"  # both engines: the one loop, the controller's own name
    for r in rows:
        assert r["steps"] == 0
        assert r["failure"] == (f"{WRONG} failed at step 0: CommandError: controller "
                                f"'{name}' returned a command of shape (3,); a "
                                "command holds one value per leg, shape (6,)")
        assert "broadcast" not in r["failure"]


@pytest.mark.slow
def test_a_failed_batch_is_reported_and_not_rerun(tmp_path: Path) -> None:
    plugins.BATCH_CALLS.clear()
    rows = _rows(tmp_path, [BATCH, JOINTS], trials=3)
    assert plugins.BATCH_CALLS == [3] * 5  # five batch steps of the 3 trials, once each
    batch = [r for r in rows if r["controller"] == BATCH]
    assert len(batch) == 3
    for r in batch:
        assert r["failure"].startswith(f"the batch of 3 trials of {BATCH} failed at step 4 "
                                       "(every trial of it counted failed, not rerun): "
                                       "RuntimeError: deliberate batch crash")
        assert r["steps"] == 4 and r["final_position_error_mm"] > 0
    assert all(r["failure"] is None or "batch" not in r["failure"]
               for r in rows if r["controller"] == JOINTS)


@pytest.mark.slow
def test_a_controller_failing_all_its_trials_exits_3(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]
                                                     ) -> None:
    study = tmp_path / "study.toml"
    study.write_text(f'name = "broken-plugin"\ntrials = 3\ncontrollers = ["{AT_STEP}", '
                     f'"{JOINTS}"]\n[task]\nmax_steps = 100\n')
    code = main(["run", str(study), "--out", str(tmp_path / "o"), "--no-progress",
                 "--record", "0"])
    err = capsys.readouterr().err
    assert code == 3, err
    assert (f"hexapod-bench: error: {AT_STEP} (broken-plugin) failed all its 3 trials (the "
            "causes are above; exit code 3: the other controllers ran)") in err


def test_a_batch_failing_before_its_first_step_is_rerun_trial_by_trial(
        tmp_path: Path) -> None:
    RESETS.clear()
    ResetFailsWithTrialOne.bad_goal = None
    rows = sorted(_rows(tmp_path, [RESET], trials=3), key=lambda r: r["trial"])
    assert RESETS == [3, 1, 1, 1]  # the batch, then each trial alone to find the one
    assert [r["failure"] is None or "not converged" in r["failure"] for r in rows] == [
        True, False, True]
    assert rows[1]["steps"] == 0 and rows[1]["final_position_error_mm"] is None
    assert rows[1]["failure"] == "RuntimeError: deliberate reset failure"
    assert rows[0]["steps"] > 0 and rows[2]["steps"] > 0


def test_a_group_whose_goals_all_fail_gives_each_trial_its_cause(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """No trial of the batch has a goal to measure: each row says why (a sensor of no
    trial was built first, and its IndexError replaced every cause)."""
    from benchmarks.sim import stepper

    def no_goals(sc: object, sensor: object, setups: list) -> list[Exception]:
        return [RuntimeError(f"no goal for trial {s.trial}") for s in setups]

    monkeypatch.setattr(stepper, "_goals", no_goals)
    rows = _rows(tmp_path, [JOINTS], trials=3)
    assert sorted(r["failure"] for r in rows) == [
        f"RuntimeError: no goal for trial {k}" for k in range(3)], rows


def test_both_engines_give_a_lengths_only_controller_the_same_fields(tmp_path: Path) -> None:
    """``features = {"lengths"}``: the batched engine withholds the camera's fields, and
    so does the per-trial engine now (it gave them: a plugin reading one worked there
    and failed in the default engine, and the engines' rows differed)."""
    only = "tests.benchmarks.plugins:LengthsOnly"
    rows = {engine: _rows(tmp_path / engine, [only], trials=2, engine=engine)
            for engine in ("batched", "per-trial")}
    for r in rows["batched"] + rows["per-trial"]:
        assert r["failure"] is None or r["failure"].startswith("not converged"), r["failure"]
    keys = ("final_position_error_mm", "final_orientation_error_deg", "steps")
    assert [[r[k] for k in keys] for r in rows["batched"]] == \
        [[r[k] for k in keys] for r in rows["per-trial"]]
