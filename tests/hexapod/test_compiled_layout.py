"""``hexapod.compiled``: the named layouts of the kernels' rows and the cache key.

Every built-in kernel declares the layout of its input and output rows where it is built;
:class:`CompiledFunction` refuses a layout whose size is not its function's, so that a
kernel change cannot silently misalign an offset. The library of a kernel is found by the
hash of its serialized function, or of its :func:`~hexapod.compiled.code_key` (the source
of the modules that write it and its builder's arguments): a warm process does not
generate C code to find it, and a keyed kernel is not even built.
"""

from __future__ import annotations

import hashlib
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest

from hexapod import compiled
from hexapod.compiled import CompiledFunction, Layout, code_key
from hexapod.exceptions import LayoutError


def test_blocks_are_named_slices_and_shaped_views() -> None:
    lay = Layout([("R", (3, 3)), ("t", 3), ("flag", 1)], "test row")
    assert lay.size == 13 and list(lay) == ["R", "t", "flag"]
    assert lay["t"] == slice(9, 12) and lay.index("flag") == 12 and "R" in lay
    rows = np.zeros((4, 13))
    v = lay.views(rows)
    assert v["R"].shape == (4, 3, 3) and v["t"].shape == (4, 3) and v["flag"].shape == (4, 1)
    v["R"][:] = np.arange(9.0).reshape(3, 3)  # written through: a view, not a copy
    v["t"][2] = (1.0, 2.0, 3.0)
    np.testing.assert_array_equal(rows[:, 0:9], np.tile(np.arange(9.0), (4, 1)))
    np.testing.assert_array_equal(rows[2, 9:12], [1.0, 2.0, 3.0])
    assert lay.extended([("more", 2)]).slices["more"] == slice(13, 15)
    x = ca.SX.sym("x", 13)
    assert str(lay.split(x)["t"]) == str(x[9:12])


@pytest.mark.parametrize(("make", "evidence"), [
    (lambda: Layout([("a", 2), ("a", 3)]), "named twice"),
    (lambda: Layout([("a", 2)])["b"], "no block 'b'"),
    (lambda: Layout([("a", 2)]).index("a"), "holds 2 numbers"),
    (lambda: Layout([("a", 2)]).view(np.zeros(3), "a"), "a row of 3 numbers"),
    (lambda: Layout([("a", 2)]).view(np.zeros((2, 4))[:, ::2], "a"), "stride 16"),
])
def test_misuse_is_refused_with_the_evidence(make: Callable[[], object], evidence: str) -> None:
    with pytest.raises(LayoutError, match=evidence):
        make()


def test_a_layout_that_does_not_fit_its_function_is_refused() -> None:
    x = ca.SX.sym("x", 5)
    f = ca.Function("hexapod_test_layout_fit", [x], [ca.vertcat(x, ca.sum1(x))])
    fits_in, fits_out = Layout([("a", 2), ("b", 3)]), Layout([("x", 5), ("sum", 1)])
    assert CompiledFunction(f, False, fits_in, fits_out).inputs is fits_in
    with pytest.raises(LayoutError, match=r"hexapod_test_layout_fit: input layout .* has 4"):
        CompiledFunction(f, False, Layout([("a", 2), ("b", 2)]), fits_out)
    with pytest.raises(LayoutError, match=r"output layout .* has 7 numbers, the "
                                          r"function's output has 6"):
        CompiledFunction(f, False, fits_in, Layout([("x", 5), ("sum", 2)]))


