"""What the controllers are told about a trial's goal: the scenario's goal setting
(``[task] goal``, ``docs/scenarios.md``, "Fairness"), stated in the rows (``goal``).

- ``"mixed"`` (the default): the vision laws get the features measured at the TRUE goal
  (taught by showing, averaged over ``teach_frames``), the encoder and pose laws the
  goal pose and its NOMINAL inverse kinematics;
- ``"taught"``: the images and the encoders recorded at the true goal (the true lengths
  plus the joint offsets, quantised in the dynamic world); the pose laws get the pose
  their model computes from the taught lengths, and a trajectory's reference is moved to
  end there (:class:`AnchoredReference`);
- ``"cartesian"``: a pose in the base frame; every family predicts its goal from its
  model (the features through the estimated camera, the lengths by inverse kinematics).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from benchmarks.sim.world import TrialSetup, inverse_kinematics_by_robot
from controllers.base import Goal, ObservationBatch
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import inverse_kinematics
from hexapod.trajectory import ReferenceSample

#: The goal settings of ``[task] goal``; the first is the default.
GOAL_SETTINGS = ("mixed", "taught", "cartesian")

#: The settings in words (``run.json``, the report).
GOAL_TEXT = {
    "mixed": "mixed (legacy): vision laws taught at the true goal, encoder and pose laws "
             "the nominal inverse kinematics of the goal pose",
    "taught": "taught: images and encoders recorded at the true goal; pose laws the "
              "forward kinematics of the taught lengths in their model",
    "cartesian": "cartesian: a pose in the base frame; features and lengths predicted "
                 "from each controller's model",
}


def goal_setting(sc: Any) -> str:
    """The goal setting of a scenario (``[task] goal``; ``"mixed"`` when its task has
    none).

    Raises:
        ValueError: Not one of :data:`GOAL_SETTINGS` (naming the key and the value).
    """
    value = getattr(sc.task, "goal", GOAL_SETTINGS[0])
    if value not in GOAL_SETTINGS:
        raise ValueError(f"task.goal: expected one of {', '.join(GOAL_SETTINGS)}, got "
                         f"{value!r}")
    return str(value)


def taught_lengths(sc: Any, setup: TrialSetup) -> np.ndarray:
    """The encoder readings at the trial's true goal (6,) [m]: the true robot's inverse
    kinematics plus its joint offsets, quantised to its encoder resolution in the dynamic
    world (what the plant's ``measured_lengths`` reads there)."""
    world = setup.world
    q = inverse_kinematics(world.geometry, setup.goal_rotation, setup.goal_translation)
    q = np.asarray(q, dtype=float) + np.asarray(world.joint_offsets, dtype=float)
    if getattr(sc, "world", "kinematic") == "dynamic":
        from hexapod.dynamics.drive_model import quantise

        q = quantise(q, np.asarray(world.geometry.drives.encoder_resolution, float))
    return q


def model_pose(geometry: HexapodGeometry, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pose the model ``geometry`` computes from leg lengths [m] (forward kinematics
    from the home pose, as a user's model would; the stroke is not checked: the robot
    was there).

    Raises:
        ForwardKinematicsError: No pose for these lengths in the model.
    """
    from hexapod.fk import forward_kinematics

    sol = forward_kinematics(geometry, np.asarray(lengths, dtype=float), check_stroke=False)
    return np.asarray(sol.rotation, float), np.asarray(sol.translation, float)


def controller_geometry(setup: TrialSetup) -> HexapodGeometry:
    """The controller's model of the robot with ITS base points: the nominal geometry,
    its base points replaced by the trial's estimated (calibrated) ones brought to the
    base frame through the estimated camera pose when they differ from the nominal."""
    model = setup.nominal_geometry
    cam_from_base = setup.estimated_camera.camera_from_base
    nominal_points = cam_from_base.apply(model.base_points)
    points = np.asarray(setup.base_points, dtype=float)
    if np.array_equal(nominal_points, points):
        return model
    return model.replace(base_points=cam_from_base.inverse().apply(points))


def predicted_features(camera: Any, geometry: HexapodGeometry, rotation: np.ndarray,
                       translation: np.ndarray) -> dict[str, Any]:
    """The goal features the model predicts at a pose: edge normals (NaN where hidden),
    image lines (a perspective camera, else None), leg directions (NaN where an edge is
    hidden) and edge visibility, as ``camera`` sees ``geometry``. An edge the model
    predicts hidden is NaN, as a hidden edge is in a taught goal: a law that needs it
    says so itself (an encoder law does not).
    """
    from benchmarks.sim.sensors import seen_edges
    from vision.legs import observe_legs

    seen = observe_legs(camera, geometry, np.asarray(rotation, float),
                        np.asarray(translation, float))
    visible = np.asarray(seen.edge_visible, dtype=bool)
    normals = np.where(visible[..., None], np.asarray(seen.normals, float), np.nan)
    return row_features(seen_edges(camera, normals[None], visible[None]), 0)


def taught_goal(m: ObservationBatch, setup: TrialSetup, sc: Any, row: int = 0) -> Goal:
    """The :class:`Goal` of ``"taught"``: the features of row ``row`` of the camera's batch
    taught at the goal, the encoders read there (:func:`taught_lengths`) and the pose the
    controller's model computes from them (:func:`model_pose`)."""
    q = taught_lengths(sc, setup)
    R, t = model_pose(setup.nominal_geometry, q)
    return Goal(lengths=q, rotation=R, translation=t, **row_features(m, row))


def measured_goals(m: ObservationBatch, setups: list[TrialSetup], sc: Any) -> list[Goal]:
    """The goals of the ``"mixed"`` and ``"taught"`` settings of trials whose goal images
    are the rows of one batch ``m`` (row ``k``: ``setups[k]``): the values
    :func:`benchmarks.sim.sensors.trial_goal` gives one by one, the features views of
    the rows and the nominal inverse kinematics one call per nominal robot.

    Raises:
        ValueError: The setting is ``"cartesian"`` (nothing is measured at the goal).
    """
    setting = goal_setting(sc)
    if setting == "cartesian":
        raise ValueError("task.goal: a cartesian goal is predicted, not measured")
    if setting == "taught":
        return [taught_goal(m, s, sc, k) for k, s in enumerate(setups)]
    lengths = inverse_kinematics_by_robot([s.nominal_geometry for s in setups],
                                          np.array([s.goal_rotation for s in setups]),
                                          np.array([s.goal_translation for s in setups]))
    return [Goal(lengths=lengths[k], rotation=s.goal_rotation, translation=s.goal_translation,
                 **row_features(m, k)) for k, s in enumerate(setups)]


def row_features(m: ObservationBatch, row: int) -> dict[str, Any]:
    """The goal features of row ``row`` of a camera's batch (views)."""
    return {"normals": m.normals[row],  # type: ignore[index]
            "lines": None if m.lines is None else m.lines[row],
            "directions": m.directions[row],  # type: ignore[index]
            "edge_visible": m.edge_visible[row]}


def cartesian_goal(setup: TrialSetup) -> Goal:
    """The :class:`Goal` of ``"cartesian"``: the goal pose, its inverse kinematics in the
    controller's model and the features that model predicts there through the estimated
    camera (:func:`predicted_features`); nothing is measured at the goal."""
    R, t = setup.goal_rotation, setup.goal_translation
    feats = predicted_features(setup.estimated_camera, controller_geometry(setup), R, t)
    return Goal(lengths=inverse_kinematics(setup.nominal_geometry, R, t), rotation=R,
                translation=t, **feats)


class AnchoredReference:
    """A ``reference`` trajectory (``duration`` [s], ``at(times)``) moved to end at the
    goal pose ``rotation`` (3, 3), ``translation`` (3,) [m] (``"taught"``): each sample's
    displacement from the end, in the base frame, is applied to the goal (``t' = t -
    t_end + t_goal``, ``R' = R R_end^T R_goal``). Velocities, accelerations, the time
    axis and every other attribute are the reference's: the same motion, started from
    where the model says the taught goal is (turning the path would turn its shape)."""

    def __init__(self, reference: Any, rotation: np.ndarray, translation: np.ndarray
                 ) -> None:
        self.reference = reference
        end = reference.at(np.array([float(reference.duration)]))
        #: ``R_end^T R_goal``, applied on the right of every orientation.
        self.rotation_offset = end.rotation[0].T @ np.asarray(rotation, float)
        #: ``t_goal - t_end`` [m], added to every position.
        self.translation_offset = np.asarray(translation, float) - end.translation[0]

    def at(self, t: float | np.ndarray) -> ReferenceSample:
        """The moved reference at times ``t`` [s]."""
        s = self.reference.at(t)
        return ReferenceSample(s.rotation @ self.rotation_offset,
                               s.translation + self.translation_offset, s.velocity,
                               s.angular_velocity, s.acceleration, s.angular_acceleration)

    def __getattr__(self, name: str) -> Any:
        if name == "reference":  # not set yet (a copy being built)
            raise AttributeError(name)
        return getattr(self.reference, name)
