"""GCS formatting and parsing, the official error texts, and the pose conventions."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod import HexapodGeometry
from hexapod.backends import gcs_protocol as gp
from hexapod.backends.gcs_pose import (
    PoseConvention,
    from_wire,
    rotation_from_uvw,
    to_wire,
    uvw_from_rotation,
)
from hexapod.link_errors import (
    GcsControllerError,
    GcsOutOfLimitsError,
    GcsReplyError,
    GcsStoppedError,
)


def test_numbers_on_the_wire() -> None:
    assert gp.format_number(1.5) == "1.5"
    assert gp.format_number(-0.0) == "0"
    assert gp.format_number(-1e-12) == "0"
    assert gp.format_number(2.0) == "2"
    assert gp.format_number(-0.000123456789) == "-0.000123457"
    with pytest.raises(ValueError):
        gp.format_number(float("nan"))
    assert gp.format_answer_number(-1e-9) == "0.000000"
    assert gp.format_answer_number(12.5) == "12.500000"
    assert gp.parse_number("-1.5e-3") == -0.0015
    for bad in ("nan", "inf", "0x10", "1,5", ""):
        with pytest.raises(ValueError):
            gp.parse_number(bad)


def test_commands() -> None:
    assert gp.command("MOV", {"X": 1.5, "W": -2}) == "MOV X 1.5 W -2"
    assert gp.command("POS?") == "POS?"
    assert gp.encode("MOV X 1", "ERR?") == b"MOV X 1\nERR?\n"
    assert gp.parse_axis_values(["X", "1", "U", "-0.5"]) == {"X": 1.0, "U": -0.5}
    with pytest.raises(gp.CommandSyntaxError) as exc:
        gp.parse_axis_values(["R", "1"])
    assert exc.value.code == gp.GcsError.INVALID_AXIS_IDENTIFIER
    assert gp.parse_axis_values(["R", "1"], gp.PIVOT_AXES) == {"R": 1.0}
    assert gp.parse_axis_list([]) == list(gp.AXES)


def test_answer_framing() -> None:
    assert gp.frame_answer(["X=1", "Y=2"]) == b"X=1 \nY=2\n"
    assert gp.frame_answer(["0"]) == b"0\n"
    assert gp.frame_answer([]) == b""
    assert gp.answer_end(b"X=1 \nY=2\nZ") == 9
    assert gp.answer_end(b"X=1 \nY=2 \n") == -1  # continues
    assert gp.answer_end(b"\n") == 1
    assert gp.answer_lines(b"X=1 \nY=2\n") == ["X=1", "Y=2"]


def test_answer_parsing() -> None:
    assert gp.parse_axis_answer(b"Y = 2.5 \nX=1\n", ("X", "Y")) == {"X": 1.0, "Y": 2.5}
    for bad in (b"X=1\n", b"X=1 \nX=2\n", b"X=a \nY=1\n", b"7\n", b"X=1 \nQ=1\n"):
        with pytest.raises(GcsReplyError):
            gp.parse_axis_answer(bad, ("X", "Y"), "POS? X Y")
    assert gp.parse_int_answer(b"10\n") == 10
    assert gp.parse_float_answer(b"12.5\n") == 12.5
    with pytest.raises(GcsReplyError):
        gp.parse_int_answer(b"X=1\n")
    with pytest.raises(GcsReplyError):
        gp.parse_int_answer(b"\xff\n")


def test_official_error_numbers_and_texts() -> None:
    # PI's numbers and texts (pipython gcserror)
    assert gp.error_text(0) == "No error"
    assert gp.error_text(1) == "Parameter syntax error"
    assert gp.error_text(2) == "Unknown command"
    assert gp.error_text(7) == "Position out of limits"
    assert gp.error_text(10) == "Controller was stopped by command"
    assert gp.error_text(15) == "Invalid axis identifier"
    assert gp.error_text(17) == "Parameter out of range"
    assert "1234" in gp.error_text(1234)
    e = gp.controller_error(7, "MOV Z 100", "tcp://127.0.0.1:1")
    assert isinstance(e, GcsOutOfLimitsError)
    assert (e.code, e.text, e.command) == (7, "Position out of limits", "MOV Z 100")
    assert "error 7 (Position out of limits) after 'MOV Z 100'" in str(e)
    assert isinstance(gp.controller_error(10), GcsStoppedError)
    assert type(gp.controller_error(15)) is GcsControllerError


@pytest.mark.parametrize("order", ["moving-xyz", "fixed-xyz"])
def test_uvw_round_trip(order: str) -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        uvw = rng.uniform(-0.5, 0.5, 3)
        R = rotation_from_uvw(*uvw, order)
        assert np.allclose(R @ R.T, np.eye(3))
        assert np.allclose(uvw_from_rotation(R, order), uvw, atol=1e-12)


def test_moving_axes_is_x_then_y_about_the_moved_axis() -> None:
    u, v = np.deg2rad(30), np.deg2rad(20)
    R = rotation_from_uvw(u, v, 0.0, "moving-xyz")
    Ru = rotation_from_uvw(u, 0.0, 0.0)
    y_moved = Ru @ np.array([0.0, 1.0, 0.0])  # V turns about the Y axis U has moved
    assert np.allclose(R @ np.array([0.0, 1.0, 0.0]), y_moved)


def test_pose_convention(geometry: HexapodGeometry) -> None:
    pivot = np.array([0.01, 0.0, 0.03])
    conv = PoseConvention.for_geometry(geometry, pivot)
    R, t = conv.pose(np.zeros(6))
    assert np.allclose(R, np.eye(3)) and np.allclose(t, [0, 0, geometry.home_height])
    c = np.array([0.002, -0.001, 0.004, 0.01, -0.02, 0.03])
    R, t = conv.pose(c)
    assert np.allclose(R @ pivot + t, np.array([0.01, 0.0, geometry.home_height + 0.03]) + c[:3])
    assert np.allclose(conv.coords(R, t), c, atol=1e-14)
    assert np.allclose(from_wire(to_wire(c)), c)
    assert to_wire(c)["X"] == pytest.approx(2.0) and to_wire(c)["U"] == pytest.approx(
        np.rad2deg(0.01))
