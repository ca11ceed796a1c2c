"""What a user needs to trust a setup (a robot, a camera, a task box) before a study.

:func:`check_setup` measures: the home pose and its leg lengths, the size of the reachable
workspace (the fraction of random poses of the task box inside the strokes, their ranges,
the reach along each axis from home), which leg edges the camera sees at home (with their
pixels) and over the workspace, and the conditioning of the edge interaction at home. It
lists the problems in plain words with the key to change; an ``"error"`` problem means
that every trial would fail the same way (``hexapod-bench check`` exits non-zero, ``run``
refuses the study before its first trial).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import inverse_kinematics
from hexapod.se3 import exp_so3
from hexapod.workspace import home_pose

#: Random poses drawn in the task box to measure the workspace.
WORKSPACE_SAMPLES = 2000
#: Reachable poses over which the camera's view is measured.
VIEW_SAMPLES = 300
#: Below this fraction of the task box inside the strokes, drawing a trial's start and goal
#: may fail (:func:`hexapod.workspace.sample_poses` gives up below about 1 in 1000).
LOW_FRACTION = 0.01
#: Fewest edges whose interaction can have the rank 6 the image laws need (an edge's
#: error ``n x n*`` has rank 2).
MIN_EDGES = 3
#: Smallest / largest singular value of the edge interaction below which it is singular.
SINGULAR_RATIO = 1e-6
#: Below this smallest/largest singular value ratio (a condition number over 1000) the
#: edges at home observe the pose poorly: a warning. (The number mixes metres and
#: radians: a robot ten times smaller gives 465 with the front camera, a telephoto camera
#: three times farther 675; a camera pose in radians where degrees are meant, 1505.)
POOR_RATIO = 1e-3


@dataclass(frozen=True)
class Problem:
    """Something that stops the setup from running (``"error"``) or may spoil it.

    Attributes:
        severity: ``"error"`` (every trial would fail the same way) or ``"warning"``.
        text: What is wrong, in plain words, with the key to change.
        topic: ``"camera"`` (what the camera sees: only the controllers that use the
            camera suffer), or ``"robot"`` (the workspace, the task).
    """

    severity: str
    text: str
    topic: str = "robot"
    #: Whether the trials it concerns fail (False: a warning of a poorer result).
    fails: bool = True
    #: The sweep point it was found at (``"payload.mass_kg = 20"``; empty: the study's),
    #: said after the text (:func:`benchmarks.study.preflight.measure_study` names a
    #: problem found the same at several points once, with its points).
    point: str = ""


@dataclass(frozen=True)
class Where:
    """How to name the keys of a setup in messages.

    Attributes:
        strokes: Where the strokes are set (``"stroke_mm in robot.toml"``).
        points: Where the joint points are set.
        camera: Where the camera is placed.
        task: Where the task box is set.
        intrinsics: Where the focal lengths are set.
    """

    strokes: str = "stroke_mm in the robot file"
    points: str = "base_points_mm / platform_points_mm in the robot file"
    camera: str = "[camera_from_base] in the camera file"
    task: str = "[task] max_translation_mm / max_angle_deg / margin_mm in the scenario"
    intrinsics: str = "fx_px / fy_px in the camera file"


@dataclass
class SetupReport:
    """The measurements of :func:`check_setup` (millimetres and degrees for display).

    Attributes:
        home_height_mm: Height of the home pose [mm].
        home_lengths_mm: (6,) leg lengths at home [mm].
        box: ``(max_translation_mm, max_angle_deg, margin_mm)`` of the task box.
        samples: Random poses drawn in the box.
        fraction: Fraction of them with every leg inside the strokes (less the margin).
        translation_range_mm: (3, 2) min and max of x, y, z of the reachable poses
            relative to home [mm] (NaN when none).
        max_angle_reached_deg: Largest rotation among the reachable poses [deg].
        reach_mm: Reach from home along +x, -x, +y, -y, +z, -z alone [mm].
        reach_deg: Reach from home about x, y, z (positive sense) alone [deg].
        home_visible: (6, 2) edges seen at home.
        home_pixels: (6, 2, 2, 2) pixels of the ends of each edge at home (base end,
            platform end), NaN where not imaged.
        home_ends: (6, 2, 2) where each end of each edge is at home
            (:func:`end_status`: ``"image"``, ``"outside"``, ``"far"``, ``"behind"``,
            ``"unimaged"``, ``"inside-leg"``).
        home_fraction: (6, 2) fraction of each edge's length in view at home (imaged,
            inside the image, not hidden).
        view_fraction: (6, 2) fraction of the reachable poses where each edge is seen.
        poses_blind: Fraction of the reachable poses where no edge is seen.
        poses_few_edges: Fraction of them where fewer than :data:`MIN_EDGES` are seen.
        poses_all_visible: Fraction where all 12 edges are seen.
        edge_ratio: Smallest / largest singular value of the edge interaction at home
            (the visible edges; NaN when none is visible).
        edge_condition: Its condition number (largest / smallest).
        problems: What is wrong.
    """

    home_height_mm: float
    home_lengths_mm: np.ndarray
    box: tuple[float, float, float]
    samples: int
    fraction: float
    translation_range_mm: np.ndarray
    max_angle_reached_deg: float
    reach_mm: np.ndarray
    reach_deg: np.ndarray
    home_visible: np.ndarray
    home_pixels: np.ndarray
    view_fraction: np.ndarray
    poses_blind: float
    poses_few_edges: float
    poses_all_visible: float
    edge_ratio: float
    edge_condition: float
    problems: list[Problem] = field(default_factory=list)
    home_ends: np.ndarray = field(default_factory=lambda: np.full((6, 2, 2), "image"))
    home_fraction: np.ndarray = field(default_factory=lambda: np.ones((6, 2)))

    @property
    def can_run(self) -> bool:
        """No problem is an error."""
        return not any(p.severity == "error" for p in self.problems)


def random_box_poses(geometry: HexapodGeometry, n: int, max_translation: float,
                     max_angle: float, rng: np.random.Generator
                     ) -> tuple[np.ndarray, np.ndarray]:
    """``n`` poses uniform in the task box: positions in a cube of half-width
    ``max_translation`` [m] around home, rotation vectors uniform in a ball of radius
    ``max_angle`` [rad] (the distribution of :func:`hexapod.workspace.sample_poses`)."""
    t = home_pose(geometry)[1] + rng.uniform(-max_translation, max_translation, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return exp_so3(d * (max_angle * rng.uniform(0, 1, n) ** (1 / 3))[:, None]), t


def _inside(geometry: HexapodGeometry, R: np.ndarray, t: np.ndarray,
            margin: float = 0.0) -> np.ndarray:
    q = inverse_kinematics(geometry, R, t)
    return np.all((q >= geometry.q_min + margin) & (q <= geometry.q_max - margin), axis=-1)


def axis_reach(geometry: HexapodGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Reach from home along each axis alone, by bisection on the stroke test.

    Returns:
        Translations along +x, -x, +y, -y, +z, -z [m] and rotations about x, y, z [rad]
        (0 when home itself is outside the strokes).
    """
    R0, t0 = home_pose(geometry)
    if not _inside(geometry, R0, t0):
        return np.zeros(6), np.zeros(3)
    dirs = np.vstack([np.eye(3), -np.eye(3)])[[0, 3, 1, 4, 2, 5]]
    lo, hi = np.zeros(6), np.full(6, 2.0 * geometry.q_max)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        ok = _inside(geometry, np.broadcast_to(R0, (6, 3, 3)), t0 + mid[:, None] * dirs)
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    alo, ahi = np.zeros(3), np.full(3, np.pi)
    for _ in range(40):
        mid = 0.5 * (alo + ahi)
        ok = _inside(geometry, exp_so3(np.eye(3) * mid[:, None]), np.broadcast_to(t0, (3, 3)))
        alo, ahi = np.where(ok, mid, alo), np.where(ok, ahi, mid)
    return lo, alo


