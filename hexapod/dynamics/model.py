"""``DynamicModel``: forward and inverse dynamics of the hexapod's mechanism.

Conventions (``docs/math.md`` section 11): the platform pose ``(R, t)`` in the base
frame; the twist ``(v, w)`` with ``v = dt/dt`` the velocity of the platform frame's
origin and ``w`` the angular velocity, both in the base frame; the acceleration
``(dv/dt, dw/dt)``; leg force ``f_i`` along the leg, positive when it pushes the
platform away from the base. The mechanism only: rigid bodies, gravity and the leg
forces, no friction and no drive inertia (:mod:`hexapod.dynamics.drives`).

Two implementations, tested equal: ``"compiled"`` (default, :mod:`.compiled`, CasADi
generated to C, batched) and ``"pinocchio"`` (:mod:`.reference`, the closed-chain
Pinocchio model and ``pin.constraintDynamics``).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from hexapod.dynamics import compiled as _c
from hexapod.exceptions import DynamicsError, ShapeError
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import check_rotations

Method = Literal["compiled", "pinocchio"]

#: Largest relative residual ``|K^T f - (M acc + h)| / |M acc + h|`` of an inverse
#: solve; above it the pose is singular (no forces give that acceleration).
INVERSE_TOLERANCE = 1e-6


def checked_array(name: str, value: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as floats, refused unless its trailing shape is ``shape`` and every
    value is finite.

    Raises:
        ShapeError: The shape, or the first non-finite value with its index (names
            ``name``).
    """
    arr = np.asarray(value, dtype=float)
    if arr.shape[arr.ndim - len(shape):] != shape:
        raise ShapeError(name, f"shape (..., {', '.join(map(str, shape))})", arr.shape)
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        at = tuple(int(i) for i in bad)  # (plain ints: numpy's printed as np.int64(0))
        raise ShapeError(name, "finite values", f"{arr[at]} at index {at}")
    return arr


#: How far ``R^T R`` may be from the identity in a state given to the dynamics: an
#: orientation integrated without re-orthonormalising drifts (RK4 over the energy
#: test's seconds: 2.5e-5), a scaled or mirrored matrix is refused (1.01 I: 0.02).
DRIFT_TOLERANCE = 1e-3


