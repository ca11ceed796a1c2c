"""``hexapod-bench perf NAME``: a count below 1, a non-positive step or rate, a negative
noise is refused right after parsing, naming the option and the value (exit 2), before any
timed work; every option's help gives its default."""

from __future__ import annotations

import argparse
import importlib
from typing import Any
from unittest import mock

import pytest

#: What each module's main runs after parsing: patched to fail, so that a check missing
#: shows as a failed test rather than a timed run.
WORK = {
    "calibration": ["run_study"],
    "controllers": ["time_controllers"],
    "detect": ["_run", "interleaved_times"],
    "dynamics": ["dynamics_figures", "energy_drift"],
    "features": ["compare"],
    "fk": ["fk_figures"],
    "serial": ["measure", "open_emulated_robot", "SerialRobot"],
    "study": [],  # loads its scenario first (patched in the test)
    "vision": ["accuracy_figures", "edges_figure"],
}

# (The value each refusal replaced, on `hexapod-bench perf NAME ...`, in brackets.)
BAD = [
    # (already refused, as "--repeats must be >= 1")
    ("calibration", ["--repeats", "0"], "--repeats: at least 1, got 0"),
    # (a ValueError traceback from vision.noise.random_rotations)
    ("calibration", ["--noise", "0.01", "-0.05"],
     "--noise: finite non-negative amplitudes in degrees, got -0.05"),
    # (timed 5 steps per controller, silently: max(steps // 5, 1) per round)
    ("controllers", ["--steps", "0"], "--steps: at least 1, got 0"),
    ("controllers", ["--steps", "-10"], "--steps: at least 1, got -10"),
    # (a ValueError traceback from sample_poses: "need at least one array to concatenate")
    ("detect", ["--frames", "0"], "--frames: at least 1, got 0"),
    # (an UnboundLocalError traceback in _run)
    ("detect", ["--repeats", "0"], "--repeats: at least 1, got 0"),
    # (already refused, as "-n and --repeats must be >= 1")
    ("dynamics", ["-n", "0"], "-n: at least 1, got 0"),
    ("dynamics", ["--repeats", "0"], "--repeats: at least 1, got 0"),
    # (as perf controllers: 5 steps per controller timed, silently)
    ("features", ["--steps", "0"], "--steps: at least 1, got 0"),
    # (reported as a --controllers plugin that failed to load, naming MODULE:ATTR.pinv)
    ("features", ["--attr", "NOPE"], "--attr NOPE: tests.controllers.plugin_feature_joints "
     "has no attribute 'NOPE'; its controllers_for(...) results: JOINTS"),
    ("features", ["--attr", "PlatformJointPinv"], "--attr PlatformJointPinv: "
     "tests.controllers.plugin_feature_joints.PlatformJointPinv is a class, not a "
     "controllers_for(...) result; its controllers_for(...) results: JOINTS"),
    ("features", ["nosuch.module"], "MODULE 'nosuch.module' cannot be imported: No module "
     "named 'nosuch'"),
    # (already refused, as "-n 0: at least one pose")
    ("fk", ["-n", "0"], "-n: at least 1, got 0"),
    # (an IndexError traceback from np.percentile of no round trips, the emulator started)
    ("serial", ["--periods", "0"], "--periods: at least 1, got 0"),
    # (refused by the robot's step, after the emulator started: "dt must be positive")
    ("serial", ["--dt", "0"], "--dt: a positive control period in seconds, got 0.0"),
    ("serial", ["--dt", "-0.02"], "--dt: a positive control period in seconds, got -0.02"),
    # (a ValueError traceback, "I/O operation on closed file", the emulator process dead)
    ("serial", ["--line-rate", "0", "-1"], "--line-rate: non-negative rates in baud, got -1.0"),
    # (refused by the emulator's configuration, the latency given in seconds)
    ("serial", ["--latency", "-5"], "--latency: a reply latency in milliseconds >= 0, got "
     "-5.0"),
    ("serial", ["--garble", "1.5"], "--garble: a probability in [0, 1], got 1.5"),
    # (refused by the renderer naming its own keys, blur_px and noise_std)
    ("detect", ["--blur", "-1"], "--blur: a blur sigma [px] >= 0, got -1.0"),
    ("detect", ["--noise", "-2"], "--noise: a noise std [grey levels] >= 0, got -2.0"),
    # (already refused, after loading the scenario, as "--trials and --repeats must be >= 1")
    ("study", ["--trials", "0"], "--trials: at least 1, got 0"),
    ("study", ["--repeats", "0"], "--repeats: at least 1, got 0"),
    # (a ValueError traceback from sample_poses)
    ("vision", ["--poses", "0"], "--poses: at least 1, got 0"),
    # (0: a ValueError traceback from edge_points; 1 to 4: rows of NaN (the conic fit of
    # the omnidirectional camera needs 5 points), with 2 the SVD fit 90 deg off)
    ("vision", ["--points", "0"], "--points: at least 5 (the conic fit's least), got 0"),
    ("vision", ["--points", "4"], "--points: at least 5 (the conic fit's least), got 4"),
    # (a ValueError traceback from vision.noise.pixel_noise)
    ("vision", ["--sigma", "-1"], "--sigma: a finite non-negative pixel noise, got -1.0"),
]


def _no_work(*args: Any, **kwargs: Any) -> Any:
    raise AssertionError("the timed work ran: the bad value was not refused first")


@pytest.mark.parametrize(("module", "args", "says"), BAD,
                         ids=[f"{m} {' '.join(a)}" for m, a, _ in BAD])
def test_bad_values_are_refused_naming_the_option(module: str, args: list[str], says: str,
                                                  capsys: pytest.CaptureFixture[str],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    mod = importlib.import_module(f"benchmarks.perf.{module}")
    for name in WORK[module]:
        monkeypatch.setattr(mod, name, _no_work)
    if module == "study":
        import benchmarks.study.scenario

        monkeypatch.setattr(benchmarks.study.scenario, "load_scenario", _no_work)
    with pytest.raises(SystemExit) as info:
        mod.main(args)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert f"error: {says}\n" in err, err


class _ParsedError(Exception):
    pass


@pytest.mark.parametrize("module", sorted(WORK))
def test_every_option_says_its_default(module: str) -> None:
    """Every option taking a value (flags aside, off unless given) gives its default."""
    def caught(self: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> None:
        raise _ParsedError(self)

    with mock.patch.object(argparse.ArgumentParser, "parse_args", caught), \
            pytest.raises(_ParsedError) as parsed:
        importlib.import_module(f"benchmarks.perf.{module}").main([])
    parser = parsed.value.args[0]
    silent = [a.option_strings[-1] for a in parser._actions
              if a.option_strings and a.nargs != 0 and "default" not in (a.help or "")]
    assert silent == []


@pytest.mark.parametrize("module", ["calibration", "controllers", "detect", "dynamics",
                                    "features", "fk", "serial", "vision"])
def test_a_negative_seed_is_refused_and_the_usage_names_the_command(
        module: str, capsys: pytest.CaptureFixture[str]) -> None:
    """A negative --seed ended in numpy's ValueError traceback; the usage lines named
    ``python -m benchmarks.perf.NAME`` where the user typed ``hexapod-bench perf NAME``."""
    main = importlib.import_module(f"benchmarks.perf.{module}").main
    args = ["--seed", "-1"]
    with pytest.raises(SystemExit) as info:
        main(args)
    err = capsys.readouterr().err
    assert info.value.code == 2, err
    assert "argument --seed: a non-negative integer, got -1" in err, err
    assert f"usage: hexapod-bench perf {module}" in err, err
