"""Batched SE(3) helpers (numpy): exponential map, pose integration, pose errors.

Twists follow ``docs/math.md`` section 2: ``(v, w)`` expressed in a fixed frame and
reduced at its origin, so that a point of the moving body has ``dP/dt = v + w x P``.
"""

from __future__ import annotations

import math

import numpy as np

from hexapod.exceptions import ShapeError

#: How far ``cos^2 + sin^2`` of the angle :func:`log_so3` reads from a matrix (its trace
#: and antisymmetric part) may be from 1: a hundred times the kinematics' tolerance
#: (:data:`hexapod.kinematics.ROTATION_TOLERANCE`, not imported: it imports this module),
#: so that products of rotations within it (pose errors) pass, while ``2 I``, a zero
#: matrix or most mirrors do not.
LOG_ROTATION_TOLERANCE = 1e-4


def skew(x: np.ndarray) -> np.ndarray:
    """Skew matrices ``[x]_x`` of vectors (..., 3) -> (..., 3, 3).

    Raises:
        ShapeError: ``x`` not (..., 3).
    """
    x = np.asarray(x, dtype=float)
    if x.shape[-1:] != (3,):
        raise ShapeError("x", "vectors of shape (..., 3)", x.shape)
    out = np.zeros((*x.shape[:-1], 3, 3))  # filled in place: no stacks (hot in CTC laws)
    out[..., 0, 1] = -x[..., 2]
    out[..., 0, 2] = x[..., 1]
    out[..., 1, 0] = x[..., 2]
    out[..., 1, 2] = -x[..., 0]
    out[..., 2, 0] = -x[..., 1]
    out[..., 2, 1] = x[..., 0]
    return out


def norms(x: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """Euclidean norms of float vectors (..., n) along the last axis: the bits of
    ``np.linalg.norm(x, axis=-1)`` (``sqrt`` of ``add.reduce`` of the squares), without
    its argument handling. Three-vectors (every camera noise, edge and pose error of
    the simulator, every period) are summed as numpy's reduction of three numbers does,
    ``(x0^2 + x1^2) + x2^2`` (``tests/hexapod/test_se3.py`` holds the two equal), in
    three passes instead of a reduction along a short axis (four times faster). A list (or
    an integer array) is read as floats.

    Raises:
        ShapeError: ``x`` a scalar, not vectors.
    """
    if not isinstance(x, np.ndarray) or x.dtype.kind in "biu":
        x = np.asarray(x, dtype=float)
    if x.ndim == 0:
        raise ShapeError("x", "vectors of shape (..., n)", "a scalar")
    if x.shape[-1:] != (3,):
        return np.sqrt(np.add.reduce(x * x, axis=-1, keepdims=bool(keepdims)))  # type: ignore[no-any-return,call-overload]
    out = x[..., 0] * x[..., 0]
    out += x[..., 1] * x[..., 1]
    out += x[..., 2] * x[..., 2]
    out = np.sqrt(out, out=out) if isinstance(out, np.ndarray) else np.sqrt(out)
    return out[..., None] if keepdims else out  # type: ignore[no-any-return]


def exp_so3(w: np.ndarray) -> np.ndarray:
    """Rotation matrices ``exp([w]_x)`` of rotation vectors (..., 3) [rad].

    ``I + a K + b K^2`` with ``K = [w]_x``, ``a = sin(theta) / theta`` and ``b = (1 -
    cos(theta)) / theta^2`` (their Taylor series below ``theta = 1e-6``), written into
    one array: the same operations, in the same order, as the textbook expression, so
    the same bits, with fewer temporaries (every trial-step's camera noise goes
    through it).

    Raises:
        ShapeError: ``w`` not (..., 3).
    """
    w = np.asarray(w, dtype=float)
    if w.shape[-1:] != (3,):
        raise ShapeError("w", "rotation vectors of shape (..., 3) [rad]", w.shape)
    theta = norms(w)
    K = skew(w)
    KK = K @ K
    small = theta < 1e-6
    if small.any():
        th = np.where(small, 1.0, theta)
        a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(th) / th)
        b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(th)) / th**2)
    else:  # the other branch of each where, on theta itself
        a = np.sin(theta) / theta
        b = (1.0 - np.cos(theta)) / theta**2
    out = np.multiply(np.asarray(a)[..., None, None], K, out=K)  # a K
    out += _EYE  # I + a K (addition commutes bit for bit)
    out += np.multiply(KK, np.asarray(b)[..., None, None], out=KK)  # + b K^2
    return out


