"""Each controller declares its options once (:func:`controllers.options.option_table`):
``list --options`` prints that table and the scenario checks accept what it holds."""

from __future__ import annotations

import pytest

from benchmarks.cli import main
from controllers import BUILTIN_SPECS, registry
from controllers.options import REQUIRED, OptionSpec, docstring_args, option_table
from tests.benchmarks.plugins import DeclaredOptions, ProportionalJoints


@pytest.mark.parametrize("name", sorted(BUILTIN_SPECS))
def test_every_builtin_option_is_documented(name: str) -> None:
    """Every option of a built-in has a type, a default and one sentence of meaning."""
    import inspect

    table = option_table(registry.factory(name))
    params = [p for p, v in inspect.signature(registry.factory(name)).parameters.items()
              if v.kind is not inspect.Parameter.VAR_KEYWORD]
    assert table.names == params
    for o in table.options:
        assert o.meaning and o.meaning.endswith((".", ")")), (name, o.name, o.meaning)
        assert o.type and o.default is not REQUIRED, (name, o.name)


def test_units_come_from_the_docstring() -> None:
    table = {o.name: o for o in option_table(registry.factory("leg-edge-mpc")).options}
    assert table["gain"].unit == "1/s"
    assert table["stroke_margin"].unit == "m"
    assert table["max_speed"].unit == "m/s"
    assert table["drive_model"].unit == ""  # "[drives]" names a table, not a unit
    assert option_table(registry.factory("vision-ctc")).options[0].unit == "Hz"
    qp = {o.name: o for o in option_table(registry.factory("leg-edge-qp")).options}
    assert qp["eps_abs"].meaning == "OSQP absolute tolerance."  # from OPTION_DOCS


def test_a_plugin_declares_its_options() -> None:
    table = option_table(DeclaredOptions)
    assert table.options == (OptionSpec("gain", "float", 2.0, "1/s",
                                        "Gain of the leg-length servo."),)
    # without OPTIONS: the signature, and a meaning left empty when undocumented
    plain = option_table(ProportionalJoints)
    assert plain.names == ["gain"] and plain.options[0].meaning == ""


def test_an_option_type_may_be_given_as_a_type() -> None:
    """``OptionSpec("gain", float, ...)`` is ``OptionSpec("gain", "float", ...)`` (``list
    --options`` failed on the type object); anything else is refused naming the option."""
    assert OptionSpec("gain", float, 2.0) == OptionSpec("gain", "float", 2.0)
    with pytest.raises(TypeError, match="'gain': type must be a name"):
        OptionSpec("gain", 3, 2.0)  # type: ignore[arg-type]


def test_docstring_args_joins_continued_lines() -> None:
    doc = """Something.

    Args:
        alpha: First line
            continued [m/s]. More.
        beta (float): Second.

    Returns:
        Nothing.
    """
    assert docstring_args(doc) == {"alpha": "First line continued [m/s]. More.",
                                   "beta": "Second."}


def test_list_options_prints_the_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["list", "--options", "vision-ctc"]) == 0
    out = capsys.readouterr().out
    assert "Options of vision-ctc" in out
    for o in registry.options("vision-ctc").options:
        assert o.name in out and repr(o.default) in out
    assert "Natural frequency f_n [Hz] of the error's second-order response" in out
    assert main(["list", "--options", "vison-ctc"]) == 2
    assert "did you mean 'vision-ctc'" in capsys.readouterr().err


def test_list_descriptions_are_whole_sentences() -> None:
    for info in registry.info():
        assert info.description.endswith("."), info
    assert registry.source("vision-ctc").description == (
        "Cartesian computed torque with the pose the camera sees of the legs (Paccot et al. "
        "2008, with leg observation instead of a target on the platform).")


@pytest.mark.slow
def test_module_attr_is_recorded_with_its_distribution() -> None:
    import yaml

    from controllers.registry import _module_distribution

    assert _module_distribution("yaml") == ("PyYAML", yaml.__version__)
    assert _module_distribution("tests.benchmarks.plugins") == ("tests", "unknown")


def test_the_docs_table_is_the_real_output(capsys: pytest.CaptureFixture[str]) -> None:
    """docs/scenarios.md shows ``list --options vision-ctc`` as it prints."""
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "scenarios.md").read_text()
    block = doc[doc.index("$ hexapod-bench list --options vision-ctc"):]
    rows = [line for line in block[:block.index("```")].splitlines()
            if line.startswith("│")]
    assert len(rows) == 5
    assert main(["list", "--options", "vision-ctc"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert rows == [line for line in out if line.startswith("│")]


#: Options of these types given a string in a file (``shortcut = "false"``, ``gain =
#: "2.0"``) must be refused: ``bool("false")`` is True and a quoted number is a slip.
_STRING_REFUSED = {"bool": "false", "bool | None": "false", "float": "1.0",
                   "float | None": "1.0", "int": "3"}


@pytest.mark.parametrize("name", sorted(BUILTIN_SPECS))
def test_a_string_for_a_flag_or_a_number_is_refused_naming_the_option(name: str) -> None:
    """Every boolean and numeric option of every built-in refuses a string (``"false"``
    passed as true: the QP's ``shortcut``, the laws' ``compiled``), naming the option."""
    from controllers.exceptions import OptionError

    for o in option_table(registry.factory(name)).options:
        if o.type not in _STRING_REFUSED:
            continue
        with pytest.raises((OptionError, ValueError)) as info:
            registry.create(name, **{o.name: _STRING_REFUSED[o.type]})
        assert o.name in str(info.value), (name, o.name, str(info.value))
