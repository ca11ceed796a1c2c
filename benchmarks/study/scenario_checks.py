"""Checks of what a scenario file names, in the file's terms: the files it references
(relative to the scenario file), the options of its controllers (against each
controller's signature, and each controller built once), and the consistency of its
sections (lens error against the camera's model, scaled calibration errors within
range, trajectory-only task keys, calibration configurations, a fixed task's leg
lengths within the strokes)."""

from __future__ import annotations

import contextlib
import math
import re
from collections.abc import Collection, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from benchmarks.exceptions import ScenarioError
from benchmarks.study.scenario_model import (
    RANGES,
    SCALED_ERROR_KEYS,
    TASK_KEYS,
    TRAJECTORY_ONLY_KEYS,
    CalibrationErrorConfig,
    ControllerSpec,
    Scenario,
    TaskConfig,
)
from benchmarks.study.scenario_ranges import unit_of
from hexapod.config import suggest


def referenced_file(base_dir: Path, value: str, key: str, path: str) -> str:
    """The path of a file a scenario names (relative to the scenario file's folder).

    Raises:
        ScenarioError: The file does not exist: naming the key, the full path tried and
            the rule for relative paths.
    """
    target = base_dir / value
    if not target.is_file():
        rule = ("" if Path(value).is_absolute() else
                f" (a relative path is relative to the folder of the scenario file, "
                f"{base_dir.resolve()})")
        what = "is a folder, not a file" if target.is_dir() else "file not found"
        raise ScenarioError(path, f"{value!r}: {what}: tried {target.resolve()}{rule}",
                            key=key)
    return str(target)


def option_origin(source: str, spec: ControllerSpec, option: str, default: str
                  ) -> tuple[str, str]:
    """The file and key an option of ``spec`` was written at: an options file's
    (``--options-file``, recorded as ``FILE: controllers."LABEL".OPTION``) or the
    scenario's (``source``, ``default`` when the option has no recorded key)."""
    key = spec.option_keys.get(option, default)
    file, sep, rest = key.partition(": ")
    return (file, rest) if sep and rest.startswith('controllers."') else (source, key)


#: A keyword argument a class or function does not take, as Python says it.
_UNEXPECTED = re.compile(r"got an unexpected keyword argument '(\w+)'")


def _unexpected_option(source: str, spec: ControllerSpec, table: Any, where: str,
                       exc: TypeError) -> ScenarioError:
    """An open controller's refusal of an option it hands on (``TypeError``), in the
    words of a closed one's: the key as written, the controller's own options and the
    close one (it named the fallback law's ``__init__``, with no suggestion)."""
    found = _UNEXPECTED.search(str(exc))
    if found is None or found[1] not in spec.options:
        return ScenarioError(source, f"{spec.name}: {exc}", key=where)
    option = found[1]
    path, key = option_origin(source, spec, option, f"{where}.{option}")
    names = list(table.names)
    inner = spec.options.get("law")  # a wrapper's law: its options are handed on too
    if isinstance(inner, str):
        from controllers.registry import registry

        with contextlib.suppress(Exception):  # (an unknown law is reported on its own)
            names += [n for n in registry.options(inner).names if n not in names]
    return ScenarioError(
        path, f"controller '{spec.name}' takes no option '{option}' (nor does the law it "
        f"hands further options to); its options: {', '.join(names) or 'none'} "
        f"(hexapod-bench list --options {spec.name})", key=key,
        suggestion=suggest(option, names))


def check_option_names(source: str, spec: ControllerSpec, table: Any, where: str) -> None:
    """Every option of ``spec`` is one the controller declares
    (:func:`controllers.options.option_table`: the same table ``list --options`` prints).

    Raises:
        ScenarioError: An option the controller does not take, naming the key as written
            in the file, the controller's options and the close one.
    """
    if table.open:  # it hands further options on: they are checked when it is built
        return
    for option in spec.options:
        if not table.declares(option):
            path, key = option_origin(source, spec, option, f"{where}.{option}")
            raise ScenarioError(
                path, f"controller '{spec.name}' has no option '{option}'; its options: "
                f"{', '.join(table.names) or 'none'} (hexapod-bench list --options "
                f"{spec.name})", key=key, suggestion=suggest(option, table.names))


