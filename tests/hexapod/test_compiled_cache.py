"""The kernel cache under concurrent writers: processes that need the same kernel at the
same moment (pytest-xdist workers, a process pool, `hexapod-bench warm`) each get a working
library. With the per-kernel lock exactly one of them compiles it; without the lock (a
writer that ignores it) several compile at once and the atomic rename still gives every
reader a whole library. Either way the cache ends with one library and no temporary file."""

from __future__ import annotations

import multiprocessing as mp
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

WORKERS = 4
X = np.array([0.3, -2.0, 1.5])


def _function() -> ca.Function:
    x = ca.SX.sym("x", 3)
    return ca.Function("hexapod_cache_race", [x], [ca.vertcat(ca.sin(x[0]) * x[1], x[2] ** 3)])


def _compile_at_once(barrier: mp.synchronize.Barrier, queue: mp.Queue,  # type: ignore[type-arg]
                     locked: bool) -> None:
    import hexapod.compiled as compiled

    real_run, compilations = compiled.subprocess.run, []

    def counting_run(*args: object, **kwargs: object) -> object:
        compilations.append(args)
        return real_run(*args, **kwargs)  # type: ignore[call-overload]

    # patched in this child process only
    compiled.subprocess.run = counting_run  # type: ignore[assignment]
    if not locked:
        compiled.fcntl.flock = lambda *_: None  # type: ignore[assignment]
    barrier.wait(timeout=60)
    f = compiled.CompiledFunction(_function())
    queue.put((f.compiled, f.single(X).tolist(), len(compilations)))


@pytest.mark.slow
@pytest.mark.parametrize("locked", [True, False], ids=["locked", "lock-ignored"])
def test_concurrent_builds_of_one_kernel(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                         locked: bool) -> None:
    monkeypatch.setenv("HEXAPOD_CACHE_DIR", str(tmp_path))
    ctx = mp.get_context("fork")
    barrier, queue = ctx.Barrier(WORKERS), ctx.Queue()
    procs = [ctx.Process(target=_compile_at_once, args=(barrier, queue, locked))
             for _ in range(WORKERS)]
    for p in procs:
        p.start()
    results = [queue.get(timeout=120) for _ in procs]
    for p in procs:
        p.join(timeout=60)
        assert p.exitcode == 0
    expected = np.asarray(_function()(X)).ravel()
    for compiled, value, _ in results:
        assert compiled  # each process loaded a C library, none fell back to the VM
        np.testing.assert_allclose(value, expected, rtol=1e-14)
    compilations = sum(n for *_, n in results)
    if locked:
        assert compilations == 1  # the others waited for it and loaded its library
    else:
        assert compilations >= 2  # the race was real: several compilers at once
    names = sorted(p.name for p in tmp_path.iterdir())
    libraries = [n for n in names if n.endswith(".so")]
    assert len(libraries) == 1 and libraries[0].startswith("hexapod_cache_race_"), names
    # nothing else but the lock file: no temporary .c or per-process .so left behind
    assert [n for n in names if n not in libraries] == [libraries[0][:-3] + ".lock"]
