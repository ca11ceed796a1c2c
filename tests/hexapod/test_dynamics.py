"""Tests of hexapod.dynamics.DynamicModel: the compiled model against the Pinocchio
closed-chain reference, and both against independent physics (Newton-Euler of the
platform with massless legs, energy conservation, power balance, virtual work)."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod import HexapodGeometry, inverse_kinematics, sample_poses
from hexapod.dynamics import DynamicModel
from hexapod.dynamics.reference import ReferenceDynamics
from hexapod.exceptions import DynamicsError, ShapeError
from hexapod.kinematics import leg_directions
from hexapod.se3 import exp_so3


def _lopsided(g: HexapodGeometry) -> HexapodGeometry:
    """The robot with a general inertia: CoM off the origin, products of inertia,
    heavier legs with other centres of mass, gravity not along z."""
    inertia = g.inertia.replace(
        platform_mass=3.1, platform_com=np.array([0.012, -0.02, 0.03]),
        platform_inertia=np.array([0.03, 0.04, 0.05, 0.002, -0.001, 0.003]),
        body_mass=0.7, body_com=0.11, body_inertia=np.array([0.006, 0.0002]),
        rod_mass=0.35, rod_com=0.2, rod_inertia=np.array([0.002, 0.00005]),
        gravity=np.array([0.3, -0.2, -9.81]))
    return g.replace(inertia=inertia)


def _states(g: HexapodGeometry, n: int, rng: np.random.Generator
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    R, t = sample_poses(g, n, rng=rng)
    twist = np.concatenate([rng.normal(scale=0.1, size=(n, 3)),
                            rng.normal(scale=0.5, size=(n, 3))], axis=1)
    forces = rng.normal(scale=30.0, size=(n, 6))
    return R, t, twist, forces


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("robot", ["reference", "other-lopsided", "massless"])
def test_compiled_equals_pinocchio_reference(geometry: HexapodGeometry,
                                             other_geometry: HexapodGeometry,
                                             rng: np.random.Generator, robot: str) -> None:
    g = {"reference": geometry, "other-lopsided": _lopsided(other_geometry),
         "massless": _lopsided(geometry).replace(
             inertia=_lopsided(geometry).inertia.massless())}[robot]
    fast, ref = DynamicModel(g), DynamicModel(g, method="pinocchio")
    R, t, twist, forces = _states(g, 12, rng)
    acc = fast.forward_batch(R, t, twist, forces)
    acc_ref = ref.forward_batch(R, t, twist, forces)
    assert np.all(np.linalg.norm(twist, axis=1) > 0.1)
    assert np.all(np.linalg.norm(acc_ref, axis=1) > 1.0)  # not a trivial comparison
    worst = max(_rel(acc[k], acc_ref[k]) for k in range(len(t)))
    assert worst < 1e-9
    f_back = ref.inverse_batch(R, t, twist, acc_ref)
    assert max(_rel(f_back[k], forces[k]) for k in range(len(t))) < 1e-9
    f_fast = fast.inverse_batch(R, t, twist, acc_ref)
    assert max(_rel(f_fast[k], forces[k]) for k in range(len(t))) < 1e-9
    M, M_ref = fast.mass_matrix_batch(R, t), ref.mass_matrix_batch(R, t)
    assert max(_rel(M[k], M_ref[k]) for k in range(len(t))) < 1e-9
    E, E_ref = fast.energy_batch(R, t, twist), ref.energy_batch(R, t, twist)
    np.testing.assert_allclose(E, E_ref, rtol=1e-9)


def test_single_state_api_matches_batch(geometry: HexapodGeometry,
                                        rng: np.random.Generator) -> None:
    dyn = DynamicModel(geometry)
    R, t, twist, forces = _states(geometry, 3, rng)
    acc = dyn.forward(R[1], t[1], twist[1], forces[1])
    assert acc.shape == (6,)
    np.testing.assert_array_equal(acc, dyn.forward_batch(R, t, twist, forces)[1])
    assert dyn.mass_matrix(R[1], t[1]).shape == (6, 6)
    assert isinstance(dyn.energy(R[1], t[1], twist[1]), float)


def test_constraint_dynamics_equals_dense_kkt(other_geometry: HexapodGeometry,
                                              rng: np.random.Generator) -> None:
    """Two routes through Pinocchio: constraintDynamics and the dense KKT system."""
    g = _lopsided(other_geometry)
    ref = ReferenceDynamics(g)
    R, t, twist, forces = _states(g, 5, rng)
    for k in range(5):
        a = ref.forward(R[k], t[k], twist[k], forces[k])
        assert _rel(a, ref.forward_kkt(R[k], t[k], twist[k], forces[k])) < 1e-11


def test_reference_legs_close_the_loops(geometry: HexapodGeometry,
                                        rng: np.random.Generator) -> None:
    """The reference's leg velocities keep every loop closed, with no spin."""
    ref = ReferenceDynamics(geometry)
    R, t, twist, _ = _states(geometry, 1, rng)
    q, v, J = ref.state(R[0], t[0], twist[0])
    assert np.abs(ref.hm.constraint_residual(q)).max() < 1e-12
    assert np.abs(J @ v).max() < 1e-12
    spins = [v[ref.model.joints[j].idx_v + 2] for j in ref.hm.spherical_joints]
    assert np.abs(spins).max() < 1e-12


