"""The numpy leg kinematics the laws compute with outside their compiled cores
(``docs/math.md`` sections 2 and 3): :func:`cross` and the leg-direction interaction
matrices :func:`direction_interaction` ``M_i`` (the dead reckoning of hidden legs,
:meth:`controllers.estimators.LegDirectionEstimate.predict_hidden`). Twists
``tau = (v, w)`` are expressed in the camera frame and reduced at its origin. (The
tests' numpy oracle of the tasks' CasADi blocks: ``tests/controllers/interaction_oracle.py``.)
"""

from __future__ import annotations

import numpy as np

from hexapod.se3 import skew

__all__ = ["cross", "direction_interaction"]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product along the last axis (faster than :func:`numpy.cross` on small arrays)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    shape = a.shape if a.shape == b.shape else np.broadcast_shapes(a.shape, b.shape)
    out = np.empty(shape)
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def direction_interaction(
    base_points: np.ndarray, directions: np.ndarray, lengths: np.ndarray
) -> np.ndarray:
    """Leg-direction interaction matrices ``u_dot_i = M_i tau``, ``M_i = (1/q_i) P(u_i)
    [I3, -[A_i + q_i u_i]_x]`` (``docs/math.md`` section 3).

    Args:
        base_points: (..., 3) ``A_i`` in the camera frame [m].
        directions: (..., 3) unit ``u_i``.
        lengths: (...) ``q_i`` [m].

    Returns:
        (..., 3, 6) [1/m for the v columns, 1 for the w columns].
    """
    A = np.asarray(base_points, dtype=float)
    u = np.asarray(directions, dtype=float)
    q = np.asarray(lengths, dtype=float)
    P = np.eye(3) - u[..., :, None] * u[..., None, :]
    B = A + q[..., None] * u
    M = np.concatenate([P, -P @ skew(B)], axis=-1)
    return M / q[..., None, None]
