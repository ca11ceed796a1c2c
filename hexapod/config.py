"""TOML helpers shared by every package: strict keys, close-name suggestions."""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from hexapod.exceptions import ConfigFileError


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file, turning I/O and syntax problems into :class:`ConfigFileError`.

    Args:
        path: File to read.

    Returns:
        The parsed table.
    """
    p = Path(path)
    try:
        with p.open("rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigFileError(str(p), "file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigFileError(str(p), f"not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:  # an image, an archive: not a text file
        raise ConfigFileError(str(p), f"not a TOML text file (not UTF-8 text: byte "
                                      f"{exc.object[exc.start]:#04x} at offset {exc.start})"
                              ) from None
    except OSError as exc:
        raise ConfigFileError(str(p), f"cannot be read: {exc}") from None


#: Keys only one kind of the project's files has: a file given where another kind is
#: meant (a robot file named as the camera file) is told what it is.
KIND_MARKERS = {"robot file": ("base_points_mm", "platform_points_mm"),
                "camera file": ("fx_px", "opencv", "camera_from_base"),
                "scenario": ("controllers", "task", "noise")}
#: Where each kind of file is given.
KIND_PLACES = {"robot file": "[robot] geometry in a scenario, or --geometry",
               "camera file": "[camera] file in a scenario, or --camera-file",
               "scenario": "the SCENARIO of hexapod-bench run or check"}


def check_file_kind(table: Mapping[str, Any], path: str, expected: str) -> None:
    """Refuse a file of another kind than ``expected`` (a key of :data:`KIND_MARKERS`),
    naming what it is and where it goes.

    Raises:
        ConfigFileError: The table has another kind's marker keys and none of its own.
    """
    if any(k in table for k in KIND_MARKERS[expected]):
        return
    for kind, markers in KIND_MARKERS.items():
        found = [k for k in markers if k in table]
        if kind != expected and found:
            raise ConfigFileError(path, f"a {kind} (it has '{found[0]}'), not a {expected}: "
                                  f"a {kind} goes to {KIND_PLACES[kind]}", key=found[0])


def suggest(name: str, candidates: Iterable[str]) -> str | None:
    """Return the candidate closest to ``name``, if one is close enough."""
    match = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return match[0] if match else None


def check_keys(
    table: Mapping[str, Any],
    allowed: Iterable[str],
    path: str,
    prefix: str = "",
    required: Iterable[str] = (),
) -> None:
    """Reject unknown keys (suggesting the close one) and missing required keys.

    Args:
        table: The table to check.
        allowed: Every key the table may have.
        path: File name, for the message.
        prefix: Dotted name of the table, for the message.
        required: Keys that must be present.
    """
    allowed = list(allowed)
    for key in table:
        if key not in allowed:
            raise ConfigFileError(
                path,
                f"unknown key; expected one of {', '.join(sorted(allowed))}",
                key=prefix + key,
                suggestion=suggest(key, allowed),
            )
    for key in required:
        if key not in table:
            raise ConfigFileError(path, "missing required key", key=prefix + key)


def get_number(table: Mapping[str, Any], key: str, path: str, prefix: str = "") -> float:
    """Read a finite number from ``table[key]``."""
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigFileError(path, f"expected a finite number, got {value!r}", key=prefix + key)
    return float(value)


def _not_a_number(value: Any) -> Any:
    """The first entry of a nested list that is text or a boolean (None: none is)."""
    if isinstance(value, list | tuple):
        for v in value:
            if (found := _not_a_number(v)) is not None:
                return found
        return None
    return value if isinstance(value, str | bool) else None


def _ragged(value: Any, shape: tuple[int, ...]) -> str:
    """``: row 2 (leg 2) has 2 numbers`` for a list of rows whose first wrong row is
    named (``(leg i)`` for a point per leg); empty where rows do not explain it."""
    if len(shape) != 2 or not isinstance(value, list) or not any(
            isinstance(row, list) for row in value):
        return ""
    for i, row in enumerate(value):
        n = len(row) if isinstance(row, list) else None
        if n != shape[1]:
            leg = f" (leg {i})" if shape == (6, 3) else ""
            has = "is not a row" if n is None else f"has {n} number{'s' * (n != 1)}"
            return f": row {i}{leg} {has}, not {shape[1]}"
    return ""


def get_matrix(
    table: Mapping[str, Any], key: str, shape: tuple[int, ...], path: str, prefix: str = ""
) -> np.ndarray:
    """Read a nested list of finite numbers of the given shape from ``table[key]``."""
    value = table[key]
    text = _not_a_number(value)
    if text is not None:  # ("410" would convert, silently: a typo in a file, refused)
        raise ConfigFileError(
            path, f"expected an array of numbers of shape {shape}, got {text!r}",
            key=prefix + key)
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigFileError(
            path, f"expected an array of numbers of shape {shape}{_ragged(value, shape)}",
            key=prefix + key) from None
    if arr.shape != shape:
        raise ConfigFileError(
            path, f"expected shape {shape}, got {arr.shape}{_ragged(value, shape)}",
            key=prefix + key)
    bad = np.argwhere(~np.isfinite(arr))
    if len(bad):
        where = tuple(int(i) for i in bad[0])
        if shape == (6, 3):  # a point per leg
            what = f"leg {where[0]}: its point's {'xyz'[where[1]]} coordinate is {arr[where]}"
        else:
            what = f"entry {list(where)} is {arr[where]}"
        raise ConfigFileError(path, f"contains NaN or inf: {what}", key=prefix + key)
    return arr
