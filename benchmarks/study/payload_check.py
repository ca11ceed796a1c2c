"""What ``check`` (and ``run``'s pre-flight) says of a scenario's ``[payload]``: the leg
forces it takes, against the drives' force limits, at every sweep point.

- **static**: the drive forces that hold each sampled start pose at rest (the mechanism's
  inverse dynamics at zero velocity and acceleration: gravity on the platform, the
  payload and the legs), the largest over the starts and legs;
- **peak** (a trajectory task): the drive forces that follow the reference exactly, the
  largest over every control instant of every sampled reference and every leg: the
  mechanism's inverse dynamics along the reference (its twist and acceleration) plus each
  drive's rotor inertia times the leg's acceleration and its friction (viscous and
  Coulomb): the feed-forward of a perfect controller, what no controller of the study
  can do with less.

The starts are the run's own (:func:`benchmarks.sim.world.make_trials`: the first
:data:`SAMPLED_STARTS` trials of each point), on each trial's TRUE robot (payload
included). A static load above a drive's force limit is a warning (the drive cannot hold
the platform at rest: the study is then about what happens past that point); a peak
above it is said (the drives will saturate along the reference).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchmarks.study.setup_check import Problem

#: Starts sampled per sweep point.
SAMPLED_STARTS = 50


@dataclass
class PayloadFacts:
    """The leg forces of one sweep point with its payload.

    Attributes:
        sweep: The sweep point's keys (empty: no sweep).
        mass_kg: The payload's mass [kg].
        static_n: (6,) largest static force of each leg over the sampled starts [N].
        peak_n: (6,) largest force of each leg along the sampled references [N] (None:
            not a trajectory task).
        limit_n: (6,) the drives' force limits [N].
        problems: What the forces say (a static load over a limit).
    """

    sweep: dict[str, Any]
    mass_kg: float
    static_n: np.ndarray
    peak_n: np.ndarray | None
    limit_n: np.ndarray
    problems: list[Problem] = field(default_factory=list)
    #: The fraction of the sampled starts every drive can hold at rest.
    held: float = 1.0


def _drive_forces(g: Any, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                  acc: np.ndarray) -> np.ndarray:
    """The drive forces (n, 6) [N] that give the platform ``acc`` at ``(R, t, twist)``:
    the mechanism's plus the rotors' inertia and the friction."""
    from hexapod.dynamics import DynamicModel

    model = DynamicModel(g)
    forces = model.inverse_batch(R, t, twist, acc)
    q_dot, bias = model.legs_batch(R, t, twist)
    _, _, K, _, _ = model.terms_batch(R, t, twist)
    q_ddot = np.einsum("nij,nj->ni", K, acc) + bias
    d = g.drives
    return (forces + np.asarray(d.rotor_inertia) * q_ddot + np.asarray(d.viscous) * q_dot
            + np.asarray(d.coulomb) * np.sign(q_dot))


def static_forces_at_home(g: Any) -> np.ndarray | None:
    """The drive forces (6,) [N] that hold ``g``'s platform still at its home pose
    (None: no home pose)."""
    from hexapod.workspace import home_pose

    try:
        R, t = home_pose(g)
    except Exception:  # (no home pose: the workspace check says so)
        return None
    zero = np.zeros((1, 6))
    return np.asarray(_drive_forces(g, R[None], t[None], zero, zero)[0])


def _point(sc: Any, samples: int) -> PayloadFacts | None:
    return _facts(sc, samples, peaks=True)


def _static_point(sc: Any, samples: int) -> PayloadFacts | None:
    return _facts(sc, samples, peaks=False)


def _facts(sc: Any, samples: int, peaks: bool) -> PayloadFacts | None:
    from benchmarks.sim.reference import trial_reference
    from benchmarks.study.trajectory_check import sampled_setups

    setups = sampled_setups(sc, samples)
    if not setups:
        return None
    static = np.zeros(6)
    peak = np.zeros(6) if sc.task.kind == "trajectory" and peaks else None
    held = 0
    for s in setups:
        g = s.world.geometry
        R, t = s.start_rotation[None], s.start_translation[None]
        zero = np.zeros((1, 6))
        at_rest = np.abs(_drive_forces(g, R, t, zero, zero))[0]
        static = np.maximum(static, at_rest)
        held += bool(np.all(at_rest <= np.asarray(g.drives.force_limit, dtype=float)))
        ref = trial_reference(sc, s) if peak is not None else None
        if ref is not None and peak is not None:
            times = np.append(np.arange(0.0, ref.duration, sc.dt), ref.duration)
            r = ref.at(times)
            f = _drive_forces(g, r.rotation, r.translation, r.twist, r.twist_rate)
            peak = np.maximum(peak, np.abs(f).max(axis=0))
    mass = sc.payload.mass_kg if sc.payload is not None else 0.0
    limit = np.asarray(setups[0].world.geometry.drives.force_limit, dtype=float)
    return PayloadFacts(dict(sc.sweep), mass, static, peak, limit, held=held / len(setups))


def payload_facts(sc: Any, samples: int = SAMPLED_STARTS) -> list[PayloadFacts]:
    """The facts and problems of each sweep point of a scenario in the dynamic world
    (empty otherwise): with a ``[payload]``, its static and peak forces; without, the
    static load of the robot's own weight. A static load over a limit is a warning (a
    payload study may be about what happens past it); when no sampled start of any
    sweep point can be held at rest, an error (every trial would fall)."""
    if sc.world != "dynamic":
        return []
    from benchmarks.study.trajectory_check import sweep_facts

    payload = getattr(sc, "payload", None) is not None
    out = []
    warned_com = False
    for point, facts, where, at in sweep_facts(sc, _point if payload else _static_point,
                                               samples):
        if payload and not warned_com and (text := _com_problem(point, where)):
            facts.problems.append(Problem("warning", text, point=at))
            warned_com = True
        over = np.flatnonzero(facts.static_n > facts.limit_n)
        if over.size:
            leg = int(over[np.argmax(facts.static_n[over] - facts.limit_n[over])])
            load = (f"with a {facts.mass_kg:g} kg payload the static load alone" if payload
                    else "the robot's own weight alone (no payload)")
            facts.problems.append(Problem("warning", (
                f"{load} exceeds the drives' force limit: leg {leg} needs "
                f"{facts.static_n[leg]:.0f} N at rest, its limit is {facts.limit_n[leg]:g} "
                f"N ({over.size} leg(s) over; {100 * (1 - facts.held):.0f} % of the sampled "
                f"starts cannot be held): the drives cannot hold the platform still {where}"),
                point=at))
        out.append(facts)
    if out and all(f.held == 0 for f in out):  # every start of every point falls
        first = out[0]
        first.problems.append(Problem("error", (
            "no sampled start of the study can be held at rest: the drives' force limits "
            f"({first.limit_n.min():g} N) are below the static load at every one, so no "
            "controller can hold the platform where a trial starts (it sags from the first "
            "period: onto an end stop, or as far as the drives' friction lets it); raise "
            f"force_limit in [drives] of the robot file, or lighten the load, in {sc.source}")))
    return out


def _com_problem(point: Any, where: str) -> str | None:
    """A payload whose centre of mass lies beyond the platform's disc (more than its
    radius from the platform's axis) or below the base: a key in metres, or a slip."""
    from benchmarks.sim.world import load_geometry
    from hexapod.workspace import home_pose

    g = load_geometry(point)
    com = np.asarray(point.payload.com_mm, dtype=float) * 1e-3
    radius = float(np.max(np.linalg.norm(g.platform_points[:, :2], axis=1)))
    reach = float(np.linalg.norm(com[:2]))
    height = float(home_pose(g)[1][2])
    if reach > radius:
        return (f"the payload's centre of mass is {reach * 1e3:.0f} mm from the platform's "
                f"axis, beyond its {radius * 1e3:.0f} mm radius (payload.com_mm, platform "
                f"frame, in millimetres) {where}")
    if height + com[2] < 0:
        return (f"the payload's centre of mass is {-(height + com[2]) * 1e3:.0f} mm below "
                f"the base plane at home (payload.com_mm z = {com[2] * 1e3:g} mm, the "
                f"platform {height * 1e3:.0f} mm above the base) {where}")
    return None


