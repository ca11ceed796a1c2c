"""The camera must agree with the encoders: the servo session's per-period camera check
(``docs/servo.md``, "The camera must agree with the encoders").

At the start (period 0, before any command) and at every period, the platform pose
*from the encoders* (the nominal forward kinematics of the measured lengths) is compared
with the pose *seen by the camera*: the rigid fit of the platform points to
``A_i + q_i u_i`` (:func:`visual_pose`: ``u_i`` the directions of the legs whose both
edges were found, ``A_i`` the base points in the camera frame, ``q_i`` the measured
lengths), mapped to the base frame by the camera's pose as the (calibrated) base points
place it. The camera says where the legs *point*, the encoders how long they are: a
camera that sees another motion points the legs elsewhere. Poses further apart than
``max_distance`` or ``max_angle`` stop the session (``ServoExit.SAFETY``); so does a
camera *blind* (no pose: a lost frame, fewer than :data:`MIN_LEGS` legs, collinear legs)
for ``blind_timeout``; a recording whose first frame gives no pose is refused
(``ServoExit.REFUSED``). SI units inside; millimetres and degrees in the messages.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.robot.exits import ServoExit, SessionStop
from benchmarks.robot.models import EncoderPose
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import Transform
from hexapod.se3 import log_so3, pose_error

log = logging.getLogger(__name__)

#: Default translation threshold [mm]. With the simulated camera (1 px noise, the loop's
#: detector) the camera pose lies 1.5 mm (median) and 3.9 mm (largest) from the encoder
#: pose over 180 poses of the deltalab workspace and the three camera presets (leg
#: directions from two nearly parallel edges are noisy; ``docs/servo.md``, "Camera
#: check"); a real camera adds its calibration error and its latency (one 20 ms period
#: at 50 mm/s: 1 mm). Ten millimetres is 2.5 times the largest and 6 times the median.
DEFAULT_CONSISTENCY_MM = 10.0
#: Default rotation threshold [deg]: 0.3 deg median and 0.81 deg largest simulated;
#: three degrees is 3.7 times the largest.
DEFAULT_CONSISTENCY_DEG = 3.0
#: Default blind-camera timeout [s].
DEFAULT_BLIND_TIMEOUT_S = 3.0
#: Fewest legs (both edges seen) for a camera pose.
MIN_LEGS = 3
#: Smallest second singular value of the seen platform points, relative to the
#: platform radius, for them not to count as collinear.
SPREAD = 1e-2


@dataclass(frozen=True)
class CheckResult:
    """One period's check: the legs (0-5) the camera pose was fitted to (empty: blind),
    the translation [m] and rotation [rad] between the camera and the encoder poses
    (NaN: blind), and why there is no camera pose (or None)."""

    legs: tuple[int, ...]
    distance: float
    angle: float
    why_blind: str | None = None


def visual_pose(normals: np.ndarray | None, edge_visible: np.ndarray | None,
                lengths: np.ndarray, base_points: np.ndarray, platform_points: np.ndarray,
                base_from_camera: Transform
                ) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]] | str:
    """The platform pose from the legs the camera sees and the measured lengths.

    Args:
        normals: (6, 2, 3) edge normals in the camera frame (NaN where missing), or None
            (a lost frame).
        edge_visible: (6, 2) which edges were found.
        lengths: (6,) measured leg lengths [m].
        base_points: (6, 3) base points ``A_i`` in the camera frame [m].
        platform_points: (6, 3) platform points in the platform frame [m].
        base_from_camera: The camera's pose in the base frame.

    Returns:
        ``(R, t, legs)``: the platform pose in the base frame and the legs used; or why
        there is none (a sentence).
    """
    from controllers.cartesian_ctc import directions_seen
    from controllers.mpc.prediction import fit_pose

    if normals is None:
        return "no image (lost frame)"
    u, seen = directions_seen(None, normals, None, edge_visible)
    q = np.asarray(lengths, float)
    seen &= np.isfinite(q)
    legs = tuple(int(i) for i in np.flatnonzero(seen))
    if len(legs) < MIN_LEGS:
        return (f"only {len(legs)} legs seen (both edges), the camera pose needs "
                f"{MIN_LEGS}")
    A = np.asarray(base_points, float)[seen]
    E = np.asarray(platform_points, float)[seen]
    s = np.linalg.svd(E - E.mean(axis=0), compute_uv=False)
    if s[1] < SPREAD * float(np.linalg.norm(E, axis=1).max()):
        return f"the legs seen ({_legs(legs)}) are collinear on the platform"
    Rc, tc = fit_pose(A + q[seen, None] * u[seen], E)
    bc = base_from_camera
    return bc.rotation @ Rc, bc.rotation @ tc + bc.translation, legs


def format_pose(R: np.ndarray, t: np.ndarray) -> str:
    """``x y z`` [mm] and the rotation vector [deg], for a message."""
    w = np.degrees(log_so3(np.asarray(R)))
    x = np.asarray(t) * 1e3
    return (f"({x[0]:.2f}, {x[1]:.2f}, {x[2]:.2f}) mm, rotation "
            f"({w[0]:.2f}, {w[1]:.2f}, {w[2]:.2f}) deg")


def _legs(legs: tuple[int, ...]) -> str:
    return ", ".join(str(i) for i in legs)


class CameraCheck:
    """The servo session's camera check (module docstring), a per-period check
    (:class:`~benchmarks.robot.loop.PeriodCheck`).

    Args:
        geometry: The nominal robot (platform points).
        base_points: (6, 3) base points in the camera frame (the controller's: nominal
            or calibrated) [m]; they place the camera (the rigid fit of the nominal
            base points to them).
        max_distance: Translation threshold [m] (> 0).
        max_angle: Rotation threshold [rad] (> 0).
        blind_timeout: Longest run of periods without a camera pose [s] (> 0).
        camera: The ``--camera`` spec, for the messages.
        must_agree_at_start: A recording: refuse the session when the first frame gives
            no camera pose.
        clock: Monotonic clock [s] (tests).

    Raises:
        BenchmarkError: A threshold or timeout that is not positive and finite.
    """

    #: Not called once a recording has ended (no image is not a blind period).
    needs_image = True

    def __init__(self, geometry: HexapodGeometry, base_points: np.ndarray,
                 max_distance: float = DEFAULT_CONSISTENCY_MM
                 * 1e-3, max_angle: float = math.radians(DEFAULT_CONSISTENCY_DEG),
                 blind_timeout: float = DEFAULT_BLIND_TIMEOUT_S, camera: str = "camera",
                 must_agree_at_start: bool = False,
                 clock: Callable[[], float] = time.monotonic) -> None:
        for name, value, unit, scale in (
                ("--consistency-mm", max_distance, "mm", 1e3),
                ("--consistency-deg", max_angle, "deg", 180 / math.pi),
                ("--blind-timeout-s", blind_timeout, "s", 1.0)):
            if not (math.isfinite(value) and value > 0):
                raise BenchmarkError(f"{name} must be a positive number of {unit}, got "
                                     f"{value * scale:g}")
        from controllers.mpc.prediction import fit_pose

        self.base_points = np.asarray(base_points, float)
        self.platform_points = np.asarray(geometry.platform_points, float)
        R, t = fit_pose(self.base_points, np.asarray(geometry.base_points, float))
        self.base_from_camera = Transform(R, t).inverse()
        self.max_distance, self.max_angle = float(max_distance), float(max_angle)
        self.blind_timeout = float(blind_timeout)
        self.camera = camera
        self.must_agree_at_start = must_agree_at_start
        self.clock = clock
        self.checked = 0
        self.worst_distance = 0.0
        self.worst_angle = 0.0
        self._encoder_pose = EncoderPose(geometry, "camera check: no encoder pose",
                                         warn=False)
        self._seen_at: float | None = None
        self._blind_why: str | None = None

    def __call__(self, step: int, lengths: np.ndarray, features: Any) -> None:
        """:meth:`compare` against the encoder pose of ``lengths``.

        Raises:
            SessionStop: As :meth:`compare`.
            BenchmarkError: No encoder pose for the first lengths.
        """
        q = np.asarray(lengths, float)
        R, t = self._encoder_pose(q)
        self.compare(step, q, R, t, None if features is None else features.normals,
                     None if features is None else features.edge_visible)

    def compare(self, step: int, lengths: np.ndarray, rotation: np.ndarray,
                translation: np.ndarray, normals: np.ndarray | None,
                edge_visible: np.ndarray | None) -> CheckResult:
        """Check one period (before its command) against a given encoder pose.

        Args:
            step: The period (0: the start check).
            lengths: (6,) measured leg lengths [m].
            rotation, translation: Their encoder pose ((3, 3), (3,) [m]).
            normals, edge_visible: This period's edges (as :func:`visual_pose`).

        Returns:
            What was checked.

        Raises:
            SessionStop: ``SAFETY``: the poses disagree, or the camera has been blind
                for ``blind_timeout``; ``REFUSED``: a recording whose first frame gives
                no pose.
        """
        now = self.clock()
        if self._seen_at is None:
            self._seen_at = now  # the blind timer starts with the session
        pose = visual_pose(normals, edge_visible, lengths, self.base_points,
                           self.platform_points, self.base_from_camera)
        if isinstance(pose, str):
            return self._blind(step, now, pose)
        Rv, tv, legs = pose
        dist, angle = (float(x) for x in pose_error(Rv, tv, rotation, translation))
        self.checked += 1
        self.worst_distance = max(self.worst_distance, dist)
        self.worst_angle = max(self.worst_angle, angle)
        if dist > self.max_distance or angle > self.max_angle:
            when = "at start, before any motion" if step == 0 else f"at period {step}"
            raise SessionStop(ServoExit.SAFETY, (
                f"the camera {self.camera} disagrees with the encoders {when}: camera pose "
                f"{format_pose(Rv, tv)} (legs {_legs(legs)}), encoder pose "
                f"{format_pose(rotation, translation)}: {dist * 1e3:.2f} mm and "
                f"{math.degrees(angle):.2f} deg apart (limits {self.max_distance * 1e3:g} "
                f"mm, {math.degrees(self.max_angle):g} deg: --consistency-mm, "
                f"--consistency-deg)"))
        if self._blind_why is not None:
            log.info("the camera sees the platform again (legs %s)", _legs(legs))
        self._seen_at, self._blind_why = now, None
        return CheckResult(legs, dist, angle)

    def _blind(self, step: int, now: float, why: str) -> CheckResult:
        """A period without a camera pose (``why``): refused at a recording's start, a
        safety stop past the blind timeout."""
        if step == 0 and self.must_agree_at_start:
            raise SessionStop(ServoExit.REFUSED, (
                f"the recording {self.camera} cannot be checked against the encoders at "
                f"start ({why}): a recording drives the robot only if it agrees with the "
                "encoders"))
        if self._blind_why is None:
            log.warning("camera check: no camera pose at period %d (%s)", step, why)
        self._blind_why = why
        assert self._seen_at is not None
        blind_for = now - self._seen_at
        if blind_for >= self.blind_timeout:
            raise SessionStop(ServoExit.SAFETY, (
                f"the camera {self.camera} has given no platform pose for {blind_for:.2f} s "
                f"(--blind-timeout-s {self.blind_timeout:g}; at period {step}: {why})"))
        return CheckResult((), math.nan, math.nan, why)

    def summary(self) -> str:
        """One line: how many periods were checked and the largest disagreement (none
        checked: said so, not a disagreement of zero)."""
        if not self.checked:
            return (f"camera check: no period checked (limits {self.max_distance * 1e3:g} mm, "
                    f"{math.degrees(self.max_angle):g} deg)")
        return (f"camera check: {self.checked} periods checked, largest disagreement "
                f"{self.worst_distance * 1e3:.2f} mm, {math.degrees(self.worst_angle):.2f} "
                f"deg (limits {self.max_distance * 1e3:g} mm, "
                f"{math.degrees(self.max_angle):g} deg)")
