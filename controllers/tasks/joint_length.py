"""The joint-length row ``L_i = [u_i^T, (A_i x u_i)^T]``: the rows of the inverse
Jacobian (``docs/math.md`` section 3), one per leg, from which the compiled law cores
build their ``J_inv`` (``q_dot = J_inv tau``).
"""

from __future__ import annotations

import casadi as ca


def inverse_jacobian_row(u: ca.SX, base_point: ca.SX) -> ca.SX:
    """``[u^T, (A x u)^T]`` (1, 6): ``q_dot = row tau`` for the platform twist ``tau``.

    Args:
        u: (3, 1) unit leg direction.
        base_point: (3, 1) ``A`` [m].
    """
    return ca.horzcat(u.T, ca.cross(base_point, u).T)
