"""Two features of one name in one module (a plugin author's slip): their controllers
share their registry names, and pickling one of them must say so."""

from __future__ import annotations

import casadi as ca

from controllers.features import LegFeature, controllers_for


class Joints(LegFeature):
    """The platform joint ``B_i`` (camera frame) [m]."""

    name = "joint"
    rows = 3

    def value(self, u: ca.SX, q: ca.SX, A: ca.SX) -> ca.SX:
        return A + q * u


class Depths(LegFeature):
    """The platform joint's depth, under the same name."""

    name = "joint"
    rows = 1

    def value(self, u: ca.SX, q: ca.SX, A: ca.SX) -> ca.SX:
        return (A + q * u)[2]


JOINTS = controllers_for(Joints())
DEPTHS = controllers_for(Depths())
