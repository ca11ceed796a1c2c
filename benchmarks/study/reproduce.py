"""``hexapod-bench reproduce``: run the studies behind the papers' figures and set each
declared figure (:mod:`benchmarks.study.paper_figures`) beside the framework's value,
its 95 % interval and a verdict.

The scorecard's rules (stated in docs/reproduction.md, "The scorecard"), one for every
row whether the paper's figure is one trial or many:

- ``equal``: the framework's 95 % interval of its statistic (the distribution-free
  interval of the median over its trials; Wilson's for a rate) meets the paper's number
  widened by the row's declared tolerance.
- ``below``: the interval's upper end is below the paper's bound.
- A row with ``other`` (a claim about two controllers) holds when both rates meet theirs.

A *number* that misses is *outside (higher / lower)*; a *claim* that misses is
*contradicts*; a row whose statistic has no value (no finite trial) is *not comparable*.
A study whose task is one fixed start and goal gives repetitions of ONE task: the
scorecard says so and its rates are the task's repeatability, not a rate over tasks.
"""

from __future__ import annotations

import json
import logging
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.study import exact, stats
from benchmarks.study.paper_figures import (
    SEEDS,
    TAIL_FRACTION,
    Figure,
    builtin_figures,
)
from benchmarks.study.reproduce_runs import Transform, check_studies, run_study
from vision.exceptions import CalibrationError

log = logging.getLogger(__name__)

#: Verdict categories, in the order the summary counts them.
CATEGORIES = ("within", "outside", "contradicts", "not comparable")
#: Tail lengths [periods] at which the median tail maximum is also printed (seed 001).
TAIL_LENGTHS = (25, 50, 100)



@dataclass
class Result:
    """A paper's figure beside the framework's.

    Attributes:
        figure: The declared row.
        framework: The framework's value as text.
        value: The statistic (mm, or a fraction for a rate); None: no value.
        interval: Its 95 % interval.
        n: Trials (calibrations) behind it.
        other_interval: The 95 % interval of ``figure.other``'s rate.
        note: What else the row computes (one task repeated, the tail maximum against
            the tail length, where the paper's number falls among single trials).
        verdict: ``within``, ``outside (higher|lower)``, ``contradicts``,
            ``not comparable (...)``.
        why: The declared reason, when not within.
    """

    figure: Figure
    framework: str
    value: float | None
    interval: tuple[float, float] | None
    n: int
    other_interval: tuple[float, float] | None = None
    note: str = ""
    verdict: str = ""
    why: str = ""

    @property
    def category(self) -> str:
        """The verdict's category (:data:`CATEGORIES`)."""
        return next(c for c in CATEGORIES if self.verdict.startswith(c))


def select(which: str, figures: list[Figure] | None = None) -> list[Figure]:
    """The figures of one seed, or of ``all``.

    Raises:
        BenchmarkError: Unknown seed name.
    """
    figs = list(builtin_figures()) if figures is None else figures
    if which == "all":
        return figs
    if which not in SEEDS:
        raise BenchmarkError(f"reproduce {which!r}: expected one of {', '.join(SEEDS)}, all")
    return [f for f in figs if f.seed == which]


def _rows(df: Any, fig: Figure, controller: str) -> Any:
    sel = df[df["controller"] == controller]
    for k, v in fig.sweep.items():
        sel = sel[np.isclose(sel[k].astype(float), float(v))]
    if sel.empty:
        raise BenchmarkError(f"{fig.study}: no trial of {controller!r} at {fig.sweep}")
    return sel


def _calibration_point(d: Path, fig: Figure) -> dict[str, Any]:
    doc = json.loads((d / "calibration.json").read_text())
    for p in doc["points"]:
        sweep = {k.replace(".", "_"): v for k, v in p["sweep"].items()}
        if all(np.isclose(float(sweep.get(k, np.nan)), float(v)) for k, v in fig.sweep.items()):
            return dict(p)
    raise BenchmarkError(f"{d / 'calibration.json'}: no sweep point {fig.sweep}")


def _one_task(d: Path) -> bool:
    """Whether a run directory's study is one fixed start and goal (repetitions of one task)."""
    from benchmarks.study.run_facts import fixed_task_scenarios, run_meta

    return bool(fixed_task_scenarios(run_meta(d)))


