"""The feature computed-torque laws' reference on the control grid
(:mod:`controllers.feature_ctc`): the anchored model features of many trials' references
at once (:func:`features_motion`: one observation of the model's edges and one call of
the features' motion, :mod:`controllers.solvers.reference_motion`, over all their
instants; rows are independent, so each trial's rows are the numbers of its own call),
and the rows sanitised for the compiled step (:func:`grid_rows`, :func:`sanitised`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from controllers.solvers.reference_motion import feature_motion, layouts
from controllers.tracking import anchored, model_goals

if TYPE_CHECKING:
    from controllers.feature_ctc import FeatureCTC

#: A unit vector standing in for a hidden leg's features (its rows are not used).
DUMMY = np.array([0.0, 0.0, 1.0])
DUMMY.flags.writeable = False


def features_motion(laws: list[FeatureCTC], times: list[np.ndarray]
                    ) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`FeatureCTC.motion_and_seen` of ``laws`` (one model world: camera and robot)
    at their ``times``, rows law after law: each reference sampled once with its end (a
    second past its duration), one observation of every pose and one call of the
    features' motion."""
    law0 = laws[0]
    ctx = law0.context
    assert ctx is not None
    feature, size = law0.observed_feature, law0.observed_feature.task_rows
    samples = []
    for law, t in zip(laws, times, strict=True):
        ref = law.reference
        assert ref is not None
        samples.append(ref.at(np.append(t, float(ref.duration) + 1.0)))
    model = model_goals(ctx, np.concatenate([s.rotation for s in samples]),
                        np.concatenate([s.translation for s in samples]),
                        fields=(law0.key,))[law0.key]
    count = np.array([len(t) for t in times])
    last = np.cumsum(count + 1) - 1  # each law's end
    ends = model[last]
    of = np.repeat(np.arange(len(laws)), count)  # each row's law
    moving = np.delete(model, last, axis=0)
    # the model's camera sees where the anchored features are finite
    taught = np.array([law.taught for law in laws])
    seen = np.isfinite(anchored(moving, ends[of], taught[of])).reshape(len(of), size)
    inputs = layouts(feature)[0]
    constants = np.empty((len(laws), inputs.size))
    v = inputs.views(constants)
    g = ctx.geometry
    # the taught features where finite, else the model's at the end
    v["taught"][:] = np.where(np.all(np.isfinite(taught), axis=-1)[..., None], taught,
                              ends).reshape(len(laws), -1)
    v["end"][:] = ends.reshape(len(laws), -1)
    v["frame"][:] = [np.concatenate([law.camera_frame.rotation.ravel(),
                                     law.camera_frame.translation]) for law in laws]
    v["points"][:] = (g.base_points, g.platform_points)
    v["radius"][:] = g.leg_radius
    rows = constants[of]
    poses = []
    for law, s in zip(laws, samples, strict=True):
        R, t, tw, twr = law.anchor(s.rotation[:-1], s.translation[:-1], s.twist[:-1],
                                   s.twist_rate[:-1])
        poses.append(np.concatenate([R.reshape(len(t), 9), t, tw, twr], axis=1))
    inputs.views(rows)["reference"][:] = np.concatenate(poses)
    out = feature_motion(feature).batch(rows, lanes=True, overwrite=True)
    return out.reshape(len(of), 3, size), seen


def grid_rows(out: np.ndarray, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                           np.ndarray]:
    """Grid rows from :meth:`FeatureCTC.motion_and_seen` ``out`` (n, 3, m), ``seen`` (n, m):
    the rows sanitised (n, 3 m) (:func:`sanitised_rows`, in ``out``), those known
    (n, m) and whether they all are (n,) (row by row: any rows give each its own)."""
    n, _, m = out.shape
    rows = out.reshape(n, 3 * m)
    if seen.all() and np.isfinite(rows).all():  # the common case: all known
        return rows, np.ones((n, m), dtype=bool), np.ones(n, dtype=bool)
    known = np.repeat(seen.reshape(n, -1, 3).all(axis=2) & np.isfinite(
        out).reshape(n, 3, -1, 3).all(axis=(1, 3)), 3, axis=1)
    every = np.all(known, axis=1)
    bad = np.flatnonzero(~every)  # rare: only these rows are sanitised
    rows[bad] = sanitised_rows(np.where(seen[bad, None, :], out[bad], np.nan))[0]
    return rows, known, every


def sanitised(ref: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(3, m) desired features, rates and accelerations -> (3 m,) with every unit vector
    having a non-finite value replaced by a unit vector at rest, and the rows kept (None:
    all)."""
    known = np.repeat(np.isfinite(ref).reshape(3, -1, 3).all(axis=(0, 2)), 3)
    if known.all():
        return np.ascontiguousarray(ref).ravel(), None
    out = np.where(known, ref, 0.0)
    out[0] = np.where(known, out[0], np.tile(DUMMY, known.size // 3))
    return out.ravel(), known


def sanitised_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sanitised` of every row of ``rows`` (n, 3, m) at once: the sanitised rows
    (n, 3 m) and their rows kept (n, m)."""
    n, _, m = rows.shape
    known = np.repeat(np.isfinite(rows).reshape(n, 3, -1, 3).all(axis=(1, 3)), 3, axis=1)
    out = np.where(known[:, None, :], rows, 0.0)
    out[:, 0] = np.where(known, out[:, 0], np.tile(DUMMY, m // 3))
    return out.reshape(n, 3 * m), known


__all__ = ["DUMMY", "features_motion", "grid_rows", "sanitised", "sanitised_rows"]
