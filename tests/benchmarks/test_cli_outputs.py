"""Every output of every subcommand is protected (issue 35): the test walks the parser of
``hexapod-bench``, so a new subcommand or a new output option cannot be forgotten. For each
option that names a file or directory the command writes, a user's existing file is
refused (exit code 2, file unchanged) and replaced with ``--overwrite``; each output
carries the project's mark, read back with the real library (json, pyarrow, PIL)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from benchmarks.cli import build_parser
from benchmarks.cli import main as cli_main
from benchmarks.study.outdir import OutputDir, OutputFile
from hexapod.outputs import GENERATOR

#: Exit code of a refused output (the CLI's "bad input" code, docs/outputs.md).
REFUSED = 2

#: Options that look like paths but name a file or directory the command only reads, or
#: a name (a scenario, a camera preset).
INPUTS = {("run", "scenarios"), ("run", "--calibration"), ("calibrate", "scenario"),
          ("warm", "scenarios"),
          ("calibrate", "--observations"), ("check", "file"), ("viz", "dir"),
          ("viz", "--scenario"), ("viz", "--geometry"), ("viz", "--camera-file"),
          ("viz", "--camera-pose"), ("viz", "--goal"), ("conformance", "--geometry"),
          ("compare", "dirs"), ("export", "dir"),
          ("servo", "--camera-file"), ("servo", "--camera-pose"), ("servo", "--geometry"),
          ("servo", "--calibration"), ("servo", "--camera"), ("perf calibration", "--camera"),
          ("perf controllers", "--camera"), ("perf dynamic-world", "--scenario"),
          ("perf study", "--scenario"), ("identify", "robot"), ("identify", "--truth"),
          ("run", "--options-file"), ("tune", "scenario"), ("tune", "--space")}
#: Option names and metavars that look like a path: each such option must be an output
#: (tagged ``OutputFile``/``OutputDir``) or listed in :data:`INPUTS`.
_PATHY_DEST = {"out", "dir", "dirs", "file", "json", "parquet", "picture", "markdown", "html",
               "pictures", "figure", "log", "goal", "calibration", "observations", "scenario",
               "scenarios", "camera_file", "camera_pose", "geometry", "camera", "csv", "png",
               "output", "path"}
_PATHY_METAVAR = ("FILE", "PNG", "DIR", "PATH", "TOML", "SCENARIO", "JSON", "CSV", "HTML")


class _ParsedError(Exception):
    """Carries the parser a module's ``main`` built (see :func:`_perf_parsers`)."""


