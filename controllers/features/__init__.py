"""Features as plugins: one feature, one file, four compiled controllers.

A plugin defines a :class:`LegFeature` (its value for one leg, a CasADi expression of
the leg's direction, length and base point) and gets from :func:`controllers_for` the
pseudo-inverse (``<name>-pinv``), limit-QP (``<name>-qp``), predictive (``<name>-mpc``,
local model) and computed-torque (``<name>-ctc``) controllers, each stepping through a
kernel compiled to C from the feature's own expression (``docs/plugins.md``, "Adding a
feature"; the worked example is ``tests/controllers/plugin_feature_joints.py``).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

from controllers.features.ctc import FeatureComputedTorque
from controllers.features.laws import FeatureLaw, FeatureMPC, FeatureQPLaw
from controllers.law_kernel import feature_law_kernel
from controllers.tasks.leg_feature import FeatureTask, LegFeature

__all__ = ["FeatureComputedTorque", "FeatureControllers", "FeatureLaw", "FeatureMPC",
           "FeatureQPLaw", "FeatureTask", "LegFeature", "controllers_for", "feature_law_kernel"]


@dataclass(frozen=True)
class FeatureControllers:
    """The controller classes of one feature (each its own factory, as every controller:
    register them, or name them as ``module:attr``)."""

    pinv: type[FeatureLaw]
    qp: type[FeatureQPLaw]
    mpc: type[FeatureMPC]
    ctc: type[FeatureComputedTorque]

    def all(self) -> tuple[type, ...]:
        """The four classes."""
        return (self.pinv, self.qp, self.mpc, self.ctc)


def controllers_for(feature: LegFeature) -> FeatureControllers:
    """The four controllers of a feature (said to live in the module of the feature's
    class, ``__module__``, for the results' records).

    Args:
        feature: The feature (its ``name`` prefixes the controllers' names).

    Raises:
        ValueError: The feature's definition does not hold (:meth:`LegFeature.check`).
    """
    feature.check()
    stem = "".join(part.capitalize() for part in feature.c_name.split("_"))
    mod = type(feature).__module__
    def make(base: type, suffix: str, kind: str, extra: dict[str, object]) -> type:
        return type(f"{stem}{kind}", (base,), {
            "name": f"{feature.name}-{suffix}", "feature": feature, "unit": feature.unit,
            "features": frozenset({"lengths", "directions"}), "__module__": mod,
            "__doc__": f"``{feature.name}``: {base.__doc__}", "__reduce_ex__": _reduce_ex,
            **extra})

    qp = make(FeatureQPLaw, "qp", "QP", {})
    return FeatureControllers(
        pinv=make(FeatureLaw, "pinv", "PseudoInverse", {}),
        qp=qp,
        mpc=make(FeatureMPC, "mpc", "MPC", {"law_class": qp}),
        ctc=make(FeatureComputedTorque, "ctc", "ComputedTorque", {}))


def _reduce_ex(self: Any, protocol: Any) -> Any:
    """Pickle a generated controller by its module and registry name (its class is bound
    in the feature's module under a name of the author's choosing, not its own, so
    pickle cannot find it by ``__qualname__``): :func:`_instance_of` finds it again in
    that module, in this process or another. A class the module does not hold (made in
    a function) is copied and pickled as any object, which fails to pickle by name."""
    cls = type(self)
    if _generated(cls.__module__, cls.name) is cls:
        return (_instance_of, (cls.__module__, cls.name), self.__getstate__())
    return object.__reduce_ex__(self, protocol)


def _generated(module: str, name: str) -> type[Any] | None:
    """The generated controller class named ``name`` that ``module`` holds at its top
    level, itself or in a :class:`FeatureControllers` (None: none).

    Raises:
        LookupError: Two features of the module share the name (their controllers too).
    """
    found: list[type[Any]] = []
    for value in list(vars(importlib.import_module(module)).values()):
        for cls in value.all() if isinstance(value, FeatureControllers) else (value,):
            if (isinstance(cls, type) and getattr(cls, "__reduce_ex__", None) is _reduce_ex
                    and getattr(cls, "name", None) == name and cls not in found):
                found.append(cls)
    if len(found) > 1:
        features = sorted({type(cls.feature).__name__ for cls in found})
        raise LookupError(f"controller {name!r}: module {module} makes it from "
                          f"{len(features)} features of one name ({', '.join(features)}): "
                          "give each feature of a module its own name (it names its "
                          "controllers)")
    return found[0] if found else None


def _instance_of(module: str, name: str) -> Any:
    """An empty instance of the generated controller ``name`` of ``module`` (unpickling;
    the state is set after)."""
    cls: Any = _generated(module, name)
    if cls is None:
        raise LookupError(f"controller {name!r}: module {module} no longer makes it "
                          "(controllers_for at its top level)")
    return cls.__new__(cls)
