"""A simulated robot: leg lengths integrate the clamped velocity commands exactly."""

from __future__ import annotations

import numpy as np

from hexapod.backends.base import Backend, BackendStep, HaltReport, clamp_velocities
from hexapod.exceptions import ShapeError, StrokeLimitError
from hexapod.geometry import HexapodGeometry


class SimulatedRobot(Backend):
    """An ideal robot: each leg length moves by the clamped velocity times dt.

    Args:
        geometry: The TRUE geometry (strokes and speed limit are taken from it).
        lengths: Initial leg lengths [m] (mid-stroke if None).
        joint_offsets: (6,) encoder offsets [m]: measured = true + offset.
    """

    simulated = True

    def __init__(self, geometry: HexapodGeometry, lengths: np.ndarray | None = None,
                 joint_offsets: np.ndarray | None = None) -> None:
        self.geometry = geometry
        self.stroke = geometry.stroke
        self.max_speed = geometry.max_speed
        self.joint_offsets = np.zeros(6) if joint_offsets is None else np.asarray(
            joint_offsets, float)
        self._q = np.full(6, geometry.q_mid)
        self.reset(lengths)

    @property
    def true_lengths(self) -> np.ndarray:
        """The true leg lengths (6,) [m] (what the forward kinematics of the world uses)."""
        return self._q.copy()

    def reset(self, lengths: np.ndarray | None = None) -> np.ndarray:
        """Set the true leg lengths (checked against the stroke) and return the measured ones."""
        if lengths is not None:
            q = np.asarray(lengths, dtype=float)
            if q.shape != (6,) or not np.all(np.isfinite(q)):
                raise ShapeError("lengths", "6 finite leg lengths [m]", q)
            for i, x in enumerate(q):
                if not self.stroke[0] - 1e-12 <= x <= self.stroke[1] + 1e-12:
                    raise StrokeLimitError(i, float(x), *self.stroke)
            self._q = q.copy()
        return self.measured_lengths()

    def step(self, velocities: np.ndarray, dt: float) -> BackendStep:
        """Apply the clamped velocities for ``dt`` [s]."""
        v = np.asarray(velocities, dtype=float)
        if v.shape != (6,):
            raise ShapeError("velocities", "shape (6,)", v.shape)
        vc, clamped = clamp_velocities(self._q, v, dt, self.stroke, self.max_speed)
        self._q = np.clip(self._q + vc * dt, *self.stroke)
        return BackendStep(self.measured_lengths(), vc, clamped)

    def halt_confirmed(self, timeout_s: float = 2.0) -> HaltReport:
        """A simulated robot moves only when stepped: it is stopped."""
        return HaltReport(True, "simulated robot: stopped")

    def measured_lengths(self) -> np.ndarray:
        """Encoder reading: true lengths plus the joint offsets [m]."""
        return self._q + self.joint_offsets
