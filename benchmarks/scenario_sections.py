"""The sections of a scenario that the simulator reads as they are: ``[task]``,
``[noise]``, ``[clock]``, ``[image]``, ``[drives]`` and ``[calibration_error]``.

The study reads and checks them from a scenario file
(:mod:`benchmarks.study.scenario_model`, :mod:`benchmarks.study.scenario`) and the
simulator runs them (:mod:`benchmarks.sim.inputs`): one definition of each field for
both, in a module that imports neither (reading a scenario does not import the
simulator, the simulator imports nothing of the study).
"""

from __future__ import annotations

from dataclasses import dataclass

#: The controllers' model's systematic errors [%] (not random, not multiplied by ``scale``):
#: the true robot's value is the robot file's divided by ``1 + e / 100``.
MODEL_ERROR_KEYS = ("model_mass_error_percent", "model_inertia_error_percent",
                    "model_friction_error_percent", "model_rotor_inertia_error_percent",
                    "model_drive_bandwidth_error_percent")
#: Calibration errors that are not standard deviations: not multiplied by ``scale``.
UNSCALED = ("scale", "distortion_percent", *MODEL_ERROR_KEYS, "payload_mass_percent")


@dataclass(frozen=True)
class NoiseConfig:
    """Measurement noise.

    Attributes:
        model: ``"none"``, ``"rotation"`` (random rotation of each edge normal,
            angle uniform in [0, amplitude]) or ``"pixel"`` (Gaussian noise on
            points sampled along each edge, then the normal fit).
        amplitude_deg: Rotation-noise amplitude [deg].
        pixel_sigma_px: Pixel-noise standard deviation [px].
        points_per_edge: Points sampled per edge (pixel model).
        outlier_fraction: Fraction of outlier points (pixel model).
        dropout_probability: Probability that an edge is missed at a step.
        on_goal: Whether the desired features (taken from the goal image) are noisy too.
    """

    model: str = "none"
    amplitude_deg: float = 0.0
    pixel_sigma_px: float = 0.0
    points_per_edge: int = 20
    outlier_fraction: float = 0.0
    dropout_probability: float = 0.0
    on_goal: bool = True


