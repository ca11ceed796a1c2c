"""Interaction matrices of the leg features (``docs/math.md`` sections 3, 4, 5, 6), in numpy:
the tests' oracle.

The independent reference of the tasks' CasADi blocks (:mod:`controllers.tasks`), from
which the vision laws' compiled cores are generated (:mod:`controllers.law_kernel`): the
laws do not compute with these functions; the tests do (``tests/controllers/numpy_law.py``
steps a law with them). ``M_i`` (:func:`~controllers.interaction.direction_interaction`)
and :func:`~controllers.interaction.cross` are the library's (the dead reckoning of
hidden legs uses them). Twists ``tau = (v, w)`` are expressed in the camera frame and
reduced at its origin (``docs/math.md`` section 2).

Two forms are given:

- the explicit matrices of ``docs/math.md`` (:func:`direction_interaction` ``M_i``,
  :func:`edge_interaction` ``H``, :func:`line_jacobian` ``J_l``), batched over
  leading axes, for tests and for readers;
- the task blocks used by the control laws (:func:`direction_task`,
  :func:`edge_normal_task`, :func:`edge_line_task`), written with the structure
  of the products so that a step costs a few vector operations:

  * ``n^T M_i = (1/q_i) [r^T, (B_i x r)^T]`` with ``r = P(u_i) n`` and
    ``B_i = A_i + q_i u_i`` (the platform joint);
  * ``H M_i = -z g^T`` is rank one, with ``g = M_i^T n`` and
    ``z = u - (u x n) (A^T u) / (A^T (u x n))``;
  * hence ``-[n*]_x H M_i = (n* x z) g^T`` and
    ``-[l*]_x J_l H M_i = (l* x J_l z) g^T``.

Every function is tested against finite differences of the true kinematics
and cameras (``tests/controllers/test_interaction.py``), never against another
copy of the formulas.
"""

from __future__ import annotations

import numpy as np

from controllers.interaction import cross, direction_interaction
from hexapod.se3 import skew

__all__ = [
    "cross",
    "direction_interaction",
    "direction_task",
    "edge_interaction",
    "edge_line_factors",
    "edge_line_task",
    "edge_normal_factors",
    "edge_normal_task",
    "edge_rank_one",
    "line_jacobian",
]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...k,...k->...", a, b)


# --------------------------------------------------------------------------- explicit
def edge_interaction(normals: np.ndarray, directions: np.ndarray,
                     base_points: np.ndarray) -> np.ndarray:
    """Edge interaction matrices ``n_dot = H(n, u, A) u_dot`` (``docs/math.md`` section 4).

    ``H = -(I3 - (u x n) A^T / (A^T (u x n))) u n^T``.

    Args:
        normals: (..., 3) unit edge normals ``n``.
        directions: (..., 3) unit leg directions ``u``.
        base_points: (..., 3) ``A`` [m].

    Returns:
        (..., 3, 3).
    """
    n = np.asarray(normals, dtype=float)
    u = np.asarray(directions, dtype=float)
    A = np.asarray(base_points, dtype=float)
    A = np.broadcast_to(A, np.broadcast_shapes(A.shape, u.shape))
    w = cross(u, n)
    G = np.eye(3) - w[..., :, None] * A[..., None, :] / _dot(A, w)[..., None, None]
    return -(G @ u[..., :, None]) * n[..., None, :]


def line_jacobian(lines: np.ndarray, line_matrix: np.ndarray) -> np.ndarray:
    """Pixel-line Jacobian ``l_dot = J_l n_dot`` (``docs/math.md`` section 5).

    ``J_l = |K^T l| (I3 - l l^T) K^-T`` for ``l = K^-T n / |K^-T n|``.

    Args:
        lines: (..., 3) unit image lines in normalised pixel coordinates.
        line_matrix: (3, 3) ``K`` (the camera's ``line_matrix``).

    Returns:
        (..., 3, 3).
    """
    l = np.asarray(lines, dtype=float)
    K = np.asarray(line_matrix, dtype=float)
    scale = np.linalg.norm(l @ K, axis=-1)
    P = np.eye(3) - l[..., :, None] * l[..., None, :]
    return scale[..., None, None] * (P @ np.linalg.inv(K).T)


# --------------------------------------------------------------------------- task blocks
def _normal_row(normals: np.ndarray, directions: np.ndarray, base_points: np.ndarray,
                lengths: np.ndarray) -> np.ndarray:
    """``g = M_i^T n`` (..., 6): the row ``n^T M_i``."""
    n, u = normals, directions
    r = n - _dot(n, u)[..., None] * u
    B = base_points + lengths[..., None] * u
    g = np.empty((*r.shape[:-1], 6))
    inv_q = 1.0 / lengths[..., None]
    g[..., :3] = r * inv_q
    g[..., 3:] = cross(B, r) * inv_q
    return g


