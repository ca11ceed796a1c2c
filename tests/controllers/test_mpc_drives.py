"""The predictive controllers' model of lagging velocity drives (``drive_model = "lag"``).

The predicted leg lengths are checked against the drive they model integrated
numerically (each leg's velocity ``v' = omega (u - v)`` by RK4 on a fine grid), not
against the closed form the kernel uses; the QP data against central differences of
the kernel's own cost and constraint values; the limit of an infinitely fast drive
against the ideal prediction.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from controllers.exceptions import OptionError
from controllers.mpc.drive_state import drive_lag
from tests.controllers.controller_world import World, make_camera

DT = 0.02


def _geometry(geometry, bandwidth_hz: float, mode: str = "velocity"):  # type: ignore[no-untyped-def]
    drives = replace(geometry.drives, velocity_bandwidth=np.full(6, bandwidth_hz), mode=mode)
    return replace(geometry, drives=drives)


def _fresh(geometry, bandwidth_hz: float = 8.0, horizon: int = 5, **options):  # type: ignore[no-untyped-def]
    """A reset ``leg-edge-mpc`` with the lag model and its first observation (a pose
    near its goal)."""
    from controllers import registry

    world = World(_geometry(geometry, bandwidth_hz), make_camera("unified", geometry))
    Rs, ts = world.poses(2, np.random.default_rng(3), margin=0.02)
    ctrl = registry.create("leg-edge-mpc", horizon=horizon, drive_model="lag",
                           compiled=False, **options)
    ctrl.reset(world.context(world.goal(Rs[1], ts[1]), DT))
    return ctrl, world.observation(Rs[0], ts[0])


def _stepped(geometry, bandwidth_hz: float, model: str, v0: np.ndarray | None,  # type: ignore[no-untyped-def]
             horizon: int = 5, **options):
    """:func:`_fresh` (one SQP iteration) after one step, with ``q_dot = v0``."""
    ctrl, obs = _fresh(geometry, bandwidth_hz, horizon, model=model, max_iter=1, **options)
    ctrl.step(obs if v0 is None else replace(obs, q_dot=v0))
    return ctrl, obs


def _kernel(ctrl, U: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    vec = ctrl._vec.copy()
    vec[ctrl._lay.slices["U"]] = U
    return np.asarray(ctrl._kernel.single(vec))


def _rk4_lengths(q0: np.ndarray, v0: np.ndarray, setpoints: np.ndarray, omega: np.ndarray,
                 substeps: int = 400) -> np.ndarray:
    """Leg lengths at the end of each period: ``q' = v``, ``v' = omega (u_k - v)``, RK4."""
    return _rk4(q0, v0, setpoints, omega, substeps)[0]


def _rk4(q0: np.ndarray, v0: np.ndarray, setpoints: np.ndarray, omega: np.ndarray,
         substeps: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Leg lengths and velocities at the end of each period (see :func:`_rk4_lengths`)."""
    h = DT / substeps
    q, v = q0.copy(), v0.copy()
    out, vel = [], []
    def f(qv: tuple[np.ndarray, np.ndarray], u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return qv[1], omega * (u - qv[1])

    for u in setpoints:
        for _ in range(substeps):
            k1 = f((q, v), u)
            k2 = f((q + h / 2 * k1[0], v + h / 2 * k1[1]), u)
            k3 = f((q + h / 2 * k2[0], v + h / 2 * k2[1]), u)
            k4 = f((q + h * k3[0], v + h * k3[1]), u)
            q = q + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            v = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        out.append(q)
        vel.append(v)
    return np.array(out), np.array(vel)


@pytest.mark.parametrize("bandwidth_hz", [2.0, 8.0, 50.0])
def test_local_prediction_is_the_lagging_drive(geometry, bandwidth_hz: float) -> None:  # type: ignore[no-untyped-def]
    """Local model: the predicted lengths of stage k are those of six first-order drives
    started at the measured velocities and fed the setpoints ``J_0 tau_j`` (RK4, 400
    substeps a period: its own error below 1e-13 m here)."""
    rng = np.random.default_rng(int(bandwidth_hz))
    v0 = rng.normal(scale=0.01, size=6)
    N = 5
    ctrl, _ = _stepped(geometry, bandwidth_hz, "local", v0, horizon=N)
    spec, o = ctrl._spec, ctrl._out.slices
    J0 = ctrl._vec[ctrl._lay.slices["J0"]].reshape(6, 6)
    q0 = ctrl._vec[ctrl._lay.slices["q0"]]
    U = (rng.normal(size=(N, 6)) * np.array([0.01, 0.01, 0.01, 0.05, 0.05, 0.05]))
    values = _kernel(ctrl, U.reshape(-1))[o["values"]]
    predicted = np.array([values[k * spec.stage_rows:k * spec.stage_rows + 6]
                          for k in range(N)])
    truth = _rk4_lengths(q0, v0, U @ J0.T, np.full(6, 2 * np.pi * bandwidth_hz))
    np.testing.assert_allclose(predicted, truth, rtol=0, atol=1e-12)
    ideal = q0 + DT * np.cumsum(U @ J0.T, axis=0)
    assert np.abs(ideal - truth).max() > 1e-6  # the lag is visible at these bandwidths


@pytest.mark.parametrize("model", ["local", "global"])
def test_lag_qp_data_match_finite_differences(geometry, model: str) -> None:  # type: ignore[no-untyped-def]
    """With the lag model the condensed QP is still the Gauss-Newton model of the cost
    (``2 g`` its gradient) and ``C`` the Jacobian of the constraint values, by central
    differences at a random ``U``; a slow drive (3 Hz) so that every lag term counts."""
    rng = np.random.default_rng(11)
    ctrl, _ = _stepped(geometry, 3.0, model, rng.normal(scale=0.01, size=6), horizon=4)
    spec, o = ctrl._spec, ctrl._out.slices
    n, m = 24, spec.rows
    U = (rng.normal(size=(4, 6)) * np.array([0.02, 0.02, 0.02, 0.1, 0.1, 0.1])).reshape(-1)
    out = _kernel(ctrl, U)
    g, C = out[o["g"]], out[o["C"]].reshape(m, n)
    stage = spec.horizon * spec.stage_rows
    h = 1e-6
    for j in range(n):
        du = np.zeros(n)
        du[j] = h
        op, om = _kernel(ctrl, U + du), _kernel(ctrl, U - du)
        grad = (op[o["cost"]][0] - om[o["cost"]][0]) / (2 * h)
        assert abs(grad - 2 * g[j]) <= 1e-6 * max(1.0, abs(grad)), (j, grad, 2 * g[j])
        col = (op[o["values"]] - om[o["values"]]) / (2 * h)
        np.testing.assert_allclose(C[:stage, j], col[:stage], rtol=1e-5,
                                   atol=1e-6 * (1 + np.abs(col[:stage]).max()))


@pytest.mark.parametrize("model", ["local", "global"])
def test_an_infinitely_fast_drive_is_the_ideal_prediction(geometry, model: str) -> None:  # type: ignore[no-untyped-def]
    """At 1e10 Hz the lag model's QP data equal the ideal model's (same state, same ``U``):
    the lag costs ``c = 1 / omega`` = 1.6e-11 s of each 20 ms period (8e-10 relative)."""
    from controllers import registry

    rng = np.random.default_rng(5)
    v0 = rng.normal(scale=0.01, size=6)
    lag, obs = _stepped(geometry, 1e10, model, v0, horizon=4)
    ideal = registry.create("leg-edge-mpc", model=model, horizon=4, compiled=False, max_iter=1)
    ideal.reset(lag.context)
    ideal.step(replace(obs, q_dot=v0))
    U = (rng.normal(size=(4, 6)) * np.array([0.02, 0.02, 0.02, 0.1, 0.1, 0.1])).reshape(-1)
    vec = ideal._vec.copy()
    vec[ideal._lay.slices["U"]] = U
    a = np.asarray(ideal._kernel.single(vec))
    b = _kernel(lag, U)
    for key in ("cost", "H", "g", "C", "lba", "uba"):
        s = ideal._out.slices[key]
        np.testing.assert_allclose(b[s], a[s], rtol=1e-8, atol=1e-12 * (1 + np.abs(a[s]).max()),
                                   err_msg=key)


def test_the_drive_state_without_measured_velocities(geometry) -> None:  # type: ignore[no-untyped-def]
    """``drive_state = "model"``: the lag's run on the setpoints it commanded
    (``v_{k+1} = a v_k + (1 - a) u_k``, from rest at reset), whatever is measured. The
    default ``"measured"`` takes ``q_dot`` when it is finite, else the reconstruction
    from the encoder lengths (as ``"encoders"`` would give), never a NaN command."""
    from controllers.mpc.drive_state import DriveLag

    ctrl, obs = _fresh(geometry, drive_state="model")
    a = ctrl.drives.a
    v0_slice = ctrl._lay.slices["v0"]
    u0 = ctrl.step(obs).velocities
    np.testing.assert_array_equal(ctrl._vec[v0_slice], np.zeros(6))
    u1 = ctrl.step(replace(obs, q_dot=np.full(6, 0.003))).velocities  # ignored
    np.testing.assert_allclose(ctrl._vec[v0_slice], (1 - a) * u0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(ctrl.drives.velocities, a * (1 - a) * u0 + (1 - a) * u1,
                               rtol=0, atol=1e-15)
    assert np.abs(u0).max() > 1e-4 and np.abs(u1 - u0).max() > 0

    measured, _ = _fresh(geometry)
    reconstruct = DriveLag(measured.drives.a, measured.drives.c, DT, "encoders")
    v = np.full(6, 0.003)
    u = measured.step(replace(obs, q_dot=v)).velocities
    np.testing.assert_array_equal(measured._vec[v0_slice], v)
    reconstruct.sent(v, obs.lengths, u)
    moved = replace(obs, lengths=obs.lengths + 1e-5)
    want = reconstruct.now(moved.lengths, None)
    for q_dot in (None, np.array([0.001, np.nan, 0, 0, 0, 0])):
        fresh, _ = _fresh(geometry)
        fresh.step(replace(obs, q_dot=v))
        cmd = fresh.step(replace(moved, q_dot=q_dot))
        np.testing.assert_allclose(fresh._vec[v0_slice], want, rtol=0, atol=1e-15)
        assert cmd.reason is None and np.all(np.isfinite(cmd.velocities))
    assert np.abs(want - a * v - (1 - a) * u).max() > 1e-4  # not the lag's run


def test_lag_model_refused_on_force_drives(geometry) -> None:  # type: ignore[no-untyped-def]
    """Force-mode drives have no velocity loop to lag: the option is refused, naming it."""
    from controllers import registry

    world = World(_geometry(geometry, 50.0, mode="force"), make_camera("unified", geometry))
    Rs, ts = world.poses(2, np.random.default_rng(3), margin=0.02)
    ctrl = registry.create("leg-edge-mpc", drive_model="lag", compiled=False)
    with pytest.raises(OptionError, match=r"drive_model.*force"):
        ctrl.reset(world.context(world.goal(Rs[1], ts[1]), DT))
    with pytest.raises(OptionError, match="drive_model"):
        registry.create("leg-edge-mpc", drive_model="second-order")
    with pytest.raises(OptionError, match="drive_state"):
        registry.create("leg-edge-mpc", drive_model="lag", drive_state="estimated")


def test_drive_lag_constants(geometry) -> None:  # type: ignore[no-untyped-def]
    """``a = exp(-omega dt)``, ``c = (1 - a) / omega``: c is the time a step of the
    setpoint loses over one period (the integral of ``1 - exp(-omega t)`` is
    ``dt - c``), checked by quadrature."""
    world = World(_geometry(geometry, 12.0), make_camera("unified", geometry))
    Rs, ts = world.poses(1, np.random.default_rng(3), margin=0.02)
    a, c = drive_lag(world.context(world.goal(Rs[0], ts[0]), DT), DT, "x")
    omega = 2 * np.pi * 12.0
    t = np.linspace(0.0, DT, 200_001)
    moved = np.trapezoid(1 - np.exp(-omega * t), t)
    np.testing.assert_allclose(c, DT - moved, rtol=1e-8)
    np.testing.assert_allclose(a, np.exp(-omega * DT), rtol=1e-15)


def test_the_feed_forward_offset_makes_the_prediction_relative(geometry) -> None:  # type: ignore[no-untyped-def]
    """``velocity_offset(ff)`` before a step (the tracking wrapper's feed-forward): the
    prediction starts from the measured velocities minus ``ff`` (the legs relative to
    the moving goal), the lag model's own estimate runs on the command plus ``ff``, and
    the offset holds for that step only."""
    ctrl, obs = _fresh(geometry, horizon=4)
    a = ctrl.drives.a
    v0_slice = ctrl._lay.slices["v0"]
    v = np.linspace(-0.004, 0.006, 6)
    ff = np.full(6, 0.002)
    ctrl.velocity_offset(ff)
    u = ctrl.step(replace(obs, q_dot=v)).velocities
    np.testing.assert_allclose(ctrl._vec[v0_slice], v - ff, rtol=0, atol=1e-18)
    np.testing.assert_allclose(ctrl.drives.velocities, a * v + (1 - a) * (u + ff), rtol=0,
                               atol=1e-15)
    ctrl.step(replace(obs, q_dot=v))
    np.testing.assert_array_equal(ctrl._vec[v0_slice], v)


@pytest.mark.parametrize("bandwidth_hz", [3.0, 50.0])
def test_the_encoders_give_the_drives_velocity(bandwidth_hz: float) -> None:
    """``drive_state = "encoders"``: from the encoder lengths alone (and the setpoints
    sent), the leg velocities now are those of six first-order drives integrated by RK4,
    from an unknown start velocity and an encoder offset, from the second step on."""
    from controllers.mpc.drive_state import DriveLag

    rng = np.random.default_rng(int(bandwidth_hz))
    omega = np.full(6, 2 * np.pi * bandwidth_hz)
    a = np.exp(-omega * DT)
    lag = DriveLag(a, (1 - a) / omega, DT, "encoders")
    setpoints = rng.normal(scale=0.01, size=(8, 6))
    v_start = rng.normal(scale=0.01, size=6)
    q, v = _rk4(np.full(6, 0.4), v_start, setpoints, omega)
    offset = rng.normal(scale=1e-3, size=6)  # the encoders' zero error
    lengths = np.vstack([np.full(6, 0.4), q]) + offset
    velocities = np.vstack([v_start, v])
    for k in range(len(setpoints)):
        now = lag.now(lengths[k], None)
        if k == 0:
            np.testing.assert_array_equal(now, np.zeros(6))  # nothing yet: the lag's run
        else:
            np.testing.assert_allclose(now, velocities[k], rtol=0, atol=1e-10)
        lag.sent(now, lengths[k], setpoints[k])
