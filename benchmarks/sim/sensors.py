"""What the camera gives in a simulated trial: geometric features with the scenario's
noise (:class:`GeometricSensor`), or rendered images through the
detector, and the desired features taught at the goal (:func:`trial_goal`).

Every sensor returns an :class:`~controllers.base.ObservationBatch` holding the camera's
part of the observation (:func:`camera_batch`: features and visibility, lengths NaN); the
closed loop (:mod:`benchmarks.sim.loop`) adds the rows' trials, time and encoder readings.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from benchmarks.sim.goal import cartesian_goal, goal_setting, measured_goals
from benchmarks.sim.inputs import SimScenario
from benchmarks.sim.world import TrialSetup, World, trial_rng
from controllers.base import Goal, ObservationBatch
from vision.cameras import Camera
from vision.cameras.perspective import PerspectiveCamera, lines_and_normals
from vision.fast_observe import WorldParams, observe_batch
from vision.legs import LegObservation, directions_from_edges
from vision.noise import Generators, rotation_noise_batch


def camera_batch(normals: np.ndarray | None, lines: np.ndarray | None,
                 directions: np.ndarray | None, edge_visible: np.ndarray,
                 direction_visible: np.ndarray, image_t: np.ndarray | None = None
                 ) -> ObservationBatch:
    """The camera's part of the observations of ``n`` rows: normals (n, 6, 2, 3), image
    lines (idem), leg directions (n, 6, 3) (each None when not measured), their visibility
    (n, 6, 2), (n, 6) and capture times ``image_t`` (n,) [s] or None; ``trials``
    ``0..n-1``, ``t`` zeros and ``lengths`` NaN until the loop adds the rows, the time and
    the encoders."""
    n = len(edge_visible)
    return ObservationBatch(trials=np.arange(n), t=np.zeros(n),
                            lengths=np.full((n, 6), np.nan), normals=normals, lines=lines,
                            directions=directions, edge_visible=edge_visible,
                            direction_visible=direction_visible, image_t=image_t)


def edge_batch(normals: np.ndarray, lines: np.ndarray | None, visible: np.ndarray
               ) -> ObservationBatch:
    """The camera's batch (:func:`camera_batch`) of ``n`` rows' edges: normals (n, 6, 2, 3),
    image lines or None, visibility (n, 6, 2); a leg's direction where both its edges are
    seen, NaN elsewhere."""
    both = visible[..., 0] & visible[..., 1]  # visible.all(axis=-1), without a reduction
    with np.errstate(invalid="ignore", divide="ignore"):
        directions = directions_from_edges(normals)
    if not both.all():
        directions = np.where(both[..., None], directions, np.nan)
    return camera_batch(normals, lines, directions, visible, both)


def seen_edges(camera: Any, normals: np.ndarray, visible: np.ndarray) -> ObservationBatch:
    """The :func:`edge_batch` of edges (n, 6, 2, 3), (n, 6, 2) seen by ``camera``: with
    their image lines when it is of the perspective family (fisheye included), else (a
    unified camera, or None) without."""
    lines = None
    if getattr(camera, "family", "") == "perspective":
        with np.errstate(invalid="ignore", divide="ignore"):
            lines = camera.normal_to_line(normals)
    return edge_batch(normals, lines, visible)


class GeometricSensor:
    """Features from the true geometry plus the scenario's noise model, for rows each in
    its own world (one C call for the legs, edges and visibility of every row,
    :func:`vision.fast_observe.observe_batch`), with the noise of :func:`noisy_features`.

    Args:
        sc: The scenario (its noise).
        worlds: The true world of each row (one world: every row sees it).
        estimated_camera: The camera the controllers are told of (every row's).
        rngs: One generator per row for :meth:`observe` (the run's noise).
    """

    def __init__(self, sc: SimScenario, worlds: World | Sequence[World],
                 estimated_camera: Camera, rngs: Sequence[Any] = ()) -> None:
        self.sc = sc
        self.worlds = [worlds] if isinstance(worlds, World) else list(worlds)
        self.params = WorldParams.from_worlds([w.geometry for w in self.worlds],
                                              [w.camera for w in self.worlds])
        self.est: Any = estimated_camera  # a PerspectiveCamera when ``perspective``
        self.perspective = self.worlds[0].camera.family == "perspective"
        # rows of one camera object go through its methods together
        ids: dict[int, int] = {}
        self._camera_group = np.array([ids.setdefault(id(w.camera), len(ids))
                                       for w in self.worlds])
        self._group_camera = {g: self.worlds[k].camera for k, g in
                              reversed(list(enumerate(self._camera_group)))}
        #: Each world's true :attr:`~vision.cameras.perspective.PerspectiveCamera.
        #: normal_to_line_matrix` (every true camera perspective; else None): the image
        #: lines of every row in one call.
        true_cameras = [w.camera for w in self.worlds]
        self._line_maps = (np.stack([c.normal_to_line_matrix for c in true_cameras
                                     if isinstance(c, PerspectiveCamera)])
                           if all(isinstance(c, PerspectiveCamera) for c in true_cameras)
                           else None)
        #: The rows' generators with their bit generators' addresses, taken once (the
        #: rotation noise draws every row's numbers in one C call, every period).
        self.generators = Generators(list(rngs))
        #: The rows of every world, in order (:meth:`observe` of every row).
        self._every = np.arange(len(self.worlds))
        self.detect_times: list[float] = []
        #: Whether :meth:`observe` measures the features (the loop's controller reads
        #: them, :func:`reads_features`); else only the visibility, where the noise does
        #: not change it (nothing drawn: no row depends on features nobody reads).
        self.features = True
        noise = sc.noise
        self._visibility_only = noise.model != "pixel" and not noise.dropout_probability > 0

    @classmethod
    def of_trials(cls, sc: SimScenario, setups: list[TrialSetup]) -> GeometricSensor:
        """The sensor of trials in their worlds, with their run's generators."""
        return cls(sc, [s.world for s in setups], setups[0].estimated_camera,
                   rows_generators(sc, setups, 1, True))

    def observe(self, rows: np.ndarray, rotations: np.ndarray, translations: np.ndarray
                ) -> ObservationBatch:
        """The loop's interface: the camera's batch of ``rows`` (sorted distinct rows, as
        the loop's) at their true poses."""
        gens = self.generators
        every = len(rows) == len(gens)  # every row, in order: what is kept for them
        if not self.features and self._visibility_only:
            seen = observe_batch(self.params, rotations, translations,
                                 None if every else rows).edge_visible
            return camera_batch(None, None, None, seen, seen[..., 0] & seen[..., 1])
        if every:
            return self.sample(rotations, translations, self._every, gens)
        return self.sample(rotations, translations, rows, gens.take(rows))

    def measure(self, rotations: np.ndarray, translations: np.ndarray,
                rngs: Sequence[Any], apply_noise: bool = True) -> ObservationBatch:
        """Measurements of the first world at true poses (N, 3, 3), (N, 3); one generator
        per item."""
        return self.sample(rotations, translations, np.zeros(len(rotations), dtype=int),
                           rngs, apply_noise)

    def sample(self, rotations: np.ndarray, translations: np.ndarray, items: np.ndarray,
               rngs: Sequence[Any], apply_noise: bool = True) -> ObservationBatch:
        """Features of the worlds ``items`` at poses (n, 3, 3), (n, 3), one generator
        each (anything when :func:`draws_noise` is False)."""
        obs = observe_batch(self.params, rotations, translations,
                            None if items is self._every else items)
        line_maps = self._line_maps
        if line_maps is not None and items is not self._every:
            line_maps = line_maps[items]
        cameras: list[tuple[np.ndarray, Any]] = []
        if line_maps is None:
            groups = self._camera_group[items]
            # the groups present, sorted (np.unique would import numpy.ma: ~30 ms a process)
            cameras = [(np.flatnonzero(groups == g), self._group_camera[int(g)])
                       for g in np.flatnonzero(np.bincount(groups))]

        def item(k: int) -> tuple[LegObservation, Any]:
            world = self.worlds[int(items[k])]
            return _leg_observation(obs, k, world.geometry.leg_radius,
                                    float(self.params.platform_radius[items[k]])), world.camera

        return noisy_features(self.sc, obs.normals, obs.edge_visible, rngs, apply_noise,
                              self.est, cameras, item, line_maps)

    def measure_goal(self, rotation: np.ndarray, translation: np.ndarray,
                     rng: np.random.Generator, frames: int = 1, apply_noise: bool = True
                     ) -> ObservationBatch:
        """The desired features: ``frames`` measurements at the true goal pose (3, 3),
        (3,) [m] with ``rng`` (noisy if ``apply_noise``: ``[noise] on_goal``), averaged
        (:func:`vision.estimate.average_normals`) into a batch of one."""
        R = np.repeat(np.asarray(rotation, float)[None], frames, axis=0)
        t = np.repeat(np.asarray(translation, float)[None], frames, axis=0)
        m = self.measure(R, t, [rng] * frames, apply_noise=apply_noise)
        return _average_frames(m, self.est if self.perspective else None)


def reads_features(controller: Any) -> bool:
    """Whether ``controller`` may read a field the camera measures: True unless it (the
    law inside a tracking, latency or foreign-object wrapper) declares its ``features``
    itself, in its class or instance, and they are only the encoders' ``lengths``. The
    base class's default ``{"lengths"}`` is no declaration: a plugin that never set
    ``features`` still gets every field."""
    return not _declares_features(controller) or bool(set(controller.features) - {"lengths"})


def _declares_features(obj: Any) -> bool:
    """Whether the law of ``obj`` (through the wrappers) sets ``features`` itself."""
    from controllers.base import Controller
    from controllers.batch import ForeignController
    from controllers.latency import LatencyCompensated
    from controllers.tracking import TrackingController

    if isinstance(obj, TrackingController | ForeignController):
        return _declares_features(obj.inner)
    if isinstance(obj, LatencyCompensated):
        return _declares_features(obj.law)
    if not isinstance(obj, Controller):
        return hasattr(obj, "features")
    mro = type(obj).__mro__
    return "features" in vars(obj) or any("features" in vars(k)
                                          for k in mro[:mro.index(Controller)])


def draws_noise(sc: SimScenario, apply_noise: bool) -> bool:
    """Whether :func:`noisy_features` draws from the rows' generators (without noise, the
    batched engine does not create them: ten microseconds each)."""
    noise = sc.noise
    return apply_noise and ((noise.model == "rotation" and noise.amplitude_deg > 0)
                            or noise.model == "pixel" or noise.dropout_probability > 0)


def noisy_features(sc: SimScenario, normals: np.ndarray, visible: np.ndarray,
                   rngs: Sequence[Any], apply_noise: bool, estimated: Any,
                   cameras: list[tuple[np.ndarray, Any]],
                   item: Callable[[int], tuple[Any, Any]],
                   line_maps: np.ndarray | None = None) -> ObservationBatch:
    """The scenario's noise on true edges, and the features the controllers receive.

    Rotation noise perturbs each true edge normal; the perspective image lines follow
    through the TRUE camera and the normals the controller receives are recomputed from
    them with the ESTIMATED intrinsics (an intrinsics error reaches the controller).
    Pixel noise fits each normal on noisy points along the visible edge, lifted with the
    estimated camera. Each row draws from its own generator only.

    Args:
        sc: The scenario (its ``[noise]``).
        normals: (n, 6, 2, 3) true edge normals; visible: (n, 6, 2).
        rngs: One generator per row (anything when :func:`draws_noise` is False).
        apply_noise: Whether the noise applies.
        estimated: The estimated camera (every row's).
        cameras: ``(rows, true camera)`` groups covering every row (without ``line_maps``).
        item: Row -> (its :class:`vision.legs.LegObservation`, its true camera) (pixels).
        line_maps: (n, 3, 3) each row's true ``normal_to_line_matrix`` (every camera
            perspective), or None.

    Returns:
        The camera's batch (``lines`` None for a unified camera).
    """
    noise = sc.noise
    n = len(rngs)
    # the caller's arrays are not changed: copies where they are written in place
    normals = np.asarray(normals, dtype=float)
    writes = apply_noise and (noise.model == "pixel" or noise.dropout_probability > 0)
    visible = np.array(visible, dtype=bool) if writes else np.asarray(visible, dtype=bool)
    if apply_noise and noise.model == "rotation" and noise.amplitude_deg > 0:
        normals = rotation_noise_batch(normals, np.deg2rad(noise.amplitude_deg),
                                       rngs if isinstance(rngs, Generators) else list(rngs))
    elif apply_noise and noise.model == "pixel":
        normals = np.array(normals, dtype=float)
        from vision.pixel_measure import normals_from_noisy_pixels

        for k in range(n):  # one generator per trial: results do not depend on batching
            lo_k, cam_k = item(k)
            normals[k], visible[k] = normals_from_noisy_pixels(
                cam_k, estimated, lo_k, noise.pixel_sigma_px,
                max(int(noise.points_per_edge), 2), rngs[k], noise.outlier_fraction)
    if apply_noise and noise.dropout_probability > 0:
        for k in range(n):
            visible[k] &= rngs[k].uniform(size=(6, 2)) >= noise.dropout_probability
    all_visible = bool(visible.all())
    if not all_visible:
        normals = np.where(visible[..., None], normals, np.nan)
    lines = None
    if estimated.family == "perspective":
        if noise.model == "pixel" and apply_noise:
            # fitted with the estimated camera already; the image line is the true one
            lines = estimated.normal_to_line(normals)
        elif line_maps is not None:
            lines, normals = lines_and_normals(normals, line_maps, estimated)
        else:
            lines = np.empty_like(normals)
            for rows, cam in cameras:
                lines[rows] = cam.normal_to_line(normals[rows])
            normals = estimated.line_to_normal(lines)
    return edge_batch(normals, lines, visible)


def _average_frames(m: ObservationBatch, camera: Any | None,
                    max_deviation: float | None = None) -> ObservationBatch:
    """Average K measurements of one static pose (leading axis K) into a batch of one:
    :func:`vision.estimate.average_normals` (frames farther than ``max_deviation`` [rad]
    from the median do not count; an edge kept in fewer than half of the frames is
    missing), seen by the estimated ``camera`` (:func:`seen_edges`). One frame is
    returned unchanged."""
    from vision.estimate import average_normals

    if len(m) == 1:
        return m
    assert m.normals is not None  # a camera's batch has normals
    normals, visible = average_normals(m.normals, m.edge_visible, max_deviation=max_deviation)
    return seen_edges(camera, normals[None], visible[None])


def trial_goal(sensor: GeometricSensor | Any, setup: TrialSetup, sc: SimScenario) -> Goal:
    """The :class:`~controllers.base.Goal` the controllers of trial ``setup`` are told, by
    the scenario's goal setting (:mod:`benchmarks.sim.goal`): under ``"mixed"`` and
    ``"taught"`` the sensor (:func:`make_sensor`) measures the TRUE goal pose
    ``sc.teach_frames`` times (noisy when ``[noise] on_goal``), the normals averaged;
    under ``"cartesian"`` nothing is measured."""
    setting = goal_setting(sc)
    if setting == "cartesian":
        return cartesian_goal(setup)
    rng = trial_rng(sc.seed, setup.trial, 2)
    m = sensor.measure_goal(setup.goal_rotation, setup.goal_translation, rng,
                            frames=sc.teach_frames, apply_noise=sc.noise.on_goal)
    return measured_goals(m, [setup], sc)[0]


def make_sensor(sc: SimScenario, setup: TrialSetup) -> Any:
    """The sensor of a trial: a :class:`GeometricSensor`, or rendered images through
    :class:`vision.image_sensor.ImageSensor` (``[sensor] kind = "image"``; pixel noise
    from the trial's stream 4)."""
    if sc.sensor == "image":
        from vision.image_sensor import ImageSensor

        return _ImageSensorAdapter(ImageSensor(
            setup.world.camera, setup.estimated_camera, setup.world.geometry,
            rng=trial_rng(sc.seed, setup.trial, 4), background=sc.image.background,
            blur_px=sc.image.blur_px, noise_std=sc.image.noise_std,
            estimated_geometry=setup.nominal_geometry))
    return GeometricSensor(sc, setup.world, setup.estimated_camera)


class _ImageSensorAdapter:
    """Adapts :class:`vision.image_sensor.ImageSensor` to the batched sensor interface.

    During a run each trial's detector tracks the edges found in that trial's last
    measurement (the others come from the aligned model prediction), keyed by the
    trial's sensor generator (alive for the whole run). The goal frames are taught as
    ``hexapod-bench servo --teach`` does: the first detected from the model's prediction,
    the next ones tracked from the previous frame; they never seed the run's tracking.
    """

    def __init__(self, sensor: Any) -> None:
        self.sensor = sensor
        self.detect_times: list[float] = []
        self._previous: dict[int, np.ndarray] = {}  # last normals per trial (tracking)

    def measure_goal(self, rotation: np.ndarray, translation: np.ndarray,
                     rng: np.random.Generator, frames: int = 1, apply_noise: bool = True
                     ) -> ObservationBatch:
        """``frames`` rendered images of the goal pose, tracked as the run tracks them
        (detecting each frame afresh left the taught edges 0.1 px off, which held the
        edge law 0.2-0.4 mm from the goal in 3 of 20 trials of
        andreff2006-images-distorted), their normals averaged without the frames farther
        from the median than ``outlier_px``. ``rng``, ``apply_noise``: unused (the pixel
        noise is the renderer's)."""
        from vision.estimate import radians_per_pixel

        normals, visible = [], []
        prev = None
        for _ in range(frames):
            m = self.sensor.measure(rotation, translation, predicted_normals=prev)
            prev = np.asarray(m.normals) if np.any(np.asarray(m.edge_visible)) else None
            normals.append(np.asarray(m.normals, float))
            visible.append(np.asarray(m.edge_visible, bool))
        est = self.sensor.estimated_camera
        tolerance = self.sensor.detector.outlier_px * radians_per_pixel(est)
        return _average_frames(seen_edges(est, np.array(normals), np.array(visible)), est,
                               tolerance)

    def measure(self, rotations: np.ndarray, translations: np.ndarray,
                rngs: list[np.random.Generator], apply_noise: bool = True
                ) -> ObservationBatch:
        """Each row's image rendered and detected, tracked from that row's last one."""
        out: dict[str, list[Any]] = {"normals": [], "lines": [], "edge_visible": []}
        for k in range(len(rotations)):
            key = id(rngs[k])
            prev = self._previous.get(key) if apply_noise else None
            m = self.sensor.measure(rotations[k], translations[k], predicted_normals=prev)
            if apply_noise and np.any(np.asarray(m.edge_visible)):
                self._previous[key] = np.asarray(m.normals)  # NaN where not found
            else:
                self._previous.pop(key, None)
            self.detect_times.append(float(m.detect_time_s))
            out["normals"].append(m.normals)
            out["lines"].append(m.lines)
            out["edge_visible"].append(m.edge_visible)
        lines = None if out["lines"][0] is None else np.array(out["lines"], float)
        return edge_batch(np.array(out["normals"], float), lines,
                          np.array(out["edge_visible"], bool))


class RowSensor:
    """The loop's sensor interface (``observe(rows, R, t)``) over a sensor of one world
    (rendered images, or a study's own) with ``measure(R, t, rngs)`` like
    :class:`GeometricSensor`, and one generator per row of the group (``rngs``)."""

    def __init__(self, sensor: Any, rngs: list[np.random.Generator]) -> None:
        self.sensor = sensor
        self.rngs = rngs
        #: Detection times of rendered images [s] (empty for geometric features).
        self.detect_times: list[float] = getattr(sensor, "detect_times", [])
        #: Whether the controller reads the camera's features (:func:`reads_features`);
        #: else they are withheld, their visibility given, as :class:`GeometricSensor`
        #: withholds them (the two engines give a controller the same fields).
        self.features = True

    def observe(self, rows: np.ndarray, rotations: np.ndarray, translations: np.ndarray
                ) -> ObservationBatch:
        """The camera's batch of ``rows`` at their true poses."""
        batch: ObservationBatch = self.sensor.measure(
            rotations, translations, [self.rngs[k] for k in rows])
        if self.features:
            return batch
        return replace(batch, normals=None, lines=None, directions=None)


def rows_generators(sc: SimScenario, setups: list[TrialSetup], stream: int, apply_noise: bool
                    ) -> list[Any]:
    """The trials' random streams ``stream`` for the sensor, or Nones when the scenario's
    noise draws nothing (:func:`draws_noise`: ten microseconds saved per trial)."""
    if not draws_noise(sc, apply_noise):
        return [None] * len(setups)
    return [trial_rng(sc.seed, s.trial, stream) for s in setups]


def _leg_observation(obs: Any, k: int, radius: float, platform_radius: float
                     ) -> LegObservation:
    """Row ``k`` of a batch observation as a :class:`LegObservation` (pixel noise)."""
    return LegObservation(
        base_points=obs.base_points[k], directions=obs.directions[k], lengths=obs.lengths[k],
        normals=obs.normals[k], exists=obs.exists[k], edge_visible=obs.edge_visible[k],
        visible_fraction=obs.visible_fraction[k], lines=None,
        segments=np.full((6, 2, 2, 2), np.nan), visible_interval=obs.visible_interval[k],
        platform_centre=obs.platform_centre[k], platform_normal=obs.platform_normal[k],
        platform_radius=platform_radius, radius=radius)
