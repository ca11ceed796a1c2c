"""No silent simulation (benchmarks.robot.models): which camera a session may use
with real hardware, checked before the robot is contacted."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.exceptions import BenchmarkError
from benchmarks.robot import servo
from benchmarks.robot.models import ALLOW_SIMULATED_FLAG, choose_camera, describe_camera
from hexapod.backends.registry import backends

# a port that cannot be opened: an error about it would mean the robot was contacted
NO_ROBOT = "serial:/nonexistent/hexapod-port"


class FakeHardware:
    """A plugin without a ``simulated`` attribute: hardware."""


class FakeModel:
    """A plugin that says it is a model."""

    simulated = True


def test_which_backends_are_simulated() -> None:
    assert backends.is_simulated("sim") and backends.is_simulated("emulator")
    assert backends.is_simulated("gcs-emulator")
    assert not backends.is_simulated("serial:/dev/ttyUSB0")
    assert not backends.is_simulated("gcs:tcp://192.168.0.10:50000")
    assert not backends.is_simulated("hexapod.backends.serial:SerialRobot:/dev/ttyUSB0")
    assert backends.is_simulated("hexapod.backends.sim:SimulatedRobot")


def test_a_plugin_is_hardware_unless_it_says_otherwise() -> None:
    from hexapod.backends.registry import BackendRegistry

    reg = BackendRegistry()
    reg._plugins_loaded = True  # no entry points: this registry only
    reg.register("hw", lambda a, g, s: FakeHardware())  # type: ignore[arg-type,return-value]
    reg.register("model", lambda a, g, s: FakeModel())  # type: ignore[arg-type,return-value]
    reg.register("said", lambda a, g, s: FakeHardware(),  # type: ignore[arg-type,return-value]
                 simulated=True)
    assert not reg.is_simulated("hw")
    assert not reg.is_simulated("model"), "the opener, not what it returns, is registered"
    assert reg.is_simulated("said")


def test_choose_camera() -> None:
    assert choose_camera("emulator", None, False) == "sim"
    assert choose_camera("sim", "video:a.avi", False) == "video:a.avi"
    assert choose_camera(NO_ROBOT, "device:0", False) == "device:0"
    assert choose_camera(NO_ROBOT, "sim", True) == "sim"
    with pytest.raises(BenchmarkError, match=r"is real hardware: give the camera"):
        choose_camera(NO_ROBOT, None, False)
    with pytest.raises(BenchmarkError, match=r"--camera sim with --backend serial:/nonex"):
        choose_camera(NO_ROBOT, "sim", False)


@pytest.mark.parametrize(("extra", "fragment"), [
    ([], "is real hardware: give the camera that watches it (--camera device:N"),
    (["--camera", "sim"], f"or add {ALLOW_SIMULATED_FLAG} to do it on purpose"),
    (["--camera", "sim", "--teach"], "would close the loop on images rendered"),
])
def test_the_cli_refuses_a_simulated_camera_on_hardware_before_contacting_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str],
        fragment: str) -> None:
    goal = tmp_path / "goal.toml"
    goal.write_text("lengths_mm = [415, 415, 415, 415, 415, 415]\n")
    assert servo.main(["--backend", NO_ROBOT, "--goal", str(goal), *extra]) == 2
    err = capsys.readouterr().err
    assert fragment in err
    assert "nonexistent/hexapod-port" in err and "could not" not in err.lower()


def test_describe_camera_names_the_file_and_the_pose() -> None:
    from hexapod.geometry import deltalab
    from vision.cameras import load_camera

    cam = load_camera("front", deltalab())
    text = describe_camera("device:0", "front", None, cam)
    assert text.startswith("camera device:0 (live; file front, perspective ")
    x = cam.camera_from_base.inverse().translation * 1e3
    assert f"at ({x[0]:.1f}, {x[1]:.1f}, {x[2]:.1f}) mm in the base frame" in text
    assert "pose from omni" in describe_camera("video:a.avi", "cam.yaml", "omni", cam)
