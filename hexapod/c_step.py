"""The C written around compiled kernels (a controller's one step over a batch), and how
Python meets it: each layout and signature declared once, in the C.

:data:`KERNEL_CALL_C` is the headers of such C and ``kernel_call(k, x, y)``, one row of a
:class:`~hexapod.compiled.CompiledFunction` called from C through a :class:`KernelCall`
(its entry and work arrays); :func:`c_library` compiles a source once (cached as the
kernels are, :func:`~hexapod.compiled.build_shared_library`) with :data:`C_STEP_FLAGS` and
gives each function the argument and result types read from its definition;
:func:`c_struct` is the ctypes mirror of a struct read from its declaration;
:class:`RowArrays` holds a step's per-row arrays and their addresses in the C's order.
"""

from __future__ import annotations

import ctypes
import re
from typing import Any

import numpy as np

from hexapod.compiled import CompilationError, CompiledFunction, build_shared_library

#: The C of a call of a compiled function from C (:class:`KernelCall`): the headers a
#: one-step C needs, the struct and ``kernel_call(k, x, y)``, ``y = f(x)`` for one row
#: (nonzero when the function fails).
KERNEL_CALL_C = r"""
#include <math.h>
#include <stdint.h>
#include <string.h>

typedef struct {
    int (*f)(const double **, double **, int64_t *, double *, int);
    const double **arg; double **res; int64_t *iw; double *w;
} KernelCall;
static int kernel_call(const KernelCall *k, const double *x, double *y) {
    k->arg[0] = x; k->res[0] = y;
    return k->f(k->arg, k->res, k->iw, k->w, 0);
}
"""


class KernelCall(ctypes.Structure):
    """A compiled function's C entry and its own work arrays (addresses), the C
    ``KernelCall`` of :data:`KERNEL_CALL_C`: C code written around kernels calls them
    row by row through it (the arrays it points to are the instance's ``arrays``)."""

    _fields_ = [("f", ctypes.c_void_p), ("arg", ctypes.c_void_p), ("res", ctypes.c_void_p),
                ("iw", ctypes.c_void_p), ("w", ctypes.c_void_p)]

    @classmethod
    def of(cls, function: CompiledFunction) -> KernelCall:
        """The call of ``function``'s C entry with new work arrays.

        Raises:
            CompilationError: The function has no C (no C compiler).
        """
        if function.entry is None:
            raise CompilationError(f"{function.name}: C code calling it needs its compiled "
                                   "C (no C compiler?)")
        n_arg, n_res, n_iw, n_w = function.work_sizes
        arg = (ctypes.c_void_p * max(n_arg, 1))()
        res = (ctypes.c_void_p * max(n_res, 1))()
        iw, w = np.zeros(max(n_iw, 1), dtype=np.int64), np.zeros(max(n_w, 1))
        call = cls(ctypes.cast(function.entry, ctypes.c_void_p).value, ctypes.addressof(arg),
                   ctypes.addressof(res), iw.ctypes.data, w.ctypes.data)
        call.arrays = (arg, res, iw, w)  # (they live as long as the call)
        return call


#: The flags of :func:`c_library`: no builtin (``pow`` is the C library's, as Python's)
#: and no fused multiply-add, so the C's IEEE operations are those written (and the
#: numpy or Python expressions' bits it replaces).
C_STEP_FLAGS = ("-O2", "-fno-builtin", "-ffp-contract=off")


def c_library(name: str, source: str) -> ctypes.CDLL:
    """The C ``source`` written around compiled kernels (a controller's one step),
    compiled once with :data:`C_STEP_FLAGS` (cached as the kernels are,
    :func:`build_shared_library`) and loaded, each function that is not ``static`` with
    its argument and result types read from its definition (as :func:`c_struct` reads a
    struct: a pointer is an address).

    Raises:
        CompilationError: No C compiler, or the source does not compile.
        ValueError: A function's parameter or result of a type not mirrored.
    """
    signatures = []
    for result, function, params in re.findall(r"^(\w+) (\w+)\(([^)]*)\)\s*\{", source,
                                               re.M):
        if result == "static":
            continue
        if result not in ("int", "void"):
            raise ValueError(f"{name}: {function} returns {result} (not mirrored)")
        types: list[Any] = []
        for param in params.split(","):
            base = re.match(r"\s*(?:const\s+)?(\w+)", param)
            if "*" in param:
                types.append(ctypes.c_void_p)
            elif base is not None and base.group(1) in _C_SCALARS:
                types.append(_C_SCALARS[base.group(1)])
            else:
                raise ValueError(f"{name}: {function}'s parameter {param.strip()!r} (not "
                                 "mirrored)")
        signatures.append((function, types, ctypes.c_int if result == "int" else None))
    lib = ctypes.CDLL(str(build_shared_library(name, source, C_STEP_FLAGS)))
    for function, types, restype in signatures:
        entry = getattr(lib, function)
        entry.argtypes, entry.restype = types, restype
    return lib


