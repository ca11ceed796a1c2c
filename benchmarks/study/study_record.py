"""A run directory holds one study: what defines it, the check of ``run --resume``, and the
list of the commands that wrote the directory.

``run.json`` records, for each scenario of the run, the *study* (:func:`study_of`): every
setting that decides which trials run and what they do (the scenario's content with the
files it names reduced to a hash of their content, the world, the controllers with their
options, the seed, the step budget, the sweep and the trial count). A later ``run`` into
the same directory is compared with it before any trial runs (:func:`check_same_study`):
any difference is refused, naming each one (``--seed: 1 in the directory, 99 given``); a
larger trial count with everything else the same *grows* the study and is said. The
scenario's description and the papers' reference figures are words, not settings: they
are not part of the study. The backend is recorded in every row (the report keeps the
backends apart), so it is not part of the study either.

``run.json`` also keeps every command line that wrote to the directory
(:func:`command_entry`, oldest first), each with its time, the package version and what
it did; the report lists them. See ``docs/outputs.md``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shlex
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from benchmarks.exceptions import StudyMismatchError

#: The key of a scenario's study in ``run.json`` (``scenarios[NAME][STUDY_KEY]``).
STUDY_KEY = "study"
#: Version of the study record (a record of another version is compared key by key all
#: the same: a key one side lacks is a difference).
STUDY_VERSION = 1
#: Scenario fields that are not settings of the study (words, the file's path, the data
#: read from the files, which are hashed by file instead).
_NOT_SETTINGS = frozenset({"name", "description", "reference", "sweep", "source",
                           "geometry_data", "camera_data", "calibration_points",
                           "model_data", "controller_options"})
#: Keys earlier versions recorded that say nothing the others do not, ignored on both
#: sides: the file's ``[controller_options]`` are in each controller's entry (the ones
#: it took), and the runnable copy of the inputs folds them there (a study resumed from
#: ``inputs/NAME/scenario.toml`` has none left to give).
_REDUNDANT = frozenset({"controller_options"})
#: Fields that name a file: the study holds a hash of its content.
_FILE_FIELDS = {"robot_geometry": "robot.geometry", "robot_model": "robot.model",
                "camera_file": "camera.file",
                "calibration.file": "calibration.file"}
#: Keys a command-line option sets: differences are named by the option.
OPTIONS = {"seed": "--seed", "trials": "--trials", "world": "--world",
           "controllers": "--controllers", "task.max_steps": "--max-steps",
           "task.goal": "--goal"}
#: Keys added after studies were first recorded, with the value a record without them
#: ran with (a directory of that time resumes under the same settings).
_ADDED = {"task.goal": "mixed"}
_ABSENT = object()


def _digest(data: bytes) -> str:
    return "sha256:" + hashlib.sha256(data).hexdigest()


def file_digest(path: str | Path) -> str:
    """A hash of a file's content: of its parsed table for a TOML file (so that the copy
    kept in ``inputs/``, whose paths are made local, has the hash of the original),
    with a camera file's ``opencv`` file replaced by that file's hash; of its bytes
    otherwise.

    Raises:
        OSError: The file cannot be read.
    """
    p = Path(path)
    if p.suffix != ".toml":
        return _digest(p.read_bytes())
    import tomllib

    try:
        table = tomllib.loads(p.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError):
        return _digest(p.read_bytes())
    ref = table.get("opencv")
    if isinstance(ref, str):
        ref_path = Path(ref) if Path(ref).is_absolute() else p.parent / ref
        table["opencv"] = file_digest(ref_path) if ref_path.is_file() else ref
    return _digest(json.dumps(table, sort_keys=True, default=str).encode())


def _plain(value: Any) -> Any:
    """A JSON value (tuples as lists, numpy as lists, dataclasses as dicts)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def _controller(spec: Any) -> str:
    """``label`` or ``label (name, option=value, ...)``."""
    extra = ([spec.name] if spec.name != spec.label else []) + [
        f"{k}={json.dumps(_plain(v), sort_keys=True)}" for k, v in sorted(spec.options.items())]
    return spec.label + (f" ({', '.join(extra)})" if extra else "")


def study_of(sc: Any) -> dict[str, Any]:
    """The study a scenario defines, as ``run.json`` records it: flat keys (``seed``,
    ``world``, ``noise.amplitude_deg``, ``sweep.noise.amplitude_deg``, ``robot.geometry``
    as a content hash, ...) with JSON values.

    Args:
        sc: The scenario as run (command-line overrides applied, before its sweep is
            expanded).
    """
    out: dict[str, Any] = {"version": STUDY_VERSION}
    for f in dataclasses.fields(sc):
        if f.name in _NOT_SETTINGS:
            continue
        value = getattr(sc, f.name)
        if f.name == "controllers":
            out["controllers"] = [_controller(c) for c in value]
        elif f.name == "sweep_axes":
            for key, values in value.items():
                out[f"sweep.{key}"] = _plain(values)
        elif f.name in _FILE_FIELDS:
            out[_FILE_FIELDS[f.name]] = file_digest(value) if value else None
        elif dataclasses.is_dataclass(value):
            for sub in dataclasses.fields(value):
                key = f"{f.name}.{sub.name}"
                v = getattr(value, sub.name)
                out[key] = (file_digest(v) if v else None) if key in _FILE_FIELDS else _plain(v)
        else:
            out[f.name] = _plain(value)
    result: dict[str, Any] = json.loads(json.dumps(out, sort_keys=True, default=str))
    return result