def end_status(camera: Any, obs: Any) -> np.ndarray:
    """Where the two ends of each edge of one observation are, for the user: in the
    image, outside it (within one image size of it), far outside it, behind a
    perspective camera, not imaged by the lens (beyond a fisheye's or a mirror's field
    of view), or without edges (the camera inside the leg's cylinder).

    Args:
        camera: The camera of the observation.
        obs: One :class:`vision.legs.LegObservation` (not batched).

    Returns:
        (6, 2, 2) strings: ``"image"``, ``"outside"``, ``"far"``, ``"behind"``,
        ``"unimaged"`` or ``"inside-leg"``.
    """
    from vision.legs import limb_points

    ends = limb_points(obs.base_points, obs.directions, obs.radius, obs.lengths,
                       obs.normals, np.array([0.0, 1.0]))  # camera frame
    px = np.asarray(obs.segments, float)
    w, h = float(camera.width), float(camera.height)
    finite = np.all(np.isfinite(px), axis=-1)
    with np.errstate(invalid="ignore"):
        x, y = px[..., 0], px[..., 1]
        inside = finite & (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)
        near = finite & (x >= -w) & (x <= 2 * w) & (y >= -h) & (y <= 2 * h)
        behind = (ends[..., 2] <= 0) if camera.kind == "perspective" else np.zeros(
            finite.shape, bool)
    out = np.full(finite.shape, "unimaged", dtype=object)
    out[finite & ~near] = "far"
    out[near & ~inside] = "outside"
    out[inside] = "image"
    out[behind] = "behind"
    no_edges = ~np.all(np.isfinite(obs.normals), axis=-1)  # (6, 2)
    out[no_edges] = "inside-leg"
    return out


