"""CasADi functions compiled to C and called through ctypes, looped over a batch in C.

Calling a CasADi ``Function`` from Python costs tens of microseconds (argument
conversion); the same function generated to C by CasADi, compiled once by the
system C compiler and called through :mod:`ctypes` on preallocated buffers costs
a few microseconds, and a batch is looped over in C. The shared library is
cached in ``$HEXAPOD_CACHE_DIR`` (default ``~/.cache/hexapod-vs``) under a hash
of its function (below). Without a C compiler the CasADi virtual machine evaluates the
same function (same results, slower) and a warning is logged once.

A function must have one dense vector input and one dense vector output, each described
where the function is built by a :class:`Layout` (ordered named blocks with shapes): the
caller reads and writes its rows by name (:meth:`Layout.views`), never by hand offsets, and
a layout whose size is not the function's is refused (:class:`~hexapod.exceptions.
LayoutError`). A caller that evaluates one row at a time in a hot loop can
:meth:`CompiledFunction.bind` its own input and output buffers and call the C function on
them in place (no copies).

The cache key of a library is the hash of what determines its function, CasADi's version,
the C wrapper and the compiler flags. A kernel built with a :func:`code_key` (the source
of the modules that write its expression and the builder's arguments) gives a builder
instead of the function: a warm process finds its library without building the
expression at all (the function is built only when the library is missing, or when it is
asked for: :attr:`CompiledFunction.function`). Without one, the key is the serialized
function (``Function.serialize()``): built, but no C code generated.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import hashlib
import importlib
import logging
import os
import platform
import shutil
import subprocess
import tempfile
import threading
from collections.abc import Callable, Sequence
from functools import cache, partial
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from hexapod.exceptions import LayoutError
from hexapod.layout import Layout as Layout  # (re-exported: the kernels import both from here)
from hexapod.layout import Shape as Shape

log = logging.getLogger(__name__)

#: The compiler flags of a kernel (``-shared -fPIC`` are added).
DEFAULT_FLAGS = ("-O2", "-fno-math-errno")
#: Rows from which :meth:`CompiledFunction.batch` evaluates by lanes when asked (two
#: vectors of :data:`hexapod.compiled_lanes.LANES` rows: fewer gain little).
LANE_ROWS = 8

_BATCH_WRAPPER = r"""
#include <stdlib.h>
int {name}_batch(const casadi_real* x, casadi_real* y, long long n) {{
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  if ({name}_work(&sz_arg, &sz_res, &sz_iw, &sz_w)) return 1;
  const casadi_real** arg = malloc(sizeof(casadi_real*) * (sz_arg > 1 ? sz_arg : 1));
  casadi_real** res = malloc(sizeof(casadi_real*) * (sz_res > 1 ? sz_res : 1));
  casadi_int* iw = malloc(sizeof(casadi_int) * (sz_iw > 1 ? sz_iw : 1));
  casadi_real* w = malloc(sizeof(casadi_real) * (sz_w > 1 ? sz_w : 1));
  int flag = 0;
  for (long long k = 0; k < n && !flag; ++k) {{
    arg[0] = x + {n_in} * k;
    res[0] = y + {n_out} * k;
    flag = {name}(arg, res, iw, w, 0);
  }}
  free(arg); free(res); free(iw); free(w);
  return flag;
}}
"""


#: A CasADi function, or a function building it on demand (:func:`code_key`).
Builder = ca.Function | Callable[[], ca.Function]


def code_key(modules: Sequence[str], *arguments: object) -> str:
    """What determines a kernel's expression, found without building it: the source of
    each of ``modules`` (every module whose code writes the expression or whose constants
    it reads, imported) and the ``repr`` of the builder's ``arguments`` (numbers, names).
    A changed line in one of those modules, or another argument, is another key, hence
    another library (the tests trace each keyed kernel's build and check that its key
    names every project module whose code runs in it: ``tests/hexapod/kernel_keys.py``)."""
    return "\n".join([*(f"{m} {_source_digest(m)}" for m in modules),
                      *(repr(a) for a in arguments)])


@cache
def _source_digest(module: str) -> str:
    path = Path(str(importlib.import_module(module).__file__))
    return hashlib.sha256(path.read_bytes()).hexdigest()


def built(function: Builder) -> ca.Function:
    """``function`` itself, or what its builder returns."""
    return function if isinstance(function, ca.Function) else function()


class CompilationError(OSError):
    """The C code of a CasADi function could not be compiled or loaded."""


#: Whether this process has said that it compiles C kernels.
_ANNOUNCED = False


def cache_dir() -> Path:
    """Where compiled libraries are kept: ``$HEXAPOD_CACHE_DIR`` or ``~/.cache/hexapod-vs``."""
    return Path(os.environ.get("HEXAPOD_CACHE_DIR", Path.home() / ".cache" / "hexapod-vs"))


def build_shared_library(name: str, code: str | Callable[[], str],
                         flags: tuple[str, ...] = ("-O2",), key: str | None = None) -> Path:
    """Compile C source to a shared library once, cached under the hash of its key.

    The library is written to :func:`cache_dir` as ``{name}_{hash}.so``. Processes that
    need the same library at once take turns on ``{name}_{hash}.lock`` (an advisory lock),
    so one compiles and the others load its result; the library appears by an atomic
    rename of a per-process temporary file, so no reader ever sees half of it (even a
    writer that ignores the lock, e.g. an older version of this code, is safe).

    Args:
        name: A C identifier-like name for the files.
        code: The complete C translation unit, or a function generating it (called only
            when the library is missing).
        flags: Compiler flags (``-shared -fPIC`` are added).
        key: What identifies the code (default: the code itself); it must change
            whenever the code would.

    Returns:
        The path of the shared library.

    Raises:
        CompilationError: No compiler (``$CC``, default ``cc``).
        subprocess.CalledProcessError: The compiler failed (its stderr is attached).
    """
    if key is None:
        code = code if isinstance(code, str) else code()
        key = code
    cc = os.environ.get("CC", "cc")
    if shutil.which(cc) is None:
        raise CompilationError(f"no C compiler '{cc}'")
    cache = cache_dir()
    digest = hashlib.sha256((key + platform.machine() + " ".join(flags)).encode()
                            ).hexdigest()[:16]
    lib_path = cache / f"{name}_{digest}.so"
    if lib_path.exists():
        return lib_path
    cache.mkdir(parents=True, exist_ok=True)
    # one compiler per kernel: a process that finds another compiling it waits for the
    # library instead of compiling it again (test workers, process pools, warm)
    with open(cache / f"{name}_{digest}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if lib_path.exists():
            return lib_path
        global _ANNOUNCED
        if not _ANNOUNCED:  # once per process: the user sees why the first run waits
            _ANNOUNCED = True
            log.warning("compiling the controllers' C kernels (first run only, ~30 s; "
                        "cached in %s)", cache)
        log.info("compiling %s (C, cached in %s)", name, cache)
        src = cache / f"{name}_{digest}.{os.getpid()}.c"
        src.write_text(code if isinstance(code, str) else code())
        tmp_lib = cache / f"{name}_{digest}.{os.getpid()}.so"
        try:
            subprocess.run([cc, *flags, "-shared", "-fPIC", str(src), "-o", str(tmp_lib)],
                           check=True, capture_output=True, timeout=300)
            os.replace(tmp_lib, lib_path)  # atomic: a reader sees no library or all of it
        finally:
            src.unlink(missing_ok=True)
            tmp_lib.unlink(missing_ok=True)
    return lib_path


def generated_code(function: ca.Function) -> str:
    """CasADi's C code of ``function`` (generated in a temporary directory)."""
    name = function.name()
    with tempfile.TemporaryDirectory() as tmp:
        cwd = os.getcwd()
        try:
            os.chdir(tmp)
            function.generate(f"{name}.c")
        finally:
            os.chdir(cwd)
        return (Path(tmp) / f"{name}.c").read_text()


