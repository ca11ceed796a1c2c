"""A run as a table for analysis: one pandas row per trial (``benchmarks.study.load``),
written to Parquet by ``hexapod-bench export``.

pandas is the table a notebook user continues with; pyarrow writes Parquet (typed
columns, compressed, read back by pandas, polars, R's arrow or DuckDB alike).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from benchmarks.exceptions import ResultsError
from benchmarks.study.metrics import sweep_values
from benchmarks.study.results import RESULTS_FILE, read_results

if TYPE_CHECKING:
    import pandas as pd

log = logging.getLogger(__name__)

#: Columns first, in this order (then the sweep values, then the rest, sorted).
LEAD_COLUMNS = ["scenario", "point", "controller", "backend", "trial"]
#: The Parquet schema metadata key of the run's record (``run.json``, as JSON) in a file
#: of :func:`export_parquet`, for readers other than pandas (polars, DuckDB, R's arrow).
RUN_METADATA = b"hexapod_bench.run"


def load(out_dir: str | Path) -> pd.DataFrame:
    """The trials of a run directory as a DataFrame, one row per trial.

    Columns: ``scenario``, ``point`` (sweep point index), ``controller``, ``backend``,
    ``trial``, then the sweep values (``noise_amplitude_deg``...), then every other key
    of the rows (``converged``, ``final_position_error_mm``, ``steps``...). Missing
    values (a crashed trial's error) are NaN. Duplicate rows of one trial (two runs
    into one directory) keep the first, as the report does. ``df.attrs`` holds
    ``sweep_columns`` and the run's ``run.json`` (``meta``) when present.

    Args:
        out_dir: A directory written by ``hexapod-bench run``.

    Returns:
        The table.

    Raises:
        ResultsError: No ``results.jsonl`` in the directory, or a corrupted line.
    """
    out_dir = Path(out_dir)
    df = _read_fast(out_dir)
    if df is None:  # the exact reader names a corrupted line
        import pandas as pd

        rows = read_results(out_dir)
        if not rows:
            raise ResultsError(str(out_dir / RESULTS_FILE), "no trial rows")
        df = pd.DataFrame.from_records(rows)
    # rows written before the goal setting existed used the legacy one (benchmarks.sim.goal)
    for col, default in (("point", 0), ("backend", "sim"), ("goal", "mixed")):
        if col not in df:
            df[col] = default
    before = len(df)
    df = df.drop_duplicates(subset=["scenario", "point", "controller", "trial"], keep="first")
    if len(df) < before:
        log.warning("%s: %d duplicate row(s) ignored (the first row of each trial kept)",
                    out_dir / RESULTS_FILE, before - len(df))
    df = df.reset_index(drop=True)
    for col in df.columns:
        if df[col].dtype == object and df[col].map(
                lambda v: isinstance(v, list | dict | np.ndarray)).any():
            df[col] = df[col].map(lambda v: json.dumps(np.asarray(v).tolist())
                                  if isinstance(v, list | dict | np.ndarray) else v)
    sweep_cols = [c for c in sweep_values(dict.fromkeys(df.columns)) if c not in LEAD_COLUMNS]
    rest = sorted(c for c in df.columns if c not in LEAD_COLUMNS and c not in sweep_cols)
    df = df[[c for c in LEAD_COLUMNS if c in df.columns] + sweep_cols + rest]
    df["converged"] = df["converged"].fillna(False).astype(bool)
    for col in ("final_position_error_mm", "final_orientation_error_deg", "step_time_us"):
        if col in df:
            df[col] = df[col].astype(float)
    df.attrs["sweep_columns"] = sweep_cols
    meta = out_dir / "run.json"
    if meta.exists():
        try:
            df.attrs["meta"] = json.loads(meta.read_text())
        except json.JSONDecodeError:
            log.warning("%s: not valid JSON, left out of df.attrs", meta)
    return df


def _read_fast(out_dir: Path) -> pd.DataFrame | None:
    """``results.jsonl`` parsed by pyarrow's JSON reader (C++, about ten times faster
    than one ``json.loads`` per line); None when it cannot parse the file (then the
    line-by-line reader says which line is wrong)."""
    import pyarrow as pa
    import pyarrow.json as pj

    path = out_dir / RESULTS_FILE
    if not path.exists():
        raise ResultsError(str(path), "no results file (run 'hexapod-bench run' first)")
    data = path.read_bytes()
    cut = data.rfind(b"\n") + 1
    if cut < len(data):
        log.warning("%s: ignoring a partial last line", path)
        data = data[:cut]
    if not data.strip():
        raise ResultsError(str(path), "no trial rows")
    try:
        table = pj.read_json(pa.BufferReader(data),
                             read_options=pj.ReadOptions(block_size=max(len(data), 1 << 20)))
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError) as exc:
        log.info("%s: pyarrow could not read it (%s); reading line by line", path, exc)
        return None
    if any(key not in table.column_names or table[key].null_count
           for key in ("scenario", "controller", "trial")):
        return None  # a row without its trial key: the exact reader names its line
    return table.to_pandas()


def export_parquet(out_dir: str | Path, path: str | Path, overwrite: bool = False
                   ) -> tuple[Path, int]:
    """Write the table of :func:`load` to a Parquet file with the run's record:
    ``pandas.read_parquet`` gives back ``df.attrs`` (``sweep_columns`` and ``meta``, the
    run's ``run.json``), and the schema metadata holds ``run.json`` under
    :data:`RUN_METADATA` and ``generator`` (:func:`hexapod.outputs.write_output`).

    Args:
        out_dir: The run directory.
        path: The Parquet file.
        overwrite: Replace a file hexapod-bench did not write.

    Returns:
        The file and its number of rows.

    Raises:
        OutputError: ``path`` is a user's file (without ``overwrite``); nothing written.
    """
    import pyarrow as pa

    from hexapod.outputs import check_replace, write_output

    check_replace(path, overwrite, kind="Parquet")  # before reading the run
    df = load(out_dir)
    # the run's record travels with the table: pandas restores ``df.attrs`` (the
    # ``pandas`` metadata), other readers find run.json under RUN_METADATA
    table = pa.Table.from_pandas(df, preserve_index=False)
    if "meta" in df.attrs:
        table = table.replace_schema_metadata({
            **(table.schema.metadata or {}),
            RUN_METADATA: json.dumps(df.attrs["meta"]).encode()})
    return write_output(path, table, overwrite), len(df)
