"""Latency compensation: a law fed the features predicted at the control instant.

The camera's image is older than the control instant (``Observation.image_t < t``), while
the encoders are read at the instant. :class:`LatencyCompensated` wraps any law and,
before each step, predicts the features over the delay with the NOMINAL model:

``s_pred = s_image + s_model(q(t)) - s_model(q(image_t))``

where ``s_model(q)`` is what the estimated camera would see of the nominal robot at the
forward kinematics of the encoder lengths ``q``, and ``q(image_t)`` interpolates the
encoder readings around the capture time: linearly (exact in the kinematic world, whose
legs move at constant speed within a period), or cubic Hermite with the measured leg
velocities where the readings have them (``use_rates``; the dynamic world). Normals and
leg directions are renormalised, image lines follow from the normals through the
estimated camera. With an exact model the prediction is the image the camera would take
at ``t`` (tested); with a model error, the error is that of the model's feature CHANGE.

A feature the image does not show stays missing; where the model cannot predict (its
forward kinematics fails, or its change is not finite) the image feature is used as it is.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from controllers.base import (
    CommandBatch,
    Controller,
    ControllerContext,
    GoalBatch,
    Observation,
    ObservationBatch,
)
from controllers.batch import actuation_of
from controllers.exceptions import named_as
from controllers.law_tools import check_flag
from hexapod.fk import forward_kinematics_batch
from hexapod.workspace import home_pose
from vision.legs import directions_from_edges, observe_legs

log = logging.getLogger(__name__)

#: Encoder readings kept (control periods): more than any latency studied.
HISTORY = 512
#: The offsets of a pose pair's two rows (capture instant, control instant).
_PAIR = np.array([0, 1])


def move_normals(seen: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Image normals (..., 6, 2, 3) moved by the model's change ``delta`` and
    renormalised (an unseen NaN stays; the image normal where ``delta`` is not finite)."""
    delta_ok = np.all(np.isfinite(delta), axis=-1)
    with np.errstate(invalid="ignore"):
        moved = seen + np.where(delta_ok[..., None], delta, 0.0)
        moved /= np.linalg.norm(moved, axis=-1, keepdims=True)
    return np.where(np.isfinite(seen), moved, seen)


def _finite(values: np.ndarray) -> bool:
    """Whether every value of a small float array is finite (a Python loop over its
    values: cheaper than a numpy reduction for the six of one reading)."""
    return all(map(math.isfinite, values.ravel().tolist()))


class EncoderHistory:
    """The encoder readings of one trial (times, lengths, measured rates) and the last
    pose of the nominal forward kinematics (its warm start).

    Args:
        use_rates: Interpolate with the measured rates when both readings have them.
    """

    def __init__(self, use_rates: bool = True) -> None:
        self.use_rates = bool(use_rates)
        self.times: deque[float] = deque(maxlen=HISTORY)
        self.lengths: deque[np.ndarray] = deque(maxlen=HISTORY)
        self.rates: deque[np.ndarray | None] = deque(maxlen=HISTORY)
        #: The nominal pose at the last prediction's control instant, or None.
        self.guess: tuple[np.ndarray, np.ndarray] | None = None

    def record(self, observation: Observation) -> None:
        """Keep the reading of an observation with 6 finite lengths and a finite time (a
        time that goes back starts the history afresh)."""
        q = np.asarray(observation.lengths, dtype=float)
        t = float(observation.t)
        if q.shape == (6,) and _finite(q) and math.isfinite(t):
            if self.times and t <= self.times[-1]:
                self.times.clear()
                self.lengths.clear()
                self.rates.clear()
            self.times.append(t)
            self.lengths.append(q.copy())
            rate = None if observation.q_dot is None else np.array(observation.q_dot, float)
            ok = rate is not None and rate.shape == (6,) and _finite(rate)
            self.rates.append(rate if ok else None)

    def predicts(self, observation: Observation) -> bool:
        """Whether the observation's image is older than its (recorded) control instant."""
        image_t = observation.image_t
        t = float(observation.t)
        return not (image_t is None or not math.isfinite(float(image_t))
                    or image_t >= t - 1e-12 or not self.times or self.times[-1] != t)

    def lengths_at(self, time: float) -> np.ndarray:
        """The encoder lengths at ``time``, interpolated between readings (the last
        reading at or before ``time`` is found from the newest back: a capture instant
        is a few periods old)."""
        times = self.times
        j = len(times) - 1
        while j >= 0 and times[j] > time:
            j -= 1
        if j < 0:
            return np.array(self.lengths[0])
        if j >= len(times) - 1:
            return np.array(self.lengths[-1])
        a, b = self.lengths[j], self.lengths[j + 1]
        h = times[j + 1] - times[j]
        frac = (time - times[j]) / h
        va, vb = self.rates[j], self.rates[j + 1]
        if self.use_rates and va is not None and vb is not None:  # cubic Hermite
            s2, s3 = frac * frac, frac * frac * frac
            return ((2 * s3 - 3 * s2 + 1) * a + (s3 - 2 * s2 + frac) * h * va  # type: ignore[no-any-return]
                    + (3 * s2 - 2 * s3) * b + (s3 - s2) * h * vb)
        return a + frac * (b - a)  # type: ignore[no-any-return]


