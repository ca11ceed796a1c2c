"""A CasADi SX step iterated in C over a batch, several rows at once (SIMD lanes).

:class:`LaneFunction` takes a ``ca.Function`` of one row to the next row of the same
width (one physics step, say) and generates its own C from the function's instruction
list (not CasADi's code generator): every value is a vector of :data:`LANES` doubles
(GCC/Clang vector extensions), so one pass through the instructions advances
:data:`LANES` rows; the step is repeated ``iterations`` times in C with the row kept in
registers and on the stack. Every instruction is one IEEE operation per lane, as in
CasADi's own C (``-ffp-contract=off``: no fused multiply-add), so the results are those
of the scalar code bit for bit; the transcendental functions (``tanh``, ``sin``, ...)
are libm's, lane by lane (``atan2`` too). A function whose output is not as wide as its
input (a controller's compiled step, :meth:`hexapod.compiled.CompiledFunction.batch` with
``lanes=True``) is applied once per row (:meth:`LaneFunction.evaluate`). It is compiled
with ``-O3`` (no ``-march``, no
``-ffast-math``: GCC keeps every IEEE operation; about 9 % faster than ``-O2`` on the
dynamic world's period, the same bits).

The C is compiled twice in one library, for the baseline instruction set and for AVX2
(chosen at run time with ``__builtin_cpu_supports`` on x86-64; the same results, the
instruction set only changes the width of the machine's vector operations). The library
is cached as :mod:`hexapod.compiled`'s are, under :func:`lane_key` (no C generated to
find it). Without a C compiler, or with an instruction
this generator does not know, :meth:`LaneFunction.create` returns None and the caller
keeps CasADi's path.
"""

from __future__ import annotations

import ctypes
import logging
import math
import subprocess
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path

import casadi as ca
import numpy as np

from hexapod.compiled import Builder, build_shared_library, built
from hexapod.exceptions import UnsupportedInstructionError

log = logging.getLogger(__name__)

#: Rows advanced together (doubles per vector).
LANES = 4

_OPS = {getattr(ca, name): name[3:] for name in dir(ca) if name.startswith("OP_")}

#: Binary operators written with C's operator on vectors.
_INFIX = {"ADD": "+", "SUB": "-", "MUL": "*", "DIV": "/"}
#: Comparisons: a mask, then 1.0 or 0.0 as CasADi's C gives.
_COMPARE = {"LT": "<", "LE": "<=", "EQ": "==", "NE": "!="}
#: Functions of one argument applied lane by lane (libm).
_LIBM = {"SQRT": "sqrt", "TANH": "tanh", "SIN": "sin", "COS": "cos", "EXP": "exp",
         "LOG": "log", "TAN": "tan", "ATAN": "atan", "ASIN": "asin", "ACOS": "acos",
         "SINH": "sinh", "COSH": "cosh", "ERF": "erf", "FLOOR": "floor", "CEIL": "ceil"}
#: Functions of two arguments applied lane by lane (libm).
_LIBM2 = {"ATAN2": "atan2"}

_ONE = "(V){" + ", ".join(["1.0"] * LANES) + "}"
_ABS_MASK = "(VI){" + ", ".join(["0x7fffffffffffffffLL"] * LANES) + "}"


def _infix(c: str) -> Callable[[list[str]], str]:
    return lambda a: f"{a[0]} {c} {a[1]}"


def _compare(c: str) -> Callable[[list[str]], str]:
    # a mask, then 1.0 or 0.0 as CasADi's C gives
    return lambda a: f"lane_mask((VI)({a[0]} {c} {a[1]}))"


def _min_max(cmp: str) -> Callable[[list[str]], str]:
    # libm's fmin/fmax: a NaN argument gives the other one
    return lambda a: (f"lane_select((VI)({a[1]} != {a[1]}), {a[0]}, "
                      f"lane_select((VI)({a[0]} {cmp} {a[1]}), {a[0]}, {a[1]}))")


