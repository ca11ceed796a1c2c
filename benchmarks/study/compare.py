"""Paired comparisons of controllers: within one run, or between two runs of a scenario.

Every controller of a run meets the same trials (same worlds, same draws), so the
comparison of two controllers is paired: trial ``k`` of one against trial ``k`` of the
other at the same sweep point. Convergence is compared by McNemar's exact test with
Newcombe's paired interval of the rate difference, the continuous metrics (final
errors, tracking) by Wilcoxon's signed-rank test with the median paired difference and
its order-statistic interval, the steps to converge as censored data (a trial that did
not converge is censored at the run's length) by the sign test on the pairs whose order
is known. Holm's correction runs over all the comparisons of one metric (every pair at
every sweep point): a difference is called significant when its Holm-adjusted p-value
is below :data:`ALPHA`. "No difference" is never concluded from a test that found
none: two controllers are *equivalent within M* only when the two one-sided tests
(TOST, on the paired differences; :data:`MARGINS` per metric, Holm-corrected over the
metric's comparisons too) reject a difference of M or more; otherwise they are *not
shown equivalent*.

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
from benchmarks.study import exact, stats
from benchmarks.study.verdicts import (
    ALPHA,
    MARGINS,
    holm_and_verdicts,
    margin_text,
    resolve_margins,
)
from hexapod.outputs import json_signed

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ALPHA", "MARGINS", "Comparison", "compare_controllers", "compare_runs",
           "margin_text", "resolve_margins"]

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
#: Metrics compared as censored data (a trial that did not converge or settle is known
#: only to exceed the run): steps to converge, settling time.
CENSORED = ("steps", "settling")
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
        test: ``mcnemar-exact``, ``wilcoxon`` or ``sign-censored`` (steps).
        n: Pairs used.
        statistic: The test's statistic.
        p_value: Two-sided p-value.
        p_holm: Holm-adjusted p-value over the comparisons of the metric.
        difference: Rate difference (converged) or median paired difference (steps:
            ``+-inf`` for a pair where only one converged).
        interval: Its 95 % interval (Newcombe's; order statistics).
        a_value: ``a``'s rate or median over the pairs.
        b_value: ``b``'s rate or median over the pairs.
        better: ``a``, ``b`` or None (not significant).
        verdict: The result in plain words.
        margin: The equivalence margin (the metric's unit; None: no margin known).
        p_equivalence: TOST p-value (nan without a margin).
        p_equivalence_holm: Its Holm-adjusted value over the metric's comparisons.
        outcome: ``different``, ``unclear`` (the test significant, the difference's
            interval not on its side: not shown better), ``equivalent`` (within the
            margin, not different) or ``not shown equivalent``.
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
    margin: float | None = None
    p_equivalence: float = float("nan")
    p_equivalence_holm: float = float("nan")
    outcome: str = ""
    unit: str = field(default="", repr=False)

    def to_json(self) -> dict[str, Any]:
        """A JSON object: NaN as null; an infinite value (a censored median, an
        interval's end outside the sample) as the string ``"inf"`` or ``"-inf"``, which
        keeps its sign (JSON has no infinity; ``float(s)`` reads it back)."""
        d = asdict(self)
        d["interval"] = list(self.interval)
        d["discordant"] = list(self.discordant) if self.discordant else None
        return {k: json_signed(v) for k, v in d.items()}


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


def censor_steps(steps: np.ndarray, converged: np.ndarray) -> np.ndarray:
    """Steps to converge, ``+inf`` for a trial that did not (a failed trial included:
    it counts as not converged), so that only its order is used."""
    return np.where(np.asarray(converged, dtype=bool), np.asarray(steps, dtype=float), np.inf)


def _values(frame: pd.DataFrame, column: str, metric: str) -> pd.DataFrame:
    """Trials x controllers of one (scenario, point); steps censored (``+inf``) where
    not converged; a failed trial (:func:`failed_mask`) has no value but its
    convergence (a failure) and its censored steps."""
    sub = frame[["trial", "controller", column]].copy()
    if metric == "steps":
        sub[column] = censor_steps(sub[column].to_numpy(dtype=float),
                                   frame["converged"].fillna(False).to_numpy(dtype=bool))
    elif metric == "settling":  # not settled, or failed: censored at the run's end
        settled = sub[column].notna().to_numpy() & ~failed_mask(frame).to_numpy()
        sub[column] = censor_steps(sub[column].to_numpy(dtype=float), settled)
    elif metric != "converged":
        sub[column] = sub[column].where(~failed_mask(frame))
    return sub.pivot(index="trial", columns="controller", values=column)


def censored_sign_test(x: np.ndarray, y: np.ndarray) -> stats.TestResult:
    """Paired steps to converge with censoring (``+inf``: did not converge): the exact
    sign test on the pairs whose order is known (both converged, or one did: it was the
    faster), the pairs where neither converged left out; the median of the paired
    differences (``+-inf`` where one did not converge) with its order-statistic
    interval."""
    ok = ~(np.isnan(x) | np.isnan(y))
    with np.errstate(invalid="ignore"):  # inf - inf: nan
        d = x[ok] - y[ok]
    d = d[~np.isnan(d)]  # neither converged: the order is unknown
    pos, neg, p = exact.sign_test(d)
    if d.size == 0:
        return stats.TestResult("sign-censored", 0, 0.0, 1.0, float("nan"), float("nan"),
                                float("nan"), (0, 0), 0)
    low, high = exact.quantile_interval(d, 0.5)
    med = exact.censored_quantile(d, 0.5)  # -inf and +inf in the middle: unknown, nan
    return stats.TestResult("sign-censored", int(d.size), float(pos), p, med, low, high,
                            (pos, neg),
                            int(np.sign(pos - neg)))


def _test(x: np.ndarray, y: np.ndarray, metric: str) -> stats.TestResult:
    if metric == "converged":
        ok = ~(np.isnan(x) | np.isnan(y))
        return stats.mcnemar_exact(x[ok] > 0.5, y[ok] > 0.5)
    if metric in CENSORED:
        return censored_sign_test(x, y)
    return stats.wilcoxon_signed_rank(x, y)


def _equivalence(x: np.ndarray, y: np.ndarray, metric: str, margin: float | None) -> float:
    """TOST p-value of the pairs within ``margin`` (nan without a margin)."""
    if margin is None:
        return float("nan")
    ok = ~(np.isnan(x) | np.isnan(y))
    if metric == "converged":
        a, b = x[ok] > 0.5, y[ok] > 0.5
        return exact.tost_rate(int(np.sum(a & b)), int(np.sum(a & ~b)), int(np.sum(~a & b)),
                               int(np.sum(~a & ~b)), margin)
    with np.errstate(invalid="ignore"):  # neither converged (inf - inf): nan, left out
        d = x[ok] - y[ok]
    return exact.tost_paired(d, margin)


def _summary_value(x: np.ndarray, y: np.ndarray, metric: str) -> tuple[float, float]:
    ok = ~(np.isnan(x) | np.isnan(y))
    if metric not in CENSORED:
        ok &= np.isfinite(x) & np.isfinite(y)
    if not ok.any():
        return float("nan"), float("nan")
    if metric == "converged":
        return float(np.mean(x[ok])), float(np.mean(y[ok]))
    return exact.censored_quantile(x[ok], 0.5), exact.censored_quantile(y[ok], 0.5)


def _comparison(scenario: str, point: int, sweep: str, a: str, b: str, metric: str,
                column: str, unit: str, x: np.ndarray, y: np.ndarray,
                margin: float | None = None) -> Comparison:
    res = _test(x, y, metric)
    av, bv = _summary_value(x, y, metric)
    return Comparison(scenario, point, sweep, a, b, metric, column, res.test, res.n,
                      res.statistic, res.p_value, float("nan"), res.difference,
                      (res.low, res.high), av, bv, unit=unit, direction=res.direction,
                      discordant=res.discordant, margin=margin,
                      p_equivalence=_equivalence(x, y, metric, margin))


def _metric_plan(df: pd.DataFrame, metrics: tuple[str, ...] | None
                 ) -> tuple[list[str], dict[str, tuple[str, ...]]]:
    """The metrics to compare, and those of each scenario (its task's defaults when
    ``metrics`` is None, else ``metrics`` everywhere)."""
    if metrics is not None:
        return list(metrics), {str(s): metrics for s in df["scenario"].unique()}
    per = default_metrics(df)
    return list(dict.fromkeys(m for ms in per.values() for m in ms)), per


def compare_controllers(df: pd.DataFrame, baseline: str | None = None,
                        metrics: tuple[str, ...] | None = None,
                        margins: dict[str, float] | None = None) -> list[Comparison]:
    """Every pair of controllers of a run (or each against ``baseline``), at every sweep
    point, on the trials both ran (the failed trials left out of every metric but
    ``converged``).

    Args:
        df: From :func:`benchmarks.study.load`.
        baseline: Compare every other controller against this one only.
        metrics: Metric names (:data:`METRICS`) or numeric columns; None: each
            scenario's task's (:func:`task_metrics`).
        margins: Equivalence margins by metric name, over :data:`MARGINS`.

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
    margin_of = resolve_margins(margins, names)
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
                                          column, unit, x, y, margin_of.get(name)))
        holm_and_verdicts(family, name, METRICS.get(name, ('', '', False))[2])
        out += family
    return out


