"""MeshCat scene of the hexapod: live view, replay of a recorded trial, static HTML export.

The scene is the closed-chain Pinocchio model (:mod:`hexapod.model`) drawn by
:class:`pinocchio.visualize.MeshcatVisualizer`: base, platform and the six legs
as cylinders of the true radius, plus the camera as a frustum (a mirror and a
wide cone for an omnidirectional camera) at its pose, the goal pose as a
translucent ghost platform, optionally the interpretation planes of the leg
edges, and leg colours that mark the legs whose edges the camera does not see
(occluded or outside the image).

Nothing here waits for a browser, and nothing waits for the MeshCat server
without a timeout:

- the server is started in a child process whose web server listens on
  127.0.0.1 only (``meshcat-server`` itself listens on every interface), and
  every ZeroMQ request to it times out (:data:`ZMQ_TIMEOUT`);
- :meth:`HexapodViewer.display` only hands the newest pose to a sender thread,
  which draws at most :data:`LIVE_PERIOD`-spaced updates: a control loop pays
  microseconds per call, watched or not;
- the HTML export asks the server for the scene (``static_html``), never for a
  screenshot.

A trial record is the ``.npz`` file the benchmark writes for a recorded trial
(see :data:`RECORD_SHAPES` and :func:`load_trial`). ``hexapod`` knows nothing of
cameras or controllers: records and camera drawings take plain arrays.
"""

from __future__ import annotations

import atexit
import contextlib
import io
import logging
import os
import queue
import re
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hexapod.exceptions import RecordError, ViewerError
from hexapod.geometry import HexapodGeometry
from hexapod.model import (
    LEG_BODY_COLOR,
    LEG_ROD_COLOR,
    HexapodModel,
    build_model,
)

__all__ = [
    "RECORD_KEYS", "RECORD_SHAPES", "HexapodViewer", "RecordError", "TrialRecord",
    "ViewerError", "load_trial", "plot_trial", "replay_html", "replay_trial", "save_trial",
    "synthetic_record",
]

log = logging.getLogger(__name__)

#: Colour of a leg whose edges the camera does not see (RGBA).
HIDDEN_LEG_COLOR = np.array([0.85, 0.10, 0.10, 1.0])
#: Colour of the goal ghost platform and its outline (hex RGB).
GOAL_COLOR = 0x22AA55
#: Opacity of the goal ghost platform.
GOAL_OPACITY = 0.12
#: Colour of the camera drawing (hex RGB).
CAMERA_COLOR = 0x22AA22
#: Colour of the interpretation planes of the edges (hex RGB).
PLANE_COLOR = 0xAA44CC
#: Minimum time between two live updates [s] (30 Hz).
LIVE_PERIOD = 1.0 / 30.0
#: Longest wait for any answer of the MeshCat server [s].
ZMQ_TIMEOUT = 5.0
#: Longest wait for a started MeshCat server to announce its addresses [s].
SERVER_START_TIMEOUT = 30.0

#: Shape of every array of a trial record; ``"T"`` is the number of control periods.
RECORD_SHAPES: dict[str, tuple[int | str, ...]] = {
    "t": ("T",), "lengths": ("T", 6), "rotations": ("T", 3, 3), "translations": ("T", 3),
    "edge_visible": ("T", 6, 2), "error_norm": ("T",), "position_error": ("T",),
    "orientation_error": ("T",), "velocities": ("T", 6),
    "goal_rotation": (3, 3), "goal_translation": (3,),
    "camera_from_base": (4, 4), "camera_kind": (), "camera_K": (3, 3), "camera_size": (2,),
    "camera_xi": (), "base_points": (6, 3), "platform_points": (6, 3), "stroke": (2,),
    "leg_radius": (), "scenario": (), "controller": (), "trial": (),
}
#: Keys of a trial record, with their number of dimensions.
RECORD_KEYS: dict[str, int] = {k: len(s) for k, s in RECORD_SHAPES.items()}
#: Camera kinds a record may name.
CAMERA_KINDS = ("perspective", "unified")

# The MeshCat server, with its web server bound to the loopback interface: meshcat's
# ZMQWebSocketBridge calls ``app.listen(port)``, which tornado binds to every interface.
_SERVER_CODE = """
import tornado.web
_listen = tornado.web.Application.listen
def _loopback_listen(self, port, address=None, **kwargs):
    return _listen(self, port, "127.0.0.1", **kwargs)
tornado.web.Application.listen = _loopback_listen
from meshcat.servers.zmqserver import main
main()
"""

