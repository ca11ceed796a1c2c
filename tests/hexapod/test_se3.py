"""Tests of hexapod.se3 against independent computations (matrix exponential, Pinocchio)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.linalg import expm

from hexapod.se3 import (
    exp_se3,
    exp_so3,
    integrate_pose,
    log_so3,
    look_at,
    one_rotation_defect,
    pose_error,
    rotation_defect,
    rotation_from_rpy,
    skew,
)


def _random_axes(rng: np.random.Generator, n: int) -> np.ndarray:
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_skew(rng: np.random.Generator) -> None:
    x, y = rng.normal(size=(2, 10, 3))
    np.testing.assert_allclose((skew(x) @ y[..., None])[..., 0], np.cross(x, y), atol=1e-15)
    np.testing.assert_array_equal(skew(x), -np.swapaxes(skew(x), -1, -2))


def test_exp_so3_matches_matrix_exponential(rng: np.random.Generator) -> None:
    angles = np.r_[0.0, 1e-9, 1e-7, 1e-6, 2e-6, 1e-3, rng.uniform(0, np.pi, 30), np.pi]
    w = _random_axes(rng, len(angles)) * angles[:, None]
    R = exp_so3(w)
    for k in range(len(w)):
        np.testing.assert_allclose(R[k], expm(skew(w[k])), atol=1e-14)


@pytest.mark.parametrize("delta", [0.0, 1e-12, 1e-9, 1e-7, 1e-5, 1e-4, 5e-4, 1e-3, 2e-3])
def test_log_exp_round_trip_near_pi(rng: np.random.Generator, delta: float) -> None:
    axes = _random_axes(rng, 50)
    theta = np.pi - delta
    w = axes * theta
    back = log_so3(exp_so3(w))
    assert np.linalg.norm(back, axis=1) == pytest.approx(np.full(50, theta), abs=1e-7)
    # At exactly pi the sign of the axis is ambiguous; compare rotations and the axis line.
    np.testing.assert_allclose(exp_so3(back), exp_so3(w), atol=1e-9)
    if delta >= 1e-7:
        np.testing.assert_allclose(back, w, atol=1e-6)


def test_log_exp_round_trip(rng: np.random.Generator) -> None:
    angles = np.r_[0.0, 1e-12, 1e-8, 1e-6, 1e-4, rng.uniform(0, np.pi - 0.01, 500)]
    w = _random_axes(rng, len(angles)) * angles[:, None]
    np.testing.assert_allclose(log_so3(exp_so3(w)), w, atol=1e-12)
    # Batched over several axes.
    np.testing.assert_allclose(log_so3(exp_so3(w[:500].reshape(5, 100, 3))),
                               w[:500].reshape(5, 100, 3), atol=1e-12)


def test_exp_se3_matches_matrix_exponential_and_pinocchio(rng: np.random.Generator) -> None:
    for scale in (1e-8, 1e-5, 0.1, 1.0, 3.0):
        v = rng.normal(size=3)
        w = _random_axes(rng, 1)[0] * min(scale, 3.0)
        R, p = exp_se3(v, w)
        X = np.zeros((4, 4))
        X[:3, :3] = skew(w)
        X[:3, 3] = v
        E = expm(X)
        np.testing.assert_allclose(R, E[:3, :3], atol=1e-13)
        np.testing.assert_allclose(p, E[:3, 3], atol=1e-13)
        M = pin.exp6(pin.Motion(v, w))
        np.testing.assert_allclose(R, M.rotation, atol=1e-13)
        np.testing.assert_allclose(p, M.translation, atol=1e-13)


def test_integrate_pose_left_multiplication(rng: np.random.Generator) -> None:
    R = exp_so3(rng.normal(size=(20, 3)))
    t = rng.normal(size=(20, 3))
    tw = rng.normal(size=(20, 6))
    dt = rng.uniform(0.01, 0.5, 20)
    R1, t1 = integrate_pose(R, t, tw, dt)
    for k in range(20):
        M = pin.exp6(pin.Motion(tw[k, :3] * dt[k], tw[k, 3:] * dt[k])) * pin.SE3(R[k], t[k])
        np.testing.assert_allclose(R1[k], M.rotation, atol=1e-13)
        np.testing.assert_allclose(t1[k], M.translation, atol=1e-13)
    # Points of the body move with dP/dt = v + w x P (MATH section 2).
    P_body = rng.normal(size=3)
    h = 1e-6
    Rp, tp = integrate_pose(R[0], t[0], tw[0], h)
    Rm, tm = integrate_pose(R[0], t[0], tw[0], -h)
    P = R[0] @ P_body + t[0]
    vel = ((Rp @ P_body + tp) - (Rm @ P_body + tm)) / (2 * h)
    np.testing.assert_allclose(vel, tw[0, :3] + np.cross(tw[0, 3:], P), atol=1e-8)


def test_pose_error(rng: np.random.Generator) -> None:
    R = exp_so3(rng.normal(size=3))
    t = rng.normal(size=3)
    dp, da = pose_error(R, t, R, t)
    assert dp == 0.0 and da == pytest.approx(0.0, abs=1e-7)
    axis = _random_axes(rng, 1)[0]
    dp, da = pose_error(R @ exp_so3(0.3 * axis), t + np.array([0.0, 0.004, 0.003]), R, t)
    assert dp == pytest.approx(0.005, abs=1e-15) and da == pytest.approx(0.3, abs=1e-12)


def test_rotation_from_rpy() -> None:
    R = rotation_from_rpy(0.1, -0.2, 0.3)
    np.testing.assert_allclose(
        R, exp_so3(np.array([0, 0, 0.3])) @ exp_so3(np.array([0, -0.2, 0]))
        @ exp_so3(np.array([0.1, 0, 0])), atol=1e-15)


def test_look_at() -> None:
    eye, target = np.array([0.7, 0.1, 0.3]), np.array([0.0, 0.0, 0.2])
    R = look_at(eye, target, np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)
    d = (target - eye) / np.linalg.norm(target - eye)
    np.testing.assert_allclose(R[:, 2], d, atol=1e-15)  # z forward
    assert R[2, 1] < 0  # image y points down (against "up")
    with pytest.raises(ValueError, match="parallel"):
        look_at(eye, eye + np.array([0, 0, 1.0]), np.array([0.0, 0.0, 1.0]))


@pytest.mark.parametrize("shape", [(3,), (1, 3), (7, 3), (2400, 3), (200, 6, 2, 3), (5, 4),
                                   (2, 1)])
def test_norms_are_numpys_norms_bit_for_bit(shape: tuple[int, ...]) -> None:
    """norms (the simulator's hot path: three-vectors summed in three passes) gives
    np.linalg.norm's bits, with and without keepdims, NaN and infinities included: the
    order of numpy's reduction of three numbers is what it relies on."""
    from hexapod.se3 import norms

    rng = np.random.default_rng(len(shape) + shape[0])
    for scale in (1e-160, 1e-3, 1.0, 1e150):
        x = rng.normal(size=shape) * scale
        x.reshape(-1)[:2] = [np.nan, np.inf] if x.size > 4 else x.reshape(-1)[:2]
        assert norms(x).tobytes() == np.linalg.norm(x, axis=-1).tobytes()
        assert norms(x, keepdims=True).tobytes() == np.linalg.norm(
            x, axis=-1, keepdims=True).tobytes()


@pytest.mark.parametrize("shape", [(3, 3), (1, 3, 3), (7, 3, 3), (200, 3, 3), (5, 4, 3, 3)])
def test_log_so3_sums_the_trace_as_numpy_does(shape: tuple[int, ...]) -> None:
    """log_so3 sums the diagonal itself (every period's pose error): the bits of
    ``np.trace``, which it relies on, for rotations and for any matrices."""
    rng = np.random.default_rng(shape[0])
    for M in (exp_so3(rng.normal(size=shape[:-1])), rng.normal(size=shape) * 1e3):
        diagonal = M[..., 0, 0] + M[..., 1, 1] + M[..., 2, 2]
        assert diagonal.tobytes() == np.trace(M, axis1=-2, axis2=-1).tobytes()


def test_integrate_pose_takes_lists_and_names_a_wrong_shape() -> None:
    """A list twist gave 'list indices must be integers or slices, not tuple', a (3,)
    twist an IndexError naming nothing."""
    import pytest

    from hexapod.exceptions import ShapeError
    from hexapod.se3 import integrate_pose

    R = integrate_pose(np.eye(3), [0.0, 0.0, 0.0], [0, 0, 0, 0, 0, 0.1], 0.02)[0]
    np.testing.assert_allclose(R, integrate_pose(np.eye(3), np.zeros(3),
                                                 np.array([0, 0, 0, 0, 0, 0.1]), 0.02)[0])
    with pytest.raises(ShapeError, match=r"twist: expected shape \(\.\.\., 6\)"):
        integrate_pose(np.eye(3), np.zeros(3), np.zeros(3), 0.02)


def test_helpers_name_a_wrong_shape_and_take_lists() -> None:
    """A (2,) rotation vector gave 'IndexError: index 2 is out of bounds', norms of a list
    'AttributeError: 'list' object has no attribute 'shape''."""
    from hexapod.exceptions import ShapeError
    from hexapod.se3 import norms

    with pytest.raises(ShapeError, match=r"^w: expected rotation vectors of shape \(\.\.\., 3\) "
                       r"\[rad\], got \(2,\)$"):
        exp_so3(np.array([0.1, 0.2]))
    with pytest.raises(ShapeError, match=r"^x: expected vectors of shape \(\.\.\., 3\), got "
                       r"\(4, 2\)$"):
        skew(np.zeros((4, 2)))
    with pytest.raises(ShapeError, match=r"^R: expected rotation matrices of shape "
                       r"\(\.\.\., 3, 3\), got \(3,\)$"):
        log_so3(np.eye(3)[0])
    with pytest.raises(ShapeError, match=r"^twist: expected v \[m\] and w \[rad\] of shape "
                       r"\(\.\.\., 3\), got \(\(2,\), \(3,\)\)$"):
        exp_se3(np.zeros(2), np.zeros(3))
    with pytest.raises(ShapeError, match=r"^x: expected vectors of shape"):
        norms(np.float64(3.0))
    assert norms([3.0, 4.0]) == 5.0 and norms([3.0, 4.0, 0.0]) == 5.0
    assert norms([[3, 4, 0], [0, 0, 2]]).tolist() == [5.0, 2.0]
    assert exp_so3([0.1, 0.2, 0.3]).tobytes() == exp_so3(np.array([0.1, 0.2, 0.3])).tobytes()


def test_log_so3_refuses_a_matrix_that_is_not_a_rotation(rng: np.random.Generator) -> None:
    """log_so3(2 I) returned [0, 0, 0]: the trace and the antisymmetric part it reads are
    not the cosine and sine of one angle."""
    from hexapod.exceptions import ShapeError
    from hexapod.se3 import LOG_ROTATION_TOLERANCE, norms

    with pytest.raises(ShapeError, match=r"^R: expected rotation matrices \(R\^T R = I, det = "
                       r"\+1: not a scaled, sheared or mirrored matrix\), got cos\^2 \+ sin\^2 "
                       r"of its angle = 6\.25, \|R\^T R - I\| = 3\.00e\+00, det 8$"):
        log_so3(2 * np.eye(3))
    batch = exp_so3(rng.normal(size=(4, 3)))
    batch[2] = 0.0
    with pytest.raises(ShapeError, match=r"of its angle = 0\.25, .* det 0 \(matrix 2\)$"):
        log_so3(batch)
    with pytest.raises(ShapeError, match=r"det -1$"):
        log_so3(np.diag([1.0, 1.0, -1.0]))  # a mirror
    # NaN passes through (a failed trial's pose), and so does the product of two rotations
    # each as far from one as the kinematics accepts (a pose error)
    assert np.isnan(log_so3(np.full((3, 3), np.nan))).all()
    from hexapod.kinematics import ROTATION_TOLERANCE

    assert LOG_ROTATION_TOLERANCE >= 10 * ROTATION_TOLERANCE
    for _ in range(200):
        a = exp_so3(rng.normal(size=3)) + rng.uniform(-1, 1, (3, 3)) * ROTATION_TOLERANCE / 2
        b = exp_so3(rng.normal(size=3)) + rng.uniform(-1, 1, (3, 3)) * ROTATION_TOLERANCE / 2
        assert np.isfinite(norms(log_so3(a.T @ b)))


def test_look_at_refuses_an_eye_on_the_target() -> None:
    """look_at(eye, eye, up) returned a NaN matrix with a RuntimeWarning."""
    from hexapod.exceptions import ShapeError

    eye = np.array([0.7, 0.1, 0.3])
    with pytest.raises(ValueError, match=r"^look_at: eye \[0\.7, 0\.1, 0\.3\] and target "
                       r"\[0\.7, 0\.1, 0\.3\] coincide: no viewing direction$"):
        look_at(eye, eye.copy(), np.array([0.0, 0.0, 1.0]))
    with pytest.raises(ShapeError, match=r"^up: expected a point or direction of shape \(3,\), "
                       r"got \(2,\)$"):
        look_at(eye, np.zeros(3), np.array([0.0, 1.0]))
    assert look_at([0.7, 0.1, 0.3], [0, 0, 0], [0, 0, 1]).tobytes() == look_at(
        eye, np.zeros(3), np.array([0.0, 0.0, 1.0])).tobytes()


def test_rotation_defect_of_one_matrix_is_the_batch_arithmetic(
        rng: np.random.Generator) -> None:
    """One matrix is checked in Python floats (a servo period's warm start): the same
    defect and determinant as the batched numpy path and ``np.linalg.det`` to rounding,
    for rotations, scaled, sheared and mirrored matrices, and NaN where the matrix has a
    NaN (the callers let a NaN pass to the solve that fails it)."""
    from scipy.spatial.transform import Rotation

    rotations = Rotation.random(8, random_state=1).as_matrix()
    cases = [*rotations, 1.01 * rotations[0], rotations[1] @ np.diag([1.0, 1.0, -1.0]),
             rotations[2] + 1e-3 * rng.normal(size=(3, 3)), np.zeros((3, 3)), 2 * np.eye(3)]
    batch_defect, batch_det = rotation_defect(np.array(cases))
    np.testing.assert_allclose(batch_det, np.linalg.det(np.array(cases)), rtol=0, atol=0)
    for k, R in enumerate(cases):
        defect, det = one_rotation_defect(R)
        assert defect == pytest.approx(float(batch_defect[k]), rel=1e-12, abs=1e-15)
        assert det == pytest.approx(float(np.linalg.det(R)), rel=1e-12, abs=1e-15)
        one, one_det = rotation_defect(R)  # the (3, 3) call goes through the same path
        assert one.shape == () and float(one) == defect and float(one_det) == det
        assert rotation_defect(R[None])[0].shape == (1,)
    nan = rotations[0].copy()
    nan[1, 2] = np.nan
    defect, det = one_rotation_defect(nan)
    assert np.isnan(defect) and np.isnan(det)
    assert np.isnan(rotation_defect(nan[None])[0][0])
