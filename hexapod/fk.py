"""Forward kinematics: leg lengths -> platform pose.

Two methods:

- ``"pinocchio"`` (reference, baseline): Gauss-Newton on the loop-closure
  residual of the closed-chain Pinocchio model (:mod:`hexapod.model`) with the
  prismatic joints fixed at the given lengths.
- ``"newton"`` (fast): Newton on the six length equations
  ``|R eB_i + t - A_i| = q_i``, with the iterations compiled as one CasADi
  function (``casadi.SX``; the PyPI ``pin`` wheel has no ``pinocchio.casadi``),
  mapped over a batch.

Both start from a guess (default: the home pose) and raise
:class:`~hexapod.exceptions.ForwardKinematicsError` rather than return garbage.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, Literal

import casadi as ca
import numpy as np

from hexapod.compiled import CompiledFunction, Layout
from hexapod.exceptions import ForwardKinematicsError, ShapeError, StrokeLimitError
from hexapod.geometry import HexapodGeometry
from hexapod.se3 import one_rotation_defect, rotation_defect
from hexapod.workspace import home_pose

if TYPE_CHECKING:  # Pinocchio (0.15 s to import) only for the "pinocchio" method
    from hexapod.model import HexapodModel

log = logging.getLogger(__name__)

#: Newton iterations unrolled in one call of the compiled CasADi function.
ITERATIONS_PER_CALL = 3
#: The Newton steps' input row: the guess ``R`` (column-major: the block's (3, 3) view is
#: ``R^T``) and ``t`` [m], the lengths ``q`` [m], the base and platform points (6 x 3) [m].
NEWTON_INPUTS = Layout([("R", (3, 3)), ("t", 3), ("q", 6), ("A", (6, 3)), ("E", (6, 3))],
                       "forward-kinematics Newton input")
#: Its output row: ``R`` (column-major) and ``t`` after the steps, the length residual.
NEWTON_OUTPUTS = Layout([("R", (3, 3)), ("t", 3), ("residual", 6)],
                        "forward-kinematics Newton output")
#: The pose (``R`` then ``t``: the same slice in and out), each output block's slice.
_POSE = slice(NEWTON_INPUTS["R"].start, NEWTON_INPUTS["t"].stop)
_R_OUT, _T_OUT, _RESIDUAL = (NEWTON_OUTPUTS[k] for k in ("R", "t", "residual"))
#: The input blocks a warm-started batch rewrites every call (:func:`set_guesses`).
_R_IN, _T_IN, _Q_IN = (NEWTON_INPUTS[k] for k in ("R", "t", "q"))

Method = Literal["newton", "pinocchio"]


@dataclass(frozen=True)
class ForwardKinematicsResult:
    """Result of one forward-kinematics solve.

    Attributes:
        rotation: (3, 3) platform orientation in the base frame.
        translation: (3,) platform position in the base frame [m].
        iterations: Newton / Gauss-Newton iterations made.
        residual: Max absolute residual at the solution [m] (length
            equations for ``newton``, loop closure for ``pinocchio``).
        method: The method used.
    """

    rotation: np.ndarray
    translation: np.ndarray
    iterations: int
    residual: float
    method: str


@dataclass(frozen=True)
class BatchForwardKinematicsResult:
    """Result of a batch of forward-kinematics solves (method ``newton``).

    Attributes:
        rotations: (N, 3, 3).
        translations: (N, 3) [m].
        residuals: (N,) max absolute length residual [m].
        converged: (N,) whether the residual reached the tolerance.
        iterations: Iterations made (the same for the whole batch).
    """

    rotations: np.ndarray
    translations: np.ndarray
    residuals: np.ndarray
    converged: np.ndarray
    iterations: int


@lru_cache(maxsize=1)
def _newton_expression() -> ca.Function:
    """CasADi function of ``ITERATIONS_PER_CALL`` Newton steps on the length equations.

    Input ``x`` (54): R (3x3, column-major), t (3), q (6), A (3x6 base points,
    column-major, i.e. point after point), E (3x6 platform points).
    Output ``y`` (18): R and t after the steps, and the residual
    ``|R E_i + t - A_i| - q_i`` (6) there.

    The unknowns are the translation and a rotation vector applied on the left
    of R; each step solves ``J step = -(lengths - q)`` with the 6x6 inverse
    Jacobian of the current estimate.
    """
    x = ca.SX.sym("x", NEWTON_INPUTS.size)
    v = NEWTON_INPUTS.split(x)
    R = ca.reshape(v["R"], 3, 3)
    t = v["t"]
    q = v["q"]
    A = ca.reshape(v["A"], 3, 6)
    E = ca.reshape(v["E"], 3, 6)

    def lengths_and_jacobian(R: ca.SX, t: ca.SX) -> tuple[ca.SX, ca.SX]:
        rows, lens = [], []
        for i in range(6):
            p = R @ E[:, i]  # platform point relative to the platform origin
            L = p + t - A[:, i]
            n = ca.sqrt(ca.dot(L, L))
            u = L / n
            lens.append(n)
            rows.append(ca.horzcat(u.T, ca.cross(p, u).T))
        return ca.vertcat(*lens), ca.vertcat(*rows)

    Rk, tk = R, t
    for _ in range(ITERATIONS_PER_CALL):
        lens, J = lengths_and_jacobian(Rk, tk)
        step = -ca.solve(J, lens - q)
        w = step[3:]
        theta = ca.fmax(ca.sqrt(ca.dot(w, w)), 1e-12)
        a = ca.sin(theta) / theta
        b = 2 * ca.sin(theta / 2) ** 2 / theta**2
        K = ca.skew(w)
        Rk = (ca.SX.eye(3) + a * K + b * (K @ K)) @ Rk
        tk = tk + step[:3]
    lens, _ = lengths_and_jacobian(Rk, tk)
    return ca.Function("hexapod_fk_newton", [x], [ca.vertcat(ca.reshape(Rk, 9, 1), tk, lens - q)])


def newton_function() -> ca.Function:
    """The (uncompiled) CasADi function of ``ITERATIONS_PER_CALL`` Newton steps, its
    layout as :func:`_newton_expression`, for composing into other functions."""
    return _newton_expression()


@lru_cache(maxsize=1)
def newton_kernel() -> CompiledFunction:
    """The Newton steps compiled to C (see :mod:`hexapod.compiled`)."""
    return CompiledFunction(_newton_expression(), inputs=NEWTON_INPUTS, outputs=NEWTON_OUTPUTS)


def _pack(R: np.ndarray, t: np.ndarray, q: np.ndarray, A: np.ndarray, E: np.ndarray
          ) -> np.ndarray:
    """Pack batched inputs (N, ...) into rows of :data:`NEWTON_INPUTS` (N, 54)."""
    x = np.empty((q.shape[0], NEWTON_INPUTS.size))
    v = NEWTON_INPUTS.views(x)
    v["R"][:] = np.swapaxes(R, -1, -2)  # (a column-major block: its view is R^T)
    v["t"][:] = t
    v["q"][:] = q
    v["A"][:] = A
    v["E"][:] = E
    return x


def _unpack(y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rotations (N, 3, 3), translations (N, 3) and residuals (N, 6) of output rows
    ``y`` (N, :data:`NEWTON_OUTPUTS`) (views; the slices are the layout's, looked up
    once: a per-period call)."""
    return (np.swapaxes(y[:, _R_OUT].reshape(-1, 3, 3), -1, -2), y[:, _T_OUT],
            y[:, _RESIDUAL])