def _kernels() -> Iterator[tuple[str, Callable[[], Any]]]:
    """Every built-in kernel factory (the lru-cached ones)."""
    from controllers import law_kernel, model_based
    from controllers.mpc.problem import ProblemSpec, problem_kernel
    from controllers.mpc.solver import CompiledQP
    from controllers.solvers import (
        compiled_ctc,
        compiled_task_ctc,
        osqp_limits,
        reference_motion,
    )
    from controllers.tasks import EDGE_LINES, EDGE_NORMALS, LEG_DIRECTIONS, PLATFORM_POSE
    from hexapod import fk
    from hexapod.dynamics import compiled as dyn
    from hexapod.dynamics import robots_compiled

    yield "fk", fk.newton_kernel
    for name in ("forward", "inverse", "terms", "forward_drives"):
        yield f"dynamics {name}", lambda name=name: dyn.compiled(name)
    yield "dynamic robots' period", lambda: robots_compiled.period_function(2)
    yield "joint-space ctc", compiled_ctc.joint_step
    for kind, fk_pose in ((PLATFORM_POSE, True), (PLATFORM_POSE, False), (EDGE_NORMALS, True),
                          (LEG_DIRECTIONS, True)):
        yield f"task ctc {kind}", lambda k=kind, f=fk_pose: compiled_task_ctc.task_step(k, f)
    for kind in reference_motion.FEATURES:
        yield f"reference motion {kind}", lambda k=kind: reference_motion.feature_motion(k)
    yield "QP refinement", osqp_limits.refine_kernel
    yield "pose servo", model_based.pose_servo_kernel
    for interaction in ("current", "mean"):
        yield f"direction law {interaction}", lambda i=interaction: law_kernel.feature_law_kernel(
            LEG_DIRECTIONS, i).function
        yield f"edge law {interaction}", lambda i=interaction: law_kernel.feature_law_kernel(
            EDGE_LINES, i).function
    for spec in (ProblemSpec(EDGE_LINES, "local", 2, False, False),
                 ProblemSpec(EDGE_NORMALS, "global", 2, True, True, True)):
        yield f"MPC {spec}", lambda s=spec: problem_kernel(s)
    yield "DAQP", lambda: CompiledQP(12, 30).function


