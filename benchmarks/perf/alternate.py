"""Time one ``hexapod-bench`` command in two code trees, alternated on one machine.

A machine's speed drifts over minutes and hours (a 2-core machine took 58 to 184 s for
the same study on different days), so the only fair comparison of two commits is one
run of each after the other, several times: ``OLD``, ``NEW``, ``OLD``, ``NEW``, ... Each
run is ``python -m benchmarks.cli ARGS`` in its tree (``PYTHONPATH`` at it), ``{out}``
in the arguments replaced by a new directory per run; the first ``--warmup`` pairs are
run and left out (a tree's first run may compile its kernels). Printed: each pair's wall
times, the ratio old / new, and the median ratio, then the same for the trials alone
when the command prints them (``run``'s ``N trials in X s``).

Run (a tree of the old commit from ``git worktree add /tmp/old REV``)::

    python -m benchmarks.perf.alternate /tmp/old . --rounds 5 -- run paccot2008-tracking \\
        --trials 200 --workers 1 --out {out}
"""

from __future__ import annotations

import argparse
import re
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from benchmarks.perf import check_counts, cli_in_tree

#: ``run``'s last line: the trials' own time.
TRIALS = re.compile(r"(\d+) trials in ([0-9.]+) s")


@dataclass(frozen=True)
class Timed:
    """One run of the command.

    Attributes:
        tree: The code tree it ran in.
        wall_s: Its wall time [s], the interpreter's start and exit included.
        trials_s: The trials' time it printed [s], or None.
    """

    tree: str
    wall_s: float
    trials_s: float | None


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
    return Timed(str(tree), wall, float(found[-1][1]) if found else None)


def ratios(pairs: Sequence[tuple[Timed, Timed]], trials: bool = False) -> list[float]:
    """Old / new of each pair, of the wall times or of the trials' (pairs without them
    left out)."""
    if not trials:
        return [old.wall_s / new.wall_s for old, new in pairs]
    return [old.trials_s / new.trials_s for old, new in pairs
            if old.trials_s is not None and new.trials_s is not None]


def summary(pairs: Sequence[tuple[Timed, Timed]]) -> list[str]:
    """The printed lines: each pair, then the median ratios."""
    lines = []
    wall = ratios(pairs)
    for k, ((old, new), ratio) in enumerate(zip(pairs, wall, strict=True), 1):
        line = f"pair {k}: old {old.wall_s:.2f} s, new {new.wall_s:.2f} s, {ratio:.2f} times"
        if old.trials_s is not None and new.trials_s is not None:
            line += f" (trials {old.trials_s:.1f} / {new.trials_s:.1f} s, " \
                    f"{old.trials_s / new.trials_s:.2f} times)"
        lines.append(line)
    if wall:
        lines.append(f"median {statistics.median(wall):.2f} times over {len(wall)} pairs "
                     f"({min(wall):.2f} to {max(wall):.2f}); new faster in "
                     f"{sum(r > 1 for r in wall)} of {len(wall)}")
    alone = ratios(pairs, trials=True)
    if alone:
        lines.append(f"trials alone: median {statistics.median(alone):.2f} times "
                     f"({min(alone):.2f} to {max(alone):.2f})")
    return lines


def _progress(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def alternate(old: Path, new: Path, args: Sequence[str], rounds: int, warmup: int,
              report: Callable[[str], None] = _progress) -> list[tuple[Timed, Timed]]:
    """``warmup + rounds`` pairs, old then new, each pair reported as it ends (progress,
    on standard error by default); the timed pairs (the warm-up's left out)."""
    pairs = []
    with tempfile.TemporaryDirectory(prefix="hexapod-alternate-") as scratch:
        for k in range(warmup + rounds):
            timed = (run_once(old, args, Path(scratch) / f"old-{k}"),
                     run_once(new, args, Path(scratch) / f"new-{k}"))
            label = "warm-up" if k < warmup else f"pair {k - warmup + 1}"
            report(f"{label}: old {timed[0].wall_s:.2f} s, new {timed[1].wall_s:.2f} s")
            if k >= warmup:
                pairs.append(timed)
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
        pairs = alternate(args.old.resolve(), args.new.resolve(), command, args.rounds,
                          args.warmup)
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print("\n".join(summary(pairs)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
