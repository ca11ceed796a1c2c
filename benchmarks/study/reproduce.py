"""``hexapod-bench reproduce``: run the studies behind the papers' figures and set the
paper's number beside the framework's, with the framework's 95 % interval and a verdict.

Verdict rules (stated in docs/reproduction.md):

- ``equal``: *within* when the framework's 95 % interval (or, for a maximum, its
  value) meets the paper's number widened by half a unit of its last printed digit
  (the paper's "0.6 mm" is anything in [0.55, 0.65]); *outside (higher / lower)*
  otherwise, with the reason. A paper's figure read from one trial (one calibration)
  is set against the central 95 % of the framework's single trials instead of the
  interval of their median: that is the spread a single draw has.
- ``below``: *within* when the interval's upper end is below the paper's bound.
- ``better``: *within* when the paired test (Wilcoxon on the errors, McNemar on the
  convergence) finds the paper's winner better at 5 %, Holm-corrected over the paired
  figures of the table.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.study import exact, stats
from benchmarks.study.paper_figures import (
    FIGURES,
    RECORD_ALL,
    REPEATS,
    SEEDS,
    TAIL_FRACTION,
    TRIALS,
    Figure,
)

log = logging.getLogger(__name__)


@dataclass
class Result:
    """A paper's figure beside the framework's."""

    figure: Figure
    framework: str
    value: float | None
    interval: tuple[float, float] | None
    n: int
    verdict: str = ""
    p_value: float | None = None
    why: str = ""


def select(which: str) -> list[Figure]:
    """The figures of one seed, or of ``all``.

    Raises:
        BenchmarkError: Unknown seed name.
    """
    if which == "all":
        return list(FIGURES)
    if which not in SEEDS:
        raise BenchmarkError(f"reproduce {which!r}: expected one of {', '.join(SEEDS)}, all")
    return [f for f in FIGURES if f.seed == which]


def _study_dir(out: Path, study: str, quick: bool) -> Path:
    return out / (study.replace(":", "_") + ("-quick" if quick else ""))


def run_study(study: str, out: Path, quick: bool, workers: int,
              say: Callable[[str], None]) -> Path:
    """Run (or finish) one study into its directory under ``out``; returns the directory."""
    from benchmarks.study.scenario import load_scenario

    kind, _, rest = study.partition(":")
    name, _, variant = rest.partition(":")
    d = _study_dir(out, study, quick)
    if kind == "calibrate":
        from benchmarks.study.calibration import run_calibration

        if (d / "calibration.json").exists():
            say(f"{study}: reusing {d / 'calibration.json'}")
            return d
        repeat = REPEATS[1] if quick else REPEATS[0]
        sc = load_scenario(name)
        if variant == "omni":
            sc = replace(sc, camera_preset="omni", camera_file=None, name=f"{name}-omni")
        say(f"{study}: {repeat} calibrations per sweep point "
            f"(hexapod-bench calibrate {name} --repeat {repeat}"
            + (", omnidirectional camera" if variant else "") + ")")
        run_calibration(sc, d, repeat=repeat)
        return d
    from benchmarks.study.commands import auto_chunk
    from benchmarks.study.runner import completed_keys, plan, run_lock, run_units
    from benchmarks.study.study_record import (
        check_same_study,
        command_entry,
        record_command,
        study_of,
    )

    trials = TRIALS[name][1 if quick else 0]
    sc = load_scenario(name).with_overrides(trials=trials)
    with run_lock(d):
        done = completed_keys(d)
        record = trials if name in RECORD_ALL else 0
        units = plan([sc], auto_chunk([sc], workers, "sim"), record, done)
        todo = sum(len(u.trials) for u in units)
        say(f"{study}: {todo} trials to run, {len(done)} done "
            f"(hexapod-bench run {name} --trials {trials} --out {d} --workers {workers})")
        meta = json.loads((d / "run.json").read_text()) if (d / "run.json").is_file() else {}
        check_same_study(d, meta, [sc])
        record_command(meta, command_entry(
            ["run", name, "--trials", str(trials), "--out", str(d)],
            f"hexapod-bench reproduce: {len(done)} trials already done, {todo} to run"))
        meta["scenarios"] = {sc.name: {"description": sc.description,
                                       "reference": sc.reference, "source": sc.source,
                                       "study": study_of(sc)}}
        (d / "run.json").write_text(json.dumps(meta, indent=2))
        t0 = time.perf_counter()
        if units:
            run_units(units, d, workers)
        if todo:
            say(f"{study}: {todo} trials in {time.perf_counter() - t0:.1f} s")
    return d


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


def measure(fig: Figure, d: Path, frames: dict[Path, Any]) -> Result:
    """The framework's value of one figure from its study's results."""
    kind, _, column = fig.measure.partition(":")
    if fig.study.startswith("calibrate"):
        p = _calibration_point(d, fig)
        err = np.asarray(p["errors_mm"], float)  # repetitions x points
        if kind == "median_error":
            # the root of the median squared error is the median error
            lo, hi = exact.quantile_interval(err.ravel(), 0.5)
            v = float(np.sqrt(np.median(err.ravel() ** 2)))
            return Result(fig, f"{v:.3g} mm", v, (lo, hi), err.size)
        worst = int(np.argmax(np.median(err, axis=0)))
        lo, hi = exact.quantile_interval(err[:, worst], 0.5)
        v = float(np.median(err[:, worst]))
        return Result(fig, f"{v:.3g} mm (leg {worst})", v, (lo, hi), err.shape[0])
    if d not in frames:
        from benchmarks.study.table import load

        frames[d] = load(d)
    df = frames[d]
    rows = _rows(df, fig, fig.controller)
    if kind == "rate":
        k, n = int(rows["converged"].sum()), len(rows)
        lo, hi = stats.wilson_interval(k, n)
        return Result(fig, f"{100 * k / n:.1f} % ({k}/{n})", k / n, (lo, hi), n)
    if kind in ("median", "max", "tailmax"):
        if kind == "tailmax":
            x = _tail_max(d, rows, fig.controller)
        else:
            x = rows[column].to_numpy(dtype=float)
            x = x[np.isfinite(x)]
        if kind == "max":
            v = float(x.max())
            return Result(fig, f"{v:.3g} mm", v, None, x.size)
        v = float(np.median(x))
        if fig.single:  # one trial in the paper: the range of single trials
            lo, hi = (float(q) for q in np.percentile(x, [2.5, 97.5]))
        else:
            lo, hi = exact.quantile_interval(x, 0.5)
        return Result(fig, f"{v:.3g} mm", v, (lo, hi), x.size)
    # paired: controller against other on the same trials
    other = _rows(df, fig, fig.other).set_index("trial")
    mine = rows.set_index("trial")
    common = mine.index.intersection(other.index)
    a = mine.loc[common, column].to_numpy(dtype=float)
    b = other.loc[common, column].to_numpy(dtype=float)
    if column == "converged":
        res = stats.mcnemar_exact(a > 0.5, b > 0.5)
        text = (f"{fig.controller} {100 * a.mean():.0f} %, {fig.other} {100 * b.mean():.0f} % "
                f"converged (McNemar p = {exact.format_p(res.p_value)})")
        better = res.direction > 0
    else:
        res = stats.wilcoxon_signed_rank(a, b)
        text = (f"median {np.nanmedian(a):.3g} mm against {np.nanmedian(b):.3g} mm "
                f"(Wilcoxon p = {exact.format_p(res.p_value)})")
        better = res.direction < 0
    r = Result(fig, text, res.difference, (res.low, res.high), res.n, p_value=res.p_value)
    r.verdict = "better" if better else "worse"
    return r


def _tail_max(d: Path, rows: Any, controller: str) -> np.ndarray:
    """Largest position error [mm] over the convergence tail of each recorded trial."""
    out = []
    for _, r in rows.iterrows():
        f = (d / "trials" /
             f"{r['scenario']}__p{int(r['point'])}__{controller}__{int(r['trial']):05d}.npz")
        if not f.exists():
            raise BenchmarkError(f"{f}: missing; the tail statistics need every trial "
                                 "recorded (remove the directory to run it again)")
        with np.load(f) as rec:
            e = np.asarray(rec["position_error"], float) * 1e3
        out.append(float(e[len(e) - int(TAIL_FRACTION * len(e)):].max()))
    return np.asarray(out)


def _half_unit(text: str) -> float:
    """Half a unit of the last printed digit of a number in ``text`` (``"0.6 mm"``:
    0.05; ``"10 mm"``: 0.5; ``"1.2 cm"``: 0.05 cm, returned in the figure's unit)."""
    token = next((t for t in text.replace("<", " ").split() if t[0].isdigit()), "")
    decimals = len(token.split(".")[1]) if "." in token else 0
    scale = 10.0 if "cm" in text else 1.0
    return 0.5 * 10 ** (-decimals) * scale


def verdicts(results: list[Result]) -> None:
    """Fill every result's verdict (Holm over the paired figures)."""
    paired = [r for r in results if r.figure.relation == "better"]
    for r, p in zip(paired, stats.holm([r.p_value or 1.0 for r in paired]), strict=True):
        ok = r.verdict == "better" and p < 0.05
        r.verdict = (f"within (Holm p = {exact.format_p(p)})" if ok else
                     f"outside (not found better at 5 %, Holm p = {exact.format_p(p)})")
        if not ok:
            r.why = r.figure.why_outside
    for r in results:
        f = r.figure
        if f.relation == "better" or r.value is None or f.value is None:
            continue
        lo, hi = r.interval if r.interval else (r.value, r.value)
        if f.relation == "below":
            ok = hi < f.value
            side = "higher"
        else:
            h = _half_unit(f.paper) if f.paper[0].isdigit() else 0.0
            if f.measure.startswith("rate"):
                h = 0.005 if f.paper.endswith("%") else 0.0
            ok = lo <= f.value + h and hi >= f.value - h
            side = "higher" if lo > f.value + h else "lower"
        r.verdict = "within" if ok else f"outside ({side})"
        if not ok:
            r.why = f.why_outside


def reproduce(which: str, out: Path, quick: bool = False, workers: int = 1,
              say: Callable[[str], None] = print) -> list[Result]:
    """Run the studies behind the figures of ``which`` and measure them."""
    figs = select(which)
    dirs: dict[str, Path] = {}
    for study in dict.fromkeys(f.study for f in figs):
        dirs[study] = run_study(study, out, quick, workers, say)
    frames: dict[Path, Any] = {}
    results = [measure(f, dirs[f.study], frames) for f in figs]
    verdicts(results)
    return results


def interval_text(r: Result) -> str:
    """The framework's interval as text (``-`` for none)."""
    if r.interval is None:
        return "- (a maximum)"
    lo, hi = r.interval
    if r.figure.measure.startswith("rate"):
        return f"[{stats.percent_bound(lo)}, {stats.percent_bound(hi)}] %"
    if r.figure.measure.startswith("paired:converged"):
        return f"difference [{100 * lo:+.0f}, {100 * hi:+.0f}] points"
    if r.figure.relation == "better":
        return f"paired difference [{lo:+.3g}, {hi:+.3g}] mm"
    if r.figure.single:
        return f"[{lo:.3g}, {hi:.3g}] mm (95 % of single trials)"
    return f"[{lo:.3g}, {hi:.3g}] mm"


def markdown(results: list[Result]) -> str:
    """The table of ``docs/reproduction.md``."""
    head = ["paper", "where", "quantity", "paper's figure", "framework", "95 % interval",
            "n", "verdict", "why (when outside)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        f = r.figure
        lines.append("| " + " | ".join([f.seed, f.where, f.quantity, f.paper, r.framework,
                                        interval_text(r), str(r.n), r.verdict,
                                        r.why or "-"]) + " |")
    return "\n".join(lines)
