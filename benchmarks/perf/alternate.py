"""Time one ``hexapod-bench`` command in two code trees, alternated on one machine.

A machine's speed drifts over minutes and hours (a 2-core machine took 58 to 184 s for
the same study on different days), so the only fair comparison of two commits is one
run of each after the other, several times, the order turned every pair (``OLD NEW``,
``NEW OLD``, ``OLD NEW``, ...: a steady drift favours neither tree). Each run is
``python -m benchmarks.cli ARGS`` in its tree (``PYTHONPATH`` at it), ``{out}`` in the
arguments replaced by a new directory per run; the first ``--warmup`` pairs are run and
left out (a tree's first run may compile its kernels). Printed: each pair's wall times,
the ratio old / new, and the median ratio, then the same for the trials alone when the
command prints them (``run``'s ``N trials in X s``) with each tree's time outside them,
and for ``perf controllers`` each controller's per-trial step (its median us in each run,
the median over the pairs, and whether the new one is within 10 % or 5 us of the old: the
measure of a change that should not slow any step); when a run fails, the pairs timed
before it, then its error.

Run (a tree of the old commit from ``git worktree add /tmp/old REV``)::

    python -m benchmarks.perf.alternate /tmp/old . --rounds 5 -- run paccot2008-tracking \\
        --trials 200 --workers 1 --out {out}
    python -m benchmarks.perf.alternate /tmp/old . --rounds 3 -- perf controllers \\
        --steps 2000 computed-torque leg-edge joint-space
"""

from __future__ import annotations

import argparse
import math
import re
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from benchmarks.perf import check_counts, cli_in_tree

#: ``run``'s last line: the trials' own time.
TRIALS = re.compile(r"(\d+) trials in ([0-9.]+) s")
#: A row of ``perf controllers``' table: the controller's name and its median step [us].
STEP_ROW = re.compile(r"^(\S+)\s+([0-9.]+|nan)\s")
#: How far a new per-trial step may be behind the old one: 10 %, or 5 us if that is more.
STEP_SLACK, STEP_SLACK_US = 0.10, 5.0


@dataclass(frozen=True)
class Timed:
    """One run of the command.

    Attributes:
        tree: The code tree it ran in.
        wall_s: Its wall time [s], the interpreter's start and exit included.
        trials_s: The trials' time it printed [s], or None.
        steps_us: The median step per controller of the ``perf controllers`` table it
            printed [us] (empty: none).
    """

    tree: str
    wall_s: float
    trials_s: float | None
    steps_us: dict[str, float] = field(default_factory=dict)


def step_medians(text: str) -> dict[str, float]:
    """The median step [us] of each controller of a ``perf controllers`` table in
    ``text``: the rows after its header (``controller  median us ...``)."""
    out: dict[str, float] = {}
    rows = False
    for line in text.splitlines():
        if line.startswith("controller ") and "median us" in line:
            rows = True
        elif rows and (m := STEP_ROW.match(line)) is not None:
            out[m.group(1)] = float(m.group(2))
        else:
            rows = False
    return out


def run_once(tree: Path, args: Sequence[str], out: Path,
             clock: Callable[[], float] = time.perf_counter) -> Timed:
    """Run ``python -m benchmarks.cli ARGS`` in ``tree`` (``{out}`` -> ``out``).

    Raises:
        RuntimeError: The command failed (its exit status and the end of its output).
    """
    start = clock()
    done = cli_in_tree(tree, [a.replace("{out}", str(out)) for a in args])
    wall = clock() - start
    if done.returncode != 0:
        tail = (done.stdout + done.stderr).strip().splitlines()[-5:]
        raise RuntimeError(f"{tree}: exit status {done.returncode}: " + " | ".join(tail))
    found = TRIALS.findall(done.stdout + done.stderr)
    return Timed(str(tree), wall, float(found[-1][1]) if found else None,
                 step_medians(done.stdout))


class AlternationError(RuntimeError):
    """A run failed: its message, and the pairs timed before it (``pairs``)."""

    def __init__(self, message: str, pairs: list[tuple[Timed, Timed]]) -> None:
        super().__init__(message)
        self.pairs = pairs


def ratio(old: float | None, new: float | None) -> float | None:
    """``old / new``, or None without both or with ``new`` not positive (a run that
    printed ``0.0 s``)."""
    return None if old is None or new is None or not new > 0 else old / new


def summary(pairs: Sequence[tuple[Timed, Timed]]) -> list[str]:
    """The printed lines: each pair, then the median ratios (of the wall times, and of the
    trials' times of the pairs that printed both)."""
    lines, wall, alone = [], [], []
    for k, (old, new) in enumerate(pairs, 1):
        line = f"pair {k}: old {old.wall_s:.2f} s, new {new.wall_s:.2f} s"
        if (r := ratio(old.wall_s, new.wall_s)) is not None:
            wall.append(r)
            line += f", {r:.2f} times"
        if (t := ratio(old.trials_s, new.trials_s)) is not None:
            alone.append(t)
            line += f" (trials {old.trials_s:.1f} / {new.trials_s:.1f} s, {t:.2f} times)"
        lines.append(line)
    if wall:
        lines.append(f"median {statistics.median(wall):.2f} times over {len(wall)} pairs "
                     f"({min(wall):.2f} to {max(wall):.2f}); new faster in "
                     f"{sum(r > 1 for r in wall)} of {len(wall)}")
    if alone:
        lines.append(f"trials alone: median {statistics.median(alone):.2f} times "
                     f"({min(alone):.2f} to {max(alone):.2f})")
        lines.append(outside_line(pairs))
    return lines + step_lines(pairs)