def _shared_options(sc: Scenario, tables: list[Any]) -> tuple[list[ControllerSpec], list[str]]:
    """Give each ``[controller_options]`` key to the controllers that declare it.

    A key no controller of the study declares is refused (a typo), unless
    ``--controllers`` chose the controllers (the file's keys were written for others):
    then it is left out, with a warning.

    Returns:
        The controllers with their options, and the warnings.
    """
    shared = {o for spec in sc.controllers for o, k in spec.option_keys.items()
              if k == f"controller_options.{o}"}
    takers = {o: [spec.label for spec, t in zip(sc.controllers, tables, strict=True)
                  if t.open or t.declares(o)] for o in sorted(shared)}
    warnings: list[str] = []
    for option, labels in takers.items():
        if labels:
            continue
        declared = sorted({n for t in tables for n in t.names})
        if any(spec.key is None for spec in sc.controllers):
            warnings.append(
                f"[controller_options] {option} of {sc.source} is left out: no controller "
                f"chosen by --controllers ({', '.join(s.label for s in sc.controllers)}) "
                "takes it")
            continue
        raise ScenarioError(
            sc.source, "no controller of the study takes this option ("
            + "; ".join(f"{spec.label}: {', '.join(t.names) or 'none'}"
                        for spec, t in zip(sc.controllers, tables, strict=True))
            + "); [controller_options] go to each controller that declares them",
            key=f"controller_options.{option}", suggestion=suggest(option, declared))
    specs = []
    for spec, t in zip(sc.controllers, tables, strict=True):
        drop = {o for o in spec.options if spec.option_keys.get(o) == f"controller_options.{o}"
                and not (t.open or t.declares(o))}
        specs.append(replace(spec, options={k: v for k, v in spec.options.items()
                                            if k not in drop},
                             option_keys={k: v for k, v in spec.option_keys.items()
                                          if k not in drop}) if drop else spec)
    return specs, warnings


def check_lens_error(camera: Any, cal_err: CalibrationErrorConfig,
                      sweep: dict[str, list[Any]], path: str) -> None:
    """Each ``distortion_percent`` is one the camera file's lens model has (a fisheye,
    double sphere or extended unified lens: 0 or 100 only)."""
    if camera is None:
        return
    from vision.exceptions import CameraError

    key = "calibration_error.distortion_percent"
    for value in sweep.get(key, [cal_err.distortion_percent]):
        try:
            camera.lens_scaled(1.0 - 1e-2 * float(value))
        except CameraError as exc:
            raise ScenarioError(path, f"{value}: {exc}", key=key) from None


def check_scaled_errors(cal_err: CalibrationErrorConfig, sweep: dict[str, list[Any]],
                         path: str) -> None:
    """Each calibration error times the largest ``scale`` stays within its key's range."""
    scales = sweep.get("calibration_error.scale", [cal_err.scale])
    for key in SCALED_ERROR_KEYS:
        values = sweep.get(f"calibration_error.{key}", [getattr(cal_err, key)])
        worst = max(values) * max(scales)
        hi = RANGES[f"calibration_error.{key}"][1]
        if worst > hi:
            unit = unit_of(f"calibration_error.{key}")
            unit = f" {unit}" if unit else ""
            raise ScenarioError(path, f"times scale {max(scales):g} gives a standard "
                                f"deviation of {worst:g}{unit}, beyond the allowed {hi:g}{unit}",
                                key=f"calibration_error.{key}")