class DynamicModel:
    """Rigid-body dynamics of the closed chain in the platform's coordinates.

    ``M(x) acc + h(x, twist) = K(x)^T f`` with ``K`` the inverse Jacobian of this twist
    (``q_dot = K twist``). The twist ``(v [m/s], w [rad/s])`` is ``v = dt/dt``, the
    velocity of the platform frame's origin, and ``w`` the angular velocity, both in the
    base frame: NOT the twist of :mod:`hexapod.kinematics` and :mod:`hexapod.se3`,
    whose ``v`` is reduced at the base origin (``v_base = v - w x t``); give one for the
    other and the accelerations are those of another motion. The acceleration is
    ``(dv/dt, dw/dt)``; a leg force ``f_i`` [N] acts along the leg, positive when it
    pushes the platform away from the base.

    Args:
        geometry: The robot; masses, inertias and gravity from ``geometry.inertia``.
        method: ``"compiled"`` (fast, batched) or ``"pinocchio"`` (reference).

    Every method refuses (:class:`~hexapod.exceptions.ShapeError`, naming the argument)
    a wrong shape, a value not finite, and an orientation ``R`` that is not a rotation
    (:func:`hexapod.kinematics.check_rotations` within :data:`DRIFT_TOLERANCE`: a
    scaled or mirrored matrix); a state
    whose result is not finite raises :class:`~hexapod.exceptions.DynamicsError`.
    """

    def __init__(self, geometry: HexapodGeometry, method: Method = "compiled") -> None:
        if method not in ("compiled", "pinocchio"):
            raise ValueError(f"unknown dynamics method {method!r}; use 'compiled' or "
                             "'pinocchio'")
        self.geometry = geometry
        self.method = method
        self.parameters = _c.parameter_row(geometry.inertia)
        self._reference = None
        if method == "pinocchio":
            from hexapod.dynamics.reference import ReferenceDynamics

            self._reference = ReferenceDynamics(geometry)

    # ------------------------------------------------------------ one state
    def forward(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray, forces: np.ndarray
                ) -> np.ndarray:
        """Platform acceleration (6,) ``(dv/dt [m/s^2], dw/dt [rad/s^2])``.

        Args:
            R: (3, 3) platform orientation in the base frame.
            t: (3,) platform position [m].
            twist: (6,) ``(v [m/s], w [rad/s])``, ``v`` the platform origin's velocity
                (the class docstring).
            forces: (6,) leg forces [N].
        """
        if self._reference is not None:
            R, t, twist, forces = self._one(R, t, twist, forces, "forces")
            return self.checked(self._reference.forward(R, t, twist, forces), "forward")
        return self.forward_batch(*(np.asarray(x, dtype=float)[None]
                                    for x in (R, t, twist, forces)))[0]

    def inverse(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray, acc: np.ndarray
                ) -> np.ndarray:
        """Leg forces (6,) [N] that give the platform the acceleration ``acc`` (6,)."""
        if self._reference is not None:
            R, t, twist, acc = self._one(R, t, twist, acc, "acc")
            return self.checked(self._reference.inverse(R, t, twist, acc), "inverse")
        return self.inverse_batch(*(np.asarray(x, dtype=float)[None]
                                    for x in (R, t, twist, acc)))[0]

    def mass_matrix(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(6, 6) mass matrix: the kinetic energy is ``twist^T M twist / 2`` [J]."""
        if self._reference is not None:
            R, t, _, _ = self._one(R, t, np.zeros(6), np.zeros(6), "acc")
            return self._reference.mass_matrix(R, t)
        return self.mass_matrix_batch(*(np.asarray(x, dtype=float)[None] for x in (R, t)))[0]

    def energy(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray) -> float:
        """Kinetic plus potential energy [J] (potential zero at the base origin)."""
        if self._reference is not None:
            R, t, twist, _ = self._one(R, t, twist, np.zeros(6), "acc")
            return self._reference.energy(R, t, twist)
        return float(self.energy_batch(*(np.asarray(x, dtype=float)[None]
                                         for x in (R, t, twist)))[0])

    # ------------------------------------------------------------ batches
    def rows(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray, u: np.ndarray,
             base_points: np.ndarray | None = None, platform_points: np.ndarray | None = None,
             parameters: np.ndarray | None = None) -> np.ndarray:
        """Validated input rows (N, 79) of the compiled functions
        (:func:`hexapod.dynamics.compiled.pack`); per-item geometry or inertial
        parameters override the model's (e.g. the true robots of a study)."""
        R = checked_array("R", R, (3, 3))
        check_rotations(R, "R", DRIFT_TOLERANCE)
        t = checked_array("t", t, (3,))
        twist = checked_array("twist", twist, (6,))
        u = checked_array("forces/acc", u, (6,))
        n = t.shape[0]
        if R.shape != (n, 3, 3) or twist.shape != (n, 6) or u.shape != (n, 6):
            raise ShapeError("R/t/twist", f"matching batches of {n}",
                             f"{R.shape}, {t.shape}, {twist.shape}, {u.shape}")
        A = self.geometry.base_points if base_points is None else base_points
        E = self.geometry.platform_points if platform_points is None else platform_points
        p = self.parameters if parameters is None else parameters
        return _c.pack(R, t, twist, u, A, E, p)

    def forward_batch(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                      forces: np.ndarray, **overrides: np.ndarray) -> np.ndarray:
        """:meth:`forward` over a leading axis: (N, 3, 3), (N, 3), (N, 6), (N, 6) ->
        (N, 6). ``overrides``: ``base_points``, ``platform_points``, ``parameters``
        (:meth:`rows`)."""
        if self._reference is not None:
            return np.array([self.forward(*args) for args in zip(R, t, twist, forces,
                                                                 strict=True)])
        return self.checked(_c.compiled("forward").batch(
            self.rows(R, t, twist, forces, **overrides)), "forward")

    def inverse_batch(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                      acc: np.ndarray, **overrides: np.ndarray) -> np.ndarray:
        """:meth:`inverse` over a leading axis -> (N, 6) [N]."""
        if self._reference is not None:
            return np.array([self.inverse(*args) for args in zip(R, t, twist, acc,
                                                                 strict=True)])
        y = _c.OUTPUTS["inverse"].views(
            _c.compiled("inverse").batch(self.rows(R, t, twist, acc, **overrides)))
        residual = np.linalg.norm(y["residual"], axis=1)
        singular = ~(residual <= INVERSE_TOLERANCE * np.linalg.norm(y["rhs"], axis=1)
                     + 1e-12)
        if np.any(singular):
            raise DynamicsError("inverse", int(np.argmax(singular)))
        return self.checked(y["forces"], "inverse")

    def terms_batch(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                    **overrides: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The equation's terms over a leading axis (always the compiled model).

        Returns:
            ``M`` (N, 6, 6), ``h`` (N, 6) (velocity and gravity terms [N, N m]),
            ``K`` (N, 6, 6) (``q_dot = K twist``), kinetic (N,) and potential (N,)
            energies [J].
        """
        n = np.shape(t)[0]
        y = _c.compiled("terms").batch(self.rows(R, t, twist, np.zeros((n, 6)), **overrides))
        v = _c.OUTPUTS["terms"].views(self.checked(y, "terms"))
        M = np.swapaxes(v["M"], -1, -2)  # (column-major blocks)
        K = np.swapaxes(v["K"], -1, -2)
        return M, v["h"], K, v["kinetic"][:, 0], v["potential"][:, 0]

    def jacobian_batch(self, R: np.ndarray, t: np.ndarray, **overrides: np.ndarray
                       ) -> np.ndarray:
        """The inverse Jacobian ``K`` (N, 6, 6) (``q_dot = K twist``) of :meth:`terms_batch`
        alone (the "jacobian" kernel: the same numbers, without the mass matrix)."""
        n = np.shape(t)[0]
        y = _c.compiled("jacobian").batch(self.rows(R, t, np.zeros((n, 6)), np.zeros((n, 6)),
                                                    **overrides))
        v = _c.OUTPUTS["jacobian"].views(self.checked(y, "jacobian"))
        return np.swapaxes(v["K"], -1, -2)  # (column-major blocks)

    def legs_batch(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                   **overrides: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Leg rates ``q_dot = K twist`` (N, 6) [m/s] and the leg accelerations at zero
        platform acceleration ``K_dot twist`` (N, 6) [m/s^2] (always the compiled model),
        so that
        ``q_ddot = K acc + K_dot twist``."""
        n = np.shape(t)[0]
        y = _c.compiled("legs").batch(self.rows(R, t, twist, np.zeros((n, 6)), **overrides))
        v = _c.OUTPUTS["legs"].views(self.checked(y, "legs"))
        return v["q_dot"], v["leg_bias"]

    def legs_jacobian_batch(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                            **overrides: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`jacobian_batch` and :meth:`legs_batch` of the same poses from one
        packed input (the "jacobian" kernel does not read the twist: the same numbers as
        the two calls).

        Returns:
            ``K`` (N, 6, 6), ``q_dot`` (N, 6) [m/s] and ``K_dot twist`` (N, 6) [m/s^2].
        """
        n = np.shape(t)[0]
        x = self.rows(R, t, twist, np.zeros((n, 6)), **overrides)
        K = _c.OUTPUTS["jacobian"].views(
            self.checked(_c.compiled("jacobian").batch(x), "jacobian"))["K"]
        legs = _c.OUTPUTS["legs"].views(self.checked(_c.compiled("legs").batch(x), "legs"))
        return np.swapaxes(K, -1, -2), legs["q_dot"], legs["leg_bias"]

    def forward_drives_batch(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                             forces: np.ndarray, added_mass: np.ndarray,
                             implicit_mass: np.ndarray | None = None,
                             **overrides: np.ndarray
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Forward dynamics with leg-space masses, for the drives' layer (compiled).

        Solves ``(M + K^T diag(a + b) K) acc = K^T (f - a K_dot twist) - h``
        (:mod:`hexapod.dynamics.compiled`).

        Args:
            R, t, twist: The states, as :meth:`forward_batch`.
            forces: (N, 6) net leg forces [N] (the drives' force minus friction).
            added_mass: ``a``, (6,) or (N, 6) mass moving with each leg's length [kg]
                (the reflected rotor inertia).
            implicit_mass: ``b``, (6,) or (N, 6) ``-dt d(forces)/d(q_dot)`` [kg]: a
                velocity-dependent force taken implicitly over a step ``dt``; zero if
                None.
            overrides: ``base_points``, ``platform_points``, ``parameters`` (:meth:`rows`).

        Returns:
            The platform acceleration (N, 6), the leg rates ``q_dot`` (N, 6) [m/s] and
            the leg accelerations ``q_ddot = K acc + K_dot twist`` (N, 6) [m/s^2].
        """
        if self._reference is not None:
            raise ValueError("forward_drives_batch is computed by the compiled model only "
                             "(DynamicModel(geometry) without method='pinocchio')")
        rows = self.rows(R, t, twist, forces, **overrides)
        n = rows.shape[0]
        a = checked_array("added_mass", np.broadcast_to(added_mass, (n, 6)), (6,))
        b = np.zeros((n, 6)) if implicit_mass is None else checked_array(
            "implicit_mass", np.broadcast_to(implicit_mass, (n, 6)), (6,))
        y = _c.compiled("forward_drives").batch(np.concatenate([rows, a, b], axis=1))
        v = _c.OUTPUTS["forward_drives"].views(self.checked(y, "forward_drives"))
        return v["acc"], v["q_dot"], v["q_ddot"]

    def mass_matrix_batch(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """:meth:`mass_matrix` over a leading axis -> (N, 6, 6)."""
        if self._reference is not None:
            return np.array([self.mass_matrix(*args) for args in zip(R, t, strict=True)])
        return self.terms_batch(R, t, np.zeros((np.shape(t)[0], 6)))[0]

    def energy_batch(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """:meth:`energy` over a leading axis -> (N,) [J]."""
        if self._reference is not None:
            return np.array([self.energy(*args) for args in zip(R, t, twist, strict=True)])
        _, _, _, kinetic, potential = self.terms_batch(R, t, twist)
        return kinetic + potential

    # ------------------------------------------------------------ helpers
    @staticmethod
    def _one(R: np.ndarray, t: np.ndarray, twist: np.ndarray, u: np.ndarray, name: str
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        R = checked_array("R", R, (3, 3))
        check_rotations(R, "R", DRIFT_TOLERANCE)
        return (R, checked_array("t", t, (3,)), checked_array("twist", twist, (6,)),
                checked_array(name, u, (6,)))

    @staticmethod
    def checked(y: np.ndarray, what: str) -> np.ndarray:
        """Refuse non-finite results (a singular pose or mass matrix) naming the item."""
        if not np.all(np.isfinite(y)):
            bad = np.argwhere(~np.isfinite(np.atleast_2d(y)))[0]
            raise DynamicsError(what, int(bad[0]))
        return y
