"""The registry's lazy entries: ``import controllers`` imports no controller module; a
built-in's module is imported when the name is first used, and a bad lazy entry fails
with the name and the spec."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

import controllers
from controllers import BUILTIN_SPECS, registry
from controllers.exceptions import PluginLoadError, UnknownControllerError
from controllers.registry import Registry

#: Modules a kinematic study does not need, which ``import controllers`` must not import.
HEAVY = ("scipy", "osqp", "pinocchio", "matplotlib", "controllers.mpc",
         "controllers.force_mpc", "controllers.computed_torque", "controllers.task_ctc",
         "controllers.solvers.computed_torque", "controllers.qp",
         "controllers.solvers.limit_qp")


def _imported_after(code: str) -> set[str]:
    """The modules of :data:`HEAVY` a fresh interpreter has imported after ``code``."""
    probe = textwrap.dedent(f"""
        import sys
        {code}
        print(" ".join(m for m in {HEAVY!r} if m in sys.modules))
    """)
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True)
    return set(out.stdout.split())


def test_import_controllers_imports_no_controller_module() -> None:
    assert _imported_after("import controllers") == set()


def test_a_kinematic_law_imports_no_qp_mpc_or_dynamics() -> None:
    """Building the laws of tahri2009-convergence leaves OSQP, SciPy, the MPC and the
    computed-torque modules unimported."""
    code = ("from controllers import registry\n"
            "        registry.create('leg-edge'); registry.create('leg-direction')")
    assert _imported_after(code) == set()


def test_names_do_not_import_and_factory_does() -> None:
    reg = Registry()
    reg.register_lazy("lazy-qp", "controllers.qp:LegEdgeQPController")
    assert reg.names() == ["lazy-qp"]
    assert "lazy-qp" not in reg._factories
    from controllers.qp import LegEdgeQPController

    assert reg.factory("lazy-qp") is LegEdgeQPController
    (info,) = reg.info()
    assert (info.name, info.package) == ("lazy-qp", "hexapod-vs")
    assert info.description.startswith("Leg-edge")


def test_bad_lazy_entries_name_the_controller_and_the_spec() -> None:
    reg = Registry()
    reg.register_lazy("no-module", "controllers.no_such_module:Law")
    reg.register_lazy("no-attr", "controllers.leg_edge:NoSuchLaw")
    reg.register_lazy("not-callable", "controllers.leg_edge:__doc__")
    with pytest.raises(PluginLoadError, match=r"'no-module'.*controllers.no_such_module:Law"
                       r".*ModuleNotFoundError"):
        reg.factory("no-module")
    with pytest.raises(PluginLoadError, match=r"'no-attr'.*NoSuchLaw.*AttributeError"):
        reg.create("no-attr")
    with pytest.raises(PluginLoadError, match=r"'not-callable'.*not callable"):
        reg.options("not-callable")
    with pytest.raises(PluginLoadError, match=r"'bad spec'.*contains ' '"):
        reg.register_lazy("bad spec", "controllers.leg_edge:LegEdgeController")
    with pytest.raises(PluginLoadError, match=r"'x'.*'controllers.leg_edge' is not"):
        reg.register_lazy("x", "controllers.leg_edge")
    with pytest.raises(UnknownControllerError, match=r"did you mean 'no-attr'"):
        reg.factory("no-atr")


def test_a_registered_factory_overrides_a_lazy_entry() -> None:
    reg = Registry()
    reg.register_lazy("law", "controllers.leg_edge:LegEdgeController")
    from controllers.leg_direction import LegDirectionController

    reg.register("law", LegDirectionController, "tests", "1")
    assert reg.factory("law") is LegDirectionController
    assert reg.source("law").package == "tests"


def test_builtin_specs_and_lazy_classes() -> None:
    assert len(BUILTIN_SPECS) == 16
    for name, spec in BUILTIN_SPECS.items():
        module, _, attr = spec.partition(":")
        cls = registry.factory(name)
        assert (cls.__module__.startswith(module), cls.__name__) == (True, attr)
        assert getattr(controllers, attr) is cls
    with pytest.raises(AttributeError, match="NoSuchLaw"):
        controllers.NoSuchLaw  # noqa: B018
