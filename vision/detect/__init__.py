"""Leg-edge detection in images, for the unified (omnidirectional) and the perspective camera.

Both detectors output a :class:`EdgeDetection`: for each leg ``i`` and edge ``j``
the interpretation-plane normal ``n_ij`` (``docs/math.md`` sections 4 and 5, fitted from
the edge pixels lifted with the *given* camera model, i.e. the estimated one), the
number of points and the fit residual, and whether the edge was found. A missing
edge is reported as missing (``edge_visible`` False, NaN normal), never invented.

Order and orientation of the normals follow :func:`vision.legs.leg_edges`: edge 1
is the limb on the ``+h`` side of the plane through the projection centre and the
leg axis (``h = A x u``), and each normal is oriented to agree in sign with the
predicted normal of the same edge (``n1 = cos(theta) h - sin(theta) w``, ...). The
prediction (:class:`LegPrediction`) only has to be good enough to tell the two
edges of a leg apart and to associate image features with legs.

**Omnidirectional** (:class:`OmniDetector`, seed 003 section III-A): the image is
sampled along ``n_circles`` circles centred on the principal point with diameters
from ``d_min`` to ``d_max`` (nearest pixels, indices computed once), each 1D signal
is thresholded half-way between its darkest sample and its median (the background:
the legs cover a small part of every circle, a bright object may set its maximum),
and every leg crosses every circle as a dark band whose start and end are the two
edges. Each edge is then located with sub-sample accuracy as the strongest gradient
of its polarity near the transition (central differences of the bilinearly
interpolated signal, refined by a parabola), which does not depend on the grey
levels on either side (on a cluttered background the local level differs from the
circle's). An edge whose points lie farther than ``max_rms_px`` (RMS) from their
plane is reported missing; a straight dark object running along a leg can still
bias an edge within that tolerance (``docs/results.md``). Bands are associated to
legs by the angle where the predicted leg axis crosses the circle (the nearest
predicted leg wins, within half the distance to the next predicted leg); a band
whose width is far from the predicted width (two legs merged, clutter) is dropped.
No initialisation is needed: without a prediction the legs at the home pose are
used (the legs stay near their base joints' azimuth, which the calibration gives).

**Perspective** (:class:`PerspectiveTracker`, the moving-edges idea of ViSP):
``n_samples`` points are placed along each predicted edge segment; from each, a 1D
profile is read along the normal of the predicted line over ``+-search_px`` (exact
bilinear interpolation) and the strongest grey-level gradient of the right polarity
(dark leg inside, brighter background outside) is kept if stronger than
``min_contrast``, refined by a parabola. Samples that fall inside another leg's
predicted band (where a leg may hide the edge, or be hidden by it against a dark
background) are not used. A robust line (Theil-Sen on the offsets from the
predicted line, then a residual test) rejects the points of the remaining occluders
and clutter, and the normal is the robust least-squares fit of the inliers.

Initialisation and tracking (:meth:`PerspectiveTracker.track`, the policy of the
simulator's image sensor and of the servo loop's cameras): edges found in the
previous frame are searched around their last position; for the others, the model
prediction (the pose of the measured leg lengths, seen by the estimated camera) is
first aligned with the image by one translation (:meth:`PerspectiveTracker.align`:
the consensus of the twelve edges' gradient responses), which absorbs the image
offset of the calibration error (tens of pixels) without locking an edge onto
another leg's limb; a final narrow pass ends every frame. There is no
prediction-free (Hough/LSD) detection: the encoders always give the prediction.

**Lens distortion** (``camera.is_distorted``; an ideal lens runs exactly the code
above). The tracker's predictions are curves: the samples are the projections of
3D points of the predicted limbs, each searched along the image normal of its curve
(from :meth:`Camera.project_jacobian`), the occlusion gate works in the ideal
image where the legs' bands are straight, the Theil-Sen line runs on the offsets
from the curve, the edge points are lifted through the distortion before the fit
and the alignment translates the curved prediction
(:mod:`vision.detect.curves`). The omnidirectional scan stays in pixel space; the
rays of a circle keep a common elevation under a radial distortion (isotropic
``K``), so that case keeps the one-call compiled path with the circles' elevations
and pixels per radian computed through the lens; decentring terms (or an
anisotropic ``K``) break the rotational symmetry: the association reference is then
projected with the camera model and the rays of the edge points are interpolated
between the lifted rays of the circle's samples.

Both detectors run compiled cores (:mod:`vision.kernels`) that compute the same as
the numpy code of this package, which stays as the reference and the fallback.

Modules: :mod:`vision.detect.common` (prediction, result, robust plane fit),
:mod:`vision.detect.omni` (:class:`OmniDetector`), :mod:`vision.detect.tracker`
(:class:`PerspectiveTracker`), :mod:`vision.detect.curves` (the tracker's curved
predictions through a distorted lens), :mod:`vision.detect.profiles` (the tracker's
1D profiles and Theil-Sen line), :mod:`vision.detect.draw` (:func:`draw_detection`).
"""

from vision.detect.common import EdgeDetection, LegPrediction, fit_normals
from vision.detect.common import _robust_fit as _robust_fit
from vision.detect.draw import draw_detection
from vision.detect.omni import OmniDetector
from vision.detect.profiles import _pixel_lines as _pixel_lines
from vision.detect.tracker import PerspectiveTracker
from vision.exceptions import DetectionError

__all__ = [
    "DetectionError",
    "EdgeDetection",
    "LegPrediction",
    "OmniDetector",
    "PerspectiveTracker",
    "draw_detection",
    "fit_normals",
]
