"""The standard dynamic parameters of the hexapod, in which its dynamics are linear.

The model of :mod:`hexapod.dynamics.compiled` is written with masses, centres of mass
and inertias about the centres of mass; its equations are linear in

- the platform's 10 standard parameters (Khalil and Dombre): mass ``m_p``, first moments
  ``m_p c`` (platform frame) [kg m] and the inertia about the platform *origin*,
  ``I_O = I_c + m_p (|c|^2 I - c c^T)`` (platform axes) [kg m^2];
- 8 parameters shared by the six legs: the body's mass, first moment about ``A_i``
  ``m_b d_b``, transverse inertia about ``A_i`` ``i_b + m_b d_b^2`` and axial inertia;
  the rod's mass, first moment about ``B_i`` ``m_r d_r``, transverse inertia about
  ``B_i`` ``i_r + m_r d_r^2`` and axial inertia;
- per drive (6 x 3): the reflected rotor inertia [kg], viscous [N s/m] and Coulomb [N]
  friction.

:data:`STANDARD_NAMES` orders them. Which of them the leg forces can reveal is for
:mod:`.base` to say (several cannot: e.g. the axial inertias never enter).
"""

from __future__ import annotations

import numpy as np

from hexapod.dynamics.drives import DriveParameters
from hexapod.dynamics.inertia import InertiaParameters, inertia_matrix
from hexapod.exceptions import InertiaError

PLATFORM_NAMES = ("m_p", "mx_p", "my_p", "mz_p", "Ixx_p", "Iyy_p", "Izz_p", "Ixy_p",
                  "Ixz_p", "Iyz_p")
LEG_NAMES = ("m_b", "md_b", "It_b", "Ia_b", "m_r", "md_r", "It_r", "Ia_r")
DRIVE_NAMES = tuple(f"{k}_{i}" for i in range(6) for k in ("rotor", "viscous", "coulomb"))
#: Every standard parameter, in the order of the regressor's columns.
STANDARD_NAMES = PLATFORM_NAMES + LEG_NAMES + DRIVE_NAMES
#: Units of the standard parameters (by name prefix).
UNITS = {"m_p": "kg", "mx_p": "kg m", "my_p": "kg m", "mz_p": "kg m", "m_b": "kg",
         "md_b": "kg m", "m_r": "kg", "md_r": "kg m", "rotor": "kg", "viscous": "N s/m",
         "coulomb": "N"}
#: Number of mechanism (rigid-body) parameters, then of drive parameters.
N_MECHANISM = len(PLATFORM_NAMES) + len(LEG_NAMES)
N_STANDARD = len(STANDARD_NAMES)


def unit(name: str) -> str:
    """The SI unit of a standard parameter."""
    if name in UNITS:
        return UNITS[name]
    prefix = name.split("_")[0]
    return UNITS.get(prefix, "kg m^2")


def standard_vector(inertia: InertiaParameters, drives: DriveParameters) -> np.ndarray:
    """The standard parameters (:data:`N_STANDARD`,) of a robot file's tables."""
    m, c = inertia.platform_mass, np.asarray(inertia.platform_com, float)
    I_o = inertia.platform_tensor + m * (c @ c * np.eye(3) - np.outer(c, c))
    platform = [m, *(m * c), I_o[0, 0], I_o[1, 1], I_o[2, 2], I_o[0, 1], I_o[0, 2], I_o[1, 2]]
    mb, db, (ib, ab) = inertia.body_mass, inertia.body_com, inertia.body_inertia
    mr, dr, (ir, ar) = inertia.rod_mass, inertia.rod_com, inertia.rod_inertia
    legs = [mb, mb * db, ib + mb * db**2, ab, mr, mr * dr, ir + mr * dr**2, ar]
    drive = np.stack([drives.rotor_inertia, drives.viscous, drives.coulomb], axis=1).ravel()
    return np.concatenate([platform, legs, drive])


def to_tables(theta: np.ndarray, template: InertiaParameters, drives: DriveParameters,
              source: str | None = None) -> tuple[InertiaParameters, DriveParameters]:
    """The ``[inertia]`` and ``[drives]`` tables of standard parameters ``theta``.

    Centres of mass and inertias about them follow from the first moments and the
    inertias about the origin/hinges; a massless leg part keeps ``template``'s centre of
    mass. Gravity, force limits, encoders, mode and bandwidth are kept from the templates.

    Raises:
        InertiaError: The parameters describe no rigid body (a non-positive platform
            mass, a tensor not positive definite), naming the key.
    """
    th = np.asarray(theta, float)
    m = th[0]
    if not m > 0:
        raise InertiaError("inertia.platform_mass", f"identified platform mass {m} kg is not "
                           "positive", source)
    c = th[1:4] / m
    six = th[4:10]
    I_o = inertia_matrix(six)
    I_c = I_o - m * (c @ c * np.eye(3) - np.outer(c, c))
    mb, mdb, itb, iab, mr, mdr, itr, iar = th[10:18]

    def part(mass: float, first: float, transverse: float, axial: float, default_com: float
             ) -> tuple[float, float, np.ndarray]:
        if mass <= 0:
            return 0.0, default_com, np.zeros(2)
        d = first / mass
        return mass, d, np.array([transverse - mass * d**2, axial])

    mb, db, ib = part(mb, mdb, itb, iab, template.body_com)
    mr, dr, ir = part(mr, mdr, itr, iar, template.rod_com)
    inertia = template.replace(
        platform_mass=m, platform_com=c,
        platform_inertia=np.array([I_c[0, 0], I_c[1, 1], I_c[2, 2], I_c[0, 1], I_c[0, 2],
                                   I_c[1, 2]]),
        body_mass=mb, body_com=db, body_inertia=ib, rod_mass=mr, rod_com=dr,
        rod_inertia=ir, source=source)
    d = th[N_MECHANISM:].reshape(6, 3)
    new_drives = drives.replace(rotor_inertia=np.maximum(d[:, 0], 0.0),
                                viscous=np.maximum(d[:, 1], 0.0),
                                coulomb=np.maximum(d[:, 2], 0.0), source=source)
    return inertia, new_drives