def check_trajectory_task(task: TaskConfig, sweep: dict[str, list[Any]], path: str,
                          written: Collection[str] = ()) -> TaskConfig:
    """A trajectory task runs for ``max_steps`` (``fixed_duration``); its keys swept only
    in a trajectory task (``goal``, the goal setting, in any task), and written
    (``written``: the keys of the file's ``[task]``) only in one: a ``shape = "circle"``
    without ``kind = "trajectory"`` ran a point-to-point study without a word; so did
    ``start_mm``/``goal_mm`` without ``kind = "fixed"`` (random pairs were drawn)."""
    if task.kind != "fixed":
        for key in ("start_mm", "goal_mm"):
            if key in written:
                raise ScenarioError(path, f"only a fixed task reads it (kind = \"fixed\"); "
                                    f"this task is {task.kind!r}, which draws its own: remove "
                                    "the key or set the kind", key=f"task.{key}")
    if task.kind == "trajectory":
        if "fixed_duration" in written and not task.fixed_duration:
            raise ScenarioError(path, "a trajectory task runs for max_steps whatever the "
                                "error (its tracking error over the whole reference): remove "
                                "fixed_duration = false", key="task.fixed_duration")
        return replace(task, fixed_duration=True)
    for key in TASK_KEYS:
        if f"task.{key}" in sweep and key != "goal":
            raise ScenarioError(path, "only a trajectory task sweeps it", key=f"task.{key}")
    for key in TRAJECTORY_ONLY_KEYS:
        if key in written:
            raise ScenarioError(path, f"only a trajectory task reads it (kind = "
                                f"\"trajectory\"); this task is {task.kind!r}: remove the key "
                                "or set the kind", key=f"task.{key}")
    return task


def check_configurations(value: str, path: str) -> None:
    """``extremal`` or ``random:N`` with an integer N >= 2."""
    key = "calibration.configurations"
    if value == "extremal":
        return
    if not value.startswith("random:"):
        raise ScenarioError(path, f"expected 'extremal' or 'random:N', got {value!r}", key=key)
    count = value.split(":", 1)[1]
    if not count.isdigit() or not 2 <= int(count) <= 100_000:
        raise ScenarioError(path, f"expected 'random:N' with an integer N in [2, 100000], got "
                            f"{value!r}", key=key)


def check_fixed_task(task: TaskConfig, preset: str | None, geometry: Any,
                      path: str) -> None:
    """A fixed task has 6 leg lengths per end, inside the nominal strokes."""
    from hexapod.geometry import preset as geometry_preset

    for key in ("start_mm", "goal_mm"):
        value = getattr(task, key)
        if value is None or len(value) != 6:
            got = "none" if value is None else f"{len(value)}"
            raise ScenarioError(path, f"a fixed task needs 6 leg lengths [mm], got {got}",
                                key=f"task.{key}")
    if geometry is None:
        geometry = geometry_preset(preset or "deltalab")
    lo, hi = (1e3 * x for x in geometry.stroke)
    for key in ("start_mm", "goal_mm"):
        for leg, q in enumerate(getattr(task, key)):
            if not lo <= q <= hi:
                raise ScenarioError(path, f"leg {leg}: {q:g} mm is outside the stroke "
                                    f"[{lo:g}, {hi:g}] mm", key=f"task.{key}")


def _close_attribute(spec: str) -> str | None:
    """For a ``module:attr`` whose attribute is misspelt, ``module:close`` (None when the
    module does not import or nothing is close)."""
    import importlib

    module, _, attr = spec.partition(":")
    try:
        names = [n for n in vars(importlib.import_module(module)) if not n.startswith("_")]
    except Exception:  # (the module's own failure is the message already)
        return None
    close = suggest(attr, names)
    return None if close is None else f"{module}:{close}"


