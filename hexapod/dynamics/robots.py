"""Many hexapods with mass and drives, integrated in time (the dynamic world's physics).

:class:`DynamicRobots` holds the state of ``n`` robots (rows), each with its own geometry,
inertia and drives, and integrates them over a control period in steps of ``h``:

1. the mechanism's terms ``M(x)``, ``h(x, tau)`` and ``K(x)`` (``q_dot = K tau``) of the
   compiled closed-chain model (:mod:`hexapod.dynamics.compiled`);
2. the drives' forces (:mod:`hexapod.dynamics.drive_model`: PI velocity loop or force
   mode, friction);
3. the leg's equation with the reflected rotor inertia ``m_r``: the force on the
   mechanism is ``motor - friction - m_r q_ddot`` with ``q_ddot = K tau_dot + b``,
   ``b_i = u_i . (w x (w x r_i)) + |B_dot_i - q_dot_i u_i|^2 / q_i``, so
   ``(M + K^T diag(m_r - h s) K) tau_dot = K^T (motor - friction - m_r b) - h``, with
   ``s`` the velocity slope of the drives' forces taken implicitly (**linearly implicit
   Euler** in the twist);
4. the pose with the new twist (**semi-implicit Euler on SE(3)**): ``t += h v``,
   ``R <- exp(h [w]x) R``; the legs follow (``q_i = |t + R eB_i - A_i|``).

One implementation of the step: the compiled period
(:mod:`hexapod.dynamics.robots_compiled`, every step of a period fused in C, used by
:meth:`DynamicRobots.advance`); the tests hold it equal to the same step written out in
numpy (``tests/hexapod/dynamic_robots_oracle.py``).

A robot starts at rest, its drives holding the platform against gravity (the integral
action preloaded with the static leg forces).
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from hexapod.dynamics import compiled as _c
from hexapod.dynamics.compiled import parameter_row
from hexapod.dynamics.drive_model import DriveModel
from hexapod.dynamics.model import DynamicModel, checked_array
from hexapod.dynamics.robots_compiled import advance_compiled, column, new_table, row_index
from hexapod.workspace import home_pose

log = logging.getLogger(__name__)

#: The blocks of the legs kernel's input rows that :meth:`DynamicRobots.leg_rates` writes.
_IN_R, _IN_T, _IN_TWIST = _c.INPUTS["R"], _c.INPUTS["t"], _c.INPUTS["twist"]


def legs(R: np.ndarray, t: np.ndarray, A: np.ndarray, E: np.ndarray
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leg lengths (n, 6) [m], unit vectors (n, 6, 3) and platform arms ``r_i = R eB_i``
    (n, 6, 3) [m] of poses ``R`` (n, 3, 3), ``t`` (n, 3) [m]."""
    r = np.einsum("nij,nkj->nki", R, E)
    leg = t[:, None, :] + r - A
    q = np.linalg.norm(leg, axis=-1)
    return q, leg / q[..., None], r


