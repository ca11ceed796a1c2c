"""Options files (``run --options-file``): read, written back as read, applied over the
scenario's options, and refused in the file's terms when they name a label or an option
that does not exist."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.study.options_file import (
    apply_options_file,
    load_options_file,
    options_line,
    write_options_file,
)
from benchmarks.study.scenario import parse_scenario

SC = {"name": "t", "controllers": [{"name": "leg-edge", "edge_feature": "normals"},
                                   "computed-torque"], "robot": {"world": "dynamic"}}


def test_round_trip_and_apply(tmp_path: Path) -> None:
    f = tmp_path / "o.toml"
    opts = {"leg-edge": {"adaptive_gain": [5.0, 1.0, 30.0], "leg_rate_feedforward": True},
            "computed-torque": {"natural_frequency": 4.0}}
    tuning = {"scenario": "t", "criterion": "median-final", "budget": "6 x 5 x 1",
              "tuning_seed": 1000004, "study_seed": 1, "chosen": {"leg-edge": 2}}
    write_options_file(f, opts, tuning, "written by hexapod-vs: test")
    read = load_options_file(f)
    assert read.controllers == opts and read.tuning == tuning
    assert read.digest.startswith("sha256:")
    (sc,) = apply_options_file([parse_scenario(SC)], read)
    edge, ctc = sc.controllers
    assert edge.options == {"edge_feature": "normals", **opts["leg-edge"]}
    assert ctc.options == {"natural_frequency": 4.0}
    line = options_line({"options_file": read.record()})
    assert "**tuned**" in line and "median-final" in line and "1000004" in line
    assert "as given" in options_line({})
    # a controller of the run the file does not tune is said to run as given (it was not)
    from benchmarks.study.study_record import study_of

    ran = {"t": {"study": study_of(parse_scenario({**SC, "controllers": [
        *SC["controllers"], "leg-direction"]}))}}
    line = options_line({"options_file": read.record(), "scenarios": ran})
    assert line.endswith(" Options of leg-direction: **as given** (the scenario's; not in "
                         "the file)."), line


def test_a_value_without_one_is_left_out_of_the_file(tmp_path: Path) -> None:
    """``tune`` whose options as given scored best recorded p-values of None, and the
    file failed to write ('cannot write None to TOML'): TOML has no null, the key is left
    out."""
    f = tmp_path / "o.toml"
    tuning = {"scenario": "t", "note": None,
              "shown_better": {"leg-edge": {"best": 0, "kept": "as given",
                                            "p_sign_one_sided": None}}}
    write_options_file(f, {"leg-edge": {"gain": 2.0}}, tuning, "written by hexapod-vs: test")
    read = load_options_file(f)
    assert read.tuning == {"scenario": "t",
                           "shown_better": {"leg-edge": {"best": 0, "kept": "as given"}}}


@pytest.mark.parametrize(("text", "fragment"), [
    ('[controllers."leg-edge"]\ngian = 2.0\n', "did you mean 'gain'"),
    ('[controllers."leg-egde"]\ngain = 2.0\n', "no controller of the run has this label"),
    ('[controllers]\n"leg-edge" = 2.0\n', "expected a table of options"),
    ('[tunning]\nx = 1\n[controllers."leg-edge"]\ngain = 2.0\n', "did you mean 'tuning'"),
    ("[tuning]\nx = 1\n", "expected [controllers"),
])
def test_bad_files_name_the_file_and_key(tmp_path: Path, text: str, fragment: str) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ScenarioError) as info:
        apply_options_file([parse_scenario(SC)], load_options_file(f))
    assert str(f) in str(info.value) and fragment in str(info.value), str(info.value)


def test_a_missing_file_says_where_it_looked(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"file not found \(--options-file\): tried "):
        load_options_file(tmp_path / "nope.toml")


@pytest.mark.parametrize("value", ['"clamp"', '"fast"', "-2.0"])
def test_a_bad_value_is_refused_naming_the_options_file_and_its_key(
        tmp_path: Path, value: str) -> None:
    """A value the controller refuses, from an options file: the error names that file
    and its key (it named the scenario, the file inside the key)."""
    from benchmarks.study.scenario_checks import check_controllers

    f = tmp_path / "opts.toml"
    f.write_text(f'[controllers."computed-torque"]\nsaturation = {value}\n')
    (sc,) = apply_options_file([parse_scenario(SC, "study.toml")], load_options_file(f))
    with pytest.raises(ScenarioError) as info:
        check_controllers(sc)
    assert str(info.value).startswith(f"{f}: key 'controllers.\"computed-torque\"."
                                      "saturation': computed-torque: "), str(info.value)


def test_the_report_says_when_tuned_options_are_not_held_out(tmp_path: Path) -> None:
    """'tuned ... held-out trials' was said of a run with the tuning's own seed (the
    tuning trials, bit for bit), of another scenario than the tuned one, of a file whose
    [tuning] table was written by hand, and a controller with nothing to search was
    'kept as given, no candidate shown better' as one searched and not improved."""
    from benchmarks.study.options_file import goal_mismatches
    from benchmarks.study.study_record import study_of

    f = tmp_path / "o.toml"
    tuning = {"scenario": "t", "criterion": "median-final", "budget": "3 x 3 x 1",
              "tuning_seed": 1000004, "study_seed": 1, "held_out": True,
              "candidates_run": {"leg-edge": 3, "computed-torque": 1},
              "shown_better": {"leg-edge": {"kept": "as given"},
                               "computed-torque": {"kept": "as given"}}}
    write_options_file(f, {"leg-edge": {"gain": 2.0}, "computed-torque": {}}, tuning,
                       "written by hexapod-vs: test")
    record = load_options_file(f).record()

    def line(name: str, seed: int) -> str:
        sc = parse_scenario({**SC, "name": name, "seed": seed})
        return options_line({"options_file": record, "scenarios": {name: {
            "study": study_of(sc)}}})

    fine = line("t", 1)
    assert "held-out trials" in fine and "NOT held out" not in fine
    assert "kept as given, no candidate shown better: leg-edge" in fine
    assert "nothing to search, as given: computed-torque" in fine
    assert "NOT held out: t runs with the tuning's own seed 1000004: its trials are the " \
        "tuning trials" in line("t", 1000004)
    assert "NOT held out: options tuned on t, not on other" in line("other", 1)
    said = goal_mismatches([parse_scenario({**SC, "name": "other", "seed": 1000004})], record)
    assert any("options tuned on t, not on other" in w for w in said)
    assert any("runs with the tuning's own seed 1000004" in w for w in said)
    # a [tuning] table written by hand, without the tuning's keys: not "tuned"
    write_options_file(f, {"leg-edge": {"gain": 2.0}}, {"note": "mine"},
                       "written by hexapod-vs: test")
    hand = options_line({"options_file": load_options_file(f).record()})
    assert "written by hand, not tuned; its [tuning] table lacks scenario" in hand
    assert "**tuned**" not in hand


def test_a_wrappers_misspelt_law_option_names_the_options_file(tmp_path: Path) -> None:
    """An options file's typo in an option a wrapper hands on to its law was a
    TypeError naming the built-in scenario's key, without did-you-mean."""
    from benchmarks.study.scenario import load_scenario

    f = tmp_path / "o.toml"
    f.write_text('[controllers."leg-edge+comp"]\nadaptive_gian = [7.0, 1.4, 42.0]\n')
    sc = load_scenario("camera-latency-p2p").with_overrides(controllers=["leg-edge+comp"])
    with pytest.raises(ScenarioError, match="has no option 'adaptive_gian'") as info:
        apply_options_file([sc], load_options_file(f))
    assert str(f) in str(info.value) and info.value.suggestion == "adaptive_gain"


