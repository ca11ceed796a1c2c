"""Paired comparisons of controllers: within one run, or between two runs of a scenario.

Every controller of a run meets the same trials (same worlds, same draws), so the
comparison of two controllers is paired: trial ``k`` of one against trial ``k`` of the
other at the same sweep point. Convergence is compared by McNemar's exact test, the
continuous metrics (final errors; steps, on the trials both converged) by Wilcoxon's
signed-rank test with the median paired difference and its bootstrap interval. Holm's
correction runs over all the comparisons of one metric (every pair at every sweep
point): a difference is called significant when its Holm-adjusted p-value is below
:data:`ALPHA`.

Between two runs (before and after a change, two machines, two library versions) the
trials are matched by (scenario, sweep point, controller, trial); a significant
worsening is a regression, and matched rows whose outcome differs are listed (with the
same code, seeds and libraries they should be identical: a determinism check).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.study import stats

if TYPE_CHECKING:
    import pandas as pd

#: Significance level of the verdicts (after Holm's correction).
ALPHA = 0.05

#: ``--metric`` names -> (column, unit, higher is better).
METRICS: dict[str, tuple[str, str, bool]] = {
    "converged": ("converged", "", True),
    "final_error": ("final_position_error_mm", "mm", False),
    "orientation_error": ("final_orientation_error_deg", "deg", False),
    "steps": ("steps", "steps", False),
    "tracking_rms": ("tracking_rms_position_mm", "mm", False),
    "tracking_max": ("tracking_max_position_mm", "mm", False),
    "settling": ("settling_time_s", "s", False),
    "saturation": ("saturation_time_s", "s", False),
}
#: Default metrics of a point-to-point task.
DEFAULT_METRICS = ("converged", "final_error", "steps")
#: Default metrics of a trajectory task (``saturation``: in the dynamic world).
TRACKING_METRICS = ("tracking_rms", "tracking_max", "settling", "saturation")
KEY = ["scenario", "point", "controller", "trial"]
#: Columns compared by the determinism check of two runs.
OUTCOME_COLUMNS = ("converged", "steps", "final_position_error_mm",
                   "final_orientation_error_deg")


@dataclass
class Comparison:
    """One paired comparison (difference: ``a - b``; in two-run mode ``a`` is run B).

    Attributes:
        scenario: Scenario name.
        point: Sweep point index.
        sweep: The sweep values, as text.
        a: First controller (two runs: ``B:controller``).
        b: Second controller (two runs: ``A:controller``).
        metric: ``converged``, ``final_error``, ``steps``... or a column name.
        column: The row column compared.
        test: ``mcnemar-exact`` or ``wilcoxon``.
        n: Pairs used.
        statistic: The test's statistic.
        p_value: Two-sided p-value.
        p_holm: Holm-adjusted p-value over the comparisons of the metric.
        difference: Rate difference (converged) or median paired difference.
        interval: Its 95 % bootstrap interval.
        a_value: ``a``'s rate or median over the pairs.
        b_value: ``b``'s rate or median over the pairs.
        better: ``a``, ``b`` or None (not significant).
        verdict: The result in plain words.
    """

    scenario: str
    point: int
    sweep: str
    a: str
    b: str
    metric: str
    column: str
    test: str
    n: int
    statistic: float
    p_value: float
    p_holm: float
    difference: float
    interval: tuple[float, float]
    a_value: float
    b_value: float
    better: str | None = None
    verdict: str = ""
    direction: int = 0
    discordant: tuple[int, int] | None = None
    unit: str = field(default="", repr=False)

    def to_json(self) -> dict[str, Any]:
        """A JSON object (NaN as null)."""
        d = asdict(self)
        d["interval"] = list(self.interval)
        d["discordant"] = list(self.discordant) if self.discordant else None
        return {k: _clean(v) for k, v in d.items()}


def _clean(v: Any) -> Any:
    if isinstance(v, float) and not np.isfinite(v):
        return None
    if isinstance(v, list):
        return [_clean(x) for x in v]
    return v


def resolve_metric(name: str, columns: list[str]) -> tuple[str, str, bool]:
    """(column, unit, higher is better) of a ``--metric`` name or a numeric column.

    Raises:
        BenchmarkError: Unknown name (listing the known ones).
    """
    if name in METRICS:
        return METRICS[name]
    if name in columns:
        return name, "", False
    raise BenchmarkError(f"--metric {name!r}: not a metric ({', '.join(METRICS)}) nor a "
                         f"column of the results ({', '.join(sorted(columns))})")


def _has_values(frame: pd.DataFrame, column: str) -> bool:
    return column in frame and bool(frame[column].notna().any())


def task_metrics(frame: pd.DataFrame) -> tuple[str, ...]:
    """The default metrics of one scenario's trials: :data:`TRACKING_METRICS` for a
    trajectory task (the rows carry tracking figures; ``saturation`` only with the
    dynamic world's drive figures), :data:`DEFAULT_METRICS` for a point-to-point one."""
    if not _has_values(frame, "tracking_rms_position_mm"):
        return DEFAULT_METRICS
    return tuple(m for m in TRACKING_METRICS if _has_values(frame, METRICS[m][0]))


def default_metrics(df: pd.DataFrame) -> dict[str, tuple[str, ...]]:
    """:func:`task_metrics` of every scenario of a run."""
    return {str(name): task_metrics(frame) for name, frame in df.groupby("scenario")}


def failed_mask(frame: pd.DataFrame, suffix: str = "") -> pd.Series:
    """The trials that did not run to their end (an end stop, a crash: a ``failure`` that
    is not the ``not converged`` of a trial that ran to its end)."""
    import pandas as pd

    col = f"failure{suffix}"
    if col not in frame:
        return pd.Series(False, index=frame.index)
    text = frame[col].astype("string")
    return (text.notna() & (text != "") & ~text.str.startswith("not conv")).fillna(False)


def _sweep_text(df: pd.DataFrame) -> dict[tuple[str, int], str]:
    cols = df.attrs.get("sweep_columns", [])
    first = df.drop_duplicates(["scenario", "point"])
    out = {}
    for _, r in first.iterrows():
        vals = [f"{c}={r[c]}" for c in cols if c in r and r[c] == r[c] and r[c] is not None]
        out[(str(r["scenario"]), int(r["point"]))] = ", ".join(vals) or "-"
    return out


def _values(frame: pd.DataFrame, column: str, metric: str) -> pd.DataFrame:
    """Trials x controllers of one (scenario, point); steps only where converged; a
    failed trial (:func:`failed_mask`) has no value but its convergence (a failure)."""
    sub = frame[["trial", "controller", column]].copy()
    if metric == "steps":
        sub[column] = sub[column].where(frame["converged"].astype(bool))
    if metric != "converged":
        sub[column] = sub[column].where(~failed_mask(frame))
    return sub.pivot(index="trial", columns="controller", values=column)


def _test(x: np.ndarray, y: np.ndarray, metric: str) -> stats.TestResult:
    if metric == "converged":
        ok = ~(np.isnan(x) | np.isnan(y))
        return stats.mcnemar_exact(x[ok] > 0.5, y[ok] > 0.5)
    return stats.wilcoxon_signed_rank(x, y)


def _summary_value(x: np.ndarray, y: np.ndarray, metric: str) -> tuple[float, float]:
    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.any():
        return float("nan"), float("nan")
    f = np.mean if metric == "converged" else np.median
    return float(f(x[ok])), float(f(y[ok]))


def _comparison(scenario: str, point: int, sweep: str, a: str, b: str, metric: str,
                column: str, unit: str, x: np.ndarray, y: np.ndarray) -> Comparison:
    res = _test(x, y, metric)
    av, bv = _summary_value(x, y, metric)
    return Comparison(scenario, point, sweep, a, b, metric, column, res.test, res.n,
                      res.statistic, res.p_value, float("nan"), res.difference,
                      (res.low, res.high), av, bv, unit=unit, direction=res.direction,
                      discordant=res.discordant)


def _metric_plan(df: pd.DataFrame, metrics: tuple[str, ...] | None
                 ) -> tuple[list[str], dict[str, tuple[str, ...]]]:
    """The metrics to compare, and those of each scenario (its task's defaults when
    ``metrics`` is None, else ``metrics`` everywhere)."""
    if metrics is not None:
        return list(metrics), {str(s): metrics for s in df["scenario"].unique()}
    per = default_metrics(df)
    return list(dict.fromkeys(m for ms in per.values() for m in ms)), per


def compare_controllers(df: pd.DataFrame, baseline: str | None = None,
                        metrics: tuple[str, ...] | None = None) -> list[Comparison]:
    """Every pair of controllers of a run (or each against ``baseline``), at every sweep
    point, on the trials both ran (the failed trials left out of every metric but
    ``converged``).

    Args:
        df: From :func:`benchmarks.study.load`.
        baseline: Compare every other controller against this one only.
        metrics: Metric names (:data:`METRICS`) or numeric columns; None: each
            scenario's task's (:func:`task_metrics`).

    Returns:
        The comparisons, Holm-adjusted per metric, with verdicts.

    Raises:
        BenchmarkError: Unknown baseline or metric, or fewer than two controllers.
    """
    controllers = sorted(df["controller"].unique())
    if baseline is not None and baseline not in controllers:
        raise BenchmarkError(f"--baseline {baseline!r}: not a controller of this run "
                             f"({', '.join(controllers)})")
    if len(controllers) < 2:
        raise BenchmarkError(f"one controller in this run ({', '.join(controllers)}): "
                             "nothing to compare; compare two runs with DIR_A DIR_B")
    sweeps = _sweep_text(df)
    names, per_scenario = _metric_plan(df, metrics)
    out: list[Comparison] = []
    for name in names:
        column, unit, _ = resolve_metric(name, list(df.columns))
        family: list[Comparison] = []
        for (scenario, point), frame in df.groupby(["scenario", "point"], sort=True):
            if name not in per_scenario[str(scenario)]:
                continue
            table = _values(frame, column, name)
            present = [c for c in controllers if c in table.columns]
            if baseline is not None:
                pairs = [(c, baseline) for c in present if c != baseline
                         and baseline in present]
            else:
                pairs = [(present[i], present[j]) for i in range(len(present))
                         for j in range(i + 1, len(present))]
            for a, b in pairs:
                x = table[a].to_numpy(dtype=float)
                y = table[b].to_numpy(dtype=float)
                family.append(_comparison(str(scenario), int(point),
                                          sweeps[(str(scenario), int(point))], a, b, name,
                                          column, unit, x, y))
        _holm_and_verdicts(family, name)
        out += family
    return out


def _holm_and_verdicts(family: list[Comparison], metric: str) -> None:
    adjusted = stats.holm([c.p_value for c in family])
    higher_better = METRICS.get(metric, ("", "", False))[2]
    for c, p in zip(family, adjusted, strict=True):
        c.p_holm = p
        if not np.isfinite(p) or c.n == 0:
            c.verdict = f"{metric}: no pairs to compare"
            continue
        if p >= ALPHA or c.direction == 0:
            c.verdict = (f"{metric}: no significant difference between {c.a} and {c.b} "
                         f"(Holm p = {p:.3g}, {c.n} pairs)")
            continue
        a_better = (c.direction > 0) == higher_better
        c.better = c.a if a_better else c.b
        worse = c.b if a_better else c.a
        c.verdict = f"{metric}: {c.better} is better than {worse} ({_effect(c)}, " \
                    f"Holm p = {p:.3g}, {c.n} pairs)"


def _effect(c: Comparison) -> str:
    lo, hi = c.interval
    if c.metric == "converged":
        return (f"{100 * c.a_value:.1f} % against {100 * c.b_value:.1f} %, difference "
                f"{100 * c.difference:+.1f} points [{100 * lo:+.1f}, {100 * hi:+.1f}]")
    unit = f" {c.unit}" if c.unit else ""
    up, down = c.discordant or (0, 0)
    return (f"median paired difference {c.difference:+.4g}{unit} [{lo:+.4g}, {hi:+.4g}], "
            f"medians {c.a_value:.4g} and {c.b_value:.4g}{unit}; {c.a} higher in {up} and "
            f"lower in {down} of the pairs")


def match_counts(df_a: pd.DataFrame, df_b: pd.DataFrame) -> tuple[int, int, int]:
    """Trials of two runs matched by (scenario, sweep point, controller, trial).

    Returns:
        ``(matched, only in A, only in B)``.
    """
    a = set(map(tuple, df_a[KEY].astype(str).to_numpy().tolist()))
    b = set(map(tuple, df_b[KEY].astype(str).to_numpy().tolist()))
    return len(a & b), len(a - b), len(b - a)


def compare_runs(df_a: pd.DataFrame, df_b: pd.DataFrame, name_a: str = "A",
                 name_b: str = "B", metrics: tuple[str, ...] | None = None
                 ) -> tuple[list[Comparison], pd.DataFrame, int]:
    """Two runs of the same scenarios: run B against run A, per controller and sweep
    point, on the matched trials (a trial failed in either run left out of every metric
    but ``converged``; ``metrics`` None: each scenario's task's, :func:`task_metrics`
    of run A).

    Returns:
        The comparisons (``a`` is ``B:controller``, ``b`` is ``A:controller``; a
        significant worsening of B says *regression* in its verdict), the matched rows
        whose outcome differs (key columns, then ``column``, ``a``, ``b``), and the
        number of matched rows.

    Raises:
        BenchmarkError: The runs share no trial.
    """
    import pandas as pd

    common = sorted(set(df_a.columns) & set(df_b.columns))
    names, per_scenario = _metric_plan(df_a, metrics)
    if metrics is None:  # the task's metrics that both runs recorded
        names = [n for n in names if METRICS[n][0] in common]
    metric_cols = {resolve_metric(name, common)[0] for name in names}
    cols = sorted(set(OUTCOME_COLUMNS) & set(common))
    merge_cols = sorted((set(cols) | metric_cols | {"converged"}
                         | ({"failure"} & set(common))) - set(KEY))
    merged = df_a[KEY + merge_cols].merge(df_b[KEY + merge_cols], on=KEY,
                                           suffixes=("_a", "_b"))
    if merged.empty:
        raise BenchmarkError(f"{name_a} and {name_b} share no trial (matched by scenario, "
                             "sweep point, controller and trial)")
    diffs = []
    for c in cols:
        x, y = merged[f"{c}_a"], merged[f"{c}_b"]
        if c in ("converged", "steps"):
            bad = ~((x == y) | (x.isna() & y.isna()))
        else:
            xf, yf = x.astype(float), y.astype(float)
            bad = ~(((xf - yf).abs() <= 1e-9 * (1 + xf.abs())) | (xf.isna() & yf.isna()))
        if bad.any():
            part = merged.loc[bad, KEY].copy()
            part["column"] = c
            part["a"] = x[bad].to_numpy()
            part["b"] = y[bad].to_numpy()
            diffs.append(part)
    different = (pd.concat(diffs, ignore_index=True) if diffs
                 else pd.DataFrame(columns=[*KEY, "column", "a", "b"]))
    sweeps = _sweep_text(df_a)
    out: list[Comparison] = []
    for name in names:
        column, unit, _ = resolve_metric(name, common)
        family: list[Comparison] = []
        for (scenario, point, ctrl), g in merged.groupby(["scenario", "point", "controller"],
                                                         sort=True):
            if name not in per_scenario.get(str(scenario), ()):
                continue
            xa = g[f"{column}_a"].to_numpy(dtype=float)
            xb = g[f"{column}_b"].to_numpy(dtype=float)
            if name != "converged":
                xa = np.where(failed_mask(g, "_a").to_numpy(), np.nan, xa)
                xb = np.where(failed_mask(g, "_b").to_numpy(), np.nan, xb)
            if name == "steps":
                xa = np.where(g["converged_a"].astype(bool), xa, np.nan)
                xb = np.where(g["converged_b"].astype(bool), xb, np.nan)
            family.append(_comparison(str(scenario), int(point),
                                      sweeps.get((str(scenario), int(point)), "-"),
                                      f"{name_b}:{ctrl}", f"{name_a}:{ctrl}", name, column,
                                      unit, xb, xa))
        _holm_and_verdicts(family, name)
        for comp in family:
            if comp.better is not None and comp.better == comp.b:
                comp.verdict = "REGRESSION: " + comp.verdict
        out += family
    return out, different, len(merged)
