"""The adaptive gain has one definition (``gain_formula``) for the per-trial laws (numbers)
and the compiled cores (CasADi): both evaluations agree to the last bit, and the formula
has the properties that define it (ViSP's ``vpAdaptiveGain``): ``lambda(0) = lambda0``,
``lambda(x) -> lambda_inf`` for large errors, slope ``-lambda0'`` at zero (a
forward difference), constant when ``lambda0 = lambda_inf``."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from controllers.law_tools import Gain, gain_formula

GAINS = [Gain(4.0, 0.5, 30.0), Gain(2.0, 1.0, 0.3), Gain(1.5, 1.5, 0.0)]


@pytest.mark.parametrize("gain", GAINS)
def test_numbers_and_expressions_give_the_same_gain(gain: Gain) -> None:
    x, l0, linf, s = (ca.SX.sym(k) for k in ("x", "l0", "linf", "s"))
    f = ca.Function("gain", [x, l0, linf, s], [gain_formula(x, l0, linf, s, ca.exp, ca.if_else)])
    for value in (0.0, 1e-4, 0.01, 0.3, 2.0, 50.0):
        expr = float(f(value, gain.at_zero, gain.at_infinity, gain.slope_at_zero))
        assert expr == gain(value)


@pytest.mark.parametrize("gain", GAINS)
def test_the_gain_has_its_defining_properties(gain: Gain) -> None:
    assert gain(0.0) == gain.at_zero
    assert abs(gain(1e6) - gain.at_infinity) < 1e-12
    h = 1e-6
    slope = (gain(h) - gain(0.0)) / h  # one-sided at the boundary x = 0
    expected = 0.0 if gain.at_zero == gain.at_infinity else -gain.slope_at_zero
    assert slope == pytest.approx(expected, rel=1e-4, abs=1e-9)
    xs = np.linspace(0.0, 10.0, 50)
    values = np.array([gain(x) for x in xs])
    assert np.all(np.diff(values) <= 0.0)  # never grows with the error


@pytest.mark.parametrize("values", [["5", "1", "30"], [True, 1.0, 30.0]])
def test_an_adaptive_gain_of_strings_or_booleans_is_refused(values: list[object]) -> None:
    """They were converted without a word (and the study's copy kept the strings)."""
    from controllers.exceptions import OptionError

    with pytest.raises(OptionError, match=r"adaptive_gain.*expected \(lambda0, lambda_inf, "
                                          r"lambda0'\)"):
        Gain.from_options("leg-edge", 1.0, values)  # type: ignore[arg-type]
