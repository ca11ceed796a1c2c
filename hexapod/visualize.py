"""MeshCat scene of the hexapod: live view, replay of a recorded trial, static HTML export.

The scene is the closed-chain Pinocchio model (:mod:`hexapod.model`) drawn by
:class:`pinocchio.visualize.MeshcatVisualizer`: base, platform and the six legs
as cylinders of the true radius, plus the camera as a frustum at its pose, the
goal pose as a translucent ghost platform, and leg colours that mark the legs
whose edges the camera does not see (occluded or outside the image).

Nothing here waits for a browser: the MeshCat server (loopback only) is
started by ``meshcat.Visualizer``; live updates are rate-limited so that an
unwatched viewer does not slow a control loop; the HTML export asks the server
for the scene (``static_html``), never for a screenshot.

A trial record is the ``.npz`` file the benchmark writes for a recorded trial
(see :func:`load_trial` for its keys). ``hexapod`` knows nothing of cameras or
controllers: records and camera drawings take plain arrays.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hexapod.exceptions import HexapodError
from hexapod.geometry import HexapodGeometry
from hexapod.model import (
    LEG_BODY_COLOR,
    LEG_ROD_COLOR,
    HexapodModel,
    build_model,
)

log = logging.getLogger(__name__)

#: Colour of a leg whose edges the camera does not see (RGBA).
HIDDEN_LEG_COLOR = np.array([0.85, 0.10, 0.10, 1.0])
#: Colour of the goal outline (hex RGB).
GOAL_COLOR = 0x2277FF
#: Colour of the camera frustum (hex RGB).
CAMERA_COLOR = 0x22AA22
#: Minimum time between two live updates [s] (30 Hz).
LIVE_PERIOD = 1.0 / 30.0

#: Keys of a trial record, with their expected number of dimensions.
RECORD_KEYS: dict[str, int] = {
    "t": 1, "lengths": 2, "rotations": 3, "translations": 2, "edge_visible": 3,
    "error_norm": 1, "position_error": 1, "orientation_error": 1, "velocities": 2,
    "goal_rotation": 2, "goal_translation": 1, "camera_from_base": 2, "camera_kind": 0,
    "camera_K": 2, "camera_size": 1, "camera_xi": 0, "base_points": 2, "platform_points": 2,
    "stroke": 1, "leg_radius": 0, "scenario": 0, "controller": 0, "trial": 0,
}


class RecordError(HexapodError, ValueError):
    """A trial record file is missing, unreadable or lacks a key.

    Attributes:
        path: The file.
        key: The missing or malformed key (None for the file itself).
        problem: What is wrong.
    """

    def __init__(self, path: str, problem: str, key: str | None = None) -> None:
        self.path = path
        self.key = key
        self.problem = problem
        super().__init__(f"{path}: " + (f"key '{key}': " if key else "") + problem)


@dataclass
class TrialRecord:
    """Time series of one closed-loop trial (as saved by the benchmark).

    Attributes:
        arrays: Every array of the record, by key (see :data:`RECORD_KEYS`).
        path: The file it was read from.
    """

    arrays: dict[str, np.ndarray]
    path: str = "<memory>"

    def __getitem__(self, key: str) -> np.ndarray:
        return self.arrays[key]

    @property
    def frames(self) -> int:
        """Number of recorded control periods."""
        return len(self.arrays["t"])

    @property
    def geometry(self) -> HexapodGeometry:
        """The robot drawn (the nominal geometry of the study)."""
        a = self.arrays
        return HexapodGeometry(a["base_points"], a["platform_points"],
                               (float(a["stroke"][0]), float(a["stroke"][1])),
                               float(a["leg_radius"]), name=str(a["scenario"]))

    @property
    def title(self) -> str:
        """``scenario / controller / trial k``."""
        a = self.arrays
        return f"{a['scenario']} / {a['controller']} / trial {int(a['trial'])}"


def save_trial(path: str | Path, **arrays: Any) -> Path:
    """Save a trial record (compressed ``.npz``), checking its keys first.

    The file is written beside its final name and renamed, so that an interrupted
    run never leaves a truncated record.
    """
    missing = [k for k in RECORD_KEYS if k not in arrays]
    if missing:
        raise RecordError(str(path), f"missing keys {missing}")
    p = Path(path)
    tmp = p.with_name(p.name + f".{os.getpid()}.tmp.npz")
    data: dict[str, Any] = {k: np.asarray(v) for k, v in arrays.items()}
    np.savez_compressed(tmp, **data)
    os.replace(tmp, p)
    return p


def load_trial(path: str | Path) -> TrialRecord:
    """Read and validate a trial record.

    Raises:
        RecordError: Naming the file and the missing or malformed key.
    """
    p = Path(path)
    if not p.exists():
        raise RecordError(str(p), "no such trial record")
    try:
        with np.load(p, allow_pickle=False) as data:
            arrays = {k: np.array(data[k]) for k in data.files}
    except (OSError, ValueError) as exc:
        raise RecordError(str(p), f"not a readable .npz record: {exc}") from None
    for key, ndim in RECORD_KEYS.items():
        if key not in arrays:
            raise RecordError(str(p), "missing", key)
        if arrays[key].ndim != ndim:
            raise RecordError(str(p), f"expected {ndim} dimensions, got shape "
                              f"{arrays[key].shape}", key)
    n = len(arrays["t"])
    for key in ("lengths", "rotations", "translations", "edge_visible"):
        if len(arrays[key]) != n:
            raise RecordError(str(p), f"{len(arrays[key])} frames but t has {n}", key)
    if n == 0:
        raise RecordError(str(p), "the record has no frame", "t")
    return TrialRecord(arrays, str(p))


def _frustum_segments(camera_from_base: np.ndarray, K: np.ndarray, size: np.ndarray,
                      kind: str, depth: float = 0.12) -> np.ndarray:
    """End points (3, 2N) in the base frame of the camera drawing's line segments."""
    T = np.asarray(camera_from_base, dtype=float)
    R, p = T[:3, :3], T[:3, 3]
    centre = -R.T @ p
    w, h = float(size[0]), float(size[1])
    if kind == "perspective":
        Kinv = np.linalg.inv(K)
        corners = [Kinv @ np.array([u, v, 1.0]) for u, v in ((0, 0), (w, 0), (w, h), (0, h))]
        corners = [c / c[2] * depth for c in corners]
    else:  # a wide cone for a catadioptric camera: 4 rays at 60 deg off the axis
        corners = [depth * np.array([np.sin(1.05) * np.cos(a), np.sin(1.05) * np.sin(a),
                                     np.cos(1.05)]) for a in np.arange(4) * np.pi / 2]
    pts = [R.T @ c + centre for c in corners]
    segs = []
    for k in range(4):
        segs += [centre, pts[k], pts[k], pts[(k + 1) % 4]]
    return np.array(segs).T