#: The C expression of each instruction from its arguments' values.
_TRANSLATE: dict[str, Callable[[list[str]], str]] = {
    **{op: _infix(c) for op, c in _INFIX.items()},
    **{op: _compare(c) for op, c in _COMPARE.items()},
    "SQ": lambda a: f"{a[0]} * {a[0]}",
    "TWICE": lambda a: f"{a[0]} + {a[0]}",
    "NEG": lambda a: f"-{a[0]}",
    "INV": lambda a: f"1.0 / {a[0]}",
    "ASSIGN": lambda a: a[0],
    "NOT": lambda a: f"lane_mask((VI)({a[0]} == 0.0))",
    "AND": lambda a: f"lane_mask((VI)({a[0]} != 0.0) & (VI)({a[1]} != 0.0))",
    "OR": lambda a: f"lane_mask((VI)({a[0]} != 0.0) | (VI)({a[1]} != 0.0))",
    # CasADi's C: (c ? x : 0), a NaN condition counts as true
    "IF_ELSE_ZERO": lambda a: f"(V)((VI)({a[0]} != 0.0) & (VI){a[1]})",
    "FABS": lambda a: f"(V)((VI){a[0]} & {_ABS_MASK})",
    "FMIN": _min_max("<"),
    "FMAX": _min_max(">"),
    # casadi_sign: -1, 1, or the argument itself (0, -0, NaN)
    "SIGN": lambda a: (f"lane_select((VI)({a[0]} < 0.0), -{_ONE}, "
                       f"lane_select((VI)({a[0]} > 0.0), {_ONE}, {a[0]}))"),
}

_PRELUDE = r"""
#include <math.h>
#include <string.h>
typedef double V __attribute__((vector_size({bytes})));
typedef long long VI __attribute__((vector_size({bytes})));
#define LANES {lanes}
static inline V lane_select(VI m, V a, V b) {{ return (V)(((VI)a & m) | ((VI)b & ~m)); }}
static inline V lane_mask(VI m) {{ const V one = {{{ones}}}; return (V)((VI)one & m); }}
"""

_LIBM_LANE = r"""
static inline V lane_{f}(V a) {{ V r; for (int i = 0; i < LANES; ++i) r[i] = {f}(a[i]);
  return r; }}
"""

_LIBM2_LANE = r"""
static inline V lane_{f}(V a, V b) {{ V r; for (int i = 0; i < LANES; ++i)
  r[i] = {f}(a[i], b[i]); return r; }}
"""

_BLOCK = r"""
static inline __attribute__((always_inline)) void {name}_block(V* st, long long iterations) {{
  V nx[{width}];
  for (long long it = 0; it < iterations; ++it) {{
{body}
  }}
{finish}
}}
"""

_FINISH = r"""  {{
{body}
  }}"""

_ROWS = r"""
{attribute}
static void {name}_rows{suffix}(double* table, const long long* rows, long long n,
                               long long iterations, long long check, unsigned char* bad) {{
  V st[{width}];
  for (long long k = 0; k < n; k += LANES) {{
    long long m = n - k < LANES ? n - k : LANES;
    for (int j = 0; j < {width}; ++j)
      for (int l = 0; l < LANES; ++l) st[j][l] = table[rows[k + (l < m ? l : m - 1)] * {width} + j];
    {name}_block(st, iterations);
    for (int l = 0; l < m; ++l) {{
      int finite = 1;
      for (long long j = 0; j < check; ++j) finite &= isfinite(st[j][l]) ? 1 : 0;
      bad[k + l] = (unsigned char)!finite;
      if (finite)
        for (int j = 0; j < {width}; ++j) table[rows[k + l] * {width} + j] = st[j][l];
    }}
  }}
}}
"""

_RUN = r"""
int {name}_run(double* table, const long long* rows, long long n, long long iterations,
               long long check, unsigned char* bad, int isa) {{
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  if (isa != 0 && __builtin_cpu_supports("avx2")) {{
    {name}_rows_avx2(table, rows, n, iterations, check, bad);
    return 1;
  }}
#endif
  {name}_rows(table, rows, n, iterations, check, bad);
  return 0;
}}
"""

_AVX2 = "#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))\n"


def _constant(value: float) -> str:
    if math.isnan(value):
        return "NAN"
    if math.isinf(value):
        return "INFINITY" if value > 0 else "-INFINITY"
    return value.hex()


def _check(function: ca.Function, name: str, same_width: bool = True) -> int:
    """The width of a lane function's row: its input's (``same_width``), else the wider
    of its input and output (the input in the row's first values, the output written
    over them)."""
    n_in, n_out = int(function.nnz_in(0)), int(function.nnz_out(0))
    if (function.n_in() != 1 or function.n_out() != 1 or (same_width and n_out != n_in)
            or not function.sparsity_in(0).is_dense()
            or not function.sparsity_out(0).is_dense()):
        raise ValueError(f"{name}: a lane function maps one dense row to one dense row"
                         + (" of the same width" if same_width else ""))
    return max(n_in, n_out)


