"""The pre-flight of a study: ONE function, :func:`preflight`, that ``hexapod-bench run``
calls before its first trial and ``hexapod-bench check`` calls on a scenario, so that
both give the same verdict in the same words.

It resolves the controllers (names, options against each controller's declared table,
``[controller_options]`` given to the controllers that declare them, each built once,
what it commands against the world), checks a calibration file against the robot and
camera, measures the setup (:func:`benchmarks.study.check_command.examine`) and, for a
trajectory task, the plan's references (:mod:`benchmarks.study.trajectory_check`).
A problem found in the file's terms raises a :class:`~benchmarks.exceptions.ScenarioError`;
a setup whose every trial would fail raises a :class:`~benchmarks.exceptions.SetupError`
(:func:`refuse`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from benchmarks.exceptions import ScenarioError, SetupError
from benchmarks.scenario_sections import MODEL_ERROR_KEYS
from benchmarks.study.setup_check import Problem


@dataclass
class StudyCheck:
    """What the pre-flight found for one scenario.

    Attributes:
        scenario: The scenario with its controllers resolved (what runs).
        setup: What ``check`` describes (:class:`benchmarks.study.check_command.Setup`).
        report: The setup's measurements (:class:`~benchmarks.study.setup_check.SetupReport`).
        trajectory: A trajectory task's references, per sweep point.
        payload: A payload's leg forces, per sweep point
            (:mod:`benchmarks.study.payload_check`).
        problems: Every problem (the setup's, then the trajectory's).
    """

    scenario: Any
    setup: Any = None
    report: Any = None
    trajectory: list[Any] = field(default_factory=list)
    payload: list[Any] = field(default_factory=list)
    problems: list[Problem] = field(default_factory=list)

    @property
    def errors(self) -> list[Problem]:
        """The problems that make every trial fail."""
        return [p for p in self.problems if p.severity == "error"]


@dataclass
class Preflight:
    """The pre-flight of a study.

    Attributes:
        checks: One per scenario, in order.
        warnings: Warnings about the files (a foreign calibration, an option left out).
    """

    checks: list[StudyCheck]
    warnings: list[str]

    @property
    def scenarios(self) -> list[Any]:
        """The scenarios as they run."""
        return [c.scenario for c in self.checks]


#: The ``[calibration_error]`` keys that act only in the dynamic world (masses,
#: inertias, the drives) or on a payload.
DYNAMIC_ERRORS = ("mass_percent", "inertia_percent", *MODEL_ERROR_KEYS)


def dynamics_only(sc: Any) -> list[str]:
    """Warnings for settings that have no effect where the scenario runs: errors of the
    masses, inertias and drives in the kinematic world, a payload's mass error without
    a payload (they were accepted without a word)."""
    ce = sc.calibration_error
    where = f"{sc.source or sc.name}: [calibration_error]"
    out = []
    if sc.world != "dynamic":
        keys = [k for k in DYNAMIC_ERRORS
                if any(sc.sweep_axes.get(f"calibration_error.{k}", [getattr(ce, k)]))]
        if keys:
            out.append(f"{where} {', '.join(keys)}: errors of the robot's masses, inertias "
                       "or drives, which the kinematic world does not have: no effect (set "
                       "[robot] world = \"dynamic\", or run with --world dynamic)")
    if getattr(sc, "payload", None) is None and any(sc.sweep_axes.get(
            "calibration_error.payload_mass_percent", [ce.payload_mass_percent])):
        out.append(f"{where} payload_mass_percent: the error of a payload's mass, and the "
                   "scenario has no [payload]: no effect")
    return out


def _swept(sc: Any, section: str, key: str) -> list[Any]:
    """The values a key takes over the scenario's sweep (its one value if not swept)."""
    return list(sc.sweep_axes.get(f"{section}.{key}", [getattr(getattr(sc, section), key)]))


def without_effect(sc: Any) -> list[str]:
    """Warnings for settings the scenario's sensor and noise model do not read (a sweep of
    them gave identical points, the report saying 'noise: none' beside 'swept
    noise.amplitude_deg'): a noise amplitude of another model than the one chosen, the
    rendering keys without rendered images, a lens error the geometric features never
    meet."""
    where, noise, out = sc.source or sc.name, sc.noise, []
    out += _clipped_jitter(sc, where)
    for key, model in (("amplitude_deg", "rotation"), ("pixel_sigma_px", "pixel"),
                       ("outlier_fraction", "pixel")):
        if noise.model != model and any(_swept(sc, "noise", key)):
            out.append(f"{where}: [noise] {key}: read by model = \"{model}\" only, and the "
                       f"model is {noise.model!r}"
                       + (" (the default)" if noise.model == "none" else "")
                       + f": no effect (set model = \"{model}\")")
    if sc.sensor != "image":
        default = type(sc.image)()
        keys = [k for k in ("background", "blur_px", "noise_std")
                if any(v != getattr(default, k) for v in _swept(sc, "image", k))]
        if keys:
            out.append(f"{where}: [sensor] {', '.join(keys)}: settings of rendered images, and "
                       f"the sensor is {sc.sensor!r}: no effect (set [sensor] kind = \"image\")")
        if noise.model != "pixel" and any(_swept(sc, "calibration_error",
                                                 "distortion_percent")):
            out.append(f"{where}: [calibration_error] distortion_percent: an error of the "
                       "camera model's lens, which geometric features never pass through: no "
                       "effect (it acts with [sensor] kind = \"image\" or [noise] model = "
                       "\"pixel\")")
    return out


