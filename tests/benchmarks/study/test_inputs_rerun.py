"""Every ``inputs/NAME/scenario.toml`` a run writes reruns the same study, and
``[controller_options]`` apply the same way from ``--controllers`` and from a file."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.study.inputs import copy_inputs
from benchmarks.study.preflight import preflight
from benchmarks.study.scenario import builtin_scenarios, load_scenario

ADAPTIVE = "tests.benchmarks.plugins:AdaptiveJoints"
PLAIN = "tests.benchmarks.plugins:ProportionalJoints"


def _controllers(sc: object) -> list[tuple[str, str, dict]]:
    return [(c.name, c.label, c.options) for c in sc.controllers]  # type: ignore[attr-defined]


def _rerun(tmp_path: Path, sc: object) -> object:
    """What the run's pre-flight makes of ``sc``, written as a run writes it, read back
    and checked again: the scenario the copy runs."""
    pre = preflight([sc], measure=False)
    ran = pre.scenarios[0]
    kept = copy_inputs(tmp_path, ran)
    again = preflight([load_scenario(tmp_path / kept["folder"] / "scenario.toml")],
                      measure=False)
    assert again.warnings == []
    assert _controllers(again.scenarios[0]) == _controllers(ran)
    return ran


@pytest.mark.parametrize("name", sorted(builtin_scenarios()))
def test_every_builtin_scenario_copy_reruns(name: str, tmp_path: Path) -> None:
    _rerun(tmp_path, load_scenario(name))


def test_a_plugin_takes_the_options_it_declares_from_the_command_line(tmp_path: Path) -> None:
    quick = load_scenario("quick")
    ran = _rerun(tmp_path / "a", quick.with_overrides(controllers=[ADAPTIVE]))
    assert _controllers(ran) == [(ADAPTIVE, ADAPTIVE,
                                  {"adaptive_gain": quick.controller_options["adaptive_gain"]})]
    # a plugin that does not declare it runs without it (warned), and its copy reruns
    ran = _rerun(tmp_path / "b", quick.with_overrides(controllers=[PLAIN]))
    assert _controllers(ran) == [(PLAIN, PLAIN, {})]


def test_the_same_options_from_a_file(tmp_path: Path) -> None:
    study = tmp_path / "study.toml"
    study.write_text(f'name = "own"\ncontrollers = ["{ADAPTIVE}"]\n[controller_options]\n'
                     "adaptive_gain = [5.0, 1.0, 30.0]\n")
    ran = preflight([load_scenario(study)], measure=False).scenarios[0]
    cli = preflight([load_scenario("quick").with_overrides(controllers=[ADAPTIVE])],
                    measure=False).scenarios[0]
    assert _controllers(ran) == _controllers(cli)


@pytest.mark.slow
def test_the_goal_setting_is_kept_in_the_copy_and_stated_in_the_settings(
        tmp_path: Path) -> None:
    """``--goal taught`` (``Scenario.with_goal``) is written into the runnable copy, which
    reruns in that setting; the run's settings state it in words; a swept setting stays
    the file's list."""
    from benchmarks.cli import build_parser
    from benchmarks.study.inputs import settings

    args = build_parser().parse_args(["run", "quick", "--out", str(tmp_path / "o"),
                                      "--goal", "taught"])
    sc = load_scenario("quick").with_goal(args.goal)
    kept = copy_inputs(tmp_path / "a", sc)
    again = load_scenario(tmp_path / "a" / kept["folder"] / "scenario.toml")
    assert again.task.goal == "taught"
    assert settings(load_scenario("quick"))["goal"].startswith("mixed (legacy)")
    assert settings(again)["goal"].startswith("taught: images and encoders")
    source = tmp_path / "swept.toml"
    source.write_text(Path(load_scenario("quick").source).read_text()
                       .replace('kind = "random-pairs"',
                                'kind = "random-pairs"\ngoal = ["mixed", "cartesian"]'))
    swept = load_scenario(source)
    kept = copy_inputs(tmp_path / "b", swept)
    again = load_scenario(tmp_path / "b" / kept["folder"] / "scenario.toml")
    assert again.sweep_axes["task.goal"] == ["mixed", "cartesian"]
    assert settings(swept)["goal"] == "swept (task.goal)"
    assert settings(swept)["swept task.goal"] == "mixed, cartesian"
