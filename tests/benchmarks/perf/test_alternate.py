"""``benchmarks.perf.alternate``: a command run in two trees, the order turned every
pair, in real subprocesses (two stand-in trees whose ``benchmarks.cli`` logs its call
and prints a trials line that changes from call to call), the warm-up left out, the
ratios from what the runs printed."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.perf.alternate import Timed, alternate, main, summary

#: The stand-in command line: its ``k``-th call (of its tree) prints ``base + step * k``
#: seconds of trials, and fails from its ``fail``-th call on.
CLI = """import os, sys
path = os.environ["ALTERNATE_LOG"]
with open(path, "a") as log:
    log.write("{name} " + " ".join(sys.argv[1:]) + "\\n")
with open(path) as log:
    k = sum(1 for line in log if line.startswith("{name} "))
if k >= {fail}:
    print("no such scenario: nowhere", file=sys.stderr)
    sys.exit(3)
if sys.argv[1:2] == ["perf"]:  # perf controllers' table: (name, us + more * k^2)
    print("controller step time, reference robot, front camera, all features visible")
    print("controller                        median us    p95 us  x joint  budget us")
    for row, us, more in {table!r}:
        print(f"{{row:<32}} {{us + more * k * k:>10.1f}} {{2 * us:>9.1f}}      1.0")
    print("(a line after the table)")
    sys.exit(0)
print(f"3000 trials in {{{base} + {step} * k:.1f}} s (in-process, 1 worker(s))")
"""


def _tree(root: Path, name: str, base: float, step: float = 0.0, fail: int = 10**6,
          table: tuple[tuple[str, float, float], ...] = ()) -> Path:
    tree = root / name
    (tree / "benchmarks").mkdir(parents=True)
    (tree / "benchmarks" / "__init__.py").write_text("")
    (tree / "benchmarks" / "cli.py").write_text(
        CLI.format(name=name, base=base, step=step, fail=fail, table=table))
    return tree


def test_runs_alternate_in_their_trees_with_a_new_directory_each(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    log = tmp_path / "calls.log"
    monkeypatch.setenv("ALTERNATE_LOG", str(log))
    # old's trials 13, 14, 15, 16 s; new's 2, 4, 6, 8 s: the timed pairs' ratios 3.5,
    # 2.5 and 2.0 (median 2.5; their mean, 2.67, or any one pair would differ)
    old, new = _tree(tmp_path, "old", 12.0, 1.0), _tree(tmp_path, "new", 0.0, 2.0)
    lines: list[str] = []
    pairs = alternate(old, new, ["run", "quick", "--out", "{out}"], rounds=3, warmup=1,
                      report=lines.append)
    calls = [line.split() for line in log.read_text().splitlines()]
    # the warm-up pair, then three, the order turned every pair
    assert [c[0] for c in calls] == ["old", "new", "new", "old"] * 2
    outs = [c[-1] for c in calls]
    assert len(set(outs)) == 8 and "{out}" not in outs  # a new directory per run
    assert all(c[1:3] == ["run", "quick"] for c in calls)
    assert len(pairs) == 3  # the warm-up left out
    assert [(a.tree, b.tree) for a, b in pairs] == [(str(old), str(new))] * 3
    assert [(a.trials_s, b.trials_s) for a, b in pairs] == [(14, 4), (15, 6), (16, 8)]
    assert lines[0].startswith("warm-up: ") and lines[0].endswith("(old first)")
    assert lines[1].startswith("pair 1: ") and lines[1].endswith("(new first)")
    out = summary(pairs)
    assert out[0].endswith("(trials 14.0 / 4.0 s, 3.50 times)")
    assert out[2].endswith("(trials 16.0 / 8.0 s, 2.00 times)")
    assert out[-2] == "trials alone: median 2.50 times (2.00 to 3.50)"
    assert out[-1].startswith("outside the trials: old ")


def test_a_relative_tree_is_read_from_the_working_directory(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``sub/old`` given from ``tmp_path``: the run's ``PYTHONPATH`` had stayed relative
    and was read again inside the tree (``sub/old/sub/old``): no ``benchmarks.cli``."""
    monkeypatch.setenv("ALTERNATE_LOG", str(tmp_path / "calls.log"))
    _tree(tmp_path / "sub", "old", 3.0), _tree(tmp_path / "sub", "new", 1.0)
    monkeypatch.chdir(tmp_path)
    (pair,) = alternate(Path("sub/old"), Path("sub/new"), ["list"], rounds=1, warmup=0,
                        report=lambda line: None)
    assert (pair[0].trials_s, pair[1].trials_s) == (3.0, 1.0)


