"""What the hosts do when a robot backend fails (tests/hexapod/failing_robot.py): the
robot is halted, then closed, whatever failed; the failure is named, as the backend's,
with the exit code of a robot failure, not an internal error's traceback."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hexapod.backends.conformance import check_backend
from hexapod.backends.registry import backends
from hexapod.exceptions import BackendPluginError
from hexapod.geometry import deltalab
from tests.hexapod import failing_robot
from tests.hexapod.failing_robot import CALLS

SPEC = "tests.hexapod.failing_robot:FailingRobot"


@pytest.fixture(autouse=True)
def _calls() -> None:
    CALLS.clear()


def _host_calls() -> list[str]:
    """The calls the host made (the simulator's own set-up left out)."""
    return [c for where, c in CALLS if where]


def test_a_plugin_that_fails_to_open_is_named_not_a_traceback() -> None:
    with pytest.raises(BackendPluginError, match="ValueError: vendor SDK: device not found"):
        backends.open(f"{SPEC}:open", deltalab())


def test_a_failed_move_to_the_start_halts_the_robot_before_closing_it() -> None:
    """reset() is the longest move a real robot makes; its failure closed it unhalted."""
    with pytest.raises(BackendPluginError, match="RuntimeError: vendor SDK: reset failed"):
        backends.open(f"{SPEC}:reset", deltalab(), np.full(6, deltalab().q_mid))
    assert _host_calls() == ["reset", "halt", "close"]


def test_a_failed_close_does_not_hide_why_the_move_to_the_start_failed() -> None:
    """close() raising after a failed reset() replaced the reset's exception."""
    with pytest.raises(BackendPluginError, match="reset failed"):
        backends.open(f"{SPEC}:reset+close", deltalab(), np.full(6, deltalab().q_mid))
    assert _host_calls() == ["reset", "halt", "close"]


def test_conformance_fails_a_backend_that_raises_and_halts_it() -> None:
    g = deltalab()
    report = check_backend(lambda geo, q: backends.open(f"{SPEC}:step", g, q), g)
    assert not report.ok
    assert any("the check stopped after 0 period(s): RuntimeError: vendor SDK: drive fault "
               "E42" in p
               for p in report.problems), report.problems
    assert _host_calls()[-2:] == ["halt", "close"]


def test_conformance_halts_the_robot_on_ctrl_c() -> None:
    g = deltalab()
    with pytest.raises(KeyboardInterrupt):
        check_backend(lambda geo, q: backends.open(f"{SPEC}:step-interrupt", g, q), g)
    assert _host_calls()[-2:] == ["halt", "close"]  # (close only, before)


def test_a_close_that_raises_does_not_undo_a_trial(tmp_path: Path) -> None:
    """The trial ran to its end; closing the robot failed after: said, the row kept
    (it was 'did not run to its end', and the run 'cannot run')."""
    from benchmarks.cli import main
    from benchmarks.study.runner import read_results

    out = tmp_path / "run"
    assert main(["run", "quick", "--backend", f"{SPEC}:close", "--controllers", "leg-edge",
                 "--trials", "1", "--out", str(out), "--no-progress"]) == 0
    (row,) = read_results(out)
    assert row["failure"] is None and row["converged"]
    assert _host_calls()[-2:] == ["halt", "close"]


@pytest.mark.slow
@pytest.mark.parametrize(("where", "code", "said"), [
    ("five-legs", 5, "at the start: the backend measured 5 values of shape (5,)"),
    ("step", 4, "FailingRobot: its step raised RuntimeError: vendor SDK: drive fault E42"),
])
def test_a_servo_session_stops_safely_on_a_failing_plugin(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], where: str, code: int,
        said: str) -> None:
    """Five lengths crashed the session before they were checked (exit 1, a traceback);
    a plugin's RuntimeError in step was an 'internal error' with a traceback: a safety
    stop (5) and a robot failure (4), the robot halted and closed, the record final."""
    from benchmarks.robot import servo
    from tests.benchmarks.robot.sessions import final, goal_file

    out = tmp_path / "session"
    assert servo.main(["--backend", f"{SPEC}:{where}", "--camera", "sim",
                       "--simulated-camera-on-real-robot", "--goal",
                       str(goal_file(tmp_path)), "--out", str(out), "--dt", "0.03",
                       "--max-steps", "20"]) == code
    text = " ".join(capsys.readouterr().out.split())
    assert said in text and "Traceback" not in text
    assert final(out)["exit_code"] == code
    assert _host_calls()[-2:] == ["halt", "close"]
    assert failing_robot.CALLS is CALLS


