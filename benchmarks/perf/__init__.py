"""The performance and accuracy figures behind ``hexapod-bench perf NAME`` (one module per
figure, each with its own ``main(argv)``)."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path


def seed(text: str) -> int:
    """An ``argparse`` type for ``--seed``: a non-negative integer (numpy's generators
    refuse a negative one with a traceback)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"a non-negative integer, got {value}")
    return value


def check_counts(parser: argparse.ArgumentParser, args: argparse.Namespace,
                 *options: str) -> None:
    """Refuse (``parser.error``, exit 2) a count option below 1, right after parsing:
    ``options`` are their flags (``"--trials"``, ``"-n"``), an unset one (None) passes."""
    for option in options:
        value = getattr(args, option.lstrip("-").replace("-", "_"))
        if value is not None and value < 1:
            parser.error(f"{option}: at least 1, got {value}")


def cli_in_tree(tree: str | Path, args: Sequence[str]) -> subprocess.CompletedProcess[str]:
    """``python -m benchmarks.cli ARGS`` with the code of another tree of this project (its
    directory the working directory and first on ``PYTHONPATH``), output captured: how
    two commits are compared on one machine (:mod:`benchmarks.perf.rows_diff`,
    :mod:`benchmarks.perf.alternate`). ``tree`` is resolved first (a relative
    ``PYTHONPATH`` entry named nothing from inside the tree, where the command's own
    processes start); paths in ``args`` are read from the tree, so give them absolute."""
    tree = Path(tree).resolve()
    return subprocess.run([sys.executable, "-m", "benchmarks.cli", *args], cwd=tree,
                          env={**os.environ, "PYTHONPATH": str(tree)}, capture_output=True,
                          text=True, check=False)