# Put in the exported page right after the viewer is created. MeshCat's page applies its
# commands asynchronously (one fetch of a data: URL each) and lists the animation first,
# before the objects it animates exist; this holds the animation until every command is
# applied, then loads it, and ``page.html#t=1.5`` shows it paused at 1.5 s.
_PAGE_SCRIPT = """
(function () {
  var expected = %d, seen = 0, held = null;
  var m = /(?:^#|&)t=([0-9.eE+-]+)/.exec(window.location.hash);
  var seekTo = m === null ? null : parseFloat(m[1]);
  var load = viewer.set_animation.bind(viewer);
  var handle = viewer.handle_command_bytearray.bind(viewer);
  function finish() {
    if (held !== null) { load(held[0], held[1]); held = null; }
    if (seekTo !== null && viewer.animator) {
      viewer.animator.pause();
      viewer.animator.seek(seekTo);
      viewer.animator.display_progress(seekTo);
    }
    window.hexapodReplayReady = true;
  }
  viewer.set_animation = function (animations, options) {
    if (seen < expected) { held = [animations, options]; } else { load(animations, options); }
  };
  viewer.handle_command_bytearray = function (bytes) {
    handle(bytes);
    seen += 1;
    if (seen === expected) { finish(); }
  };
})();
"""
_VIEWER_CREATED = re.compile(r"var viewer = new MeshCat\.Viewer\([^;]*\);")


# --------------------------------------------------------------------------- records


@dataclass
class TrialRecord:
    """Time series of one closed-loop trial (as saved by the benchmark), validated.

    Attributes:
        arrays: Every array of the record, by key (see :data:`RECORD_SHAPES`): times
            ``t`` [s], ``lengths`` [m], the true platform pose ``rotations``,
            ``translations`` [m] in the base frame, ``edge_visible``, the errors
            ``error_norm``, ``position_error`` [m], ``orientation_error`` [rad],
            ``velocities`` [m/s], the goal, the camera, the geometry and the labels.
        path: The file it was read from.

    Raises:
        RecordError: A key is missing or has the wrong shape or value.
    """

    arrays: dict[str, np.ndarray]
    path: str = "<memory>"

    def __post_init__(self) -> None:
        self.arrays = _validated(self.arrays, self.path)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.arrays[key]

    @property
    def frames(self) -> int:
        """Number of recorded control periods."""
        return len(self.arrays["t"])

    @property
    def camera_kind(self) -> str:
        """``"perspective"`` or ``"unified"``."""
        return str(self.arrays["camera_kind"])

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


def _validated(arrays: dict[str, Any], path: str) -> dict[str, np.ndarray]:
    """The arrays as numpy arrays, after checking every key's presence and shape."""
    out = {k: np.asarray(v) for k, v in arrays.items()}
    for key in RECORD_SHAPES:
        if key not in out:
            raise RecordError(path, "missing", key)
    if out["t"].ndim != 1 or len(out["t"]) == 0:
        raise RecordError(path, f"expected a non-empty (T,) array, got shape "
                          f"{out['t'].shape}", "t")
    n = len(out["t"])
    for key, shape in RECORD_SHAPES.items():
        want = tuple(n if s == "T" else s for s in shape)
        if out[key].shape != want:
            raise RecordError(path, f"expected shape {want} (T = {n} frames), got "
                              f"{out[key].shape}", key)
    if str(out["camera_kind"]) not in CAMERA_KINDS:
        raise RecordError(path, f"'{out['camera_kind']}' is not one of {CAMERA_KINDS}",
                          "camera_kind")
    out["edge_visible"] = out["edge_visible"].astype(bool)
    return out


def save_trial(path: str | Path, **arrays: Any) -> Path:
    """Save a trial record (compressed ``.npz``), checking its keys and shapes first.

    The file is written beside its final name and renamed, so that an interrupted
    run never leaves a truncated record.

    Args:
        path: Output file.
        **arrays: The arrays of :data:`RECORD_SHAPES` (extra keys are kept).

    Returns:
        The path written.

    Raises:
        RecordError: A key is missing or malformed (nothing is written).
    """
    missing = [k for k in RECORD_SHAPES if k not in arrays]
    if missing:
        raise RecordError(str(path), f"missing keys {missing}")
    data = _validated(arrays, str(path))
    p = Path(path)
    tmp = p.with_name(p.name + f".{os.getpid()}.tmp.npz")
    np.savez_compressed(tmp, **data)  # type: ignore[arg-type]
    os.replace(tmp, p)
    return p


