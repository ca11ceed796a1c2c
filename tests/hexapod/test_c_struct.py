"""``hexapod.c_step.c_struct``: the ctypes mirror of a C struct read from its declaration;
``c_library``: the functions' signatures read from their definitions; ``RowArrays``.

The oracle is the C compiler itself: a small library reports ``sizeof`` and every
field's ``offsetof`` of the struct, which the mirror's layout must equal; and a value
written through the mirror must be what the C reads. A function called through the
signature read from its definition must get every argument (an ``int64_t`` beyond 32
bits, a ``double``, addresses) and give its result.
"""

from __future__ import annotations

import ctypes
import re
from typing import Any

import numpy as np
import pytest

from controllers import joint_ctc_rows, law_rows, model_based_rows, task_ctc_c
from hexapod.c_step import KERNEL_CALL_C, KernelCall, RowArrays, c_library, c_struct
from hexapod.compiled import build_shared_library

SOURCE = r"""
#include <stddef.h>
#include <stdint.h>
""" + KERNEL_CALL_C + r"""
typedef struct {
    double *X; int64_t n, at;  /* a comment, with, commas; and a semicolon */
    const uint8_t *flags; const double *const *grids; uint8_t mark; double peak;
    KernelCall first, second;
    int count; double *scratch;
} Probe;

void probe_layout(int64_t *out) {
    out[0] = sizeof(Probe);
    out[1] = offsetof(Probe, X); out[2] = offsetof(Probe, n); out[3] = offsetof(Probe, at);
    out[4] = offsetof(Probe, flags); out[5] = offsetof(Probe, grids);
    out[6] = offsetof(Probe, mark); out[7] = offsetof(Probe, peak);
    out[8] = offsetof(Probe, first); out[9] = offsetof(Probe, second);
    out[10] = offsetof(Probe, count); out[11] = offsetof(Probe, scratch);
}

double probe_read(const Probe *p) {
    return p->peak + (double)p->n + (double)p->mark + (double)p->count + p->X[1];
}
"""

FIELDS = ("X", "n", "at", "flags", "grids", "mark", "peak", "first", "second", "count",
          "scratch")


def _library() -> ctypes.CDLL:
    lib = ctypes.CDLL(str(build_shared_library("test_c_struct", SOURCE)))
    lib.probe_layout.argtypes = [ctypes.c_void_p]
    lib.probe_layout.restype = None
    lib.probe_read.argtypes = [ctypes.c_void_p]
    lib.probe_read.restype = ctypes.c_double
    return lib


def test_the_mirror_has_the_compilers_layout() -> None:
    probe = c_struct(SOURCE, "Probe")
    layout = np.zeros(1 + len(FIELDS), dtype=np.int64)
    _library().probe_layout(layout.ctypes.data)
    assert ctypes.sizeof(probe) == layout[0]
    assert [name for name, _ in probe._fields_] == list(FIELDS)
    assert [getattr(probe, name).offset for name in FIELDS] == layout[1:].tolist()
    types = dict(probe._fields_)
    assert types["first"] is KernelCall and types["mark"] is ctypes.c_uint8
    assert types["grids"] is ctypes.c_void_p and types["count"] is ctypes.c_int


def test_what_python_writes_is_what_the_c_reads() -> None:
    x = np.array([0.0, 0.25])
    p = c_struct(SOURCE, "Probe")(X=x.ctypes.data, n=3, mark=200, peak=1.5, count=-7)
    assert _library().probe_read(ctypes.addressof(p)) == 1.5 + 3 + 200 - 7 + 0.25


@pytest.mark.parametrize("module, struct", [
    (joint_ctc_rows, "JointCtc"), (task_ctc_c, "TaskCtc"), (task_ctc_c, "TaskCall"),
    (model_based_rows, "ModelBased"), (law_rows, "VisionRows"), (law_rows, "StepRows")])
def test_every_c_step_struct_is_read(module: object, struct: str) -> None:
    fields = c_struct(module.SOURCE, struct)._fields_  # type: ignore[attr-defined]
    assert len(fields) >= 9 and len({name for name, _ in fields}) == len(fields)


def test_a_missing_struct_or_an_unmirrored_field_is_named() -> None:
    with pytest.raises(ValueError, match=re.escape("no 'typedef struct {...} Nothing;'")):
        c_struct(SOURCE, "Nothing")
    with pytest.raises(ValueError, match=r"Odd\.ratio: a field of type float"):
        c_struct("typedef struct { double a; float ratio; } Odd;", "Odd")


CALLS = KERNEL_CALL_C + r"""
static double twice(double x) { return 2.0 * x; }

int scaled_sum(const double *x, int64_t n, double scale,
               double *out) {
    double s = 0.0;
    for (int64_t k = 0; k < n; k++) s += x[k];
    out[0] = twice(s) * scale;
    return n > 3;
}

void store_index(int64_t i, int64_t *out) { out[0] = i; }
"""


def test_the_functions_are_called_with_the_signatures_of_their_definitions() -> None:
    lib = c_library("test_c_library", CALLS)
    assert lib.scaled_sum.argtypes == [ctypes.c_void_p, ctypes.c_int64, ctypes.c_double,
                                       ctypes.c_void_p]
    assert lib.scaled_sum.restype is ctypes.c_int and lib.store_index.restype is None
    x, out = np.array([1.0, 2.0, 3.5, 4.0]), np.zeros(1)
    assert lib.scaled_sum(x.ctypes.data, 3, 0.25, out.ctypes.data) == 0
    assert out[0] == 2.0 * 6.5 * 0.25
    assert lib.scaled_sum(x.ctypes.data, 4, 1.0, out.ctypes.data) == 1
    index = np.zeros(1, dtype=np.int64)
    lib.store_index(2**40 + 3, index.ctypes.data)  # (an int64_t, not truncated to an int)
    assert index[0] == 2**40 + 3
    assert not hasattr(lib, "twice")  # (static: no symbol, no signature set)


def test_an_unmirrored_parameter_or_result_is_named_before_compiling() -> None:
    with pytest.raises(ValueError, match=r"test_odd_param: half's parameter 'float x'"):
        c_library("test_odd_param", "int half(float x) { return x > 0; }\n")
    with pytest.raises(ValueError, match=r"test_odd_result: ratio returns double"):
        c_library("test_odd_result", "double ratio(int64_t n) { return n / 2.0; }\n")


def test_row_arrays_and_their_struct() -> None:
    rows = RowArrays(3, {"trials": ((), np.int64), "q": ((6,), float),
                         "vis": ((6, 2), bool)}, c_struct(
        "typedef struct { int64_t *trials; double *q; uint8_t *vis; int64_t m; } R;", "R"), 3)
    assert rows.trials.shape == (3,) and rows.trials.dtype == np.int64
    assert rows.q.shape == (3, 6) and rows.vis.shape == (3, 6, 2) and rows.vis.dtype == bool
    assert not rows.q.any()
    assert rows.addresses == (rows.trials.ctypes.data, rows.q.ctypes.data,
                              rows.vis.ctypes.data)
    call: Any = rows.call
    assert (call.trials, call.q, call.vis, call.m) == (*rows.addresses, 3)
    assert rows.at == ctypes.addressof(rows.call)
    with pytest.raises(AttributeError, match="no row array 'lengths'"):
        _ = rows.lengths
    assert RowArrays(2, {"t": ((), float)}).call is None
