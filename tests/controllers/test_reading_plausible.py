"""Measured lengths no leg of the nominal robot can have (millimetres for metres, a leg
of 1e200 m) are refused, row by row, by every built-in controller, with the leg, the value
and the hint: taught in metres and fed millimetres, `joint-space` commanded 418 m/s,
`leg-edge` 3.2 m/s and `vision-ctc` 134 N with no reason given. The compiled steps
screen the readings (no cost per period); the reason comes from the row's own stroke."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from controllers import registry
from controllers.base import ControllerContext, Goal, Observation
from controllers.data import ObservationBatch
from controllers.plausible import reading_bounds
from hexapod import deltalab
from hexapod.compiled import LANE_ROWS
from hexapod.workspace import home_pose
from vision.cameras import front_camera
from vision.legs import observe_legs

ROBOT = deltalab()
CAMERA = front_camera(ROBOT)
R0, T0 = home_pose(ROBOT)[:2]
GOAL_SEEN = observe_legs(CAMERA, ROBOT, R0, T0)
SEEN = observe_legs(CAMERA, ROBOT, R0, T0 + np.array([0.003, 0.0, 0.002]))
A = CAMERA.camera_from_base.apply(ROBOT.base_points)
GOAL = Goal(normals=GOAL_SEEN.normals, lines=GOAL_SEEN.lines,
            directions=GOAL_SEEN.directions, edge_visible=GOAL_SEEN.edge_visible,
            lengths=GOAL_SEEN.lengths, rotation=R0, translation=T0)
BUILTINS = sorted(i.name for i in registry.info()
                  if i.package == "hexapod-vs" and ":" not in i.name)
MM = ("leg 0 at 415.627 m, where no leg of the nominal robot can be (its stroke 345 to "
      "485 mm) (millimetres? SI units: metres)")


def _law(name: str, rows: int = 1) -> object:
    law = registry.create(name)
    law.reset_batch([ControllerContext(A, ROBOT, CAMERA, 0.02, GOAL)] * rows)
    return law


def _observation(lengths: np.ndarray) -> Observation:
    return Observation(normals=SEEN.normals, lines=SEEN.lines, directions=SEEN.directions,
                       edge_visible=SEEN.edge_visible, lengths=lengths, q_dot=np.zeros(6),
                       t=0.0)


def _values(command: object) -> np.ndarray:
    forces = getattr(command, "forces", None)
    return np.asarray(forces if forces is not None else command.values)  # type: ignore[attr-defined]


def test_the_builtins_are_all_here() -> None:
    assert len(BUILTINS) == 16


@pytest.mark.parametrize("name", BUILTINS)
def test_millimetres_are_refused_with_the_hint(name: str) -> None:
    law = _law(name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (nothing computed on them: no overflow)
        cmd = law.step(_observation(SEEN.lengths * 1e3))  # type: ignore[attr-defined]
    assert cmd.reason is not None and cmd.reason.endswith(MM), cmd.reason
    assert not np.any(_values(cmd))
    ok = law.step(_observation(SEEN.lengths.copy()))  # type: ignore[attr-defined]
    assert ok.reason is None and np.any(_values(ok))  # the trial goes on


@pytest.mark.parametrize("rows", [3, LANE_ROWS + 2])
@pytest.mark.parametrize("name", BUILTINS)
def test_in_a_batch_only_the_row_in_millimetres_is_refused(name: str, rows: int) -> None:
    law = _law(name, rows)
    one = ObservationBatch.of(_observation(SEEN.lengths.copy()))
    assert one is not None
    batch = one.rows(np.zeros(rows, dtype=int))
    batch.trials[:] = np.arange(rows)
    batch.lengths[1] *= 1e3
    out = law.step_batch(batch)  # type: ignore[attr-defined]
    reasons = list(out.reasons)
    assert reasons[1] is not None and reasons[1].endswith(MM), reasons[1]
    assert reasons[:1] + reasons[2:] == [None] * (rows - 1)
    values = np.asarray(out.forces if out.forces is not None else out.values)
    assert not np.any(values[1]) and np.all(np.any(values[[0, 2]], axis=1))


def test_the_bounds_of_a_batch() -> None:
    lo, hi = reading_bounds([(0.345, 0.485), (0.38, 0.56)])
    assert (lo, hi) == pytest.approx((0.38 - 0.18, 0.56 + 0.18))  # the union
    assert reading_bounds([(0.345, 0.485), None]) == (-np.inf, np.inf)


@pytest.mark.parametrize("name", BUILTINS)
def test_a_negative_length_names_its_leg(name: str) -> None:
    """(The vision laws said "non-positive leg length -0.4 m", no leg; the others named
    it.)"""
    lengths = SEEN.lengths.copy()
    lengths[2] = -0.4
    cmd = _law(name).step(_observation(lengths))  # type: ignore[attr-defined]
    assert cmd.reason is not None and "leg 2 at -0.4 m" in cmd.reason, cmd.reason
    assert not np.any(_values(cmd))
