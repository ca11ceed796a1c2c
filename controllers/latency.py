"""Latency compensation: a law fed the features predicted at the control instant.

The camera's image is older than the control instant (``Observation.image_t < t``: the
latency and the frame period, :mod:`benchmarks.sim.clock`), while the encoders are read
at the instant. :class:`LatencyCompensated` wraps any law and, before each step,
predicts the features over the delay with the NOMINAL model:

``s_pred = s_image + s_model(q(t)) - s_model(q(image_t))``

where ``s_model(q)`` is what the estimated camera would see of the nominal robot at the
forward kinematics of the encoder lengths ``q``, and ``q(image_t)`` is the linear
interpolation of the encoder readings around the capture time (the legs move at the
commanded, constant speed within a period in the kinematic world, so it is exact
there; before the first reading the robot rests at its first reading). Where the
readings carry the measured leg velocities (``Observation.q_dot``, the dynamic world,
whose legs accelerate within a period) the interpolation is the cubic Hermite one of
the lengths and their rates (``use_rates``). Edge normals
and leg directions are predicted and renormalised, image lines follow from the
predicted normals through the estimated camera. With an exact model the prediction is
the image the camera would take at ``t`` (tested); with a model error the error of the
prediction is that of the model's feature CHANGE over the delay, not of the features.

A feature the image does not show stays missing; where the model cannot predict (its
forward kinematics fails, or it predicts an edge the image shows as hidden) the image
feature is used as it is, and the command's notes say so.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import replace
from typing import Any

import numpy as np

from controllers.base import Command, Controller, ControllerContext, Goal, Observation
from controllers.batch import actuation_of
from controllers.latency_batch import BatchedLatency
from controllers.tracking import retarget

log = logging.getLogger(__name__)

#: Encoder readings kept (control periods): more than any latency studied.
HISTORY = 512


def move_normals(seen: np.ndarray, delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image normals (..., 6, 2, 3) moved by the model's change ``delta`` and
    renormalised (a NaN, unseen component stays; where the model's change is not finite
    the image normal is kept), and the mask (..., 6, 2) of finite changes."""
    delta_ok = np.all(np.isfinite(delta), axis=-1)
    with np.errstate(invalid="ignore"):
        moved = seen + np.where(delta_ok[..., None], delta, 0.0)
        moved /= np.linalg.norm(moved, axis=-1, keepdims=True)
    return np.where(np.isfinite(seen), moved, seen), delta_ok


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

    def clear(self) -> None:
        """Forget the readings and the warm start."""
        self.times.clear()
        self.lengths.clear()
        self.rates.clear()
        self.guess = None

    def record(self, observation: Observation) -> None:
        """Keep the reading of an observation with 6 finite lengths and a finite time (a
        time that goes back starts the history afresh)."""
        q = np.asarray(observation.lengths, dtype=float)
        t = float(observation.t)
        if q.shape == (6,) and np.all(np.isfinite(q)) and math.isfinite(t):
            if self.times and t <= self.times[-1]:
                self.times.clear()
                self.lengths.clear()
                self.rates.clear()
            self.times.append(t)
            self.lengths.append(q.copy())
            rate = None if observation.q_dot is None else np.array(observation.q_dot, float)
            ok = rate is not None and rate.shape == (6,) and bool(np.all(np.isfinite(rate)))
            self.rates.append(rate if ok else None)

    def predicts(self, observation: Observation) -> bool:
        """Whether the observation's image is older than its (recorded) control instant."""
        image_t = observation.image_t
        t = float(observation.t)
        return not (image_t is None or not math.isfinite(float(image_t))
                    or image_t >= t - 1e-12 or not self.times or self.times[-1] != t)

    def lengths_at(self, time: float) -> np.ndarray:
        """The encoder lengths at ``time``, interpolated between readings."""
        times = np.fromiter(self.times, dtype=float, count=len(self.times))
        j = int(np.searchsorted(times, time, side="right")) - 1
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