def load_trial(path: str | Path) -> TrialRecord:
    """Read and validate a trial record.

    Args:
        path: A ``.npz`` file written by :func:`save_trial`.

    Returns:
        The record.

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
    return TrialRecord(arrays, str(p))


def synthetic_record(geometry: HexapodGeometry, frames: int = 101, duration: float = 2.0,
                     seed: int = 3, hidden: tuple[int, float, float] | None = (3, 0.4, 0.6),
                     camera_kind: str = "perspective") -> TrialRecord:
    """A made-up trial for tests and demos: the platform glides between two sampled poses.

    The start and goal poses come from :func:`hexapod.workspace.sample_poses`; the
    motion is a geodesic (constant rotation rate, straight translation), the leg
    lengths its inverse kinematics.

    Args:
        geometry: The robot.
        frames: Number of control periods.
        duration: Length of the trial [s].
        seed: Seed of the two poses.
        hidden: ``(leg, start, end)``: that leg's second edge is hidden between these
            fractions of the trial; None: every edge always visible.
        camera_kind: ``"perspective"`` or ``"unified"`` (the camera drawn).

    Returns:
        The record (``save_trial(path, **record.arrays)`` writes it).
    """
    from hexapod.kinematics import inverse_kinematics
    from hexapod.se3 import exp_so3, log_so3, look_at
    from hexapod.workspace import sample_poses

    R, t = sample_poses(geometry, 2, rng=seed, max_translation=0.06, max_angle=0.2)
    s = np.linspace(0.0, 1.0, frames)
    w = log_so3(R[1] @ R[0].T)
    rot = np.array([exp_so3(w * x) @ R[0] for x in s])
    trans = t[0] + s[:, None] * (t[1] - t[0])
    vis = np.ones((frames, 6, 2), dtype=bool)
    if hidden is not None:
        vis[(s >= hidden[1]) & (s <= hidden[2]), hidden[0], 1] = False
    lengths = inverse_kinematics(geometry, rot, trans)
    # a camera in front of the robot, looking at its centre (x right, y down, z forward)
    centre = np.array([0.0, 0.0, 0.5 * float(t[0][2])])
    eye = centre + np.array([0.9, 0.0, 0.35])
    base_from_camera = look_at(eye, centre, np.array([0.0, 0.0, 1.0]))
    camera_from_base = np.eye(4)
    camera_from_base[:3, :3] = base_from_camera.T
    camera_from_base[:3, 3] = -base_from_camera.T @ eye
    dt = duration / max(frames - 1, 1)
    arrays = {
        "t": s * duration, "lengths": lengths, "rotations": rot, "translations": trans,
        "edge_visible": vis, "error_norm": np.exp(-3.0 * s),
        "position_error": np.linalg.norm(trans - t[1], axis=1),
        "orientation_error": np.linalg.norm(log_so3(np.swapaxes(rot, 1, 2) @ R[1]),
                                            axis=-1),
        "velocities": np.gradient(lengths, dt, axis=0),
        "goal_rotation": R[1], "goal_translation": t[1],
        "camera_from_base": camera_from_base, "camera_kind": np.array(camera_kind),
        "camera_K": np.array([[600.0, 0, 320], [0, 600, 240], [0, 0, 1]]),
        "camera_size": np.array([640, 480]),
        "camera_xi": np.array(0.9 if camera_kind == "unified" else 0.0),
        "base_points": geometry.base_points, "platform_points": geometry.platform_points,
        "stroke": np.array(geometry.stroke), "leg_radius": np.array(geometry.leg_radius),
        "scenario": np.array("synthetic"), "controller": np.array("none"),
        "trial": np.array(0),
    }
    return TrialRecord(arrays)


# --------------------------------------------------------------------------- drawings


def _camera_centre(camera_from_base: np.ndarray) -> np.ndarray:
    T = np.asarray(camera_from_base, dtype=float)
    return np.asarray(-T[:3, :3].T @ T[:3, 3])


def _frustum_segments(camera_from_base: np.ndarray, K: np.ndarray, size: np.ndarray,
                      kind: str, depth: float = 0.12) -> np.ndarray:
    """End points (3, 2N) in the base frame of the camera drawing's line segments.

    A perspective camera is a pyramid through the image corners (depth along the
    optical axis [m]); a unified (catadioptric) camera is a cone of rays 75 deg off
    its axis, wider than a hemisphere would be drawn by a pyramid.
    """
    T = np.asarray(camera_from_base, dtype=float)
    R = T[:3, :3]
    centre = _camera_centre(T)
    w, h = float(size[0]), float(size[1])
    if kind == "perspective":
        Kinv = np.linalg.inv(K)
        corners = [Kinv @ np.array([u, v, 1.0]) for u, v in ((0, 0), (w, 0), (w, h), (0, h))]
        rim = [c / c[2] * depth for c in corners]
        # a small triangle above the top edge marks the image's "up" (-y)
        up = [rim[0] + 0.3 * (rim[1] - rim[0]), rim[0] + 0.7 * (rim[1] - rim[0]),
              0.5 * (rim[0] + rim[1]) + np.array([0.0, -0.25 * depth, 0.0])]
        loops = [rim, up]
    else:
        a = np.linspace(0.0, 2 * np.pi, 13)[:-1]
        half = np.deg2rad(75.0)
        rim = [depth * np.array([np.sin(half) * np.cos(x), np.sin(half) * np.sin(x),
                                 np.cos(half)]) for x in a]
        loops = [rim]
    segs: list[np.ndarray] = []
    for c in rim:
        segs += [np.zeros(3), c]
    for loop in loops:
        for k in range(len(loop)):
            segs += [loop[k], loop[(k + 1) % len(loop)]]
    pts = np.array(segs) @ R + centre  # camera frame -> base frame: R^T p + centre
    return np.asarray(pts.T)


def _edge_planes(geometry: HexapodGeometry, rotation: np.ndarray, translation: np.ndarray,
                 centre: np.ndarray) -> np.ndarray:
    """Triangles (6, 2, 3, 3) [m]: camera centre and the two ends of each leg edge.

    A leg edge is a generator of the leg cylinder tangent to the ray from the camera
    centre; its interpretation plane contains the centre and the edge.
    """
    A = geometry.base_points
    B = np.asarray(translation) + geometry.platform_points @ np.asarray(rotation).T
    tris = np.zeros((6, 2, 3, 3))
    r = float(geometry.leg_radius)
    for i in range(6):
        axis = B[i] - A[i]
        length = float(np.linalg.norm(axis))
        u = axis / length
        d = (centre - A[i]) - ((centre - A[i]) @ u) * u
        dist = float(np.linalg.norm(d))
        if dist <= r:  # the centre is inside the cylinder: no edge
            continue
        dn = d / dist
        side = np.cross(u, dn)
        cos_a = r / dist
        sin_a = np.sqrt(1.0 - cos_a**2)
        for j, sgn in enumerate((1.0, -1.0)):
            p = A[i] + r * (cos_a * dn + sgn * sin_a * side)
            tris[i, j] = [centre, p, p + length * u]
    return tris


def _start_server(timeout: float) -> tuple[subprocess.Popen[bytes], str, str]:
    """Start a MeshCat server listening on 127.0.0.1 only.

    Returns:
        The child process, its ZeroMQ address and its web address.

    Raises:
        ViewerError: It did not announce its addresses within ``timeout`` [s].
    """
    env = dict(os.environ)
    import meshcat

    env["PYTHONPATH"] = os.pathsep.join(
        [str(Path(meshcat.__file__).parents[1]), env.get("PYTHONPATH", "")])
    proc = subprocess.Popen([sys.executable, "-u", "-c", _SERVER_CODE],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env,
                            start_new_session=True)
    atexit.register(_stop_process, proc)
    lines: queue.Queue[str] = queue.Queue()

    def drain() -> None:  # keeps reading so that the server never blocks on a full pipe
        assert proc.stdout is not None
        for raw in proc.stdout:
            line = raw.decode("utf-8", "replace").strip()
            log.debug("meshcat-server: %s", line)
            lines.put(line)

    threading.Thread(target=drain, name="meshcat-server-output", daemon=True).start()
    urls: dict[str, str] = {}
    deadline = time.monotonic() + timeout
    while len(urls) < 2:
        remaining = deadline - time.monotonic()
        if remaining <= 0 or proc.poll() is not None:
            _stop_process(proc)
            raise ViewerError("exited" if proc.poll() not in (None, -9, -15) else
                              "did not announce its addresses", timeout=timeout)
        with contextlib.suppress(queue.Empty):
            line = lines.get(timeout=min(remaining, 0.2))
            for key in ("zmq_url", "web_url"):
                if line.startswith(key + "="):
                    urls[key] = line.split("=", 1)[1]
    return proc, urls["zmq_url"], urls["web_url"]


def _stop_process(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


def _probe(zmq_url: str, timeout: float) -> None:
    """Check that a MeshCat server answers at ``zmq_url`` within ``timeout`` [s]."""
    import zmq

    sock: Any = zmq.Context.instance().socket(zmq.REQ)
    sock.setsockopt(zmq.LINGER, 0)
    try:
        sock.connect(zmq_url)
        sock.send(b"url")
        if not sock.poll(int(timeout * 1000)):
            raise ViewerError("no answer", url=zmq_url, timeout=timeout)
        sock.recv()
    finally:
        sock.close()


class HexapodViewer:
    """A MeshCat view of a hexapod.

    Args:
        geometry: The robot to draw.
        open_browser: Open the page in a browser (never waited for).
        zmq_url: Connect to a running ``meshcat-server`` instead of starting one (a
            server started here listens on 127.0.0.1 only).

    Raises:
        ViewerError: The server could not be started or did not answer in time.
    """

    def __init__(self, geometry: HexapodGeometry, open_browser: bool = False,
                 zmq_url: str | None = None) -> None:
        import meshcat
        import zmq
        from pinocchio.visualize import MeshcatVisualizer

        self.geometry = geometry
        self.hm: HexapodModel = build_model(geometry)
        self._server: subprocess.Popen[bytes] | None = None
        self._lock = threading.Lock()          # one ZeroMQ request at a time
        if zmq_url is None:
            self._server, zmq_url, _ = _start_server(SERVER_START_TIMEOUT)
        try:
            _probe(zmq_url, ZMQ_TIMEOUT)
            with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints the URL
                self.viewer = meshcat.Visualizer(zmq_url=zmq_url)
            sock = self.viewer.window.zmq_socket
            sock.setsockopt(zmq.RCVTIMEO, int(ZMQ_TIMEOUT * 1000))
            sock.setsockopt(zmq.SNDTIMEO, int(ZMQ_TIMEOUT * 1000))
            sock.setsockopt(zmq.LINGER, 0)
            self.viz = MeshcatVisualizer(self.hm.model, self.hm.visual_model,
                                         self.hm.visual_model)
            self.viz.initViewer(viewer=self.viewer, loadModel=True)
        except BaseException:
            if self._server is not None:
                _stop_process(self._server)
            raise
        self.root = self.viz.viewerVisualGroupName
        self._pending: tuple[np.ndarray, np.ndarray, np.ndarray | None] | None = None
        self._wake = threading.Condition()
        self._closed = False
        self._failed = False
        self._hidden = np.zeros(6, dtype=bool)
        self._camera_centre: np.ndarray | None = None
        self.updates = 0                       # poses drawn (live and forced)
        self._set_view()
        self._sender = threading.Thread(target=self._send_loop, name="hexapod-viewer",
                                        daemon=True)
        self._sender.start()
        log.info("MeshCat viewer at %s", self.url())
        if open_browser:
            self.viewer.open()

    # ----------------------------------------------------------------- scene

    def _set_view(self, include: np.ndarray | None = None) -> None:
        """Look at the robot from the front-right, from far enough to see ``include``
        (points (N, 3) [m], such as the camera centre) too."""
        import meshcat.transformations as tf

        v = self.viewer
        h = float(self.hm.home_translation[2])
        target = np.array([0.0, 0.0, 0.45 * h])
        offset = np.array([1.7, 1.5, 1.5]) * h
        if include is not None:  # look across the robot-to-points line, back off to fit
            pts = np.atleast_2d(include)
            toward = pts.mean(axis=0)
            toward[2] = 0.0
            if np.linalg.norm(toward) > 1e-6:
                toward /= np.linalg.norm(toward)
                across = np.array([-toward[1], toward[0], 0.0])
                direction = 0.8 * across - 0.3 * toward + np.array([0.0, 0.0, 0.55])
                offset = float(np.linalg.norm(offset)) * direction / np.linalg.norm(direction)
            reach = float(np.max(np.linalg.norm(pts, axis=1)))  # the view orbits the origin
            offset *= max(1.0, 1.2 * reach / float(np.linalg.norm(offset)))
        with self._lock:
            v["/Cameras/default"].set_transform(tf.translation_matrix(target))
            # MeshCat's camera is y-up: (x, y, z) of the scene is (x, z, -y) there
            v["/Cameras/default/rotated/<object>"].set_property(
                "position", [float(offset[0]), float(offset[2]), float(-offset[1])])
            v["/Grid"].set_property("visible", False)
            v["/Axes"].set_property("visible", False)
            v["/Background"].set_property("visible", False)  # plain white: colours readable

    def url(self) -> str:
        """The page of the viewer (http://127.0.0.1:PORT/static/ for a server started here)."""
        return str(self.viewer.url())

    def show_camera(self, camera_from_base: np.ndarray, K: np.ndarray, width: int,
                    height: int, kind: str = "perspective") -> None:
        """Draw the camera at its pose: a frustum (perspective) or a mirror and a wide cone
        (unified).

        Args:
            camera_from_base: (4, 4) ``p_camera = R p_base + t`` [m].
            K: (3, 3) intrinsics [px].
            width: Image width [px].
            height: Image height [px].
            kind: ``"perspective"`` or ``"unified"``.
        """
        import meshcat.geometry as mg
        import meshcat.transformations as tf

        if kind not in CAMERA_KINDS:
            raise ValueError(f"camera kind '{kind}' is not one of {CAMERA_KINDS}")
        segs = _frustum_segments(camera_from_base, np.asarray(K, float),
                                 np.array([width, height]), kind)
        self._camera_centre = _camera_centre(camera_from_base)
        self._set_view(include=self._camera_centre)
        with self._lock:
            self.viewer["camera/frustum"].set_object(mg.LineSegments(
                mg.PointsGeometry(segs),
                mg.LineBasicMaterial(color=CAMERA_COLOR, linewidth=2)))
            if kind == "unified":
                self.viewer["camera/mirror"].set_object(
                    mg.Sphere(0.015), mg.MeshLambertMaterial(color=0x99AAAA))
                self.viewer["camera/mirror"].set_transform(
                    tf.translation_matrix(self._camera_centre))
            else:
                self.viewer["camera/mirror"].delete()

    def show_goal(self, rotation: np.ndarray, translation: np.ndarray) -> None:
        """Draw the goal pose as a ghost: a translucent platform, its outline and the
        legs it needs (lines).

        Args:
            rotation: (3, 3) goal platform orientation in the base frame.
            translation: (3,) goal platform position [m].
        """
        import meshcat.geometry as mg

        g = self.geometry
        R, p = np.asarray(rotation, float), np.asarray(translation, float)
        # wider and thinner than the platform (1.08 R, 10 mm): at the goal, the robot's
        # platform stays on top and the ghost shows as a rim around it
        radius = 1.2 * float(np.max(np.linalg.norm(g.platform_points[:, :2], axis=1)))
        thickness = 0.006
        a = np.linspace(0.0, 2 * np.pi, 73)
        circle = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros_like(a)], axis=1)
        segs: list[np.ndarray] = []
        for z in (0.001, 0.007):
            ring = circle + np.array([0.0, 0.0, z])
            for k in range(len(ring) - 1):
                segs += [ring[k], ring[k + 1]]
        local = np.array(segs) @ R.T + p
        tips = g.platform_points @ R.T + p
        legs = np.stack([g.base_points, tips], axis=1).reshape(-1, 3)
        pts = np.concatenate([local, legs]).T
        # meshcat's cylinder is along y; the platform disc is along its z
        disc = np.eye(4)
        disc[:3, :3] = R @ np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
        disc[:3, 3] = p + R @ np.array([0.0, 0.0, 0.004])
        with self._lock:
            self.viewer["goal/outline"].set_object(mg.LineSegments(
                mg.PointsGeometry(pts), mg.LineBasicMaterial(color=GOAL_COLOR, linewidth=2)))
            self.viewer["goal/platform"].set_object(
                mg.Cylinder(thickness, radius),
                mg.MeshLambertMaterial(color=GOAL_COLOR, opacity=GOAL_OPACITY,
                                       transparent=True, depthWrite=False))
            self.viewer["goal/platform"].set_transform(disc)

    def show_edge_planes(self, rotation: np.ndarray, translation: np.ndarray,
                         edge_visible: np.ndarray | None = None) -> None:
        """Draw the interpretation planes of the leg edges (after :meth:`show_camera`):
        a translucent triangle from the camera centre to each edge (visible edges only).

        Args:
            rotation: (3, 3) platform orientation in the base frame.
            translation: (3,) platform position [m].
            edge_visible: (6, 2) which edges to draw; default all.
        """
        import meshcat.geometry as mg

        if self._camera_centre is None:
            raise ValueError("show_camera first: the planes go through the camera centre")
        tris = _edge_planes(self.geometry, rotation, translation, self._camera_centre)
        vis = (np.ones((6, 2), bool) if edge_visible is None
               else np.asarray(edge_visible, bool))
        keep = tris[vis & np.any(tris != 0, axis=(-1, -2))]
        with self._lock:
            if len(keep) == 0:
                self.viewer["edge_planes"].delete()
                return
            vertices = keep.reshape(-1, 3)
            faces = np.arange(len(vertices)).reshape(-1, 3)
            self.viewer["edge_planes"].set_object(
                mg.TriangularMeshGeometry(vertices, faces),
                mg.MeshBasicMaterial(color=PLANE_COLOR, opacity=0.15, transparent=True,
                                     side=2, depthWrite=False))

    # ----------------------------------------------------------------- motion

    def _draw(self, rotation: np.ndarray, translation: np.ndarray,
              edge_visible: np.ndarray | None) -> None:
        """Send one pose (caller holds the lock)."""
        self.viz.display(self.hm.configuration(rotation, translation))
        hidden = np.zeros(6, dtype=bool) if edge_visible is None else ~np.all(
            np.asarray(edge_visible, bool), axis=-1)
        for i in np.flatnonzero(hidden != self._hidden):
            body = HIDDEN_LEG_COLOR if hidden[i] else LEG_BODY_COLOR
            rod = HIDDEN_LEG_COLOR if hidden[i] else LEG_ROD_COLOR
            for name, colour in ((f"leg{i}_body", body), (f"leg{i}_rod", rod)):
                self.viewer[f"{self.root}/{name}"].set_property("color", colour.tolist())
        self._hidden = hidden
        self.updates += 1

    def _send_loop(self) -> None:
        last = -np.inf
        while True:
            with self._wake:
                while self._pending is None and not self._closed:
                    self._wake.wait()
                if self._closed:
                    return
            wait = last + LIVE_PERIOD - time.monotonic()
            if wait > 0:  # at most one update per LIVE_PERIOD; newer poses replace it
                time.sleep(wait)
            with self._wake:
                pose, self._pending = self._pending, None
                if pose is None:
                    continue
            last = time.monotonic()
            try:
                with self._lock:
                    if not self._closed:
                        self._draw(*pose)
            except Exception as exc:  # server gone or stuck: stop drawing, never the loop
                self._failed = True
                log.warning("MeshCat viewer stopped updating: %s", exc)
                return
            with self._wake:
                self._wake.notify_all()

    def display(self, rotation: np.ndarray, translation: np.ndarray,
                edge_visible: np.ndarray | None = None, force: bool = False) -> bool:
        """Show the robot at a platform pose.

        Without ``force`` this returns at once: the pose replaces any pose not yet drawn
        and a background thread draws the newest one at most every :data:`LIVE_PERIOD`,
        so a control loop is not slowed whether or not a browser watches.

        Args:
            rotation: (3, 3) platform orientation in the base frame.
            translation: (3,) platform position [m].
            edge_visible: (6, 2) which edges the camera sees (legs with a hidden edge
                turn red).
            force: Draw now, in this thread (waits for the server, with a timeout).

        Returns:
            Whether the pose was drawn or queued (False once the viewer is closed or
            its server stopped answering).
        """
        if self._closed or self._failed:
            return False
        vis = None if edge_visible is None else np.array(edge_visible, dtype=bool)
        pose = (np.array(rotation, dtype=float), np.array(translation, dtype=float), vis)
        if force:
            with self._lock:
                self._draw(*pose)
            return True
        with self._wake:
            self._pending = pose
            self._wake.notify_all()
        return True

    def flush(self, timeout: float = 1.0) -> bool:
        """Wait until the newest pose given to :meth:`display` is drawn.

        Args:
            timeout: Longest wait [s].

        Returns:
            Whether it was drawn in time.
        """
        deadline = time.monotonic() + timeout
        with self._wake:
            while self._pending is not None and not self._failed:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._wake.wait(remaining)
        with self._lock:  # the pose taken by the sender is drawn once the lock is free
            pass
        return not self._failed

    # ----------------------------------------------------------------- export

    def static_html(self) -> str:
        """The current scene as a self-contained HTML page (JavaScript inlined)."""
        with self._lock:
            return str(self.viewer.static_html())

    def animate(self, record: TrialRecord, fps: float = 25.0) -> None:
        """Load the trial's motion as a MeshCat animation, played at the trial's pace.

        Every ``1/fps`` seconds of the trial gives one frame (the control period
        closest in time): the transforms of every geometry (placements from
        ``pinocchio.updateGeometryPlacements``) and, for the legs that have a hidden
        edge at some time, the colour of the leg body and rod.

        Args:
            record: The trial.
            fps: Frames per second of the animation.
        """
        import meshcat.animation as ma
        import pinocchio as pin

        model, vmodel = self.hm.model, self.hm.visual_model
        data, vdata = model.createData(), vmodel.createData()
        anim = ma.Animation(default_framerate=fps)
        t = np.asarray(record["t"], float)
        times = np.arange(0.0, t[-1] - t[0] + 0.5 / fps, 1.0 / fps)
        frames = np.clip(np.searchsorted(t - t[0], times - 0.5 / fps), 0, record.frames - 1)
        hidden = ~np.all(record["edge_visible"], axis=-1)  # (T, 6)
        ever_hidden = np.flatnonzero(hidden.any(axis=0))
        names = [self.viz.getViewerNodeName(obj, pin.GeometryType.VISUAL)
                 for obj in vmodel.geometryObjects]
        for f_idx, k in enumerate(frames):
            q = self.hm.configuration(record["rotations"][k], record["translations"][k])
            pin.forwardKinematics(model, data, q)
            pin.updateGeometryPlacements(model, data, vmodel, vdata)
            with anim.at_frame(self.viewer, f_idx) as frame:
                for g_id, name in enumerate(names):
                    frame[name].set_transform(vdata.oMg[g_id].homogeneous)
                for i in ever_hidden:
                    for part, normal in (("body", LEG_BODY_COLOR), ("rod", LEG_ROD_COLOR)):
                        colour = HIDDEN_LEG_COLOR if hidden[k, i] else normal
                        frame[f"{self.root}/leg{i}_{part}/<object>"].set_property(
                            "material.color", "color", colour[:3].tolist())
        with self._lock:
            self.viewer.set_animation(anim, play=True, repetitions=1)

    # ----------------------------------------------------------------- life

    def close(self) -> None:
        """Stop the sender thread and the MeshCat server this viewer started (if any)."""
        if self._closed:
            return
        with self._wake:
            self._closed = True
            self._wake.notify_all()
        self._sender.join(timeout=ZMQ_TIMEOUT + 1.0)
        with contextlib.suppress(Exception):
            self.viewer.window.zmq_socket.close(linger=0)
        if self._server is not None:
            _stop_process(self._server)

    @property
    def server_process(self) -> subprocess.Popen[bytes] | None:
        """The MeshCat server started by this viewer (None if it connected to one)."""
        return self._server

    def __enter__(self) -> HexapodViewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# --------------------------------------------------------------------------- replay