def edge_interaction_ratio(obs: Any) -> tuple[float, float]:
    """Smallest / largest singular value, and condition number, of the edge interaction
    ``L`` (``docs/math.md`` section 6) of the visible edges of one observation."""
    from controllers.tasks.base import map_blocks
    from controllers.tasks.leg_edge import EDGE_NORMALS

    vis = np.asarray(obs.edge_visible, bool)
    if not vis.any():
        return float("nan"), float("nan")
    legs, _ = np.nonzero(vis)
    n = obs.normals[vis]
    eye = np.broadcast_to(np.eye(3).reshape(1, 9), (len(n), 9))  # unused for normals
    _, L = map_blocks(EDGE_NORMALS.block_function, n, n, obs.directions[legs],
                      obs.base_points[legs], obs.lengths[legs], eye, eye)
    s = np.linalg.svd(L.reshape(-1, 6), compute_uv=False)
    ratio = float(s[-1] / s[0]) if s[0] > 0 else 0.0
    return ratio, (float(s[0] / s[-1]) if s[-1] > 0 else float("inf"))


def check_setup(geometry: HexapodGeometry, camera: Any, max_translation_mm: float = 60.0,
                max_angle_deg: float = 10.0, margin_mm: float = 5.0,
                needs_camera: bool = True, where: Where | None = None,
                seed: int = 0) -> SetupReport:
    """Measure a setup and list its problems.

    Args:
        geometry: The robot.
        camera: The camera (placed by its ``camera_from_base``).
        max_translation_mm: Half-width of the task box [mm].
        max_angle_deg: Largest rotation of the task box [deg].
        margin_mm: Distance kept from the stroke limits [mm].
        needs_camera: Whether the controllers need the camera (a blind camera is then an
            error, else a warning).
        where: How to name the keys in the messages.
        seed: Seed of the random poses (the report is reproducible).
    """
    from vision.legs import observe_legs

    where = where or Where()
    rng = np.random.default_rng(seed)
    problems: list[Problem] = []
    R0, t0 = home_pose(geometry)
    q0 = inverse_kinematics(geometry, R0, t0)
    out_legs = [i for i in range(6) if not geometry.q_min <= q0[i] <= geometry.q_max]
    stroke = f"[{geometry.q_min * 1e3:g}, {geometry.q_max * 1e3:g}] mm"
    if out_legs:
        if np.min(q0) > geometry.q_max:
            why = (f"even with the platform lowered onto the base the legs measure "
                   f"{_mm_list(q0[out_legs])} mm, longer than the longest length of the "
                   f"stroke {stroke}")
        else:
            why = (f"with the platform parallel to the base and centred, leg(s) "
                   f"{', '.join(map(str, out_legs))} cannot be within the stroke {stroke} at "
                   f"any height (at {t0[2] * 1e3:.1f} mm: {_mm_list(q0[out_legs])} mm)")
        metres = (" (a stroke under 10 mm: given in metres? stroke_mm is in millimetres)"
                  if geometry.q_max < 0.01 else "")
        problems.append(Problem("error", (
            f"empty workspace, no home pose: {why}{metres}; change {where.strokes}, or "
            f"{where.points}")))
    problems += unit_slips(geometry, where)
    if not out_legs:
        problems += _legs_crossing(geometry, R0, t0, where)
    R, t = random_box_poses(geometry, WORKSPACE_SAMPLES, 1e-3 * max_translation_mm,
                            np.deg2rad(max_angle_deg), rng)
    ok = _inside(geometry, R, t, 1e-3 * margin_mm)
    fraction = float(ok.mean())
    if not ok.any() and not out_legs:  # (no home pose already says it)
        problems.append(Problem("error", (
            f"empty workspace: none of {WORKSPACE_SAMPLES} random poses (within "
            f"{max_translation_mm:g} mm and {max_angle_deg:g} deg of the home pose) keeps "
            f"every leg {margin_mm:g} mm inside the stroke {stroke}; change {where.strokes}, "
            f"or {where.task}")))
    elif fraction < LOW_FRACTION and not out_legs:
        problems.append(Problem("warning", (
            f"small workspace: {100 * fraction:.2f} % of the random poses of the task box "
            f"keep the legs inside the strokes; drawing a trial's start and goal may fail; "
            f"shrink {where.task}, or widen {where.strokes}")))
    rel = t[ok] - t0
    trange = (np.stack([rel.min(axis=0), rel.max(axis=0)], axis=-1) * 1e3 if ok.any()
              else np.full((3, 2), np.nan))
    angles = np.degrees(np.arccos(np.clip((np.trace(R[ok], axis1=1, axis2=2) - 1) / 2,
                                          -1, 1))) if ok.any() else np.array([np.nan])
    reach_t, reach_r = axis_reach(geometry)

    home_obs = observe_legs(camera, geometry, R0, t0)
    kept = np.flatnonzero(ok)[:VIEW_SAMPLES]
    if len(kept):
        obs = observe_legs(camera, geometry, R[kept], t[kept])
        vis = np.asarray(obs.edge_visible, bool)
    else:
        vis = home_obs.edge_visible[None]
    seen = vis.reshape(len(vis), -1).any(axis=1)
    ratio, cond = edge_interaction_ratio(home_obs)
    report = SetupReport(
        home_height_mm=t0[2] * 1e3, home_lengths_mm=q0 * 1e3,
        box=(max_translation_mm, max_angle_deg, margin_mm), samples=WORKSPACE_SAMPLES,
        fraction=fraction, translation_range_mm=trange,
        max_angle_reached_deg=float(np.max(angles)), reach_mm=reach_t * 1e3,
        reach_deg=np.degrees(reach_r), home_visible=np.asarray(home_obs.edge_visible, bool),
        home_pixels=np.asarray(home_obs.segments, float), view_fraction=vis.mean(axis=0),
        poses_blind=float(1.0 - seen.mean()),
        poses_few_edges=float((vis.reshape(len(vis), -1).sum(axis=1) < MIN_EDGES).mean()),
        poses_all_visible=float(vis.reshape(len(vis), -1).all(axis=1).mean()),
        edge_ratio=ratio, edge_condition=cond, problems=problems,
        home_ends=end_status(camera, home_obs),
        home_fraction=np.nan_to_num(np.asarray(home_obs.visible_fraction, float)))
    if not out_legs:  # (without a home pose the camera's view of it is no advice)
        problems += _camera_problems(report, camera, home_obs, needs_camera, where)
    return report


