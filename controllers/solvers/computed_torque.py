"""The computed-torque solver: a task's second-order error dynamics, linearised by the
nominal inverse dynamic model, to leg forces.

For a task with error ``e`` (m,), Jacobian ``L`` (m, 6) with respect to the platform
twist ``tau`` and second-order term ``L_dot tau`` (:mod:`controllers.tasks`), tracking a
reference that moves on its own, the error's derivatives are

``e_dot = L tau + e_t``,  ``e_ddot = L tau_dot + L_dot tau + e_tt``

with ``e_t`` and ``e_tt`` what the reference's motion alone adds (for an error
``e = s - s*``: ``e_t = -s*_dot``, ``e_tt = -s*_ddot``; the tasks give them analytically,
:meth:`controllers.tasks.Task.reference_terms`). The laws ask for
``e_ddot = -2 zeta omega_n e_dot - omega_n^2 e``:

``tau_dot = L^+ (-2 zeta omega_n e_dot - omega_n^2 e - L_dot tau - e_tt)``

(least squares over the rows given, refused when ``L`` loses rank; inside their compiled
steps, :mod:`controllers.solvers.compiled_ctc` and
:mod:`controllers.solvers.compiled_task_ctc`), then the leg forces

``f = DynamicModel.inverse(R, t, tau, tau_dot) + m_r a + c q_dot + f_c tanh(v_ref / v_s)``

(:func:`drive_forces`: the nominal drives' reflected rotor inertia at the leg
acceleration ``a = K tau_dot + K_dot tau``, viscous and Coulomb friction). With an exact
model and a square, full-rank ``L`` the error obeys the designed second-order response.

Twists: the solver works in the dynamic model's coordinates (``docs/math.md`` section
11: base frame, ``v = dt/dt`` the platform origin's velocity). A task written in another
frame with the spatial twist of :mod:`controllers.tasks` (``B_dot = v + w x B``, e.g.
the camera frame) is brought to them by :func:`task_in_model_twist`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from controllers.law_tools import check_number
from controllers.solvers.saturation import checked_strategy, saturated
from hexapod.dynamics import DynamicModel
from hexapod.dynamics.drive_model import COULOMB_SMOOTHING
from hexapod.kinematics import Transform
from hexapod.se3 import skew


@dataclass(frozen=True)
class SecondOrderGains:
    """``e_ddot + 2 zeta omega_n e_dot + omega_n^2 e = 0``.

    Attributes:
        natural_frequency: ``f_n`` [Hz].
        damping: ``zeta``.
    """

    natural_frequency: float
    damping: float

    @staticmethod
    def checked(controller: str, natural_frequency: float, damping: float
                ) -> SecondOrderGains:
        """Validated gains.

        Raises:
            OptionError: Naming the option that is not a positive, finite number.
        """
        return SecondOrderGains(check_number(controller, "natural_frequency", natural_frequency),
                                check_number(controller, "damping", damping))

    @property
    def omega(self) -> float:
        """``omega_n`` [rad/s]."""
        return 2 * math.pi * self.natural_frequency

    @property
    def kp(self) -> float:
        """``omega_n^2`` [1/s^2]."""
        return self.omega**2

    @property
    def kd(self) -> float:
        """``2 zeta omega_n`` [1/s]."""
        return 2 * self.damping * self.omega


def checked_integral_gain(controller: str, integral_gain: float) -> float:
    """A validated integral gain ``Ki`` [1/s] (0: no integral action).

    Raises:
        OptionError: Naming the option when it is not a finite number >= 0.
    """
    return check_number(controller, "integral_gain", integral_gain, 0.0, strict=False)


class ComputedTorqueSolver:
    """Second-order task dynamics to leg forces (see the module docstring): the gains
    and the rank threshold of a law's compiled solve, and the forces of a platform
    acceleration.

    Args:
        gains: The designed error dynamics.
        threshold: Relative singular-value threshold of the rank test.
    """

    def __init__(self, gains: SecondOrderGains, threshold: float = 1e-6) -> None:
        self.gains = gains
        self.threshold = float(threshold)

    @staticmethod
    def forces(model: DynamicModel, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
               acc: np.ndarray, q_dot: np.ndarray, coulomb_velocity: np.ndarray | None = None,
               hold: float = 0.0, inverse_jacobian: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """Leg forces [N] of the platform acceleration, and the leg acceleration [m/s^2].

        Args:
            model: The NOMINAL dynamic model (its geometry's drives).
            R, t: Platform pose (base frame) [-, m].
            twist: (6,) model twist.
            acc: (6,) platform acceleration.
            q_dot: (6,) measured leg velocities [m/s].
            coulomb_velocity: (6,) the leg velocities whose sign the Coulomb friction
                takes [m/s]; None: the velocity the legs reach over ``hold`` at the
                commanded acceleration, ``q_dot + hold a``.
            hold: Time the force is held (the control period) [s].
            inverse_jacobian: ``K`` (6, 6) at the pose when already known.
        """
        K = inverse_jacobian if inverse_jacobian is not None else model.terms_batch(
            R[None], t[None], twist[None])[2][0]
        bias = model.legs_batch(R[None], t[None], twist[None])[1][0]
        a = K @ acc + bias
        v = q_dot + hold * a if coulomb_velocity is None else coulomb_velocity
        f = model.inverse(R, t, twist, acc) + drive_forces(model, a, q_dot, v)
        return f, a


class CTCOptions:
    """The checked options of a computed-torque law: its error dynamics, integral action
    and saturation strategy, and the solver they give.

    Args:
        controller: The law's name (named by a refusal of an option).
        natural_frequency: ``f_n`` [Hz] of the error's second-order response.
        damping: Its damping ratio ``zeta``.
        integral_gain: Integral action ``Ki`` [1/s] (0: none).
        saturation: Forces over the drives' limit: "clip", "scale" or "qp"
            (:mod:`controllers.solvers.saturation`).

    Raises:
        OptionError: Naming the option that is not valid.
    """

    def __init__(self, controller: str, natural_frequency: float, damping: float,
                 integral_gain: float, saturation: str) -> None:
        self.gains = SecondOrderGains.checked(controller, natural_frequency, damping)
        self.integral_gain = checked_integral_gain(controller, integral_gain)
        self.saturation = checked_strategy(controller, saturation)
        self.solver = ComputedTorqueSolver(self.gains)

    def saturated(self, forces: np.ndarray, limit: np.ndarray,
                  bias: Callable[[], np.ndarray]) -> np.ndarray:
        """The forces [N] commanded for the law's ``forces`` (6,) over a limit ``limit``
        (6,) [N] under the strategy; ``bias()`` gives the forces at zero acceleration
        (called for ``"qp"`` only)."""
        return saturated(self.saturation, forces, limit,
                         bias() if self.saturation == "qp" else None)


def drive_forces(model: DynamicModel, a: np.ndarray, q_dot: np.ndarray,
                 coulomb_velocity: np.ndarray) -> np.ndarray:
    """The nominal drives' share [N]: reflected rotor inertia at the leg acceleration
    ``a``, viscous friction at the measured leg velocity, Coulomb friction in the
    direction of ``coulomb_velocity`` (a reference's: at rest the measured velocity's
    sign is noise, and a held force must break away)."""
    d = model.geometry.drives
    return (np.asarray(d.rotor_inertia) * a + np.asarray(d.viscous) * q_dot  # type: ignore[no-any-return]
            + np.asarray(d.coulomb) * np.tanh(coulomb_velocity / COULOMB_SMOOTHING))


def task_in_model_twist(jacobian: np.ndarray, translation: np.ndarray, twist: np.ndarray,
                        frame_from_base: Transform | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A task written with the spatial twist of its frame, in model coordinates.

    The spatial twist of the task's frame is ``tau_s = G tau`` with
    ``G = Ad(frame_from_base) [[I, [t]_x], [0, I]]`` (the base frame's spatial velocity
    ``v_s = v - w x t``, then the adjoint of the frame), so ``L_model = L G`` and
    ``e_ddot`` gains ``L G_dot tau`` with ``G_dot tau = Ad (v x w, 0)``.

    Args:
        jacobian: (m, 6) ``L`` of the task's spatial twist.
        translation: (3,) platform position, base frame [m].
        twist: (6,) model twist ``(v, w)``.
        frame_from_base: The task frame (None: the base frame).

    Returns:
        ``L G`` (m, 6), the task's twist ``tau_s`` (6,) (to evaluate its
        ``L_dot tau_s``), and ``L G_dot tau`` (m,).
    """
    G = np.eye(6)
    G[:3, 3:] = skew(np.asarray(translation, dtype=float))
    gdot = np.concatenate([np.cross(twist[:3], twist[3:]), np.zeros(3)])
    if frame_from_base is not None:
        Rf, pf = frame_from_base.rotation, frame_from_base.translation
        Ad = np.zeros((6, 6))
        Ad[:3, :3] = Rf
        Ad[:3, 3:] = skew(pf) @ Rf
        Ad[3:, 3:] = Rf
        G = Ad @ G
        gdot = Ad @ gdot
    L = np.asarray(jacobian, dtype=float)
    return L @ G, G @ twist, L @ gdot


__all__ = [
    "CTCOptions",
    "ComputedTorqueSolver",
    "SecondOrderGains",
    "checked_integral_gain",
    "drive_forces",
    "task_in_model_twist",
]
