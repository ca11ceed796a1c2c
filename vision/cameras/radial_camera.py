"""The common base of the cameras whose lens is a central radial model.

:class:`RadialLensCamera` is a perspective camera whose lens map is one of
:mod:`vision.cameras.radial` (its :attr:`~RadialLensCamera.lens_type`): rays in front of
the camera only (``Z > 0``); the ideal image (lines ``K^-T n``) is the pinhole's
``K (X/Z, Y/Z)``, which the perspective pipeline (renderer, tracker, calibration) uses
with the lens as for any distortion. The models (:mod:`vision.cameras.fisheye`,
:mod:`vision.cameras.double_sphere`, :mod:`vision.cameras.eucm`) only name their lens,
its default coefficients and their ``kind``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from vision.cameras.lens import Lens
from vision.cameras.perspective import PerspectiveCamera
from vision.cameras.radial import RadialLens
from vision.exceptions import CameraError


class RadialLensCamera(PerspectiveCamera):
    """A perspective camera whose lens is a :class:`vision.cameras.radial.RadialLens`.

    Constructed as :class:`~vision.cameras.perspective.PerspectiveCamera` (the same
    arguments and errors; ``name`` None: the model's ``kind``), except ``distortion``:
    the lens model's coefficients in the order of its ``names`` (None:
    :attr:`default_distortion`).
    """

    #: The lens map of the model (a subclass of :class:`~vision.cameras.radial.RadialLens`).
    lens_type: ClassVar[type[RadialLens]]
    #: The coefficients of ``distortion=None``.
    default_distortion: ClassVar[tuple[float, ...]]

    def _make_lens(self, distortion: Any) -> tuple[Lens, np.ndarray]:
        coefficients = self.default_distortion if distortion is None else distortion
        lens = self.lens_type(coefficients, self.source)
        return lens, np.array(lens.coefficients)

    def lens_scaled(self, factor: float) -> PerspectiveCamera:
        """The camera itself (``factor`` 1) or, ignoring the lens (``factor`` 0), the
        pinhole camera of the same ``K``, pose and name (what a pipeline without this
        model uses).

        Raises:
            CameraError: Another factor (the lens has no partial form).
        """
        if factor == 1.0:
            return self
        if factor == 0.0:
            return PerspectiveCamera(self.K, self.width, self.height, self.camera_from_base,
                                     self.name, self.source)
        raise CameraError("distortion", f"a {self.kind} lens is modelled (0 %) or ignored "
                                        f"(100 %), not in part (factor {factor:g})",
                          self.source)