def _legs_crossing(geometry: HexapodGeometry, R0: np.ndarray, t0: np.ndarray,
                   where: Where) -> list[Problem]:
    """A warning for each pair of legs whose cylinders meet at home away from their
    joints (between 10 % and 90 % of each leg's length): axes closer than two leg radii.
    Legs that share a joint's neighbourhood meet there by design; crossed legs (two rows
    of the points swapped) or legs thicker than their joints' spacing do not."""
    A = geometry.base_points
    B = (R0 @ geometry.platform_points.T).T + t0
    s = np.linspace(0.1, 0.9, 81)[:, None]
    axis = A[:, None, :] + s[None] * (B - A)[:, None, :]  # (6, 81, 3)
    out = []
    for i in range(6):
        for j in range(i + 1, 6):
            d = np.linalg.norm(axis[i][:, None] - axis[j][None], axis=2)
            k = np.unravel_index(int(np.argmin(d)), d.shape)
            if d[k] < 2 * geometry.leg_radius:
                out.append(Problem("warning", (
                    f"legs {i} and {j} meet at home: their axes pass {d[k] * 1e3:.1f} mm "
                    f"apart ({100 * s[k[0], 0]:.0f} % along leg {i}, {100 * s[k[1], 0]:.0f} % "
                    f"along leg {j}), closer than two leg radii ({2e3 * geometry.leg_radius:g} "
                    f"mm): no robot has them; check {where.points} (two rows swapped?) or "
                    "leg_radius_mm"), "robot"))
    return out