@pytest.mark.parametrize("method", ["compiled", "pinocchio"])
def test_forward_of_inverse_is_identity(other_geometry: HexapodGeometry,
                                        rng: np.random.Generator, method: str) -> None:
    g = _lopsided(other_geometry)
    dyn = DynamicModel(g, method=method)  # type: ignore[arg-type]
    R, t, twist, _ = _states(g, 6, rng)
    acc = np.concatenate([rng.normal(scale=2.0, size=(6, 3)),
                          rng.normal(scale=5.0, size=(6, 3))], axis=1)
    back = dyn.forward_batch(R, t, twist, dyn.inverse_batch(R, t, twist, acc))
    np.testing.assert_allclose(back, acc, rtol=0, atol=1e-10 * np.abs(acc).max())


def _newton_euler(g: HexapodGeometry, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                  forces: np.ndarray) -> np.ndarray:
    """The platform alone, pushed by six forces along the legs at B_i, written out:
    m (a_o + dw x r + w x (w x r)) = sum f_i u_i + m g,
    I dw + w x I w + m r x (a_o + w x (w x r)) ... taken about the CoM."""
    ine = g.inertia
    m = ine.platform_mass
    r = R @ ine.platform_com                       # CoM from the platform origin
    I_c = R @ ine.platform_tensor @ R.T             # about the CoM, base axes
    w = twist[3:]
    u = leg_directions(g, R, t)
    b = g.platform_points @ R.T                     # B_i from the platform origin
    push = forces[:, None] * u
    F = push.sum(axis=0) + m * ine.gravity
    torque_c = np.cross(b - r, push).sum(axis=0)    # about the CoM
    # unknowns a_o (origin acceleration) and dw:
    #   m a_o - m [r]x dw = F - m w x (w x r)        (a_c = a_o + dw x r + w x (w x r))
    #   I_c dw = torque_c - w x I_c w
    rx = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    lhs = np.zeros((6, 6))
    lhs[:3, :3] = m * np.eye(3)
    lhs[:3, 3:] = -m * rx
    lhs[3:, 3:] = I_c
    rhs = np.concatenate([F - m * np.cross(w, np.cross(w, r)), torque_c - np.cross(w, I_c @ w)])
    return np.linalg.solve(lhs, rhs)


@pytest.mark.parametrize("method", ["compiled", "pinocchio"])
def test_massless_legs_equal_platform_newton_euler(geometry: HexapodGeometry,
                                                   rng: np.random.Generator,
                                                   method: str) -> None:
    g = _lopsided(geometry)
    g = g.replace(inertia=g.inertia.massless())
    dyn = DynamicModel(g, method=method)  # type: ignore[arg-type]
    R, t, twist, forces = _states(g, 6, rng)
    for k in range(6):
        expected = _newton_euler(g, R[k], t[k], twist[k], forces[k])
        assert _rel(dyn.forward(R[k], t[k], twist[k], forces[k]), expected) < 1e-11
        assert _rel(dyn.inverse(R[k], t[k], twist[k], expected), forces[k]) < 1e-11


