"""The pre-flight's look at a study's per-trial calibration (``[calibration] method =
"linear"``): the calibrations of a few trials of each sweep point, run as the study will
run them (the same worlds and the same random stream), so that ``check`` and ``run`` say
when they fail (``check`` said "No problem found" of a study whose every trial then
failed at its calibration, ill-conditioned legs under the file's own
``min_singular_ratio``). A warning, not a refusal: a few trials say too little of all."""

from __future__ import annotations

from typing import Any

import numpy as np

from benchmarks.study.setup_check import Problem
from benchmarks.study.trajectory_check import sweep_text

#: Trials sampled per sweep point, and sweep points at most (spread over the sweep).
SAMPLED_TRIALS, MAX_POINTS = 3, 8


def calibration_problems(sc: Any) -> list[Problem]:
    """The problems of a scenario's per-trial calibration, per sampled sweep point: a
    warning when a sampled trial's calibration fails; none for a study that does not
    calibrate."""
    if sc.calibration.method != "linear":
        return []
    from benchmarks.sim import load_camera, load_geometry, make_trials, trial_rng
    from benchmarks.study.calibration import calibration_hook
    from vision.exceptions import CalibrationError

    points = sc.expand()
    picks = sorted(set(np.linspace(0, len(points) - 1, min(MAX_POINTS, len(points)))
                       .round().astype(int).tolist()))
    out = []
    for point in (points[i] for i in picks):
        nominal = load_geometry(point)
        trials = list(range(min(point.trials, SAMPLED_TRIALS)))
        setups = [s for s in make_trials(point, trials, nominal, load_camera(point, nominal))
                  if not isinstance(s, Exception)]
        hook = calibration_hook(point)
        if hook is None or not setups:
            continue
        failed = []
        for s in setups:
            try:
                hook(s.world, trial_rng(point.seed, s.trial, 3))  # (the run's stream)
            except CalibrationError as exc:
                failed.append(str(exc))
        if failed:
            out.append(Problem(
                "warning",
                f"the calibration of {len(failed)} of {len(setups)} sampled trials fails "
                f"({failed[0]}): their trials would fail; change [calibration] in "
                f"{sc.source} (configurations, min_singular_ratio) or the camera's view",
                point=sweep_text(dict(point.sweep))))
    return out