#: The smallest radius [m] of a hexapod's base or platform joints (the smallest
#: precision hexapods' are centimetres; points in metres give a fraction of a millimetre).
MIN_JOINT_RADIUS = 0.002


#: The fastest leg speed limit [m/s] a hexapod file is taken to mean (the fastest motion
#: simulators' legs move at about 1 m/s; micrometres per second typed into
#: ``max_speed_mm_s`` give a thousand times the speed).
MAX_LEG_SPEED = 2.0


def unit_slips(geometry: HexapodGeometry, where: Where) -> list[Problem]:
    """Warnings for values no hexapod has, which a unit slip gives: a leg radius under
    1 mm, a leg speed limit under 0.1 mm/s (slow precision hexapods move at a fraction
    of a millimetre per second) or over :data:`MAX_LEG_SPEED`; and an error for joints
    within :data:`MIN_JOINT_RADIUS` of their centre (the base's or the platform's points
    in metres: no leg can reach them, every trial would fail)."""
    out = []
    robot = where.strokes.split(" in ", 1)[-1]  # the robot file
    for key, points in (("base_points_mm", geometry.base_points),
                        ("platform_points_mm", geometry.platform_points)):
        radius = float(np.linalg.norm(points - points.mean(axis=0), axis=1).max())
        if radius < MIN_JOINT_RADIUS:
            out.append(Problem("error", f"the joints of {key} lie within "
                               f"{radius * 1e3:.3g} mm of their centre: given in metres? "
                               f"{key} is in millimetres; check {key} in {robot}", "robot"))
    if geometry.leg_radius < 1e-3:
        out.append(Problem("warning", f"leg radius {geometry.leg_radius * 1e3:g} mm: given "
                           "in metres? leg_radius_mm is in millimetres (the camera sees "
                           f"a leg's two edges 2 radii apart); check leg_radius_mm in {robot}",
                           "robot"))
    if geometry.max_speed < 1e-4:
        out.append(Problem("warning", f"leg speed limit {geometry.max_speed * 1e3:g} mm/s: "
                           "given in m/s? max_speed_mm_s is in millimetres per second; "
                           f"check max_speed_mm_s in {robot}", "robot"))
    if geometry.max_speed > MAX_LEG_SPEED:
        out.append(Problem("warning", f"leg speed limit {geometry.max_speed * 1e3:g} mm/s "
                           f"(over {MAX_LEG_SPEED:g} m/s): given in micrometres per second? "
                           f"max_speed_mm_s is in millimetres per second; check "
                           f"max_speed_mm_s in {robot}", "robot"))
    return out


