"""The camera's clock (``[clock]``, ``docs/scenarios.md``, "The camera's clock"): frames at
their own rate, delivered after a latency, with timestamp jitter; the encoders are read
at every control period.

Frame ``k`` is captured at ``c_k = k / frame_rate + j_k`` (the jitter ``j_k``: normal,
``jitter_ms``, clipped to +-0.45 frame so that frames stay in order, drawn from the
trial's stream 5) and delivered at ``c_k + latency``; at ``tau = step dt`` the controller
gets the newest frame delivered (again until the next), its capture time as ``image_t``.
The image shows the true robot at ``c_k``: the true lengths interpolated between the two
control instants around it (exact in the kinematic world) and their forward kinematics,
warm-started at the earlier instant (a frame on a control instant takes that instant's
pose, bit for bit); frames before 0 see the start pose. With an exposure ``T`` the
sensor gets the poses at the midpoints of ``exposure_samples`` slices of
``[c_k - T, c_k]`` and ``image_t`` is ``c_k - T / 2``. Without a clock (or a camera at
the control rate without latency) the measurement is the one the engines make without.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from benchmarks.sim.inputs import SimScenario
from benchmarks.sim.sensors import camera_batch
from benchmarks.sim.world import TrialSetup, trial_rng
from controllers.base import ObservationBatch
from hexapod.fk import pack_rows, set_guesses, solve_rows

#: The random stream of a trial's frame-time jitter.
JITTER_STREAM = 5
#: Largest jitter, as a fraction of the frame period (frames stay in order).
MAX_JITTER_FRACTION = 0.45
#: Capture times closer than this to a control instant are that instant [s].
INSTANT = 1e-9

#: A sensor: ``(rows, R, t) ->`` the camera's batch of ``rows`` at poses ``R``, ``t``.
Measure = Callable[[np.ndarray, np.ndarray, np.ndarray], ObservationBatch]
#: The fields of a frame kept until the next one arrives.
FRAME_FIELDS = ("normals", "lines", "directions", "edge_visible", "direction_visible")


def clock_active(sc: SimScenario) -> bool:
    """Whether the scenario's camera has a clock of its own (see the module docstring)."""
    c = getattr(sc, "clock", None)
    return c is not None and (c.frame_rate_hz > 0 or c.latency_ms > 0 or c.latency_frames > 0
                              or c.jitter_ms > 0 or c.exposure_ms > 0)