def describe_payload(facts: list[PayloadFacts], sc: Any) -> list[str]:
    """The lines ``check`` prints about the static load (and a ``[payload]``'s forces):
    one per sweep point, named by its swept values."""
    if not facts:
        return []
    from benchmarks.study.trajectory_check import sweep_text

    p = sc.payload
    lines = ([f"Payload (com {list(p.com_mm)} mm in the platform frame, inertia "
              f"{list(p.inertia_kg_m2)} kg m^2; drive forces over the sampled starts and "
              "legs, peak: following the reference exactly, rotor inertia and friction "
              "included):"] if p is not None else
             ["Static load (the robot's own weight, no payload; drive forces holding the "
              "sampled starts at rest, the largest over starts and legs):"])
    if p is None and len({(round(float(f.static_n.max())), float(f.limit_n.min()))
                          for f in facts}) == 1:  # the same at every sweep point (as printed)
        f = facts[0]
        return [*lines, f"  {f.static_n.max():.0f} N; force limit {f.limit_n.min():g} N"
                + (" (every sweep point)" if len(facts) > 1 else ""), ""]
    for f in facts:
        peak = ("" if f.peak_n is None else
                f", peak {f.peak_n.max():.0f} N" + (" (beyond the limit: the drives will "
                                                    "saturate)" if np.any(f.peak_n > f.limit_n)
                                                    else ""))
        what = f"{f.mass_kg:g} kg" if p is not None else "static"
        others = {k: v for k, v in f.sweep.items() if k != "payload.mass_kg"}  # (shown)
        point = f" ({sweep_text(others)})" if others else ""
        static = f"static {f.static_n.max():.0f} N" if p is not None else \
            f"{f.static_n.max():.0f} N"
        lines.append(f"  {what}{point}: {static}{peak}; force limit {f.limit_n.min():g} N")
    return [*lines, ""]