class DynamicRobots:
    """``n`` robots with mass and drives (see the module docstring).

    The geometry, inertia and drive parameters are read at construction; the state
    (``twist``, ``drives.integral``, ``forces`` and the accumulators) lives in the rows
    of :attr:`table`, which the compiled period advances in place: write into these
    arrays (``robots.twist[:] = ...``), never rebind them.

    Args:
        geometries: The true robot of every row (geometry, ``inertia``, ``drives``); one
            drive mode for all.
        R: (n, 3, 3) platform rotations (used and changed in place).
        t: (n, 3) platform positions [m] (used and changed in place).
        base_points, platform_points: (6, 3) or (n, 6, 3) points [m] (default: each
            row's geometry's).
    """

    def __init__(self, geometries: list[Any], R: np.ndarray, t: np.ndarray,
                 base_points: np.ndarray | None = None,
                 platform_points: np.ndarray | None = None) -> None:
        n = len(geometries)
        self.n = n
        self.R, self.t = R, t
        self.A = np.array(np.broadcast_to(
            base_points if base_points is not None else [g.base_points for g in geometries],
            (n, 6, 3)))
        self.E = np.array(np.broadcast_to(
            platform_points if platform_points is not None
            else [g.platform_points for g in geometries], (n, 6, 3)))
        self.model = DynamicModel(geometries[0])
        self.parameters = np.array([parameter_row(g.inertia) for g in geometries])
        drives = [g.drives for g in geometries]
        self.rotor = np.array([d.rotor_inertia for d in drives], dtype=float)
        self.resolution = np.array([d.encoder_resolution for d in drives], dtype=float)
        self.drives = DriveModel(drives, self._tuned_mass(geometries), n,
                                 np.array([g.max_speed for g in geometries], dtype=float))
        #: (n, 6) twists ``(v, w)`` [m/s, rad/s].
        self.twist = np.zeros((n, 6))
        rows = np.arange(n)
        self.drives.hold(rows, self.model.inverse_batch(R, t, np.zeros((n, 6)),
                                                        np.zeros((n, 6)), **self.rows(rows)))
        #: (n, 6) the drives' forces at the end of the last step [N].
        self.forces = self.drives.integral.copy()
        #: (n,) time any drive of the row spent at its force limit [s].
        self.saturated_time = np.zeros(n)
        #: (n, 6) time each drive spent at its force limit [s].
        self.saturated_legs = np.zeros((n, 6))
        #: (n,) sum of the squared drive tracking errors [m^2/s^2] and their count.
        self.track_sq = np.zeros(n)
        self.track_count = np.zeros(n)
        #: (n,) largest drive tracking error [m/s] and largest drive force [N].
        self.track_max = np.zeros(n)
        self.force_max = np.abs(self.forces).max(axis=1)
        #: (n, 79) the rows of :meth:`leg_rates` (built on first use).
        self._leg_rows: np.ndarray | None = None
        self._share_table()

    def _share_table(self) -> None:
        """Keep every row in one table (constants, state, accumulators: the compiled
        period's rows, advanced in place) and make the state attributes its views."""
        #: (n, W) the robots' rows (:data:`hexapod.dynamics.robots_compiled.LAYOUT`).
        self.table = new_table(self)
        #: The step [s] and drive mode last written into every row of the table
        #: (:func:`~hexapod.dynamics.robots_compiled.load_period`), None before.
        self.period_constants: tuple[float, float] | None = None
        self.twist = column(self.table, "twist")
        self.drives.integral = column(self.table, "integral")
        self.forces = column(self.table, "motor")
        self.saturated_time = column(self.table, "saturated_time")
        self.saturated_legs = column(self.table, "saturated_legs")
        self.track_sq = column(self.table, "track_sq")
        self.track_max = column(self.table, "track_max")
        self.force_max = column(self.table, "force_max")
        #: (n, 6) true leg lengths [m] at the end of the last :meth:`advance` (at
        #: construction before it).
        self.period_lengths = column(self.table, "q")

    def rows(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        """The per-row overrides of :class:`DynamicModel`'s batches for ``rows``."""
        return {"base_points": self.A[rows], "platform_points": self.E[rows],
                "parameters": self.parameters[rows]}

    def _tuned_mass(self, geometries: list[Any]) -> np.ndarray:
        """(n, 6) the inertia each velocity loop is tuned on [kg]: the rotor's plus the
        mechanism's seen by the leg at the robot's home pose (the diagonal of
        ``K^-T M K^-1``), as a drive is tuned once on its robot."""
        n = len(geometries)
        homes = [home_pose(g) for g in geometries]
        R0 = np.array([h[0] for h in homes])
        t0 = np.array([h[1] for h in homes])
        M, _, K, _, _ = self.model.terms_batch(R0, t0, np.zeros((n, 6)),
                                               **self.rows(np.arange(n)))
        Kinv = np.linalg.inv(K)
        joint = np.swapaxes(Kinv, -1, -2) @ M @ Kinv
        return self.rotor + np.diagonal(joint, axis1=-2, axis2=-1)  # type: ignore[no-any-return]

    def leg_rates(self, rows: np.ndarray | slice) -> np.ndarray:
        """True leg rates ``q_dot = K twist`` (n, 6) [m/s] of ``rows`` (indices, or a
        slice) at their present state: :meth:`DynamicModel.legs_batch` with each row's own
        geometry and inertia, its input rows taken from a table of their constants packed
        once (only the poses and twists are written each call, into the table itself for
        consecutive rows, else into a copy of their rows; the same kernel on the same
        inputs).

        Raises:
            ShapeError: A pose or twist of the rows is not finite (names the value).
            DynamicsError: The kernel's result is not finite (names the row).
        """
        if self._leg_rows is None:  # A, E, the inertia, u = 0: constant per row
            n = self.n
            self._leg_rows = _c.pack(self.R, self.t, self.twist, np.zeros((n, 6)), self.A,
                                     self.E, self.parameters)
        index = row_index(rows)
        x = self._leg_rows[index]  # (consecutive rows: a view, written in place)
        R, t, twist = self.R[index], self.t[index], self.twist[index]
        x[:, _IN_R].reshape(-1, 3, 3)[:] = np.swapaxes(R, -1, -2)
        x[:, _IN_T] = t
        x[:, _IN_TWIST] = twist
        y = _c.compiled("legs").batch(x)
        if not np.isfinite(y).all():  # (a non-finite input gives one) the input at fault
            checked_array("R", R, (3, 3))
            checked_array("t", t, (3,))
            checked_array("twist", twist, (6,))
            self.model.checked(y, "legs")  # else the row
        return _c.OUTPUTS["legs"].view(y, "q_dot")

    def lengths(self, rows: np.ndarray) -> np.ndarray:
        """True leg lengths (n, 6) [m] of ``rows``."""
        return legs(self.R[rows], self.t[rows], self.A[rows], self.E[rows])[0]

    def advance(self, rows: np.ndarray, setpoints: np.ndarray, h: float, steps: int
                ) -> np.ndarray:
        """Integrate ``rows`` over ``steps`` steps of ``h`` [s] (compiled).

        Args:
            rows: (n,) row indices.
            setpoints: (n, 6) leg velocities [m/s] (velocity mode) or forces [N] (force
                mode), held over the period.
            h: Physics step [s].
            steps: Steps in the period.

        Returns:
            (n,) mask of rows whose state is not finite after the period (left unchanged).
        """
        return advance_compiled(self, rows, setpoints, h, steps)
