"""Features as plugins: one feature, one file, four compiled controllers.

A plugin defines a :class:`LegFeature` (its value for one leg, a CasADi expression of
the leg's direction, length and base point) and gets from :func:`controllers_for` the
pseudo-inverse (``<name>-pinv``), limit-QP (``<name>-qp``), predictive (``<name>-mpc``,
local model) and computed-torque (``<name>-ctc``) controllers, each stepping through a
kernel compiled to C from the feature's own expression (``docs/plugins.md``, "Adding a
feature"; the worked example is ``tests/controllers/plugin_feature_joints.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

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
            "__doc__": f"``{feature.name}``: {base.__doc__}", **extra})

    qp = make(FeatureQPLaw, "qp", "QP", {})
    return FeatureControllers(
        pinv=make(FeatureLaw, "pinv", "PseudoInverse", {}),
        qp=qp,
        mpc=make(FeatureMPC, "mpc", "MPC", {"law_class": qp}),
        ctc=make(FeatureComputedTorque, "ctc", "ComputedTorque", {}))