def _clipped_jitter(sc: Any, where: str) -> list[str]:
    """A warning when the camera's capture jitter is clipped for more than 1 % of its
    draws (each is clipped to 0.45 frame so that frames stay in order: a 100 ms jitter at
    a 20 ms frame ran without a word, nothing like the normal spread it asked for)."""
    from benchmarks.sim.clock import MAX_JITTER_FRACTION

    out = []
    for rate in _swept(sc, "clock", "frame_rate_hz"):
        frame = 1.0 / rate if rate > 0 else sc.dt
        limit = MAX_JITTER_FRACTION * frame * 1e3  # [ms]
        for jitter in _swept(sc, "clock", "jitter_ms"):
            if jitter > 0 and (clipped := math.erfc(limit / (jitter * math.sqrt(2)))) > 0.01:
                out.append(f"{where}: [clock] jitter_ms = {jitter:g}: a capture time is "
                           f"clipped to +-{limit:g} ms (0.45 of a {frame * 1e3:g} ms frame), "
                           f"and {100 * clipped:.0f} % of them would be: not the normal "
                           "spread asked for")
    return out


def preflight(scenarios: list[Any], allow_foreign_calibration: bool = False,
              measure: bool = True) -> Preflight:
    """Check a study before it runs (``run``) or as ``check`` does.

    Args:
        scenarios: The scenarios, command-line overrides applied.
        allow_foreign_calibration: ``--allow-foreign-calibration``.
        measure: Measure the setups and the trajectories (False: ``run --no-check``, the
            file checks only).

    Raises:
        ScenarioError: A controller, option or file refused, in the file's terms.
    """
    from benchmarks.study.provenance import check_scenario_calibration
    from benchmarks.study.scenario import check_physics_dt
    from benchmarks.study.scenario_checks import check_controllers

    checks, warnings = [], []
    for sc in scenarios:
        if sc.world == "dynamic":  # (--world dynamic may make a kinematic file dynamic)
            check_physics_dt(sc.dt, sc.physics_dt, sc.source)
        elif getattr(sc, "payload", None) is not None:
            raise ScenarioError(sc.source, "a payload has weight and inertia only in the "
                                "dynamic world: set [robot] world = \"dynamic\" (or run "
                                "with --world dynamic)", key="payload")
        resolved, notes = check_controllers(sc)
        warnings += notes + dynamics_only(sc) + without_effect(sc)
        warnings += check_scenario_calibration(resolved, allow_foreign_calibration)
        checks.append(StudyCheck(resolved))
    if measure:
        for check in checks:
            measure_study(check)
    return Preflight(checks, warnings)


def measure_study(check: StudyCheck) -> None:
    """Measure one resolved scenario: its setup and, for a trajectory task, its plan's
    references (fills ``check``)."""
    from benchmarks.study.calibration_check import calibration_problems
    from benchmarks.study.check_command import examine, scenario_setup
    from benchmarks.study.payload_check import payload_facts
    from benchmarks.study.trajectory_check import trajectory_facts

    check.setup = scenario_setup(check.scenario)
    check.report = examine(check.setup)
    check.problems = check.report.problems  # one list: the report's verdict includes all
    if check.report.can_run:  # a robot without a workspace has no trajectory to check
        check.trajectory = trajectory_facts(check.scenario)
        check.payload = payload_facts(check.scenario)
        points = len(check.scenario.expand())
        found = [p for facts in check.trajectory for p in facts.problems]
        found += [p for facts in check.payload for p in facts.problems]
        found += calibration_problems(check.scenario)
        check.problems += _merged(found, points)


def _merged(problems: list[Problem], points: int) -> list[Problem]:
    """Problems found per sweep point, a problem the same at several points said once
    with its points (``(every sweep point)`` when at all ``points``), the point named
    after the text: a reference too fast was said six times, once per payload, in the
    same words."""
    groups: dict[tuple[str, str, str, bool], list[str]] = {}
    for p in problems:
        groups.setdefault((p.severity, p.text, p.topic, p.fails), []).append(p.point)
    out = []
    for (severity, text, topic, fails), at in groups.items():
        named = [a for a in at if a]
        if len(named) > 1:
            where = ("every sweep point" if len(named) == points > 1
                     else "sweep points " + "; ".join(named))
            text = f"{text} ({where})"
        elif named:
            text = f"{text} (sweep point {named[0]})"
        out.append(Problem(severity, text, topic, fails))
    return out


def refusal(check: StudyCheck) -> SetupError | None:
    """The refusal of a study whose every trial would fail (None: it can run)."""
    errors = check.errors
    return SetupError(check.scenario.source, errors) if errors else None


def warning_lines(check: StudyCheck) -> list[str]:
    """The warnings of a study that can run, as ``run`` prints them on stderr."""
    return [f"hexapod-bench: warning: {check.scenario.name}: {p.text}"
            for p in check.problems if p.severity != "error"]
