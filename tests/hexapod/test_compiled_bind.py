"""``CompiledFunction.bind``: the C function evaluated in place on the caller's own rows.

The oracle is :meth:`CompiledFunction.single` (its own buffers, copies in and out) and the
CasADi virtual machine evaluating the symbolic function; the bound call must give the
same numbers (bitwise: the same C code on the same input) into its own output row, and
bindings must not share buffers (one binding's call leaves another's rows untouched).
"""

from __future__ import annotations

import copy
import pickle

import casadi as ca
import numpy as np

from hexapod.compiled import CompiledFunction


def _function() -> ca.Function:
    x = ca.SX.sym("x", 5)
    y = ca.vertcat(ca.sin(x[0]) * x[1] + x[2] ** 3, ca.solve(ca.SX([[2.0, 1.0], [1.0, 3.0]]),
                                                              x[3:5]), ca.exp(-x[4]))
    return ca.Function("hexapod_test_bind", [x], [y])


def test_the_bound_call_equals_single_in_place() -> None:
    fn = CompiledFunction(_function())
    assert fn.compiled, "no C compiler: the bound C call is not tested"
    bound = fn.bind()
    y_row = bound.y
    rng = np.random.default_rng(0)
    for _ in range(20):
        bound.x[:] = rng.normal(size=5)
        assert bound.call() == 0
        assert bound.y is y_row  # written in place, not a new array
        np.testing.assert_array_equal(bound.y, fn.single(bound.x))
        vm = np.asarray(fn.function(bound.x), dtype=float).ravel()
        np.testing.assert_allclose(bound.y, vm, rtol=1e-14, atol=1e-14)


def test_bindings_and_their_copies_share_no_buffers() -> None:
    fn = CompiledFunction(_function())
    a, b = fn.bind(), fn.bind()
    a.x[:] = [0.1, 0.2, 0.3, 0.4, 0.5]
    b.x[:] = [1.0, -1.0, 2.0, 0.0, 3.0]
    assert a.call() == 0 and b.call() == 0
    y_a = a.y.copy()
    fn.single(np.full(5, 7.0))  # single()'s buffers are not a binding's
    c = copy.deepcopy(a)
    assert c.x is not a.x and c.y is not a.y
    np.testing.assert_array_equal(c.x, a.x)
    c.x[:] = -2.0
    assert c.call() == 0
    np.testing.assert_array_equal(a.y, y_a)  # untouched by b, single() and the copy
    np.testing.assert_array_equal(c.y, fn.single(np.full(5, -2.0)))
    assert a.call() == 0
    np.testing.assert_array_equal(a.y, y_a)


def test_pickled_functions_and_bindings_evaluate_the_same_numbers_apart() -> None:
    """A pickled function is made again from its arguments (its C found in the cache) and
    gives the same bits; a pickled binding holds copies of the rows it had, bound to
    the unpickled function, and its calls leave the original's rows untouched."""
    fn = CompiledFunction(_function())
    again = pickle.loads(pickle.dumps(fn))
    assert again is not fn and again.compiled and again.name == fn.name
    x = np.array([0.4, -1.3, 0.2, 2.5, -0.6])
    np.testing.assert_array_equal(again.single(x), fn.single(x))
    a = fn.bind()
    a.x[:] = x
    assert a.call() == 0
    y_a = a.y.copy()
    b = pickle.loads(pickle.dumps(a))
    assert b.function is not fn and b.x is not a.x
    np.testing.assert_array_equal(b.x, a.x)
    np.testing.assert_array_equal(b.y, a.y)
    b.x[:] = -x
    assert b.call() == 0
    np.testing.assert_array_equal(b.y, fn.single(-x))
    np.testing.assert_array_equal(a.y, y_a)
    np.testing.assert_array_equal(a.x, x)


def test_the_virtual_machine_binding_evaluates_the_same_function() -> None:
    fn = CompiledFunction(_function(), compile=False)
    assert not fn.compiled
    bound = fn.bind()
    bound.x[:] = [0.3, -0.2, 1.1, 0.7, -0.4]
    assert bound.call() == 0
    np.testing.assert_array_equal(bound.y, fn.single(bound.x))
    assert np.all(np.isfinite(bound.y)) and np.any(bound.y)
