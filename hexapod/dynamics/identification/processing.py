"""From what a robot measures to the identification model's samples.

The encoders' leg lengths (quantised) are low-pass filtered with a zero-phase
Butterworth filter (``scipy.signal.filtfilt``, order 4: no delay) and differentiated by
central differences; the measured forces go through the *same* filter (parallel
filtering: model and measurement see the same frequency response), and both are
decimated to twice the cutoff so that the residuals of the kept samples are nearly
independent (Gautier's parallel decimation). The platform's pose comes from the filtered
lengths by the forward kinematics, its twist and acceleration from the legs' rates
(``tau = K^-1 q_dot``, ``tau_dot = K^-1 (q_ddot - K_dot tau)``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal

from hexapod.dynamics.model import DynamicModel
from hexapod.exceptions import IdentificationError
from hexapod.fk import forward_kinematics_batch
from hexapod.geometry import HexapodGeometry
from hexapod.workspace import home_pose

#: Default cutoff of the zero-phase filter [Hz].
DEFAULT_CUTOFF_HZ = 50.0
#: Leg equations with the leg slower than this are not used [m/s]: around a reversal the
#: Coulomb model (and a real drive's stick-slip) is least reliable.
DEFAULT_MIN_SPEED = 2e-3
#: Time dropped at each end (the filter's and the differences' edges) [s].
EDGE_S = 0.25


@dataclass
class Samples:
    """The identification model's inputs at the kept instants.

    Attributes:
        time: (N,) [s].
        R, t, twist, acc: Platform pose, twist and acceleration (N, ...).
        forces: (N, 6) filtered measured forces [N].
        lengths: (N, 6) filtered leg lengths [m].
        rates: (N, 6) leg rates [m/s] (filtered, differentiated).
    """

    time: np.ndarray
    R: np.ndarray
    t: np.ndarray
    twist: np.ndarray
    acc: np.ndarray
    forces: np.ndarray
    lengths: np.ndarray
    rates: np.ndarray

    def mask(self, min_speed: float = DEFAULT_MIN_SPEED) -> np.ndarray:
        """(N, 6) the leg equations whose leg moves at least ``min_speed`` [m/s]."""
        return np.abs(self.rates) >= min_speed  # type: ignore[no-any-return]


def samples(geometry: HexapodGeometry, time_step: float, lengths: np.ndarray,
            forces: np.ndarray, cutoff_hz: float = DEFAULT_CUTOFF_HZ) -> Samples:
    """Filter, differentiate and decimate a record (module docstring).

    Args:
        geometry: The robot (kinematics).
        time_step: Sampling period of the record [s].
        lengths: (N, 6) encoder leg lengths [m].
        forces: (N, 6) measured leg forces [N].
        cutoff_hz: Cutoff of the zero-phase filter [Hz], below the Nyquist frequency.

    Raises:
        IdentificationError: Shapes, a cutoff above Nyquist, a record too short, or
            lengths without a pose (naming the sample).
    """
    q = np.asarray(lengths, float)
    f = np.asarray(forces, float)
    if q.ndim != 2 or q.shape[1] != 6 or f.shape != q.shape:
        raise IdentificationError(f"lengths and forces: expected two (N, 6) arrays, got "
                                  f"{q.shape} and {f.shape}")
    for name, values, unit in (("length", q, "m"), ("force", f, "N")):
        if not np.all(np.isfinite(values)):
            k, leg = (int(x) for x in np.argwhere(~np.isfinite(values))[0])
            raise IdentificationError(f"sample {k}: the {name} of leg {leg} is "
                                      f"{values[k, leg]} [{unit}], not a finite value")
    nyquist = 0.5 / time_step
    if not 0 < cutoff_hz < nyquist:
        raise IdentificationError(f"cutoff {cutoff_hz} Hz must be in (0, {nyquist:g}) Hz "
                                  f"(the Nyquist frequency of a {time_step * 1e3:g} ms record)")
    edge = int(np.ceil(EDGE_S / time_step))
    if q.shape[0] < 4 * edge + 20:
        raise IdentificationError(f"record of {q.shape[0]} samples ({q.shape[0] * time_step:g} s)"
                                  f" is too short: at least {4 * edge + 20} samples "
                                  f"({(4 * edge + 20) * time_step:g} s; the filter drops "
                                  f"{EDGE_S:g} s at each end)")
    b, a = scipy.signal.butter(4, cutoff_hz / nyquist)
    qf = scipy.signal.filtfilt(b, a, q, axis=0)
    ff = scipy.signal.filtfilt(b, a, f, axis=0)
    qd = np.gradient(qf, time_step, axis=0)
    qdd = np.gradient(qd, time_step, axis=0)
    step = max(1, int(np.floor(nyquist / cutoff_hz)))
    keep = np.arange(edge, q.shape[0] - edge, step)
    R0, t0 = home_pose(geometry)
    n = keep.size
    fk = forward_kinematics_batch(geometry, qf[keep], np.broadcast_to(R0, (n, 3, 3)).copy(),
                                  np.broadcast_to(t0, (n, 3)).copy())
    if not np.all(fk.converged):
        bad = int(keep[np.argmin(fk.converged)])
        raise IdentificationError(f"leg lengths {np.round(qf[bad] * 1e3, 3).tolist()} mm at "
                                  f"sample {bad} have no pose (forward kinematics)")
    R, t = fk.rotations, fk.translations
    model = DynamicModel(geometry)
    _, _, K, _, _ = model.terms_batch(R, t, np.zeros((n, 6)))
    twist = np.linalg.solve(K, qd[keep][..., None])[..., 0]
    _, bias = model.legs_batch(R, t, twist)
    acc = np.linalg.solve(K, (qdd[keep] - bias)[..., None])[..., 0]
    return Samples(keep * time_step, R, t, twist, acc, ff[keep], qf[keep], qd[keep])