def _median_result(fig: Figure, x: np.ndarray, unit_text: str = "") -> Result:
    """The median of per-trial values with its order-statistic interval; for a paper's
    one-trial figure, also where the paper's number falls among the single trials."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        return Result(fig, "no finite value", None, None, 0)
    v = float(np.median(x))
    lo, hi = exact.quantile_interval(x, 0.5)
    note = ""
    if fig.paper_trials == 1:
        pct = 100.0 * float(np.mean(x <= fig.value * fig.scale))
        note = (f"{pct:.0f} % of the framework's {x.size} single trials are at or below "
                f"the paper's one-trial {fig.paper}")
    return Result(fig, f"{v:.3g} mm{unit_text}", v, (lo, hi), x.size, note=note)


def _worst_point(fig: Figure, err: np.ndarray) -> Result:
    """The largest of the points' median errors (calibrations x points ``err``) with an
    interval that holds whichever point is the worst: each point's median interval at
    95 % / points (Bonferroni), their largest ends (the worst point is chosen after
    seeing the data: its own 95 % interval would say more than they do)."""
    m = err.shape[1]
    meds = np.median(err, axis=0)
    worst = int(np.argmax(meds))
    ends = np.array([exact.quantile_interval(err[:, k], 0.5, 1 - (1 - stats.LEVEL) / m)
                     for k in range(m)])
    r = _median_result(fig, err[:, worst], f" (leg {worst})")
    r.value = float(meds[worst])
    r.interval = (float(ends[:, 0].max()), float(ends[:, 1].max()))
    r.note = "; ".join(x for x in (r.note, (
        f"the worst of {m} points, chosen after the run: the interval holds the largest of "
        f"the {m} medians (each point's at {100 - 100 * (1 - stats.LEVEL) / m:.2f} %, "
        "Bonferroni)")) if x)
    return r


def measure(fig: Figure, d: Path, frames: dict[Path, Any]) -> Result:
    """The framework's value of one figure from its study's results."""
    if fig.statistic.startswith("calibration"):
        p = _calibration_point(d, fig)
        err = np.asarray(p["errors_mm"], float)  # repetitions x points
        if fig.statistic == "calibration_rms_median":
            # a calibration's figure, as the paper's one: the root of the median squared
            # error of its points (their median error); the median over calibrations
            per = np.sqrt(np.median(err ** 2, axis=1))
            r = _median_result(fig, per)
            r.note = "; ".join(x for x in (r.note, f"{err.shape[0]} calibrations of "
                                           f"{err.shape[1]} points each") if x)
            return r
        return _worst_point(fig, err)
    if d not in frames:
        from benchmarks.study.table import load

        frames[d] = load(d)
    df = frames[d]
    rows = _rows(df, fig, fig.controller)
    from benchmarks.study.failures import is_failure

    failures = [str(f) for f in rows.get("failure", []) if is_failure({"failure": f})]
    if fig.statistic != "rate" and len(rows) and len(failures) == len(rows):
        # (each trial's own calibration refused, at a sensitivity point: a missing column
        # or record ended the study; a rate's figure stays, 0 of n converged)
        return Result(fig, f"every trial failed ({failures[0]})", None, None, 0)
    one_task = _one_task(d)
    if fig.statistic == "rate":
        k, n = int(rows["converged"].sum()), len(rows)
        text = f"{fig.controller} {k}/{n}"
        r = Result(fig, text, k / n, stats.wilson_interval(k, n), n)
        if fig.other:
            o = _rows(df, fig, fig.other)
            ko, no = int(o["converged"].sum()), len(o)
            r.other_interval = stats.wilson_interval(ko, no)
            r.framework = f"{text}, {fig.other} {ko}/{no} converged"
        else:
            r.framework = f"{text} converged ({100 * k / n:.1f} %)"
        if one_task:
            r.note = (f"one task (a fixed start and goal) repeated {n} times with new noise "
                      "and calibration-error draws: the rate is this task's repeatability, "
                      "not a rate over tasks")
        if fig.paper_trials == 1 and r.interval is not None:
            lo, hi = r.interval
            r.note = "; ".join(x for x in (r.note, (
                f"the paper's figure is one run: a single run of the framework converges "
                f"with a probability in [{stats.percent_bound(lo)}, "
                f"{stats.percent_bound(hi)}] %, so one converging run "
                f"{'is not unusual for it' if hi >= 0.05 else 'would be unusual for it'}, "
                "whatever the verdict on the rate")) if x)
        return r
    if fig.statistic == "median_tail_max":
        tails = _tail_maxima(d, rows, fig.controller)
        r = _median_result(fig, tails[:, -2])
        med = np.median(tails[:, :-1], axis=0)
        ratio = float(np.median(tails[:, -2] / tails[:, -1]))
        r.note = "; ".join(x for x in (r.note, "median tail maximum over the last " + ", ".join(
            f"{k} periods {m:.3g} mm" for k, m in zip(TAIL_LENGTHS, med, strict=True))
            + f" ({med[-1] / med[0]:.2f}x over a {TAIL_LENGTHS[-1] // TAIL_LENGTHS[0]}x "
            f"longer tail); a trial's tail maximum is {ratio:.2g}x its tail median "
            "(median over trials)") if x)
        return r
    r = _median_result(fig, rows[fig.column].to_numpy(dtype=float))
    if fig.column.startswith("calibration_") and "calibration_min_singular_ratio" in rows:
        ratio = rows["calibration_min_singular_ratio"].to_numpy(dtype=float)
        ratio = ratio[np.isfinite(ratio) & (ratio > 0)]
        if ratio.size:
            m = float(np.median(ratio))
            r.note = "; ".join(x for x in (r.note, (
                f"smallest to largest singular value of a leg's calibration system {m:.2g} "
                f"(median over calibrations): the noise is amplified about {1 / m:.0f} "
                "times along its worst direction")) if x)
    return r


def _tail_maxima(d: Path, rows: Any, controller: str) -> np.ndarray:
    """Largest position error [mm] over the last :data:`TAIL_LENGTHS` periods of each
    recorded trial (the last length is the tail the report reads), then the median
    error over that tail: trials x (lengths + 1)."""
    out = []
    for _, r in rows.iterrows():
        f = (d / "trials" /
             f"{r['scenario']}__p{int(r['point'])}__{controller}__{int(r['trial']):05d}.npz")
        if not f.exists():
            raise BenchmarkError(f"{f}: missing; the tail statistics need every trial "
                                 "recorded (remove the directory to run it again)")
        with np.load(f) as rec:
            e = np.asarray(rec["position_error"], float) * 1e3
        tail = int(TAIL_FRACTION * len(e))
        lengths = [min(k, tail) for k in TAIL_LENGTHS[:-1]] + [tail]
        out.append([float(e[len(e) - k:].max()) for k in lengths]
                   + [float(np.median(e[len(e) - tail:]))])
    return np.asarray(out)


def judge(fig: Figure, value: float | None, interval: tuple[float, float] | None,
          other_interval: tuple[float, float] | None = None) -> str:
    """The verdict of one row: the same rule whether the paper's figure is one trial or
    many (module docstring)."""
    if value is None or interval is None:
        return "not comparable (no finite value)"
    lo, hi = interval
    if not (math.isfinite(lo) or math.isfinite(hi)) or (
            fig.rule == "equal" and not (math.isfinite(lo) and math.isfinite(hi))):
        return ("not comparable (too few trials for its interval, 95 % or wider after a "
                "Bonferroni correction: "
                f"{'an end' if math.isfinite(lo) or math.isfinite(hi) else 'both ends'} "
                "beyond the sample)")
    if fig.rule == "below":
        ok = hi < fig.value * fig.scale
        side = "higher" if lo >= fig.value * fig.scale else "not shown below: the interval " \
            "holds the bound"
    else:
        t_lo, t_hi = fig.target()
        ok = lo <= t_hi and hi >= t_lo
        side = "higher" if lo > t_hi else "lower"
        if fig.other_value is not None:
            if other_interval is None:
                return "not comparable (no value of the other controller)"
            o_lo, o_hi = fig.target(fig.other_value)
            ok = ok and other_interval[0] <= o_hi and other_interval[1] >= o_lo
    if ok:
        return "within"
    return "contradicts" if fig.kind == "claim" else f"outside ({side})"


def verdicts(results: list[Result]) -> None:
    """Fill every result's verdict and, when not within, its declared reason."""
    for r in results:
        r.verdict = judge(r.figure, r.value, r.interval, r.other_interval)
        r.why = "" if r.verdict == "within" else r.figure.why_outside


