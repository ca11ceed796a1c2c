"""The vision laws over many trials at once (``reset_batch`` / ``step_batch``).

Each trial keeps its own controller instance (the per-trial object, reset with the
trial's context), so that every case keeps exactly the per-trial behaviour. What
changes is the common case (every feature visible and finite, the CURRENT
interaction, a full-rank interaction matrix): there, the rows of all such trials go
through the law's compiled core in one C loop (:meth:`hexapod.compiled.CompiledFunction.batch`,
the same code as the per-trial :meth:`~controllers.laws.VisionLaw._step_compiled`),
and the per-trial state (measured directions, last twist, last lengths) is kept in
arrays. Any other row (a hidden or non-finite feature, a refusal, a QP whose
unconstrained optimum leaves a bound, a law without a compiled core) is stepped by
its own instance, whose state is loaded from the arrays before and saved after. The
results are those of the per-trial loop to the last bit (tested).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from controllers.base import CommandBatch, ControllerContext, ObservationBatch

#: Per-trial state of a vision law carried across steps (see ``VisionLaw``).
STATE = ("_directions", "_observed", "_u_now", "_tau_prev", "_q_prev")


#: Attribute values an instance may share with its copies (never changed in place).
_SHARED = (int, float, bool, str, bytes, frozenset, tuple, type(None))
#: The batch state of a controller (not copied into its per-trial instances): these
#: names, and any name that starts with ``_b_`` or ``_batch``.
BATCH_ATTRIBUTES = frozenset({"_trials", "_state", "_X", "_has_kernel", "_fn", "_slices",
                              "_outs"})


def _batch_attribute(name: str) -> bool:
    return name in BATCH_ATTRIBUTES or name.startswith(("_b_", "_batch"))


def fresh_copy(template: Any) -> Any:
    """A copy of a controller for one trial, independent of it for everything ``reset``
    and ``step`` change: its arrays copied, its immutable values and frozen dataclasses
    shared, anything else deep-copied, and its batch state left out
    (:data:`BATCH_ATTRIBUTES`: a controller reset as a batch before would otherwise
    copy every trial of that batch into each new one). ``copy.deepcopy`` of the whole
    object costs about ten times as much, mostly in its generic recursion."""
    return copier(template)()


def copier(template: Any) -> Callable[[], Any]:
    """:func:`fresh_copy` of ``template``, as a function to call once per trial (the
    attributes are sorted once)."""
    base = copy.copy(template)
    d = base.__dict__
    for k in [k for k in d if _batch_attribute(k)]:
        del d[k]
    arrays = [k for k, v in d.items() if isinstance(v, np.ndarray)]
    deep = [k for k, v in d.items()
            if not (isinstance(v, (np.ndarray, *_SHARED))
                    or getattr(getattr(v, "__dataclass_params__", None), "frozen", False))]

    def make() -> Any:
        inst = copy.copy(base)
        di = inst.__dict__
        for k in arrays:
            di[k] = di[k].copy()
        for k in deep:
            di[k] = copy.deepcopy(di[k])
        return inst

    return make


class BatchedLaw:
    """Mixin of :class:`~controllers.laws.VisionLaw`: ``reset_batch`` and ``step_batch``."""

    _kernel: Any
    _trials: list[Any]

    def reset(self, context: ControllerContext) -> None:  # provided by VisionLaw
        raise NotImplementedError

    def _batch_features(self, obs: ObservationBatch) -> tuple[np.ndarray | None,
                                                               np.ndarray | None]:
        """The rows' measured features for the compiled core, (n, F), and the mask (n,)
        of rows whose features are all visible. (None, None): no compiled core."""
        return None, None

    def _batch_accept(self, trials: np.ndarray, q: np.ndarray, qdot: np.ndarray
                      ) -> np.ndarray:
        """(n,) rows whose compiled result is the command as is (the QP laws check their
        bounds here)."""
        return np.ones(len(trials), dtype=bool)

    def _batch_reset_extra(self) -> None:
        """Per-trial constants of subclasses (the QP bounds)."""

    # ------------------------------------------------------------------ reset
    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """One instance per context (copies of this un-reset controller), reset with it.

        Raises:
            ContextError: A context the law cannot use (as :meth:`reset`).
        """
        make = copier(fresh_copy(self))
        self._trials = []
        for ctx in contexts:
            inst = make()
            inst.reset(ctx)
            self._trials.append(inst)
        trials = self._trials
        n = len(trials)
        self._state = {a: np.array([np.array(getattr(t, a), dtype=float) for t in trials])
                       for a in STATE}
        self._state["_observed"] = self._state["_observed"].astype(bool)
        kernels = [t._kernel for t in trials]
        self._has_kernel = np.array([k is not None for k in kernels], dtype=bool)
        self._fn = None
        if self._has_kernel.any():
            first = next(k for k in kernels if k is not None)
            self._fn = first.lean_function
            self._slices = first._slices
            self._outs = first._out
            self._X = np.zeros((n, first.function.n_in))
            for k, kern in enumerate(kernels):
                if kern is not None:
                    self._X[k] = kern._x
        self._batch_reset_extra()

    # ------------------------------------------------------------------ step
    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """One period of the rows' trials (see the module docstring)."""
        obs = observations
        n = len(obs)
        trials = np.asarray(obs.trials, dtype=int)
        out = CommandBatch.zeros(n)
        slow = np.ones(n, dtype=bool)
        feats, visible = self._batch_features(obs) if self._fn is not None else (None, None)
        if feats is not None and visible is not None:
            q = np.asarray(obs.lengths, dtype=float)
            with np.errstate(invalid="ignore"):
                fast = (self._has_kernel[trials] & visible & np.isfinite(feats).all(axis=1)
                        & np.isfinite(q).all(axis=1) & (q.min(axis=1) > 0)
                        & np.isfinite(np.asarray(obs.t, dtype=float)))
            rows = np.flatnonzero(fast)
            if len(rows):
                done = self._fast(rows, trials[rows], feats[rows], q[rows], out.velocities,
                                  out.error_norm)
                slow[rows[done]] = False
        for k in np.flatnonzero(slow):
            out.put(int(k), self._step_one(int(trials[k]), obs, int(k)))
        return out

    def _fast(self, rows: np.ndarray, trials: np.ndarray, feats: np.ndarray, q: np.ndarray,
              velocities: np.ndarray, norms: np.ndarray) -> np.ndarray:
        """The compiled core over the rows; fills the accepted ones, returns their mask."""
        assert self._fn is not None
        X = self._X[trials]
        X[:, self._slices["features"]] = feats
        X[:, self._slices["lengths"]] = q
        Y = self._fn.batch(X)
        o = self._outs
        with np.errstate(invalid="ignore"):
            ok = (np.isfinite(Y[:, o["error_norm"].start]) & np.isfinite(Y[:, o["n_sum"].start])
                  & (Y[:, o["rank"].start] >= 6) & (Y[:, o["qdot_check"].start] == 0.0))
        ok &= self._batch_accept(trials, q, Y[:, o["qdot"]])
        if ok.all():  # the common case: no row copies
            Ya, tr, qa, ra = Y, trials, q, rows
        else:
            acc = np.flatnonzero(ok)
            Ya, tr, qa, ra = Y[acc], trials[acc], q[acc], rows[acc]
        directions = Ya[:, o["directions"]].reshape(-1, 6, 3)
        st = self._state
        st["_directions"][tr] = directions
        st["_observed"][tr] = True
        st["_u_now"][tr] = directions
        st["_tau_prev"][tr] = Ya[:, o["tau"]]
        st["_q_prev"][tr] = qa
        velocities[ra] = Ya[:, o["qdot"]]
        norms[ra] = Ya[:, o["error_norm"].start]
        return ok

    def _step_one(self, trial: int, obs: ObservationBatch, k: int) -> Any:
        """Step one trial with its own instance (state loaded, stepped, saved)."""
        inst = self._trials[trial]
        st = self._state
        for a in STATE:
            setattr(inst, a, st[a][trial].copy())
        cmd = inst.step(obs.item(k))
        for a in STATE:
            st[a][trial] = getattr(inst, a)
        return cmd
