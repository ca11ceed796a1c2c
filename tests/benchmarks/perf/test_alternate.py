"""``benchmarks.perf.alternate``: a command run in two trees, old then new, in real
subprocesses (two stand-in trees whose ``benchmarks.cli`` logs its call and prints a
trials line), the warm-up left out, the ratios from what the runs printed."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.perf.alternate import Timed, alternate, main, summary

CLI = """import os, sys
with open(os.environ["ALTERNATE_LOG"], "a") as log:
    log.write("{name} " + " ".join(sys.argv[1:]) + "\\n")
if "{fail}":
    print("no such scenario: nowhere", file=sys.stderr)
    sys.exit(3)
print("3000 trials in {trials} s (in-process, 1 worker(s))")
"""


def _tree(root: Path, name: str, trials: str, fail: bool = False) -> Path:
    tree = root / name
    (tree / "benchmarks").mkdir(parents=True)
    (tree / "benchmarks" / "__init__.py").write_text("")
    (tree / "benchmarks" / "cli.py").write_text(
        CLI.format(name=name, trials=trials, fail="yes" if fail else ""))
    return tree


def test_runs_alternate_in_their_trees_with_a_new_directory_each(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    log = tmp_path / "calls.log"
    monkeypatch.setenv("ALTERNATE_LOG", str(log))
    old, new = _tree(tmp_path, "old", "12.0"), _tree(tmp_path, "new", "4.0")
    lines: list[str] = []
    pairs = alternate(old, new, ["run", "quick", "--out", "{out}"], rounds=2, warmup=1,
                      report=lines.append)
    calls = [line.split() for line in log.read_text().splitlines()]
    assert [c[0] for c in calls] == ["old", "new"] * 3  # the warm-up pair, then two
    outs = [c[-1] for c in calls]
    assert len(set(outs)) == 6 and "{out}" not in outs  # a new directory per run
    assert all(c[1:3] == ["run", "quick"] for c in calls)
    assert len(pairs) == 2  # the warm-up left out
    assert [(a.tree, b.tree) for a, b in pairs] == [(str(old), str(new))] * 2
    assert all(a.trials_s == 12.0 and b.trials_s == 4.0 for a, b in pairs)
    assert lines[0].startswith("warm-up: ") and lines[2].startswith("pair 2: ")
    assert "trials alone: median 3.00 times (3.00 to 3.00)" in summary(pairs)


def test_a_failed_run_stops_with_its_status_and_output(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("ALTERNATE_LOG", str(tmp_path / "calls.log"))
    old, new = _tree(tmp_path, "old", "1"), _tree(tmp_path, "new", "1", fail=True)
    assert main([str(old), str(new), "--rounds", "1", "--", "run", "x", "--out",
                 "{out}"]) == 1
    err = capsys.readouterr().err
    assert "exit status 3" in err and "no such scenario: nowhere" in err


def test_summary_gives_each_pair_and_the_median_ratio() -> None:
    pairs = [(Timed("a", 10.0, None), Timed("b", 5.0, None)),
             (Timed("a", 9.0, None), Timed("b", 3.0, None)),
             (Timed("a", 4.0, None), Timed("b", 5.0, None))]
    lines = summary(pairs)
    assert lines[0] == "pair 1: old 10.00 s, new 5.00 s, 2.00 times"
    assert lines[2] == "pair 3: old 4.00 s, new 5.00 s, 0.80 times"
    assert lines[3] == "median 2.00 times over 3 pairs (0.80 to 3.00); new faster in 2 of 3"
    assert len(lines) == 4  # no trials line: none printed


@pytest.mark.parametrize(("extra", "message"), [
    (["--", "run", "quick", "--out", "DIR"], "a run needs --out {out}"),
    (["--rounds", "0", "--", "list"], "--rounds: at least 1, got 0"),
    (["--warmup", "-1", "--", "list"], "--warmup: at least 0, got -1"),
    ([], "no command"),
])
def test_bad_arguments_are_refused_naming_them(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str],
        message: str) -> None:
    old, new = _tree(tmp_path, "old", "1"), _tree(tmp_path, "new", "1")
    with pytest.raises(SystemExit) as exc:
        main([str(old), str(new), *extra])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_a_tree_that_is_not_the_project_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    new = _tree(tmp_path, "new", "1")
    with pytest.raises(SystemExit):
        main([str(tmp_path / "nowhere"), str(new), "--", "list"])
    assert "not a code tree of this project" in capsys.readouterr().err