def summary(results: list[Result]) -> str:
    """The summary line: rows counted by verdict, the papers' figures and their variants
    apart, with the rule."""
    def counts(rs: list[Result]) -> str:
        c = Counter(r.category for r in rs)
        return ", ".join(f"{c[k]} {k}" for k in CATEGORIES)

    own = [r for r in results if not r.figure.variant_of]
    var = [r for r in results if r.figure.variant_of]
    text = f"{len(own)} paper figures (one row each): {counts(own)}"
    if var:
        text += f"; {len(var)} variants (a figure under another setting): {counts(var)}"
    return (text + ". Rule: within when the framework's 95 % interval (of its median "
            "over trials, or Wilson's for a rate) meets the paper's number +- the declared "
            "tolerance (or lies below a bound), for one-trial and many-trial figures alike")


def reproduce(which: str, out: Path, quick: bool = False, workers: int = 1,
              say: Callable[[str], None] = print, figures: list[Figure] | None = None,
              transform: Transform | None = None, trials: int | None = None
              ) -> list[Result]:
    """Run the studies behind the figures of ``which`` and measure them.

    Args:
        which: A seed or ``all``.
        out: Directory of the studies.
        quick: Fewer trials.
        workers: Worker processes.
        say: Progress lines.
        figures: The declared figures (default: the built-in file).
        transform: Applied to every study's scenario (:func:`run_study`).
        trials: Trials of every study instead of the declared counts.
    """
    figs = select(which, figures)
    dirs: dict[str, Path] = {}
    studies = list(dict.fromkeys(f.study for f in figs))
    check_studies(studies, out, quick, transform, trials)  # before any study runs
    refused: dict[str, str] = {}
    for study in studies:
        try:
            dirs[study] = run_study(study, out, quick, workers, say, transform, trials)
        except CalibrationError as exc:  # this setup cannot calibrate: its rows cannot be
            # compared, the others still can (one point of a sensitivity grid, a leg the
            # camera sees too poorly, ended a 54-point study after 11 minutes)
            refused[study] = f"the calibration was refused: {exc}"
            say(f"{study}: {refused[study]}")
    frames: dict[Path, Any] = {}
    results = [Result(f, refused[f.study], None, None, 0) if f.study in refused
               else measure(f, dirs[f.study], frames) for f in figs]
    tail_ratios(results)
    verdicts(results)
    for r in results:
        if r.figure.study in refused:
            r.verdict = f"not comparable ({refused[r.figure.study]})"
    return results


