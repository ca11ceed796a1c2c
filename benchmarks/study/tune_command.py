"""``hexapod-bench tune SCENARIO --controllers A,B --out DIR``: matched tuning
(``docs/tuning.md``).

Every controller goes through the same procedure: its candidates (the options as given,
then points of its declared search space, :mod:`benchmarks.study.tuning_space`) run on
TUNING trials, the same ones for every candidate and controller, whose seed is the
study's plus :data:`SEED_OFFSET` (or ``--seed``, refused when equal to the study's): no
trial of the study is used to tune. The candidate with the lowest criterion is chosen
only if it is shown better than the options as given on the tuning trials (a one-sided
exact sign test on the paired trials, Bonferroni over the searched candidates: the best
of several noisy scores is biased low); otherwise the options as given are kept, and
the output says so. Every controller has the same budget (candidates x trials x sweep
points); one without a search space runs its options as given alone, and is named. The
candidates run as one study in ``DIR/candidates``
(a run directory: resumable with ``--resume``, its report beside), and the choice is
written to ``DIR/tuned.toml`` (the options file ``run --options-file`` takes) and every
candidate's score to ``DIR/tuning.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError, ScenarioError
from benchmarks.study.options_file import controller_options
from benchmarks.study.outdir import add_command

#: The tuning seed is the study's plus this, unless ``--seed`` is given.
SEED_OFFSET = 1_000_003
#: The run directory of the candidates, inside ``--out``.
CANDIDATES_DIR = "candidates"
TUNED_FILE = "tuned.toml"
SCORES_FILE = "tuning.json"
#: Criteria: (row field, statistic over every tuning trial of every sweep point).
CRITERIA: dict[str, tuple[str, str]] = {
    "median-final": ("final_position_error_mm", "median"),
    "mean-final": ("final_position_error_mm", "mean"),
    "p90-final": ("final_position_error_mm", "p90"),
    "median-tracking-rms": ("tracking_rms_position_mm", "median"),
    "mean-tracking-rms": ("tracking_rms_position_mm", "mean"),
    "p90-tracking-rms": ("tracking_rms_position_mm", "p90"),
}


def add_arguments(s: argparse.ArgumentParser) -> None:
    """The arguments of ``hexapod-bench tune``."""
    s.add_argument("scenario", metavar="SCENARIO", help="a built-in scenario name or a TOML path")
    s.add_argument("--controllers", required=True,
                   help="comma-separated controllers: the scenario's by their labels, or "
                        "any registered controller by its name")
    from benchmarks.study.outdir import OutputDir

    s.add_argument("--out", required=True, action=OutputDir,
                   help="output directory (candidates/: the candidates' run; tuned.toml; "
                        "tuning.json)")
    s.add_argument("--trials", type=int, default=10,
                   help="tuning trials per candidate and sweep point (default 10)")
    s.add_argument("--candidates", type=int, default=6,
                   help="candidates per controller, the options as given included (default 6)")
    s.add_argument("--seed", type=int, help="tuning seed (default: the study's + "
                                           f"{SEED_OFFSET}; the study's own is refused)")
    s.add_argument("--criterion", choices=sorted(CRITERIA),
                   help="what is minimised (default: median-tracking-rms for a trajectory "
                        "task, else median-final); a failed trial counts as the worst")
    s.add_argument("--space", metavar="FILE", help="a search space TOML replacing the "
                                                   "declared one (docs/tuning.md)")
    s.add_argument("--max-steps", type=int, help="override the step budget of each trial")
    s.add_argument("--goal", choices=("mixed", "taught", "cartesian"),
                   help="the goal setting of the tuning trials (default: the scenario's; "
                        "recorded in tuned.toml: a run under another setting is warned)")
    s.add_argument("--workers", type=int, default=1, help="processes (default 1)")
    s.add_argument("--resume", action="store_true", help="finish an interrupted tuning")
    s.add_argument("--overwrite", action="store_true",
                   help="replace DIR/tuned.toml and DIR/tuning.json")
    s.add_argument("--no-progress", action="store_true", help="no progress bar")


@dataclass(frozen=True)
class Score:
    """One candidate's result on the tuning trials.

    Attributes:
        label: The controller's label.
        index: The candidate's number (0: the options as given).
        options: Its options.
        value: The criterion (inf: more than the statistic allows failed).
        trials: Tuning trials it ran.
        failed: Those counted as the worst (a crash, an end stop, no value).
    """

    label: str
    index: int
    options: dict[str, Any]
    value: float
    trials: int
    failed: int
    per_trial: dict[tuple[int, int], float] = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class Choice:
    """A controller's tuning outcome.

    Attributes:
        chosen: The options kept: the best candidate if shown better than the options as
            given, else the options as given.
        best: The candidate of the lowest criterion.
        better: Tuning trials on which the best scored lower than the options as given.
        worse: Those on which it scored higher (ties and trials both failed left out).
        p_value: One-sided exact sign test of "the best is lower" (nan: the best is the
            options as given).
        p_adjusted: ``p_value`` times the searched candidates (Bonferroni), at most 1.
    """

    chosen: Score
    best: Score
    better: int = 0
    worse: int = 0
    p_value: float = math.nan
    p_adjusted: float = math.nan

    @property
    def shown_better(self) -> bool:
        """The best candidate is kept (it is not the options as given)."""
        return self.chosen.index != 0


def trial_values(rows: list[dict[str, Any]], criterion: str) -> dict[tuple[int, int], float]:
    """The criterion's field of every row by (sweep point, trial), ``+inf`` for a trial
    that failed or has no finite value (:func:`criterion_value`'s worst)."""
    from benchmarks.study.failures import is_failure

    field_name = CRITERIA[criterion][0]
    out = {}
    for row in rows:
        v = row.get(field_name)
        key = (int(row.get("point", 0)), int(row["trial"]))
        if not is_failure(row) and isinstance(v, int | float) and math.isfinite(v):
            out[key] = float(v)
        else:
            out[key] = math.inf
    return out


def criterion_value(rows: list[dict[str, Any]], criterion: str) -> tuple[float, int]:
    """The criterion over a candidate's rows, and how many counted as the worst (+inf):
    a trial that did not run to its end (:func:`benchmarks.study.failures.is_failure`: a
    crash, an end stop, a refused command) or has no finite value of the field.

    Raises:
        KeyError: An unknown criterion.
    """
    from benchmarks.study.failures import is_failure

    field, statistic = CRITERIA[criterion]
    values = []
    failed = 0
    for row in rows:
        v = row.get(field)
        if is_failure(row) or not isinstance(v, int | float) or not math.isfinite(v):
            values.append(math.inf)
            failed += 1
        else:
            values.append(float(v))
    if not values:
        return math.inf, 0
    x = np.sort(np.asarray(values))
    if statistic == "median":
        value = float(np.median(x))
    elif statistic == "mean":
        value = float(np.mean(x))
    else:  # p90: the order statistic at rank ceil(0.9 n) (no interpolation across inf)
        value = float(x[max(0, math.ceil(0.9 * len(x)) - 1)])
    return value, failed


def choose(scores: list[Score], alpha: float = 0.05) -> Choice:
    """The lowest criterion (the earlier candidate on a tie), kept only if shown better
    than the options as given (candidate 0) on the paired tuning trials: the one-sided
    exact sign test of "lower", its p-value times the searched candidates (Bonferroni:
    the best of several is picked after the scores are seen) below ``alpha``."""
    from benchmarks.study.exact import binomial_upper_tail_half

    given = next(s for s in scores if s.index == 0)
    best = min(scores, key=lambda s: (s.value, s.index))
    if best.index == 0:
        return Choice(given, best)
    common = sorted(set(best.per_trial) & set(given.per_trial))
    d = np.array([best.per_trial[k] - given.per_trial[k] for k in common
                  if not (math.isinf(best.per_trial[k]) and math.isinf(given.per_trial[k]))])
    better, worse = int(np.sum(d < 0)), int(np.sum(d > 0))
    p = binomial_upper_tail_half(better, better + worse) if better + worse else 1.0
    adjusted = min(1.0, p * (len(scores) - 1))
    return Choice(best if adjusted < alpha else given, best, better, worse, p, adjusted)


def _own_entry(entry: Path) -> bool:
    """An entry of a tune directory: the candidates' run directory, or a tuned.toml or
    tuning.json the project wrote."""
    from hexapod.outputs import written_by_project

    if entry.name == CANDIDATES_DIR:
        return entry.is_dir()
    return entry.name in (TUNED_FILE, SCORES_FILE) and written_by_project(entry)


def _label(label: str, k: int) -> str:
    return f"{label}:c{k}"


def _run_args(args: argparse.Namespace, out: Path, scenario: str) -> argparse.Namespace:
    """The ``run`` arguments the candidates' study needs."""
    return argparse.Namespace(
        out=str(out), scenarios=[scenario], resume=args.resume, chunk=None,
        workers=args.workers, record=0, backend="sim", engine="batched", dask=None,
        viz=False, no_progress=args.no_progress, overwrite=False,
        verbose=getattr(args, "verbose", False), argv=getattr(args, "argv", sys.argv[1:]),
        allow_foreign_calibration=False, no_check=False,
        options_record={"candidates": True})  # (the report says what its options are)


def _same_tuning(run_dir: Path, study: Any, given: dict[str, int]) -> None:
    """Refuse, in tune's words, a tune directory whose candidates are another tuning's
    (the candidates' run refuses it naming their internal labels under
    ``--controllers``); ``given``: the candidates of each controller label. A directory
    this cannot read is left to the run, which says what is wrong with it.

    Raises:
        BenchmarkError: What differs (the controllers, their candidates, the search
            space, the study's other settings) and the command to finish it with.
    """
    from benchmarks.exceptions import StudyMismatchError
    from benchmarks.study.report import META_FILE
    from benchmarks.study.study_record import STUDY_KEY, check_same_study, commands_of

    try:
        meta = json.loads((run_dir / META_FILE).read_text())
        recorded = meta["scenarios"][study.name][STUDY_KEY]["controllers"]
        kept: dict[str, int] = {}
        for text in recorded:  # "LABEL:cK (NAME, options)"
            label = str(text).split(" (", 1)[0].rsplit(":c", 1)[0]
            kept[label] = kept.get(label, 0) + 1
        check_same_study(run_dir, meta, [study])
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return  # (no tuning yet, or one the run's own checks describe)
    except StudyMismatchError as exc:
        lines = [d for d in exc.differences if not d.startswith("--controllers")]
        if sorted(kept) != sorted(given):
            lines.insert(0, f"--controllers: {', '.join(kept)} in the directory, "
                            f"{', '.join(given)} given")
        elif kept != given:
            lines.insert(0, "--candidates: " + "; ".join(
                f"{label} {kept[label]} in the directory, {given[label]} given"
                for label in given if kept[label] != given[label]))
        elif len(lines) < len(exc.differences):
            lines.insert(0, "the candidates' searched options (another search space)")
        tunes = [c["command"] for c in commands_of(meta)
                 if str(c.get("command", "")).startswith("hexapod-bench tune")]
        finish = (f"finish it with its last command and --resume ({tunes[-1]})" if tunes
                  else "finish it with the command that made it and --resume")
        raise BenchmarkError(
            f"{run_dir.parent}: holds a tuning of other settings than those given (nothing "
            "was run):" + "".join(f"\n  {line}" for line in lines) + f"\n{finish}, or "
            "tune into another --out") from None


def cmd_tune(args: argparse.Namespace) -> int:
    """Tune the chosen controllers of a scenario (see the module docstring)."""
    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.study.commands import console, run_studies
    from benchmarks.study.runner import deduplicate, read_results
    from benchmarks.study.scenario import load_scenario
    from benchmarks.study.tuning_space import (
        SEARCH_SPACE,
        candidates,
        check_space_options,
        controller_space,
        load_space,
    )
    from hexapod.outputs import check_output_dir, check_replace

    con = console()
    out = Path(args.out)
    if args.candidates < 2:
        raise ScenarioError("--candidates", f"at least 2 (the options as given and one "
                            f"searched), got {args.candidates}")
    if args.workers < 1:  # (it was refused after the header, with the directory made)
        raise BenchmarkError(f"--workers {args.workers}: at least 1")
    labels = [c.strip() for c in args.controllers.split(",") if c.strip()]
    if not labels:
        raise ScenarioError("--controllers", "no controller named")
    base = load_scenario(args.scenario)
    study_seed = base.seed
    tuning_seed = study_seed + SEED_OFFSET if args.seed is None else args.seed
    if tuning_seed == study_seed:
        raise ScenarioError("--seed", f"{tuning_seed} is the study's own seed: tuning trials "
                            "must be held out from the study's (choose another seed)")
    sc = base.with_overrides(args.trials, tuning_seed, labels, args.max_steps)
    if args.goal is not None:
        sc = sc.with_goal(args.goal)
    criterion = args.criterion or ("median-tracking-rms" if sc.task.kind == "trajectory"
                                   else "median-final")
    if "tracking" in CRITERIA[criterion][0] and sc.task.kind != "trajectory":
        raise BenchmarkError(f"--criterion {criterion}: {sc.name}'s task is {sc.task.kind}, "
                             "with no reference to track (every trial would score as a "
                             "failure); choose one of "
                             + ", ".join(c for c, (f, _) in CRITERIA.items()
                                         if "tracking" not in f))
    check_output_dir(out, _own_entry, "tune directory (candidates/, tuned.toml, tuning.json)",
                     args.overwrite)
    for path, kind in ((out / TUNED_FILE, "TOML"), (out / SCORES_FILE, "JSON")):
        check_replace(path, args.overwrite, kind=kind)
    space = SEARCH_SPACE if args.space is None else load_space(args.space)
    tables = {spec.label: controller_options(spec) for spec in sc.controllers}
    own_tables = (check_space_options(space, tables, {s.label: s.name for s in sc.controllers},
                                      args.space)
                  if args.space is not None else frozenset())
    from benchmarks.study.scenario_checks import check_controllers

    sc = check_controllers(sc)[0]  # [controller_options] resolved: the options as given
    specs = []
    plans: dict[str, list[dict[str, Any]]] = {}
    families: dict[str, str | None] = {}
    axes: dict[str, Any] = {}
    for spec in sc.controllers:
        cs = controller_space(spec.label, spec.name, tables[spec.label], space,
                              own_tables)
        for text in cs.skipped:
            con.print(f"tune: {text}", markup=False, highlight=False)
        families[spec.label] = cs.family
        axes[spec.label] = cs.axes
        _check_axis_values(spec, cs.axes, space, args.space)
        plans[spec.label] = candidates(spec.options, cs.axes, args.candidates)
        for k, opts in enumerate(plans[spec.label]):
            specs.append(replace(spec, label=_label(spec.label, k), options=opts))
    points = len(sc.expand())
    budget = f"{args.candidates} candidates x {sc.trials} trials x {points} sweep point(s)"
    con.print(f"tune {sc.name}: {len(labels)} controller(s), {budget} each; criterion "
              f"{criterion}; goal setting {sc.task.goal}; tuning seed {tuning_seed} (the "
              f"study's: {study_seed})", markup=False, highlight=False)
    for label, plan in plans.items():
        if len(plan) < args.candidates:
            con.print(f"tune: warning: {label} has no search space: its options as given "
                      f"alone (1 candidate, not {args.candidates}): its budget is not the "
                      "others'", markup=False, highlight=False)
    held_out = sc.task.kind != "fixed"
    if not held_out:
        con.print(f"tune: warning: {sc.name}'s task is one fixed start and goal: the tuning "
                  "trials repeat the study's task with other noise and calibration-error "
                  "draws, so the study's run of the tuned options is not a held-out test of "
                  "other tasks", markup=False, highlight=False)
    run_dir = out / CANDIDATES_DIR
    _same_tuning(run_dir, replace(sc, controllers=tuple(specs)),
                 {label: len(plan) for label, plan in plans.items()})
    out.mkdir(parents=True, exist_ok=True)
    code = run_studies([replace(sc, controllers=tuple(specs))], run_dir,
                       _run_args(args, run_dir, args.scenario))
    if code == 130:  # (the candidates' run said how to finish: this command, --resume)
        return code
    rows, _, _ = deduplicate(read_results(run_dir))
    by_label: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        by_label.setdefault(row["controller"], []).append(row)
    scores: dict[str, list[Score]] = {}
    for spec in sc.controllers:
        scores[spec.label] = []
        for k, opts in enumerate(plans[spec.label]):
            got = by_label.get(_label(spec.label, k), [])
            value, failed = criterion_value(got, criterion)
            scores[spec.label].append(Score(spec.label, k, opts, value, len(got), failed,
                                            trial_values(got, criterion)))
    choices = {label: choose(s) for label, s in scores.items()}
    chosen = {label: c.chosen for label, c in choices.items()}
    for label, s in chosen.items():
        for axis in axes[label]:
            if s.index > 0 and axis.at_end(s.options[axis.option]):
                value = s.options[axis.option]
                first = float(value[0] if isinstance(value, list | tuple) else value)
                deadbeat = ((axis.unit == "1/s" or axis.option in ("gain", "adaptive_gain"))
                            and math.isclose(first, 1.0 / sc.dt))  # (a first-order law's)
                beyond = ("the discrete loop's deadbeat gain 1/dt, the limit of its design, "
                          "not of an arbitrary range (docs/tuning.md)" if deadbeat else
                          "the best may lie beyond (widen the space with --space)")
                con.print(f"tune: warning: {label}: the chosen {axis.option} = {value} is at "
                          f"an end of its range [{axis.low:g}, {axis.high:g}] {axis.unit}: "
                          f"{beyond}", markup=False, highlight=False)
    tuning = {
        "scenario": sc.name, "source": sc.source, "criterion": criterion,
        "metric": CRITERIA[criterion][0], "statistic": CRITERIA[criterion][1],
        "candidates": args.candidates, "trials": sc.trials, "sweep_points": points,
        "budget": budget, "tuning_seed": tuning_seed, "study_seed": study_seed,
        "seed_offset": tuning_seed - study_seed,
        "families": {k: v or "none" for k, v in families.items()},
        "candidates_run": {label: len(plan) for label, plan in plans.items()},
        "goal": sc.task.goal, "held_out": held_out,
        "chosen": {label: s.index for label, s in chosen.items()},
        "shown_better": {label: {
            "best": c.best.index, "kept": "best" if c.shown_better else "as given",
            "better_in": c.better, "worse_in": c.worse,
            "p_sign_one_sided": None if math.isnan(c.p_value) else c.p_value,
            "p_bonferroni": None if math.isnan(c.p_adjusted) else c.p_adjusted}
            for label, c in choices.items()},
        "command": "hexapod-bench " + " ".join(getattr(args, "argv", [])),
    }
    _write(out, chosen, scores, tuning)
    _print(con, scores, choices, criterion, out)
    return 0


def _check_axis_values(spec: Any, axes: Any, space: dict[str, Any], path: str | None) -> None:
    """Each axis's values at both ends of its range are options the controller takes
    (a vector option's axis without its ``shape`` gave a number where three are meant,
    refused only once the tune had started).

    Raises:
        ScenarioError: Naming the space file (or the declared space), the axis's key and
            the controller's refusal.
    """
    from controllers.exceptions import OptionError
    from controllers.registry import registry

    table = registry.options(spec.name)
    for axis in axes:
        key = next((f"{k}.{axis.option}" for k, found in space.items() if axis in found),
                   axis.option)
        declared = next((o for o in table.options if o.name == axis.option), None)
        vector = isinstance(spec.options.get(axis.option), list | tuple) or (
            declared is not None and "Sequence" in str(declared.type))  # (the hint's)
        for u in (0.0, 1.0):
            try:
                registry.create(spec.name, **{**spec.options, axis.option: axis.value(u)})
            except (OptionError, TypeError, ValueError) as exc:
                problem = getattr(exc, "problem", None) or str(exc)
                raise ScenarioError(path or "the declared search space", f"{spec.name}: "
                                    f"{problem} (the axis's value {axis.value(u)!r}"
                                    + ("; a vector option's axis needs a shape" if
                                       axis.shape is None and vector else "") + ")",
                                    key=key) from None


def _write(out: Path, chosen: dict[str, Score], scores: dict[str, list[Score]],
           tuning: dict[str, Any]) -> None:
    from benchmarks.study.options_file import write_options_file
    from hexapod.outputs import TEXT_MARKER

    held = ("the study's own seed: held-out trials" if tuning["held_out"] else
            "the study's own seed: the same fixed task, other noise draws: not held out")
    header = (f"{TEXT_MARKER}: hexapod-bench tune (docs/tuning.md)\n"
              f"Use: hexapod-bench run {tuning['scenario']} --options-file {out / TUNED_FILE} "
              f"--out DIR ({held}; tuned under the goal setting {tuning['goal']})")
    write_options_file(out / TUNED_FILE, {label: s.options for label, s in chosen.items()},
                       tuning, header)
    data = {"generator": "hexapod-vs", "tuning": tuning, "candidates": {
        label: [{"index": s.index, "options": s.options,
                 "criterion": s.value if math.isfinite(s.value) else None,
                 "trials": s.trials, "failed": s.failed} for s in ss]
        for label, ss in scores.items()}}
    (out / SCORES_FILE).write_text(json.dumps(data, indent=2) + "\n")


def _print(con: Any, scores: dict[str, list[Score]], choices: dict[str, Choice],
           criterion: str, out: Path) -> None:
    from rich.markup import escape
    from rich.table import Table

    t = Table(title=f"tuning: {criterion} \\[mm] per candidate (* kept)")  # (\\[: not markup)
    for col in ("controller", "candidate", "options", "criterion", "failed"):
        t.add_column(col, overflow="fold")
    for label, ss in scores.items():
        for s in ss:
            mark = "*" if s.index == choices[label].chosen.index else ""
            opts = ", ".join(f"{k}={v}" for k, v in s.options.items()) or "(defaults)"
            t.add_row(label, f"{s.index}{mark}" + (" (as given)" if s.index == 0 else ""),
                      escape(opts), f"{s.value:.6g}", f"{s.failed}/{s.trials}")
    con.print(t)
    for label, c in choices.items():
        if c.best.index == 0:
            text = "the options as given scored lowest: kept"
        else:
            test = (f"lower on {c.better} and higher on {c.worse} of the paired tuning "
                    f"trials, one-sided sign test p = {c.p_value:.3g}, x {len(scores[label]) - 1}"
                    f" searched candidates: {c.p_adjusted:.3g}")
            text = (f"candidate {c.best.index} kept: shown better than the options as given "
                    f"({test})" if c.shown_better else
                    f"candidate {c.best.index} scored lowest but is not shown better than the "
                    f"options as given ({test}): the options as given are kept")
        con.print(f"{label}: {text}", markup=False, highlight=False)
    con.print(f"tuned options: {out / TUNED_FILE}; every candidate: {out / SCORES_FILE}",
              markup=False, highlight=False)


def register(sub: Any) -> None:
    """Add ``tune`` to the subcommands."""
    s = add_command(sub, "tune", cmd_tune,
                    "matched tuning: each controller's gains chosen the same way on held-out "
                    "trials (docs/tuning.md)",
                    description=__doc__.split("\n\n")[0] if __doc__ else None)
    add_arguments(s)


__all__ = ["CRITERIA", "SEED_OFFSET", "Choice", "Score", "choose", "cmd_tune",
           "criterion_value", "register", "trial_values"]
