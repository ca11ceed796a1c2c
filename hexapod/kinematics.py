"""Closed-form kinematics of the Gough-Stewart platform, batched over leading axes.

``docs/math.md`` sections 1-3: ``q_i u_i = R eB_i + t - A_i``; the inverse Jacobian
row ``i`` is ``[u_i^T, (A_i x u_i)^T]`` for a twist expressed in the frame of the
points and reduced at its origin. Functions here accept poses of the platform
frame ``e`` in the base frame ``b`` and, optionally, a fixed transform
``frame_from_base`` (e.g. ``camera_from_base``) to express the result in
another frame fixed to the base.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexapod.exceptions import ShapeError
from hexapod.geometry import HexapodGeometry
from hexapod.se3 import rotation_defect


def _check_pose(rotation: np.ndarray, translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    R = np.asarray(rotation, dtype=float)
    t = np.asarray(translation, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise ShapeError("rotation", "shape (..., 3, 3)", R.shape)
    if t.shape[-1:] != (3,):
        raise ShapeError("translation", "shape (..., 3)", t.shape)
    if R.shape[:-2] != t.shape[:-1]:
        raise ShapeError(
            "rotation/translation", "matching batch shapes", f"{R.shape[:-2]} and {t.shape[:-1]}"
        )
    if not (np.isfinite(R).all() and np.isfinite(t).all()):
        raise ShapeError("pose", "finite values", "NaN or inf")
    check_rotations(R)
    return R, t


def check_rotations(R: np.ndarray, name: str = "rotation", tolerance: float | None = None
                    ) -> None:
    """Refuse finite matrices (..., 3, 3) that are not rotations: ``R^T R`` further than
    ``tolerance`` (default :data:`ROTATION_TOLERANCE`) from the identity, or a
    determinant not positive.

    Raises:
        ShapeError: Naming ``name``, the largest defect and the determinants' range.
    """
    defect, det = rotation_defect(R)
    off = float(np.max(defect, initial=0.0))
    if off > (ROTATION_TOLERANCE if tolerance is None else tolerance) or np.any(det <= 0):
        raise ShapeError(name, "rotation matrices (R^T R = I, det = +1: not a scaled, "
                         "sheared or mirrored matrix)",
                         f"|R^T R - I| = {off:.2e}, det from {float(np.min(det)):.4g} to "
                         f"{float(np.max(det)):.4g}")


#: How far ``R^T R`` may be from the identity in a pose given to the kinematics (the
#: camera's own check: a rotation built by the project is within 1e-12).
ROTATION_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Transform:
    """A rigid transform ``to_from``: ``p_to = rotation @ p_from + translation``.

    Attributes:
        rotation: (3, 3).
        translation: (3,) [m].
    """

    rotation: np.ndarray
    translation: np.ndarray

    @staticmethod
    def identity() -> Transform:
        """The identity transform."""
        return Transform(np.eye(3), np.zeros(3))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform points (..., 3)."""
        return np.asarray(points) @ self.rotation.T + self.translation

    def rotate(self, vectors: np.ndarray) -> np.ndarray:
        """Rotate free vectors (..., 3)."""
        return np.asarray(vectors) @ self.rotation.T

    def inverse(self) -> Transform:
        """The inverse transform."""
        return Transform(self.rotation.T, -self.rotation.T @ self.translation)

    def compose(self, other: Transform) -> Transform:
        """``self @ other`` (apply ``other`` first)."""
        return Transform(self.rotation @ other.rotation,
                         self.rotation @ other.translation + self.translation)

    def as_matrix(self) -> np.ndarray:
        """4x4 homogeneous matrix."""
        M = np.eye(4)
        M[:3, :3] = self.rotation
        M[:3, 3] = self.translation
        return M


def platform_points_in_base(
    geometry: HexapodGeometry, rotation: np.ndarray, translation: np.ndarray
) -> np.ndarray:
    """Platform joint centres ``B_i = R eB_i + t`` in the base frame, (..., 6, 3) [m]."""
    R, t = _check_pose(rotation, translation)
    return np.einsum("...jk,ik->...ij", R, geometry.platform_points) + t[..., None, :]