def tail_ratios(results: list[Result]) -> None:
    """Add to each tail-maximum row the ratio of the paper's tail maximum to its tail
    median at the same setting (the rows of the same study, controller and sweep point),
    beside the framework's ratio already in its note."""
    medians = {(r.figure.study, r.figure.controller, tuple(sorted(r.figure.sweep.items()))): r
               for r in results if r.figure.column == "tail_position_error_mm"}
    for r in results:
        f = r.figure
        m = medians.get((f.study, f.controller, tuple(sorted(f.sweep.items()))))
        if f.statistic != "median_tail_max" or m is None:
            continue
        mf = m.figure
        lo = (f.value - f.tolerance) / (mf.value + mf.tolerance)
        hi = (f.value + f.tolerance) / max(mf.value - mf.tolerance, 1e-12)
        r.note += (f"; the paper's tail maximum is {f.value / mf.value:.2g}x its tail median "
                   f"({f.paper} / {mf.paper}; {lo:.2g}x to {hi:.2g}x as printed)")


def interval_text(r: Result) -> str:
    """The framework's interval as text (``-`` for none)."""
    if r.interval is None:
        return "-"
    lo, hi = r.interval
    if r.figure.statistic == "rate":
        text = f"[{stats.percent_bound(lo)}, {stats.percent_bound(hi)}] %"
        if r.other_interval is not None:
            olo, ohi = r.other_interval
            text += f"; [{stats.percent_bound(olo)}, {stats.percent_bound(ohi)}] %"
        return text
    return f"[{lo:.3g}, {hi:.3g}] mm"


def target_text(f: Figure) -> str:
    """The paper's figure and what the rule sets against it."""
    if f.rule == "below":
        return f"{f.paper} (below {f.value:g} {f.unit})"
    lo, hi = f.value - f.tolerance, f.value + f.tolerance
    if f.unit == "%":  # a rate's range stays in [0, 100] %
        lo, hi = max(lo, 0.0), min(hi, 100.0)
    text = f"{f.paper} ([{lo:g}, {hi:g}] {f.unit}"
    if f.other_value is not None:
        top = f.other_value + f.tolerance
        text += f"; {f.other}: [{max(f.other_value - f.tolerance, 0):g}, " \
                f"{min(top, 100.0) if f.unit == '%' else top:g}] {f.unit}"
    return text + ", one trial)" if f.paper_trials == 1 else text + ")"


def markdown(results: list[Result]) -> str:
    """The scorecard as a Markdown table."""
    head = ["id", "paper", "where", "quantity", "paper's figure (rule's range)", "framework",
            "95 % interval", "n", "verdict", "note", "why (when not within)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        f = r.figure
        ident = f.id + (f" (variant of {f.variant_of})" if f.variant_of else "")
        lines.append("| " + " | ".join([ident, f.seed, f.where, f.quantity, target_text(f),
                                        r.framework, interval_text(r), str(r.n), r.verdict,
                                        r.note or "-", r.why or "-"]) + " |")
    return "\n".join(lines)