def test_a_typo_in_an_open_controllers_option_is_named_with_the_close_one(
        tmp_path: Path) -> None:
    """The MPC hands options it does not declare to its fallback law: a typo was refused
    by that law's ``__init__`` ('LegEdgeQPController.__init__() got an unexpected keyword
    argument'), with no key and no suggestion."""
    from benchmarks.study.preflight import preflight
    from benchmarks.study.scenario import load_scenario

    f = tmp_path / "s.toml"
    f.write_text('name = "s"\ncontrollers = [{name = "leg-edge-mpc", horizn = 3}]\n')
    with pytest.raises(ScenarioError) as info:
        preflight([load_scenario(f)])
    msg = str(info.value)
    assert "key 'controllers[0].horizn'" in msg and str(f) in msg
    assert "controller 'leg-edge-mpc' takes no option 'horizn'" in msg
    assert "did you mean 'horizon'" in msg and "__init__" not in msg


@pytest.mark.parametrize(("controllers", "key", "says"), [
    # a module:attr of the file: "from command line", no file, key or suggestion
    ('["leg-edge", "controllers.joint:JointSpaceControler"]', "controllers[1]",
     "(did you mean 'controllers.joint:JointSpaceController'?)"),
    # a wrapper's unknown inner law: no file, no key
    ('[{name = "latency-compensated", law = "leg-edgee"}]', "controllers[0].law",
     "unknown controller 'leg-edgee'"),
    # an option handed on to the inner law: the suggestion searched the wrapper's two
    ('[{name = "latency-compensated", law = "leg-edge", gian = 2.0}]', "controllers[0].gian",
     "(did you mean 'gain'?)"),
])
def test_a_plugin_or_an_inner_law_is_refused_in_the_files_terms(
        tmp_path: Path, controllers: str, key: str, says: str) -> None:
    from benchmarks.study.preflight import preflight
    from benchmarks.study.scenario import load_scenario

    f = tmp_path / "s.toml"
    f.write_text(f'name = "s"\ncontrollers = {controllers}\n')
    with pytest.raises(ScenarioError) as info:
        preflight([load_scenario(f)], measure=False)
    msg = str(info.value)
    assert f"key '{key}'" in msg and str(f) in msg and says in msg, msg