class HexapodViewer:
    """A MeshCat view of a hexapod (server on 127.0.0.1).

    Args:
        geometry: The robot to draw.
        open_browser: Open the page in a browser (never waited for).
        zmq_url: Connect to a running ``meshcat-server`` instead of starting one.
    """

    def __init__(self, geometry: HexapodGeometry, open_browser: bool = False,
                 zmq_url: str | None = None) -> None:
        import meshcat
        from pinocchio.visualize import MeshcatVisualizer

        self.geometry = geometry
        self.hm: HexapodModel = build_model(geometry)
        self.viewer = meshcat.Visualizer(zmq_url=zmq_url)
        self.viz = MeshcatVisualizer(self.hm.model, self.hm.visual_model, self.hm.visual_model)
        self.viz.initViewer(viewer=self.viewer, loadModel=True)
        self.root = self.viz.viewerVisualGroupName
        self._last = -np.inf
        self._hidden = np.zeros(6, dtype=bool)
        self._set_view()
        if open_browser:
            self.viewer.open()

    def _set_view(self) -> None:
        import meshcat.transformations as tf

        v = self.viewer
        h = float(self.geometry.home_height)
        v["/Cameras/default"].set_transform(tf.translation_matrix([0.0, 0.0, 0.5 * h]))
        v["/Cameras/default/rotated/<object>"].set_property("position",
                                                            [2.2 * h, 2.0 * h, 1.6 * h])
        v["/Grid"].set_property("visible", False)
        v["/Axes"].set_property("visible", False)
        v["/Background"].set_property("visible", False)  # plain white: colours stay readable

    def url(self) -> str:
        """The page of the viewer (loopback)."""
        return str(self.viewer.url())

    def show_camera(self, camera_from_base: np.ndarray, K: np.ndarray, width: int,
                    height: int, kind: str = "perspective") -> None:
        """Draw the camera as a frustum (perspective) or a wide cone (unified) at its pose.

        Args:
            camera_from_base: (4, 4) ``p_camera = R p_base + t``.
            K: (3, 3) intrinsics [px]. width, height: image size [px].
            kind: ``"perspective"`` or ``"unified"``.
        """
        import meshcat.geometry as mg

        segs = _frustum_segments(camera_from_base, np.asarray(K, float),
                                 np.array([width, height]), kind)
        self.viewer["camera"].set_object(mg.LineSegments(
            mg.PointsGeometry(segs), mg.LineBasicMaterial(color=CAMERA_COLOR, linewidth=2)))

    def show_goal(self, rotation: np.ndarray, translation: np.ndarray) -> None:
        """Draw the goal pose as a ghost platform: its outline and joint hexagon (lines, so
        that it never hides the robot)."""
        import meshcat.geometry as mg

        radius = 1.08 * float(np.max(np.linalg.norm(self.geometry.platform_points[:, :2],
                                                    axis=1)))
        a = np.linspace(0.0, 2 * np.pi, 73)
        circle = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros_like(a)], axis=1)
        joints = self.geometry.platform_points[[0, 3, 2, 5, 4, 1, 0]]
        segs = []
        for loop in (circle, joints):
            for k in range(len(loop) - 1):
                segs += [loop[k], loop[k + 1]]
        pts = (np.asarray(rotation) @ np.array(segs).T) + np.asarray(translation)[:, None]
        self.viewer["goal"].set_object(mg.LineSegments(
            mg.PointsGeometry(pts), mg.LineBasicMaterial(color=GOAL_COLOR, linewidth=2)))

    def _leg_colours(self, edge_visible: np.ndarray | None) -> None:
        hidden = np.zeros(6, dtype=bool) if edge_visible is None else ~np.all(
            np.asarray(edge_visible, bool), axis=-1)
        for i in np.flatnonzero(hidden != self._hidden):
            body = HIDDEN_LEG_COLOR if hidden[i] else LEG_BODY_COLOR
            rod = HIDDEN_LEG_COLOR if hidden[i] else LEG_ROD_COLOR
            for name, colour in ((f"leg{i}_body", body), (f"leg{i}_rod", rod)):
                self.viewer[f"{self.root}/{name}"].set_property("color", colour.tolist())
        self._hidden = hidden

    def display(self, rotation: np.ndarray, translation: np.ndarray,
                edge_visible: np.ndarray | None = None, force: bool = False) -> bool:
        """Show the robot at a platform pose (skipped if the last update is < 1/30 s old).

        Args:
            rotation: (3, 3) platform orientation in the base frame.
            translation: (3,) platform position [m].
            edge_visible: (6, 2) which edges the camera sees (hidden legs turn red).
            force: Update even within the rate limit.

        Returns:
            Whether the view was updated.
        """
        now = time.monotonic()
        if not force and now - self._last < LIVE_PERIOD:
            return False
        self._last = now
        self.viz.display(self.hm.configuration(rotation, translation))
        self._leg_colours(edge_visible)
        return True

    def static_html(self) -> str:
        """The current scene as a self-contained HTML page."""
        return str(self.viewer.static_html())

    def animate(self, record: TrialRecord, fps: float = 25.0) -> None:
        """Load the trial's motion as a MeshCat animation (played in the page)."""
        import meshcat.animation as ma
        import pinocchio as pin

        model, vmodel = self.hm.model, self.hm.visual_model
        data, vdata = model.createData(), vmodel.createData()
        anim = ma.Animation(default_framerate=fps)
        t = record["t"]
        dt = float(t[1] - t[0]) if len(t) > 1 else 1.0 / fps
        step = max(1, round(1.0 / (dt * fps)))
        frames = list(range(0, record.frames, step))
        if frames[-1] != record.frames - 1:
            frames.append(record.frames - 1)
        for f_idx, k in enumerate(frames):
            q = self.hm.configuration(record["rotations"][k], record["translations"][k])
            pin.forwardKinematics(model, data, q)
            pin.updateGeometryPlacements(model, data, vmodel, vdata)
            hidden = ~np.all(record["edge_visible"][k], axis=-1)
            with anim.at_frame(self.viewer, f_idx) as frame:
                for g_id, obj in enumerate(vmodel.geometryObjects):
                    frame[f"{self.root}/{obj.name}"].set_transform(
                        vdata.oMg[g_id].homogeneous)
                for i in range(6):
                    colour = HIDDEN_LEG_COLOR if hidden[i] else LEG_BODY_COLOR
                    frame[f"{self.root}/leg{i}_body"].set_property("color", "vector",
                                                                   colour.tolist())
        self.viewer.set_animation(anim, play=True, repetitions=0)

    def close(self) -> None:
        """Stop the MeshCat server this viewer started (if any)."""
        server = getattr(self.viewer.window, "server_proc", None)
        if server is not None and server.poll() is None:
            server.terminate()
            try:
                server.wait(timeout=5)
            except Exception:  # still running: kill it
                server.kill()

    def __enter__(self) -> HexapodViewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _scene_for(record: TrialRecord) -> HexapodViewer:
    viewer = HexapodViewer(record.geometry)
    a = record.arrays
    viewer.show_camera(a["camera_from_base"], a["camera_K"], int(a["camera_size"][0]),
                       int(a["camera_size"][1]), str(a["camera_kind"]))
    viewer.show_goal(a["goal_rotation"], a["goal_translation"])
    return viewer