@pytest.mark.slow
def test_every_kernel_declares_layouts_that_fit_its_function(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Built without C (the layouts are checked at construction; nothing compiled), the
    factories' caches emptied before and after."""
    built: list[str] = []

    def no_c(self: CompiledFunction, flags: object, preload: object) -> None:
        self.compiled = True  # (CompiledQP wants a compiled function; never called here)

    monkeypatch.setattr(CompiledFunction, "_compile", no_c)
    kernels = list(_kernels())
    _clear_caches()
    try:
        for name, make in kernels:
            fn = make()
            assert isinstance(fn, CompiledFunction), name
            assert fn.inputs.size == fn.function.nnz_in(0), name
            assert fn.outputs.size == fn.function.nnz_out(0), name
            # a named layout (not the default one-block one)
            assert len(fn.inputs.slices) > 1 or list(fn.inputs) != ["x"], name
            assert len(fn.outputs.slices) > 1 or list(fn.outputs) != ["y"], name
            built.append(name)
    finally:
        _clear_caches()
    assert len(built) == len(kernels) == 22


def _clear_caches() -> None:
    from controllers import law_kernel, model_based
    from controllers.mpc import problem
    from controllers.solvers import (
        compiled_ctc,
        compiled_task_ctc,
        osqp_limits,
        reference_motion,
    )
    from hexapod import fk
    from hexapod.dynamics import compiled as dyn
    from hexapod.dynamics import robots_compiled

    for cached in (fk.newton_kernel, dyn.compiled, robots_compiled.period_function,
                   compiled_ctc.joint_step, compiled_task_ctc.task_step,
                   reference_motion.feature_motion, osqp_limits.refine_kernel,
                   model_based.pose_servo_kernel, law_kernel._compiled_core,
                   problem.problem_kernel):
        cached.cache_clear()


def _function(scale: float) -> ca.Function:
    x = ca.SX.sym("x", 3)
    return ca.Function("hexapod_test_cache_key", [x], [scale * ca.sin(x)])


def test_a_warm_process_finds_its_library_without_generating_c(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("HEXAPOD_CACHE_DIR", str(tmp_path))
    calls: list[str] = []
    generate = compiled.generated_code

    def counted(function: ca.Function) -> str:
        calls.append(function.name())
        return generate(function)

    monkeypatch.setattr(compiled, "generated_code", counted)
    cold = CompiledFunction(_function(2.0))
    assert cold.compiled and calls == ["hexapod_test_cache_key"]
    assert len(list(tmp_path.glob("hexapod_test_cache_key_*.so"))) == 1
    warm = CompiledFunction(_function(2.0))  # a new function object, the same function
    assert warm.compiled and len(calls) == 1  # found by its key: no C generated
    x = np.array([0.1, -0.4, 2.0])
    np.testing.assert_array_equal(warm.single(x), cold.single(x))
    np.testing.assert_allclose(warm.single(x), 2.0 * np.sin(x), rtol=1e-15)
    other = CompiledFunction(_function(3.0))  # another function under the same name
    assert other.cache_key() != cold.cache_key() and len(calls) == 2
    assert len(list(tmp_path.glob("hexapod_test_cache_key_*.so"))) == 2
    np.testing.assert_allclose(other.single(x), 3.0 * np.sin(x), rtol=1e-15)


def test_a_binding_evaluates_a_row_its_caller_owns() -> None:
    """``bind(x)`` evaluates the caller's row in place (a row of a batch's matrix: what
    is written there is what is evaluated); a row of the wrong size, type or layout is
    refused naming the function."""
    from hexapod.exceptions import LayoutError

    f = CompiledFunction(_function(2.0))
    X = np.random.default_rng(3).normal(size=(3, f.n_in))
    bound = f.bind(X[1])
    assert bound.x.base is X
    assert bound.call() == 0
    np.testing.assert_array_equal(bound.y, f.single(X[1]))
    X[1, 0] += 1.0  # written in the matrix: evaluated
    assert bound.call() == 0
    np.testing.assert_array_equal(bound.y, f.single(X[1]))
    for bad in (np.zeros(f.n_in + 1), np.zeros(f.n_in, dtype=np.float32), X[:, 0],
                np.zeros((2, f.n_in))[:, ::2][0]):
        with pytest.raises(LayoutError, match=f.name):
            f.bind(bad)


def _keyed(scale: float, builds: list[float]) -> CompiledFunction:
    """A kernel of ``scale * sin(x)`` keyed by its argument (``builds``: the builder's calls)."""
    def build() -> ca.Function:
        builds.append(scale)
        return _function(scale)

    return CompiledFunction(build, inputs=Layout([("x", 3)]), outputs=Layout([("y", 3)]),
                            key=("hexapod_test_cache_key", code_key(["hexapod.layout"], scale)))


def test_a_keyed_kernel_is_built_only_when_its_library_is_missing(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Its key is found without building the function; another argument is another key,
    another library; the cached library gives the bits of a fresh build."""
    monkeypatch.setenv("HEXAPOD_CACHE_DIR", str(tmp_path / "cache"))
    builds: list[float] = []
    x = np.array([0.1, -0.4, 2.0])
    cold = _keyed(2.0, builds)
    assert cold.compiled and builds == [2.0]  # no library yet: built and compiled
    warm = _keyed(2.0, builds)
    assert warm.compiled and builds == [2.0]  # found by its key: not built
    np.testing.assert_array_equal(warm.single(x), cold.single(x))
    np.testing.assert_allclose(warm.single(x), 2.0 * np.sin(x), rtol=1e-15)
    other = _keyed(3.0, builds)  # another argument: another key, built and compiled
    assert other.cache_key() != warm.cache_key() and builds == [2.0, 3.0]
    assert len(list((tmp_path / "cache").glob("hexapod_test_cache_key_*.so"))) == 2
    np.testing.assert_allclose(other.single(x), 3.0 * np.sin(x), rtol=1e-15)
    monkeypatch.setenv("HEXAPOD_CACHE_DIR", str(tmp_path / "fresh"))
    fresh = _keyed(2.0, builds)  # an empty cache: built again
    assert builds == [2.0, 3.0, 2.0]
    np.testing.assert_array_equal(fresh.single(x), warm.single(x))
    assert warm.function.name() == "hexapod_test_cache_key" and builds[-1] == 2.0
    np.testing.assert_allclose(np.asarray(warm.function(x)).ravel(), warm.single(x),
                               rtol=1e-15)  # built when asked for: the same function


def test_a_code_key_changes_with_its_modules_source_and_its_arguments(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    source = tmp_path / "hexapod_test_key_module.py"
    source.write_text("SCALE = 2.0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    key = code_key(["hexapod_test_key_module", "hexapod.layout"], 1e-9, "normals")
    assert key == code_key(["hexapod_test_key_module", "hexapod.layout"], 1e-9, "normals")
    assert key != code_key(["hexapod_test_key_module", "hexapod.layout"], 2e-9, "normals")
    assert key != code_key(["hexapod_test_key_module", "hexapod.layout"], 1e-9, "lines")
    assert key != code_key(["hexapod.layout"], 1e-9, "normals")
    source.write_text("SCALE = 3.0\n")  # another process, the module edited
    monkeypatch.setattr(compiled, "_source_digest", compiled._source_digest.__wrapped__)
    assert key != code_key(["hexapod_test_key_module", "hexapod.layout"], 1e-9, "normals")
    sys.modules.pop("hexapod_test_key_module", None)


#: The package directories whose modules can write a kernel's expression.
_ROOT = Path(__file__).resolve().parents[2]


def _modules_run_by(build: Callable[[], object]) -> set[str]:
    """The project modules whose functions are called while ``build()`` runs (but
    :mod:`hexapod.compiled`, which calls the builder)."""
    files: set[str] = set()

    def profile(frame: Any, event: str, arg: Any) -> None:
        if event == "call":
            files.add(frame.f_code.co_filename)

    previous = sys.getprofile()
    sys.setprofile(profile)
    try:
        build()
    finally:
        sys.setprofile(previous)
    modules = set()
    for f in files:
        path = Path(f)
        if path.suffix != ".py" or not path.is_relative_to(_ROOT):
            continue
        parts = path.relative_to(_ROOT).with_suffix("").parts
        if parts[0] in ("hexapod", "controllers", "vision") and parts != ("hexapod", "compiled"):
            modules.add(".".join(p for p in parts if p != "__init__"))
    return modules


def _assert_key_names(key: str, modules: set[str], name: str) -> None:
    assert modules, name  # the build ran here (not a function built before)
    for module in sorted(modules):
        digest = hashlib.sha256(Path(str(sys.modules[module].__file__)).read_bytes())
        assert f"{module} {digest.hexdigest()}" in key.splitlines(), (name, module)


@pytest.mark.slow
def test_every_keyed_kernel_names_every_module_its_build_runs(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A change in a module whose code writes a kernel's expression changes its key: its
    library cannot be reused stale. Built without C, the factories' caches emptied."""
    from hexapod.dynamics import robots_compiled

    def no_c(self: CompiledFunction, flags: object, preload: object) -> None:
        self.compiled = True

    monkeypatch.setattr(CompiledFunction, "_compile", no_c)
    kernels = list(_kernels())
    _clear_caches()
    keyed = []
    try:
        for name, make in kernels:
            fn = make()
            if fn.key is not None:
                _assert_key_names(fn.key, _modules_run_by(lambda f=fn: f.function), name)
                keyed.append(name)
    finally:
        _clear_caches()
    assert len(keyed) == 13, keyed  # ctc 5, reference motions 2, dynamics 4, edge laws 2
    robots_compiled.period_functions.cache_clear()
    _assert_key_names(code_key(robots_compiled.KEY_MODULES),
                      _modules_run_by(robots_compiled.period_functions), "period lanes")


def test_a_pose_block_is_read_as_casadi_reads_it() -> None:
    """write_pose puts ``R`` in the block as a kernel's ``ca.reshape(block[0:9], 3, 3)``
    (column-major) reads it back, ``t`` after it; read_pose returns copies of both."""
    from scipy.spatial.transform import Rotation

    from hexapod.layout import read_pose, write_pose

    R = Rotation.from_euler("xyz", [0.3, -0.2, 1.1]).as_matrix()
    t = np.array([0.01, -0.02, 0.3])
    block = np.full(12, np.nan)
    write_pose(block, R, t)
    assert np.array_equal(np.array(ca.reshape(ca.DM(block[0:9]), 3, 3)), R)
    assert np.array_equal(block[9:12], t)
    R2, t2 = read_pose(block)
    assert np.array_equal(R2, R) and np.array_equal(t2, t)
    block[:] = 0.0  # copies: the block's later values do not reach them
    assert np.array_equal(R2, R) and np.array_equal(t2, t)
