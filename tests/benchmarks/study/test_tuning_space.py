"""The declared search spaces of ``hexapod-bench tune``: families by declared option,
skipped axes named, the same number of candidates for every controller (the options as
given first), and a malformed space file refused in the file's terms."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.study.tuning_space import (
    SEARCH_SPACE,
    Axis,
    candidates,
    check_space_options,
    controller_space,
    load_space,
)
from controllers.registry import registry


def _space(name: str, label: str | None = None, space: dict | None = None):  # type: ignore[no-untyped-def]
    import controllers  # noqa: F401 - registers the built-ins

    return controller_space(label or name, name, registry.options(name), space or SEARCH_SPACE)


CTC_LAWS = ("computed-torque", "cartesian-ctc", "vision-ctc", "leg-edge-ctc", "leg-direction-ctc")


def test_families_follow_the_declared_options() -> None:
    for name in ("leg-edge", "leg-direction-qp", "joint-space", "model-based", "leg-edge-mpc"):
        cs = _space(name)
        assert cs.family == "velocity" and [a.option for a in cs.axes] == ["adaptive_gain"]
    for name in CTC_LAWS:  # every computed-torque law takes integral action: both axes searched
        cs = _space(name)
        assert cs.family == "computed-torque", name
        assert [a.option for a in cs.axes] == ["natural_frequency", "integral_gain"], name
        assert cs.skipped == (), name


def test_an_axis_the_controller_does_not_take_is_skipped_and_said() -> None:
    space = {"computed-torque": (Axis("natural_frequency", 0.5, 16.0, "log"),
                                 Axis("no_such_gain", 0.0, 1.0, "linear"))}
    cs = _space("computed-torque", space=space)
    assert cs.family == "computed-torque"
    assert [a.option for a in cs.axes] == ["natural_frequency"]
    assert len(cs.skipped) == 1 and "'no_such_gain'" in cs.skipped[0]
    assert "natural_frequency" in cs.skipped[0]  # the controller's options, named


def test_the_searched_integral_gain_reaches_each_computed_torque_law() -> None:
    """The candidates' options build the laws the study steps (``registry.create`` with a
    spec's options, as ``controllers.batch`` does): each law holds the candidate's Ki,
    and the candidates search several values of it, not only the default 0."""
    for name in CTC_LAWS:
        cs = _space(name)
        plan = candidates({}, cs.axes, 6)
        gains = set()
        for opts in plan[1:]:
            law = registry.create(name, **opts)
            assert law.integral_gain == pytest.approx(opts["integral_gain"]), name  # type: ignore[attr-defined]
            gains.add(opts["integral_gain"])
        assert registry.create(name, **plan[0]).integral_gain == 0.0  # type: ignore[attr-defined]
        assert len(gains) == 5 and max(gains) > 0.0, (name, gains)


@pytest.mark.parametrize("n", [2, 3, 6, 9])
def test_every_controller_gets_n_candidates_the_given_first(n: int) -> None:
    given = {"edge_feature": "normals", "gain": 2.0}
    one = candidates(given, SEARCH_SPACE["velocity"], n)
    two = candidates({}, (Axis("natural_frequency", 0.5, 8.0, "log"),
                          Axis("integral_gain", 0.0, 4.0, "linear")), n)
    assert len(one) == len(two) == n
    assert one[0] == given and two[0] == {}
    assert all(c["edge_feature"] == "normals" for c in one)  # the other options stay
    for c in two[1:]:
        assert 0.5 <= c["natural_frequency"] <= 8.0 and 0.0 <= c["integral_gain"] <= 4.0
    assert len({repr(c) for c in two}) == n  # distinct points


def test_one_axis_is_evenly_spaced_in_its_scale_with_its_shape() -> None:
    cands = candidates({}, (Axis("adaptive_gain", 1.0, 16.0, "log", (1.0, 0.2, 6.0)),), 6)
    assert Axis("g", 1.0, 16.0, "log", (1.0, 0.2, 6.0)).at_end(cands[-1]["adaptive_gain"])
    assert not Axis("g", 1.0, 16.0, "log", (1.0, 0.2, 6.0)).at_end(cands[2]["adaptive_gain"])
    l0 = [c["adaptive_gain"][0] for c in cands[1:]]
    np.testing.assert_allclose(l0, [1.0, 2.0, 4.0, 8.0, 16.0])
    assert cands[-1]["adaptive_gain"] == [16.0, 3.2, 96.0]
    lin = candidates({}, (Axis("gain", 1.0, 3.0, "linear"),), 4)
    assert [c["gain"] for c in lin[1:]] == [1.0, 2.0, 3.0]
    with pytest.raises(ValueError, match="at least 2"):
        candidates({}, (), 1)


def test_a_controller_without_a_family_keeps_its_options_as_given() -> None:
    cs = _space("leg-edge", space={"ctc": (Axis("natural_frequency", 1.0, 2.0),)})
    assert cs.family is None and cs.axes == () and "only its options as given" in cs.skipped[0]
    assert candidates({"gain": 1.0}, cs.axes, 6) == [{"gain": 1.0}]


def test_a_space_file_is_read_and_checked(tmp_path: Path) -> None:
    f = tmp_path / "space.toml"
    f.write_text('["leg-edge"]\ngain = { low = 0.5, high = 8.0 }\n'
                 '[velocity]\nadaptive_gain = { low = 1, high = 4, scale = "linear", '
                 'shape = [1.0, 0.5, 3.0] }\n')
    space = load_space(f)
    assert space["leg-edge"] == (Axis("gain", 0.5, 8.0, "log"),)
    assert space["velocity"][0].shape == (1.0, 0.5, 3.0)
    cs = _space("leg-edge", space=space)  # the controller's own table first
    assert cs.family == "leg-edge" and cs.axes[0].option == "gain"


@pytest.mark.parametrize(("text", "fragment", "key"), [
    ('["leg-edge"]\ngain = { low = 8.0, high = 0.5 }\n', "above high", "leg-edge.gain"),
    ('["leg-edge"]\ngain = { low = 0.0, high = 1.0 }\n', "needs low > 0", "leg-edge.gain.low"),
    ('["leg-edge"]\ngain = { low = 1.0, hihg = 2.0 }\n', "did you mean 'high'",
     "leg-edge.gain.hihg"),
    ('["leg-edge"]\ngain = { low = 1.0, high = 2.0, scale = "cubic" }\n', "log, linear",
     "leg-edge.gain.scale"),
    ('["leg-edge"]\ngain = 3.0\n', "expected a table", "leg-edge.gain"),
])
def test_a_malformed_space_names_the_file_and_key(tmp_path: Path, text: str, fragment: str,
                                                  key: str) -> None:
    f = tmp_path / "space.toml"
    f.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_space(f)
    msg = str(info.value)
    assert str(f) in msg and key in msg and fragment in msg, msg


def test_an_option_the_controller_does_not_take_is_an_error(tmp_path: Path) -> None:
    import controllers  # noqa: F401 - registers the built-ins

    f = tmp_path / "space.toml"
    f.write_text('["leg-edge"]\ngian = { low = 0.5, high = 8.0 }\n')
    space = load_space(f)
    with pytest.raises(ScenarioError) as info:
        check_space_options(space, {"leg-edge": registry.options("leg-edge")},
                            {"leg-edge": "leg-edge"}, str(f))
    msg = str(info.value)
    assert "has no option 'gian'" in msg and "did you mean 'gain'" in msg and str(f) in msg


def test_halton_points_by_hand() -> None:
    from benchmarks.study.tuning_space import halton

    np.testing.assert_allclose(halton(3, 2), [[0.5, 1 / 3], [0.25, 2 / 3], [0.75, 1 / 9]])
