"""The inverse dynamic identification model: leg forces linear in the standard parameters.

``f = Y(x, tau, tau_dot) theta`` with ``theta`` the standard parameters of
:mod:`.parameters`. The mechanism's columns are derived from the very expressions of
:class:`~hexapod.dynamics.DynamicModel` (:func:`hexapod.dynamics.compiled.expressions`):
its 19 inertial parameters are written as functions of the 18 standard mechanism
parameters (``c = (m c) / m``, ``I_c = I_O - m (|c|^2 I - c c^T)``, ``d = (m d) / m``,
``i = I_hinge - m d^2``), the task-space equation ``M tau_dot + h`` differentiated with
respect to them (it is linear in them: the derivative does not depend on where it is
taken), and mapped to the legs by ``K^-T`` (``K^T f = M tau_dot + h``). The drives add,
per leg, ``rotor * q_ddot + viscous * q_dot + coulomb * tanh(q_dot / v_s)``, as the
dynamic world's plant (:mod:`hexapod.dynamics.robots`) applies them.

Tested: ``Y theta_true`` equals ``DynamicModel.inverse_batch`` (plus the drives) to
rounding on random states (``tests/hexapod/dynamics/identification/test_regressor.py``).
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from hexapod.compiled import CompiledFunction, Layout
from hexapod.dynamics import compiled as _c
from hexapod.dynamics.drive_model import COULOMB_SMOOTHING
from hexapod.dynamics.identification.parameters import N_MECHANISM, N_STANDARD
from hexapod.exceptions import DynamicsError
from hexapod.geometry import HexapodGeometry

#: The compiled function's output row: the task-space regressor ``Y_task`` (6 x
#: N_MECHANISM, column-major: its view is the transpose), ``K`` (column-major), the leg
#: rates ``q_dot`` [m/s] and the legs' acceleration bias ``K_dot tau`` [m/s^2]. Its input
#: is the dynamics' row (:data:`hexapod.dynamics.compiled.INPUTS`), the accelerations in
#: the block ``u``.
OUTPUTS = Layout([("Y_task", (N_MECHANISM, 6)), ("K", (6, 6)), ("q_dot", 6),
                  ("leg_bias", 6)], "identification regressor output")

#: Where the derivative is taken (any point with non-zero masses: the equation is linear).
_THETA0 = np.array([1.3, 0.011, -0.017, 0.023, 0.31, 0.29, 0.47, 0.013, -0.021, 0.007,
                    0.7, 0.11, 0.05, 0.01, 0.3, 0.05, 0.02, 0.004])


def _inertial_row(theta: ca.SX) -> ca.SX:
    """The model's 16 inertial parameters (without gravity) as functions of the 18
    standard mechanism parameters."""
    m, mc = theta[0], theta[1:4]
    c = mc / m
    xx, yy, zz, xy, xz, yz = (theta[k] for k in range(4, 10))
    I_o = ca.vertcat(ca.horzcat(xx, xy, xz), ca.horzcat(xy, yy, yz), ca.horzcat(xz, yz, zz))
    I_c = I_o - m * (ca.dot(c, c) * ca.SX.eye(3) - c @ c.T)
    mb, mdb, itb, mr, mdr, itr = theta[10], theta[11], theta[12], theta[14], theta[15], theta[16]
    db, dr = mdb / mb, mdr / mr
    return ca.vertcat(m, c, I_c[0, 0], I_c[1, 1], I_c[2, 2], I_c[0, 1], I_c[0, 2], I_c[1, 2],
                      mb, db, itb - mb * db**2, mr, dr, itr - mr * dr**2)


def _build() -> ca.Function:
    x, e = _c.cached_expressions()
    theta = ca.SX.sym("theta", N_MECHANISM)
    blocks = _c.INPUTS.split(x)
    params = ca.vertcat(_inertial_row(theta), _c.PARAMETERS.split(blocks["params"])["gravity"])
    new_x = ca.vertcat(*(params if block == "params" else blocks[block]
                         for block in _c.INPUTS))
    rhs = e["M"] @ blocks["u"] + e["h"]  # (the row's ``u``: the accelerations)
    rhs = ca.substitute(rhs, x, new_x)
    Y = ca.jacobian(rhs, theta)
    Y = ca.substitute(Y, theta, ca.DM(_THETA0))
    out = ca.vertcat(ca.reshape(Y, 6 * N_MECHANISM, 1), ca.reshape(e["K"], 36, 1),
                     e["q_dot"], e["leg_bias"])
    return ca.Function("hexapod_ident_regressor", [x], [ca.cse(ca.densify(out))])


@lru_cache(maxsize=1)
def compiled_regressor() -> CompiledFunction:
    """The compiled regressor function (built and compiled on first use, cached on disk)."""
    return CompiledFunction(_build(), inputs=_c.INPUTS, outputs=OUTPUTS)


def regressor(geometry: HexapodGeometry, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
              acc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The identification model at ``N`` states.

    Args:
        geometry: The robot (points and gravity; its inertia is not used).
        R: (N, 3, 3) platform orientations.
        t: (N, 3) platform positions [m].
        twist: (N, 6) twists ``(v, w)`` [m/s, rad/s].
        acc: (N, 6) accelerations ``(dv/dt, dw/dt)`` [m/s^2, rad/s^2].

    Returns:
        ``Y`` (N, 6, :data:`N_STANDARD`) (leg ``i``'s force [N] is ``Y[:, i] @ theta``),
        the leg rates ``q_dot`` (N, 6) [m/s] and accelerations ``q_ddot`` (N, 6) [m/s^2].

    Raises:
        DynamicsError: A singular pose (``K`` not invertible), naming the state's index.
    """
    from hexapod.dynamics.model import DynamicModel

    model = DynamicModel(geometry)
    rows = model.rows(R, t, twist, acc)
    n = rows.shape[0]
    y = OUTPUTS.views(compiled_regressor().batch(rows))
    Y_task = np.swapaxes(y["Y_task"], 1, 2)
    K = np.swapaxes(y["K"], 1, 2)
    qd, bias = y["q_dot"], y["leg_bias"]
    cond = np.linalg.cond(K)
    if not np.all(np.isfinite(cond)) or np.any(cond > 1e10):
        raise DynamicsError("regressor", int(np.argmax(~np.isfinite(cond) | (cond > 1e10))))
    Y_mech = np.linalg.solve(np.swapaxes(K, 1, 2), Y_task)  # K^-T Y_task
    qdd = np.einsum("nij,nj->ni", K, acc) + bias
    Y = np.zeros((n, 6, N_STANDARD))
    Y[:, :, :N_MECHANISM] = Y_mech
    legs = np.arange(6)
    cols = N_MECHANISM + 3 * legs
    Y[:, legs, cols] = qdd
    Y[:, legs, cols + 1] = qd
    Y[:, legs, cols + 2] = np.tanh(qd / COULOMB_SMOOTHING)
    return Y, qd, qdd