def _perf_parsers() -> dict[str, argparse.ArgumentParser]:
    """``perf WHAT`` -> the parser of that figure's module (each builds its own in
    ``main``: caught at its ``parse_args``, before any work)."""
    import importlib
    from unittest import mock

    from benchmarks.cli import PERF_MODULES

    def caught(self: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> None:
        raise _ParsedError(self)

    parsers = {}
    with mock.patch.object(argparse.ArgumentParser, "parse_args", caught):
        for what, module in PERF_MODULES.items():
            try:
                importlib.import_module(module).main([])
            except _ParsedError as parsed:
                parsers[f"perf {what}"] = parsed.args[0]
    assert set(parsers) == {f"perf {w}" for w in PERF_MODULES}, "a perf parser not found"
    return parsers


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    """Every subcommand's parser (``perf WHAT`` as one each)."""
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return {**{k: v for k, v in sub.choices.items() if k != "perf"}, **_perf_parsers()}


def _name(action: argparse.Action) -> str:
    return action.option_strings[-1] if action.option_strings else action.dest


def _outputs() -> dict[tuple[str, str], str]:
    """(subcommand, option) -> "file" or "directory", for every tagged output option."""
    return {(cmd, _name(a)): a.kind for cmd, p in _subcommands().items() for a in p._actions
            if isinstance(a, OutputFile | OutputDir)}


def _pathy(action: argparse.Action) -> bool:
    if action.choices is not None:  # an enumerated option (run --goal taught) names no path
        return False
    metavar = action.metavar if isinstance(action.metavar, str) else ""
    return action.dest in _PATHY_DEST or any(m in metavar.upper() for m in _PATHY_METAVAR)


# ------------------------------------------------------------------------ the fixtures
def _scenario(folder: Path, controllers: str = '["joint-space"]') -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "study.toml"
    path.write_text(f'name = "small"\ntrials = 2\ncontrollers = {controllers}\n'
                    "[task]\nmax_steps = 30\n")
    return path


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished run with a recorded trial (two controllers: compare has a pair)."""
    folder = tmp_path_factory.mktemp("outputs")
    out = folder / "run"
    assert cli_main(["run", str(_scenario(folder, '["joint-space", "leg-edge"]')), "--out",
                     str(out), "--no-progress", "--record", "1"]) == 0
    return out


def _fake_reproduce(which: str, out: Path, quick: bool, workers: int,
                    say: Any = None) -> list[Any]:
    """``reproduce`` without its minutes of studies: no figure (the table is empty)."""
    out.mkdir(parents=True, exist_ok=True)
    return []


def _user_png(path: Path) -> None:
    Image.fromarray(np.full((4, 4, 3), 200, np.uint8)).save(path)  # a photo: no mark


def _marked(path: Path) -> bool:
    """Whether an output carries the project's mark, read with the file's own library."""
    suffix = path.suffix.lower()
    if suffix == ".json":
        return bool(json.loads(path.read_text())["generator"] == GENERATOR)
    if suffix == ".parquet":
        import pyarrow.parquet as pq

        return bool((pq.read_schema(path).metadata or {}).get(b"generator")
                    == GENERATOR.encode())
    if suffix == ".png":
        with Image.open(path) as im:
            return bool(im.text.get("Software") == GENERATOR)  # type: ignore[attr-defined]
    if suffix in (".jpg", ".jpeg"):
        with Image.open(path) as im:
            return bool(im.info.get("comment") == f"written by {GENERATOR}".encode())
    if suffix == ".md":
        return f"<!-- written by {GENERATOR}" in path.read_text()
    if suffix == ".html":
        return f'<meta name="generator" content="{GENERATOR}">' in path.read_text()
    if suffix == ".toml":
        return f"# written by {GENERATOR}" in path.read_text().splitlines()[0]
    raise AssertionError(f"no reader for {path}")


#: How each output option is exercised: the command line ({out}: the output path, {run}:
#: a run directory, {scenario}: a scenario file), the user's file (a name in {tmp}) and
#: the file the command writes there.
FILE_CASES: dict[tuple[str, str], list[tuple[list[str], str]]] = {
    ("compare", "--json"): [(["compare", "{run}", "--json", "{out}"], "mynotes.json")],
    ("export", "--parquet"): [(["export", "{run}", "--parquet", "{out}"], "mydata.parquet")],
    ("check", "--picture"): [(["check", "{scenario}", "--picture", "{out}"], "photo.png"),
                             (["check", "{scenario}", "--picture", "{out}"], "photo.jpg")],
    ("reproduce", "--markdown"): [(["reproduce", "seed001", "--quick", "--out", "{tmp}/r",
                                    "--markdown", "{out}"], "draft.md")],
    ("viz", "--html"): [(["viz", "{run}", "--controller", "leg-edge", "--html", "{out}"],
                         "page.html")],
    ("perf vision", "--figure"): [(["perf", "vision", "--poses", "3", "--figure", "{out}"],
                                   "edges.png")],
    ("perf calibration", "--json"): [(["perf", "calibration", "--repeats", "1", "--noise",
                                       "0.01", "--json", "{out}"], "figures.json")],
}
#: Outputs with a rule of their own (docs/outputs.md): never replaced, no --overwrite.
NEVER_REPLACED: dict[tuple[str, str], list[str]] = {
    ("servo", "--goal"): ["servo", "--backend", "emulator", "--teach", "--goal", "{out}"],
    ("servo", "--log"): ["servo", "--backend", "emulator", "--goal", "{tmp}/none.toml",
                         "--log", "{out}"],
}
#: Directories with a rule of their own: a new or empty directory only, never replaced.
NEVER_REPLACED_DIRS: dict[tuple[str, str], list[str]] = {
    ("servo", "--out"): ["servo", "--backend", "emulator", "--goal", "{tmp}/none.toml",
                         "--out", "{out}"],
}
#: Directories: the user's file placed inside ({out}/NAME) and whether --overwrite
#: replaces it (True) or keeps it beside the outputs (False).
DIR_CASES: dict[tuple[str, str], tuple[list[str], str, bool]] = {
    ("run", "--out"): (["run", "{scenario}", "--out", "{out}", "--no-progress"],
                       "report.md", True),
    ("calibrate", "--out"): (["calibrate", "{scenario}", "--out", "{out}"],
                             "calibrated.toml", True),
    ("identify", "--out"): (["identify", "deltalab", "--out", "{out}", "--duration", "4",
                             "--search-candidates", "2"], "identified.toml", True),
    ("reproduce", "--out"): (["reproduce", "seed001", "--quick", "--out", "{out}"],
                             "notes.txt", False),
    ("report", "dir"): (["report", "{out}"], "report.md", True),
    ("tune", "--out"): (["tune", "{scenario}", "--controllers", "leg-edge", "--trials", "1",
                         "--candidates", "2", "--out", "{out}", "--no-progress"],
                        "tuned.toml", True),
    ("perf detect", "--pictures"): (["perf", "detect", "--frames", "1", "--repeats", "1",
                                     "--pictures", "{out}"], "detect-front.png", True),
}


def _argv(template: list[str], **values: str) -> list[str]:
    return [t.format(**values) for t in template]


# ----------------------------------------------------------------------------- the walk
def test_every_output_option_of_every_subcommand_is_tagged_and_exercised() -> None:
    outputs = _outputs()
    untagged = sorted((cmd, _name(a)) for cmd, p in _subcommands().items() for a in p._actions
                      if _pathy(a) and not isinstance(a, OutputFile | OutputDir)
                      and (cmd, _name(a)) not in INPUTS)
    assert not untagged, f"options that look like paths, neither output nor input: {untagged}"
    files = {k for k, kind in outputs.items() if kind == "file"}
    dirs = {k for k, kind in outputs.items() if kind == "directory"}
    assert files == set(FILE_CASES) | set(NEVER_REPLACED), "an output without its test"
    assert dirs == set(DIR_CASES) | set(NEVER_REPLACED_DIRS), \
        "an output directory without its test"
    parsers = _subcommands()
    for cmd, option in (files | dirs) - set(NEVER_REPLACED) - set(NEVER_REPLACED_DIRS):
        flags = {s for a in parsers[cmd]._actions for s in a.option_strings}
        assert "--overwrite" in flags, f"{cmd} {option}: no --overwrite"


@pytest.mark.slow
@pytest.mark.parametrize(("key", "index"), [(k, i) for k, v in FILE_CASES.items()
                                            for i in range(len(v))])
def test_a_users_file_is_refused_then_replaced_with_overwrite_and_marked(
        key: tuple[str, str], index: int, run_dir: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("benchmarks.study.reproduce.reproduce", _fake_reproduce)
    template, name = FILE_CASES[key][index]
    out = tmp_path / name
    if out.suffix in (".png", ".jpg"):
        _user_png(out)
    else:
        out.write_bytes(b"the user's own content\n")
    before = out.read_bytes()
    argv = _argv(template, out=str(out), run=str(run_dir), tmp=str(tmp_path),
                 scenario=str(_scenario(tmp_path / "sc")))
    assert cli_main(argv) == REFUSED
    err = capsys.readouterr().err
    assert f"hexapod-bench: error: {out}: already exists (" in err, err
    assert "add --overwrite to replace it" in err
    assert out.read_bytes() == before, "the user's file is unchanged"
    assert cli_main([*argv, "--overwrite"]) == 0, capsys.readouterr().err
    assert out.read_bytes() != before
    assert _marked(out), f"{out}: no {GENERATOR} mark"
    assert cli_main(argv) == 0, "its own file is replaced without --overwrite"
    assert _marked(out)


@pytest.mark.parametrize("key", sorted(NEVER_REPLACED))
def test_servo_outputs_are_never_replaced(
        key: tuple[str, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "mine.toml"
    out.write_text("my notes\n")
    assert cli_main(_argv(NEVER_REPLACED[key], out=str(out), tmp=str(tmp_path))) == REFUSED
    assert f"{out}: already exists" in capsys.readouterr().err
    assert out.read_text() == "my notes\n"


@pytest.mark.slow
@pytest.mark.parametrize("key", sorted(NEVER_REPLACED_DIRS))
def test_servo_session_directories_are_never_reused(
        key: tuple[str, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("my notes\n")
    assert cli_main(_argv(NEVER_REPLACED_DIRS[key], out=str(out), tmp=str(tmp_path))) == REFUSED
    assert f"{out}: is not empty" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["notes.txt"]
    assert (out / "notes.txt").read_text() == "my notes\n"


@pytest.mark.slow
@pytest.mark.parametrize("key", sorted(DIR_CASES))
def test_a_directory_holding_a_users_file_is_refused_unless_overwrite(
        key: tuple[str, str], run_dir: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    import shutil

    monkeypatch.setattr("benchmarks.study.reproduce.reproduce", _fake_reproduce)
    template, name, replaced = DIR_CASES[key]
    scenario = _scenario(tmp_path / "sc", '["leg-edge"]')
    out = tmp_path / "out"
    if key == ("report", "dir"):
        shutil.copytree(run_dir, out)
    else:
        out.mkdir()
    user = out / name
    if user.suffix == ".png":
        _user_png(user)
    else:
        user.write_text("my own work\n")
    before = user.read_bytes()
    argv = _argv(template, out=str(out), scenario=str(scenario))
    assert cli_main(argv) == REFUSED
    assert f"hexapod-bench: error: {out}" in capsys.readouterr().err
    assert user.read_bytes() == before
    assert cli_main([*argv, "--overwrite"]) == 0, capsys.readouterr().err
    if replaced:
        assert _marked(user)
    else:
        assert user.read_bytes() == before


# ------------------------------------------------- an output that cannot be written at all
@pytest.mark.parametrize("key", sorted(_outputs()))
def test_an_output_that_cannot_be_written_is_refused_when_the_command_line_is_read(
        key: tuple[str, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cmd, option = key
    (action,) = [a for a in _subcommands()[cmd]._actions if _name(a) == option]
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine\n")
    cases = {a_file / "sub" / "out.json": f"{a_file} is a file: no folder can be made",
             Path("/proc") / "out.json": "no file can be created in /proc (",
             a_file: "is a file, not a directory" if action.kind == "directory" else None,
             tmp_path: "is a directory, not a file" if action.kind == "file" else None}
    for path, expected in cases.items():
        if expected is None:  # a path this kind of output may take
            action(argparse.ArgumentParser(), argparse.Namespace(), str(path), option)
            continue
        with pytest.raises(SystemExit) as refused:
            action(argparse.ArgumentParser(prog="p"), argparse.Namespace(), str(path), option)
        err = capsys.readouterr().err
        assert refused.value.code == 2 and "usage" not in err  # one line, no usage
        assert err.startswith(f"p: error: argument {option}: {path}: ") and expected in err
    assert a_file.read_text() == "mine\n" and sorted(tmp_path.iterdir()) == [a_file]


def test_run_refuses_an_unwritable_out_before_any_trial(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine\n")
    with pytest.raises(SystemExit) as stopped:
        cli_main(["run", "quick", "--trials", "2", "--out", str(a_file / "run")])
    assert stopped.value.code == REFUSED
    err = capsys.readouterr().err
    assert f"argument --out: {a_file / 'run'}: {a_file} is a file" in err, err
    assert sorted(tmp_path.iterdir()) == [a_file]
