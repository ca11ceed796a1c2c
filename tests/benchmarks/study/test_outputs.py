"""Outputs stay inside their directory and never replace a user's files (issue 26): the
three reported cases, names checked where they enter, and every writing command still
working on a fresh or its own directory."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from benchmarks.cli import main as cli_main
from benchmarks.exceptions import ScenarioError
from benchmarks.study.scenario import load_scenario
from controllers.base import ENTRY_POINT_GROUP as CONTROLLER_GROUP
from controllers.base import Registry
from controllers.exceptions import PluginLoadError
from hexapod.backends.registry import ENTRY_POINT_GROUP as BACKEND_GROUP
from hexapod.backends.registry import BackendRegistry
from hexapod.exceptions import BackendPluginError


def _scenario(folder: Path, name: str = "small", controllers: str = '["joint-space"]',
              file: str = "study.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / file
    path.write_text(f'name = "{name}"\ntrials = 2\ncontrollers = {controllers}\n'
                    "[task]\nmax_steps = 30\n")
    return path


def _tree(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` with its content."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file()}


# ------------------------------------------------------------------ case 1: names -> paths
def test_a_scenario_name_that_climbs_out_is_refused_and_nothing_is_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scen = _scenario(tmp_path / "lab", name="../../escape")
    out = tmp_path / "runs" / "a" / "out"
    out.parent.mkdir(parents=True)
    before = _tree(tmp_path)
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert (f"error: {scen}: key 'name': '../../escape': contains the path separator '/'"
            in err)
    assert "letters, digits and . _ - + :" in err
    assert _tree(tmp_path) == before
    assert not out.exists()


@pytest.mark.parametrize(("toml_value", "problem"), [
    ('"lab/escape"', "path separator '/'"),
    ('"a\\\\b"', "path separator '\\\\'"),
    ('".."', "contains '..'"),
    ('"x..y"', "contains '..'"),
    ('"nul\\u0000"', "NUL character"),
    ('"bell\\u0007"', "control character '\\x07'"),
    ('"tab\\there"', "control character '\\t'"),
])
def test_names_with_separators_dots_nul_or_control_characters_are_refused_at_load(
        tmp_path: Path, toml_value: str, problem: str) -> None:
    path = tmp_path / "s.toml"
    for key, text in (("name", f'name = {toml_value}\ncontrollers = ["leg-edge"]\n'),
                      ("controllers[0].label",
                       f'name = "ok"\ncontrollers = [{{name = "leg-edge", label = '
                       f'{toml_value}}}]\n'),
                      ("controllers[0]", f'name = "ok"\ncontrollers = [{toml_value}]\n')):
        path.write_text(text)
        with pytest.raises(ScenarioError) as info:
            load_scenario(path)
        assert info.value.key == key and info.value.path == str(path)
        assert problem in str(info.value), str(info.value)


def test_a_controller_from_the_command_line_is_checked_the_same_way(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scen = _scenario(tmp_path)
    assert cli_main(["run", str(scen), "--out", str(tmp_path / "o"),
                     "--controllers", "../x:Y"]) == 2
    assert "--controllers: '../x:Y': contains the path separator '/'" in \
        capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_report_refuses_a_name_from_a_results_file_that_leaves_the_directory(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Names read back from a shared results.jsonl never checked at load."""
    out = tmp_path / "deep" / "run"
    assert cli_main(["run", str(_scenario(tmp_path)), "--out", str(out), "--no-progress",
                     "--record", "0"]) == 0
    rows = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    for r in rows:
        r["scenario"] = "../../escape"
    (out / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    capsys.readouterr()
    before = _tree(tmp_path)
    assert cli_main(["report", str(out)]) == 2
    err = capsys.readouterr().err
    assert "escape_time_to_converge.png: would be written outside" in err  # the first figure
    assert "nothing was written" in err
    assert sorted(_tree(tmp_path)) == sorted(before), "no file created anywhere"


# ---------------------------------------------------------------- plugins: names -> paths
def _dist(root: Path, group: str, body: str) -> None:
    (root / "evil_plugin.py").write_text(body)
    info = root / "evil_plugin-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: evil-plugin\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        f"[{group}]\n../evil = evil_plugin:Thing\nfine-name = evil_plugin:Thing\n")


@pytest.fixture
def on_path(tmp_path: Path) -> Iterator[Path]:
    sys.path.insert(0, str(tmp_path))
    try:
        yield tmp_path
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("evil_plugin", None)


def test_a_controller_plugin_with_an_unsafe_name_is_reported_not_registered(
        on_path: Path) -> None:
    _dist(on_path, CONTROLLER_GROUP, "def Thing(**kw):\n    return None\n")
    reg = Registry()
    names = reg.names()
    assert "fine-name" in names and "../evil" not in names
    [err] = [e for e in reg.errors if e.name == "../evil"]
    assert err.source == "evil-plugin"
    assert "contains the path separator '/'" in str(err)
    with pytest.raises(PluginLoadError, match="control character"):
        reg.register("bad\x01name", lambda: None)


def test_a_backend_plugin_with_an_unsafe_name_is_reported_not_registered(
        on_path: Path) -> None:
    _dist(on_path, BACKEND_GROUP, "def Thing(args, geometry, start):\n    return None\n")
    reg = BackendRegistry()
    names = reg.names()
    assert "fine-name" in names and "../evil" not in names
    [err] = [e for e in reg.errors if e.spec == "../evil"]
    assert "contains the path separator '/'" in str(err)
    with pytest.raises(BackendPluginError, match="NUL"):
        reg.register("x\x00", lambda a, g, s: None)


# ------------------------------------------------------- case 2: run --out over user files
@pytest.mark.slow
def test_run_refuses_a_directory_holding_a_users_files(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "mine"
    out.mkdir()
    (out / "report.md").write_text("# My notes\nhours of work\n")
    (out / "data.csv").write_text("1,2\n")
    before = _tree(out)
    assert cli_main(["run", str(_scenario(tmp_path)), "--out", str(out),
                     "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert (f"error: {out}: is not empty and is not a run directory (no results.jsonl or "
            "run.json): it holds data.csv, report.md; choose another --out, or add "
            "--overwrite") in err
    assert _tree(out) == before
    assert sorted(p.name for p in out.iterdir()) == ["data.csv", "report.md"], "no .lock"
    # the user asks explicitly: the run writes, report.md replaced, data.csv kept
    assert cli_main(["run", str(_scenario(tmp_path)), "--out", str(out), "--no-progress",
                     "--overwrite"]) == 0
    assert (out / "results.jsonl").is_file()
    assert (out / "data.csv").read_text() == "1,2\n"
    assert (out / "report.md").read_text().startswith("# Benchmark report")


def test_a_users_files_in_folders_named_as_the_runs_own_are_not_the_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``trials/`` and ``inputs/`` count as the run's own in a directory that is not a run
    directory only while they hold no file: a user's file there was replaced without a
    word (a trial record), or kept in place of the run's copy (a source.toml: no
    scenario.toml written, the report's rerun command broken). Refused, naming them;
    with ``--overwrite`` the run writes its own copies."""
    scen = _scenario(tmp_path)
    for where, name, text in (("trials", "small__p0__joint-space__00000.npz", "precious"),
                              ("inputs/small", "source.toml", "my own")):
        out = tmp_path / where.split("/")[0]
        (out / where).mkdir(parents=True)
        (out / where / name).write_text(text)
        before = _tree(out)
        assert cli_main(["run", str(scen), "--out", str(out), "--no-progress"]) == 2
        top = where.split("/")[0]
        assert f"is not a run directory (no results.jsonl or run.json): it holds {top}" \
            in capsys.readouterr().err
        assert _tree(out) == before
    (tmp_path / "empty" / "trials").mkdir(parents=True)  # empty folders: still accepted
    assert cli_main(["run", str(scen), "--out", str(tmp_path / "empty"), "--no-progress"]) == 0
    out = tmp_path / "inputs"
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--overwrite"]) == 0
    kept = out / "inputs" / "small"
    assert (kept / "source.toml").read_bytes() == scen.read_bytes()
    assert (kept / "scenario.toml").is_file()
    assert json.loads((out / "run.json").read_text())["scenarios"]["small"]["inputs"][
        "changed"] is False
    assert "differs from the copy" not in capsys.readouterr().err


@pytest.mark.slow
def test_a_run_directory_keeps_its_rule_and_its_foreign_report_is_kept(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scen = _scenario(tmp_path)
    out = tmp_path / "run"
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress"]) == 0
    capsys.readouterr()
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress"]) == 2
    assert "already holds results; use --resume" in capsys.readouterr().err
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress",
                     "--resume"]) == 0  # its own directory
    assert cli_main(["report", str(out)]) == 0
    capsys.readouterr()
    (out / "report.md").write_text("my own analysis\n")  # the user replaced it
    assert cli_main(["report", str(out)]) == 2
    assert "report.md: already exists (a .md file of 16 bytes, not written by hexapod-vs)" \
        in capsys.readouterr().err
    assert (out / "report.md").read_text() == "my own analysis\n"
    assert cli_main(["report", str(out), "--overwrite"]) == 0
    # notes that quote the mark in their text are the user's, not the project's
    notes = "# My notes\n\nThe first table was written by hexapod-vs, the rest is mine.\n"
    (out / "report.md").write_text(notes)
    assert cli_main(["report", str(out)]) == 2 and (out / "report.md").read_text() == notes
    assert cli_main(["report", str(out), "--overwrite"]) == 0
    # a figure the user edited and saved (its mark lost): kept, named, until --overwrite
    figure = sorted(out.glob("*.png"))[0]
    figure.write_bytes(b"my edited figure")
    capsys.readouterr()
    assert cli_main(["report", str(out)]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert f"holds {figure.name}, PNG file(s) hexapod-vs did not write" in err
    assert figure.read_bytes() == b"my edited figure"
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--resume"]) == 2
    assert figure.read_bytes() == b"my edited figure"
    assert cli_main(["report", str(out), "--overwrite"]) == 0
    assert figure.read_bytes().startswith(b"\x89PNG")


# ------------------------------------------------ case 3: calibrate over a calibration
def test_calibrate_never_replaces_a_calibration_silently(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scen = _scenario(tmp_path, controllers='["leg-edge"]')
    out = tmp_path / "cal"
    assert cli_main(["calibrate", str(scen), "--out", str(out)]) == 0
    capsys.readouterr()
    (out / "calibrated.toml").write_text('source = "the real robot, two days of work"\n'
                                         + (out / "calibrated.toml").read_text()
                                         .split("\n", 2)[2])
    before = _tree(out)
    assert cli_main(["calibrate", str(scen), "--out", str(out), "--repeat", "2"]) == 2
    err = capsys.readouterr().err
    assert (f"error: {out}: already holds a calibration (calibrated.toml, calibration.json; "
            "calibrated.toml made from the real robot, two days of work); choose another "
            "--out, or add --overwrite to replace it") in err
    assert _tree(out) == before
    obs = tmp_path / "obs.json"
    obs.write_text("{}")
    assert cli_main(["calibrate", str(scen), "--out", str(out), "--observations",
                     str(obs)]) == 2  # the other way to calibrate: refused the same way
    assert "already holds a calibration" in capsys.readouterr().err
    assert _tree(out) == before
    assert cli_main(["calibrate", str(scen), "--out", str(out), "--overwrite"]) == 0
    assert "two days" not in (out / "calibrated.toml").read_text()


def test_calibrate_refuses_a_directory_of_other_files(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scen = _scenario(tmp_path / "robot", controllers='["leg-edge"]')
    assert cli_main(["calibrate", str(scen), "--out", str(scen.parent)]) == 2
    assert "is not empty and is not a calibration directory: it holds study.toml" in \
        capsys.readouterr().err
    assert sorted(p.name for p in scen.parent.iterdir()) == ["study.toml"]


# ---------------------------------------------------------------- single-file outputs
@pytest.mark.slow
def test_viz_html_replaces_its_own_page_but_not_a_users_file(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    assert cli_main(["run", str(_scenario(tmp_path)), "--out", str(out), "--no-progress",
                     "--record", "1"]) == 0
    page = tmp_path / "replay.html"
    for _ in range(2):  # a fresh file, then its own
        assert cli_main(["viz", str(out), "--html", str(page)]) == 0
    capsys.readouterr()
    notes = tmp_path / "notes.html"
    notes.write_text("<p>mine</p>")
    assert cli_main(["viz", str(out), "--html", str(notes)]) == 2
    assert f"{notes}: already exists (a .html file of 11 bytes, not written by hexapod-vs); " \
        "choose another name, or add --overwrite" in capsys.readouterr().err
    assert notes.read_text() == "<p>mine</p>"
    picture = tmp_path / "page.png"
    picture.write_bytes(b"\x89PNG\r\n\x1a\n my photo")
    assert cli_main(["viz", str(out), "--html", str(tmp_path / "page.html")]) == 2
    assert "page.png: already exists" in capsys.readouterr().err
    assert not (tmp_path / "page.html").exists()
    assert cli_main(["viz", str(out), "--html", str(notes), "--overwrite"]) == 0
    assert cli_main(["viz", str(out), "--html", str(tmp_path / "x.png")]) == 2
    assert "give the page an .html name" in capsys.readouterr().err


@pytest.mark.slow
def test_a_name_with_a_colon_stays_a_local_figure_in_the_report(
        tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert cli_main(["run", str(_scenario(tmp_path, name="lab:a")), "--out", str(out),
                     "--no-progress"]) == 0
    assert (out / "lab:a_error_cdf.png").is_file()
    report = (out / "report.md").read_text()
    assert "![error CDF](./lab:a_error_cdf.png)" in report, "not a URL scheme 'lab:'"
    assert "](lab:a" not in report


@pytest.mark.slow
def test_perf_outputs_replace_their_own_files_only(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    figure, figures = tmp_path / "edges.png", tmp_path / "cal.json"
    vision = ["perf", "vision", "--poses", "3", "--figure", str(figure)]
    calibration = ["perf", "calibration", "--repeats", "1", "--noise", "0.01", "--json",
                   str(figures)]
    for _ in range(2):  # a fresh file, then its own
        assert cli_main(vision) == 0
        assert cli_main(calibration) == 0
    assert json.loads(figures.read_text())["generator"] == "hexapod-vs"
    capsys.readouterr()
    figure.write_bytes(b"\x89PNG\r\n\x1a\n a photo")
    figures.write_text('{"mine": 1}')
    assert cli_main(vision) == 2
    assert cli_main(calibration) == 2
    err = capsys.readouterr().err
    assert f"{figure}: already exists" in err and f"{figures}: already exists" in err
    assert figures.read_text() == '{"mine": 1}'
    assert cli_main([*calibration, "--overwrite"]) == 0
