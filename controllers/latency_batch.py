"""Latency compensation over many trials at once (``reset_batch`` / ``step_batch``).

The batch form of :class:`controllers.latency.LatencyCompensated`: each trial keeps its
own encoder history (:class:`~controllers.latency.EncoderHistory`, one reading per row and
period, in Python), while the prediction of every row whose image is late is computed as
arrays: one nominal forward kinematics over the two poses of all those rows (the capture
instant and the control instant, warm-started per trial), one compiled observation of the
nominal robot at all those poses (each trial's estimated camera; the numpy observation
row by row for a camera the compiled core does not reproduce), the features moved by the
same function as the per-trial step. The wrapped law then steps every row in its own
batch (its ``step_batch``, or a per-trial loop). The rows are those of the per-trial
controller, to the last bit (tested).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from controllers.base import CommandBatch, ControllerContext, ObservationBatch
from controllers.goal_batch import GoalBatch


class BatchedLatency:
    """Mixin of :class:`~controllers.latency.LatencyCompensated`: ``reset_batch``,
    ``step_batch`` and ``retarget_batch``."""

    law_name: str
    use_rates: bool
    _law_options: dict[str, Any]

    # ------------------------------------------------------------------ reset
    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """The wrapped law's batch reset with the contexts; every history empty.

        Raises:
            ContextError: A context the law cannot use (as ``reset``).
        """
        from controllers.batch import batch_controller
        from controllers.latency import EncoderHistory
        from vision import fast_observe

        self._contexts = list(contexts)
        self._histories = [EncoderHistory(self.use_rates) for _ in self._contexts]
        #: The wrapped law's batch (its own ``step_batch``, or a per-trial loop).
        self.law_batch: Any = batch_controller(self.law_name, self._law_options)
        self.law_batch.reset_batch(self._contexts)
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

    # ------------------------------------------------------------------ retarget
    def retarget_batch(self, trials: np.ndarray, goals: GoalBatch) -> None:
        """New goals for the law of some trials (the histories stay)."""
        from controllers.tracking import retarget

        batch = getattr(self.law_batch, "retarget_batch", None)
        if callable(batch):
            batch(trials, goals)
            return
        for j, k in enumerate(np.asarray(trials, dtype=int).tolist()):
            self._contexts[k] = replace(self._contexts[k], goal=goals.item(j))
            retarget(self.law_batch.controllers[k], self._contexts[k])

    # ------------------------------------------------------------------ step
    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """Every row's reading recorded, the late images' features predicted at the
        control instant, then one step of the law's batch."""
        obs = observations
        trials = np.asarray(obs.trials, dtype=int)
        late: list[int] = []
        before: list[np.ndarray] = []
        for j, k in enumerate(trials.tolist()):
            row = obs.item(j)
            history = self._histories[k]
            history.record(row)
            if (history.predicts(row) and obs.normals is not None
                    and self._contexts[k].camera is not None):
                late.append(j)
                before.append(history.lengths_at(float(row.image_t)))  # type: ignore[arg-type]
        if late:
            obs = self._predicted(obs, trials, np.array(late), np.array(before))
        return self.law_batch.step_batch(obs)  # type: ignore[no-any-return]

    def _predicted(self, obs: ObservationBatch, trials: np.ndarray, rows: np.ndarray,
                   before: np.ndarray) -> ObservationBatch:
        """The batch with the features of ``rows`` moved from their capture instants
        (encoder lengths ``before``, (m, 6)) to their control instants."""
        from controllers.latency import move_normals
        from hexapod.fk import forward_kinematics_batch
        from hexapod.workspace import home_pose
        from vision.legs import directions_from_edges

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
        pairs = np.stack([2 * keep, 2 * keep + 1], axis=1).reshape(-1)
        model = self._batch_model_normals(tr, sol.rotations[pairs], sol.translations[pairs])
        assert obs.normals is not None
        normals, _ = move_normals(np.asarray(obs.normals, dtype=float)[rows],
                                  model[1::2] - model[0::2])
        out_normals = np.array(obs.normals, dtype=float)
        out_normals[rows] = normals
        out_lines = obs.lines
        if out_lines is not None:
            out_lines = np.array(out_lines, dtype=float)
            for i, k in enumerate(tr.tolist()):
                camera = self._contexts[k].camera
                if getattr(camera, "kind", None) == "perspective":
                    with np.errstate(invalid="ignore"):
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
        return replace(obs, normals=out_normals, lines=out_lines, directions=out_dirs,
                       image_t=image_t)

    def _batch_model_normals(self, trials: np.ndarray, R: np.ndarray, t: np.ndarray
                       ) -> np.ndarray:
        """(2m, 6, 2, 3) the normals each trial's estimated camera sees of its nominal
        robot at the pose pairs ``R`` (2m, 3, 3), ``t`` (2m, 3) of ``trials`` (m,)."""
        from vision import fast_observe
        from vision.legs import observe_legs

        out = np.empty((len(R), 6, 2, 3))
        pair_trials = np.repeat(trials, 2)
        groups = self._group[pair_trials]
        for g in np.unique(groups).tolist():
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
