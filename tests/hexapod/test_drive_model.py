"""The drives' behaviour (hexapod.dynamics.drive_model), measured on one leg moving a mass:
the velocity loop's bandwidth from its simulated frequency response, saturation, friction,
encoder quantisation, force mode, and no NaN whatever the input."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from hexapod.dynamics.drive_model import DriveModel, closed_loop_gain, quantise
from hexapod.dynamics.drives import DriveParameters

MASS = 4.0  # kg: the rotor's 2.5 kg plus the mechanism's share


def _leg(params: DriveParameters, setpoint, h: float, duration: float, v0: float = 0.0,
         load: float = 0.0, hold: float = 0.0) -> dict[str, np.ndarray]:
    """One leg (all six rows identical) moving MASS under its drive, a constant external
    force ``load`` [N] and its friction: ``MASS dv/dt = motor - friction + load``,
    linearly implicit in the velocity (as the dynamic world integrates it)."""
    model = DriveModel(params, np.full(6, MASS), 1)
    rows = np.array([0])
    model.hold(rows, np.full((1, 6), hold))
    v = np.full((1, 6), v0)
    out: dict[str, list[np.ndarray]] = {"t": [], "v": [], "motor": [], "friction": [],
                                        "saturated": [], "integral": []}
    for k in range(round(duration / h)):
        time = k * h
        sp = np.full((1, 6), float(setpoint(time)))
        f = model.forces(rows, sp, v, h)
        dv = h * (f.motor - f.friction + load) / (MASS - h * f.slope)
        for key, val in (("t", np.array(time)), ("v", v[0, 0]), ("motor", f.motor[0, 0]),
                         ("friction", f.friction[0, 0]), ("saturated", f.saturated[0, 0]),
                         ("integral", model.integral[0, 0])):
            out[key].append(np.array(val, copy=True))
        v = v + dv
    return {k: np.array(x) for k, x in out.items()}


def _linear(bandwidth: float = 50.0) -> DriveParameters:
    """Drives without Coulomb friction (a linear loop) and a large force limit."""
    return DriveParameters.default().replace(coulomb=0.0, force_limit=1e6,
                                             velocity_bandwidth=bandwidth)


def _gain_at(params: DriveParameters, f_hz: float, h: float) -> float:
    """Amplitude ratio of the realised to the commanded leg velocity for a sine setpoint
    at ``f_hz``, fitted over the last 4 periods (after the transient)."""
    w = 2 * np.pi * f_hz
    amp = 1e-3
    periods = 12
    res = _leg(params, lambda time: amp * np.sin(w * time), h, periods / f_hz)
    tail = res["t"] >= (periods - 4) / f_hz
    t, v = res["t"][tail], res["v"][tail]
    basis = np.stack([np.sin(w * t), np.cos(w * t)], axis=1)
    coef, *_ = np.linalg.lstsq(basis, v, rcond=None)
    return float(np.hypot(*coef) / amp)


@pytest.mark.slow
@pytest.mark.parametrize("bandwidth", [20.0, 50.0, 120.0])
def test_the_velocity_loop_has_the_stated_bandwidth(bandwidth: float) -> None:
    """Measured from the simulated response (physics step 0.1 ms): -3 dB at the stated
    bandwidth (within 2 %), flat a decade below, rolled off a decade above."""
    params = _linear(bandwidth)
    h = 1e-4
    assert _gain_at(params, bandwidth, h) == pytest.approx(1 / np.sqrt(2), rel=0.02)
    assert _gain_at(params, bandwidth / 10, h) == pytest.approx(1.0, abs=0.05)
    assert _gain_at(params, bandwidth * 10, h) < 0.2


def test_the_bandwidth_holds_at_the_default_physics_step() -> None:
    """At the dynamic world's default 1 ms step the 50 Hz loop keeps its -3 dB point
    within 10 % in gain (the discrete loop's error)."""
    assert _gain_at(_linear(50.0), 50.0, 1e-3) == pytest.approx(1 / np.sqrt(2), rel=0.1)


def test_the_tuned_gains_put_the_analytic_response_at_the_bandwidth() -> None:
    model = DriveModel(_linear(50.0), np.full(6, MASS), 1)
    w = 2 * np.pi * 50.0
    g = closed_loop_gain(w, MASS, 50.0, model.kp[0, 0], model.ki[0, 0])
    assert g == pytest.approx(1 / np.sqrt(2), rel=1e-9)


def test_the_step_response_settles_on_the_setpoint_against_friction_and_a_load() -> None:
    """A 20 mm/s step against Coulomb friction and a 30 N load: the integral takes them up,
    the leg ends at the setpoint (within 0.1 %)."""
    params = DriveParameters.default()
    res = _leg(params, lambda time: 0.02, 1e-3, 0.5, load=-30.0)
    assert res["v"][-1] == pytest.approx(0.02, rel=1e-3)
    assert not res["saturated"][-50:].any()


def test_saturation_holds_the_force_limit_without_winding_up() -> None:
    """A setpoint far beyond what 50 N can reach in time: the force never exceeds the limit,
    the drive is saturated while it accelerates, and once the setpoint is reached the
    overshoot is small (the integral did not wind up during the long saturation)."""
    params = DriveParameters.default().replace(force_limit=50.0)
    res = _leg(params, lambda time: 0.5, 1e-3, 0.3)
    assert np.all(np.abs(res["motor"]) <= 50.0 + 1e-12)
    assert res["saturated"][:20].all()
    assert np.all(np.abs(res["integral"]) <= 50.0 + 1e-12)
    assert res["v"].max() < 0.5 * 1.02
    assert res["v"][-1] == pytest.approx(0.5, rel=1e-3)


def test_friction_opposes_motion_and_stops_a_free_leg() -> None:
    params = DriveParameters.default().replace(mode="force")
    model = DriveModel(params, np.full(6, MASS), 1)
    rows = np.array([0])
    v = np.array([[-0.05, -1e-3, -1e-5, 1e-5, 1e-3, 0.05]])
    f = model.forces(rows, np.zeros((1, 6)), v, 1e-3)
    assert np.all(f.friction * v > 0)  # friction acts against the velocity: -friction . v < 0
    assert np.all(f.slope < 0)
    res = _leg(params, lambda time: 0.0, 1e-3, 0.5, v0=0.05)
    assert abs(res["v"][-1]) < 1e-6
    assert np.all(np.diff(np.abs(res["v"])) <= 1e-15)  # it only slows down


def test_force_mode_applies_the_command_within_the_limit() -> None:
    params = DriveParameters.default().replace(mode="force")
    model = DriveModel(params, np.full(6, MASS), 2)
    cmd = np.array([[10.0, -10.0, 199.0, -199.0, 500.0, -500.0]] * 2)
    f = model.forces(np.arange(2), cmd, np.zeros((2, 6)), 1e-3)
    np.testing.assert_array_equal(f.motor, np.clip(cmd, -200.0, 200.0))
    np.testing.assert_array_equal(f.saturated, np.abs(cmd) >= 200.0)


def test_force_mode_holds_the_command_to_the_speed_limit() -> None:
    """The speed limit in force mode (50 mm/s): within it the command passes bit for bit;
    beyond it the velocity loop's proportional term of the excess is subtracted,
    ``F - kp (v - v_max)`` (``F - kp (v + v_max)`` below ``-v_max``), within the force
    limit, and its slope ``-kp`` joins the friction's (the plant takes it implicitly); a
    drive is at its limit when the force it applies is (not the command); without a
    limit the command passes at any speed."""
    params = DriveParameters.default().replace(mode="force")
    free = DriveModel(params, np.full(6, MASS), 1)
    held = DriveModel(params, np.full(6, MASS), 1, np.array([0.05]))
    kp = float(held.kp[0, 0])
    cmd = np.array([[100.0, -100.0, 100.0, -100.0, 250.0, -100.0]])
    v = np.array([[0.05, -0.0499, 0.06, -0.07, 0.3, 2.0]])
    rows = np.array([0])
    f, f0 = held.forces(rows, cmd, v, 1e-3), free.forces(rows, cmd, v, 1e-3)
    np.testing.assert_array_equal(f0.motor, np.clip(cmd, -200.0, 200.0))
    np.testing.assert_array_equal(f.motor[0, :2], cmd[0, :2])  # at and within the limit
    np.testing.assert_allclose(f.motor[0, 2:5], [100.0 - kp * 0.01, -100.0 + kp * 0.02,
                                                 200.0 - kp * 0.25], rtol=1e-12)
    assert f.motor[0, 5] == -200.0  # pulled back at the force limit: no slope there
    # at the limit: the force applied (leg 4's command is, its force is not)
    np.testing.assert_array_equal(f.saturated[0], [False] * 5 + [True])
    np.testing.assert_array_equal(f0.saturated[0], [False] * 4 + [True, False])
    slope = f.slope - f0.slope  # the limiter's part
    np.testing.assert_allclose(slope[0], [0.0, 0.0, -kp, -kp, -kp, 0.0], rtol=1e-12)
    np.testing.assert_array_equal(f.friction, f0.friction)
    with pytest.raises(ValueError, match="speed_limit"):
        DriveModel(params, np.full(6, MASS), 1, np.array([0.0]))


def test_encoders_read_the_nearest_count() -> None:
    rng = np.random.default_rng(4)
    q = rng.uniform(0.3, 0.5, (100, 6))
    res = np.array([1e-6, 1e-6, 5e-6, 1e-5, 0.0, 2.5e-7])
    m = quantise(q, res)
    assert np.all(np.abs(m - q) <= res / 2 + 1e-15)
    counts = m[:, :4] / res[:4]
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    np.testing.assert_array_equal(m[:, 4], q[:, 4])


def test_encoders_round_as_np_round_bit_for_bit() -> None:
    """quantise rounds with np.rint: np.round's bits, the halves to even included, with
    every leg counted (the common case) or one not."""
    rng = np.random.default_rng(5)
    res = np.full(6, 1e-6)
    q = np.concatenate([rng.uniform(0.3, 0.5, (50, 6)), (np.arange(300) + 0.5).reshape(50, 6)
                        * 1e-6])
    for r in (res, np.array([1e-6, 0.0, 5e-6, 1e-5, 1e-6, 2.5e-7])):
        safe = np.where(r > 0, r, 1.0)
        expected = np.where(r > 0, np.round(q / safe) * safe, q)
        assert quantise(q, r).tobytes() == expected.tobytes()


def test_never_nan_whatever_the_input() -> None:
    """Huge, tiny and infinite velocities and setpoints: finite forces within the limit."""
    model = DriveModel(DriveParameters.default(), np.full(6, MASS), 3)
    rows = np.arange(3)
    big = np.array([[1e300, -1e300, 1e-300, 0.0, 1e6, -1e6]] * 3)
    for sp, v in ((big, big[:, ::-1]), (np.full((3, 6), np.inf), big),
                  (big, np.full((3, 6), -np.inf))):
        f = model.forces(rows, sp, v, 1e-3)
        assert np.all(np.isfinite(f.motor)) and np.all(np.abs(f.motor) <= 200.0)
        assert np.all(np.isfinite(model.integral))


def test_coulomb_friction_holds_a_small_setpoint_back() -> None:
    """docs/dynamic-world.md's figures of the default drives (5 N Coulomb friction) on the
    reference robot at home, every leg stepped to one setpoint: 10 mm/s (``kp v`` under
    ``f_c`` at first) reaches about 80 % of itself in a 20 ms period and 93 % in 50 ms,
    50 mm/s 98 % in 20 ms; without Coulomb friction the loop reaches 63 % in 2.5 ms
    (its 50 Hz bandwidth's time constant, 3.2 ms, less the integral's push)."""
    from hexapod import deltalab, home_pose
    from hexapod.dynamics.robots import DynamicRobots

    def fraction(g: Any, setpoint: float, at_ms: tuple[float, ...]) -> list[float]:
        R0, t0 = home_pose(g)
        robots = DynamicRobots([g], R0[None].copy(), t0[None].copy())
        h, out, v = 1e-4, [], []
        for _ in range(round(max(at_ms) / 1e3 / h)):
            robots.advance(np.arange(1), np.full((1, 6), setpoint), h, 1)
            q_dot = robots.model.legs_batch(robots.R, robots.t, robots.twist.copy())[0][0]
            v.append(float(np.mean(q_dot)) / setpoint)
        for ms in at_ms:
            out.append(v[round(ms / 1e3 / h) - 1])
        return out

    g = deltalab()
    at20, at50 = fraction(g, 0.010, (20.0, 50.0))
    assert 0.77 < at20 < 0.83 and 0.91 < at50 < 0.95
    assert fraction(g, 0.050, (20.0,))[0] > 0.97
    linear = g.replace(drives=g.drives.replace(coulomb=0.0, force_limit=1e6))
    assert fraction(linear, 0.010, (2.5,))[0] == pytest.approx(0.63, abs=0.03)