def _body(function: ca.Function, name: str, used_libm: set[str]) -> str:
    """The statements computing the next row from the row ``st`` in place, one SSA
    vector value per instruction: the values that change are kept in ``nx`` and written
    into ``st`` at the end (an output equal to its own input is not copied); the libm
    functions used are added to ``used_libm``."""
    slot: dict[int, str] = {}  # CasADi's work index -> the SSA value it holds
    read: dict[str, int] = {}  # SSA value -> the row index it was read from
    lines, changed = [], []
    for k in range(function.n_instructions()):
        op = _OPS.get(function.instruction_id(k), str(function.instruction_id(k)))
        ins = function.instruction_input(k)
        outs = function.instruction_output(k)
        if op == "OUTPUT":
            if read.get(slot[ins[0]]) != outs[1]:
                lines.append(f"nx[{outs[1]}] = {slot[ins[0]]};")
                changed.append(outs[1])
            continue
        v = f"v{k}"
        a = [slot.get(i, "") for i in ins]
        if op == "INPUT":
            expr = f"st[{ins[1]}]"
            read[v] = ins[1]
        elif op == "CONST":
            expr = "(V){" + ", ".join(
                [_constant(float(function.instruction_constant(k)))] * LANES) + "}"
        elif op in _TRANSLATE:
            expr = _TRANSLATE[op](a)
        elif op in _LIBM:
            used_libm.add(_LIBM[op])
            expr = f"lane_{_LIBM[op]}({a[0]})"
        elif op in _LIBM2:
            used_libm.add(_LIBM2[op])
            expr = f"lane_{_LIBM2[op]}({a[0]}, {a[1]})"
        else:
            raise UnsupportedInstructionError(name, op)
        lines.append(f"const V {v} = {expr};")
        slot[outs[0]] = v
    lines += [f"st[{j}] = nx[{j}];" for j in changed]
    return "\n".join("    " + line for line in lines)


def lane_code(function: ca.Function, name: str, finish: ca.Function | None = None,
              same_width: bool = True) -> str:
    """The C source of ``function`` (one dense row in, one row of the same width out;
    ``same_width=False``: of any width, applied once, :meth:`LaneFunction.evaluate`)
    iterated over lanes of rows, then ``finish`` (the same shape) once (module docstring).

    Raises:
        UnsupportedInstructionError: An instruction outside the translated set (its name).
        ValueError: A function that does not map a row to a row of its width.
    """
    width = _check(function, name, same_width)
    used_libm: set[str] = set()
    body = _body(function, name, used_libm)
    end = ""
    if finish is not None:
        if _check(finish, name) != width:
            raise ValueError(f"{name}: the finishing function's row is not {width} long")
        end = _FINISH.format(body=_body(finish, name, used_libm))
    prelude = _PRELUDE.format(bytes=8 * LANES, lanes=LANES, ones=", ".join(["1.0"] * LANES))
    two = set(_LIBM2.values())
    helpers = "".join((_LIBM2_LANE if f in two else _LIBM_LANE).format(f=f)
                      for f in sorted(used_libm))
    rows = (_ROWS.format(name=name, width=width, attribute="", suffix="") + _AVX2
            + _ROWS.format(name=name, width=width, attribute='__attribute__((target("avx2")))',
                           suffix="_avx2") + "#endif\n")
    return (prelude + helpers + _BLOCK.format(name=name, width=width, body=body, finish=end)
            + rows + _RUN.format(name=name))


def lane_key(function: ca.Function, name: str, finish: ca.Function | None = None,
             same_width: bool = True) -> str:
    """What :func:`lane_code` makes its C from, the cache key of a lane library (a warm
    process finds it without generating the C): this generator's source, the versions of
    CasADi and numpy, the arguments, and the serialized functions (their instructions
    and constants)."""
    return "\n".join((_generator_source(), ca.CasadiMeta.version(), np.__version__, name,
                      str(same_width), function.serialize(),
                      "" if finish is None else finish.serialize()))


@lru_cache(maxsize=1)
def _generator_source() -> str:
    return Path(__file__).read_text()