class LatencyCompensated(BatchedLatency, Controller):
    """A law whose image features are predicted over the image's delay (see the module
    docstring).

    Args:
        law: Registry name of the wrapped law.
        use_rates: Interpolate the lengths with their measured rates when the readings
            have them (cubic Hermite; False: linear).
        **options: The wrapped law's options.
    """

    name = "latency-compensated"

    def __init__(self, law: str = "leg-edge", use_rates: bool = True, **options: Any
                 ) -> None:
        from controllers.registry import registry

        self.law_name = str(law)
        self.law = registry.create(self.law_name, **options)
        self.features = frozenset(getattr(self.law, "features", frozenset())) | {"lengths"}
        self.actuation = actuation_of(self.law)
        #: A law that samples ``context.reference`` itself is passed through by
        #: :class:`~controllers.tracking.TrackingController`, and so is its wrapper.
        self.tracks_reference = bool(getattr(self.law, "tracks_reference", False))
        self.context: ControllerContext | None = None
        self.use_rates = bool(use_rates)
        self._law_options = dict(options)
        #: The encoder readings and the forward kinematics' warm start.
        self.history = EncoderHistory(self.use_rates)
        self._params: Any = None  # the model's packed observation parameters

    def reset(self, context: ControllerContext) -> None:
        """Reset the law; forget the encoder history."""
        self.law.reset(context)
        self.features = frozenset(getattr(self.law, "features", self.features)) | {"lengths"}
        self.context = context
        self.history.clear()
        self._params = None

    def retarget(self, goal: Goal) -> None:
        """A new goal for the law (a trajectory task); the encoder history stays."""
        if self.context is None:
            return
        self.context = replace(self.context, goal=goal)
        retarget(self.law, self.context)

    def step(self, observation: Observation) -> Command:
        """The law's command on the predicted features."""
        if self.context is None:
            return Command.refuse(f"{self.name}: reset(context) was not called",
                                  actuation=self.actuation)
        history = self.history
        history.record(observation)
        if not history.predicts(observation):
            return self.law.step(observation)  # type: ignore[no-any-return]
        predicted, note = self._predict(observation, float(observation.image_t))  # type: ignore[arg-type]
        cmd: Command = self.law.step(predicted)
        if note:
            cmd.notes.append(note)
        return cmd

    def _lengths_at(self, time: float) -> np.ndarray:
        """The encoder lengths at ``time``, interpolated between readings."""
        return self.history.lengths_at(time)

    def _model_normals(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(n, 6, 2, 3) edge normals the estimated camera sees of the nominal robot at
        poses ``R`` (n, 3, 3), ``t`` (n, 3): the compiled observation with the model's
        parameters packed once, else :func:`vision.legs.observe_legs`."""
        from vision import fast_observe
        from vision.legs import observe_legs

        ctx = self.context
        assert ctx is not None
        if self._params is None:
            camera = ctx.camera
            fast = (fast_observe.compiled() and getattr(camera, "kind", None) in (
                "perspective", "unified") and fast_observe.supported(camera))
            self._params = (fast_observe.WorldParams.from_worlds([ctx.geometry], [camera])
                            if fast else False)
        if self._params is False:
            return observe_legs(ctx.camera, ctx.geometry, R, t).normals  # type: ignore[no-any-return]
        obs = fast_observe.observe_batch(self._params, R, t, np.zeros(len(R), dtype=int))
        return obs.normals  # type: ignore[no-any-return]

    def _predict(self, obs: Observation, image_t: float) -> tuple[Observation, str | None]:
        """The observation with its features moved from ``image_t`` to ``obs.t``."""
        from hexapod.fk import forward_kinematics_batch
        from vision.legs import directions_from_edges

        ctx = self.context
        assert ctx is not None
        camera = ctx.camera
        if camera is None or obs.normals is None:
            return obs, "latency not compensated: no camera model or no edge normals"
        q = np.stack([self._lengths_at(image_t), np.asarray(obs.lengths, dtype=float)])
        guess_R = guess_t = None
        guess = self.history.guess
        if guess is not None:
            guess_R = np.repeat(guess[0][None], 2, axis=0)
            guess_t = np.repeat(guess[1][None], 2, axis=0)
        sol = forward_kinematics_batch(ctx.geometry, q, guess_R, guess_t)
        if not np.all(sol.converged):
            return obs, "latency not compensated: nominal forward kinematics failed"
        self.history.guess = (sol.rotations[1].copy(), sol.translations[1].copy())
        model_normals = self._model_normals(sol.rotations, sol.translations)
        normals, delta_ok = move_normals(np.asarray(obs.normals, dtype=float),
                                         model_normals[1] - model_normals[0])
        lines = obs.lines
        if lines is not None and getattr(camera, "kind", None) == "perspective":
            with np.errstate(invalid="ignore"):
                lines = camera.normal_to_line(normals)
        directions = obs.directions
        if directions is not None:
            both = np.asarray(obs.direction_visible, dtype=bool)
            with np.errstate(invalid="ignore"):
                directions = np.where(both[:, None], directions_from_edges(normals),
                                      np.asarray(directions, dtype=float))
        visible = np.asarray(obs.edge_visible, dtype=bool)
        note = None
        if np.any(visible & ~delta_ok):
            note = "latency not compensated for edges the model predicts hidden"
        return replace(obs, normals=normals, lines=lines, directions=directions,
                       image_t=obs.t), note
