"""The published figures ``hexapod-bench reproduce`` checks, read from the declared file.

Every figure is one row of ``benchmarks/scenarios/declared/paper_figures.toml``, written
before any run: the paper's number as printed, its unit, the rule and the tolerance, the
statistic of the framework that is compared and the study it is read from
(docs/reproduction.md, "The scorecard"). :func:`load_figures` reads and validates it;
a bad row is refused naming the file, the row and the key. The papers
(docs/references.md):

- seed000: T. Dallej, H. Hadj-Abdelkader, N. Andreff, P. Martinet, "Kinematic
  calibration of a Gough-Stewart platform using an omnidirectional camera", IROS 2006.
- seed001: N. Andreff, P. Martinet, "Visually servoing a Gough-Stewart parallel robot
  allows for reduced and linear kinematic calibration", ICINCO 2005.
- seed002: N. Andreff, T. Dallej, P. Martinet, "Image-based visual servoing of
  Gough-Stewart parallel manipulators using legs observation", IFAC 2006.
- seed003: O. Tahri, Y. Mezouar, N. Andreff, P. Martinet, "Omnidirectional
  visual-servo of a Gough-Stewart platform", IEEE T-RO 25(1), 2009.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

from benchmarks.exceptions import FigureFileError

#: Trials per study: (full, --quick).
TRIALS: dict[str, tuple[int, int]] = {
    "andreff2005-noise": (100, 30),
    "andreff2006-front-camera": (20, 10),
    "andreff2006-images": (20, 6),
    "tahri2009-convergence": (10000, 1000),
    "tahri2009-convergence-desired": (1000, 100),
    "tahri2009-images": (20, 6),
}
#: Repetitions of the calibration studies: (full, --quick).
REPEATS = (100, 30)
#: Studies whose every trial keeps its time series (the tail statistics of seed 001).
RECORD_ALL = {"andreff2005-noise"}
#: Fraction of a fixed-duration trial read as its convergence tail (as the report).
TAIL_FRACTION = 0.2
#: The papers.
SEEDS = ("seed000", "seed001", "seed002", "seed003")
#: What a row's ``kind`` may be: a printed number, or a stated outcome.
KINDS = ("number", "claim")
#: The rules: the interval meets the paper's number +- tolerance, or lies below it.
RULES = ("equal", "below")
#: Units of the paper's numbers and their scale to the framework's (mm, or a fraction).
UNITS = {"mm": 1.0, "cm": 10.0, "%": 0.01}
#: The statistics, and whether each reads a run (``run:``) or calibrations.
STATISTICS = {"median": "run", "median_tail_max": "run", "rate": "run",
              "calibration_rms_median": "calibrate", "calibration_worst_point": "calibrate"}
#: The default declared file.
DEFAULT_FILE = "scenarios/declared/paper_figures.toml"

_REQUIRED = ("id", "seed", "where", "quantity", "paper", "kind", "value", "unit", "rule",
             "paper_trials", "statistic", "study")
_OPTIONAL = ("tolerance", "sweep", "controller", "other", "other_value", "column",
             "variant_of", "why")


@dataclass(frozen=True)
class Figure:
    """One published figure, one row of the scorecard.

    Attributes:
        id: Unique name of the row.
        seed: ``seed000`` ... ``seed003``.
        where: Section or figure of the paper.
        quantity: What is compared, in words.
        paper: The paper's figure as printed.
        kind: ``number`` (within / outside) or ``claim`` (within / contradicts).
        value: The paper's number in ``unit`` (a claim: the rate it states, in %).
        unit: ``mm``, ``cm`` or ``%``.
        rule: ``equal`` or ``below``.
        tolerance: Half-width of the paper's number in ``unit`` (``equal``).
        paper_trials: 1 (the paper's figure is one trial or one calibration) or None
            (many).
        statistic: See :data:`STATISTICS`.
        study: ``run:SCENARIO`` or ``calibrate:SCENARIO[:omni]``.
        sweep: Sweep values selecting the point (``{"noise_amplitude_deg": 0.05}``).
        controller: The controller (run studies).
        other: A second controller whose rate must meet ``other_value`` (a claim such
            as "the edge law converges, the direction law does not").
        other_value: The rate ``other`` must meet, in ``unit``.
        column: The column of the ``median`` statistic.
        variant_of: The id of the figure this row tests under another setting ("" for
            a paper figure's own row).
        why_outside: The known reason, shown when the row is not within.
    """

    id: str
    seed: str
    where: str
    quantity: str
    paper: str
    kind: str
    value: float
    unit: str
    rule: str
    statistic: str
    study: str
    tolerance: float = 0.0
    paper_trials: int | None = None
    sweep: dict[str, Any] = field(default_factory=dict)
    controller: str = ""
    other: str = ""
    other_value: float | None = None
    column: str = ""
    variant_of: str = ""
    why_outside: str = ""

    @property
    def scale(self) -> float:
        """Framework units (mm, or a fraction for rates) per unit of the paper's figure."""
        return UNITS[self.unit]

    def target(self, value: float | None = None) -> tuple[float, float]:
        """The paper's number widened by the tolerance, in the framework's units
        (``value``: another number of the row in ``unit``, e.g. ``other_value``)."""
        v = (self.value if value is None else value) * self.scale
        h = self.tolerance * self.scale
        return round(v - h, 12), round(v + h, 12)

    @property
    def scenario(self) -> str:
        """The scenario of the row's study."""
        return self.study.split(":")[1]


def _fail(path: str, row: str, key: str | None, problem: str) -> FigureFileError:
    return FigureFileError(path, row, key, problem)


def _text(path: str, rid: str, raw: dict[str, Any], key: str, choices: Any = None) -> str:
    v = raw[key]
    if not isinstance(v, str) or not v.strip():
        raise _fail(path, rid, key, f"expected a non-empty string, got {v!r}")
    if choices is not None and v not in choices:
        raise _fail(path, rid, key, f"{v!r}: expected one of {', '.join(choices)}")
    return v


def _number(path: str, rid: str, raw: dict[str, Any], key: str) -> float:
    v = raw[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise _fail(path, rid, key, f"expected a finite number, got {v!r}")
    return float(v)


def parse_figure(raw: Any, index: int, path: str, why: dict[str, str],
                 scenarios: set[str] | None = None) -> Figure:
    """Validate one ``[[figure]]`` row.

    Args:
        raw: The row's table.
        index: Its position in the file (named in the errors before its id is read).
        path: The file (for the errors).
        why: The file's ``[why]`` texts.
        scenarios: The known scenario names (None: not checked).

    Raises:
        FigureFileError: Naming the file, the row and the key.
    """
    rid = f"figure[{index}]"
    if not isinstance(raw, dict):
        raise _fail(path, rid, None, f"expected a table, got {raw!r}")
    if isinstance(raw.get("id"), str) and raw["id"].strip():
        rid = f"figure[{index}] ({raw['id']})"
    unknown = sorted(set(raw) - set(_REQUIRED) - set(_OPTIONAL))
    if unknown:
        raise _fail(path, rid, unknown[0], "unknown key; expected "
                    + ", ".join(_REQUIRED + _OPTIONAL))
    missing = [k for k in _REQUIRED if k not in raw]
    if missing:
        raise _fail(path, rid, missing[0], "missing")
    fid = _text(path, rid, raw, "id")
    kind = _text(path, rid, raw, "kind", KINDS)
    unit = _text(path, rid, raw, "unit", UNITS)
    rule = _text(path, rid, raw, "rule", RULES)
    statistic = _text(path, rid, raw, "statistic", STATISTICS)
    study = _text(path, rid, raw, "study")
    value = _number(path, rid, raw, "value")
    parts = study.split(":")
    if parts[0] not in ("run", "calibrate") or len(parts) < 2 or not parts[1] or (
            len(parts) > 3 or (len(parts) == 3 and (parts[0] != "calibrate"
                                                    or parts[2] != "omni"))):
        raise _fail(path, rid, "study", f"{study!r}: expected run:SCENARIO or "
                    "calibrate:SCENARIO[:omni]")
    if STATISTICS[statistic] != parts[0]:
        raise _fail(path, rid, "statistic", f"{statistic!r} reads a {STATISTICS[statistic]} "
                    f"study, not {study!r}")
    if scenarios is not None and parts[1] not in scenarios:
        raise _fail(path, rid, "study", f"{parts[1]!r}: no such built-in scenario")
    if (statistic == "rate") != (unit == "%"):
        raise _fail(path, rid, "unit", f"{unit!r} for the statistic {statistic!r}: a rate "
                    "is in %, a length in mm or cm")
    if kind == "claim" and statistic != "rate":
        raise _fail(path, rid, "kind", "a claim is checked on convergence rates "
                    f"(statistic = \"rate\"), not {statistic!r}")
    if unit == "%" and not 0.0 <= value <= 100.0:
        raise _fail(path, rid, "value", f"{value:g} % is not a rate")
    tolerance = 0.0
    if rule == "equal":
        if "tolerance" not in raw:
            raise _fail(path, rid, "tolerance", "missing (the rule \"equal\" needs it)")
        tolerance = _number(path, rid, raw, "tolerance")
        if tolerance < 0:
            raise _fail(path, rid, "tolerance", f"{tolerance:g} is negative")
    elif "tolerance" in raw:
        raise _fail(path, rid, "tolerance", f"the rule {rule!r} takes no tolerance")
    trials = raw["paper_trials"]
    if trials != 1 and trials != "many":
        raise _fail(path, rid, "paper_trials", f"{trials!r}: expected 1 or \"many\"")
    sweep = raw.get("sweep", {})
    if not isinstance(sweep, dict) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in sweep.values()):
        raise _fail(path, rid, "sweep", f"expected a table of numbers, got {sweep!r}")
    controller = _text(path, rid, raw, "controller") if "controller" in raw else ""
    if parts[0] == "run" and not controller:
        raise _fail(path, rid, "controller", f"missing (the statistic {statistic!r} of a "
                    "run is read for one controller)")
    column = _text(path, rid, raw, "column") if "column" in raw else ""
    if (statistic == "median") != bool(column):
        raise _fail(path, rid, "column", "the statistic \"median\" needs a column, the "
                    "others take none")
    other = _text(path, rid, raw, "other") if "other" in raw else ""
    other_value = _number(path, rid, raw, "other_value") if "other_value" in raw else None
    if bool(other) != (other_value is not None) or (other and statistic != "rate"):
        raise _fail(path, rid, "other", "other and other_value go together, with the "
                    "statistic \"rate\"")
    if other_value is not None and not 0.0 <= other_value <= 100.0:
        raise _fail(path, rid, "other_value", f"{other_value:g} % is not a rate")
    why_key = _text(path, rid, raw, "why") if "why" in raw else ""
    if why_key and why_key not in why:
        raise _fail(path, rid, "why", f"{why_key!r}: not a key of [why] ("
                    + ", ".join(why) + ")")
    return Figure(
        id=fid, seed=_text(path, rid, raw, "seed", SEEDS),
        where=_text(path, rid, raw, "where"), quantity=_text(path, rid, raw, "quantity"),
        paper=_text(path, rid, raw, "paper"), kind=kind, value=value, unit=unit, rule=rule,
        statistic=statistic, study=study, tolerance=tolerance,
        paper_trials=1 if trials == 1 else None, sweep=dict(sweep), controller=controller,
        other=other, other_value=other_value, column=column,
        variant_of=_text(path, rid, raw, "variant_of") if "variant_of" in raw else "",
        why_outside=why.get(why_key, ""))


def parse_figures(table: dict[str, Any], path: str,
                  scenarios: set[str] | None = None) -> list[Figure]:
    """Validate a declared-figures table (see :func:`load_figures`).

    Raises:
        FigureFileError: Naming the file, the row and the key.
    """
    extra = sorted(set(table) - {"why", "figure"})
    if extra:
        raise _fail(path, extra[0], None, "unknown table; expected [why] and [[figure]]")
    why = table.get("why", {})
    if not isinstance(why, dict) or not all(isinstance(v, str) for v in why.values()):
        raise _fail(path, "why", None, "expected a table of texts")
    rows = table.get("figure")
    if not isinstance(rows, list) or not rows:
        raise _fail(path, "figure", None, "expected at least one [[figure]] row")
    figs = [parse_figure(r, i, path, why, scenarios) for i, r in enumerate(rows)]
    ids: dict[str, int] = {}
    for i, f in enumerate(figs):
        if f.id in ids:
            raise _fail(path, f"figure[{i}] ({f.id})", "id",
                        f"{f.id!r} is already the id of figure[{ids[f.id]}]")
        ids[f.id] = i
    # one figure, one row: a paper's number at one place, for one controller and one
    # setting, is compared once (variants test it again under another setting, apart)
    seen: dict[tuple[Any, ...], str] = {}
    for i, f in enumerate(figs):
        if f.variant_of:
            if f.variant_of not in ids or figs[ids[f.variant_of]].variant_of:
                raise _fail(path, f"figure[{i}] ({f.id})", "variant_of",
                            f"{f.variant_of!r}: not the id of a paper figure's own row")
            continue
        key = (f.seed, f.where, f.paper, tuple(sorted(f.sweep.items())), f.controller)
        if key in seen:
            raise _fail(path, f"figure[{i}] ({f.id})", None,
                        f"the paper's {f.paper!r} ({f.seed} {f.where}, {f.controller or '-'}"
                        f", {f.sweep or 'no sweep'}) is already compared by {seen[key]!r}: "
                        "one figure, one row (declare another statistic as variant_of, or "
                        "drop it)")
        seen[key] = f.id
    return figs


def load_figures(path: str | Path | None = None) -> list[Figure]:
    """Read and validate the declared figures (default: the built-in file).

    Raises:
        FigureFileError: Naming the file, the row and the key.
    """
    from benchmarks.study.scenario import builtin_scenarios
    from hexapod.config import load_toml
    from hexapod.exceptions import ConfigFileError

    p = Path(str(resources.files("benchmarks") / DEFAULT_FILE)) if path is None else Path(path)
    try:
        table = load_toml(p)
    except ConfigFileError as exc:
        raise _fail(str(p), "file", None, str(exc)) from None
    return parse_figures(table, str(p), set(builtin_scenarios()))


@lru_cache(maxsize=1)
def builtin_figures() -> tuple[Figure, ...]:
    """The built-in declared figures (read once)."""
    return tuple(load_figures())
