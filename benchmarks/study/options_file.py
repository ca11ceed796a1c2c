"""Per-controller options files: what ``hexapod-bench tune`` writes and ``hexapod-bench
run --options-file FILE`` uses (``docs/tuning.md``).

The file is TOML: a ``[controllers."LABEL"]`` table of options for each controller label
(they replace the scenario's options of the same names, the others stay), and, when
``tune`` wrote it, a ``[tuning]`` table saying how they were chosen (scenario, criterion,
budget, tuning seed). ``run`` records the file in ``run.json`` (``options_file``: its
path, content hash, options and ``[tuning]`` table) and the report says "tuned (file,
criterion, budget)" or "as given".
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from benchmarks.exceptions import ScenarioError
from hexapod.config import suggest

#: The top-level tables of an options file.
TABLES = ("controllers", "tuning")
#: The key of ``run.json`` that records the options file.
META_KEY = "options_file"


@dataclass(frozen=True)
class OptionsFile:
    """An options file, read.

    Attributes:
        path: Where it was read.
        controllers: Options by controller label.
        tuning: Its ``[tuning]`` table (empty: options written by hand).
        digest: ``sha256:`` of its bytes.
    """

    path: str
    controllers: dict[str, dict[str, Any]]
    tuning: dict[str, Any] = field(default_factory=dict)
    digest: str = ""

    def record(self) -> dict[str, Any]:
        """What ``run.json`` keeps of it."""
        return {"path": self.path, "digest": self.digest, "controllers": self.controllers,
                "tuning": self.tuning}


def load_options_file(path: str | Path) -> OptionsFile:
    """Read an options file.

    Raises:
        ScenarioError: The file cannot be read, an unknown table, a controller entry that
            is not a table (naming the file and key).
    """
    p = str(path)
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise ScenarioError(p, f"file not found (--options-file): tried "
                            f"{Path(path).resolve()}") from None
    except OSError as exc:
        raise ScenarioError(p, f"cannot be read: {exc}") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ScenarioError(p, f"cannot be read as TOML: {exc}") from None
    for key in data:
        if key not in TABLES:
            raise ScenarioError(p, f"unknown table (an options file has {', '.join(TABLES)})",
                                key=key, suggestion=suggest(key, TABLES))
    ctrls = data.get("controllers", {})
    if not isinstance(ctrls, dict) or not ctrls:
        raise ScenarioError(p, "expected [controllers.\"LABEL\"] tables of options, one per "
                            "controller label", key="controllers")
    for label, opts in ctrls.items():
        if not isinstance(opts, dict):
            raise ScenarioError(p, f"expected a table of options, got {opts!r}",
                                key=f'controllers."{label}"')
    tuning = data.get("tuning", {})
    if not isinstance(tuning, dict):
        raise ScenarioError(p, f"expected a table, got {tuning!r}", key="tuning")
    return OptionsFile(p, {k: dict(v) for k, v in ctrls.items()}, dict(tuning),
                       "sha256:" + hashlib.sha256(raw).hexdigest())


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):  # (TOML has no null: a key without a value is left out)
        return "{ " + ", ".join(f"{json.dumps(k)} = {_toml_value(v)}"
                                for k, v in value.items() if v is not None) + " }"
    raise TypeError(f"cannot write {value!r} to TOML")


def write_options_file(path: str | Path, controllers: dict[str, dict[str, Any]],
                       tuning: dict[str, Any], header: str = "") -> None:
    """Write an options file (``[tuning]`` first, then one table per controller)."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines += ["", "[tuning]"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in tuning.items() if v is not None]
    for label, opts in controllers.items():
        lines += ["", f"[controllers.{json.dumps(label)}]"]
        lines += [f"{k} = {_toml_value(v)}" for k, v in opts.items()]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def controller_options(spec: Any) -> Any:
    """The options a controller of the scenario takes: its own, and for a wrapper that
    hands options on to a law it wraps (``latency-compensated``, ``law = "leg-edge"``)
    that law's too: its search space in ``tune`` is the law's (without them it ran its
    options as given alone, a smaller budget than the others'), and an options file's
    misspelt option of the law is refused naming the file (it was a TypeError naming
    the scenario)."""
    from controllers.options import OptionTable
    from controllers.registry import registry

    table = registry.options(spec.name)
    if not (table.open and table.declares("law")):
        return table
    law = spec.options.get("law", next(o.default for o in table.options if o.name == "law"))
    if not isinstance(law, str):
        return table
    inner = registry.options(law)
    return OptionTable(table.options + tuple(o for o in inner.options
                                             if not table.declares(o.name)), inner.open,
                       inner.passes_on)