def _camera_problems(report: SetupReport, camera: Any, home_obs: Any, needs_camera: bool,
                     where: Where) -> list[Problem]:
    """What the camera's view says: blind at home or over the workspace, too few edges."""
    out: list[Problem] = []
    n_home = int(report.home_visible.sum())
    severity = "error" if needs_camera else "warning"
    if n_home == 0:
        depth = np.einsum("ij,ij->i", home_obs.base_points, np.ones((6, 3)) * [0, 0, 1])
        if camera.kind == "perspective" and np.all(depth < 0):
            why = (f"the robot is behind the camera (its base joints are "
                   f"{-np.max(depth) * 1e3:.0f} mm or more behind the image plane; "
                   "p_camera = R p_base + t, and a perspective camera looks along its +z)")
        elif not np.any(np.isfinite(report.home_pixels)):
            why = "no point of any leg projects into the image"
        else:
            ends = report.home_ends
            counts = [(int(np.sum(ends == k)), text) for k, text in (
                ("behind", "behind the camera"), ("far", "far outside the image"),
                ("outside", "outside the image"), ("unimaged", "beyond the lens's field"),
                ("image", "in the image"))]
            why = (f"the legs project outside the {camera.width}x{camera.height} image or "
                   "hide one another (of the 24 edge ends: "
                   + ", ".join(f"{n} {text}" for n, text in counts if n) + ")")
        out.append(Problem(severity, f"the camera sees no leg edge at the home pose: {why}; "
                           f"change {where.camera}", "camera"))
    elif report.poses_blind >= 1.0:
        out.append(Problem(severity, "the camera sees no leg edge at any reachable pose of "
                           f"the task box; change {where.camera}", "camera"))
    elif report.poses_few_edges >= 1.0:
        out.append(Problem(severity, f"the camera sees fewer than {MIN_EDGES} leg edges at "
                           "every reachable pose of the task box (the image laws need at "
                           "least six independent rows, two per edge): no trial of a law "
                           f"that steers by the image can move; change {where.camera}",
                           "camera"))
    elif report.poses_blind > 0:
        out.append(Problem("warning", f"the camera sees no leg edge at "
                           f"{100 * report.poses_blind:.1f} % of the reachable poses; trials "
                           f"with such a goal fail; change {where.camera}, or {where.task}",
                           "camera"))
    pose = getattr(camera, "camera_from_base", None)
    shift = np.zeros(3) if pose is None else np.asarray(pose.translation, dtype=float)
    if 0.0 < np.abs(shift).max() < 2e-3:  # the camera within 2 mm of the base's origin
        out.append(Problem("warning", (
            f"the camera's centre is {np.linalg.norm(shift) * 1e3:.3g} mm from the base "
            f"frame's origin (camera_from_base translation {_mm_list(shift)} mm): given in "
            f"metres? The camera's translation is in millimetres; check {where.camera}"),
            "camera", fails=False))
    if min(camera.fx, camera.fy) < 50.0:  # pixels: no camera has a focal length that short
        out.append(Problem("warning", (
            f"focal length {min(camera.fx, camera.fy):g} px: given in millimetres? fx_px and "
            "fy_px are in pixels (focal length in mm / pixel pitch in mm: about 1000 for a "
            f"usual camera); the legs are then a few pixels long; check {where.intrinsics}"),
            "camera", fails=False))
    w, h = int(camera.width), int(camera.height)
    off = max(abs(camera.cx - (w - 1) / 2) / w, abs(camera.cy - (h - 1) / 2) / h)
    if off > CENTRE_FRACTION:  # (a calibration's is within a few % of the centre)
        swapped = max(abs(camera.cx - (h - 1) / 2) / h,
                      abs(camera.cy - (w - 1) / 2) / w) <= CENTRE_FRACTION
        out.append(Problem("warning", (
            f"the principal point ({camera.cx:.1f}, {camera.cy:.1f}) px is {100 * off:.0f} % "
            f"of the {w}x{h} image's size from its centre: "
            + (f"the width and height swapped? (it is near the centre of a {h}x{w} image)"
               if swapped else "a cropped image's calibration, or another camera's?")
            + f"; check {where.intrinsics}"), "camera", fails=False))
    if n_home and SINGULAR_RATIO <= report.edge_ratio < POOR_RATIO:
        out.append(Problem("warning", (
            f"the edges seen at home observe the platform's pose poorly in some direction "
            f"(edge interaction condition number {report.edge_condition:.0f}; the built-in "
            f"cameras give 22 to 67): image noise is amplified as much there; check "
            f"{where.camera} (a pose in radians where degrees are meant gives this)"),
            "camera", fails=False))
    if n_home and report.edge_ratio < SINGULAR_RATIO:
        out.append(Problem("warning", (
            f"the {n_home} edges seen at home do not determine the six degrees of freedom "
            f"of the platform (edge interaction singular: smallest/largest singular value "
            f"{report.edge_ratio:.1e}): a law that steers by the image refuses to move at "
            f"such a pose (rank < 6); change {where.camera} "
            "so that it sees more legs"), "camera"))
    return out


#: How far from the image's centre a principal point may lie before ``check`` warns
#: [fraction of the image's width or height].
CENTRE_FRACTION = 0.1


def _mm_list(values: np.ndarray) -> str:
    return ", ".join(f"{v * 1e3:.1f}" for v in values)