def _check_lengths(geometry: HexapodGeometry, lengths: np.ndarray, check_stroke: bool) -> None:
    lo, hi = float(lengths.min()), float(lengths.max())
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise ShapeError("lengths", "finite leg lengths", lengths.tolist())
    if check_stroke and (lo < geometry.q_min - 1e-12 or hi > geometry.q_max + 1e-12):
        bad = np.argwhere((lengths < geometry.q_min - 1e-12) | (lengths > geometry.q_max + 1e-12))
        if len(bad):
            idx = tuple(bad[0])
            raise StrokeLimitError(int(idx[-1]), float(lengths[idx]), geometry.q_min,
                                   geometry.q_max)


def _guess(geometry: HexapodGeometry, guess: tuple[np.ndarray, np.ndarray] | None
           ) -> tuple[np.ndarray, np.ndarray]:
    if guess is None:
        return home_pose(geometry)
    R, t = (np.asarray(x, dtype=float) for x in guess)
    if R.shape != (3, 3) or t.shape != (3,):
        raise ShapeError("guess", "(rotation (3, 3), translation (3,))", (R.shape, t.shape))
    defect, det = one_rotation_defect(R)  # (every servo period's warm start: no arrays)
    if det <= 0 or defect > ORTHONORMAL_TOLERANCE:
        return proper_rotations(R[None], "guess")[0], t
    return R, t