class RowArrays:
    """The arrays of a one-step C over ``n`` rows (zeros): one attribute per field
    ``name: (shape of a row, dtype)``, and their addresses in the fields' order
    (:attr:`addresses`: the C call's arguments, or the fields of its struct
    :attr:`call`). A step keeps them while its batches have as many rows (the addresses
    taken once).

    Args:
        n: Rows.
        fields: The arrays, in the C's order.
        struct: The C struct of the addresses followed by ``extra`` (None: none).
        extra: Its last fields.
    """

    def __init__(self, n: int, fields: dict[str, tuple[tuple[int, ...], Any]],
                 struct: type[ctypes.Structure] | None = None, *extra: int) -> None:
        self.n = n
        arrays = {name: np.zeros((n, *shape), dtype=dtype)
                  for name, (shape, dtype) in fields.items()}
        self.__dict__.update(arrays)
        #: The arrays' addresses, in the fields' order.
        self.addresses = tuple(a.ctypes.data for a in arrays.values())
        #: The struct of the addresses (None: none) and its address (0: none).
        self.call: ctypes.Structure | None = (None if struct is None
                                              else struct(*self.addresses, *extra))
        self.at = 0 if self.call is None else ctypes.addressof(self.call)

    def __getattr__(self, name: str) -> np.ndarray:
        """Reached only for a name that is no field (every field is an array)."""
        raise AttributeError(f"no row array {name!r}")


#: The C scalar types of :func:`c_struct`'s fields (any pointer is an address).
_C_SCALARS: dict[str, Any] = {"double": ctypes.c_double, "int64_t": ctypes.c_int64,
                              "int": ctypes.c_int, "uint8_t": ctypes.c_uint8}


def c_struct(source: str, name: str) -> type[ctypes.Structure]:
    """The ctypes mirror of ``typedef struct { ... } name;`` in the C ``source``: its
    fields in their order, a pointer as an address (``c_void_p``), ``double``,
    ``int64_t``, ``int``, ``uint8_t`` or a :class:`KernelCall`. The C declares a layout
    once; Python reads it from there (a hand-kept copy could silently disagree).

    Raises:
        ValueError: No such struct in ``source``, or a field of another type.
    """
    found = re.search(r"typedef struct \{([^{}]*)\}\s*" + re.escape(name) + r"\s*;", source)
    if found is None:
        raise ValueError(f"no 'typedef struct {{...}} {name};' in the C source")
    fields: list[tuple[str, Any]] = []
    for declaration in re.sub(r"/\*.*?\*/", "", found.group(1), flags=re.S).split(";"):
        if not declaration.strip():
            continue
        head = re.match(r"\s*(?:const\s+)?(\w+)\s+(.*)", declaration, re.S)
        if head is None:
            raise ValueError(f"{name}: cannot read the field declaration {declaration!r}")
        base, names = head.groups()
        for declarator in names.split(","):
            field = re.findall(r"\w+", declarator)[-1]
            if "*" in declarator:
                fields.append((field, ctypes.c_void_p))
            elif base == "KernelCall":
                fields.append((field, KernelCall))
            elif base in _C_SCALARS:
                fields.append((field, _C_SCALARS[base]))
            else:
                raise ValueError(f"{name}.{field}: a field of type {base} (not mirrored)")
    return type(name, (ctypes.Structure,), {"_fields_": fields,
                                            "__doc__": f"The C ``{name}`` (addresses)."})
