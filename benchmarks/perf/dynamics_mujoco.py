"""The same closed chain in MuJoCo, for ``hexapod-bench perf dynamics --mujoco`` (optional).

MuJoCo is not a dependency of the project: this module is imported only when the
figure is asked for, and says so when ``mujoco`` is missing. The model mirrors
:mod:`hexapod.model`: the platform on a free joint; per leg a body on a ball joint at
``A_i`` (oriented along the leg's home direction) and a rod on a slide joint along it;
six ``connect`` equality constraints between a site at each rod's tip and a site at
``B_i`` on the platform; no contacts. MuJoCo's equality constraints are soft
(``solref``/``solimp``), so its accelerations differ from the rigid ones by the
constraint softness (the table gives the difference).
"""

from __future__ import annotations

import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.model import build_model


def _vec(x: np.ndarray | tuple[float, ...]) -> str:
    return " ".join(f"{float(v):.17g}" for v in np.ravel(x))


def _quat(R: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation matrix."""
    import pinocchio as pin

    q = pin.Quaternion(np.asarray(R)).coeffs()  # x, y, z, w
    return np.array([q[3], q[0], q[1], q[2]])


def mjcf(geometry: HexapodGeometry) -> str:
    """The MJCF text of the robot (inertia from ``geometry.inertia``)."""
    hm = build_model(geometry)
    ine = geometry.inertia
    p = ine.platform_inertia
    legs, sites, eqs = [], [], []
    for i in range(6):
        body_i = (ine.body_inertia[0], ine.body_inertia[0], ine.body_inertia[1])
        rod_i = (ine.rod_inertia[0], ine.rod_inertia[0], ine.rod_inertia[1])
        legs.append(f"""
    <body name="leg{i}_body" pos="{_vec(geometry.base_points[i])}"
          quat="{_vec(_quat(hm.home_rotations[i]))}">
      <joint name="leg{i}_ball" type="ball" damping="0"/>
      <inertial pos="0 0 {ine.body_com:.17g}" mass="{ine.body_mass:.17g}"
                diaginertia="{_vec(body_i)}"/>
      <body name="leg{i}_rod">
        <joint name="leg{i}_slide" type="slide" axis="0 0 1" damping="0"/>
        <inertial pos="0 0 {-ine.rod_com:.17g}" mass="{ine.rod_mass:.17g}"
                  diaginertia="{_vec(rod_i)}"/>
        <site name="leg{i}_tip" pos="0 0 0"/>
      </body>
    </body>""")
        sites.append(f'<site name="B{i}" pos="{_vec(geometry.platform_points[i])}"/>')
        eqs.append(f'<connect site1="leg{i}_tip" site2="B{i}" solref="0.0002 1" '
                   'solimp="0.9999 0.9999 0.001"/>')
    full = (p[0], p[1], p[2], p[3], p[4], p[5])
    return f"""<mujoco model="hexapod">
  <option gravity="{_vec(ine.gravity)}" timestep="0.001" integrator="RK4"
          tolerance="1e-12" iterations="200"/>
  <worldbody>
    <body name="platform">
      <freejoint name="platform"/>
      <inertial pos="{_vec(ine.platform_com)}" mass="{ine.platform_mass:.17g}"
                fullinertia="{_vec(full)}"/>
      {' '.join(sites)}
    </body>{''.join(legs)}
  </worldbody>
  <equality>
    {' '.join(eqs)}
  </equality>
</mujoco>"""


class MujocoHexapod:
    """The closed chain in MuJoCo with the tree state taken from the Pinocchio reference.

    Args:
        geometry: The robot.
    """

    def __init__(self, geometry: HexapodGeometry) -> None:
        import mujoco

        self.mujoco = mujoco
        self.model = mujoco.MjModel.from_xml_string(mjcf(geometry))
        self.data = mujoco.MjData(self.model)
        self.slides = [self.model.joint(f"leg{i}_slide").dofadr[0] for i in range(6)]

    def set_state(self, hm_q: np.ndarray, hm_v: np.ndarray, R: np.ndarray,
                  twist: np.ndarray, forces: np.ndarray) -> None:
        """Copy a Pinocchio tree state (``ReferenceDynamics.state``) into MuJoCo.

        Pinocchio's free flyer is (x, y, z, qx, qy, qz, qw) with a LOCAL twist; MuJoCo's
        free joint is (x, y, z, qw, qx, qy, qz) with the world linear velocity and the
        local angular velocity. Spherical and ball joints both use the local angular
        velocity; the quaternions differ in order only.
        """
        d = self.data
        qpos = np.empty(self.model.nq)
        qvel = np.empty(self.model.nv)
        qpos[0:3] = hm_q[0:3]
        qpos[3:7] = hm_q[[6, 3, 4, 5]]
        qvel[0:3] = twist[:3]
        qvel[3:6] = hm_v[3:6]
        for i in range(6):
            src_q, dst_q = 7 + 5 * i, 7 + 5 * i
            qpos[dst_q:dst_q + 4] = hm_q[[src_q + 3, src_q, src_q + 1, src_q + 2]]
            qpos[dst_q + 4] = hm_q[src_q + 4]
            src_v, dst_v = 6 + 4 * i, 6 + 4 * i
            qvel[dst_v:dst_v + 4] = hm_v[src_v:src_v + 4]
        d.qpos[:] = qpos
        d.qvel[:] = qvel
        d.qfrc_applied[:] = 0.0
        d.qfrc_applied[self.slides] = forces

    def forward(self) -> None:
        """``mj_forward`` on the current state."""
        self.mujoco.mj_forward(self.model, self.data)

    def platform_acceleration(self, R: np.ndarray) -> np.ndarray:
        """``(dv/dt, dw/dt)`` in the base frame from the free joint's ``qacc``."""
        qacc = self.data.qacc
        return np.concatenate([qacc[0:3], R @ qacc[3:6]])