class CameraClock:
    """The frames of a group of trials (index = row of the group).

    Args:
        sc: The scenario (``sc.clock``, ``sc.dt``, ``sc.task.max_steps``).
        group: The trials (their indices seed the jitter).
        q, R, t: The plant's true state (read at every period).
        base_points, platform_points: (6, 3) or (N, 6, 3) true robots' points [m].
    """

    def __init__(self, sc: SimScenario, group: list[TrialSetup], q: np.ndarray, R: np.ndarray,
                 t: np.ndarray, base_points: np.ndarray, platform_points: np.ndarray) -> None:
        c = sc.clock
        n = len(group)
        self.dt = sc.dt
        self.q, self.R, self.t = q, R, t
        # (a camera triggered by the controller: frames counted at the control rate)
        self.period = 1.0 / c.frame_rate_hz if c.frame_rate_hz > 0 else sc.dt
        self.latency = 1e-3 * c.latency_ms + c.latency_frames * self.period
        run = sc.task.max_steps * sc.dt
        before = math.ceil(self.latency / self.period) + 2  # frames captured before 0
        count = before + math.ceil(run / self.period) + 2
        k = np.arange(count) - before
        capture = np.tile(k * self.period, (n, 1))
        if c.jitter_ms > 0:
            limit = MAX_JITTER_FRACTION * self.period
            for m, s in enumerate(group):
                rng = trial_rng(sc.seed, s.trial, JITTER_STREAM)
                capture[m] += np.clip(1e-3 * c.jitter_ms * rng.standard_normal(count),
                                      -limit, limit)
        self.capture = capture
        self.delivered = capture + self.latency
        self.exposure = 1e-3 * c.exposure_ms
        self.samples = c.exposure_samples
        depth = math.ceil((self.latency + self.exposure + 2.0 * self.period) / self.dt) + 3
        self.depth = depth
        self.hist_q = np.repeat(q[:, None], depth, axis=1)
        self.hist_R = np.repeat(R[:, None], depth, axis=1)
        self.hist_t = np.repeat(t[:, None], depth, axis=1)
        self.frame = np.full(n, -1)  # index into ``capture`` of each row's current frame
        self.cache: dict[str, np.ndarray | None] = {}
        self._rows = pack_rows(R, t, q, base_points, platform_points)

    def measure(self, step: int, idx: np.ndarray, measure: Measure) -> ObservationBatch:
        """The camera's batch the active rows ``idx`` receive at ``tau = step dt`` (their
        state is at ``tau``), with ``image_t`` (n,) the capture times [s]; ``measure``
        is the sensor (:data:`Measure`: a frame's noise is drawn when it is measured)."""
        slot = step % self.depth
        self.hist_q[idx, slot] = self.q[idx]
        self.hist_R[idx, slot] = self.R[idx]
        self.hist_t[idx, slot] = self.t[idx]
        tau = step * self.dt
        newest = np.array([np.searchsorted(self.delivered[m], tau + INSTANT, side="right") - 1
                           for m in idx.tolist()], dtype=int)
        new = newest != self.frame[idx]
        rows = idx[new]
        if len(rows):
            c = self.capture[rows, newest[new]]
            R_c, t_c = self._exposed_poses(rows, c, step)
            m = measure(rows, R_c, t_c)
            self._store(rows, m, len(self.q))
            self.frame[rows] = newest[new]
        frame = {k: (None if v is None else v[idx]) for k, v in self.cache.items()}
        return camera_batch(**frame,  # type: ignore[arg-type]
                            image_t=self.capture[idx, self.frame[idx]] - 0.5 * self.exposure)

    def _exposed_poses(self, rows: np.ndarray, c: np.ndarray, step: int
                       ) -> tuple[np.ndarray, np.ndarray]:
        """The true poses of the frames of ``rows`` captured at ``c``: (n, 3, 3), (n, 3)
        without exposure, else (n, S, 3, 3), (n, S, 3) at the midpoints of ``S`` slices
        of ``[c - T, c]``."""
        if self.exposure <= 0:
            return self._poses_at(rows, c, step)
        T, S = self.exposure, self.samples
        poses = [self._poses_at(rows, c - T + T * (j + 0.5) / S, step) for j in range(S)]
        return (np.stack([p[0] for p in poses], axis=1),
                np.stack([p[1] for p in poses], axis=1))

    def _store(self, rows: np.ndarray, m: ObservationBatch, n: int) -> None:
        """Keep the new frames of ``rows`` until the next ones."""
        for key in FRAME_FIELDS:
            value = getattr(m, key)
            if value is None:
                self.cache.setdefault(key, None)
                continue
            arr = np.asarray(value)
            if self.cache.get(key) is None:
                self.cache[key] = np.zeros((n, *arr.shape[1:]), dtype=arr.dtype)
            self.cache[key][rows] = arr  # type: ignore[index]

    def _poses_at(self, rows: np.ndarray, c: np.ndarray, step: int
                  ) -> tuple[np.ndarray, np.ndarray]:
        """True poses of ``rows`` at capture times ``c`` (<= ``step dt``)."""
        s0 = np.floor((c + INSTANT) / self.dt).astype(int)
        s0 = np.minimum(s0, step)
        frac = (c - s0 * self.dt) / self.dt
        before = s0 < 0  # the robot at rest at its start pose
        s0 = np.maximum(s0, 0)
        frac = np.where(before, 0.0, frac)
        a = s0 % self.depth
        b = np.minimum(s0 + 1, step) % self.depth
        q0, q1 = self.hist_q[rows, a], self.hist_q[rows, b]
        R = self.hist_R[rows, a].copy()
        t = self.hist_t[rows, a].copy()
        between = np.abs(frac) * self.dt > INSTANT
        if between.any():
            j = np.flatnonzero(between)
            x = self._rows[rows[j]]
            set_guesses(x, R[j], t[j], q0[j] + frac[j, None] * (q1[j] - q0[j]))
            sol = solve_rows(x)
            ok = sol.converged  # a failure keeps the earlier instant's pose
            R[j[ok]] = sol.rotations[ok]
            t[j[ok]] = sol.translations[ok]
        return R, t