def edge_rank_one(normals: np.ndarray, directions: np.ndarray, base_points: np.ndarray,
                  lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Factors of ``H(n, u, A) M_i = -z g^T``.

    Args:
        normals: (..., 3) edge normals.
        directions: (..., 3) leg directions (of the leg of each edge).
        base_points: (..., 3) ``A_i`` [m].
        lengths: (...) ``q_i`` [m].

    Returns:
        ``z`` (..., 3) and ``g`` (..., 6).
    """
    n, u, A = normals, directions, base_points
    w = cross(u, n)
    z = u - w * (_dot(A, u) / _dot(A, w))[..., None]
    return z, _normal_row(n, u, A, lengths)


def direction_task(
    directions: np.ndarray, desired: np.ndarray, base_points: np.ndarray, lengths: np.ndarray,
    error: bool = True, desired_skew: np.ndarray | None = None,
) -> tuple[np.ndarray | None, np.ndarray]:
    """Leg-direction task: ``e_i = u_i x u_i*``, ``L_i = -[u_i*]_x M_i``.

    Args:
        directions: (k, 3) unit directions where ``M_i`` is evaluated (current,
            desired, ...).
        desired: (k, 3) desired directions ``u_i*``.
        base_points: (k, 3) ``A_i`` [m].
        lengths: (k,) leg lengths where ``M_i`` is evaluated [m].
        error: Compute ``u x u*`` with ``u = directions`` (False: return None).
        desired_skew: ``[u_i*]_x`` (k, 3, 3) if precomputed.

    Returns:
        ``e`` (k, 3) (or None) and ``L`` (k, 3, 6).
    """
    u, us = directions, desired
    k = u.shape[0]
    # C = -(1/q) [u*]_x P(u) = -(1/q) ([u*]_x - (u* x u) u^T)
    C = skew(us) if desired_skew is None else desired_skew.copy()
    C -= cross(us, u)[:, :, None] * u[:, None, :]
    C *= (-1.0 / lengths)[:, None, None]
    B = base_points + lengths[:, None] * u
    L = np.empty((k, 3, 6))
    L[:, :, :3] = C
    L[:, :, 3:] = cross(np.broadcast_to(B[:, None, :], C.shape), C)  # rows of -C[B]_x: B x c_k
    return (cross(u, us) if error else None), L


def edge_normal_task(
    normals: np.ndarray, desired: np.ndarray, directions: np.ndarray, base_points: np.ndarray,
    lengths: np.ndarray,
) -> np.ndarray:
    """Edge task on the sphere: ``L_ij = -[n_ij*]_x H(n, u, A) M_i`` (``docs/math.md`` section 6).

    Args:
        normals: (k, 3) normals where ``H`` is evaluated.
        desired: (k, 3) desired normals ``n*``.
        directions: (k, 3) leg direction of each edge where ``H M`` is evaluated.
        base_points: (k, 3) ``A_i`` of each edge [m].
        lengths: (k,) ``q_i`` of each edge [m].

    Returns:
        ``L`` (k, 3, 6); the error ``n x n*`` is computed by the caller.
    """
    a, g = edge_normal_factors(normals, desired, directions, base_points, lengths)
    return a[:, :, None] * g[:, None, :]


def edge_normal_factors(
    normals: np.ndarray, desired: np.ndarray, directions: np.ndarray, base_points: np.ndarray,
    lengths: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Rank-one factors of :func:`edge_normal_task`: ``L_ij = a g^T``, ``a = n* x z``.

    Returns:
        ``a`` (k, 3) and ``g`` (k, 6).
    """
    z, g = edge_rank_one(normals, directions, base_points, lengths)
    return cross(desired, z), g


def edge_line_task(
    lines: np.ndarray, desired_lines: np.ndarray, normals: np.ndarray, directions: np.ndarray,
    base_points: np.ndarray, lengths: np.ndarray, line_matrix: np.ndarray,
    line_matrix_inv_t: np.ndarray | None = None,
) -> np.ndarray:
    """Edge task on pixel lines: ``L_ij = -[l_ij*]_x J_l H M_i`` (``docs/math.md`` section 6).

    Args:
        lines: (k, 3) unit lines where ``J_l`` is evaluated.
        desired_lines: (k, 3) desired lines ``l*``.
        normals: (k, 3) the normals of ``lines`` (``n ∝ K^T l``).
        directions: (k, 3) leg direction of each edge.
        base_points: (k, 3) ``A_i`` of each edge [m].
        lengths: (k,) ``q_i`` of each edge [m].
        line_matrix: (3, 3) ``K`` (the camera's ``line_matrix``).
        line_matrix_inv_t: ``K^-T`` if precomputed.

    Returns:
        ``L`` (k, 3, 6).
    """
    a, g = edge_line_factors(lines, desired_lines, normals, directions, base_points, lengths,
                             line_matrix, line_matrix_inv_t)
    return a[:, :, None] * g[:, None, :]


def edge_line_factors(
    lines: np.ndarray, desired_lines: np.ndarray, normals: np.ndarray, directions: np.ndarray,
    base_points: np.ndarray, lengths: np.ndarray, line_matrix: np.ndarray,
    line_matrix_inv_t: np.ndarray | None = None, line_scale: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Rank-one factors of :func:`edge_line_task`: ``L_ij = a g^T``, ``a = l* x J_l z``.

    Args:
        line_scale: ``|K^T l|`` (k,) if already computed.

    Returns:
        ``a`` (k, 3) and ``g`` (k, 6).
    """
    Kit = np.linalg.inv(line_matrix).T if line_matrix_inv_t is None else line_matrix_inv_t
    z, g = edge_rank_one(normals, directions, base_points, lengths)
    l = lines
    if line_scale is None:
        lK = l @ line_matrix
        line_scale = np.sqrt(_dot(lK, lK))
    y = z @ Kit.T
    y -= l * _dot(l, y)[:, None]
    y *= line_scale[:, None]
    return cross(desired_lines, y), g