def apply_options_file(scenarios: list[Any], options: OptionsFile) -> list[Any]:
    """The scenarios with each controller's options from the file (the file's value of
    an option replaces the scenario's; the scenario's other options stay).

    Raises:
        ScenarioError: A label of the file that no scenario of the run has (with the
            labels there are), or an option the controller does not take (naming the
            file, the key and the controller's options).
    """
    import controllers  # noqa: F401 - registers the built-ins

    labels = {c.label for sc in scenarios for c in sc.controllers}
    for label in options.controllers:
        if label not in labels:
            raise ScenarioError(options.path, "no controller of the run has this label (its "
                                f"controllers: {', '.join(sorted(labels))})",
                                key=f'controllers."{label}"',
                                suggestion=suggest(label, sorted(labels)))
    out = []
    for sc in scenarios:
        specs = []
        for spec in sc.controllers:
            given = options.controllers.get(spec.label)
            if given is None:
                specs.append(spec)
                continue
            table = controller_options(spec)
            keys = {}
            for option in given:
                key = f'{options.path}: controllers."{spec.label}".{option}'
                if not (table.open or table.declares(option)):
                    raise ScenarioError(
                        options.path, f"controller '{spec.name}' has no option '{option}'; "
                        f"its options: {', '.join(table.names) or 'none'} (hexapod-bench "
                        f"list --options {spec.name})", key=f'controllers."{spec.label}".'
                        f"{option}", suggestion=suggest(option, table.names))
                keys[option] = key
            specs.append(replace(spec, options={**spec.options, **given},
                                 option_keys={**spec.option_keys, **keys}))
        out.append(replace(sc, controllers=tuple(specs)))
    return out


def with_options_file(scenarios: list[Any], path: str | None
                      ) -> tuple[list[Any], dict[str, Any] | None]:
    """``run --options-file``: the scenarios with the file's options and the file's record
    for ``run.json`` (unchanged and None without a file)."""
    if not path:
        return scenarios, None
    options = load_options_file(path)
    return apply_options_file(scenarios, options), options.record()


def goal_mismatches(scenarios: list[Any], record: dict[str, Any] | None) -> list[str]:
    """Warnings for the scenarios run under another goal setting than the options file
    was tuned under (the controllers are told other things of the goal), on another
    scenario than it was tuned on, or with the tuning's own seed (its trials are the
    tuning trials: nothing is held out)."""
    tuning = (record or {}).get("tuning") or {}
    if not record or not tuning:
        return []
    out = []
    tuned = tuning.get("goal")
    for sc in scenarios:
        if tuned and sc.task.goal != tuned:
            out.append(f"{record['path']}: options tuned under the goal setting {tuned!r}, "
                       f"{sc.name} runs under {sc.task.goal!r}: the controllers are told "
                       "other things of the goal than when they were tuned "
                       "(docs/scenarios.md, \"Fairness\")")
        out += [f"{record['path']}: {text}" for text in _not_held_out(
            tuning, sc.name, sc.seed)]
    return out


