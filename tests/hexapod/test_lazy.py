"""hexapod.lazy: a package's names and submodules imported on first access."""

from __future__ import annotations

import sys

import pytest

from hexapod.lazy import lazy_names


def test_names_submodules_and_unknown_names() -> None:
    namespace: dict[str, object] = {}
    attribute = lazy_names("hexapod", {"home": "hexapod.workspace"}, namespace)
    with pytest.raises(AttributeError, match="no attribute 'home'"):
        attribute("home")  # hexapod.workspace has no 'home': the error names it
    attribute = lazy_names("hexapod", {"home_pose": "hexapod.workspace"}, namespace)
    from hexapod.workspace import home_pose

    assert attribute("home_pose") is home_pose and namespace["home_pose"] is home_pose
    assert attribute("scurve") is sys.modules["hexapod.scurve"]  # a submodule
    for name in ("no_such_thing", "_private"):
        with pytest.raises(AttributeError, match=f"module 'hexapod' has no attribute '{name}'"):
            attribute(name)


def test_packages_keep_their_submodules_as_attributes() -> None:
    import controllers
    import controllers.solvers
    import hexapod.visualize

    assert controllers.qp is sys.modules["controllers.qp"]
    assert controllers.solvers.limit_qp is sys.modules["controllers.solvers.limit_qp"]
    assert hexapod.visualize.replay is sys.modules["hexapod.visualize.replay"]
    from controllers.solvers.limit_qp import LimitQPSolver

    assert controllers.solvers.LimitQPSolver is LimitQPSolver
