"""The dynamic robots (hexapod.dynamics.robots): the compiled period equals the numpy steps,
the power balance of mechanism, rotor inertia and drives holds (a second formulation of the
integrated equations), gravity is held at rest, and the legs follow velocity setpoints."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod.dynamics.robots import DynamicRobots, legs
from hexapod.geometry import deltalab
from hexapod.workspace import sample_poses
from tests.hexapod.dynamic_robots_oracle import leg_bias, step_reference


def _robots(n: int, mode: str = "velocity", seed: int = 3, max_speed: float | None = None,
            **drive: float) -> tuple[DynamicRobots, np.ndarray, np.ndarray]:
    g = deltalab()
    g = g.replace(drives=g.drives.replace(mode=mode, **drive))
    if max_speed is not None:
        g = g.replace(max_speed=max_speed)
    R, t = sample_poses(g, n, np.random.default_rng(seed), max_translation=0.03,
                        max_angle=np.deg2rad(5.0), margin=0.02)
    R, t = np.array(R), np.array(t)
    return DynamicRobots([g] * n, R, t), R, t


def _state(r: DynamicRobots) -> np.ndarray:
    return np.concatenate([r.R.reshape(r.n, 9), r.t, r.twist, r.drives.integral, r.forces,
                           r.saturated_time[:, None], r.track_sq[:, None],
                           r.track_max[:, None], r.force_max[:, None], r.saturated_legs],
                          axis=1)


@pytest.mark.parametrize(("mode", "max_speed", "moving"), [
    ("velocity", None, 0.0), ("force", 10.0, 0.0), ("force", 0.005, 0.0),
    ("force", 0.005, 0.3)])
def test_the_compiled_period_equals_the_numpy_steps(mode: str, max_speed: float | None,
                                                    moving: float) -> None:
    """Random poses and setpoints (some drives saturate, 60 N limit), 20 steps of 1 ms:
    the same state, forces and accumulators to 1e-9 (relative to each quantity's scale);
    in force mode with the legs' speed limit out of reach (10 m/s) and at 5 mm/s, where
    it holds some legs back, from rest and from a fast start (up to 0.3 m/s), where it
    pulls some legs back at the force limit (no implicit slope there, and the time at
    the limit counted)."""
    n = 16
    rng = np.random.default_rng(5)
    sp = (rng.uniform(-0.05, 0.05, (n, 6)) if mode == "velocity"
          else rng.uniform(-120.0, 120.0, (n, 6)))
    a, _, _ = _robots(n, mode, max_speed=max_speed, force_limit=60.0)
    b, _, _ = _robots(n, mode, max_speed=max_speed, force_limit=60.0)
    start = rng.normal(0.0, moving, (n, 6)) * [1.0, 1.0, 1.0, 3.0, 3.0, 3.0]
    a.twist[:] = start
    b.twist[:] = start
    rows = np.arange(n)
    held = clipped = 0
    for _ in range(3):  # three periods: the twist and the integral are non-zero
        assert not a.advance(rows, sp, 1e-3, 20).any()
        for _ in range(20):
            if mode == "force":  # (forces() has no state to advance in this mode)
                qd, _ = b.model.legs_batch(b.R, b.t, b.twist, **b.rows(rows))
                f = b.drives.forces(rows, sp, qd, 1e-3)
                beyond = np.abs(qd) > (max_speed or 0.0)
                held += int(np.count_nonzero(beyond & (f.motor != np.clip(sp, -60.0, 60.0))))
                clipped += int(np.count_nonzero(beyond & f.saturated))
                assert np.array_equal(f.saturated, np.abs(f.motor) >= 60.0)
            step_reference(b, rows, sp, 1e-3)
    assert (held > 0) == (max_speed == 0.005)  # the speed limit held forces back, or none
    assert (clipped > 0) == (moving > 0)  # and pulled some at the force limit
    sa, sb = _state(a), _state(b)
    scale = np.maximum(np.abs(sb).max(axis=0), 1e-6)
    np.testing.assert_array_less(np.abs(sa - sb) / scale, 1e-9)
    assert np.any(a.saturated_time > 0) and np.any(np.abs(a.twist) > 1e-3)
    # a leg's time at its limit is at most the row's (any leg's), the largest equal to it
    # when one leg saturates alone
    assert np.all(a.saturated_legs <= a.saturated_time[:, None] + 1e-15)
    assert np.any(a.saturated_legs > 0) and np.any(a.saturated_legs == 0)


@pytest.mark.slow
def test_power_balance_of_mechanism_rotors_and_drives() -> None:
    """Force mode, constant forces, friction on: the change of the mechanism's energy
    (kinetic + potential, DynamicModel.energy) plus the rotors' kinetic energy
    (m_r q_dot^2 / 2) equals the work of the drives minus friction, integrated along the
    motion (0.1 ms steps over 0.2 s; agreement within 1 % of the work). The legs' speed
    limit is out of reach (10 m/s): the drives' forces are the constant commands."""
    n = 4
    r, _, _ = _robots(n, "force", max_speed=10.0, viscous=20.0, coulomb=3.0)
    rows = np.arange(n)
    hold = r.drives.integral.copy()
    push = hold + np.random.default_rng(2).uniform(-25.0, 25.0, (n, 6))

    def energy() -> np.ndarray:
        _, _, K, kin, pot = r.model.terms_batch(r.R, r.t, r.twist, **r.rows(rows))
        qd = np.einsum("nij,nj->ni", K, r.twist)
        return kin + pot + 0.5 * np.sum(r.rotor * qd**2, axis=1)

    h = 1e-4
    e0 = energy()
    work = np.zeros(n)
    for _ in range(2000):
        _, _, K, _, _ = r.model.terms_batch(r.R, r.t, r.twist, **r.rows(rows))
        qd0 = np.einsum("nij,nj->ni", K, r.twist)
        f = r.drives.forces(rows, push, qd0, h)
        step_reference(r, rows, push, h)
        _, _, K1, _, _ = r.model.terms_batch(r.R, r.t, r.twist, **r.rows(rows))
        qd1 = np.einsum("nij,nj->ni", K1, r.twist)
        net = f.motor - f.friction
        # trapezoid rule on the power, the friction's force re-evaluated at the end
        fr1 = r.drives.viscous * qd1 + r.drives.coulomb * np.tanh(qd1 / 1e-4)
        work += h * np.sum(0.5 * (net * qd0 + (f.motor - fr1) * qd1), axis=1)
    de = energy() - e0
    assert np.all(np.abs(work) > 0.05)
    np.testing.assert_allclose(de, work, rtol=0.01)


def test_force_mode_holds_the_legs_to_the_robots_speed_limit() -> None:
    """Force mode, every leg pushed 150 N off its holding force (75 % of the 200 N limit)
    for 0.2 s: with the robot's 50 mm/s limit the legs' speeds, measured as the change of
    their lengths over each 1 ms period, stay within the limit plus the proportional
    limiter's droop bounded by the force limit over kp (204 mm/s; the robot's own light
    platform adds little to the push: a heavy load would add its share);
    with the limit out of reach (10 m/s) the same push drives them past 20 times it."""
    def fastest(max_speed: float | None) -> tuple[float, float]:
        r, _, _ = _robots(3, "force", max_speed=max_speed)
        rows = np.arange(3)
        push = r.drives.integral + np.array([150.0, -150.0, 150.0, -150.0, 150.0, -150.0])
        q, top = r.lengths(rows).copy(), 0.0
        for _ in range(200):
            r.advance(rows, push, 1e-3, 1)
            q1 = r.lengths(rows).copy()
            top, q = max(top, float(np.abs(q1 - q).max()) / 1e-3), q1
        return top, float(r.drives.kp.min())

    assert deltalab().max_speed == 0.05
    held, kp = fastest(None)
    assert 0.05 < held <= 0.05 + 200.0 / kp  # (at most the force limit over kp past it)
    assert fastest(10.0)[0] > 20 * 0.05


def test_gravity_is_held_at_rest() -> None:
    """Zero velocity setpoints: the platform stays where it started (drift below 1 um
    and 1e-5 rad over 1 s), the drives carrying its weight."""
    r, R0, t0 = _robots(3)
    R0, t0 = R0.copy(), t0.copy()
    rows = np.arange(3)
    for _ in range(50):
        r.advance(rows, np.zeros((3, 6)), 1e-3, 20)
    assert np.abs(r.t - t0).max() < 1e-6
    assert np.abs(r.R - R0).max() < 1e-5
    assert np.all(np.abs(r.forces).sum(axis=1) > 1.0)


def test_the_legs_follow_their_velocity_setpoints() -> None:
    """10 mm/s on every leg for 0.2 s: the legs finish at the setpoint speed, and their
    travel falls short of 2 mm by what the integral action must absorb: by the final-value
    theorem, ``(c v + f_c) / ki`` (viscous and Coulomb friction over the integral gain),
    within 10 %."""
    r, R, t = _robots(2)
    rows = np.arange(2)
    q0 = legs(R, t, r.A, r.E)[0].copy()
    for _ in range(10):
        r.advance(rows, np.full((2, 6), 0.01), 1e-3, 20)
    deficit = 0.002 - (r.lengths(rows) - q0)
    d = r.drives
    expected = (d.viscous * 0.01 + d.coulomb) / d.ki
    np.testing.assert_allclose(deficit, expected, rtol=0.1)
    _, _, K, _, _ = r.model.terms_batch(r.R, r.t, r.twist, **r.rows(rows))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", K, r.twist), 0.01, rtol=0.02)


def test_the_step_equals_the_compiled_models_drive_layer() -> None:
    """A second formulation of one step: the acceleration of the numpy step (its twist
    change over h) equals DynamicModel.forward_drives_batch with the rotor inertia as the
    added mass and the drives' implicit slope as ``-h df/dq_dot`` (its own bias K_dot
    twist from CasADi's directional derivative, ours written out: leg_bias)."""
    n = 8
    r, _, _ = _robots(n, force_limit=60.0)
    rows = np.arange(n)
    rng = np.random.default_rng(9)
    r.twist[:] = rng.normal(0.0, [0.02, 0.02, 0.02, 0.1, 0.1, 0.1], (n, 6))
    sp = rng.uniform(-0.05, 0.05, (n, 6))
    h = 1e-3
    R, t, tw = r.R.copy(), r.t.copy(), r.twist.copy()
    integral = r.drives.integral.copy()
    qd, bias = r.model.legs_batch(R, t, tw, **r.rows(rows))
    f = r.drives.forces(rows, sp, qd, h)
    r.drives.integral[:] = integral  # forces() advanced it: the step starts from the same
    acc, _, _ = r.model.forward_drives_batch(R, t, tw, f.motor - f.friction, r.rotor,
                                             -h * f.slope, **r.rows(rows))
    q, u, arm = legs(R, t, r.A, r.E)
    np.testing.assert_allclose(leg_bias(tw, q, u, arm), bias, rtol=1e-9, atol=1e-12)
    step_reference(r, rows, sp, h)
    np.testing.assert_allclose((r.twist - tw) / h, acc, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("avx2", [True, False])
def test_the_lane_parallel_period_equals_casadis_folded_period_bit_for_bit(avx2: bool
                                                                           ) -> None:
    """The period the plant runs (hexapod.compiled_lanes, four rows per vector
    instruction) against CasADi's own C of the same step folded over the period: equal to
    the last bit, on moving robots with saturating drives (60 N) in both drive modes (in
    force mode also held to a 5 mm/s speed limit) and a row count that is not a whole
    number of lanes."""
    from hexapod.dynamics.robots_compiled import (
        LAYOUT,
        pack_period,
        period_function,
        period_lanes,
    )

    lanes = period_lanes()
    assert lanes is not None
    for mode, sp_scale, max_speed in (("velocity", 0.05, None), ("force", 120.0, None),
                                      ("force", 120.0, 0.005)):
        n = 11
        r, _, _ = _robots(n, mode, max_speed=max_speed, force_limit=60.0)
        rng = np.random.default_rng(4)
        r.twist[:] = rng.normal(0.0, [0.02, 0.02, 0.02, 0.1, 0.1, 0.1], (n, 6))
        x = pack_period(r, np.arange(n), rng.uniform(-sp_scale, sp_scale, (n, 6)), 1e-3)
        want = period_function(20).batch(x)
        got = lanes.iterate(x, 20, avx2=avx2)
        np.testing.assert_array_equal(got, want)
        tw = LAYOUT["twist"]
        assert np.all(np.any(got[:, tw] != x[:, tw], axis=1))  # every twist moved
        # the period ends with the legs' lengths of the final pose
        R = np.swapaxes(got[:, LAYOUT["R"]].reshape(n, 3, 3), -1, -2)
        np.testing.assert_allclose(got[:, LAYOUT["q"]], legs(R, got[:, LAYOUT["t"]], r.A,
                                                             r.E)[0], rtol=1e-14)


def test_a_diverging_row_is_flagged_and_left_unchanged_its_lane_neighbours_advance(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """One row given a NaN twist among 7 (so in a lane block with others): advance flags it
    and leaves its state and accumulators as they were; the other rows end exactly as
    without it, with their leg lengths updated, and CasADi's folded period (the fallback)
    does the same to the last bit."""
    import hexapod.dynamics.robots_compiled as rc

    n = 7
    sp = np.random.default_rng(8).uniform(-0.03, 0.03, (n, 6))
    rows = np.arange(n)
    others = rows != 2

    def run() -> tuple[DynamicRobots, np.ndarray, np.ndarray]:
        r, _, _ = _robots(n)
        r.twist[2] = np.nan
        before = _state(r)
        return r, before, r.advance(rows, sp, 1e-3, 20)

    a, before, bad = run()
    assert bad.tolist() == [k == 2 for k in range(n)]
    np.testing.assert_array_equal(_state(a)[2], before[2])  # NaN where it was NaN
    b, _, _ = _robots(n)
    b.advance(rows[others], sp[others], 1e-3, 20)
    np.testing.assert_array_equal(_state(a)[others], _state(b)[others])
    np.testing.assert_allclose(a.period_lengths[others], a.lengths(rows[others]), rtol=1e-14)
    assert np.all(a.period_lengths[others] != legs(*_robots(n)[1:], a.A, a.E)[0][others])
    monkeypatch.setattr(rc, "period_lanes", lambda: None)
    c, _, bad_c = run()
    assert bad_c.tolist() == bad.tolist()
    np.testing.assert_array_equal(_state(c), _state(a))
    np.testing.assert_array_equal(c.table[others], a.table[others])


def test_leg_rates_are_the_models_leg_rates_bit_for_bit() -> None:
    """The leg rates from the table packed once are legs_batch's with each row's own
    geometry and inertia, to the last bit, for rows in any order after a period (the
    poses and twists have moved); a non-finite twist is refused naming it."""
    from hexapod.exceptions import ShapeError

    n = 6
    g, (_, R, t) = deltalab(), _robots(n)
    A = g.base_points + np.random.default_rng(1).normal(scale=1e-3, size=(n, 6, 3))
    r = DynamicRobots([g] * n, R, t, base_points=A)  # each row its own robot
    rows = np.arange(n)
    assert not r.advance(rows, np.random.default_rng(2).uniform(-0.05, 0.05, (n, 6)),
                         1e-3, 20).any()
    sub = np.array([4, 1, 5, 1])
    expected, _ = r.model.legs_batch(r.R[sub], r.t[sub], r.twist[sub], **r.rows(sub))
    assert np.abs(expected).max() > 1e-4  # the legs move
    assert r.leg_rates(sub).tobytes() == expected.tobytes()
    r.twist[1, 2] = np.nan
    with pytest.raises(ShapeError, match="twist"):
        r.leg_rates(sub)