class LaneFunction:
    """A row-to-row CasADi function iterated in C over lanes of rows (module docstring).

    Build with :meth:`create`.

    Args:
        name: C name of the function.
        width: Length of a row.
        library: The loaded shared library.
        n_in, n_out: The function's input and output widths (default: ``width``).
    """

    def __init__(self, name: str, width: int, library: ctypes.CDLL, n_in: int | None = None,
                 n_out: int | None = None) -> None:
        self.name = name
        self.width = width
        self.n_in = width if n_in is None else n_in
        self.n_out = width if n_out is None else n_out
        self._lib = library
        run = getattr(library, f"{name}_run")
        run.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_longlong, ctypes.c_longlong,
                        ctypes.c_longlong, ctypes.c_void_p, ctypes.c_int]
        run.restype = ctypes.c_int
        self._run = run
        #: Whether the last call used the AVX2 code (x86-64 machines that have it).
        self.used_avx2 = False

    @classmethod
    def create(cls, function: Builder, name: str, finish: Builder | None = None,
               same_width: bool = True, key: tuple[str, tuple[int, int]] | None = None
               ) -> LaneFunction | None:
        """The compiled lane function of ``function`` (then ``finish`` once, if given), or
        None (logged) when it cannot be generated or compiled. ``same_width=False``: a
        function whose output is not as wide as its input (:meth:`evaluate` only).
        ``key``: the functions' :func:`~hexapod.compiled.code_key` and the function's
        input and output sizes; ``function`` and ``finish`` may then be builders, called
        only when the library is missing (else the key is the serialized functions)."""
        try:
            if key is None:
                function, finish = built(function), None if finish is None else built(finish)
                n_in, n_out = int(function.nnz_in(0)), int(function.nnz_out(0))
                width = _check(function, name, same_width)
                what = lane_key(function, name, finish, same_width)
            else:
                n_in, n_out = key[1]
                width = n_in if same_width else max(n_in, n_out)
                what = "\n".join((_generator_source(), ca.CasadiMeta.version(),
                                  np.__version__, name, str(same_width), f"{n_in} {n_out}",
                                  key[0]))
            path = build_shared_library(
                name, lambda: lane_code(built(function), name,
                                        None if finish is None else built(finish), same_width),
                ("-O3", "-fno-math-errno", "-ffp-contract=off"), key=what)
            return cls(name, width, ctypes.CDLL(str(path)), n_in, n_out)
        except (OSError, subprocess.SubprocessError, UnsupportedInstructionError) as exc:
            log.warning("%s: no lane-parallel C (%s); using CasADi's code", name, exc)
            return None

    def advance(self, table: np.ndarray, rows: np.ndarray, iterations: int, check: int = 0,
                avx2: bool = True) -> np.ndarray:
        """Advance rows ``rows`` of ``table`` in place: ``iterations`` applications of the
        function, then the finishing function.

        Args:
            table: (N, width) C-contiguous float64 rows, changed in place.
            rows: (n,) indices of the rows to advance.
            iterations: How many times the function is applied.
            check: A row is written back only if its first ``check`` values are finite
                (0: always).
            avx2: Allow the AVX2 code where the machine has it (False: the baseline
                instruction set, for tests).

        Returns:
            (n,) mask of the rows left unchanged (a non-finite value among the first
            ``check``).
        """
        if (table.dtype != np.float64 or not table.flags.c_contiguous or table.ndim != 2
                or table.shape[1] != self.width):
            raise ValueError(f"{self.name}: table must be a C-contiguous float64 array "
                             f"(N, {self.width}), got {table.dtype} {table.shape}")
        idx = np.ascontiguousarray(rows, dtype=np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= table.shape[0]):
            raise IndexError(f"{self.name}: row indices outside [0, {table.shape[0]})")
        bad = np.zeros(idx.shape[0], dtype=np.uint8)
        self.used_avx2 = bool(self._run(table.ctypes.data, idx.ctypes.data, idx.shape[0],
                                        int(iterations), int(check), bad.ctypes.data,
                                        int(avx2)))
        return bad.astype(bool)

    def evaluate(self, x: np.ndarray, avx2: bool = True) -> np.ndarray:
        """The function once on every row of ``x`` (N, n_in): (N, n_out) (a view of the
        work table; ``x`` is not changed)."""
        table = np.zeros((len(x), self.width))
        table[:, :self.n_in] = x
        self.advance(table, np.arange(len(x)), 1, 0, avx2)
        return table[:, :self.n_out]

    def iterate(self, x: np.ndarray, iterations: int, avx2: bool = True) -> np.ndarray:
        """The rows of ``x`` (N, width) after ``iterations`` applications of the function
        (and the finishing function); ``x`` is not changed."""
        y = np.array(x, dtype=float, order="C").reshape(-1, self.width)
        self.advance(y, np.arange(y.shape[0]), iterations, 0, avx2)
        return y
