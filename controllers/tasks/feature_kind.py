"""A built-in feature as an object: what the controllers read of it, in one place
(``docs/architecture.md``; ``docs/plugins.md``, "Built-in features are objects").

Each built-in feature object owns its definition (CasADi blocks, sizes, the observation
and goal fields it reads, its name in the generated kernels); the modules that build
controllers from a feature call its methods, none switches on a kind string. The
built-ins: :data:`~controllers.tasks.leg_edge.EDGE_NORMALS`,
:data:`~controllers.tasks.leg_edge.EDGE_LINES`,
:data:`~controllers.tasks.leg_direction.LEG_DIRECTIONS` (also a
:class:`~controllers.tasks.leg_feature.LegFeature`) and
:data:`~controllers.tasks.platform_pose.PLATFORM_POSE`.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from hexapod.compiled import Shape


class BuiltinFeature:
    """The interface every built-in feature object gives (see the module docstring).

    A method a feature has no use for raises :class:`ValueError` naming the feature and
    what was asked (e.g. the compiled computed-torque step of the image lines, which no
    controller builds).
    """

    #: The feature's name in the generated kernels' names and layouts
    #: (``"normals"``, ``"lines"``, ``"directions"``, ``"pose"``).
    kind: str = ""
    #: The :class:`~controllers.base.Observation` (and goal) field it is read from, None
    #: for a feature the camera does not give (the pose).
    field: str | None = None
    #: The observation's visibility mask of :attr:`field`.
    visibility: str | None = None
    #: The shape of :attr:`field` for one trial.
    shape: tuple[int, ...] = ()
    #: Unit vectors of one trial (12 edges, 6 legs; 0 for the pose).
    units: int = 0
    #: Rows of the stacked task error.
    task_rows: int = 0
    #: Its name in the compiled computed-torque steps' kernels and layouts (None: no
    #: compiled step).
    ctc_name: str | None = None
    #: The computed-torque task is written in the camera frame, over rows that may be
    #: hidden (a ``frame`` and a row ``mask`` input); False: the square pose task in
    #: the base frame.
    camera_task: bool = True
    #: The compiled computed-torque step can take the pose from the rigid fit of the
    #: legs seen (``fk=False``, ``vision-ctc``).
    visual_pose: bool = False
    #: The force-MPC kernel's name prefix (None: no force-MPC problem).
    force_mpc_name: str | None = None
    #: Values of the force-MPC problem's features of one stage.
    stage_features: int = 0

    def __repr__(self) -> str:
        return f"<feature {self.kind}>"

    def __reduce__(self) -> tuple[Any, tuple[str]]:
        """Pickled by reference: the one object of its kind in every process (the
        controllers, steps and problem specs that hold it compare and cache by it)."""
        return builtin_feature, (self.kind,)

    def _unsupported(self, what: str) -> ValueError:
        return ValueError(f"feature {self.kind!r}: no {what}")

    # ------------------------------------------------------------------ prediction
    def sx_of_legs(self, us: list[ca.SX], A: list[ca.SX], radius: ca.SX | float,
                   line_inv_t: ca.SX | None = None) -> list[ca.SX]:
        """The unit features (each (3, 1)) of legs of directions ``us`` and base points
        ``A`` (camera frame), as the camera sees them (all edges existing): the
        predictive controllers' global model and the computed-torque reference.

        Args:
            us: (3, 1) unit leg directions.
            A: (3, 1) base points [m], one per direction.
            radius: Leg radius [m].
            line_inv_t: ``K^-T`` of the camera's line matrix (image lines only).
        """
        raise self._unsupported("features of legs")

    def model_features(self, base_points: np.ndarray, directions: np.ndarray, radius: float,
                       line_matrix: np.ndarray | None) -> np.ndarray:
        """(units, 3) :meth:`sx_of_legs` in numpy: the features of six legs (base points
        and unit directions (6, 3), camera frame) seen through ``line_matrix``."""
        raise self._unsupported("features of legs")

    def line_inv_t(self, line_matrix: np.ndarray | None) -> np.ndarray:
        """``K^-T`` (3, 3) the prediction maps normals with (identity but for lines)."""
        return np.eye(3)

    # ------------------------------------------------------------------ computed torque
    def ctc_blocks(self, fk: bool) -> tuple[tuple[str, Shape], ...]:
        """The compiled computed-torque step's input blocks of the feature, after the
        common ones (:func:`controllers.solvers.compiled_task_ctc.layout`)."""
        raise self._unsupported("compiled computed-torque step")

    def sx_ctc_task(self, v: dict[str, ca.SX], q: ca.SX, R: ca.SX, t: ca.SX, tau_s: ca.SX
                    ) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
        """Error, Jacobian (the task frame's twist ``tau_s``), ``L_dot tau_s``, ``e_t`` and
        ``e_tt`` of the task in a compiled computed-torque step.

        Args:
            v: The step's input blocks (:meth:`ctc_blocks` among them).
            q: (6, 1) leg lengths [m].
            R: (3, 3) platform rotation (base frame).
            t: (3, 1) platform position [m] (base frame).
            tau_s: (6, 1) the task frame's twist.
        """
        raise self._unsupported("compiled computed-torque step")

    # ------------------------------------------------------------------ force MPC
    def sx_stage_features(self, t: ca.SX, R_column_major: ca.SX, normals: list[ca.SX]
                          ) -> ca.SX:
        """The force-MPC features of a stage (:attr:`stage_features`) from the platform
        position and rotation (base frame) and the twelve edge normals (camera frame)."""
        raise self._unsupported("force-MPC features")

    def task_of(self, desired: np.ndarray, **options: Any) -> Any:
        """The numpy :class:`~controllers.tasks.base.Task` towards ``desired``."""
        raise self._unsupported("task")


def builtin_feature(kind: str) -> BuiltinFeature:
    """The built-in feature object named ``kind`` (its name in the kernels).

    Raises:
        ValueError: No built-in feature has that name (naming the choices).
    """
    from controllers.tasks import BUILTIN_FEATURES

    for feature in BUILTIN_FEATURES:
        if feature.kind == kind:
            return feature
    raise ValueError(f"feature: expected one of "
                     f"{', '.join(f.kind for f in BUILTIN_FEATURES)}, got {kind!r}")