def _show(key: str, value: Any) -> str:
    if value is _ABSENT:
        return "absent"
    if key == "controllers" and isinstance(value, list):
        return ", ".join(str(v) for v in value) or "none"
    if isinstance(value, str) and value.startswith("sha256:"):
        return f"content {value[7:19]}"
    return json.dumps(value) if not isinstance(value, str) else value


def _name(key: str) -> str:
    return OPTIONS.get(key, key if key in _FILE_FIELDS.values() else f"scenario key {key}")


def differences(recorded: dict[str, Any], given: dict[str, Any]) -> tuple[list[str], int | None]:
    """The differences between the study of a directory and the one given.

    Returns:
        Each difference in words (``--seed: 1 in the directory, 99 given``), and the
        trial count the study grows to (None: it does not grow). Fewer trials than the
        directory's is a difference (a study grows, it does not shrink).
    """
    lines: list[str] = []
    grows = None
    for key in sorted(set(recorded) | set(given)):
        a, b = recorded.get(key, _ADDED.get(key, _ABSENT)), given.get(key, _ABSENT)
        if key == "version" or key in _REDUNDANT or a == b:
            continue
        if key == "trials" and isinstance(a, int) and isinstance(b, int):
            if b > a:
                grows = b
                continue
            lines.append(f"--trials: {a} in the directory, {b} given (a study grows, it "
                         f"does not shrink: give --trials {a} or more)")
            continue
        lines.append(f"{_name(key)}: {_show(key, a)} in the directory, {_show(key, b)} given")
    return lines, grows


def check_same_study(out: Path, meta: dict[str, Any], scenarios: list[Any]
                     ) -> dict[str, tuple[int, int]]:
    """Refuse a run into a directory that holds another study.

    Args:
        out: The run directory.
        meta: Its ``run.json`` (empty for a new directory: nothing to check).
        scenarios: The scenarios given (overrides applied).

    Returns:
        The scenarios that grow: name -> (trials in the directory, trials given).

    Raises:
        StudyMismatchError: Naming every difference (another set of scenarios, or a
            setting of one), or a directory written before studies were recorded.
    """
    kept = meta.get("scenarios") or {}
    if not kept:
        return {}
    lines: list[str] = []
    given_names = [sc.name for sc in scenarios]
    if sorted(kept) != sorted(given_names):
        lines.append(f"scenarios: {', '.join(sorted(kept))} in the directory, "
                     f"{', '.join(sorted(given_names)) or 'none'} given")
    unrecorded = sorted(n for n, entry in kept.items()
                        if n in given_names and STUDY_KEY not in entry)
    if unrecorded:
        raise StudyMismatchError(str(out), [
            f"{', '.join(unrecorded)}: the directory was written by an earlier hexapod-bench "
            "that did not record the study (seed, world, controllers, scenario content), so "
            "a resume cannot be checked; finish it with the version that started it, or run "
            "into another --out"])
    grows: dict[str, tuple[int, int]] = {}
    for sc in scenarios:
        if sc.name not in kept:
            continue
        recorded = kept[sc.name][STUDY_KEY]
        diff, grow = differences(recorded, study_of(sc))
        prefix = f"{sc.name}: " if len(kept) > 1 or len(scenarios) > 1 else ""
        lines += [prefix + d for d in diff]
        if grow is not None:
            grows[sc.name] = (int(recorded["trials"]), grow)
    if lines:
        raise StudyMismatchError(str(out), lines)
    return grows


def package_version() -> str:
    """``hexapod-vs X.Y.Z`` (``unknown`` when not installed)."""
    import importlib.metadata as md

    try:
        return f"hexapod-vs {md.version('hexapod-vs')}"
    except md.PackageNotFoundError:
        return "hexapod-vs unknown"


def command_line(argv: list[str]) -> str:
    """``hexapod-bench ARGS`` quoted for a shell."""
    return "hexapod-bench " + " ".join(shlex.quote(a) for a in argv)


def command_entry(argv: list[str], did: str) -> dict[str, str]:
    """One entry of ``run.json``'s ``commands``: the command line, the time (UTC, ISO
    8601), the package version and what it did."""
    return {"command": command_line(argv),
            "time": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "version": package_version(), "did": did}


def commands_of(meta: dict[str, Any]) -> list[dict[str, Any]]:
    """The commands that wrote a directory, oldest first (a ``run.json`` written before
    the list existed gives its one ``command``, time and version unknown)."""
    commands = meta.get("commands")
    if isinstance(commands, list):
        return [c for c in commands if isinstance(c, dict)]
    if isinstance(meta.get("command"), str):
        return [{"command": meta["command"], "time": None, "version": None,
                 "did": "the last command before the list was kept"}]
    return []


def record_command(meta: dict[str, Any], entry: dict[str, str]) -> None:
    """Append a command to ``meta["commands"]`` (converting an older single ``command``)."""
    meta["commands"] = [*commands_of(meta), entry]
    meta.pop("command", None)


def command_lines(meta: dict[str, Any]) -> list[str]:
    """The report's "Commands" lines: every command that wrote the directory, oldest
    first, with its time, version and what it did (none: no line)."""
    commands = commands_of(meta)
    if not commands:
        return []
    lines = ["", "Commands that wrote this directory (oldest first):", ""]
    for k, c in enumerate(commands, 1):
        when = ", ".join(str(x) for x in (c.get("time"), c.get("version")) if x)
        lines.append(f"{k}. `{c.get('command', '?')}`" + (f" ({when})" if when else "")
                     + (f": {c['did']}" if c.get("did") else ""))
    return lines