def check_controllers(sc: Scenario) -> tuple[Scenario, list[str]]:
    """Resolve every controller of a scenario, give it its options and build it once.

    A misspelt name, an option a controller does not declare or refuses (a NaN gain), a
    ``[controller_options]`` key no controller declares, or a controller that commands
    what the scenario's world cannot apply (leg forces in the kinematic world) is reported
    before any trial runs, in the file's terms, instead of failing every trial.

    Returns:
        The scenario with each controller's options resolved (``[controller_options]``
        kept only where declared), and warnings to print.

    Raises:
        UnknownControllerError: A name no controller is registered under (with the close one).
        PluginLoadError: A ``module:attr`` that cannot be imported.
        ScenarioError: An option the controller refuses, naming the controller and option.
    """
    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.sim.plant import world_actuation
    from controllers.batch import actuation_of
    from controllers.exceptions import OptionError, PluginLoadError, UnknownControllerError
    from controllers.registry import registry
    from hexapod.exceptions import ActuationError

    tables = []
    for k, spec in enumerate(sc.controllers):
        where = spec.key or f"controllers[{k}]"
        try:
            tables.append(registry.options(spec.name))
        except UnknownControllerError as exc:
            if spec.key is None:  # named on the command line
                raise ScenarioError("--controllers", str(exc)) from None
            raise ScenarioError(sc.source, str(exc), key=where) from None
        except PluginLoadError as exc:  # a module:attr of the file: it said "command line"
            if spec.key is None:
                raise
            raise ScenarioError(sc.source, f"controller {spec.name!r} cannot be loaded: "
                                f"{exc.reason}", key=where,
                                suggestion=_close_attribute(spec.name)) from None
    specs, warnings = _shared_options(sc, tables)
    sc = replace(sc, controllers=tuple(specs))
    accepted, world = world_actuation(sc)
    for k, (spec, table) in enumerate(zip(sc.controllers, tables, strict=True)):
        where = spec.key or f"controllers[{k}]"
        named = spec.key or "--controllers"
        check_option_names(sc.source, spec, table, where)
        try:
            ctrl = registry.create(spec.name, **spec.options)
        except OptionError as exc:
            path, key = option_origin(sc.source, spec, exc.option, f"{where}.{exc.option}")
            raise ScenarioError(path, f"{spec.name}: {exc.problem}", key=key) from None
        except TypeError as exc:  # an option the factory (or the law it wraps) does not take
            raise _unexpected_option(sc.source, spec, table, where, exc) from None
        except UnknownControllerError as exc:  # a wrapper's inner law (latency-compensated)
            option = next((k for k, v in spec.options.items() if v == exc.name), None)
            if option is None:
                raise ScenarioError(sc.source, f"{spec.name}: {exc}", key=where) from None
            path, key = option_origin(sc.source, spec, option, f"{where}.{option}")
            raise ScenarioError(path, f"{spec.name}: {exc}", key=key) from None
        kind = actuation_of(ctrl)
        if kind not in accepted:
            try:
                from hexapod.actuation import check_actuation

                check_actuation(kind, accepted, world, spec.label)
            except ActuationError as exc:
                fix = ("set [robot] world = \"dynamic\" (or run with --world dynamic)"
                       if sc.world != "dynamic" else "choose another controller")
                raise ScenarioError(sc.source if spec.key else "--controllers",
                                    f"{exc}; {fix}",
                                    key=named if spec.key else None) from None
        warnings += gain_warnings(spec, table, sc.dt)
    return sc, warnings + unmatched_gains(sc.source, sc.controllers, tables)


#: The options that set a first-order law's gain schedule (``adaptive_gain`` overrides
#: ``gain``: ``docs/math.md`` section 6).
GAIN_OPTIONS = ("gain", "adaptive_gain")


def unmatched_gains(source: str, specs: Sequence[ControllerSpec], tables: list[Any]
                    ) -> list[str]:
    """A warning when the first-order laws of a study (those that declare
    ``adaptive_gain``) run under different gain schedules (gains from an options file,
    ``tune``'s or written on purpose, left out): their comparison then measures the
    gains as much as the laws (a law left at its constant default beside one given quick's adaptive
    gain reversed ``payload-saturation``'s verdicts at 40 and 55 kg).

    Args:
        source: The scenario file (for the text).
        specs: The controllers, their options resolved.
        tables: Their option tables.
    """
    schedules: dict[str, str] = {}
    for spec, table in zip(specs, tables, strict=True):
        if not table.declares("adaptive_gain"):
            continue
        if any(": controllers." in spec.option_keys.get(o, "") for o in GAIN_OPTIONS):
            continue  # run --options-file: tuned (the same effort) or chosen on purpose
        given = resolved_options(spec, table)
        lam = given.get("adaptive_gain")
        schedules[spec.label] = (f"adaptive_gain {[float(x) for x in lam]}" if lam is not None
                                 else f"constant gain {float(given.get('gain', 1.0)):g} 1/s")
    if len(set(schedules.values())) < 2:
        return []
    return [f"{source}: the first-order laws run under different gain schedules ("
            + "; ".join(f"{label}: {text}" for label, text in schedules.items())
            + "): their comparison measures the gains as much as the laws; give them one "
            "schedule ([controller_options] adaptive_gain or gain) or tune them all "
            "(hexapod-bench tune, docs/tuning.md)"]