def test_a_failed_run_stops_with_its_status_and_output(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("ALTERNATE_LOG", str(tmp_path / "calls.log"))
    old, new = _tree(tmp_path, "old", 1.0), _tree(tmp_path, "new", 1.0, fail=1)
    assert main([str(old), str(new), "--rounds", "1", "--", "run", "x", "--out",
                 "{out}"]) == 1
    err = capsys.readouterr().err
    assert "exit status 3" in err and "no such scenario: nowhere" in err


def test_the_pairs_before_a_failed_run_are_printed(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The new tree fails on its third call (the second timed pair): the first timed
    pair's line and median are printed before the error (they had been lost)."""
    monkeypatch.setenv("ALTERNATE_LOG", str(tmp_path / "calls.log"))
    old, new = _tree(tmp_path, "old", 6.0), _tree(tmp_path, "new", 2.0, fail=3)
    assert main([str(old), str(new), "--rounds", "3", "--", "run", "x", "--out",
                 "{out}"]) == 1
    out, err = capsys.readouterr()
    assert out.splitlines()[0].startswith("pair 1: ")
    assert "trials alone: median 3.00 times (3.00 to 3.00)" in out
    assert "pair 2" not in out and "exit status 3" in err


def test_summary_gives_each_pair_and_the_median_ratio() -> None:
    pairs = [(Timed("a", 10.0, None), Timed("b", 5.0, None)),
             (Timed("a", 9.0, None), Timed("b", 3.0, None)),
             (Timed("a", 4.0, None), Timed("b", 5.0, None))]
    lines = summary(pairs)
    assert lines[0] == "pair 1: old 10.00 s, new 5.00 s, 2.00 times"
    assert lines[2] == "pair 3: old 4.00 s, new 5.00 s, 0.80 times"
    assert lines[3] == "median 2.00 times over 3 pairs (0.80 to 3.00); new faster in 2 of 3"
    assert len(lines) == 4  # no trials line: none printed


def test_summary_gives_the_time_outside_the_trials() -> None:
    """Wall minus trials, of the pairs whose two runs printed their trials (the third
    pair's old run did not: left out of both sides)."""
    pairs = [(Timed("a", 62.0, 57.75), Timed("b", 15.25, 12.75)),
             (Timed("a", 60.0, 55.0), Timed("b", 15.0, 12.0)),
             (Timed("a", 61.0, None), Timed("b", 14.0, 13.5))]
    lines = summary(pairs)
    assert lines[-1] == ("outside the trials: old 4.25 to 5.00 s (median 4.62), new 2.50 to "
                         "3.00 s (median 2.75)")


def test_summary_leaves_out_a_trials_ratio_it_cannot_form() -> None:
    """A run that printed ``0.0 s`` of trials (a short command) had divided by zero after
    every pair had run; its pair's trials ratio is left out, the others' median kept."""
    pairs = [(Timed("a", 10.0, 9.0), Timed("b", 5.0, 3.0)),
             (Timed("a", 9.0, 8.0), Timed("b", 3.0, 0.0)),
             (Timed("a", 4.0, 6.0), Timed("b", 5.0, 1.0)),
             (Timed("a", 4.0, 2.0), Timed("b", 5.0, 2.0))]
    lines = summary(pairs)
    assert lines[1] == "pair 2: old 9.00 s, new 3.00 s, 3.00 times"
    assert lines[-2] == "trials alone: median 3.00 times (1.00 to 6.00)"


@pytest.mark.parametrize(("extra", "message"), [
    (["--", "run", "quick", "--out", "DIR"], "a run needs --out {out}"),
    (["--rounds", "0", "--", "list"], "--rounds: at least 1, got 0"),
    (["--warmup", "-1", "--", "list"], "--warmup: at least 0, got -1"),
    ([], "no command"),
])
def test_bad_arguments_are_refused_naming_them(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str],
        message: str) -> None:
    old, new = _tree(tmp_path, "old", 1.0), _tree(tmp_path, "new", 1.0)
    with pytest.raises(SystemExit) as exc:
        main([str(old), str(new), *extra])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_a_tree_that_is_not_the_project_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    new = _tree(tmp_path, "new", 1.0)
    with pytest.raises(SystemExit):
        main([str(tmp_path / "nowhere"), str(new), "--", "list"])
    assert "not a code tree of this project" in capsys.readouterr().err



def test_rows_diff_runs_a_relative_tree_with_paths_from_the_working_directory(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``rows_diff run sub/old rows`` from ``tmp_path``: the scenario's path and ``--out``
    were passed relative and read by the run from inside the tree (no such scenario; the
    rows written under ``sub/old/rows``, where ``diff`` does not look)."""
    from benchmarks.perf import rows_diff

    log = tmp_path / "calls.log"
    monkeypatch.setenv("ALTERNATE_LOG", str(log))
    tree = _tree(tmp_path / "sub", "old", 3.0)
    (tree / "benchmarks" / "scenarios").mkdir()
    (tree / "benchmarks" / "scenarios" / "quick.toml").write_text("")
    monkeypatch.chdir(tmp_path)
    rows_diff.run("sub/old", "rows")
    (call,) = [line.split() for line in log.read_text().splitlines()]
    scenario, out = Path(call[2]), Path(call[call.index("--out") + 1])
    assert scenario == tree / "benchmarks" / "scenarios" / "quick.toml"
    assert out == tmp_path / "rows" / "quick"


def test_perf_controllers_steps_compared_controller_by_controller(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``perf controllers`` in both trees: each controller's median over the pairs, old /
    new, and whether the new one is within 10 % or 5 us. ``joint-space`` old 11, 14, 19,
    new 14, 17, 22 us (medians 14 and 17; their means would be 14.7 and 17.7): +3 us
    (+21 %, within 5 us); ``leg-edge`` old 40, new 50: +10 us, +25 % (behind);
    ``leg-edge-qp`` old 200, 203, 208, new 215: +12 us, +6 % (within 10 %); a controller
    only one tree has is left out, named."""
    monkeypatch.setenv("ALTERNATE_LOG", str(tmp_path / "calls.log"))
    old = _tree(tmp_path, "old", 1.0, table=(("joint-space", 10.0, 1.0),
                                             ("leg-edge", 40.0, 0.0),
                                             ("leg-edge-qp", 199.0, 1.0),
                                             ("gone", 5.0, 0.0)))
    new = _tree(tmp_path, "new", 1.0, table=(("joint-space", 13.0, 1.0),
                                             ("leg-edge", 50.0, 0.0),
                                             ("leg-edge-qp", 215.0, 0.0)))
    pairs = alternate(old, new, ["perf", "controllers", "--steps", "10"], rounds=3,
                      warmup=0, report=lambda line: None)
    assert pairs[0][0].steps_us == {"joint-space": 11.0, "leg-edge": 40.0,
                                    "leg-edge-qp": 200.0, "gone": 5.0}
    assert pairs[0][0].trials_s is None  # (no trials line)
    lines = summary(pairs)
    steps = lines[lines.index(next(x for x in lines if x.startswith("per-trial"))) + 1:]
    assert steps == [
        "joint-space: 14.0 / 17.0 us [11.0, 14.0, 19.0 / 14.0, 17.0, 22.0]: +3.0 us, "
        "+21 %: within",
        "leg-edge: 40.0 / 50.0 us [40.0, 40.0, 40.0 / 50.0, 50.0, 50.0]: +10.0 us, +25 %: "
        "BEHIND",
        "leg-edge-qp: 203.0 / 215.0 us [200.0, 203.0, 208.0 / 215.0, 215.0, 215.0]: +12.0 "
        "us, +6 %: within",
        "not timed by every run (left out): gone"]
