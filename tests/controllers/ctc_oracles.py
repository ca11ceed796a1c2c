"""The numpy computed-torque step, the test oracle of the compiled one.

``computed-torque`` steps through its compiled function only
(:mod:`controllers.solvers.compiled_ctc`); this is the step it replaced, by numpy around
the model's separate compiled calls (:func:`hexapod.fk.forward_kinematics`, an SVD
solve in :func:`tests.controllers.ctc_solver_oracle.acceleration`,
:meth:`hexapod.dynamics.DynamicModel.inverse`), kept to check the compiled step against.
"""

from __future__ import annotations

import numpy as np

from controllers.base import Command
from controllers.computed_torque import ComputedTorqueController
from controllers.solvers.computed_torque import drive_forces
from hexapod.actuation import Actuation
from hexapod.fk import forward_kinematics
from tests.controllers.ctc_solver_oracle import acceleration


def numpy_joint_step(ctrl: ComputedTorqueController, q: np.ndarray, qd: np.ndarray,
                     q_s: np.ndarray, qd_s: np.ndarray, qdd_s: np.ndarray) -> Command:
    """The law's step by numpy from its last pose (``ctrl._pose``, set to the pose found),
    without saturation or integral action.

    Args:
        ctrl: A reset ``computed-torque`` controller.
        q, qd: Lengths [m] and leg velocities [m/s].
        q_s, qd_s, qdd_s: The reference's lengths, rates and accelerations.
    """
    ctx, model = ctrl._ctx, ctrl._model
    assert ctx is not None and model is not None

    def refuse(problem: str) -> Command:
        return Command.refuse(f"{ctrl.name}: {problem}", actuation=Actuation.FORCE)

    try:
        fk = forward_kinematics(ctx.geometry, q, guess=ctrl._pose, check_stroke=False)
        R, p = fk.rotation, fk.translation
        K = model.terms_batch(R[None], p[None], np.zeros((1, 6)))[2][0]
        twist = np.linalg.solve(K, qd)
        bias = model.legs_batch(R[None], p[None], twist[None])[1][0]
        e = q_s - q
        sol = acceleration(ctrl.solver, -e, K, bias, twist, error_t=-qd_s, error_tt=-qdd_s)
        if sol.reason is not None:
            return refuse(sol.reason)
        a = K @ sol.acc + bias
        f = model.inverse(R, p, twist, sol.acc) + drive_forces(model, a, qd, qd_s)
    except Exception as exc:  # the nominal model failed here: refuse with its reason
        return refuse(f"nominal model failed: {exc}")
    if not np.all(np.isfinite(f)):
        return refuse(f"non-finite leg forces {f}")
    ctrl._pose = (R, p)
    return Command.of_forces(f, error=e, error_norm=float(np.linalg.norm(e)),
                             rank=sol.rank, condition=sol.condition, features_used=6)
