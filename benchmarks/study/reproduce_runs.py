"""The studies behind ``hexapod-bench reproduce``'s figures: where each one goes under the
output directory, what it runs (a run of a built-in scenario at the scorecard's trial
count, or a calibration study), and running or finishing it there. A directory that holds
another study than the one planned is refused before any study runs
(:func:`check_studies`), in reproduce's words where the difference is a trial count the
scorecard fixes."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from benchmarks.study.paper_figures import RECORD_ALL, REPEATS, TRIALS
from hexapod.outputs import replace_whole

#: A change applied to each study's scenario before it runs (the sensitivity study).
Transform = Callable[[Any], Any]


def _study_dir(out: Path, study: str, quick: bool) -> Path:
    return out / (study.replace(":", "_") + ("-quick" if quick else ""))


def _planned(study: str, out: Path, quick: bool, transform: Transform | None,
             trials: int | None) -> tuple[str, Path, Any, int]:
    """What ``study`` runs: its kind (``run``, ``calibrate``), directory, scenario (the
    transform applied) and trials (calibrations)."""
    from benchmarks.study.scenario import load_scenario

    kind, _, rest = study.partition(":")
    name, _, variant = rest.partition(":")
    change = transform or (lambda sc: sc)
    d = _study_dir(out, study, quick)
    if kind == "calibrate":
        sc = load_scenario(name)
        if variant == "omni":
            sc = replace(sc, camera_preset="omni", camera_file=None, name=f"{name}-omni")
        return kind, d, change(sc), trials or (REPEATS[1] if quick else REPEATS[0])
    n = trials or TRIALS[name][1 if quick else 0]
    return kind, d, change(load_scenario(name).with_overrides(trials=n)), n


def _check_calibration(d: Path, sc: Any, repeat: int) -> bool:
    """Whether ``d`` holds this calibration study already (False: none yet).

    Raises:
        StudyMismatchError: It holds another one (other settings, repetitions, or one
            written before calibrations recorded their study), naming the differences.
    """
    from benchmarks.exceptions import StudyMismatchError
    from benchmarks.study.study_record import differences, study_of

    path = d / "calibration.json"
    if not path.exists():
        return False
    doc = json.loads(path.read_text())
    if "study" not in doc:
        raise StudyMismatchError(str(d), [
            "the calibration was written by an earlier hexapod-bench that did not record "
            "its study, so it cannot be checked; remove the directory to calibrate again"])
    lines = differences(doc["study"], study_of(sc))[0]
    if doc.get("repetitions") != repeat:
        lines.append(f"--repeat: {doc.get('repetitions')} in the directory, {repeat} given")
    if lines:
        raise StudyMismatchError(str(d), lines)
    return True


def check_studies(studies: list[str], out: Path, quick: bool, transform: Transform | None,
                  trials: int | None) -> None:
    """Refuse, before any study runs, an ``out`` whose directories hold other studies
    than these (a run's or a calibration's: they would be mixed or reused as they are).

    Raises:
        StudyMismatchError: Naming the directory and every difference.
    """
    from benchmarks.exceptions import StudyMismatchError
    from benchmarks.study.study_record import check_same_study

    for study in studies:
        kind, d, sc, n = _planned(study, out, quick, transform, trials)
        try:
            if kind == "calibrate":
                _check_calibration(d, sc, n)
            elif (d / "run.json").is_file():
                check_same_study(d, json.loads((d / "run.json").read_text()), [sc])
        except StudyMismatchError as exc:
            if trials is not None:  # (the sensitivity study's: it takes --trials)
                raise
            raise StudyMismatchError(str(d), [_in_scorecard_words(line, quick)
                                              for line in exc.differences]) from None


def _in_scorecard_words(line: str, quick: bool) -> str:
    """A difference of trials or repetitions in the scorecard's words: it plans them
    itself and takes no ``--trials`` or ``--repeat`` (the run's wording told to give
    one)."""
    for option, what in (("--trials", "trials"), ("--repeat", "calibrations")):
        if line.startswith(f"{option}: ") and " in the directory, " in line:
            kept, rest = line[len(option) + 2:].split(" in the directory, ", 1)
            planned = rest.split(" ", 1)[0]
            return (f"{what}: {kept} in the directory, {planned} planned by the scorecard"
                    f"{' with --quick' if quick else ''} (which takes no {option}: the "
                    "directory is another study's)")
    return line


def run_study(study: str, out: Path, quick: bool, workers: int,
              say: Callable[[str], None], transform: Transform | None = None,
              trials: int | None = None) -> Path:
    """Run (or finish) one study into its directory under ``out``; returns the directory.

    Args:
        study: ``run:SCENARIO`` or ``calibrate:SCENARIO[:omni]``.
        out: The parent directory.
        quick: Fewer trials (:data:`TRIALS`, :data:`REPEATS`).
        workers: Worker processes.
        say: Progress lines.
        transform: Applied to the loaded scenario (the sensitivity study).
        trials: Trials (calibrations) instead of :data:`TRIALS` / :data:`REPEATS`.
    """
    kind, d, sc, n = _planned(study, out, quick, transform, trials)
    name = study.split(":")[1]
    if kind == "calibrate":
        from benchmarks.study.calibration import run_calibration

        if _check_calibration(d, sc, n):
            say(f"{study}: reusing {d / 'calibration.json'}")
            return d
        variant = study.count(":") == 2
        say(f"{study}: {n} calibrations per sweep point "
            f"(hexapod-bench calibrate {name} --repeat {n}"
            + (", omnidirectional camera" if variant else "") + ")")
        run_calibration(sc, d, repeat=n)
        return d
    from benchmarks.study.commands import auto_chunk
    from benchmarks.study.runner import completed_keys, plan, run_lock, run_units
    from benchmarks.study.study_record import (
        check_same_study,
        command_entry,
        record_command,
        study_of,
    )

    with run_lock(d):
        done = completed_keys(d)
        record = n if name in RECORD_ALL else 0
        units = plan([sc], auto_chunk([sc], workers, "sim"), record, done)
        todo = sum(len(u.trials) for u in units)
        say(f"{study}: {todo} trials to run, {len(done)} done "
            f"(hexapod-bench run {name} --trials {n} --out {d} --workers {workers})")
        meta = json.loads((d / "run.json").read_text()) if (d / "run.json").is_file() else {}
        check_same_study(d, meta, [sc])
        record_command(meta, command_entry(
            ["run", name, "--trials", str(n), "--out", str(d)],
            f"hexapod-bench reproduce: {len(done)} trials already done, {todo} to run"))
        meta["scenarios"] = {sc.name: {"description": sc.description,
                                       "reference": sc.reference, "source": sc.source,
                                       "study": study_of(sc)}}
        replace_whole(d / "run.json", json.dumps(meta, indent=2))
        t0 = time.perf_counter()
        if units:
            run_units(units, d, workers)
        if todo:
            say(f"{study}: {todo} trials in {time.perf_counter() - t0:.1f} s")
    return d