@dataclass(frozen=True)
class CalibrationErrorConfig:
    """Truth minus what the controllers are told (standard deviations).

    Attributes:
        base_points_mm: Per-coordinate std of the base points [mm].
        platform_points_mm: Per-coordinate std of the platform points [mm].
        joint_offsets_mm: Std of the encoder offsets [mm].
        camera_pose_mm: Per-axis std of the camera position [mm].
        camera_pose_deg: Std of the camera orientation error angle per axis [deg].
        intrinsics_percent: Relative std of focal lengths and principal point [%].
        leg_radius_percent: Relative std of the leg radius [%].
        distortion_percent: How much of the lens distortion the camera model misses
            [%]: its coefficients are the true ones times ``1 - distortion_percent /
            100`` (100: a model that ignores the distortion, what a pipeline without
            distortion support assumes). Not random, not multiplied by ``scale``.
        mass_percent: Relative std of the platform's and the legs' masses [%] (the
            dynamic world's true robot; the controllers are told the robot file's).
        inertia_percent: Relative std of their rotational inertias [%]. Each body's
            factor is ``exp(s z)`` (always positive, about ``1 + s z`` for small ``s``).
        model_mass_error_percent: The controllers' model's error on every body's mass
            (platform, leg body, leg rod) [%], the same for every trial: the robot
            file's masses (what the controllers are told) are the true ones times
            ``1 + e / 100`` (+30: the model is 30 % too heavy). Not random, not
            multiplied by ``scale``; the drives' rotor inertia is not changed.
        model_inertia_error_percent: Likewise for their rotational inertias [%].
        model_friction_error_percent: The controllers' model's error on every drive's
            friction, viscous [N s/m] and Coulomb [N] alike [%]: the true drives' are the
            robot file's divided by ``1 + e / 100`` (+30: the model's friction 30 %
            too high). Not random, not multiplied by ``scale``.
        model_rotor_inertia_error_percent: Likewise for the drives' rotor inertia
            reflected to the legs [%].
        model_drive_bandwidth_error_percent: Likewise for the bandwidth of the drives'
            velocity loops [%] (what the drive-aware predictive controllers and the
            ``leg_rate_feedforward`` option model).
        payload_mass_percent: The controllers' model of the ``[payload]``: its mass
            (and inertia) the true one's times ``1 + e / 100`` [%] (-100: unknown to
            them). Not random, not multiplied by ``scale``; the true world is unchanged.
        scale: Multiplies every standard deviation above (sweep it to grow all
            errors together).
    """

    scale: float = 1.0
    base_points_mm: float = 0.0
    platform_points_mm: float = 0.0
    joint_offsets_mm: float = 0.0
    camera_pose_mm: float = 0.0
    camera_pose_deg: float = 0.0
    intrinsics_percent: float = 0.0
    leg_radius_percent: float = 0.0
    distortion_percent: float = 0.0
    mass_percent: float = 0.0
    inertia_percent: float = 0.0
    model_mass_error_percent: float = 0.0
    model_inertia_error_percent: float = 0.0
    model_friction_error_percent: float = 0.0
    model_rotor_inertia_error_percent: float = 0.0
    model_drive_bandwidth_error_percent: float = 0.0
    payload_mass_percent: float = 0.0

    def at_scale(self) -> CalibrationErrorConfig:
        """The errors at the scale: every key but :data:`UNSCALED` times ``scale``."""
        return type(self)(**{k: getattr(self, k) * self.scale if k not in UNSCALED
                             else getattr(self, k) for k in self.__dataclass_fields__})

    def nominal_world(self) -> bool:
        """Whether no error moves the true world away from the nominal one (every trial
        then shares it: ``distortion_percent`` and ``payload_mass_percent`` change only
        the controllers' models)."""
        return all(getattr(self, k) == 0.0 for k in self.__dataclass_fields__
                   if k not in ("scale", "distortion_percent", "payload_mass_percent"))


@dataclass(frozen=True)
class ImageConfig:
    """Rendering settings of the image sensor (``[sensor] kind = "image"``).

    Attributes:
        background: ``"plain"`` (seed 003) or ``"cluttered"``.
        blur_px: Gaussian blur [px].
        noise_std: Pixel noise standard deviation [grey levels].
    """

    background: str = "plain"
    blur_px: float = 0.8
    noise_std: float = 2.0


@dataclass(frozen=True)
class ClockConfig:
    """The camera's clock (:mod:`benchmarks.sim.clock`); the defaults: a camera triggered
    at every control instant whose image arrives at once.

    Attributes:
        frame_rate_hz: Frames per second (0: one frame per control period, at its instant).
        latency_ms: Delay from capture to delivery [ms].
        latency_frames: Further delay, in frame periods (control periods at rate 0).
        jitter_ms: Standard deviation of the capture times around their nominal grid
            [ms] (clipped to 0.45 frame).
        exposure_ms: Exposure time [ms] (0: an instant): a frame integrates the robot's
            motion over the exposure that ends at its capture time (motion blur; the
            rendered images only, ``[sensor] kind = "image"``); its ``image_t`` is the
            middle of the exposure.
        exposure_samples: Poses drawn and averaged over the exposure
            (:func:`vision.exposure.render_exposed`).
    """

    frame_rate_hz: float = 0.0
    latency_ms: float = 0.0
    latency_frames: float = 0.0
    jitter_ms: float = 0.0
    exposure_ms: float = 0.0
    exposure_samples: int = 8


@dataclass(frozen=True)
class DrivesConfig:
    """Changes to the robot's drives (the robot file's ``[drives]``): the true robot of the
    dynamic world and the controllers' nominal model alike, so that a study can sweep
    them on one robot file.

    Attributes:
        velocity_bandwidth_hz: Bandwidth of every leg's velocity loop [Hz] (0: the robot
            file's own).
    """

    velocity_bandwidth_hz: float = 0.0