def outside_line(pairs: Sequence[tuple[Timed, Timed]]) -> str:
    """The runs' time outside their trials (wall minus trials: the start, imports,
    pre-flight and report) [s], old and new, of the pairs whose runs printed both."""
    def spans(runs: list[Timed]) -> str:
        rest = [t.wall_s - t.trials_s for t in runs if t.trials_s is not None]
        return f"{min(rest):.2f} to {max(rest):.2f} s (median {statistics.median(rest):.2f})"

    both = [(old, new) for old, new in pairs
            if old.trials_s is not None and new.trials_s is not None]
    return (f"outside the trials: old {spans([o for o, _ in both])}, new "
            f"{spans([n for _, n in both])}")


def step_lines(pairs: Sequence[tuple[Timed, Timed]]) -> list[str]:
    """Each controller timed by every run (``perf controllers``): its median step [us] in
    each pair, old then new, the medians over the pairs, and whether the new median is
    within :data:`STEP_SLACK` (or :data:`STEP_SLACK_US`, the larger) of the old."""
    if not pairs or not pairs[0][0].steps_us:
        return []
    names = [n for n in pairs[0][0].steps_us
             if all(n in old.steps_us and n in new.steps_us for old, new in pairs)]
    lines = [f"per-trial steps, median us over {len(pairs)} pairs, old / new (each pair's "
             f"in brackets); within: {100 * STEP_SLACK:.0f} % or {STEP_SLACK_US:g} us"]
    for name in names:
        olds = [old.steps_us[name] for old, _ in pairs]
        news = [new.steps_us[name] for _, new in pairs]
        a, b = statistics.median(olds), statistics.median(news)
        if not (math.isfinite(a) and math.isfinite(b) and a > 0):  # (every step refused)
            verdict = "no median to compare"
        else:
            within = b - a <= max(STEP_SLACK * a, STEP_SLACK_US)
            verdict = (f"{b - a:+.1f} us, {100 * (b - a) / a:+.0f} %: "
                       + ("within" if within else "BEHIND"))
        lines.append(f"{name}: {a:.1f} / {b:.1f} us [{', '.join(f'{x:.1f}' for x in olds)}"
                     f" / {', '.join(f'{x:.1f}' for x in news)}]: {verdict}")
    left = sorted({n for old, new in pairs for n in (*old.steps_us, *new.steps_us)}
                  - set(names))
    if left:
        lines.append("not timed by every run (left out): " + ", ".join(left))
    return lines


def _progress(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def alternate(old: Path, new: Path, args: Sequence[str], rounds: int, warmup: int,
              report: Callable[[str], None] = _progress) -> list[tuple[Timed, Timed]]:
    """``warmup + rounds`` pairs, the order turned every pair (old first in the first),
    each pair reported as it ends (progress, on standard error by default); the timed
    pairs as ``(old, new)`` (the warm-up's left out).

    Raises:
        AlternationError: A run failed (with the pairs timed before it).
    """
    trees = {"old": old, "new": new}  # (cli_in_tree resolves them)
    pairs: list[tuple[Timed, Timed]] = []
    with tempfile.TemporaryDirectory(prefix="hexapod-alternate-") as scratch:
        for k in range(warmup + rounds):
            order = ("old", "new") if k % 2 == 0 else ("new", "old")
            timed: dict[str, Timed] = {}
            for name in order:
                try:
                    timed[name] = run_once(trees[name], args, Path(scratch) / f"{name}-{k}")
                except RuntimeError as exc:
                    raise AlternationError(str(exc), pairs) from None
            label = "warm-up" if k < warmup else f"pair {k - warmup + 1}"
            report(f"{label}: old {timed['old'].wall_s:.2f} s, new {timed['new'].wall_s:.2f} s"
                   f" ({order[0]} first)")
            if k >= warmup:
                pairs.append((timed["old"], timed["new"]))
    return pairs


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    p = argparse.ArgumentParser(
        prog="python -m benchmarks.perf.alternate",
        usage="%(prog)s [-h] [--rounds N] [--warmup N] OLD NEW -- ARGS...",
        description=(__doc__ or "").splitlines()[0],
        epilog="ARGS: the hexapod-bench arguments, {out} for a new directory per run")
    p.add_argument("old", type=Path, help="the old commit's tree (a git worktree)")
    p.add_argument("new", type=Path, help="the new commit's tree")
    p.add_argument("--rounds", type=int, default=5, help="timed pairs (default 5)")
    p.add_argument("--warmup", type=int, default=1,
                   help="pairs run first and left out (default 1)")
    given = list(sys.argv[1:] if argv is None else argv)
    cut = given.index("--") if "--" in given else len(given)
    args, command = p.parse_args(given[:cut]), given[cut + 1:]
    if not command:
        p.error("no command: give it after --")
    check_counts(p, args, "--rounds")
    if args.warmup < 0:
        p.error(f"--warmup: at least 0, got {args.warmup}")
    for tree in (args.old, args.new):
        if not (tree / "benchmarks" / "cli.py").is_file():
            p.error(f"{tree}: not a code tree of this project (no benchmarks/cli.py)")
    if command[0] == "run" and not any("{out}" in a for a in command):
        p.error("a run needs --out {out} (each run writes into a new directory)")
    try:
        pairs = alternate(args.old, args.new, command, args.rounds, args.warmup)
    except AlternationError as exc:
        if exc.pairs:  # (the pairs timed before the failure are not lost)
            print("\n".join(summary(exc.pairs)))
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print("\n".join(summary(pairs)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
