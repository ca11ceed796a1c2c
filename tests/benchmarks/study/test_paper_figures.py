"""The declared paper figures: the built-in file, and bad rows refused with the file, the
row and the key named."""

from __future__ import annotations

import copy
import re
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

import pytest

from benchmarks.exceptions import FigureFileError
from benchmarks.study import paper_figures
from benchmarks.study.paper_figures import (
    TRIALS,
    builtin_figures,
    load_figures,
    parse_figures,
)


def _builtin_table() -> dict[str, Any]:
    path = resources.files("benchmarks") / paper_figures.DEFAULT_FILE
    return tomllib.loads(path.read_text(encoding="utf-8"))


def test_builtin_file_one_row_per_paper_figure() -> None:
    figs = builtin_figures()
    own = [f for f in figs if not f.variant_of]
    keys = [(f.seed, f.where, f.paper, tuple(sorted(f.sweep.items())), f.controller)
            for f in own]
    assert len(keys) == len(set(keys))
    assert {f.seed for f in own} == set(paper_figures.SEEDS)
    # seed 001's medians: the tail median only, not the final error against the same number
    seed001 = [f for f in own if f.seed == "seed001" and f.paper in ("0.1 mm", "0.6 mm")]
    assert {f.column for f in seed001 if f.statistic == "median"} == {"tail_position_error_mm"}
    # the contradicting and the variant rows are declared
    ids = {f.id for f in figs}
    assert {"seed003-experiment-directions", "seed002-fig3-5",
            "seed003-convergence-directions-desired"} <= ids
    # every run study has its trial counts
    assert {f.scenario for f in figs if f.study.startswith("run:")} <= set(TRIALS)
    # the lenient one-trial rule is gone: the 1.4 mm is compared under the same rule
    cal = next(f for f in figs if f.id == "seed001-5.3-calibration-0.05")
    assert (cal.paper_trials, cal.rule, cal.target()) == (1, "equal", (1.35, 1.45))


def _one_row(**change: Any) -> dict[str, Any]:
    table = _builtin_table()
    row = copy.deepcopy(next(r for r in table["figure"] if r["id"] == "seed001-5.3-tail-max-0.05"))
    for k, v in change.items():
        if v is None:
            row.pop(k, None)
        else:
            row[k] = v
    return {"why": table["why"], "figure": [row]}


@pytest.mark.parametrize(("change", "key", "message"), [
    ({"colour": "red"}, "colour", "unknown key"),
    ({"value": None}, "value", "missing"),
    ({"value": "1.9"}, "value", "finite number"),
    ({"value": float("nan")}, "value", "finite number"),
    ({"unit": "inch"}, "unit", "expected one of mm, cm, %"),
    ({"tolerance": None}, "tolerance", "needs it"),
    ({"tolerance": -0.1}, "tolerance", "negative"),
    ({"rule": "below"}, "tolerance", "takes no tolerance"),
    ({"statistic": "calibration_rms_median"}, "statistic", "reads a calibrate study"),
    ({"kind": "claim"}, "kind", "convergence rates"),
    ({"study": "run:no-such-scenario"}, "study", "no such built-in scenario"),
    ({"study": "simulate:andreff2005-noise"}, "study", "expected run:SCENARIO"),
    ({"paper_trials": 2}, "paper_trials", "expected 1 or \"many\""),
    ({"why": "nothing"}, "why", "not a key of \\[why\\]"),
    ({"controller": None}, "controller", "missing"),
    ({"column": "final_position_error_mm"}, "column", "needs a column"),
    ({"seed": "seed004"}, "seed", "expected one of seed000"),
    ({"other": "leg-edge"}, "other", "go together"),
])
def test_bad_rows_name_the_file_the_row_and_the_key(change: dict[str, Any], key: str,
                                                   message: str) -> None:
    with pytest.raises(FigureFileError, match=message) as exc:
        parse_figures(_one_row(**change), "figs.toml", {"andreff2005-noise"})
    assert exc.value.path == "figs.toml"
    assert exc.value.key == key
    assert exc.value.row == "figure[0] (seed001-5.3-tail-max-0.05)"
    assert str(exc.value).startswith("figs.toml: figure[0] (seed001-5.3-tail-max-0.05).")


def test_a_figure_compared_twice_is_refused() -> None:
    table = _one_row()
    twice = copy.deepcopy(table["figure"][0])
    twice.update(id="seed001-again", statistic="median", column="final_position_error_mm")
    table["figure"].append(twice)
    with pytest.raises(FigureFileError, match=re.escape(
            "already compared by 'seed001-5.3-tail-max-0.05'")) as exc:
        parse_figures(table, "figs.toml")
    assert exc.value.row == "figure[1] (seed001-again)"
    # declared as a variant of the first, it is accepted (and counted apart)
    twice["variant_of"] = "seed001-5.3-tail-max-0.05"
    figs = parse_figures(table, "figs.toml")
    assert figs[1].variant_of == "seed001-5.3-tail-max-0.05"
    # ... but not as a variant of a row that does not exist, or of a variant
    twice["variant_of"] = "nothing"
    with pytest.raises(FigureFileError, match="not the id of a paper figure's own row"):
        parse_figures(table, "figs.toml")


def test_duplicate_ids_and_unknown_tables() -> None:
    table = _one_row()
    table["figure"].append(dict(table["figure"][0], variant_of="seed001-5.3-tail-max-0.05"))
    with pytest.raises(FigureFileError, match="already the id of figure\\[0\\]"):
        parse_figures(table, "figs.toml")
    with pytest.raises(FigureFileError, match="unknown table"):
        parse_figures({**_one_row(), "figures": []}, "figs.toml")
    with pytest.raises(FigureFileError, match="at least one"):
        parse_figures({"why": {}}, "figs.toml")


def test_load_figures_names_an_unreadable_file(tmp_path: Path) -> None:
    bad = tmp_path / "figs.toml"
    bad.write_text("[[figure]\nid = 1\n")
    with pytest.raises(FigureFileError, match=str(bad)):
        load_figures(bad)
    assert len(load_figures()) == len(builtin_figures())
