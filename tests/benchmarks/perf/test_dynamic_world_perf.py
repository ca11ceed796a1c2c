"""``hexapod-bench perf dynamic-world``: both worlds timed in one table, the dynamic
world's compiled period as the plant runs it (lane-parallel C) and as CasADi generates it
(the fallback), with the verdict against the goal."""

from __future__ import annotations

import re

import pytest

from benchmarks.cli import main as cli_main


def test_the_table_times_both_worlds_and_both_compiled_periods(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["perf", "dynamic-world", "--trials", "6", "--periods", "2",
                     "--repeats", "1"]) == 0
    out = capsys.readouterr().out
    rows = {}
    for line in out.splitlines():
        m = re.match(r"\| (.+?) \| ([0-9.]+) \|", line)
        if m:
            rows[m.group(1)] = float(m.group(2))
    assert set(rows) == {
        "kinematic (clamp, integrate, forward kinematics)",
        "dynamic (drives, mechanism, integration, legs)",
        "dynamic: the compiled period alone (lane-parallel C, used)",
        "dynamic: the compiled period alone (CasADi's C, fallback)"}
    assert all(v > 0 for v in rows.values())
    assert re.search(r"the dynamic world (meets|misses) the (goal|moonshot)", out)


@pytest.mark.parametrize(("args", "says"), [
    (["--trials", "0"], "--trials: at least 1, got 0"),
    (["--repeats", "0"], "--repeats: at least 1, got 0"),
    (["--physics-dt", "-1"], "--physics-dt: a positive step in milliseconds, got -1.0")])
def test_bad_counts_are_refused_naming_the_option(args: list[str], says: str,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """(The help showed no defaults; --trials 0 ended in an IndexError, --repeats 0 in
    "no median for empty data", each with a traceback.)"""
    from benchmarks.perf.dynamic_world import main

    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code == 2 and says in capsys.readouterr().err
