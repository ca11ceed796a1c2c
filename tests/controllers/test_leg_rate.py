"""The velocity laws' measured-leg-rate feed-forward (option ``leg_rate_feedforward``,
:mod:`controllers.leg_rate`): the setpoint moves a first-order drive by exactly what the
law asks over the period, a wrapper's offset composes, the option is off by default (the
law's command unchanged), the batched and per-trial engines agree, and it recovers much
of what the drive-aware MPC recovers on slow drives."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks.sim import run_trials
from benchmarks.study.scenario import parse_scenario
from controllers import registry
from controllers.exceptions import ContextError, OptionError
from controllers.leg_rate import feed_forward, feedforward_gain
from hexapod.geometry import preset


def _context(bandwidth: float, mode: str = "velocity") -> object:
    g = preset("deltalab")
    drives = g.drives.replace(velocity_bandwidth=np.full(6, bandwidth), mode=mode)
    return type("Ctx", (), {"geometry": dataclasses.replace(g, drives=drives)})()


def _lag_displacement(u: np.ndarray, v: np.ndarray, omega: float, dt: float) -> np.ndarray:
    """The displacement of ``v' = omega (u - v)`` over ``dt`` by RK4 on a fine grid."""
    n = 500
    h = dt / n
    vel, q = v.copy(), np.zeros_like(v)
    for _ in range(n):
        def f(x: np.ndarray) -> np.ndarray:
            return omega * (u - x)
        k1 = f(vel)
        k2 = f(vel + h / 2 * k1)
        k3 = f(vel + h / 2 * k2)
        k4 = f(vel + h * k3)
        q += h / 6 * (vel + 2 * (vel + h / 2 * k1) + 2 * (vel + h / 2 * k2) + (vel + h * k3))
        vel = vel + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return q


@pytest.mark.parametrize("bandwidth", [5.0, 10.0, 50.0])
def test_the_setpoint_moves_a_lagging_leg_by_what_the_law_asks(bandwidth: float) -> None:
    dt = 0.02
    kappa = feedforward_gain(_context(bandwidth), dt, "leg-edge")  # type: ignore[arg-type]
    omega = 2 * np.pi * bandwidth
    c = (1 - np.exp(-omega * dt)) / omega
    np.testing.assert_allclose(kappa, c / (dt - c), rtol=1e-14)
    rng = np.random.default_rng(0)
    q_dot, v = 0.01 * rng.standard_normal(6), 0.01 * rng.standard_normal(6)
    u = feed_forward(q_dot, v, np.zeros(6), kappa)
    np.testing.assert_allclose(_lag_displacement(u, v, omega, dt), dt * q_dot, rtol=1e-8,
                               atol=1e-15)
    # without the feed-forward the lagging leg falls short (or overshoots) of it
    assert np.max(np.abs(_lag_displacement(q_dot, v, omega, dt) - dt * q_dot)) > 1e-6


def test_fast_drives_give_the_law_back_and_force_drives_are_refused() -> None:
    kappa = feedforward_gain(_context(1e6), 0.02, "leg-edge")  # type: ignore[arg-type]
    assert np.all(kappa < 1e-4)
    with pytest.raises(ContextError, match="velocity-mode"):
        feedforward_gain(_context(50.0, "force"), 0.02, "leg-edge")  # type: ignore[arg-type]


def test_offsets_compose_and_unmeasured_rows_keep_the_law() -> None:
    rng = np.random.default_rng(1)
    q, v, r = (rng.standard_normal((4, 6)) for _ in range(3))
    kappa = np.full(6, 0.7)
    np.testing.assert_allclose(feed_forward(q, v, r, kappa) + r,
                               feed_forward(q + r, v, np.zeros((4, 6)), kappa), rtol=1e-12)
    v[2, 3] = np.nan
    out = feed_forward(q, v, np.zeros((4, 6)), kappa)
    np.testing.assert_array_equal(out[2], q[2])
    assert not np.allclose(out[1], q[1])
    np.testing.assert_array_equal(feed_forward(q, None, r, kappa), q)


def test_the_option_is_checked_and_only_then_told_offsets() -> None:
    assert not hasattr(registry.create("leg-edge"), "velocity_offset")
    assert callable(registry.create("leg-direction-qp", leg_rate_feedforward=True)
                    .velocity_offset)
    with pytest.raises(OptionError, match="true or false"):
        registry.create("leg-edge", leg_rate_feedforward="yes")
    with pytest.raises(OptionError, match="drive_model"):
        registry.create("leg-edge-mpc", leg_rate_feedforward=True)


SLOW_DRIVES = {
    "name": "ff", "seed": 1, "trials": 3,
    "controllers": ["leg-edge", {"name": "leg-edge", "label": "ff",
                                 "leg_rate_feedforward": True},
                    {"name": "leg-edge", "label": "off", "leg_rate_feedforward": False}],
    "controller_options": {"adaptive_gain": [5.0, 1.0, 30.0]},
    "robot": {"world": "dynamic"}, "drives": {"velocity_bandwidth_hz": 5.0},
    "calibration_error": {"base_points_mm": 1.0},
    "task": {"kind": "random-pairs", "max_steps": 200, "fixed_duration": True,
             "position_tolerance_mm": 0.5, "orientation_tolerance_deg": 0.05},
}


def _rows(engine: str, index: int) -> list[dict]:
    sc = parse_scenario(SLOW_DRIVES)
    out = run_trials(sc, index, [0, 1, 2], engine=engine)
    return [{k: v for k, v in r.row.items() if k not in ("step_time_us", "controller")}
            for r in out]


@pytest.mark.slow
def test_on_slow_drives_engines_agree_off_is_the_law_and_on_helps() -> None:
    plain, off, ff = _rows("batched", 0), _rows("batched", 2), _rows("batched", 1)
    assert plain == off  # the option off: the law's rows, bit for bit
    assert _rows("per-trial", 1) == ff  # both engines, the same rows
    err = [np.median([r["final_position_error_mm"] for r in rows]) for rows in (plain, ff)]
    # 5 Hz drives, 4 s: the law alone wanders near 1 mm; fed forward, well below
    assert err[1] < 0.5 * err[0], err