def replay_html(record: TrialRecord, html_path: str | Path, fps: float = 25.0,
                frame: int | None = None) -> Path:
    """Write a self-contained HTML page of a trial (no network needed to open it).

    Args:
        record: The trial.
        html_path: Output file.
        fps: Frames per second of the animation.
        frame: If given, a still of that control period instead of the animation
            (negative values count from the end).

    Returns:
        The path written.
    """
    with _scene_for(record) as viewer:
        if frame is None:
            viewer.display(record["rotations"][0], record["translations"][0],
                           record["edge_visible"][0], force=True)
            viewer.animate(record, fps)
        else:
            k = frame % record.frames
            viewer.display(record["rotations"][k], record["translations"][k],
                           record["edge_visible"][k], force=True)
        html = viewer.static_html()
    path = Path(html_path)
    path.write_text(html)
    return path


def plot_trial(record: TrialRecord, png_path: str | Path) -> Path:
    """Feature error norm, pose error and leg lengths against their strokes (matplotlib)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = record.arrays
    t = a["t"]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    err = np.asarray(a["error_norm"], float)
    ok = np.isfinite(err) & (err > 0)
    axes[0].semilogy(t[ok], err[ok])
    axes[0].set_title("feature error norm")
    axes[1].semilogy(t, np.maximum(a["position_error"] * 1e3, 1e-6), label="position [mm]")
    axes[1].semilogy(t, np.maximum(np.rad2deg(a["orientation_error"]), 1e-7),
                     label="orientation [deg]")
    axes[1].set_title("pose error (true pose vs true goal)")
    axes[1].legend(fontsize=8)
    for i in range(6):
        axes[2].plot(t, a["lengths"][:, i] * 1e3, label=f"leg {i}")
    for q in a["stroke"]:
        axes[2].axhline(q * 1e3, color="k", linestyle="--", linewidth=0.8)
    axes[2].set_title("leg lengths [mm] and strokes")
    axes[2].legend(fontsize=7, ncol=2)
    for ax in axes:
        ax.set_xlabel("time [s]")
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(record.title)
    fig.tight_layout()
    path = Path(png_path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def replay_trial(npz_path: str | Path, html_path: str | Path) -> tuple[Path, Path]:
    """Replay a recorded trial: the HTML animation and, beside it, the matplotlib curves."""
    record = load_trial(npz_path)
    html = replay_html(record, html_path)
    png = plot_trial(record, Path(html_path).with_suffix(".png"))
    return html, png
