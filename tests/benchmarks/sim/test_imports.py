"""The simulator does not import the study: ``benchmarks/sim/`` reads a scenario through
its own protocols (:mod:`benchmarks.sim.inputs`), the study drives the simulator."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]

PROBE = """
import importlib, json, pkgutil, sys
import benchmarks.sim
names = sorted(m.name for m in pkgutil.iter_modules(benchmarks.sim.__path__))
for name in names:
    importlib.import_module("benchmarks.sim." + name)
print(json.dumps({"modules": names,
                  "study": sorted(k for k in sys.modules if k.startswith("benchmarks.study"))}))
"""


@pytest.mark.slow
def test_no_simulator_module_imports_the_study() -> None:
    """Every module of ``benchmarks.sim``, imported in a fresh interpreter (a clean
    ``sys.modules``), leaves no ``benchmarks.study`` module imported."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", PROBE], cwd=ROOT, env=env,
                          capture_output=True, text=True, check=False, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.splitlines()[-1])
    assert {"loop", "plant", "sensors", "stepper", "world", "book"} <= set(out["modules"])
    assert out["study"] == []