@dataclass(frozen=True)
class TaskConfig:
    """What each trial must do.

    Attributes:
        kind: ``"random-pairs"`` (start and goal drawn inside the strokes), ``"fixed"``
            or ``"trajectory"`` (track a reference from a random start: the trial runs
            ``max_steps``, as ``fixed_duration``).
        start_mm: Start leg lengths (fixed task) [mm].
        goal_mm: Goal leg lengths (fixed task) [mm].
        max_steps: Step budget.
        position_tolerance_mm: Convergence threshold on the platform position [mm].
        orientation_tolerance_deg: Convergence threshold on the orientation [deg].
        margin_mm: Random poses keep this distance from the stroke limits [mm].
        max_translation_mm: Half-width of the random position box [mm].
        max_angle_deg: Maximal random rotation [deg].
        settle_steps: Steps the tolerances must hold to count as converged.
        fixed_duration: Run every trial for ``max_steps`` (noise studies: the final
            error is the error at the end; converged means within tolerance then).
        shape: Trajectory task: ``"line"`` (start to goal), ``"circle"`` or
            ``"lemniscate"`` (through the start, ``laps`` times); see
            :mod:`hexapod.trajectory`.
        profile: Trajectory timing law: ``"quintic"``, ``"trapezoidal"`` or ``"s-curve"``
            (jerk-limited, :mod:`hexapod.scurve`).
        speed_mm_s: Largest platform speed along the trajectory [mm/s].
        acceleration_mm_s2: Largest tangential acceleration [mm/s^2].
        angular_speed_deg_s: Largest angular speed of a line [deg/s].
        angular_acceleration_deg_s2: Largest angular acceleration of a line [deg/s^2].
        jerk_mm_s3: Largest tangential jerk [mm/s^3] (the ``"s-curve"`` profile).
        angular_jerk_deg_s3: Largest angular jerk of a line [deg/s^3] (``"s-curve"``).
        peak_acceleration_mm_s2: The motion scaled in time until its largest
            acceleration ``|d2p/dt2|`` is this [mm/s^2] (0: as the limits time it).
        radius_mm: Radius of the circle, half-width of the lemniscate [mm].
        laps: Turns of a closed curve.
        plane: Plane of a closed curve in the base frame: ``"xy"``, ``"xz"``, ``"yz"``.
        feed_forward: Add the reference's nominal leg-length rate to the velocity
            commands (:mod:`controllers.tracking`); false: feedback only.
        goal: What the controllers are told about the goal (:mod:`benchmarks.sim.goal`):
            ``"mixed"`` (the legacy default: vision laws taught at the true goal, encoder
            and pose laws the nominal inverse kinematics), ``"taught"`` (images and
            encoders recorded at the true goal) or ``"cartesian"`` (a pose; every law
            predicts its goal from its model).
    """

    kind: str = "random-pairs"
    start_mm: tuple[float, ...] | None = None
    goal_mm: tuple[float, ...] | None = None
    max_steps: int = 1000
    position_tolerance_mm: float = 0.1
    orientation_tolerance_deg: float = 0.01
    margin_mm: float = 5.0
    max_translation_mm: float = 60.0
    max_angle_deg: float = 10.0
    settle_steps: int = 1
    fixed_duration: bool = False
    shape: str = "line"
    profile: str = "quintic"
    speed_mm_s: float = 50.0
    acceleration_mm_s2: float = 500.0
    angular_speed_deg_s: float = 10.0
    angular_acceleration_deg_s2: float = 50.0
    jerk_mm_s3: float = 10_000.0
    angular_jerk_deg_s3: float = 1000.0
    peak_acceleration_mm_s2: float = 0.0
    radius_mm: float = 20.0
    laps: int = 1
    plane: str = "xy"
    feed_forward: bool = True
    goal: str = "mixed"
