"""Simulated calibration runs: configuration sets, rotation noise, observations of the legs
in a known world.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import Transform, inverse_kinematics, legs_in_frame
from hexapod.workspace import extremal_configurations, sample_poses
from vision import noise as vision_noise
from vision.calibration.data import CalibrationData
from vision.legs import leg_edges

log = logging.getLogger(__name__)

#: A noise model on edge normals: ``(normals (..., 3), rng) -> noisy normals``.
NoiseFunction = Callable[[np.ndarray, np.random.Generator], np.ndarray]


def rotation_noise(amplitude_deg: float) -> NoiseFunction:
    """The rotation noise of the seeds (``docs/math.md`` section 8) as a noise function.

    Each unit vector is rotated about an axis uniform on the sphere by an angle
    uniform in ``[0, amplitude]`` (:func:`vision.noise.rotation_noise`).

    Args:
        amplitude_deg: Maximal rotation angle [deg].
    """

    amplitude = np.deg2rad(float(amplitude_deg))

    def apply(normals: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return vision_noise.rotation_noise(normals, amplitude, rng)

    return apply


ConfigurationsSpec = str | tuple[str, int]


def configuration_poses(
    geometry: HexapodGeometry,
    configurations: ConfigurationsSpec = "extremal",
    rng: np.random.Generator | int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Platform poses (base frame) of a calibration set.

    Args:
        geometry: The robot.
        configurations: ``"extremal"`` (the reachable ones of the 64 configurations
            with every leg at a stroke limit), ``("random", N)`` or ``"random:N"``
            (N uniform poses inside the strokes).
        rng: Generator or seed (random configurations).

    Returns:
        Rotations (N, 3, 3) and translations (N, 3) [m].
    """
    if isinstance(configurations, str) and configurations.startswith("random:"):
        try:
            configurations = ("random", int(configurations.split(":", 1)[1]))
        except ValueError:
            raise ValueError(f"configurations: expected 'random:N', got {configurations!r}"
                             ) from None
    if configurations == "extremal":
        ext = extremal_configurations(geometry)
        if not ext.reachable.all():
            log.warning("calibration: %d extremal configurations unreachable: %s",
                        len(ext.unreachable_indices), ext.unreachable_indices)
        return ext.rotations[ext.reachable], ext.translations[ext.reachable]
    if (isinstance(configurations, tuple) and len(configurations) == 2
            and configurations[0] == "random"):
        n = int(configurations[1])
        if n < 2:
            raise ValueError(f"configurations: need at least 2 random configurations, got {n}")
        return sample_poses(geometry, n, rng=rng)
    raise ValueError(f"configurations: expected 'extremal', ('random', N) or 'random:N', "
                     f"got {configurations!r}")


def collect_observations(
    geometry: HexapodGeometry,
    camera_from_base: Transform | Any,
    configurations: ConfigurationsSpec = "extremal",
    noise: NoiseFunction | None = None,
    rng: np.random.Generator | int | None = None,
    poses: tuple[np.ndarray, np.ndarray] | None = None,
) -> CalibrationData:
    """Simulate the leg-edge observations of a calibration run with the true geometry.

    Args:
        geometry: The TRUE robot (its leg radius makes the edges).
        camera_from_base: The true camera pose, a :class:`Transform` (every existing
            edge is observed), or a :class:`vision.cameras.Camera` (visibility from
            :func:`vision.legs.observe_legs`: image bounds and occlusions).
        configurations: See :func:`configuration_poses`.
        noise: Applied to the normals, ``(normals, rng) -> normals`` (e.g.
            :func:`rotation_noise`); None for exact observations.
        rng: Generator or seed (random configurations and noise).
        poses: Explicit platform poses ``(rotations (N, 3, 3), translations (N, 3))``
            in the base frame (overrides ``configurations``).

    Returns:
        The observations.
    """
    gen = np.random.default_rng(rng)
    R, t = poses if poses is not None else configuration_poses(geometry, configurations, gen)
    if isinstance(camera_from_base, Transform):
        legs = legs_in_frame(geometry, R, t, camera_from_base)
        normals, exists = leg_edges(legs.base_points, legs.directions, geometry.leg_radius)
        visible = np.broadcast_to(exists[..., None], normals.shape[:-1])
        lengths = legs.lengths
    else:
        from vision.legs import observe_legs

        obs = observe_legs(camera_from_base, geometry, R, t)
        normals, visible, lengths = obs.normals, obs.edge_visible, obs.lengths
    if noise is not None:
        normals = np.where(visible[..., None], noise(np.nan_to_num(normals), gen), np.nan)
    return CalibrationData(normals, visible, lengths)


def collect_image_observations(
    sensor: Any,
    geometry: HexapodGeometry,
    configurations: ConfigurationsSpec = "extremal",
    rng: np.random.Generator | int | None = None,
) -> CalibrationData:
    """The observations of a calibration run through rendered images: each configuration
    rendered, its leg edges detected and their normals fitted by ``sensor`` (a
    :class:`vision.image_sensor.ImageSensor`: its detector reads the image through the
    user's camera model, from the nominal robot's prediction, not tracked from the
    previous configuration), the leg lengths those of the true robot (the encoders).

    Args:
        sensor: Renders and measures a pose: ``sensor.measure(rotation, translation)``
            with ``.normals`` (6, 2, 3) and ``.edge_visible`` (6, 2).
        geometry: The TRUE robot (its lengths at each configuration).
        configurations: See :func:`configuration_poses`.
        rng: Generator or seed (random configurations; the pixel noise is the sensor's).
    """
    gen = np.random.default_rng(rng)
    R, t = configuration_poses(geometry, configurations, gen)
    measured = [sensor.measure(R[k], t[k]) for k in range(len(R))]
    visible = np.array([m.edge_visible for m in measured], bool)
    normals = np.where(visible[..., None], np.array([m.normals for m in measured], float),
                       np.nan)
    return CalibrationData(normals, visible, inverse_kinematics(geometry, R, t))


def collect_pixel_observations(
    geometry: HexapodGeometry,
    camera: Any,
    configurations: ConfigurationsSpec,
    sigma_px: float,
    points_per_edge: int,
    rng: np.random.Generator | int | None = None,
    outlier_fraction: float = 0.0,
) -> CalibrationData:
    """Like :func:`collect_observations` with pixel noise on points along each edge.

    Each visible edge is measured by fitting its normal to ``points_per_edge``
    pixels with Gaussian noise ``sigma_px`` (see :mod:`vision.pixel_measure`).
    """
    from vision.legs import observe_legs
    from vision.pixel_measure import normals_from_noisy_pixels

    gen = np.random.default_rng(rng)
    R, t = configuration_poses(geometry, configurations, gen)
    obs = observe_legs(camera, geometry, R, t)
    normals, visible = normals_from_noisy_pixels(camera, camera, obs, sigma_px,
                                                 max(int(points_per_edge), 2), gen,
                                                 outlier_fraction)
    return CalibrationData(normals, visible, obs.lengths)