def _not_held_out(tuning: dict[str, Any], scenario: str, seed: Any) -> list[str]:
    """Why a study does not test the options of ``tuning`` on held-out trials: tuned on
    another scenario, or run with the tuning's own seed."""
    out = []
    if tuning.get("scenario") and tuning["scenario"] != scenario:
        out.append(f"options tuned on {tuning['scenario']}, not on {scenario}: its trials "
                   "test them, but they were not tuned for it")
    if seed is not None and seed == tuning.get("tuning_seed"):
        out.append(f"{scenario} runs with the tuning's own seed {seed}: its trials are "
                   "the tuning trials, not held out")
    return out


#: The keys of a ``[tuning]`` table that make a file's options "tuned" in a report (a
#: table without them, written by hand, is reported as hand-written options).
TUNING_KEYS = ("scenario", "criterion", "budget", "tuning_seed", "study_seed")


def record_options(meta: dict[str, Any], record: dict[str, Any] | None) -> None:
    """Keep the options file's record in ``run.json`` (a run without one: none kept)."""
    if record:
        meta[META_KEY] = record
    else:
        meta.pop(META_KEY, None)


def options_line(meta: dict[str, Any]) -> str:
    """The report's line on the controllers' options: tuned (file, criterion, budget) or
    as given."""
    rec = meta.get(META_KEY)
    if not rec:
        return ("Controller options: **as given** (the scenario's; no `--options-file`, "
                "docs/tuning.md).")
    if rec.get("candidates"):  # (its header said "as given" of searched options)
        return ("Controller options: the **candidates** of `hexapod-bench tune` "
                "(`LABEL:c0` the options as given, `LABEL:c1`... the searched ones: "
                "`tuning.json` beside this directory lists each; docs/tuning.md).")
    tuning = rec.get("tuning") or {}
    labels = ", ".join(rec.get("controllers", {}))
    others = _run_labels(meta) - set(rec.get("controllers", {}))
    given = (f" Options of {', '.join(sorted(others))}: **as given** (the scenario's; not in "
             "the file)." if others else "")
    missing = [k for k in TUNING_KEYS if tuning.get(k) is None]
    if not tuning or missing:
        table = (f"; its [tuning] table lacks {', '.join(missing)}" if tuning else "")
        return (f"Controller options of {labels}: from `{rec.get('path')}` (written by hand, "
                f"not tuned{table}; {rec.get('digest', '')[:19]}).{given}")
    held = ("held-out trials" if tuning.get("held_out", True) else "the same fixed task "
            "with other noise draws: not held out")
    studies = (meta.get("scenarios") or {}).items()
    not_held = [t for name, entry in studies
                for t in _not_held_out(tuning, name, (entry.get("study") or {}).get("seed"))]
    if not_held:
        held = "NOT held out: " + "; ".join(not_held)
    searched = tuning.get("candidates_run") or {}
    kept = sorted(label for label, t in (tuning.get("shown_better") or {}).items()
                  if t.get("kept") == "as given" and searched.get(label, 2) > 1)
    unsearched = sorted(label for label, n in searched.items() if n <= 1)
    goal = f", goal setting {tuning['goal']}" if tuning.get("goal") else ""
    return (f"Controller options of {labels}: **tuned** (`{rec.get('path')}`, "
            f"{rec.get('digest', '')[:19]}): by `hexapod-bench tune` on "
            f"{tuning.get('scenario')}, criterion {tuning.get('criterion')}, budget "
            f"{tuning.get('budget')}{goal}, tuning seed {tuning.get('tuning_seed')} (the "
            f"study's: {tuning.get('study_seed')}; {held})"
            + (f"; kept as given, no candidate shown better: {', '.join(kept)}" if kept
               else "")
            + (f"; nothing to search, as given: {', '.join(unsearched)}" if unsearched
               else "") + "." + given)


def _run_labels(meta: dict[str, Any]) -> set[str]:
    """The labels of the controllers a run's studies ran (``run.json``'s studies record
    each as ``label`` or ``label (name, option=value, ...)``)."""
    return {str(c).split(" (", 1)[0] for entry in (meta.get("scenarios") or {}).values()
            for c in (entry.get("study") or {}).get("controllers", [])}
