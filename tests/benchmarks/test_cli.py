"""The command line's start-up: a command builds the arguments it needs, and neither the
servo loop nor the closed-chain model is imported to parse another command."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.cli import build_parser, command_word, main

ROOT = Path(__file__).resolve().parents[2]


def _choices(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


def test_the_command_word_is_the_first_word_not_an_option() -> None:
    assert command_word(["-v", "run", "quick", "--out", "o"]) == "run"
    assert command_word(["--help"]) is None
    assert command_word([]) is None


def test_servo_is_listed_but_built_only_when_asked_for() -> None:
    listed = _choices(build_parser({"run"}))["servo"]
    assert not any(a.dest == "backend" for a in listed._actions)  # a name and a help line
    full = _choices(build_parser({"servo"}))["servo"]
    assert any(a.dest == "backend" for a in full._actions)
    assert any(a.dest == "backend" for a in _choices(build_parser())["servo"]._actions)


def test_parsing_run_imports_neither_the_servo_loop_nor_pinocchio() -> None:
    code = ("import sys, benchmarks.cli as c; "
            "c.build_parser({'run'}).parse_args(['run', 'quick', '--out', 'o']); "
            "print(sorted(m for m in ('benchmarks.robot.servo', 'pinocchio', 'casadi', "
            "'matplotlib', 'scipy.stats') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert out.stdout.strip() == "[]"


def test_the_command_process_leaves_its_objects_to_the_exit(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``hexapod-bench`` itself (no ``argv``: the console script, ``python -m``) freezes
    its objects when the command ends, so that the interpreter's exit does not collect
    them one by one; a call with ``argv`` (a test, a caller) leaves the collector alone."""
    import gc

    from benchmarks.cli import main

    missing = str(tmp_path / "missing")
    assert gc.get_freeze_count() == 0
    assert main(["report", missing]) == 2 and gc.get_freeze_count() == 0
    monkeypatch.setattr(sys, "argv", ["hexapod-bench", "report", missing])
    try:
        assert main() == 2 and gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()


def test_a_reader_that_leaves_stops_the_command_quietly() -> None:
    """``hexapod-bench check quick | head -1``: the reader closes the pipe, the command's
    next print fails; it said 'error: BrokenPipeError' with the exit code of an invalid
    file (2), and now stops quietly with 141 (128 + SIGPIPE) as a Unix tool does."""
    code = "import sys; from benchmarks.cli import main; sys.exit(main())"
    p = subprocess.Popen([sys.executable, "-c", code, "check", "quick"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert p.stdout is not None and p.stderr is not None
    p.stdout.close()  # before the command writes its first line
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141 and err == ""


def test_a_mistyped_command_is_named_with_the_close_one(
        capsys: pytest.CaptureFixture[str]) -> None:
    """argparse printed its usage and 'invalid choice', with no suggestion."""
    assert main(["runs", "quick", "--out", "r1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hexapod-bench: error: no command 'runs'; the commands: ")
    assert "(did you mean 'run'?)" in err and "usage:" not in err


def test_the_version_is_printed(capsys: pytest.CaptureFixture[str]) -> None:
    """It answered 'the following arguments are required: command'."""
    from importlib import metadata

    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"hexapod-bench {metadata.version('hexapod-vs')}"


def test_every_command_s_help_examples_parse_and_name_built_in_scenarios(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each ``COMMAND --help`` ends with examples that parse as written, every command
    has some, and a scenario an example names by a bare name is a built-in one."""
    import shlex

    from benchmarks.cli_examples import EXAMPLES
    from benchmarks.study.scenario import builtin_scenarios

    monkeypatch.chdir(tmp_path)  # (the examples' output directories are relative)
    parser = build_parser()
    assert set(EXAMPLES) == set(_choices(parser)), "a command without help examples"
    builtin = builtin_scenarios()
    for command, examples in EXAMPLES.items():
        help_text = _choices(parser)[command].format_help()
        for line, what in examples:
            assert f"  {line}\n      {what}" in help_text  # as written, not re-wrapped
            argv = shlex.split(line)
            assert argv[:2] == ["hexapod-bench", command]
            args = parser.parse_args(argv[1:])
            names = {"run": lambda a: a.scenarios, "tune": lambda a: [a.scenario],
                     "check": lambda a: [a.file], "calibrate": lambda a: [a.scenario]}
            for name in names.get(command, lambda a: [])(args):
                assert name.endswith(".toml") or name in builtin, (command, name)
