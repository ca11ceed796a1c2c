"""A feature added as a plugin would add it, in this one file (``docs/plugins.md``,
"Adding a feature"): the platform joints ``B_i = A_i + q_i u_i`` seen in the camera
frame, with its four compiled controllers."""

from __future__ import annotations

import casadi as ca

from controllers.features import LegFeature, controllers_for


class PlatformJoints(LegFeature):
    """The platform joint ``B_i = A_i + q_i u_i`` of each leg, camera frame [m]."""

    name = "platform-joint"
    rows = 3

    def value(self, u: ca.SX, q: ca.SX, A: ca.SX) -> ca.SX:
        return A + q * u


JOINTS = controllers_for(PlatformJoints())
PlatformJointPinv = JOINTS.pinv
PlatformJointQP = JOINTS.qp
PlatformJointMPC = JOINTS.mpc
PlatformJointCTC = JOINTS.ctc