class CompiledFunction:
    """A CasADi function of one vector, compiled to C (CasADi VM fallback).

    Args:
        function: ``ca.Function`` with one dense input (n_in,) and one dense output
            (n_out,), or (with ``key``) a function building it when it is needed.
        compile: Generate and compile the C code (False: the CasADi virtual machine
            evaluates the function, by choice, without a warning).
        inputs: The layout of the input row (default: one block ``"x"``; required with
            a builder).
        outputs: The layout of the output row (default: one block ``"y"``; required with
            a builder).
        flags: Compiler flags (``-shared -fPIC`` are added).
        preload: Shared libraries the generated code links against, loaded with global
            symbols before it (e.g. a QP solver's).
        key: ``(name, code_key(...))``: the function's name and what determines it
            (:func:`code_key`), the library's cache key instead of the serialized
            function.

    Raises:
        LayoutError: A layout's size is not the function's input's or output's.
        ValueError: A builder without its key and layouts.
    """

    def __init__(self, function: Builder, compile: bool = True,
                 inputs: Layout | None = None, outputs: Layout | None = None,
                 flags: tuple[str, ...] = DEFAULT_FLAGS, preload: Sequence[Path] = (),
                 key: tuple[str, str] | None = None) -> None:
        self._function: ca.Function | None = None
        self._builder = function
        #: The arguments it was made with (a pickle makes it again from them).
        self._made = (function, compile, inputs, outputs, flags, tuple(preload), key)
        #: What determines the function (:func:`code_key`; None: its serialization).
        self.key = None if key is None else key[1]
        if isinstance(function, ca.Function):
            self._checked(function)
            self.name = function.name()
            self.n_in = int(function.nnz_in(0))
            self.n_out = int(function.nnz_out(0))
        elif key is None or inputs is None or outputs is None:
            raise ValueError("a CompiledFunction built on demand needs its key and layouts")
        else:
            self.name, self.n_in, self.n_out = key[0], inputs.size, outputs.size
        #: Where each named quantity lies in an input row and in an output row.
        self.inputs = inputs if inputs is not None else Layout([("x", self.n_in)], "input")
        self.outputs = outputs if outputs is not None else Layout([("y", self.n_out)], "output")
        self.inputs.check(self.n_in, self.name, "input")
        self.outputs.check(self.n_out, self.name, "output")
        if isinstance(function, ca.Function):
            self._function = function
        self.compiled = False
        #: The C entry point ``f(arg, res, iw, w, mem)`` (None without compilation).
        self.entry: Any = None
        #: Sizes of its ``arg``, ``res``, ``iw`` and ``w`` work arrays.
        self.work_sizes = (0, 0, 0, 0)
        self._lib: ctypes.CDLL | None = None
        #: The lane-parallel C (:meth:`lanes`; False: not built yet).
        self._lanes: Any = False
        #: Held by a call on the shared buffers of :meth:`single` (and, with
        #: :attr:`shared_memory`, by every call): the threads of a process (a Dask
        #: worker's) share the compiled functions, and their rows changed with the
        #: interleaving (17 of 40 rows with two threads) before it.
        self.lock = threading.Lock()
        #: The C code keeps state between calls in one memory slot (a QP solver's):
        #: every call of any binding holds :attr:`lock`.
        self.shared_memory = False
        if not compile:
            return
        try:
            self._compile(flags, preload)
        except (OSError, subprocess.SubprocessError) as exc:
            log.warning("%s: C compilation unavailable (%s); using the CasADi virtual machine",
                        self.name, exc)

    @staticmethod
    def _checked(function: ca.Function) -> ca.Function:
        if function.n_in() != 1 or function.n_out() != 1:
            raise ValueError("CompiledFunction needs exactly one input and one output")
        return function

    @property
    def function(self) -> ca.Function:
        """The CasADi function (built on first use when a builder was given: its name and
        sizes checked against the key's and the layouts')."""
        if self._function is None:
            function = self._checked(built(self._builder))
            if function.name() != self.name:
                raise LayoutError(self.name, f"the builder made {function.name()!r}")
            self.inputs.check(int(function.nnz_in(0)), self.name, "input")
            self.outputs.check(int(function.nnz_out(0)), self.name, "output")
            self._function = function
        return self._function

    def cache_key(self) -> str:
        """What identifies the library: CasADi's version, the function's :func:`code_key`
        (else the serialized function) and the C wrapper (no code generation; the flags
        and the machine are added by :func:`build_shared_library`)."""
        what = (f"{self.name} {self.n_in} {self.n_out}\n{self.key}" if self.key is not None
                else self.function.serialize())
        return "\n".join((ca.CasadiMeta.version(), what, self._wrapper()))

    def _wrapper(self) -> str:
        return _BATCH_WRAPPER.format(name=self.name, n_in=self.n_in, n_out=self.n_out)

    def _compile(self, flags: tuple[str, ...], preload: Sequence[Path]) -> None:
        self._preloaded = [ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL) for path in preload]
        lib_path = build_shared_library(
            self.name, lambda: generated_code(self.function) + self._wrapper(), flags,
            key=self.cache_key())
        lib = ctypes.CDLL(str(lib_path))
        n_arg, n_res, n_iw, n_w = (ctypes.c_longlong() for _ in range(4))
        getattr(lib, f"{self.name}_work")(ctypes.byref(n_arg), ctypes.byref(n_res),
                                          ctypes.byref(n_iw), ctypes.byref(n_w))
        alloc = getattr(lib, f"{self.name}_alloc_mem", None)
        init = getattr(lib, f"{self.name}_init_mem", None)
        if alloc is not None and init is not None:  # memory slot 0 (a QP solver's)
            alloc.restype = ctypes.c_int
            init(alloc())
            self.shared_memory = True
        single = getattr(lib, self.name)
        single.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_int]
        single.restype = ctypes.c_int
        batch = getattr(lib, f"{self.name}_batch")
        batch.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_longlong]
        batch.restype = ctypes.c_int
        self._xbuf = np.zeros(self.n_in)
        self._ybuf = np.zeros(self.n_out)
        self._args = (ctypes.c_void_p * max(n_arg.value, 1))(self._xbuf.ctypes.data)
        self._res = (ctypes.c_void_p * max(n_res.value, 1))(self._ybuf.ctypes.data)
        self._iw = np.zeros(max(n_iw.value, 1), dtype=np.int64)
        self._w = np.zeros(max(n_w.value, 1))
        self._call = (ctypes.addressof(self._args), ctypes.addressof(self._res),
                      self._iw.ctypes.data, self._w.ctypes.data, 0)
        self._single = single
        self._batch = batch
        self._lib = lib
        self.entry = single
        self.work_sizes = (n_arg.value, n_res.value, n_iw.value, n_w.value)
        self.compiled = True

    def __deepcopy__(self, memo: dict[int, object]) -> CompiledFunction:
        """Shared, not copied: the compiled code is immutable (callers copy inputs)."""
        return self

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickled as the arguments it was made with (its library found again in the
        cache on unpickling; a builder that is a lambda cannot be pickled)."""
        return CompiledFunction, self._made

    def bind(self, x: np.ndarray | None = None) -> BoundCall:
        """Own input and output buffers evaluated in place (see :class:`BoundCall`);
        the input row ``x`` (n_in,) when given (a contiguous float64 view the caller owns,
        e.g. one row of a batch's input matrix, evaluated without a copy)."""
        return BoundCall(self, x)

    def single(self, x: np.ndarray) -> np.ndarray:
        """Evaluate on one input (n_in,) -> a fresh (n_out,) array."""
        if self._lib is None:
            return np.asarray(self.function(x), dtype=float).ravel()
        with self.lock:  # (the buffers are the function's, shared by the threads)
            self._xbuf[:] = x
            if self._single(*self._call):
                raise CompilationError(f"{self.name}: the compiled function failed")
            return self._ybuf.copy()

    def lanes(self) -> Any:
        """The function's lane-parallel C (:class:`hexapod.compiled_lanes.LaneFunction`,
        ``same_width=False``: the same operations, bit for bit, several rows at once;
        compiled on first use and cached as the kernels are), or None without a compiler
        or for an instruction it does not translate."""
        if self._lanes is False:
            from hexapod.compiled_lanes import LaneFunction

            self._lanes = None if self._lib is None else LaneFunction.create(
                (lambda: self.function) if self._function is None else self._function,
                f"{self.name}_lanes", same_width=False,
                key=None if self.key is None else (self.key, (self.n_in, self.n_out)))
        return self._lanes

    def batch(self, x: np.ndarray, lanes: bool = False, overwrite: bool = False
              ) -> np.ndarray:
        """Evaluate on the rows of ``x`` (N, n_in) -> (N, n_out); ``lanes``: a batch of
        :data:`LANE_ROWS` rows or more by :meth:`lanes` where it is built (the same
        numbers, about three times faster; the result may be a view), ``overwrite``:
        there ``x`` may be their work table (no copy; ``x`` is then lost)."""
        x = np.ascontiguousarray(x, dtype=float).reshape(-1, self.n_in)
        n = x.shape[0]
        if lanes and n >= LANE_ROWS:
            lane = self.lanes()
            if lane is not None and overwrite and lane.width == self.n_in and \
                    x.flags.writeable:
                lane.advance(x, np.arange(n), 1)
                return x[:, :self.n_out]
            if lane is not None:
                return lane.evaluate(x)  # type: ignore[no-any-return]
        y = np.empty((n, self.n_out))
        if self._lib is not None:
            with self.lock if self.shared_memory else contextlib.nullcontext():
                if self._batch(x.ctypes.data, y.ctypes.data, n):
                    raise CompilationError(f"{self.name}: the compiled function failed")
            return y
        for k in range(n):
            y[k] = np.asarray(self.function(x[k]), dtype=float).ravel()
        return y


class BoundCall:
    """One input row :attr:`x` (n_in,) and one output row :attr:`y` (n_out,) of a
    :class:`CompiledFunction`, owned by the caller, and :attr:`call` evaluating the
    function from ``x`` into ``y`` in place: no argument conversion and no copies
    (:meth:`CompiledFunction.single` copies its input in and its output out). ``y`` is
    overwritten by the next call: copy what must outlive it.

    ``call()`` returns 0 on success and a nonzero flag when the C function fails (check
    it). Its own work arrays make bindings independent of each other and of
    :meth:`CompiledFunction.single`. :attr:`inputs` and :attr:`outputs` are their views by
    block (the function's :class:`Layout`). A deep copy is a new binding with copies of
    the buffers.

    Args:
        function: The compiled function (or its CasADi virtual-machine fallback).
        x: The input row to evaluate from (n_in,), a C-contiguous float64 array the
            caller owns (e.g. one row of a batch's input matrix); default: its own.

    Raises:
        LayoutError: ``x`` is not a writeable contiguous float64 array of ``n_in`` values.
    """

    def __init__(self, function: CompiledFunction, x: np.ndarray | None = None) -> None:
        self.function = function
        if x is None:
            x = np.zeros(function.n_in)
        elif (x.dtype != np.float64 or x.shape != (function.n_in,)
              or not x.flags.c_contiguous or not x.flags.writeable):
            raise LayoutError(function.name, "the bound input row must be a writeable "
                              f"contiguous float64 array of shape ({function.n_in},), got "
                              f"{x.dtype} {x.shape}")
        self.x = x
        self.y = np.zeros(function.n_out)
        #: Views of :attr:`x` and :attr:`y` by block (the function's layouts).
        self.inputs = function.inputs.views(self.x)
        self.outputs = function.outputs.views(self.y)
        self.call: Callable[[], int]
        if function.entry is None:  # the CasADi virtual machine: same results, slower
            def evaluate() -> int:
                self.y[:] = np.asarray(function.function(self.x), dtype=float).ravel()
                return 0
            self.call = evaluate
            return
        n_arg, n_res, n_iw, n_w = function.work_sizes
        self._args = (ctypes.c_void_p * max(n_arg, 1))(self.x.ctypes.data)
        self._res = (ctypes.c_void_p * max(n_res, 1))(self.y.ctypes.data)
        self._iw = np.zeros(max(n_iw, 1), dtype=np.int64)
        self._w = np.zeros(max(n_w, 1))
        self.call = partial(function.entry, ctypes.addressof(self._args),
                            ctypes.addressof(self._res), self._iw.ctypes.data,
                            self._w.ctypes.data, 0)
        if function.shared_memory:  # (the function's one memory slot: one call at a time)
            entry = self.call

            def locked() -> int:
                with function.lock:
                    return int(entry())
            self.call = locked

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickled as its function and copies of its buffers (a new binding, as
        :meth:`__deepcopy__` makes)."""
        return _bound_again, (self.function, self.x.copy(), self.y.copy())

    def __deepcopy__(self, memo: dict[int, object]) -> BoundCall:
        """A new binding of the same function with copies of the buffers (a plain deep
        copy would keep pointers to this binding's buffers)."""
        copy = memo[id(self)] = _bound_again(self.function, self.x, self.y)
        return copy


def _bound_again(function: CompiledFunction, x: np.ndarray, y: np.ndarray) -> BoundCall:
    """A new :class:`BoundCall` of ``function`` holding copies of ``x`` and ``y`` (a deep
    copy, an unpickled binding)."""
    bound = BoundCall(function)
    bound.x[:] = x
    bound.y[:] = y
    return bound