def _rk4(dyn: DynamicModel, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
         forces: np.ndarray, dt: float, steps: int
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Classical RK4 on (R as 9 numbers, t, twist) with R_dot = [w]x R, t_dot = v."""
    def f(R: np.ndarray, t: np.ndarray, tw: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w = tw[3:]
        wx = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        return wx @ R, tw[:3], dyn.forward(R, t, tw, forces)

    for _ in range(steps):
        k1 = f(R, t, twist)
        k2 = f(*(x + 0.5 * dt * k for x, k in zip((R, t, twist), k1, strict=True)))
        k3 = f(*(x + 0.5 * dt * k for x, k in zip((R, t, twist), k2, strict=True)))
        k4 = f(*(x + dt * k for x, k in zip((R, t, twist), k3, strict=True)))
        R, t, twist = (x + dt / 6 * (a + 2 * b + 2 * c + d)
                       for x, a, b, c, d in zip((R, t, twist), k1, k2, k3, k4, strict=True))
    return R, t, twist


def test_energy_conserved_in_free_motion(geometry: HexapodGeometry,
                                         rng: np.random.Generator) -> None:
    """No gravity, no force: RK4 at 1 ms over 1 s keeps the energy to 1e-12 relative
    (measured: about 2e-16 here; ``hexapod-bench perf dynamics --energy``)."""
    g = _lopsided(geometry)
    g = g.replace(inertia=g.inertia.replace(gravity=np.zeros(3)))
    dyn = DynamicModel(g)
    R, t, _, _ = _states(g, 1, rng)
    twist = np.array([0.02, -0.01, 0.015, 0.2, -0.3, 0.25])
    E0 = dyn.energy(R[0], t[0], twist)
    R1, t1, tw1 = _rk4(dyn, R[0], t[0], twist, np.zeros(6), 1e-3, 1000)
    q0, q1 = inverse_kinematics(g, R[0], t[0]), inverse_kinematics(g, R1, t1)
    assert np.abs(q1 - q0).max() > 5e-3       # the robot did move
    assert np.abs(R1.T @ R1 - np.eye(3)).max() < 1e-9
    assert abs(dyn.energy(R1, t1, tw1) - E0) < 1e-12 * E0


def test_energy_balance_with_constant_forces(geometry: HexapodGeometry,
                                             rng: np.random.Generator) -> None:
    """dE/dt = sum f_i dq_i/dt; with constant forces, E(T) - E(0) = f . (q(T) - q(0))."""
    g = _lopsided(geometry)
    dyn = DynamicModel(g)
    R, t, _, _ = _states(g, 1, rng)
    hold = dyn.inverse(R[0], t[0], np.zeros(6), np.zeros(6))
    forces = hold + rng.normal(scale=1.0, size=6)
    twist = np.array([0.01, 0.02, -0.01, 0.1, 0.05, -0.1])
    E0 = dyn.energy(R[0], t[0], twist)
    R1, t1, tw1 = _rk4(dyn, R[0], t[0], twist, forces, 1e-3, 500)
    work = forces @ (inverse_kinematics(g, R1, t1) - inverse_kinematics(g, R[0], t[0]))
    gained = dyn.energy(R1, t1, tw1) - E0
    assert abs(work) > 1e-2
    assert abs(gained - work) < 1e-9 * max(abs(work), E0)
    # and instantaneously, by central differences of short RK4 runs
    h = 1e-5
    Ra, ta, twa = _rk4(dyn, R[0], t[0], twist, forces, h, 1)
    Rb, tb, twb = _rk4(dyn, R[0], t[0], twist, forces, -h, 1)
    dE = (dyn.energy(Ra, ta, twa) - dyn.energy(Rb, tb, twb)) / (2 * h)
    dq = (inverse_kinematics(g, Ra, ta) - inverse_kinematics(g, Rb, tb)) / (2 * h)
    assert dE == pytest.approx(forces @ dq, rel=1e-6)


@pytest.mark.parametrize("method", ["compiled", "pinocchio"])
def test_static_forces_equal_virtual_work(other_geometry: HexapodGeometry,
                                          rng: np.random.Generator, method: str) -> None:
    """At rest, the forces holding a pose satisfy dV = f . dq for every displacement
    (finite differences of the potential energy and of the leg lengths)."""
    g = _lopsided(other_geometry)
    dyn = DynamicModel(g, method=method)  # type: ignore[arg-type]
    R, t, _, _ = _states(g, 1, rng)
    R, t = R[0], t[0]
    hold = dyn.inverse(R, t, np.zeros(6), np.zeros(6))
    eps = 1e-6
    dV, dq = np.empty(6), np.empty((6, 6))
    for k, e in enumerate(np.eye(6)):
        plus = (exp_so3(eps * e[3:]) @ R, t + eps * e[:3])
        minus = (exp_so3(-eps * e[3:]) @ R, t - eps * e[:3])
        dV[k] = (dyn.energy(*plus, np.zeros(6)) - dyn.energy(*minus, np.zeros(6))) / (2 * eps)
        dq[k] = (inverse_kinematics(g, *plus) - inverse_kinematics(g, *minus)) / (2 * eps)
    virtual = np.linalg.solve(dq, dV)
    np.testing.assert_allclose(hold, virtual, rtol=1e-6, atol=1e-6 * np.abs(hold).max())
    assert np.abs(hold).max() > 1.0


def test_lcaba_agrees_with_constraint_dynamics(geometry: HexapodGeometry,
                                               rng: np.random.Generator) -> None:
    """lcaba (proximal, mu = 1e-3, 50 iterations, its own datas) agrees to 1e-9."""
    ref = ReferenceDynamics(geometry)
    R, t, twist, forces = _states(geometry, 4, rng)
    worst = max(_rel(ref.forward_lcaba(R[k], t[k], twist[k], forces[k]),
                     ref.forward(R[k], t[k], twist[k], forces[k])) for k in range(4))
    assert worst < 1e-9


def test_bad_input_is_refused(geometry: HexapodGeometry, rng: np.random.Generator) -> None:
    dyn = DynamicModel(geometry)
    R, t, twist, forces = _states(geometry, 2, rng)
    bad = forces.copy()
    bad[1, 4] = np.nan
    with pytest.raises(ShapeError, match="forces"):
        dyn.forward_batch(R, t, twist, bad)
    with pytest.raises(ShapeError, match="twist"):
        dyn.forward(R[0], t[0], twist[0, :5], forces[0])
    with pytest.raises(ValueError, match="unknown dynamics method"):
        DynamicModel(geometry, method="mujoco")  # type: ignore[arg-type]
    # A scaled or mirrored matrix is no orientation: its forces would be of no robot.
    scaled, mirrored = R.copy(), R.copy()
    scaled[1] *= 1.01
    mirrored[0, :, 2] *= -1
    for method in ("compiled", "pinocchio"):
        model = DynamicModel(geometry, method=method)  # type: ignore[arg-type]
        with pytest.raises(ShapeError, match=r"R: expected rotation matrices.*det from"):
            model.forward_batch(scaled, t, twist, forces)
        with pytest.raises(ShapeError, match=r"R: expected rotation.*det from -1 to -1"):
            model.inverse(mirrored[0], t[0], twist[0], forces[0])
        with pytest.raises(ShapeError, match="R: expected rotation"):
            model.mass_matrix(scaled[1], t[1])
    # Every leg through one platform point: no force balances a torque about it.
    with pytest.raises(DynamicsError, match="state 0"):
        dyn.inverse_batch(R, t, twist, forces, platform_points=np.zeros((2, 6, 3)))


def test_added_leg_mass_equals_pinocchio_armature(other_geometry: HexapodGeometry,
                                                  rng: np.random.Generator) -> None:
    """A mass moving with each leg's length (reflected rotor inertia) is Pinocchio's
    armature on the prismatic joints."""
    g = _lopsided(other_geometry)
    a = np.array([2.5, 1.0, 3.0, 0.5, 2.0, 4.0])
    ref = ReferenceDynamics(g, armature=a)
    R, t, twist, forces = _states(g, 6, rng)
    acc, _, _ = DynamicModel(g).forward_drives_batch(R, t, twist, forces, a)
    for k in range(6):
        expected = ref.forward(R[k], t[k], twist[k], forces[k])
        assert _rel(acc[k], expected) < 1e-9
        assert _rel(acc[k], DynamicModel(g).forward(R[k], t[k], twist[k], forces[k])) > 1e-3


def test_leg_rates_and_bias_are_derivatives_of_leg_lengths(geometry: HexapodGeometry,
                                                           rng: np.random.Generator) -> None:
    """Under a constant twist (acc = 0), q(s) = IK(exp(s w) R, t + s v): its first and
    second derivatives are q_dot and K_dot twist."""
    dyn = DynamicModel(geometry)
    R, t, twist, _ = _states(geometry, 3, rng)
    q_dot, bias = dyn.legs_batch(R, t, twist)
    h = 1e-4
    for k in range(3):
        def q(s: float, k: int = k) -> np.ndarray:
            return inverse_kinematics(geometry, exp_so3(s * twist[k, 3:]) @ R[k],
                                      t[k] + s * twist[k, :3])
        np.testing.assert_allclose(q_dot[k], (q(h) - q(-h)) / (2 * h), rtol=1e-6, atol=1e-10)
        np.testing.assert_allclose(bias[k], (q(h) - 2 * q(0.0) + q(-h)) / h**2, rtol=1e-4,
                                   atol=1e-7)
        assert np.abs(bias[k]).max() > 1e-3


def test_leg_rates_and_jacobian_kernels_are_the_terms_kernels_bitwise(
        geometry: HexapodGeometry, rng: np.random.Generator) -> None:
    """legs_batch evaluates the leg rates and their bias alone (the "legs" kernel, a
    tenth of the "terms" kernel) and jacobian_batch the inverse Jacobian alone: the
    same numbers as the "terms" kernel's, to the last bit, on the model's robot and on
    per-state robots (a study's true worlds)."""
    from hexapod.dynamics import compiled as dyn_compiled

    dyn = DynamicModel(geometry)
    R, t, twist, _ = _states(geometry, 40, rng)
    A = geometry.base_points + rng.normal(scale=1e-3, size=(40, 6, 3))
    E = geometry.platform_points + rng.normal(scale=1e-3, size=(40, 6, 3))
    for overrides in ({}, {"base_points": A, "platform_points": E}):
        q_dot, bias = dyn.legs_batch(R, t, twist, **overrides)
        terms = dyn_compiled.OUTPUTS["terms"].views(dyn_compiled.compiled("terms").batch(
            dyn.rows(R, t, twist, np.zeros((40, 6)), **overrides)))
        assert q_dot.tobytes() == np.ascontiguousarray(terms["q_dot"]).tobytes()
        assert bias.tobytes() == np.ascontiguousarray(terms["leg_bias"]).tobytes()
        assert np.abs(q_dot).max() > 1e-3
        K = dyn.jacobian_batch(R, t, **overrides)  # K alone, from the pose (any twist)
        assert K.tobytes() == np.ascontiguousarray(dyn.terms_batch(R, t, twist,
                                                                   **overrides)[2]).tobytes()
        # both from one packed input (the twist given): the two calls' numbers
        K2, q_dot2, bias2 = dyn.legs_jacobian_batch(R, t, twist, **overrides)
        assert K2.tobytes() == K.tobytes()
        assert q_dot2.tobytes() == q_dot.tobytes() and bias2.tobytes() == bias.tobytes()
    bad = twist.copy()
    bad[3, 4] = np.nan
    with pytest.raises(ShapeError, match="twist"):  # named, as legs_batch names it
        dyn.legs_jacobian_batch(R, t, bad)


def test_implicit_mass_takes_a_damping_force_implicitly(geometry: HexapodGeometry,
                                                        rng: np.random.Generator) -> None:
    """With b = c dt, the acceleration is the fixed point of the damping force taken at
    the end-of-step leg rates: f = f0 - c (q_dot + dt K acc)."""
    dyn = DynamicModel(geometry)
    R, t, twist, f0 = _states(geometry, 4, rng)
    a, c, dt = np.full(6, 2.5), np.full(6, 400.0), 1e-3
    q_dot, bias = dyn.legs_batch(R, t, twist)
    acc, q_dot2, q_ddot = dyn.forward_drives_batch(R, t, twist, f0 - c * q_dot, a, c * dt)
    np.testing.assert_array_equal(q_dot2, q_dot)
    end_forces = f0 - c * (q_dot + dt * (q_ddot - bias))
    again, _, _ = dyn.forward_drives_batch(R, t, twist, end_forces, a)
    np.testing.assert_allclose(again, acc, rtol=1e-10, atol=1e-10 * np.abs(acc).max())
    explicit, _, _ = dyn.forward_drives_batch(R, t, twist, f0 - c * q_dot, a)
    assert np.abs(explicit - acc).max() > 1e-3 * np.abs(acc).max()