def leg_vectors(
    geometry: HexapodGeometry, rotation: np.ndarray, translation: np.ndarray
) -> np.ndarray:
    """Leg vectors ``B_i - A_i`` in the base frame, (..., 6, 3) [m]."""
    return platform_points_in_base(geometry, rotation, translation) - geometry.base_points


def inverse_kinematics(
    geometry: HexapodGeometry, rotation: np.ndarray, translation: np.ndarray
) -> np.ndarray:
    """Leg lengths of platform poses.

    Args:
        geometry: The robot.
        rotation: (..., 3, 3) orientation of the platform frame in the base frame.
        translation: (..., 3) position of the platform frame in the base frame [m].

    Returns:
        Leg lengths (..., 6) [m].
    """
    return np.linalg.norm(leg_vectors(geometry, rotation, translation), axis=-1)


def leg_directions(
    geometry: HexapodGeometry, rotation: np.ndarray, translation: np.ndarray
) -> np.ndarray:
    """Unit leg directions ``u_i`` in the base frame, (..., 6, 3)."""
    L = leg_vectors(geometry, rotation, translation)
    return L / np.linalg.norm(L, axis=-1, keepdims=True)


def inverse_jacobian(base_points: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Inverse Jacobian ``q_dot = J_inv tau`` (``docs/math.md`` section 3).

    Frame-agnostic: ``base_points`` and ``directions`` in any frame fixed to the
    base; the twist ``tau = (v, w)`` is then expressed in that frame, at its origin.

    Args:
        base_points: (..., 6, 3) ``A_i`` [m].
        directions: (..., 6, 3) unit ``u_i``.

    Returns:
        (..., 6, 6) matrices with rows ``[u_i^T, (A_i x u_i)^T]``.
    """
    A = np.asarray(base_points, dtype=float)
    u = np.asarray(directions, dtype=float)
    A = np.broadcast_to(A, u.shape)
    return np.concatenate([u, np.cross(A, u)], axis=-1)


@dataclass(frozen=True)
class LegState:
    """Legs expressed in one frame fixed to the base.

    Attributes:
        base_points: (..., 6, 3) ``A_i`` [m].
        directions: (..., 6, 3) unit ``u_i``.
        lengths: (..., 6) ``q_i`` [m].
    """

    base_points: np.ndarray
    directions: np.ndarray
    lengths: np.ndarray

    @property
    def inverse_jacobian(self) -> np.ndarray:
        """(..., 6, 6) inverse Jacobian in this frame."""
        return inverse_jacobian(self.base_points, self.directions)


def legs_in_frame(
    geometry: HexapodGeometry,
    rotation: np.ndarray,
    translation: np.ndarray,
    frame_from_base: Transform | None = None,
) -> LegState:
    """Base points, leg directions and lengths, expressed in a frame fixed to the base.

    Args:
        geometry: The robot.
        rotation: (..., 3, 3) platform orientation in the base frame.
        translation: (..., 3) platform position in the base frame [m].
        frame_from_base: Transform from the base frame to the target frame
            (e.g. ``camera_from_base``); identity when None.
    """
    L = leg_vectors(geometry, rotation, translation)
    q = np.linalg.norm(L, axis=-1)
    u = L / q[..., None]
    A = np.broadcast_to(geometry.base_points, u.shape)
    if frame_from_base is not None:
        A = frame_from_base.apply(A)
        u = frame_from_base.rotate(u)
    return LegState(np.array(A), u, q)


def twist_to_frame(twist: np.ndarray, frame_from_base: Transform) -> np.ndarray:
    """Express a twist given in the base frame (at its origin) in another fixed frame.

    Args:
        twist: (..., 6) ``(v, w)`` in ``b`` at the origin of ``b``.
        frame_from_base: Transform ``c_from_b``.

    Returns:
        (..., 6) ``(v, w)`` in ``c`` at the origin of ``c``.

    Raises:
        ShapeError: ``twist`` not (..., 6).
    """
    twist = np.asarray(twist, dtype=float)
    if twist.shape[-1:] != (6,):
        raise ShapeError("twist", "shape (..., 6): (v [m/s], w [rad/s])", twist.shape)
    R, p = frame_from_base.rotation, frame_from_base.translation
    w = twist[..., 3:] @ R.T
    v = twist[..., :3] @ R.T - np.cross(w, p)
    return np.concatenate([v, w], axis=-1)
