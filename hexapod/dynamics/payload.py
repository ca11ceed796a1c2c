"""A payload: a rigid body fixed to the platform (a tool, a part, a camera).

A payload is its mass, its centre of mass in the platform frame and its inertia about
that centre (platform axes), the convention of ``[inertia] platform_inertia``. Fixed
rigidly to the platform, it makes with it one rigid body (:func:`with_payload`): the
masses add, the centre of mass is their weighted mean and the inertias, each moved to
the common centre of mass by the parallel-axis theorem (Huygens-Steiner), add::

    m = m_p + m_l,   c = (m_p c_p + m_l c_l) / m,
    I = I_p + m_p (|d_p|^2 1 - d_p d_p^T) + I_l + m_l (|d_l|^2 1 - d_l d_l^T),

``d_k = c_k - c``. Nothing else of the robot changes (the legs, the drives, gravity).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexapod.dynamics.inertia import InertiaParameters, inertia_matrix
from hexapod.exceptions import InertiaError


def _six(tensor: np.ndarray) -> np.ndarray:
    """``[ixx, iyy, izz, ixy, ixz, iyz]`` of a symmetric 3x3 tensor."""
    return np.array([tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1], tensor[0, 2],
                     tensor[1, 2]])


def _steiner(mass: float, offset: np.ndarray) -> np.ndarray:
    """The parallel-axis term ``m (|d|^2 1 - d d^T)`` [kg m^2] of a body of mass ``mass``
    whose centre of mass is ``offset`` [m] from the new reference point."""
    d = np.asarray(offset, dtype=float)
    return mass * (float(d @ d) * np.eye(3) - np.outer(d, d))


@dataclass(frozen=True)
class Payload:
    """A rigid body fixed to the platform.

    Attributes:
        mass: [kg], zero or positive (zero: no payload).
        com: (3,) its centre of mass in the platform frame [m].
        inertia: (6,) ``[ixx, iyy, izz, ixy, ixz, iyz]`` about its centre of mass,
            platform axes [kg m^2] (zeros: a point mass).
        source: Where it was read (for error messages).

    Raises:
        InertiaError: A negative or non-finite mass, a centre of mass or an inertia of
            the wrong shape or not finite, an inertia that no rigid body has (not
            positive semi-definite, or its principal moments violating the triangle
            inequality), or an inertia without mass. ``field`` is ``payload.<key>``.
    """

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    source: str | None = None

    def __post_init__(self) -> None:
        src = self.source
        for key, shape in (("mass", ()), ("com", (3,)), ("inertia", (6,))):
            arr = np.array(getattr(self, key), dtype=float)
            if arr.shape != shape:
                raise InertiaError(f"payload.{key}", f"expected shape {shape}, got "
                                   f"{arr.shape}", src)
            if not np.all(np.isfinite(arr)):
                raise InertiaError(f"payload.{key}", f"not finite: {arr.tolist()}", src)
            arr.flags.writeable = False
            object.__setattr__(self, key, float(arr) if shape == () else arr)
        if self.mass < 0:
            raise InertiaError("payload.mass", f"negative mass {self.mass} kg", src)
        moments = np.linalg.eigvalsh(inertia_matrix(self.inertia))
        scale = max(float(np.abs(moments).max()), 1e-300)
        if self.mass == 0 and np.any(self.inertia != 0):
            raise InertiaError("payload.inertia", "a massless payload has no inertia: "
                               f"got {self.inertia.tolist()} kg m^2", src)
        if moments[0] < -1e-12 * scale:
            raise InertiaError("payload.inertia", "not positive semi-definite: principal "
                               f"moments {np.round(moments, 12).tolist()} kg m^2", src)
        if moments[2] > moments[0] + moments[1] + 1e-12 * scale:
            raise InertiaError("payload.inertia", "principal moments "
                               f"{np.round(moments, 12).tolist()} kg m^2 violate the "
                               "triangle inequality (no rigid body has them)", src)

    @property
    def empty(self) -> bool:
        """True when the payload has no mass (adding it changes nothing)."""
        return self.mass == 0.0

    def with_mass(self, mass: float) -> Payload:
        """The same body with another mass [kg], its inertia scaled alike (the same
        shape and density distribution, another density)."""
        factor = mass / self.mass if self.mass else 0.0
        return Payload(mass, self.com, np.asarray(self.inertia) * factor, self.source)


def with_payload(inertia: InertiaParameters, payload: Payload) -> InertiaParameters:
    """The robot's inertial parameters with ``payload`` fixed to its platform (the module
    docstring): the platform's mass, centre of mass and inertia replaced by those of the
    platform and the payload as one rigid body; ``inertia`` itself when the payload is
    empty (the very same object: no payload, no change).

    Args:
        inertia: The robot's parameters (platform frame, SI units).
        payload: The payload.
    """
    if payload.empty:
        return inertia
    m_p, m_l = inertia.platform_mass, payload.mass
    c_p = np.asarray(inertia.platform_com, dtype=float)
    c_l = np.asarray(payload.com, dtype=float)
    mass = m_p + m_l
    com = (m_p * c_p + m_l * c_l) / mass
    tensor = (inertia.platform_tensor + _steiner(m_p, c_p - com)
              + inertia_matrix(payload.inertia) + _steiner(m_l, c_l - com))
    tensor = 0.5 * (tensor + tensor.T)
    return inertia.replace(platform_mass=mass, platform_com=com, platform_inertia=_six(tensor))


def model_payload(payload: Payload, mass_error_percent: float) -> Payload:
    """A model of ``payload`` whose mass is off by ``mass_error_percent`` [%]: the true
    mass times ``1 + e / 100``, its inertia alike (the same body, another density; -100:
    a model that does not know of the payload)."""
    if mass_error_percent == 0.0 or payload.empty:
        return payload
    return payload.with_mass(payload.mass * (1.0 + 1e-2 * mass_error_percent))
