"""Closed-chain Pinocchio model of the Gough-Stewart platform.

The platform hangs on a free-flyer joint; each leg is a spherical joint at
``A_i`` (whose zero configuration points the leg along its home direction)
followed by a prismatic joint along the leg's z axis; six
:class:`pinocchio.PointAnchorConstraintModel` close the loops between each leg
tip and ``B_i`` on the platform. This is the reference model: the closed-form
kinematics of :mod:`hexapod.kinematics` is tested against it.

Configuration layout (``model.nq = 7 + 6 * 5``): free-flyer (x, y, z, quaternion),
then per leg a quaternion (spherical joint) and one length (prismatic joint).
Velocity layout (``model.nv = 6 + 6 * 4``): free-flyer twist (local frame), then
per leg an angular velocity and a length rate.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import leg_vectors

try:  # Pinocchio >= 3 ships coal (formerly hpp-fcl)
    import coal as _fcl
except ImportError:  # pragma: no cover - depends on the wheel
    import hppfcl as _fcl

#: Colours (RGBA) used by the visual model and the viewer.
BASE_COLOR = np.array([0.35, 0.35, 0.40, 1.0])
PLATFORM_COLOR = np.array([0.95, 0.55, 0.10, 1.0])
LEG_BODY_COLOR = np.array([0.15, 0.35, 0.85, 1.0])
LEG_ROD_COLOR = np.array([0.75, 0.80, 0.85, 1.0])


def _rotation_z_to(u: np.ndarray) -> np.ndarray:
    """A rotation whose z axis is the unit vector ``u``."""
    u = u / np.linalg.norm(u)
    return pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), u).matrix()


@dataclass
class HexapodModel:
    """The Pinocchio model of a hexapod with its constraints and visual geometry.

    Attributes:
        geometry: The geometry it was built from.
        model: The kinematic tree (free-flyer platform, 6 spherical + prismatic legs).
        constraint_models: Six point-anchor constraints closing the loops.
        visual_model: Cylinders for the legs, discs for the base and the platform.
        platform_joint: Joint id of the free-flyer.
        spherical_joints: Joint ids of the six spherical joints.
        prismatic_joints: Joint ids of the six prismatic joints.
        home_rotations: Rotation of each spherical joint placement (leg z axis at home).
    """

    geometry: HexapodGeometry
    model: pin.Model
    constraint_models: list[pin.PointAnchorConstraintModel]
    visual_model: pin.GeometryModel
    platform_joint: int
    spherical_joints: list[int]
    prismatic_joints: list[int]
    home_rotations: np.ndarray
    home_translation: np.ndarray
    _data: pin.Data | None = field(default=None, repr=False)

    @property
    def data(self) -> pin.Data:
        """A cached ``pin.Data`` for the model."""
        if self._data is None:
            self._data = self.model.createData()
        return self._data

    def prismatic_v_indices(self) -> np.ndarray:
        """Velocity indices of the six prismatic joints."""
        return np.array([self.model.joints[j].idx_v for j in self.prismatic_joints])

    def prismatic_q_indices(self) -> np.ndarray:
        """Configuration indices of the six prismatic joints."""
        return np.array([self.model.joints[j].idx_q for j in self.prismatic_joints])

    def configuration(self, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
        """The configuration vector that closes every loop at a platform pose.

        Args:
            rotation: (3, 3) platform orientation in the base frame.
            translation: (3,) platform position in the base frame [m].
        """
        q = pin.neutral(self.model)
        q[:3] = translation
        q[3:7] = pin.Quaternion(np.asarray(rotation)).coeffs()
        L = leg_vectors(self.geometry, rotation, translation)
        for i, (js, jp) in enumerate(zip(self.spherical_joints, self.prismatic_joints,
                                         strict=True)):
            length = float(np.linalg.norm(L[i]))
            u = L[i] / length
            # spherical rotation Rs so that R0 Rs z = u
            u_local = self.home_rotations[i].T @ u
            Rs = _rotation_z_to(u_local)
            iq = self.model.joints[js].idx_q
            q[iq:iq + 4] = pin.Quaternion(Rs).coeffs()
            q[self.model.joints[jp].idx_q] = length
        return q

    def platform_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Platform rotation and translation from a configuration vector."""
        quat = pin.Quaternion(q[6], q[3], q[4], q[5])
        quat.normalize()
        return quat.matrix(), np.array(q[:3])

    def leg_lengths(self, q: np.ndarray) -> np.ndarray:
        """The six prismatic joint values of a configuration [m]."""
        return np.array(q[self.prismatic_q_indices()])

    def constraint_residual(self, q: np.ndarray) -> np.ndarray:
        """Stacked position errors of the six loop constraints, (18,) [m]."""
        return constraint_residual_and_jacobian(self, q, jacobian=False)[0]

    def constraint_jacobian(self, q: np.ndarray) -> np.ndarray:
        """Stacked constraint Jacobians (18, nv)."""
        return constraint_residual_and_jacobian(self, q, jacobian=True)[1]