#: The identity of :func:`exp_so3` (read only).
_EYE = np.eye(3)
_EYE.flags.writeable = False


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) [rad] of rotation matrices (..., 3, 3).

    The angle is read from the trace (its cosine) and the antisymmetric part (its sine);
    a matrix where the two are not the cosine and sine of one angle (``cos^2 + sin^2``
    further than :data:`LOG_ROTATION_TOLERANCE` from 1) is refused: checked on what the
    logarithm computes anyway, not a full :func:`rotation_defect` (a matrix product,
    slower than the logarithm). NaN passes through.

    Raises:
        ShapeError: ``R`` not (..., 3, 3), or not rotations (``2 I``, a zero matrix).
    """
    R = np.asarray(R, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise ShapeError("R", "rotation matrices of shape (..., 3, 3)", R.shape)
    # the trace as np.trace sums it, (R00 + R11) + R22, without its argument handling
    cos = (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0) / 2.0
    v = np.empty((*R.shape[:-2], 3))  # filled in place: no stack (every period's book)
    np.subtract(R[..., 2, 1], R[..., 1, 2], out=v[..., 0])
    np.subtract(R[..., 0, 2], R[..., 2, 0], out=v[..., 1])
    np.subtract(R[..., 1, 0], R[..., 0, 1], out=v[..., 2])
    # atan2(sin, cos) keeps full precision near 0 and pi, where arccos(cos) loses half
    # the digits (|v| = 2 sin(theta)).
    half = 0.5 * norms(v)  # sin(theta) of a rotation
    if not _on_unit_circle(cos, half):
        _refuse_non_rotation(R, cos, half)
    theta = np.arctan2(half, cos)
    sin = np.sin(theta)
    small = sin < 1e-6
    if small.any():
        factor = np.where(small, 0.5 + theta**2 / 12.0,
                          theta / (2.0 * np.where(small, 1.0, sin)))
    else:  # the other branch of the where, on sin itself
        factor = theta / (2.0 * sin)
    w = np.asarray(factor)[..., None] * v
    # Near pi: recover the axis from the symmetric part.
    near_pi = theta > np.pi - 1e-3
    if near_pi.any():
        Rn = R[near_pi]
        th = theta[near_pi]
        B = (Rn + np.swapaxes(Rn, -1, -2)) / 2.0 - np.cos(th)[..., None, None] * np.eye(3)
        idx = np.argmax(np.diagonal(B, axis1=-2, axis2=-1), axis=-1)
        axis = B[np.arange(len(idx)), idx]
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        sign = np.sign(np.sum(axis * v[near_pi], axis=-1))
        sign = np.where(sign == 0, 1.0, sign)
        w[near_pi] = axis * (th * sign)[..., None]
    return w


def _on_unit_circle(cos: np.ndarray, sin: np.ndarray) -> bool:
    """Whether every ``cos^2 + sin^2`` is within :data:`LOG_ROTATION_TOLERANCE` of 1 (NaN
    passes; one matrix in Python floats, ten times faster than numpy's scalars)."""
    if isinstance(cos, np.ndarray):
        dev = cos * cos
        dev += sin * sin
        dev -= 1.0
        return not bool((np.abs(dev, out=dev) > LOG_ROTATION_TOLERANCE).any())
    c, s = float(cos), float(sin)
    return not abs(c * c + s * s - 1.0) > LOG_ROTATION_TOLERANCE


def _refuse_non_rotation(R: np.ndarray, cos: np.ndarray, half: np.ndarray) -> None:
    """Raise :func:`log_so3`'s error for the matrix of ``R`` furthest from a rotation
    (``cos`` and ``half``: the cosines and sines read from their traces and antisymmetric
    parts; called once a matrix is known to be refused).

    Raises:
        ShapeError: Naming the matrix (its index in a batch), ``cos^2 + sin^2`` and its
            rotation defect.
    """
    circle = np.asarray(cos * cos + half * half)
    off = np.abs(circle - 1.0)
    i = np.unravel_index(int(np.argmax(np.where(np.isnan(off), -1.0, off))), off.shape)
    defect, det = rotation_defect(R[i])
    index = tuple(int(j) for j in i)
    where = "" if not index else f" (matrix {index[0] if len(index) == 1 else index})"
    raise ShapeError("R", "rotation matrices (R^T R = I, det = +1: not a scaled, sheared or "
                     "mirrored matrix)",
                     f"cos^2 + sin^2 of its angle = {float(circle[i]):.4g}, |R^T R - I| = "
                     f"{float(defect):.2e}, det {float(det):.4g}{where}")


def exp_se3(v: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exponential of twists ``(v, w)`` (..., 3) -> rotation (..., 3, 3), translation (..., 3).

    Raises:
        ShapeError: ``v`` or ``w`` not (..., 3).
    """
    v = np.asarray(v, dtype=float)
    w = np.asarray(w, dtype=float)
    if v.shape[-1:] != (3,) or w.shape[-1:] != (3,):
        raise ShapeError("twist", "v [m] and w [rad] of shape (..., 3)", (v.shape, w.shape))
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew(w)
    small = theta < 1e-6
    th = np.where(small, 1.0, theta)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(th)) / th**2)
    c = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (th - np.sin(th)) / th**3)
    V = np.eye(3) + b * K + c * (K @ K)
    return exp_so3(w), (V @ v[..., None])[..., 0]


def rotation_defect(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far matrices ``R`` (..., 3, 3) are from rotations: ``max |R^T R - I|`` and the
    determinant, each of shape ``(...)`` (NaN where ``R`` has a NaN). One matrix (the
    check of every pose given to the kinematics, and of a forward kinematics' warm start
    every servo period) is checked in Python floats: numpy's calls cost 6 us there, the
    solve they guard 11 us."""
    R = np.asarray(R, dtype=float)
    if R.size == 9 and R.shape[-2:] == (3, 3):
        defect, det = one_rotation_defect(R)
        shape = R.shape[:-2]
        return np.full(shape, defect), np.full(shape, det)
    gram = np.matmul(np.swapaxes(R, -1, -2), R)
    gram -= np.eye(3)
    return np.abs(gram).max(axis=(-2, -1)), np.linalg.det(R)


def one_rotation_defect(R: np.ndarray) -> tuple[float, float]:
    """:func:`rotation_defect` of one matrix (3, 3), in Python floats."""
    (a, b, c), (d, e, f), (g, h, i) = np.asarray(R, dtype=float).reshape(3, 3).tolist()
    defects = (abs(a * a + d * d + g * g - 1.0), abs(b * b + e * e + h * h - 1.0),
               abs(c * c + f * f + i * i - 1.0), abs(a * b + d * e + g * h),
               abs(a * c + d * f + g * i), abs(b * c + e * f + h * i))
    defect = math.nan if any(x != x for x in defects) else max(defects)
    return defect, a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def integrate_pose(
    rotation: np.ndarray, translation: np.ndarray, twist: np.ndarray, dt: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Move poses by a constant twist for ``dt`` (left multiplication by ``exp(twist dt)``).

    Args:
        rotation: (..., 3, 3) rotation of the body in the fixed frame.
        translation: (..., 3) position of the body origin in the fixed frame [m].
        twist: (..., 6) ``(v [m/s], w [rad/s])`` in the fixed frame, at its origin.
        dt: Duration [s].

    Returns:
        The new rotation and translation.

    Raises:
        ShapeError: A twist that is not (..., 6), a rotation not (..., 3, 3) or a
            translation not (..., 3).
    """
    twist = np.asarray(twist, dtype=float)
    rotation, translation = np.asarray(rotation, float), np.asarray(translation, float)
    if twist.shape[-1:] != (6,):
        raise ShapeError("twist", "shape (..., 6): (v [m/s], w [rad/s])", twist.shape)
    if rotation.shape[-2:] != (3, 3) or translation.shape[-1:] != (3,):
        raise ShapeError("pose", "rotation (..., 3, 3) and translation (..., 3)",
                         (rotation.shape, translation.shape))
    dt_arr = np.asarray(dt, dtype=float)[..., None]
    dR, dp = exp_se3(twist[..., :3] * dt_arr, twist[..., 3:] * dt_arr)
    return dR @ rotation, (dR @ translation[..., None])[..., 0] + dp


def pose_error(
    rotation: np.ndarray, translation: np.ndarray, rotation_ref: np.ndarray,
    translation_ref: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Position error [m] and rotation angle error [rad] between poses (batched)."""
    d = np.asarray(translation) - np.asarray(translation_ref)
    dp = norms(d) if d.dtype == np.float64 else np.linalg.norm(d, axis=-1)
    dR = np.swapaxes(rotation_ref, -1, -2) @ rotation
    ang = norms(log_so3(dR))
    return dp, ang


def rotation_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` [rad]."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Rotation of a camera frame (z forward, x right, y down) looking from eye to target.

    Args:
        eye: Position of the camera (3,) [m].
        target: Point it looks at (3,) [m].
        up: Direction that is up in the image (3,) (not along the viewing direction).

    Returns:
        ``base_R_camera``: columns are the camera axes in the base frame.

    Raises:
        ShapeError: ``eye``, ``target`` or ``up`` not (3,).
        ValueError: ``eye`` and ``target`` at the same place (or not finite), or ``up``
            parallel to the viewing direction.
    """
    eye_, target_ = np.asarray(eye, float), np.asarray(target, float)
    for name, value in (("eye", eye_), ("target", target_), ("up", np.asarray(up))):
        if value.shape != (3,):
            raise ShapeError(name, "a point or direction of shape (3,)", value.shape)
    z = target_ - eye_
    distance = np.linalg.norm(z)
    if not (distance > 0 and np.isfinite(distance)):
        problem = "coincide: no viewing direction" if distance == 0 else "must be finite"
        raise ValueError(f"look_at: eye {eye_.tolist()} and target {target_.tolist()} "
                         f"{problem}")
    z /= distance
    x = np.cross(z, np.asarray(up, float))  # right = forward x up (y = z x x points down)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: up vector parallel to the viewing direction")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-1)
