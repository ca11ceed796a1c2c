"""The live MeshCat view of a hexapod: robot, camera, goal ghost, edge planes, and a
sender thread that keeps a control loop from waiting for the server."""

from __future__ import annotations

import contextlib
import io
import logging
import subprocess
import threading
import time

import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.model import LEG_BODY_COLOR, LEG_ROD_COLOR, HexapodModel, build_model
from hexapod.visualize.drawings import camera_centre, edge_planes, frustum_segments
from hexapod.visualize.forces import force_colours
from hexapod.visualize.records import CAMERA_KINDS, TrialRecord
from hexapod.visualize.server import (
    SERVER_START_TIMEOUT,
    ZMQ_TIMEOUT,
    probe,
    start_server,
    stop_process,
)

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



def nearest_periods(t: np.ndarray, fps: float) -> np.ndarray:
    """The control period shown by each frame of an animation at ``fps`` of a trial whose
    periods start at times ``t`` (from 0) [s]: the period nearest in time to each frame
    (an earlier one on a tie), and the last period on a frame of its own at the end (the
    pose the results' final error is of)."""
    times = np.arange(0.0, t[-1] + 0.5 / fps, 1.0 / fps)
    if times[-1] < t[-1]:
        times = np.append(times, t[-1])
    after = np.clip(np.searchsorted(t, times), 1, len(t) - 1) if len(t) > 1 else \
        np.zeros(len(times), dtype=int)
    if len(t) == 1:
        return after
    before = after - 1
    return np.where(times - t[before] <= t[after] - times, before, after)

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
            self._server, zmq_url, _ = start_server(SERVER_START_TIMEOUT)
        try:
            probe(zmq_url, ZMQ_TIMEOUT)
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
                stop_process(self._server)
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
        segs = frustum_segments(camera_from_base, np.asarray(K, float),
                                 np.array([width, height]), kind)
        self._camera_centre = camera_centre(camera_from_base)
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
        tris = edge_planes(self.geometry, rotation, translation, self._camera_centre)
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
        edge at some time, the colour of the leg body and rod; a record of the dynamic
        world (``leg_forces``) colours every rod by its drive force instead
        (:func:`hexapod.visualize.forces.force_colours`), the body alone showing a
        hidden edge.

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
        frames = nearest_periods(t - t[0], fps)
        hidden = ~np.all(record["edge_visible"], axis=-1)  # (T, 6)
        ever_hidden = np.flatnonzero(hidden.any(axis=0))
        rods = None  # the dynamic world: rods coloured by their drive forces
        if "leg_forces" in record.arrays:
            rods = force_colours(record["leg_forces"], record["force_limit"])
        names = [self.viz.getViewerNodeName(obj, pin.GeometryType.VISUAL)
                 for obj in vmodel.geometryObjects]
        for f_idx, k in enumerate(frames):
            q = self.hm.configuration(record["rotations"][k], record["translations"][k])
            pin.forwardKinematics(model, data, q)
            pin.updateGeometryPlacements(model, data, vmodel, vdata)
            with anim.at_frame(self.viewer, f_idx) as frame:
                for g_id, name in enumerate(names):
                    frame[name].set_transform(vdata.oMg[g_id].homogeneous)
                if rods is not None:
                    for leg in range(6):
                        frame[f"{self.root}/leg{leg}_rod/<object>"].set_property(
                            "material.color", "color", rods[k, leg, :3].tolist())
                for i in ever_hidden:
                    for part, normal in (("body", LEG_BODY_COLOR), ("rod", LEG_ROD_COLOR)):
                        if rods is not None and part == "rod":
                            continue  # the body alone shows a hidden edge
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
            stop_process(self._server)

    @property
    def server_process(self) -> subprocess.Popen[bytes] | None:
        """The MeshCat server started by this viewer (None if it connected to one)."""
        return self._server

    def __enter__(self) -> HexapodViewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