def constraint_residual_and_jacobian(
    hm: HexapodModel, q: np.ndarray, jacobian: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate the loop-closure residual (18,) [m] and Jacobian (18, nv) at ``q``."""
    model, data = hm.model, hm.data
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    if jacobian:
        pin.computeJointJacobians(model, data, q)
    res = np.empty(18)
    J = np.empty((18, model.nv)) if jacobian else np.empty((0, 0))
    for k, cm in enumerate(hm.constraint_models):
        cd = cm.createData()
        cm.calc(model, data, cd)
        res[3 * k:3 * k + 3] = cd.constraint_position_error
        if jacobian:
            J[3 * k:3 * k + 3] = cm.jacobian(model, data, cd)
    return res, J


def _leg_inertia(mass: float, moments: np.ndarray, com_z: float) -> pin.Inertia:
    """Spatial inertia of an axisymmetric leg part in its joint frame (leg along z).

    Args:
        mass: [kg] (0: massless, the zero inertia).
        moments: ``(transverse, axial)`` about the centre of mass [kg m^2].
        com_z: Centre of mass on the joint's z axis [m].
    """
    transverse, axial = (float(x) for x in moments)
    return pin.Inertia(float(mass), np.array([0.0, 0.0, com_z]),
                       np.diag([transverse, transverse, axial]))


def build_model(geometry: HexapodGeometry, home_height: float | None = None) -> HexapodModel:
    """Build the closed-chain Pinocchio model of a hexapod.

    Masses, inertias and gravity come from ``geometry.inertia``.

    Args:
        geometry: The robot.
        home_height: Height of the home pose [m] (platform parallel to the base,
            centred); default: the height where the mean leg length is mid-stroke.

    Returns:
        The :class:`HexapodModel`.
    """
    from hexapod.workspace import home_pose

    R_home, t_home = home_pose(geometry, home_height)
    model = pin.Model()
    model.name = f"hexapod_{geometry.name}"
    visual = pin.GeometryModel()
    r = geometry.leg_radius

    base_radius = float(np.max(np.linalg.norm(geometry.base_points[:, :2], axis=1)))
    plat_radius = float(np.max(np.linalg.norm(geometry.platform_points[:, :2], axis=1)))
    thickness = 0.01
    base_geom = pin.GeometryObject(
        "base", 0, pin.SE3(np.eye(3), np.array([0, 0, -thickness / 2])),
        _fcl.Cylinder(base_radius * 1.08, thickness),
    )
    base_geom.meshColor = BASE_COLOR
    visual.addGeometryObject(base_geom)

    inertia = geometry.inertia
    model.gravity = pin.Motion(np.asarray(inertia.gravity, dtype=float), np.zeros(3))
    ff = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "platform_freeflyer")
    model.appendBodyToJoint(
        ff, pin.Inertia(inertia.platform_mass, np.asarray(inertia.platform_com, dtype=float),
                        inertia.platform_tensor), pin.SE3.Identity()
    )
    model.addBodyFrame("platform", ff, pin.SE3.Identity(), model.addJointFrame(ff, 0))
    plat_geom = pin.GeometryObject(
        "platform", ff, pin.SE3(np.eye(3), np.array([0, 0, thickness / 2])),
        _fcl.Cylinder(plat_radius * 1.08, thickness),
    )
    plat_geom.meshColor = PLATFORM_COLOR
    visual.addGeometryObject(plat_geom)

    L_home = leg_vectors(geometry, R_home, t_home)
    spherical, prismatic, home_rots, constraints = [], [], [], []
    body_len = 0.9 * geometry.q_min
    for i in range(6):
        R0 = _rotation_z_to(L_home[i])
        home_rots.append(R0)
        js = model.addJoint(0, pin.JointModelSpherical(), pin.SE3(R0, geometry.base_points[i]),
                            f"leg{i}_spherical")
        model.appendBodyToJoint(js, _leg_inertia(inertia.body_mass, inertia.body_inertia,
                                                 inertia.body_com), pin.SE3.Identity())
        jp = model.addJoint(js, pin.JointModelPZ(), pin.SE3.Identity(), f"leg{i}_prismatic")
        model.lowerPositionLimit[model.joints[jp].idx_q] = geometry.q_min
        model.upperPositionLimit[model.joints[jp].idx_q] = geometry.q_max
        model.appendBodyToJoint(jp, _leg_inertia(inertia.rod_mass, inertia.rod_inertia,
                                                 -inertia.rod_com), pin.SE3.Identity())
        model.addJointFrame(js, 0)
        model.addBodyFrame(f"leg{i}_tip", jp, pin.SE3.Identity(), model.addJointFrame(jp, 0))
        spherical.append(js)
        prismatic.append(jp)

        g_body = pin.GeometryObject(
            f"leg{i}_body", js, pin.SE3(np.eye(3), np.array([0, 0, body_len / 2])),
            _fcl.Cylinder(r, body_len),
        )
        g_body.meshColor = LEG_BODY_COLOR
        visual.addGeometryObject(g_body)
        g_rod = pin.GeometryObject(
            f"leg{i}_rod", jp, pin.SE3(np.eye(3), np.array([0, 0, -body_len / 2])),
            _fcl.Cylinder(0.6 * r, body_len),
        )
        g_rod.meshColor = LEG_ROD_COLOR
        visual.addGeometryObject(g_rod)

        cm = pin.PointAnchorConstraintModel(
            model, jp, pin.SE3.Identity(), ff, pin.SE3(np.eye(3), geometry.platform_points[i])
        )
        cm.name = f"loop{i}"
        constraints.append(cm)

    return HexapodModel(
        geometry=geometry,
        model=model,
        constraint_models=constraints,
        visual_model=visual,
        platform_joint=ff,
        spherical_joints=spherical,
        prismatic_joints=prismatic,
        home_rotations=np.array(home_rots),
        home_translation=t_home,
    )
