"""CasADi functions compiled to C and called through ctypes, looped over a batch in C.

Calling a CasADi ``Function`` from Python costs tens of microseconds (argument
conversion); the same function generated to C by CasADi, compiled once by the
system C compiler and called through :mod:`ctypes` on preallocated buffers costs
a few microseconds, and a batch is looped over in C. The shared library is
cached in ``$HEXAPOD_CACHE_DIR`` (default ``~/.cache/hexapod-vs``) under the hash
of its code. Without a C compiler the CasADi virtual machine evaluates the same
function (same results, slower) and a warning is logged once.

A function must have one dense vector input and one dense vector output. A caller that
evaluates one row at a time in a hot loop can :meth:`CompiledFunction.bind` its own input
and output buffers and call the C function on them in place (no copies).
"""

from __future__ import annotations

import ctypes
import fcntl
import hashlib
import logging
import os
import platform
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

log = logging.getLogger(__name__)

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


class CompilationError(OSError):
    """The C code of a CasADi function could not be compiled or loaded."""


#: Whether this process has said that it compiles C kernels.
_ANNOUNCED = False


def cache_dir() -> Path:
    """Where compiled libraries are kept: ``$HEXAPOD_CACHE_DIR`` or ``~/.cache/hexapod-vs``."""
    return Path(os.environ.get("HEXAPOD_CACHE_DIR", Path.home() / ".cache" / "hexapod-vs"))


def build_shared_library(name: str, code: str, flags: tuple[str, ...] = ("-O2",)) -> Path:
    """Compile C source to a shared library once, cached under the hash of the source.

    The library is written to :func:`cache_dir` as ``{name}_{hash}.so``. Processes that
    need the same library at once take turns on ``{name}_{hash}.lock`` (an advisory lock),
    so one compiles and the others load its result; the library appears by an atomic
    rename of a per-process temporary file, so no reader ever sees half of it (even a
    writer that ignores the lock, e.g. an older version of this code, is safe).

    Args:
        name: A C identifier-like name for the files.
        code: The complete C translation unit.
        flags: Compiler flags (``-shared -fPIC`` are added).

    Returns:
        The path of the shared library.

    Raises:
        CompilationError: No compiler (``$CC``, default ``cc``).
        subprocess.CalledProcessError: The compiler failed (its stderr is attached).
    """
    cc = os.environ.get("CC", "cc")
    if shutil.which(cc) is None:
        raise CompilationError(f"no C compiler '{cc}'")
    cache = cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    key = code + platform.machine() + " ".join(flags)
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    lib_path = cache / f"{name}_{digest}.so"
    if lib_path.exists():
        return lib_path
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
        src.write_text(code)
        tmp_lib = cache / f"{name}_{digest}.{os.getpid()}.so"
        try:
            subprocess.run([cc, *flags, "-shared", "-fPIC", str(src), "-o", str(tmp_lib)],
                           check=True, capture_output=True, timeout=300)
            os.replace(tmp_lib, lib_path)  # atomic: a reader sees no library or all of it
        finally:
            src.unlink(missing_ok=True)
            tmp_lib.unlink(missing_ok=True)
    return lib_path


class CompiledFunction:
    """A CasADi function of one vector, compiled to C (CasADi VM fallback).

    Args:
        function: ``ca.Function`` with one dense input (n_in,) and one dense output (n_out,).
        compile: Generate and compile the C code (False: the CasADi virtual machine
            evaluates the function, by choice, without a warning).
    """

    def __init__(self, function: ca.Function, compile: bool = True) -> None:
        if function.n_in() != 1 or function.n_out() != 1:
            raise ValueError("CompiledFunction needs exactly one input and one output")
        self.function = function
        self.name = function.name()
        self.n_in = int(function.nnz_in(0))
        self.n_out = int(function.nnz_out(0))
        self.compiled = False
        #: The C entry point ``f(arg, res, iw, w, mem)`` (None without compilation).
        self.entry: Any = None
        #: Sizes of its ``arg``, ``res``, ``iw`` and ``w`` work arrays.
        self.work_sizes = (0, 0, 0, 0)
        self._lib: ctypes.CDLL | None = None
        if not compile:
            return
        try:
            self._compile()
        except (OSError, subprocess.SubprocessError) as exc:
            log.warning("%s: C compilation unavailable (%s); using the CasADi virtual machine",
                        self.name, exc)

    def _compile(self) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            cwd = os.getcwd()
            try:
                os.chdir(tmp)
                self.function.generate(f"{self.name}.c")
            finally:
                os.chdir(cwd)
            code = (Path(tmp) / f"{self.name}.c").read_text()
        code += _BATCH_WRAPPER.format(name=self.name, n_in=self.n_in, n_out=self.n_out)
        lib_path = build_shared_library(self.name, code, ("-O2", "-fno-math-errno"))
        lib = ctypes.CDLL(str(lib_path))
        n_arg, n_res, n_iw, n_w = (ctypes.c_longlong() for _ in range(4))
        getattr(lib, f"{self.name}_work")(ctypes.byref(n_arg), ctypes.byref(n_res),
                                          ctypes.byref(n_iw), ctypes.byref(n_w))
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

    def bind(self) -> BoundCall:
        """Own input and output buffers evaluated in place (see :class:`BoundCall`)."""
        return BoundCall(self)

    def single(self, x: np.ndarray) -> np.ndarray:
        """Evaluate on one input (n_in,) -> a fresh (n_out,) array."""
        if self._lib is None:
            return np.asarray(self.function(x), dtype=float).ravel()
        self._xbuf[:] = x
        if self._single(*self._call):
            raise CompilationError(f"{self.name}: the compiled function failed")
        return self._ybuf.copy()

    def batch(self, x: np.ndarray) -> np.ndarray:
        """Evaluate on the rows of ``x`` (N, n_in) -> (N, n_out)."""
        x = np.ascontiguousarray(x, dtype=float).reshape(-1, self.n_in)
        n = x.shape[0]
        y = np.empty((n, self.n_out))
        if self._lib is not None:
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
    :meth:`CompiledFunction.single`. A deep copy is a new binding with copies of the
    buffers.

    Args:
        function: The compiled function (or its CasADi virtual-machine fallback).
    """

    def __init__(self, function: CompiledFunction) -> None:
        self.function = function
        self.x = np.zeros(function.n_in)
        self.y = np.zeros(function.n_out)
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

    def __deepcopy__(self, memo: dict[int, object]) -> BoundCall:
        """A new binding of the same function with copies of the buffers (a plain deep
        copy would keep pointers to this binding's buffers)."""
        copy = BoundCall(self.function)
        copy.x[:] = self.x
        copy.y[:] = self.y
        memo[id(self)] = copy
        return copy