#: How far a guess's ``R^T R`` may be from the identity before it is replaced by the
#: nearest rotation (a rotation of the project's own is within 1e-12).
ORTHONORMAL_TOLERANCE = 1e-9


def proper_rotations(R: np.ndarray, name: str) -> np.ndarray:
    """Guesses ``R`` (N, 3, 3) as rotations: a matrix that is not orthonormal (a pose
    read back rounded, a scaled one) is replaced by the nearest rotation (the Newton
    update ``exp(w) R`` keeps a guess's scale or shear, and the six lengths can then be
    matched by a pose that is no pose: millimetres off, reported converged); the others
    are returned as they are, bit for bit.

    Raises:
        ValueError: A guess is a reflection or singular (``det <= 0``), naming ``name``.
    """
    defect, det = rotation_defect(R)
    off = defect > ORTHONORMAL_TOLERANCE  # (NaN: no)
    if np.any(det <= 0):  # (a non-finite guess is left to the solve, which fails it)
        raise ValueError(f"{name}: a rotation guess with determinant {float(det.min()):.3g} "
                         "(a reflection or a singular matrix): give a rotation matrix")
    if not off.any():
        return R
    U, _, Vt = np.linalg.svd(R[off])
    out = np.array(R, dtype=float, copy=True)
    out[off] = U @ Vt
    return out


def forward_kinematics(
    geometry: HexapodGeometry,
    lengths: np.ndarray,
    guess: tuple[np.ndarray, np.ndarray] | None = None,
    method: Method = "newton",
    tol: float = 1e-12,
    max_iterations: int = 50,
    check_stroke: bool = True,
    model: HexapodModel | None = None,
) -> ForwardKinematicsResult:
    """Platform pose from leg lengths.

    Args:
        geometry: The robot.
        lengths: (6,) leg lengths [m].
        guess: Starting pose ``(rotation, translation)``; the home pose if None.
        method: ``"newton"`` (fast, CasADi) or ``"pinocchio"`` (reference).
        tol: Convergence threshold on the max absolute residual [m] (positive).
        max_iterations: Iteration budget (``newton``: whole calls of
            :data:`ITERATIONS_PER_CALL` = 3 Newton steps, the budget rounded up: 50
            allows 51).
        check_stroke: Refuse lengths outside the stroke.
        model: A prebuilt :class:`HexapodModel` (``pinocchio`` method), built if None.

    Returns:
        The pose, iterations and residual.

    Raises:
        StrokeLimitError: A length is outside the stroke.
        ForwardKinematicsError: No convergence within the budget, or a singular Jacobian.
    """
    q = np.asarray(lengths, dtype=float)
    if q.shape != (6,):
        raise ShapeError("lengths", "shape (6,)", q.shape)
    _check_budget(tol, max_iterations)
    _check_lengths(geometry, q, check_stroke)
    R0, t0 = _guess(geometry, guess)
    if method == "newton":
        return _fk_newton(geometry, q, R0, t0, tol, max_iterations)
    if method == "pinocchio":
        from hexapod.model import build_model

        return _fk_pinocchio(model or build_model(geometry), q, R0, t0, tol, max_iterations)
    raise ValueError(f"unknown forward-kinematics method {method!r}; use 'newton' or 'pinocchio'")