def resolved_options(spec: ControllerSpec, table: Any) -> dict[str, Any]:
    """A controller's options as it runs with them: its table's defaults, the given
    ones over them."""
    return {**{o.name: o.default for o in table.options}, **spec.options}


def gain_warnings(spec: ControllerSpec, table: Any, dt: float) -> list[str]:
    """Gains beyond the bounds the docs state, said before any trial (a value in the
    wrong unit, rad/s for Hz, gives them): a first-order law's gain at or above ``2/dt``
    (the discrete loop is unstable, ``docs/tuning.md``), a computed-torque law's
    ``integral_gain`` at or above ``2 damping omega_n`` (unstable with an exact model,
    ``docs/dynamic-world.md``, "Integral action").

    Args:
        spec: The controller, its options as given.
        table: Its option table (the defaults of the options not given).
        dt: The control period [s].
    """
    given = resolved_options(spec, table)

    def value(name: str) -> Any:
        return given.get(name)

    out = []
    gains: list[float] = []
    if table.declares("adaptive_gain") and value("adaptive_gain") is not None:
        lam = value("adaptive_gain")
        gains = [float(lam[0]), float(lam[1])]  # (lambda0, lambda_inf): the largest gain
    elif table.declares("gain") and isinstance(value("gain"), int | float):
        gains = [float(value("gain"))]
    if gains and max(gains) >= 2.0 / dt:
        out.append(f"{spec.label}: gain {max(gains):g} 1/s is at least 2/dt = {2.0 / dt:g} "
                   f"1/s (robot.dt {dt * 1e3:g} ms): the discrete loop is unstable "
                   "(docs/tuning.md)")
    if table.declares("integral_gain") and table.declares("natural_frequency"):
        ki, fn = value("integral_gain"), value("natural_frequency")
        zeta = value("damping") if table.declares("damping") else 1.0
        if all(isinstance(x, int | float) for x in (ki, fn, zeta)) and ki > 0:
            bound = 2.0 * float(zeta) * 2.0 * math.pi * float(fn)
            if ki >= bound:
                out.append(f"{spec.label}: integral_gain {ki:g} 1/s is not below 2 damping "
                           f"omega_n = {bound:.3g} 1/s (natural_frequency {fn:g} Hz, damping "
                           f"{zeta:g}): the error grows even with an exact model "
                           "(docs/dynamic-world.md, \"Integral action\")")
    return out


#: The keys of ``[reference]`` (the seed's figures the report prints beside ours).
REFERENCE_KEYS = ("text", "header", "rows")


def check_reference(reference: Any, path: str) -> dict[str, Any]:
    """``[reference]``: a text, and a table of ``header`` (strings) and ``rows`` (lists
    as long as the header), both or neither (a flat ``rows`` crashed the report after every
    trial had run; a misspelt key left the table out without a word).

    Raises:
        ScenarioError: Naming the key and what it holds.
    """
    if not isinstance(reference, dict):
        raise ScenarioError(path, "expected a table", key="reference")
    for key in reference:
        if key not in REFERENCE_KEYS:
            raise ScenarioError(path, f"unknown key; expected one of {', '.join(REFERENCE_KEYS)}",
                                key=f"reference.{key}", suggestion=suggest(key, REFERENCE_KEYS))
    if "text" in reference and not isinstance(reference["text"], str):
        raise ScenarioError(path, f"expected a string, got {reference['text']!r}",
                            key="reference.text")
    if ("header" in reference) != ("rows" in reference):
        missing = "rows" if "header" in reference else "header"
        raise ScenarioError(path, f"a table needs both header and rows: {missing} missing",
                            key=f"reference.{missing}")
    if "header" in reference:
        header, rows = reference["header"], reference["rows"]
        if not isinstance(header, list) or not header:
            raise ScenarioError(path, f"expected a list of column titles, got {header!r}",
                                key="reference.header")
        for k, row in enumerate(rows if isinstance(rows, list) else [rows]):
            if not isinstance(row, list) or len(row) != len(header):
                raise ScenarioError(path, f"expected a list of rows of {len(header)} values "
                                    f"(one per header column), got {row!r}"
                                    + ("" if isinstance(rows, list) else " (not a list)"),
                                    key=f"reference.rows[{k}]" if isinstance(rows, list)
                                    else "reference.rows")
    return reference