def goal_settings(df: pd.DataFrame) -> str:
    """The goal settings of a run's rows (``[task] goal``, :mod:`benchmarks.sim.goal`), as
    ``"taught"`` or ``"mixed, taught"`` (a run of several scenarios or a swept setting);
    ``"mixed"`` for rows written before the setting existed."""
    if "goal" not in df:
        return "mixed"
    return ", ".join(sorted(str(g) for g in df["goal"].fillna("mixed").unique()))


def goal_mismatches(df_a: pd.DataFrame, df_b: pd.DataFrame) -> list[str]:
    """The scenarios and sweep points whose goal setting differs between two runs, one
    line each (``"quick point 0: A mixed, B taught"``): their differences include what
    the controllers were told of the goal, not only the controllers' behaviour."""
    def per_point(df: pd.DataFrame) -> dict[tuple[str, int], str]:
        goals = df["goal"].fillna("mixed") if "goal" in df else None
        out: dict[tuple[str, int], str] = {}
        for (scenario, point), idx in df.groupby(["scenario", "point"]).groups.items():
            out[(str(scenario), int(point))] = (
                "mixed" if goals is None else ", ".join(sorted(map(str, goals[idx].unique()))))
        return out

    a, b = per_point(df_a), per_point(df_b)
    return [f"{s} point {p}: A {a[(s, p)]}, B {b[(s, p)]}" for s, p in sorted(a.keys() & b.keys())
            if a[(s, p)] != b[(s, p)]]


