"""What a run directory's ``run.json`` says of its studies, for the commands that read
finished runs (``compare``, ``reproduce``): which scenarios repeat one fixed task, and
how the studies of two runs differ."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

#: Keys of a study record that do not make two runs' rows differ (the version of the
#: package is compared by the determinism check itself; the trial count only decides
#: which trials match).
_NOT_COMPARED = frozenset({"version", "trials"})


def run_meta(directory: str | Path) -> dict[str, Any]:
    """A run directory's ``run.json`` (empty when missing or unreadable: a run written
    by hand, or before the record existed)."""
    path = Path(directory) / "run.json"
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return meta if isinstance(meta, dict) else {}


def _studies(meta: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {name: entry["study"] for name, entry in (meta.get("scenarios") or {}).items()
            if isinstance(entry, dict) and isinstance(entry.get("study"), dict)}


def fixed_task_scenarios(meta: dict[str, Any]) -> list[str]:
    """The scenarios of a run whose task is one fixed start and goal (``kind = "fixed"``):
    their trials repeat ONE task with other noise and calibration-error draws."""
    return sorted(name for name, study in _studies(meta).items()
                  if study.get("task.kind") == "fixed")


def study_differences(meta_a: dict[str, Any], meta_b: dict[str, Any]) -> list[str]:
    """How the studies two runs share differ (``scenario: key A=... B=...``), the
    options of their controllers included: rows of such runs are not expected to be
    identical."""
    a, b = _studies(meta_a), _studies(meta_b)
    out = []
    for name in sorted(set(a) & set(b)):
        for key in sorted(set(a[name]) | set(b[name])):
            if key in _NOT_COMPARED or a[name].get(key) == b[name].get(key):
                continue
            out.append(f"{name}: {key} A={a[name].get(key)!r} B={b[name].get(key)!r}")
    return out


__all__ = ["fixed_task_scenarios", "run_meta", "study_differences"]
