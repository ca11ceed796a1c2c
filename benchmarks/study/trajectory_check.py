"""What only the plan of a trajectory task shows before it runs: how long its references
last against the trial's ``max_steps``, how far the legs travel along them against the
task's ``margin_mm``, and the fraction of the study's own starts whose reference reaches
an end stop.

The starts are the run's own (:func:`benchmarks.sim.world.make_trials` with the
scenario's seed): the first :data:`SAMPLED_STARTS` trials of each sweep point. The whole
reference path of each is sampled every control period, from its start to its end, and
its leg lengths on the TRUE robot of that trial are compared with the strokes.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import numpy as np

from benchmarks.study.setup_check import Problem


class SweepFacts(Protocol):
    """Facts of one sweep point: its swept values (key -> value)."""

    sweep: dict[str, Any]


FactsT = TypeVar("FactsT", bound=SweepFacts)

#: Starts sampled per sweep point (the plan's first trials).
SAMPLED_STARTS = 200
#: Below this time left after the longest reference ends, the trials may not settle [s].
SETTLE_TIME_S = 0.5


@dataclass
class TrajectoryFacts:
    """The references of one sweep point of a trajectory task.

    Attributes:
        sweep: The sweep point's keys (empty: no sweep).
        sampled: Starts sampled (the plan's first trials that could be drawn).
        duration_s: (min, max) duration of their references [s].
        run_time_s: ``max_steps * dt`` [s].
        travel_mm: Largest change of a leg length along a reference from its start [mm]
            (a ``margin_mm`` at least this large keeps every sampled path inside).
        hits: Sampled starts whose reference takes a leg out of its stroke.
        worst: ``(leg, length_mm, limit_mm)`` of the deepest such excursion, or None.
        leg_speed_mm_s: Largest leg speed along the references [mm/s] (the reference's
            twist through the true robot's inverse Jacobian).
        max_speed_mm_s: The robot's leg speed limit [mm/s].
    """

    sweep: dict[str, Any]
    sampled: int
    duration_s: tuple[float, float]
    run_time_s: float
    travel_mm: float
    hits: int
    worst: tuple[int, float, float] | None = None
    leg_speed_mm_s: float = 0.0
    max_speed_mm_s: float = float("inf")
    problems: list[Problem] = field(default_factory=list)

    @property
    def fraction(self) -> float:
        """Fraction of the sampled starts that would hit an end stop."""
        return self.hits / self.sampled if self.sampled else 0.0


def sampled_setups(sc: Any, samples: int) -> list[Any]:
    """The trial setups (:func:`benchmarks.sim.world.make_trials`) of the scenario's first
    ``min(trials, samples)`` trials on its nominal robot and camera, those that could be
    drawn (a trial whose start or goal could not be drawn is left out); the run of the
    same point takes these draws (:func:`benchmarks.sim.stepper.preflight_trials`)."""
    from benchmarks.sim.stepper import preflight_trials

    return [s for s in preflight_trials(sc, list(range(min(sc.trials, samples))))
            if not isinstance(s, Exception)]


def _point(sc: Any, samples: int) -> TrajectoryFacts | None:
    from benchmarks.sim.reference import trial_reference
    from hexapod.kinematics import inverse_jacobian, leg_vectors

    setups = sampled_setups(sc, samples)
    if not setups:
        return None

    durations, travel, hits, speed = [], 0.0, 0, 0.0
    worst: tuple[float, int, float, float] | None = None  # (depth, leg, q, limit)
    for s in setups:
        ref = trial_reference(sc, s)
        assert ref is not None
        durations.append(ref.duration)
        times = np.append(np.arange(0.0, ref.duration, sc.dt), ref.duration)
        sample = ref.at(times)
        g = s.world.geometry
        legs = leg_vectors(g, sample.rotation, sample.translation)  # (T, 6, 3) [m]
        q = np.linalg.norm(legs, axis=-1)  # the leg lengths (inverse kinematics) [m]
        travel = max(travel, float(np.max(np.abs(q - q[0]))))
        w = sample.angular_velocity  # the twist at the base origin: v - w x t
        tw = np.concatenate([sample.velocity - np.cross(w, sample.translation), w], axis=1)
        J = inverse_jacobian(g.base_points, legs / q[..., None])  # the leg directions
        speed = max(speed, float(np.max(np.abs(np.einsum("tij,tj->ti", J, tw)))))
        below, above = g.q_min - q, q - g.q_max
        depth = np.maximum(below, above)
        if np.any(depth >= 0):
            hits += 1
            k, leg = np.unravel_index(int(np.argmax(depth)), depth.shape)
            d = float(depth[k, leg])
            if worst is None or d > worst[0]:
                limit = g.q_min if below[k, leg] >= 0 else g.q_max
                worst = (d, int(leg), float(q[k, leg]), float(limit))
    return TrajectoryFacts(
        dict(sc.sweep), len(setups), (min(durations), max(durations)),
        sc.task.max_steps * sc.dt, travel * 1e3, hits,
        None if worst is None else (worst[1], worst[2] * 1e3, worst[3] * 1e3),
        speed * 1e3, setups[0].world.geometry.max_speed * 1e3)


def trajectory_facts(sc: Any, samples: int = SAMPLED_STARTS) -> list[TrajectoryFacts]:
    """The facts and problems of each sweep point of a trajectory task (empty for
    another task).

    Problems: every sampled start hits an end stop (an error: every trial would fail);
    some do (a warning with the fraction and the ``margin_mm`` that avoids it); the
    references last longer than ``max_steps * dt``, or leave less than
    :data:`SETTLE_TIME_S` to settle (warnings).
    """
    if sc.task.kind != "trajectory":
        return []
    out = []
    for point, facts, where, at in sweep_facts(sc, _point, samples):
        task = point.task
        if facts.hits:
            leg, q, limit = facts.worst or (0, float("nan"), float("nan"))
            text = (f"{facts.hits} of {facts.sampled} sampled starts "
                    f"({100 * facts.fraction:.0f} %) would hit an end stop following the "
                    f"{task.shape} reference (deepest: leg {leg} at {q:.1f} mm, stroke limit "
                    f"{limit:g} mm); the legs travel up to {facts.travel_mm:.1f} mm along "
                    f"it while [task] margin_mm = {task.margin_mm:g}: set margin_mm >= "
                    f"{np.ceil(facts.travel_mm):g}, or shrink the path (radius_mm, "
                    f"max_translation_mm) {where}")
            facts.problems.append(Problem(
                "error" if facts.hits == facts.sampled else "warning", text, point=at))
        if facts.leg_speed_mm_s > facts.max_speed_mm_s * (1 + 1e-9):
            facts.problems.append(Problem("warning", (
                f"the {task.shape} reference moves a leg at up to {facts.leg_speed_mm_s:.1f} "
                f"mm/s, above the robot's leg speed limit {facts.max_speed_mm_s:g} mm/s (the "
                "commands are clamped to it: no controller can follow the reference); slow "
                "it down ([task] speed_mm_s, peak_acceleration_mm_s2, radius_mm) "
                f"{where}"), point=at))
        hi = facts.duration_s[1]
        if hi > facts.run_time_s:
            facts.problems.append(Problem("warning", (
                f"the reference lasts up to {hi:.2f} s, longer than max_steps x dt = "
                f"{task.max_steps} x {point.dt * 1e3:g} ms = {facts.run_time_s:.2f} s: the "
                f"trials stop before it ends; raise [task] max_steps to at least "
                f"{int(np.ceil((hi + SETTLE_TIME_S) / point.dt))} {where}"), point=at))
        elif facts.run_time_s - hi < SETTLE_TIME_S:
            facts.problems.append(Problem("warning", (
                f"the reference lasts up to {hi:.2f} s and max_steps x dt = "
                f"{facts.run_time_s:.2f} s leaves {facts.run_time_s - hi:.2f} s to settle "
                f"after it (settling_time_s may be missing); raise [task] max_steps to at "
                f"least {int(np.ceil((hi + SETTLE_TIME_S) / point.dt))} {where}"), point=at))
        out.append(facts)
    return out


def sweep_text(sweep: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}"
                     for k, v in sweep.items())


def sweep_facts(sc: Any, point_facts: Callable[[Any, int], FactsT | None], samples: int
                ) -> Iterator[tuple[Any, FactsT, str, str]]:
    """The facts of each sweep point of a scenario (:meth:`Scenario.expand`):
    ``point_facts(point, samples)`` of each point that has some (not None), with the
    point, where its problems are for their text (``"in FILE"``) and the point's values
    (:func:`sweep_text`: a problem's ``point``), one point at a time."""
    for point in sc.expand():
        facts = point_facts(point, samples)
        if facts is None:
            continue
        yield point, facts, f"in {sc.source}", sweep_text(facts.sweep)


def describe_trajectory(facts: list[TrajectoryFacts], sc: Any) -> list[str]:
    """The lines ``check`` prints about a trajectory task's references."""
    if not facts:
        return []
    task = sc.task
    shape = (f"{task.shape}, radius {task.radius_mm:g} mm, {task.laps} lap(s) in {task.plane}"
             if task.shape != "line" else "line from start to goal")
    lines = [f"Trajectory ({shape}, {task.profile} profile; the plan's own starts, seed "
             f"{sc.seed}):"]
    for f in facts:
        lo, hi = f.duration_s
        dur = f"{lo:.2f} s" if abs(hi - lo) < 5e-3 else f"{lo:.2f} to {hi:.2f} s"
        head = f"  {sweep_text(f.sweep)}: " if f.sweep else "  "
        left = f.run_time_s - hi
        after = (f"leaves {left:.2f} s after it" if left >= 0 else
                 f"ends {-left:.2f} s before it does")
        lines.append(
            f"{head}the reference lasts {dur}; max_steps x dt = {f.run_time_s:.2f} s {after}; "
            f"the legs travel up to {f.travel_mm:.1f} mm "
            f"along it (margin_mm = {task.margin_mm:g}); {f.hits} of {f.sampled} sampled "
            f"starts ({100 * f.fraction:.1f} %) would hit an end stop")
    return [*lines, ""]
