"""The analysis commands of ``hexapod-bench``: ``export``, ``compare``, ``reproduce``.

They read run directories written by ``hexapod-bench run`` (``reproduce`` runs the
built-in scenarios first).
"""

from __future__ import annotations

import argparse
from pathlib import Path


def cmd_export(args: argparse.Namespace) -> int:
    """Write a run's trials as a Parquet table (one row per trial)."""
    from benchmarks.study.table import export_parquet

    path, n = export_parquet(Path(args.dir), Path(args.parquet))
    print(f"wrote {n} trials of {args.dir} to {path} (read it back with "
          f"pandas.read_parquet('{path}'))")
    return 0


def add_analysis_commands(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register ``export``, ``compare`` and ``reproduce`` on the CLI's sub-parsers."""
    s = sub.add_parser("export", help="write a run's trials as a table (Parquet)")
    s.add_argument("dir", help="a run directory")
    s.add_argument("--parquet", required=True, metavar="FILE", help="output Parquet file")
    s.set_defaults(func=cmd_export)