def _check_budget(tol: float, max_iterations: int) -> None:
    """Refuse a tolerance that is not a positive number (0 or NaN: a converged solve
    reported failed, residual 0) and a budget below one iteration."""
    if not (isinstance(tol, int | float) and math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol: must be a positive finite length [m], got {tol!r}")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, int | np.integer) \
            or max_iterations < 1:
        raise ValueError(f"max_iterations: must be an integer >= 1, got {max_iterations!r}")


def _fk_newton(geometry: HexapodGeometry, q: np.ndarray, R: np.ndarray, t: np.ndarray,
               tol: float, max_iterations: int) -> ForwardKinematicsResult:
    newton = newton_kernel()
    at = NEWTON_INPUTS.slices
    x = np.empty(NEWTON_INPUTS.size)
    x[at["R"]] = R.T.ravel()  # (column-major)
    x[at["t"]] = t
    x[at["q"]] = q
    x[at["A"]] = geometry.base_points.ravel()
    x[at["E"]] = geometry.platform_points.ravel()
    it = 0
    res = np.inf
    while it < max_iterations:  # (slices looked up once: a pose servo's hot loop)
        y = newton.single(x)
        it += ITERATIONS_PER_CALL
        res = float(np.abs(y[_RESIDUAL]).max())
        if not np.isfinite(res):
            raise ForwardKinematicsError("newton", res, it, "singular Jacobian on the way")
        if res < tol:
            return ForwardKinematicsResult(y[_R_OUT].reshape(3, 3).T, y[_T_OUT], it, res,
                                           "newton")
        x[_POSE] = y[_POSE]
    raise ForwardKinematicsError("newton", res, it, "no convergence within the iteration budget")


def forward_kinematics_batch(
    geometry: HexapodGeometry,
    lengths: np.ndarray,
    rotations: np.ndarray | None = None,
    translations: np.ndarray | None = None,
    tol: float = 1e-12,
    max_iterations: int = 30,
    base_points: np.ndarray | None = None,
    platform_points: np.ndarray | None = None,
) -> BatchForwardKinematicsResult:
    """Fast forward kinematics of a batch (the compiled CasADi Newton, looped in C).

    Never raises for a non-converged item: check ``converged``.

    Args:
        geometry: The robot (strokes are not checked here).
        lengths: (N, 6) leg lengths [m].
        rotations: (N, 3, 3) guesses (home pose if None).
        translations: (N, 3) guesses [m].
        tol: Convergence threshold [m] (positive).
        max_iterations: Iteration budget (whole calls of :data:`ITERATIONS_PER_CALL` = 3
            Newton steps, rounded up).
        base_points: Optional (N, 6, 3) per-item base points (overrides the geometry's).
        platform_points: Optional (N, 6, 3) per-item platform points.
    """
    q = np.asarray(lengths, dtype=float)
    if q.ndim != 2 or q.shape[1] != 6:
        raise ShapeError("lengths", "shape (N, 6)", q.shape)
    _check_budget(tol, max_iterations)
    n = q.shape[0]
    if (rotations is None) != (translations is None):  # (one alone was dropped silently)
        raise ValueError(f"{'translations' if translations is None else 'rotations'}: "
                         "missing; give both guesses, or neither (the home pose)")
    if rotations is None or translations is None:
        R0, t0 = home_pose(geometry)
        rotations = np.broadcast_to(R0, (n, 3, 3))
        translations = np.broadcast_to(t0, (n, 3))
    points = {}
    for name, given, own in (("base_points", base_points, geometry.base_points),
                             ("platform_points", platform_points, geometry.platform_points)):
        points[name] = own if given is None else np.asarray(given, float)
        if points[name].shape not in ((6, 3), (n, 6, 3)):
            raise ShapeError(name, f"shape (6, 3) or ({n}, 6, 3)", points[name].shape)
    R, t = np.asarray(rotations, float), np.asarray(translations, float)
    if R.shape != (n, 3, 3) or t.shape != (n, 3):
        raise ShapeError("rotations/translations", f"shapes ({n}, 3, 3) and ({n}, 3)",
                         f"{R.shape} and {t.shape}")
    x = pack_rows(proper_rotations(R, "rotations"), t, q, points["base_points"],
                  points["platform_points"])
    return solve_rows(x, tol, max_iterations)


def pack_rows(R: np.ndarray, t: np.ndarray, q: np.ndarray, A: np.ndarray, E: np.ndarray
              ) -> np.ndarray:
    """The (N, 54) input rows of :func:`solve_rows`: guesses ``R`` (N, 3, 3) and ``t``
    (N, 3) [m], lengths ``q`` (N, 6) [m], base and platform points ``A``, ``E`` ((6, 3)
    or (N, 6, 3)) [m]. A caller that solves the same robots again and again packs once
    and rewrites the guesses and lengths (:func:`set_guesses`)."""
    return _pack(R, t, q, A, E)


def set_guesses(x: np.ndarray, R: np.ndarray, t: np.ndarray, q: np.ndarray) -> None:
    """Rewrite the guesses ``R`` (n, 3, 3), ``t`` (n, 3) [m] and the lengths ``q`` (n, 6)
    [m] of packed rows ``x`` (n, 54) (:func:`pack_rows`) in place."""
    x[:, _R_IN] = np.swapaxes(R, -1, -2).reshape(len(x), 9)  # (column-major blocks)
    x[:, _T_IN] = t
    x[:, _Q_IN] = q


def solve_rows(x: np.ndarray, tol: float = 1e-12, max_iterations: int = 30
               ) -> BatchForwardKinematicsResult:
    """:func:`forward_kinematics_batch` on packed rows (:func:`pack_rows`; changed in
    place)."""
    n = x.shape[0]
    newton = newton_kernel()
    it = 0
    res = np.full(n, np.inf)
    active = np.arange(n)
    pose, residual = _POSE, _RESIDUAL
    y_all = np.empty((n, NEWTON_OUTPUTS.size))
    y_all[:, pose] = x[:, pose]
    y_all[:, residual] = np.inf
    while it < max_iterations and len(active):
        every = len(active) == n  # (the first call: slices, not index copies)
        y = newton.batch(x if every else x[active])
        it += ITERATIONS_PER_CALL
        r = np.max(np.abs(y[:, residual]), axis=1)
        if every:
            y_all[:] = y
            res[:] = r
            x[:, pose] = y[:, pose]
        else:
            y_all[active] = y
            res[active] = r
            x[active, pose] = y[:, pose]
        keep = np.isfinite(r) & (r >= tol)
        active = active[keep]
    rot, trans, _ = _unpack(y_all)
    converged = np.isfinite(res) & (res < tol)
    return BatchForwardKinematicsResult(rot, trans.copy(), res, converged, it)


def _fk_pinocchio(hm: HexapodModel, q: np.ndarray, R: np.ndarray, t: np.ndarray,
                  tol: float, max_iterations: int) -> ForwardKinematicsResult:
    """Gauss-Newton on the loop-closure constraints with the prismatic joints fixed."""
    import pinocchio as pin

    from hexapod.model import constraint_residual_and_jacobian

    model = hm.model
    x = hm.configuration(R, t)
    x[hm.prismatic_q_indices()] = q
    free = np.setdiff1d(np.arange(model.nv), hm.prismatic_v_indices())
    res = np.inf
    for it in range(1, max_iterations + 1):
        r, J = constraint_residual_and_jacobian(hm, x)
        res = float(np.max(np.abs(r)))
        if not np.isfinite(res):
            raise ForwardKinematicsError("pinocchio", res, it, "non-finite residual")
        if res < tol:
            Rr, tr = hm.platform_pose(x)
            return ForwardKinematicsResult(Rr, tr, it - 1, res, "pinocchio")
        Jf = J[:, free]
        dv_free, *_ = np.linalg.lstsq(Jf, -r, rcond=1e-12)
        dv = np.zeros(model.nv)
        dv[free] = dv_free
        x = pin.integrate(model, x, dv)
    raise ForwardKinematicsError("pinocchio", res, max_iterations,
                                 "no convergence within the iteration budget")
