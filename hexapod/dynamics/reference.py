"""Reference dynamics on the closed-chain Pinocchio model (``docs/dynamics.md``).

The tree of :mod:`hexapod.model` (free-flyer platform, six spherical + prismatic
legs) with six 3D loop constraints (``pin.RigidConstraintModel`` of type
``CONTACT_3D`` between each leg tip and ``B_i`` on the platform). Every call

1. puts the legs where the platform pose says (:meth:`HexapodModel.configuration`,
   inverse kinematics) and their velocities where the loop closure says (the
   least-norm solution of ``J_legs v_legs = -J_platform v_platform``, which leaves
   every leg's spin about its own axis at zero: it does not move the platform);
2. converts the platform twist of ``docs/math.md`` section 11 (velocity of the
   platform origin and angular velocity, both in the base frame) to the free-flyer's
   spatial velocity in the LOCAL frame, and the free-flyer's LOCAL spatial
   acceleration back to the classical one (``dv/dt = R (a + w_l x v_l)``);
3. solves the constrained dynamics with ``pin.constraintDynamics`` (exact
   constraints, ``mu = 0``).

Massless legs make the tree's mass matrix singular and ``constraintDynamics``'s
factorisation divides by their zero pivots (it returns NaN). For them, and as a
second formulation for every robot, :meth:`ReferenceDynamics.forward_kkt` solves the
same KKT system densely (``crba``, ``nonLinearEffects``, the loop Jacobians and
their acceleration drift from frame classical accelerations) by least squares,
which leaves the undetermined spin accelerations at zero.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from hexapod.exceptions import DynamicsError
from hexapod.geometry import HexapodGeometry
from hexapod.model import build_model

#: Pinocchio reference frame of the frame Jacobians and accelerations used here.
_WORLD = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class ReferenceDynamics:
    """Forward and inverse dynamics of the mechanism on the Pinocchio model.

    Args:
        geometry: The robot (masses and gravity from ``geometry.inertia``).
        armature: (6,) mass added to each prismatic joint [kg] (Pinocchio's
            ``model.armature``: a reflected rotor inertia); none if None.
    """

    def __init__(self, geometry: HexapodGeometry, armature: np.ndarray | None = None
                 ) -> None:
        self.geometry = geometry
        self.hm = build_model(geometry)
        model = self.hm.model.copy()
        if armature is not None:
            for j, a in zip(self.hm.prismatic_joints, armature, strict=True):
                model.armature[model.joints[j].idx_v] = float(a)
        ff = self.hm.platform_joint
        self.b_frames = [
            model.addFrame(pin.Frame(f"B{i}", ff, 0,
                                     pin.SE3(np.eye(3), geometry.platform_points[i]),
                                     pin.FrameType.OP_FRAME))
            for i in range(6)]
        self.tip_frames = [model.getFrameId(f"leg{i}_tip") for i in range(6)]
        self.model = model
        self.data = model.createData()
        self.constraints = pin.StdVec_RigidConstraintModel()
        for i, jp in enumerate(self.hm.prismatic_joints):
            self.constraints.append(pin.RigidConstraintModel(
                pin.ContactType.CONTACT_3D, model, jp, pin.SE3.Identity(), ff,
                pin.SE3(np.eye(3), geometry.platform_points[i]), pin.ReferenceFrame.LOCAL))
        self.constraint_datas = pin.StdVec_RigidConstraintData()
        for cm in self.constraints:
            self.constraint_datas.append(cm.createData())
        pin.initConstraintDynamics(model, self.data, self.constraints, self.constraint_datas)
        self.prox = pin.ProximalSettings(1e-14, 0.0, 100)
        self.prismatic_v = np.array([model.joints[j].idx_v for j in self.hm.prismatic_joints])
        self.massless_legs = geometry.inertia.massless_legs

    # ------------------------------------------------------------- state
    def loop_jacobian(self, q: np.ndarray) -> np.ndarray:
        """(18, nv) Jacobian of the tip-minus-B_i velocities in the base frame."""
        m, d = self.model, self.data
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        rows = [pin.getFrameJacobian(m, d, tip, _WORLD)[:3]
                - pin.getFrameJacobian(m, d, b, _WORLD)[:3]
                for tip, b in zip(self.tip_frames, self.b_frames, strict=True)]
        return np.vstack(rows)

    def loop_drift(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(18,) ``J_dot v``: the tip-minus-B_i classical accelerations at zero ``ddq``."""
        m, d = self.model, self.data
        pin.forwardKinematics(m, d, q, v, np.zeros(m.nv))
        pin.updateFramePlacements(m, d)
        return np.concatenate([
            pin.getFrameClassicalAcceleration(m, d, tip, _WORLD).linear
            - pin.getFrameClassicalAcceleration(m, d, b, _WORLD).linear
            for tip, b in zip(self.tip_frames, self.b_frames, strict=True)])

    def state(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tree configuration ``q``, velocity ``v`` and the loop Jacobian at a platform state.

        Args:
            R: (3, 3) platform orientation in the base frame.
            t: (3,) platform position [m].
            twist: (6,) ``(dt/dt, w)`` in the base frame [m/s, rad/s].
        """
        q = self.hm.configuration(R, t)
        J = self.loop_jacobian(q)
        v = np.zeros(self.model.nv)
        v[:3] = R.T @ twist[:3]
        v[3:6] = R.T @ twist[3:]
        v[6:] = np.linalg.lstsq(J[:, 6:], -J[:, :6] @ v[:6], rcond=None)[0]
        return q, v, J

    def velocity_map(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(nv, 6) matrix ``N`` with ``v = N twist`` (legs by the loop closure, no spin)."""
        return np.column_stack([self.state(R, t, e)[1] for e in np.eye(6)])

    # ------------------------------------------------------------- dynamics
    def generalized_forces(self, forces: np.ndarray) -> np.ndarray:
        """The generalised forces of the model (zero but on the prismatic joints) of the
        leg forces [N]."""
        tau = np.zeros(self.model.nv)
        tau[self.prismatic_v] = forces
        return tau

    @staticmethod
    def classical_acceleration(R: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Platform acceleration ``(d2t/dt2, dw/dt)`` in the base frame from the
        free-flyer's LOCAL velocity ``v[:6]`` and acceleration ``a[:6]``."""
        return np.concatenate([R @ (a[:3] + np.cross(v[3:6], v[:3])), R @ a[3:6]])

    def forward(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray, forces: np.ndarray
                ) -> np.ndarray:
        """Platform acceleration (6,) from ``pin.constraintDynamics`` (the dense KKT
        solve for massless legs, see the module docstring)."""
        if self.massless_legs:
            return self.forward_kkt(R, t, twist, forces)
        q, v, _ = self.state(R, t, twist)
        a = pin.constraintDynamics(self.model, self.data, q, v, self.generalized_forces(forces),
                                   self.constraints, self.constraint_datas, self.prox)
        return self.classical_acceleration(R, v, a)

    def forward_lcaba(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                      forces: np.ndarray, mu: float = 1e-3, iterations: int = 50
                      ) -> np.ndarray:
        """Platform acceleration (6,) from ``pin.lcaba``, for comparison only.

        ``lcaba`` is a proximal (regularised) solver: on this model, with ``mu = 1e-3``
        and 10 or more iterations it agrees with :meth:`forward` to about 1e-11
        (relative); with ``mu = 1e-6`` (its docstring's "typical value") it stalls near
        1e-8, with ``mu = 1e-9`` near 1e-5, with ``mu = 1e-12`` it is off by 1e-2 and
        with ``mu = 0`` it returns NaN (``docs/dynamics.md``). It runs on its own
        ``Data`` and constraint datas: a ``constraintDynamics`` given the constraint
        datas an ``lcaba`` call has used returns accelerations off by about 1e-3.
        """
        q, v, _ = self.state(R, t, twist)
        data = self.model.createData()
        datas = pin.StdVec_RigidConstraintData()
        for cm in self.constraints:
            datas.append(cm.createData())
        pin.computeJointMinimalOrdering(self.model, data, self.constraints)
        a = pin.lcaba(self.model, data, q, v, self.generalized_forces(forces), self.constraints,
                      datas, pin.ProximalSettings(1e-14, mu, iterations))
        return self.classical_acceleration(R, v, a)

    def forward_kkt(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                    forces: np.ndarray) -> np.ndarray:
        """Platform acceleration (6,) from the dense KKT system
        ``[M J^T; J 0] [a; -lambda] = [tau - b; -J_dot v]`` (least squares)."""
        m, d = self.model, self.data
        q, v, J = self.state(R, t, twist)
        gamma = self.loop_drift(q, v)
        M = pin.crba(m, d, q)
        M = np.triu(M) + np.triu(M, 1).T
        b = pin.nonLinearEffects(m, d, q, v)
        n, k = m.nv, J.shape[0]
        kkt = np.zeros((n + k, n + k))
        kkt[:n, :n] = M
        kkt[:n, n:] = J.T
        kkt[n:, :n] = J
        rhs = np.concatenate([self.generalized_forces(forces) - b, -gamma])
        a = np.linalg.lstsq(kkt, rhs, rcond=1e-13)[0][:n]
        return self.classical_acceleration(R, v, a)

    def inverse(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray, acc: np.ndarray
                ) -> np.ndarray:
        """Leg forces (6,) [N]: the legs' accelerations from the loop closure, the tree's
        inverse dynamics ``rnea``, then ``rnea = S f + J^T lambda`` solved for ``f``."""
        m, d = self.model, self.data
        q, v, J = self.state(R, t, twist)
        a = np.zeros(m.nv)
        a[:3] = R.T @ acc[:3] - np.cross(v[3:6], v[:3])
        a[3:6] = R.T @ acc[3:]
        gamma = self.loop_drift(q, v)
        a[6:] = np.linalg.lstsq(J[:, 6:], -gamma - J[:, :6] @ a[:6], rcond=None)[0]
        tau = pin.rnea(m, d, q, v, a)
        S = np.zeros((m.nv, 6))
        S[self.prismatic_v, np.arange(6)] = 1.0
        basis = np.hstack([S, J.T])
        sol = np.linalg.lstsq(basis, tau, rcond=None)[0]
        if np.linalg.norm(basis @ sol - tau) > 1e-6 * np.linalg.norm(tau) + 1e-12:
            raise DynamicsError("inverse", 0)  # singular pose: no forces do it
        return sol[:6]

    def mass_matrix(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(6, 6) ``N^T M_tree N``: the kinetic energy is ``twist^T M twist / 2``."""
        q = self.hm.configuration(R, t)
        M = pin.crba(self.model, self.data, q)
        M = np.triu(M) + np.triu(M, 1).T
        N = self.velocity_map(R, t)
        return N.T @ M @ N

    def energy(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray) -> float:
        """Kinetic plus potential energy [J] (Pinocchio's, potential zero at the base
        origin)."""
        q, v, _ = self.state(R, t, twist)
        kinetic = pin.computeKineticEnergy(self.model, self.data, q, v)
        potential = pin.computePotentialEnergy(self.model, self.data, q)
        return float(kinetic + potential)