def match_counts(df_a: pd.DataFrame, df_b: pd.DataFrame) -> tuple[int, int, int]:
    """Trials of two runs matched by (scenario, sweep point, controller, trial).

    Returns:
        ``(matched, only in A, only in B)``.
    """
    a = set(map(tuple, df_a[KEY].astype(str).to_numpy().tolist()))
    b = set(map(tuple, df_b[KEY].astype(str).to_numpy().tolist()))
    return len(a & b), len(a - b), len(b - a)


def compare_runs(df_a: pd.DataFrame, df_b: pd.DataFrame, name_a: str = "A",
                 name_b: str = "B", metrics: tuple[str, ...] | None = None,
                 margins: dict[str, float] | None = None
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
    margin_of = resolve_margins(margins, names)
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
            if name == "steps":
                xa = censor_steps(xa, g["converged_a"].fillna(False).to_numpy(dtype=bool))
                xb = censor_steps(xb, g["converged_b"].fillna(False).to_numpy(dtype=bool))
            elif name == "settling":
                xa = censor_steps(xa, np.isfinite(xa) & ~failed_mask(g, "_a").to_numpy())
                xb = censor_steps(xb, np.isfinite(xb) & ~failed_mask(g, "_b").to_numpy())
            elif name != "converged":
                xa = np.where(failed_mask(g, "_a").to_numpy(), np.nan, xa)
                xb = np.where(failed_mask(g, "_b").to_numpy(), np.nan, xb)
            family.append(_comparison(str(scenario), int(point),
                                      sweeps.get((str(scenario), int(point)), "-"),
                                      f"{name_b}:{ctrl}", f"{name_a}:{ctrl}", name, column,
                                      unit, xb, xa, margin_of.get(name)))
        holm_and_verdicts(family, name, METRICS.get(name, ('', '', False))[2])
        for comp in family:
            if comp.better is not None and comp.better == comp.b:
                comp.verdict = "REGRESSION: " + comp.verdict
        out += family
    return out, different, len(merged)
