"""Benchmark studies: scenarios, the runner, results, reports and their statistics.

``benchmarks.study.load(DIR)`` returns a run's trials as a pandas DataFrame.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import pandas as pd


def load(out_dir: str | Path) -> pd.DataFrame:
    """A run directory's trials as a DataFrame (:func:`benchmarks.study.table.load`)."""
    from benchmarks.study.table import load as _load

    return _load(out_dir)