def _scene_for(record: TrialRecord) -> HexapodViewer:
    viewer = HexapodViewer(record.geometry)
    a = record.arrays
    viewer.show_camera(a["camera_from_base"], a["camera_K"], int(a["camera_size"][0]),
                       int(a["camera_size"][1]), record.camera_kind)
    viewer.show_goal(a["goal_rotation"], a["goal_translation"])
    return viewer


def replay_html(record: TrialRecord, html_path: str | Path, fps: float = 25.0,
                frame: int | None = None) -> Path:
    """Write a self-contained HTML page of a trial (no network needed to open it).

    The page plays the trial once at its own pace; ``page.html#t=1.5`` opens it
    paused at 1.5 s of the trial (the Animations panel replays and scrubs it).

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
        k = 0 if frame is None else frame % record.frames
        viewer.display(record["rotations"][k], record["translations"][k],
                       record["edge_visible"][k], force=True)
        if frame is None:
            viewer.animate(record, fps)
        html = viewer.static_html()
    html = _with_page_script(html)
    path = Path(html_path)
    path.write_text(html, encoding="utf-8")
    log.info("%s: wrote %s (%.1f MB)", record.title, path, len(html) / 1e6)
    return path


def _with_page_script(html: str) -> str:
    """The page with :data:`_PAGE_SCRIPT` run right after its viewer is created."""
    found = _VIEWER_CREATED.search(html)
    if found is None:
        raise ViewerError("unexpected static HTML from meshcat: no 'var viewer = new "
                          "MeshCat.Viewer(...)' to hook the animation to")
    script = _PAGE_SCRIPT % html.count("viewer.handle_command_bytearray(")
    return html[:found.end()] + script + html[found.end():]


def plot_trial(record: TrialRecord, png_path: str | Path) -> Path:
    """Plot the trial's curves: feature error norm (log), position and orientation error
    (log), leg lengths against their strokes.

    Args:
        record: The trial.
        png_path: Output image.

    Returns:
        The path written.
    """
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
    """Replay a recorded trial: the HTML animation and, beside it, the matplotlib curves.

    Args:
        npz_path: The trial record.
        html_path: Output page; the curves go to the same name with ``.png``.

    Returns:
        The HTML and PNG paths.
    """
    record = load_trial(npz_path)
    html = replay_html(record, html_path)
    png = plot_trial(record, Path(html_path).with_suffix(".png"))
    return html, png