def test_a_plugin_module_off_the_path_is_said_so_and_a_typo_is_a_typo() -> None:
    """'my_robot:LaggingRobot' without the module on PYTHONPATH was 'unknown backend',
    hiding the ModuleNotFoundError; a misspelt registered name stays a typo."""
    from hexapod.exceptions import UnknownBackendError

    with pytest.raises(BackendPluginError, match=r"No module named 'no_such_robot' \(is the "
                       r"folder of no_such_robot.py on PYTHONPATH"):
        backends.resolve("no_such_robot:LaggingRobot")
    with pytest.raises(UnknownBackendError, match="did you mean 'serial'"):
        backends.resolve("seial:/dev/ttyUSB0")


@pytest.mark.parametrize("option", [["--lag", "0.02"], ["--watchdog", "100"],
                                    ["--drive-fault-after", "3"]])
def test_the_serial_boards_options_are_refused_with_the_gcs_controller(
        option: list[str]) -> None:
    """--drive-fault-after with --gcs was accepted and ignored (the GCS controller has
    no drive fault to latch), where --lag and --watchdog were refused."""
    from hexapod.backends.emulator import build_parser, gcs_config_from_args
    from hexapod.exceptions import BackendError

    args = build_parser().parse_args(["--gcs", "--pty", *option])
    with pytest.raises(BackendError, match=f"{option[0]} is an option of the serial board"):
        gcs_config_from_args(args)


def test_a_pipelined_exchange_is_named_on_one_line() -> None:
    """A GCS timeout during 'POS?' and 'ERR?' sent together printed the newline between
    them, across two lines of the console."""
    from hexapod.link_errors import LinkError

    text = str(LinkError("tcp://127.0.0.1:50000", "no answer within 500.0 ms",
                         "POS?\nERR?"))
    assert "\n" not in text and text.endswith("during 'POS?; ERR?'")


@pytest.mark.slow
def test_a_servo_session_says_its_robot_failed_to_close(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The plugin's close() raised at the end of a session: after a converged one the
    console said only 'converged' (the failure was in the record's reason alone); it
    warns of it, whatever the session's end (here its --max-steps)."""
    from benchmarks.robot import servo
    from tests.benchmarks.robot.sessions import final, goal_file

    out = tmp_path / "session"
    code = servo.main(["--backend", f"{SPEC}:close", "--camera", "sim",
                       "--simulated-camera-on-real-robot", "--goal",
                       str(goal_file(tmp_path)), "--out", str(out), "--dt", "0.03",
                       "--max-steps", "20"])
    text = " ".join(capsys.readouterr().out.split())
    assert code == 3 and "warning: closing the robot failed: vendor SDK: close failed" in text
    assert "closing the robot failed" in final(out)["reason"]


def test_messages_print_plain_numbers() -> None:
    """A NaN's index printed as (np.int64(0), np.int64(0)), a stroke end as
    0.34500000000000003 m."""
    from hexapod.dynamics.model import checked_array
    from hexapod.exceptions import InertiaError, ShapeError

    with pytest.raises(ShapeError) as info:
        checked_array("twist", np.array([[np.nan, 0.0]]), (2,))
    assert "at index (0, 0)" in str(info.value) and "np.int64" not in str(info.value)
    g = deltalab()
    with pytest.raises(InertiaError) as inertia:
        g.inertia.replace(body_com=171.0).check_legs(g.stroke[0])
    assert "q_min = 0.345 m" in str(inertia.value)


def test_a_lag_with_the_emulators_dynamics_is_refused() -> None:
    """--lag beside --dynamics was accepted and had no effect (the drives move the legs);
    the board's own arguments (a lag of 0 with dynamics) still pass."""
    from hexapod.backends.emulator import build_parser, config_from_args
    from hexapod.exceptions import BackendError

    with pytest.raises(BackendError, match="--lag is the legs' first-order lag"):
        config_from_args(build_parser().parse_args(["--pty", "--dynamics", "--lag", "0.02"]))
    board, _ = config_from_args(build_parser().parse_args(["--pty", "--dynamics", "--lag",
                                                           "0.0"]))
    assert board.dynamics is not None


def test_an_unknown_gcs_emulator_option_lists_the_emulators_keys_too() -> None:
    """It listed the GCS backend's keys alone, not latency_ms, drop, process..."""
    from hexapod.backends.gcs_emulated import parse_spec
    from hexapod.exceptions import BackendError

    with pytest.raises(BackendError, match="gcs-emulator option 'foo=1'") as info:
        parse_spec("latency_ms=1,foo=1")
    assert all(k in str(info.value) for k in ("latency_ms", "process", "vmo", "drop"))
    assert parse_spec("latency_ms=1,vmo=always,process=0")[1] is False
