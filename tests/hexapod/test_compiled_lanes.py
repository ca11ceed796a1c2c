"""The lane-parallel C of a row-to-row CasADi function (hexapod.compiled_lanes): every
translated instruction gives CasADi's own result bit for bit (its virtual machine, lane by
lane), NaN and signed zeros included, for any number of rows and iterations, with and
without AVX2; an instruction it does not know leaves the caller on CasADi's path."""

from __future__ import annotations

import logging

import casadi as ca
import numpy as np
import pytest

from hexapod.compiled_lanes import LaneFunction, lane_code
from hexapod.exceptions import UnsupportedInstructionError


def _every_instruction() -> ca.Function:
    """A row of 8 to a row of 8 using every instruction the generator translates."""
    x = ca.SX.sym("x", 8)
    a, b, c, d = x[0], x[1], x[2], x[3]
    y = ca.vertcat(
        a * b + c / d - (a - 0.25),
        ca.if_else(a < b, ca.sqrt(ca.fabs(c)), 0) + ca.if_else(a <= c, 1.5, 0),
        ca.fmin(a, b) + ca.fmax(c, d) + ca.sign(a) + ca.sign(d),
        ca.tanh(a) + ca.sin(b) * ca.cos(c) + ca.exp(-d * d) + ca.log(1 + c * c),
        (a == b) + (c != d) + ca.logic_not(a) + ca.logic_and(a, b) + ca.logic_or(c, 0),
        1 / (x[4] + 3) + x[4] ** 2 + 2 * x[5] - x[6],
        ca.fmin(ca.fmax(x[6], -x[7]), x[7]),
        x[7])
    return ca.Function("lanes_probe", [x], [ca.cse(y)])


def _reference(f: ca.Function, x: np.ndarray, iterations: int) -> np.ndarray:
    out = np.array(x, dtype=float)
    for _ in range(iterations):
        out = np.array([np.asarray(f(row), dtype=float).ravel() for row in out])
    return out


@pytest.fixture(scope="module")
def probe() -> tuple[ca.Function, LaneFunction]:
    f = _every_instruction()
    lanes = LaneFunction.create(f, "hexapod_test_lanes_probe")
    assert lanes is not None
    return f, lanes


@pytest.mark.parametrize("n", [1, 3, 4, 7, 9])
@pytest.mark.parametrize("avx2", [True, False])
def test_rows_equal_casadi_bit_for_bit(probe: tuple[ca.Function, LaneFunction], n: int,
                                       avx2: bool) -> None:
    """Random rows (some repeated values, zeros of both signs, a NaN and infinities
    among them; any row count, not only whole lanes), three iterations."""
    f, lanes = probe
    rng = np.random.default_rng(n)
    x = rng.normal(0.0, 1.0, (n, 8))
    x[:, 7] = np.abs(x[:, 7]) + 0.5
    x[0, 1] = x[0, 0]                      # a == b
    if n > 2:
        x[1, 0], x[1, 3] = -0.0, 0.0       # signed zeros through sign, fmin, not
        x[2, 1] = np.nan                   # fmin/fmax ignore a NaN, the rest propagate it
        x[2, 6] = np.inf
    want = _reference(f, x, 3)
    got = lanes.iterate(x, 3, avx2=avx2)
    np.testing.assert_array_equal(got, want)
    assert np.array_equal(np.signbit(got), np.signbit(want))


def test_zero_iterations_copy_and_inputs_are_untouched(
        probe: tuple[ca.Function, LaneFunction]) -> None:
    _, lanes = probe
    x = np.random.default_rng(0).normal(size=(5, 8))
    keep = x.copy()
    np.testing.assert_array_equal(lanes.iterate(x, 0), x)
    lanes.iterate(x, 2)
    np.testing.assert_array_equal(x, keep)


def test_an_unknown_instruction_is_refused(caplog: pytest.LogCaptureFixture) -> None:
    x = ca.SX.sym("x", 2)
    f = ca.Function("lanes_atan2", [x], [ca.vertcat(ca.atan2(x[0], x[1]), x[1])])
    with pytest.raises(UnsupportedInstructionError, match="ATAN2"):
        lane_code(f, "lanes_atan2")
    with caplog.at_level(logging.WARNING):
        assert LaneFunction.create(f, "lanes_atan2") is None
    assert "ATAN2" in caplog.text


def test_a_function_must_map_a_row_to_a_row_of_its_width() -> None:
    x = ca.SX.sym("x", 3)
    with pytest.raises(ValueError, match="same width"):
        lane_code(ca.Function("lanes_bad", [x], [x[0:2]]), "lanes_bad")