class LatencyCompensated(Controller):
    """A law whose image features are predicted over the image's delay (module
    docstring), over a batch: per-trial encoder histories; for all late rows at once one
    nominal forward kinematics of both instants, one compiled observation (the numpy one
    for a camera it does not reproduce); then the wrapped law's own batch step.

    Args:
        law: Registry name of the wrapped law.
        use_rates: Interpolate the lengths with their measured rates when the readings
            have them (cubic Hermite; False: linear).
        **options: The wrapped law's options.
    """

    name = "latency-compensated"

    def __init__(self, law: str = "leg-edge", use_rates: bool = True, **options: Any
                 ) -> None:
        from controllers.batch import batch_controller

        self.law_name = str(law)
        self.law = batch_controller(self.law_name, options)
        self.features = frozenset(getattr(self.law, "features", frozenset())) | {"lengths"}
        self.actuation = actuation_of(self.law)
        #: A law that samples ``context.reference`` itself is passed through by
        #: :class:`~controllers.tracking.TrackingController`, and so is its wrapper.
        self.tracks_reference = bool(getattr(self.law, "tracks_reference", False))
        self.use_rates = check_flag(self.name, "use_rates", use_rates)
        self._contexts: list[ControllerContext] = []
        self._histories: list[EncoderHistory] = []

    # ------------------------------------------------------------------ reset
    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """The wrapped law's batch reset with the contexts; every history empty.

        Raises:
            ContextError: A context the law cannot use.
        """
        from vision import fast_observe  # (imported when first needed, not with the registry)

        self._contexts = list(contexts)
        self._histories = [EncoderHistory(self.use_rates) for _ in self._contexts]
        with named_as(self.name):  # (the context is the user's of this controller)
            self.law.reset_batch(self._contexts)
        self.features = frozenset(getattr(self.law, "features", self.features)) | {"lengths"}
        self.trial_instances = [self] * len(self._contexts)
        n = len(self._contexts)
        # the compiled observation of each trial's nominal robot and estimated camera,
        # one parameter set per camera kind and image size (-1: the numpy observation)
        self._group = np.full(n, -1, dtype=int)
        self._item = np.zeros(n, dtype=int)
        self._batch_params: list[Any] = []
        keys: dict[tuple[Any, ...], list[int]] = {}
        compiled = fast_observe.compiled()
        for i, ctx in enumerate(self._contexts):
            cam = ctx.camera
            if (cam is not None and compiled and getattr(cam, "kind", None) in (
                    "perspective", "unified") and fast_observe.supported(cam)):
                keys.setdefault((cam.kind, int(cam.width), int(cam.height)), []).append(i)
        for members in keys.values():
            self._group[members] = len(self._batch_params)
            self._item[members] = np.arange(len(members))
            self._batch_params.append(fast_observe.WorldParams.from_worlds(
                [self._contexts[i].geometry for i in members],
                [self._contexts[i].camera for i in members]))

    def retarget_batch(self, trials: np.ndarray, goals: GoalBatch) -> None:
        """New goals for the law of some trials (the histories stay).

        Raises:
            ContextError: A goal the law cannot use, or no reset yet.
        """
        with named_as(self.name):
            self.law.retarget_batch(trials, goals)
        for j, k in enumerate(np.asarray(trials, dtype=int).tolist()):
            self._contexts[k] = replace(self._contexts[k], goal=goals.item(j))

    # ------------------------------------------------------------------ step
    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """Every row's reading recorded, the late images' features predicted at the
        control instant, then one step of the law's batch."""
        self.crashes = {}
        if (unreset := self.checked_batch(observations)) is not None:
            return unreset
        obs = observations
        trials = np.asarray(obs.trials, dtype=int)
        late: list[int] = []
        before: list[np.ndarray] = []
        histories = self._histories
        images = obs.image_t is not None and obs.normals is not None  # else none is late
        for j, k in enumerate(trials.tolist()):
            row = obs.item(j)
            history = histories[k]
            history.record(row)
            if images and history.predicts(row) and self._contexts[k].camera is not None:
                late.append(j)
                before.append(history.lengths_at(float(row.image_t)))  # type: ignore[arg-type]
        if late:
            obs = self._predicted(obs, trials, np.array(late), np.array(before))
        out = self.law.step_batch(obs)
        self.crashes = self.law.crashes  # the rows are the law's batch's
        return out

    def _predicted(self, obs: ObservationBatch, trials: np.ndarray, rows: np.ndarray,
                   before: np.ndarray) -> ObservationBatch:
        """The batch with the features of ``rows`` moved from their capture instants
        (encoder lengths ``before``, (m, 6)) to their control instants."""
        tr = trials[rows]
        m = len(rows)
        q = np.empty((2 * m, 6))
        q[0::2] = before
        q[1::2] = np.asarray(obs.lengths, dtype=float)[rows]
        R0 = np.empty((2 * m, 3, 3))
        t0 = np.empty((2 * m, 3))
        A = np.empty((2 * m, 6, 3))
        E = np.empty((2 * m, 6, 3))
        for i, k in enumerate(tr.tolist()):
            geo = self._contexts[k].geometry
            guess = self._histories[k].guess
            R0[2 * i:2 * i + 2], t0[2 * i:2 * i + 2] = (home_pose(geo) if guess is None
                                                        else guess)
            A[2 * i:2 * i + 2] = geo.base_points
            E[2 * i:2 * i + 2] = geo.platform_points
        sol = forward_kinematics_batch(self._contexts[int(tr[0])].geometry, q, R0, t0,
                                       base_points=A, platform_points=E)
        ok = sol.converged[0::2] & sol.converged[1::2]
        keep = np.flatnonzero(ok)
        if not len(keep):
            return obs
        for i in keep.tolist():
            self._histories[int(tr[i])].guess = (sol.rotations[2 * i + 1].copy(),
                                                 sol.translations[2 * i + 1].copy())
        rows, tr = rows[keep], tr[keep]
        pairs = (2 * keep[:, None] + _PAIR).reshape(-1)  # (2 keep, 2 keep + 1)
        model = self._batch_model_normals(tr, sol.rotations[pairs], sol.translations[pairs])
        assert obs.normals is not None
        normals = move_normals(np.asarray(obs.normals, dtype=float)[rows],
                                  model[1::2] - model[0::2])
        out_normals = np.array(obs.normals, dtype=float)
        out_normals[rows] = normals
        out_lines = obs.lines
        if out_lines is not None:
            out_lines = np.array(out_lines, dtype=float)
            with np.errstate(invalid="ignore"):
                for i, k in enumerate(tr.tolist()):
                    camera = self._contexts[k].camera
                    if getattr(camera, "kind", None) == "perspective":
                        out_lines[rows[i]] = camera.normal_to_line(normals[i])
        out_dirs = obs.directions
        if out_dirs is not None:
            out_dirs = np.array(out_dirs, dtype=float)
            both = np.asarray(obs.direction_visible, dtype=bool)[rows]
            with np.errstate(invalid="ignore"):
                out_dirs[rows] = np.where(both[..., None], directions_from_edges(normals),
                                          out_dirs[rows])
        image_t = None if obs.image_t is None else np.array(obs.image_t, dtype=float)
        if image_t is not None:
            image_t[rows] = np.asarray(obs.t, dtype=float)[rows]
        return ObservationBatch(obs.trials, obs.t, obs.lengths, out_normals, out_lines,
                                out_dirs, obs.edge_visible, obs.direction_visible, image_t,
                                obs.q_dot)

    def _batch_model_normals(self, trials: np.ndarray, R: np.ndarray, t: np.ndarray
                       ) -> np.ndarray:
        """(2m, 6, 2, 3) the normals each trial's estimated camera sees of its nominal
        robot at the pose pairs ``R`` (2m, 3, 3), ``t`` (2m, 3) of ``trials`` (m,)."""
        from vision import fast_observe

        out = np.empty((len(R), 6, 2, 3))
        pair_trials = np.repeat(trials, 2)
        groups = self._group[pair_trials]
        for g in sorted(set(groups.tolist())):
            at = np.flatnonzero(groups == g)
            if g < 0:  # pair by pair, as the per-trial step
                for i in at[0::2].tolist():
                    ctx = self._contexts[int(pair_trials[i])]
                    out[i:i + 2] = observe_legs(ctx.camera, ctx.geometry, R[i:i + 2],
                                                t[i:i + 2]).normals
            else:
                out[at] = fast_observe.observe_batch(self._batch_params[g], R[at], t[at],
                                                     self._item[pair_trials[at]]).normals
        return out
