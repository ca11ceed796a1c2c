"""Result rows written by hand (the report, load and compare are functions of
``results.jsonl`` alone), for the statistics tests."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np


def make_rows(controller: str, errors: np.ndarray, converged: np.ndarray, steps: np.ndarray,
              scenario: str = "synthetic", point: int = 0,
              sweep: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """One row per trial, with the keys the engine writes."""
    rows = []
    for k, (e, c, s) in enumerate(zip(errors, converged, steps, strict=True)):
        rows.append({
            "backend": "sim", "controller": controller, "controller_name": controller,
            "controller_package": "hexapod-vs", "controller_version": "0.1.0",
            "converged": bool(c), "failure": None if c else "not converged",
            "final_orientation_error_deg": float(e) / 5,
            "final_position_error_mm": float(e), "hidden_edge_periods": 0,
            "point": point, "scenario": scenario, "step_time_us": 1.0,
            "steps": int(s), "stroke_violations": 0, "trial": k, **(sweep or {}),
        })
    return rows


def write_run(out: Path, rows: list[dict[str, Any]]) -> Path:
    """``out/results.jsonl`` from rows."""
    out.mkdir(parents=True, exist_ok=True)
    with (out / "results.jsonl").open("w") as f:
        for r in rows:
            f.write(json.dumps(r, sort_keys=True) + "\n")
    return out


def two_controllers(n: int = 100, seed: int = 0, worse_by: float = 1.0,
                    worse_fails: int = 0) -> list[dict[str, Any]]:
    """Controllers ``good`` and ``bad`` on the same n trials: ``bad``'s final errors are
    ``good``'s times ``worse_by``, and it fails to converge on ``worse_fails`` more trials."""
    rng = np.random.default_rng(seed)
    err = rng.lognormal(-3, 0.5, n)
    steps = rng.integers(80, 140, n)
    conv = np.ones(n, bool)
    bad_conv = conv.copy()
    bad_conv[:worse_fails] = False
    return (make_rows("good", err, conv, steps)
            + make_rows("bad", err * worse_by, bad_conv, steps + (worse_by != 1.0) * 7))
