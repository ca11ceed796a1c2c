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
    """

    sweep: dict[str, Any]
    mass_kg: float
    static_n: np.ndarray
    peak_n: np.ndarray | None
    limit_n: np.ndarray
    problems: list[Problem] = field(default_factory=list)


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


def _point(sc: Any, samples: int) -> PayloadFacts | None:
    from benchmarks.sim.reference import trial_reference
    from benchmarks.study.trajectory_check import sampled_setups

    setups = sampled_setups(sc, samples)
    if not setups:
        return None
    static = np.zeros(6)
    peak = np.zeros(6) if sc.task.kind == "trajectory" else None
    for s in setups:
        g = s.world.geometry
        R, t = s.start_rotation[None], s.start_translation[None]
        zero = np.zeros((1, 6))
        static = np.maximum(static, np.abs(_drive_forces(g, R, t, zero, zero))[0])
        ref = trial_reference(sc, s)
        if ref is not None and peak is not None:
            times = np.append(np.arange(0.0, ref.duration, sc.dt), ref.duration)
            r = ref.at(times)
            f = _drive_forces(g, r.rotation, r.translation, r.twist, r.twist_rate)
            peak = np.maximum(peak, np.abs(f).max(axis=0))
    mass = sc.payload.mass_kg if sc.payload is not None else 0.0
    limit = np.asarray(setups[0].world.geometry.drives.force_limit, dtype=float)
    return PayloadFacts(dict(sc.sweep), mass, static, peak, limit)


def payload_facts(sc: Any, samples: int = SAMPLED_STARTS) -> list[PayloadFacts]:
    """The facts and problems of each sweep point of a scenario with a ``[payload]`` in
    the dynamic world (empty otherwise)."""
    if getattr(sc, "payload", None) is None or sc.world != "dynamic":
        return []
    from benchmarks.study.trajectory_check import sweep_facts

    out = []
    for _, facts, where in sweep_facts(sc, _point, samples):
        over = np.flatnonzero(facts.static_n > facts.limit_n)
        if over.size:
            leg = int(over[np.argmax(facts.static_n[over] - facts.limit_n[over])])
            facts.problems.append(Problem("warning", (
                f"with a {facts.mass_kg:g} kg payload the static load alone exceeds the "
                f"drives' force limit: leg {leg} needs {facts.static_n[leg]:.0f} N at rest, "
                f"its limit is {facts.limit_n[leg]:g} N ({over.size} leg(s) over): the "
                f"drives cannot hold the platform still {where}")))
        out.append(facts)
    return out


def describe_payload(facts: list[PayloadFacts], sc: Any) -> list[str]:
    """The lines ``check`` prints about a scenario's payload."""
    if not facts:
        return []
    p = sc.payload
    lines = [f"Payload (com {list(p.com_mm)} mm in the platform frame, inertia "
             f"{list(p.inertia_kg_m2)} kg m^2; drive forces over the sampled starts and "
             "legs, peak: following the reference exactly, rotor inertia and friction "
             "included):"]
    for f in facts:
        peak = ("" if f.peak_n is None else
                f", peak {f.peak_n.max():.0f} N" + (" (beyond the limit: the drives will "
                                                    "saturate)" if np.any(f.peak_n > f.limit_n)
                                                    else ""))
        lines.append(f"  {f.mass_kg:g} kg: static {f.static_n.max():.0f} N{peak}; force "
                     f"limit {f.limit_n.min():g} N")
    return [*lines, ""]
