"""The pieces the control laws are built from (``docs/math.md`` section 6): observation
checks, option checks, the constant or adaptive :class:`Gain`, and what a law gives its
compiled core (:class:`Selection`) and its solver (:class:`TaskStep`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.base import Observation, observation_problem
from controllers.data import FEATURE_FIELDS
from controllers.exceptions import ContextError, OptionError
from controllers.plausible import MILLIMETRES, implausible_lengths

#: Where the interaction matrix is evaluated (ViSP's CURRENT, DESIRED, MEAN).
INTERACTIONS = ("current", "desired", "mean")


# --------------------------------------------------------------------------- observations
def check_observation(obs: Observation, features: frozenset[str]) -> str | None:
    """:func:`controllers.base.observation_problem`, with a fast path.

    The common cases (float arrays of the right shapes, everything visible and
    finite, or the visible features finite) are recognised with a few calls: a finite
    sum means finite entries. Any other observation gets the full check and its reason.
    """
    try:
        q = obs.lengths
        if (type(q) is np.ndarray and q.shape == (6,) and math.isfinite(obs.t)
                and math.isfinite(q.sum())):
            for name, shape, mask in FEATURE_FIELDS:
                if name not in features:
                    continue
                arr = getattr(obs, name)
                if not (type(arr) is np.ndarray and arr.shape == shape
                        and arr.dtype == np.float64):
                    break
                seen = getattr(obs, mask)
                if not (math.isfinite(arr.sum()) and seen.all()) and not (
                        type(seen) is np.ndarray and seen.dtype == np.bool_
                        and seen.shape == shape[:-1] and np.isfinite(arr[seen]).all()):
                    break  # (a hidden feature's values may be anything)
            else:
                return None
    except (TypeError, ValueError, AttributeError):
        pass
    return observation_problem(obs, features)


# --------------------------------------------------------------------------- options
def check_number(controller: str, option: str, value: Any, minimum: float = 0.0,
                 strict: bool = True) -> float:
    """Validate a finite number above ``minimum``.

    Raises:
        OptionError: Not a finite number, or out of range.
    """
    if isinstance(value, bool | str):  # (a quoted number in a file is a mistake too)
        raise OptionError(controller, option, f"expected a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise OptionError(controller, option, f"expected a number, got {value!r}") from None
    if not math.isfinite(x):
        raise OptionError(controller, option, f"must be finite, got {x}")
    if (strict and x <= minimum) or (not strict and x < minimum):
        raise OptionError(controller, option,
                          f"must be {'>' if strict else '>='} {minimum}, got {x}")
    return x


def check_flag(controller: str, option: str, value: Any) -> bool:
    """Validate a boolean option (``true``/``false`` in a file): a string such as
    ``"false"`` is refused (Python's ``bool("false")`` is True).

    Raises:
        OptionError: Not a boolean.
    """
    if not isinstance(value, bool | np.bool_):
        raise OptionError(controller, option, f"expected true or false, got {value!r}")
    return bool(value)


def check_count(controller: str, option: str, value: Any, minimum: int,
                maximum: int | None = None) -> int:
    """Validate an integer from ``minimum`` to ``maximum`` (None: no upper bound).

    Raises:
        OptionError: Not an integer (a bool is not one), or out of range.
    """
    if (isinstance(value, bool) or not isinstance(value, int) or value < minimum
            or (maximum is not None and value > maximum)):
        bound = f">= {minimum}" if maximum is None else f"from {minimum} to {maximum}"
        raise OptionError(controller, option, f"expected an integer {bound}, got {value!r}")
    return value


def check_weights(controller: str, first: tuple[str, Any], second: tuple[str, Any],
                  why: str) -> tuple[float, float]:
    """Validate two weights ``(option, value)``: finite, >= 0, not both 0.

    Raises:
        OptionError: A weight is not a finite number >= 0, or both are 0 (naming the
            first, with ``why``).
    """
    a = check_number(controller, first[0], first[1], 0.0, strict=False)
    b = check_number(controller, second[0], second[1], 0.0, strict=False)
    if a == 0 and b == 0:
        raise OptionError(controller, first[0], f"{first[0]} and {second[0]} are both 0 "
                          f"({why})")
    return a, b


#: The spread of the estimated base points may differ from the nominal geometry's by
#: this factor (a calibration error changes it by a few per cent; a unit slip by 1000).
BASE_SPREAD_FACTOR = 2.0
#: The 15 pairs of six points.
_PAIRS = tuple((i, j) for i in range(6) for j in range(i + 1, 6))


def base_points_of(controller: str, context: Any) -> np.ndarray:
    """``context.base_points``, the estimated base points ``A_i`` in the camera frame
    (6, 3) [m], checked against the nominal geometry and the estimated camera pose.

    Two slips a calibration error cannot explain are refused: points whose spread (the
    median of their distances to each other over the nominal ones) is off by more than
    :data:`BASE_SPREAD_FACTOR` (millimetres: 1000), and, with a camera pose, points
    nearer the nominal ones in the BASE frame than the nominal ones seen through the
    camera (``camera_from_base``): the base frame given for the camera frame.

    Raises:
        ContextError: Not (6, 3) finite, or one of the slips above (with the figures).
    """
    A = np.asarray(context.base_points, dtype=float)
    # in Python floats (every trial's reset: numpy's calls on six points cost 40 us)
    points = A.tolist()
    if A.shape != (6, 3) or not all(math.isfinite(x) for p in points for x in p):
        raise ContextError(controller, "base_points",
                           f"expected 6x3 finite values [m], got shape {A.shape}"
                           + ("" if A.shape != (6, 3) else " with a value not finite"))
    nominal = np.asarray(context.geometry.base_points, dtype=float)
    nominals = nominal.tolist()
    spread = sorted(math.dist(points[i], points[j]) / math.dist(nominals[i], nominals[j])
                    for i, j in _PAIRS)[7]  # the median of the 15 ratios
    if not 1.0 / BASE_SPREAD_FACTOR <= spread <= BASE_SPREAD_FACTOR:
        hint = MILLIMETRES if 500.0 <= spread <= 2000.0 else ""
        raise ContextError(controller, "base_points",
                           f"the points are {spread:.4g} times as far apart as the nominal "
                           f"geometry's base points{hint}")
    pose = getattr(getattr(context, "camera", None), "camera_from_base", None)
    if pose is not None:
        seen = np.asarray(pose.rotation, dtype=float) @ nominal.T
        seen = (seen.T + np.asarray(pose.translation, dtype=float)).tolist()
        off_camera = max(math.dist(p, q) for p, q in zip(points, seen, strict=True))
        off_base = max(math.dist(p, q) for p, q in zip(points, nominals, strict=True))
        if off_base < 0.5 * off_camera:
            raise ContextError(
                controller, "base_points",
                f"in the base frame? They are within {off_base * 1e3:.1f} mm of the nominal "
                f"base points in the base frame but {off_camera * 1e3:.1f} mm from those "
                "seen through the estimated camera pose; give them in the CAMERA frame "
                "(camera.camera_from_base.apply(points))")
    return A


def goal_lengths(controller: str, goal: Any, stroke: tuple[float, float] | None = None
                 ) -> np.ndarray:
    """``goal.lengths`` checked: a copy (6,) [m].

    Args:
        controller: The controller's name, for the error.
        goal: The goal.
        stroke: The nominal robot's ``(q_min, q_max)`` [m]: lengths no leg of it can have
            are refused (:func:`controllers.plausible.implausible_lengths`; None: not
            checked).

    Raises:
        ContextError: Missing, not 6 positive finite lengths, or not lengths of the robot.
    """
    if goal.lengths is None:
        raise ContextError(controller, "goal.lengths", "missing")
    qs = np.array(goal.lengths, dtype=float)
    if qs.shape != (6,) or not np.all(np.isfinite(qs)) or np.any(qs <= 0):
        raise ContextError(controller, "goal.lengths",
                           f"expected 6 positive finite lengths, got {qs}")
    if stroke is not None and (problem := implausible_lengths(qs, stroke)) is not None:
        raise ContextError(controller, "goal.lengths", problem)
    return qs


def goal_directions(controller: str, goal: Any) -> tuple[np.ndarray, np.ndarray]:
    """``goal.directions`` checked: (6, 3) unit vectors, the non-finite (hidden) ones
    replaced by ``+z`` (keeps the arithmetic finite), and (6,) which were finite.

    Raises:
        ContextError: Missing, not (6, 3), none finite, or a finite one not of unit norm.
    """
    if goal.directions is None:
        raise ContextError(controller, "goal.directions", "missing")
    us = np.asarray(goal.directions, dtype=float)
    if us.shape != (6, 3):
        raise ContextError(controller, "goal.directions", f"expected shape (6, 3), got {us.shape}")
    vis = np.all(np.isfinite(us), axis=1)
    if not vis.any():
        raise ContextError(controller, "goal.directions", "no finite desired direction")
    us = np.where(vis[:, None], us, np.array([0.0, 0.0, 1.0]))
    norms = np.linalg.norm(us[vis], axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-6):
        raise ContextError(controller, "goal.directions", f"not unit vectors: norms {norms}")
    return us, vis


def check_choice(controller: str, option: str, value: Any, choices: Sequence[str]) -> str:
    """Validate a string option against its choices (suggesting the closest).

    Raises:
        OptionError: Not one of ``choices``.
    """
    from hexapod.config import suggest

    if not isinstance(value, str) or value not in choices:
        hint = suggest(str(value), choices)
        raise OptionError(controller, option,
                          f"expected one of {', '.join(choices)}, got {value!r}"
                          + (f" (did you mean '{hint}'?)" if hint else ""))
    return value


def _select(condition: Any, if_true: Any, if_false: Any) -> Any:
    return if_true if condition else if_false


def gain_formula(x: Any, at_zero: Any, at_infinity: Any, slope_at_zero: Any,
                 exp: Callable[[Any], Any] = math.exp,
                 select: Callable[[Any, Any, Any], Any] = _select) -> Any:
    """The adaptive gain [1/s] of the error size ``x = |e|_inf``, its one definition
    (:class:`Gain`'s attributes; ``docs/math.md`` section 6): ``lambda(x) = d
    exp(-lambda0' x / d) + lambda_inf``, ``d = lambda0 - lambda_inf`` (``lambda0`` when
    ``d = 0``). On numbers by default; on CasADi expressions with ``exp=ca.exp,
    select=ca.if_else`` (the compiled cores)."""
    d = at_zero - at_infinity
    return select(d == 0, at_zero,
                  d * exp(((-slope_at_zero) * x) / select(d == 0, 1.0, d)) + at_infinity)


@dataclass(frozen=True)
class Gain:
    """Constant (``at_zero == at_infinity``) or adaptive gain (ViSP's ``vpAdaptiveGain``):
    :func:`gain_formula` of ``x = |e|_inf``.

    Attributes:
        at_zero: ``lambda0``, gain for a vanishing error [1/s].
        at_infinity: ``lambda_inf``, gain for a large error [1/s].
        slope_at_zero: ``lambda0'``, slope of ``lambda(x)`` at ``x = 0`` (its
            opposite) [1/s per unit of error].
    """

    at_zero: float
    at_infinity: float
    slope_at_zero: float = 0.0

    def __call__(self, x: float) -> float:
        """Gain [1/s] for the error size ``x = |e|_inf`` (:func:`gain_formula`)."""
        return float(gain_formula(x, self.at_zero, self.at_infinity, self.slope_at_zero))

    @staticmethod
    def from_options(controller: str, gain: Any = 1.0,
                     adaptive_gain: Sequence[float] | None = None) -> Gain:
        """Build and validate a gain from the controller options.

        Args:
            controller: Controller name (for error messages).
            gain: Constant gain [1/s] (> 0), used when ``adaptive_gain`` is None.
            adaptive_gain: ``(lambda0, lambda_inf, lambda0')`` with
                ``lambda0 >= lambda_inf > 0`` and ``lambda0' > 0``.

        Raises:
            OptionError: Naming the option at fault.
        """
        value = check_number(controller, "gain", gain)  # checked when replaced too
        if adaptive_gain is None:
            return Gain(value, value, 0.0)
        try:
            if any(isinstance(x, str | bool) for x in adaptive_gain):  # ("5" was taken)
                raise TypeError
            values = [float(x) for x in adaptive_gain]
        except (TypeError, ValueError):
            raise OptionError(controller, "adaptive_gain",
                              f"expected (lambda0, lambda_inf, lambda0'), got {adaptive_gain!r}"
                              ) from None
        if len(values) != 3:
            raise OptionError(controller, "adaptive_gain",
                              f"expected 3 values (lambda0, lambda_inf, lambda0'), got "
                              f"{len(values)}")
        l0, linf, slope = values
        if not all(math.isfinite(v) for v in values):
            raise OptionError(controller, "adaptive_gain", f"values must be finite: {values}")
        if not linf > 0:
            raise OptionError(controller, "adaptive_gain", f"lambda_inf must be > 0, got {linf}")
        if l0 < linf:
            raise OptionError(controller, "adaptive_gain",
                              f"lambda0 ({l0}) must be >= lambda_inf ({linf})")
        if not slope > 0:
            raise OptionError(controller, "adaptive_gain", f"lambda0' must be > 0, got {slope}")
        return Gain(l0, linf, slope)


# --------------------------------------------------------------------------- the law
@dataclass
class Selection:
    """What a :class:`~controllers.laws.VisionLaw` gives its compiled core when a feature
    is hidden (now or in the goal).

    Attributes:
        features: (m, 3) the measured features, a finite fill value where hidden.
        used: (m,) bool, the features used this step (weight 1; the others weight 0).
        measured: (6,) bool, legs whose direction the core takes from this step's
            features.
        leg_directions: (6, 3) the directions of the other legs (dead-reckoned or
            approximated; NaN when unknown: the law then asks the nominal model).
        notes: Diagnostics to report.
    """

    features: np.ndarray
    used: np.ndarray
    measured: np.ndarray
    leg_directions: np.ndarray
    notes: list[str]


@dataclass(slots=True)
class TaskStep:
    """The stacked tasks of one period, as a solver takes them
    (:meth:`~controllers.laws.VisionLaw.tasks`).

    Attributes:
        error: (m,) stacked error ``e`` of the used features.
        error_norm: ``|e|``.
        normal: (6, 6) ``L^T L`` of the stacked interaction matrix ``L``.
        gradient: (6,) ``L^T e``.
        gain: ``lambda(|e|_inf)`` [1/s].
        inverse_jacobian: (6, 6) ``J_inv`` at the directions of ``estimate.in_use``.
        notes: Diagnostics (features used, predicted or approximated directions).
        compiled: The compiled core's :class:`~controllers.law_kernel.LawResult`.
    """

    error: np.ndarray
    error_norm: float
    normal: np.ndarray
    gradient: np.ndarray
    gain: float
    inverse_jacobian: np.ndarray
    notes: list[str]
    compiled: Any
