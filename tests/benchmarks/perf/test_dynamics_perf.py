"""``hexapod-bench perf dynamics``: Pinocchio and the compiled model on the same states,
in one table, with their accelerations compared."""

from __future__ import annotations

import pytest

from benchmarks.cli import main as cli_main
from benchmarks.perf import dynamics


def test_the_table_has_every_method_and_they_agree(capsys: pytest.CaptureFixture[str]
                                                   ) -> None:
    figures = dynamics.dynamics_figures(n=20, repeats=2)
    methods = [f.method for f in figures]
    assert methods[0] == "pinocchio constraintDynamics"
    assert {"compiled single", "compiled batch of 20"} <= set(methods)
    for f in figures:
        assert f.median_us > 0
        assert f.max_relative_error < 1e-9
    text = dynamics.format_dynamics(figures, 20)
    assert "compiled batch of 20" in text and "speed-up" in text


def test_wired_in_the_cli(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["perf", "dynamics", "-n", "10", "--repeats", "1"]) == 0
    out = capsys.readouterr().out
    assert "pinocchio constraintDynamics" in out and "DynamicModel.forward_batch" in out


def test_energy_drift_table_shrinks_with_the_step() -> None:
    rows = dynamics.energy_drift(steps=(2e-2, 1e-2), n=2)
    (dt1, drift1, ortho1), (dt2, drift2, ortho2) = rows
    assert (dt1, dt2) == (2e-2, 1e-2)
    assert drift2 < drift1 < 1e-8       # RK4: fourth order, tiny at these steps
    assert max(ortho1, ortho2) < 1e-8
    assert "classical RK4" in dynamics.format_energy(rows)


def test_mujoco_is_optional_and_said_so(monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    import importlib.util

    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    with pytest.raises(SystemExit):
        dynamics.main(["--mujoco", "-n", "2", "--repeats", "1"])
    assert "--mujoco needs MuJoCo (pip install mujoco)" in capsys.readouterr().err


def test_mujoco_model_mirrors_the_chain() -> None:
    """The MJCF (built without MuJoCo): six legs, six loop constraints, the masses."""
    import xml.etree.ElementTree as ET

    from benchmarks.perf.dynamics_mujoco import mjcf
    from hexapod import deltalab

    g = deltalab()
    root = ET.fromstring(mjcf(g))
    assert len(root.findall("./equality/connect")) == 6
    joints = [j.get("type") for j in root.iter("joint")]
    assert joints.count("ball") == 6 and joints.count("slide") == 6
    masses = sorted(float(i.get("mass", 0)) for i in root.iter("inertial"))
    assert masses == sorted([g.inertia.platform_mass] + [g.inertia.body_mass] * 6
                            + [g.inertia.rod_mass] * 6)
