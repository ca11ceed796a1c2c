"""The lane-parallel C of a row-to-row CasADi function (hexapod.compiled_lanes): every
translated instruction gives CasADi's own result bit for bit (its virtual machine, lane by
lane), NaN and signed zeros included, for any number of rows and iterations, with and
without AVX2; an instruction it does not know leaves the caller on CasADi's path."""

from __future__ import annotations

import logging

import casadi as ca
import numpy as np
import pytest

from hexapod.compiled import LANE_ROWS, CompiledFunction
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
        ca.tanh(a) + ca.sin(b) * ca.cos(c) + ca.exp(-d * d) + ca.log(1 + c * c)
        + ca.atan2(a, d),
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
    f = ca.Function("lanes_fmod", [x], [ca.vertcat(ca.fmod(x[0], x[1]), x[1])])
    with pytest.raises(UnsupportedInstructionError, match="FMOD"):
        lane_code(f, "lanes_fmod")
    with caplog.at_level(logging.WARNING):
        assert LaneFunction.create(f, "lanes_fmod") is None
    assert "FMOD" in caplog.text


def test_a_function_must_map_a_row_to_a_row_of_its_width() -> None:
    x = ca.SX.sym("x", 3)
    with pytest.raises(ValueError, match="same width"):
        lane_code(ca.Function("lanes_bad", [x], [x[0:2]]), "lanes_bad")


@pytest.mark.parametrize("n", [1, 5, 9])
@pytest.mark.parametrize("avx2", [True, False])
def test_a_function_of_other_widths_is_evaluated_once(n: int, avx2: bool) -> None:
    """A row of 3 to a row of 5 and a row of 6 to a row of 2 (``same_width=False``):
    :meth:`LaneFunction.evaluate` gives CasADi's rows bit for bit, its input untouched."""
    x3, x6 = ca.SX.sym("x", 3), ca.SX.sym("x", 6)
    wide = ca.Function("lanes_wide", [x3], [ca.cse(ca.vertcat(
        x3[0] * x3[1], ca.sqrt(ca.fabs(x3[2])), x3[0], x3[1] - x3[2], ca.tanh(x3[2])))])
    narrow = ca.Function("lanes_narrow", [x6], [ca.vertcat(x6[5] / x6[0], x6[1] + x6[2])])
    rng = np.random.default_rng(n)
    for f in (wide, narrow):
        lanes = LaneFunction.create(f, f"hexapod_test_{f.name()}", same_width=False)
        assert lanes is not None
        x = rng.normal(size=(n, f.nnz_in(0)))
        keep = x.copy()
        got = lanes.evaluate(x, avx2=avx2)
        np.testing.assert_array_equal(got, _reference(f, x, 1))
        np.testing.assert_array_equal(x, keep)


def test_a_compiled_function_batches_by_lanes_when_asked() -> None:
    """:meth:`CompiledFunction.batch` with ``lanes=True``: from ``LANE_ROWS`` rows by its
    lane-parallel C, the numbers of its CasADi C; fewer rows by CasADi's C; with
    ``overwrite``, the same numbers in the input rows themselves (from ``LANE_ROWS``)."""
    x = ca.SX.sym("x", 4)
    f = ca.Function("hexapod_test_batch_lanes", [x], [ca.cse(ca.vertcat(
        x[0] * x[1] + x[2] / x[3], ca.sin(x[0]) - ca.sqrt(x[3] * x[3] + 1)))])
    cf = CompiledFunction(f)
    assert cf.lanes() is not None
    rng = np.random.default_rng(3)
    for n in (LANE_ROWS - 1, LANE_ROWS, 3 * LANE_ROWS + 1):
        X = rng.normal(size=(n, 4))
        np.testing.assert_array_equal(cf.batch(X, lanes=True), cf.batch(X))
        own = cf.batch(X)
        in_place = cf.batch(X, lanes=True, overwrite=True)
        assert in_place.tobytes() == own.tobytes()
        assert np.shares_memory(in_place, X) == (n >= LANE_ROWS)


def test_warm_cache_generates_no_code(probe: tuple[ca.Function, LaneFunction],
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A cached lane library is found by its key without generating its C, and the key
    changes with each thing the C is made from (the function's constants, the finishing
    function, the name, the width mode, this generator's source)."""
    import hexapod.compiled_lanes as compiled_lanes

    f, lanes = probe

    def no_code(*args: object, **kwargs: object) -> str:
        raise AssertionError("C generated on a warm cache")

    monkeypatch.setattr(compiled_lanes, "lane_code", no_code)
    again = LaneFunction.create(f, "hexapod_test_lanes_probe")
    assert again is not None
    x = np.random.default_rng(0).normal(size=(5, 8))
    x[:, 7] = np.abs(x[:, 7]) + 0.5
    assert np.array_equal(again.evaluate(x), lanes.evaluate(x))
    y = ca.SX.sym("y", 8)
    g = ca.Function("lanes_probe", [y], [f(y) * 1.5])
    keys = {compiled_lanes.lane_key(f, "a"), compiled_lanes.lane_key(g, "a"),
            compiled_lanes.lane_key(f, "b"), compiled_lanes.lane_key(f, "a", same_width=False),
            compiled_lanes.lane_key(f, "a", finish=g)}
    monkeypatch.setattr(compiled_lanes, "_generator_source", lambda: "another generator")
    keys.add(compiled_lanes.lane_key(f, "a"))
    assert len(keys) == 6
