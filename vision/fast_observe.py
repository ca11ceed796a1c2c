"""Observation of the legs compiled to C, for a batch of worlds in one call.

:func:`observe_batch` is :func:`vision.legs.observe_legs` (the numpy reference) for
items that each have their own robot, camera and platform pose: the study engine
steps thousands of trials with calibration errors (a true world per trial) at once.
The C core (``vision/csrc/observe_kernels.c``) computes the legs in the camera frame,
the edge normals and the visibility of each edge's samples (imaged inside the image,
not hidden by another leg or by the platform disc), with the same decisions as the
numpy reference; the tests check them equal. Without a compiler it falls back to the
numpy reference, item by item.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.layout import Layout
from vision import kernels
from vision.cameras.distortion import RadialTangential

log = logging.getLogger(__name__)

#: Camera parameters per item: fx, skew, cx, fy, cy, xi, k1, k2, p1, p2, k3, fold radius.
N_CAMERA = 12
#: The C core's parameter row of one item (its ``OBS_N_IN`` numbers, in its order): the
#: platform pose in the base frame (``R`` row-major, ``t`` [m]), the base and platform
#: joint centres [m], the leg and platform disc radii [m], ``camera_from_base`` (rotation
#: row-major, translation [m]) and :func:`camera_vector`.
INPUTS = Layout([("R", (3, 3)), ("t", 3), ("base_points", (6, 3)),
                 ("platform_points", (6, 3)), ("leg_radius", ()), ("platform_radius", ()),
                 ("camera_rotation", (3, 3)), ("camera_translation", 3),
                 ("camera", N_CAMERA)], "leg observation input")
#: The C core's output row of one item (``OBS_N_OUT``): :class:`BatchObservation`'s
#: fields, the masks as 0 or 1.
OUTPUTS = Layout([("normals", (6, 2, 3)), ("exists", 6), ("visible_fraction", (6, 2)),
                  ("edge_visible", (6, 2)), ("base_points", (6, 3)), ("directions", (6, 3)),
                  ("lengths", 6), ("visible_interval", (6, 2, 2)), ("platform_centre", 3),
                  ("platform_normal", 3)], "leg observation output")
_R, _T = INPUTS["R"], INPUTS["t"]


def camera_vector(camera: Any) -> np.ndarray:
    """The 12 camera parameters of the C core (intrinsics, xi, distortion, fold radius)."""
    K = np.asarray(camera.K, float)
    d = np.zeros(5)
    fold = 0.0
    if getattr(camera, "is_distorted", False) and supported(camera):
        d[:] = camera.lens.coefficients
        r = float(camera.lens.fold_free_radius(np.array([1.0, 0.0])))
        fold = r if np.isfinite(r) else 0.0
    return np.array([K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2], float(camera.xi), *d, fold])


def supported(camera: Any) -> bool:
    """Whether the C core reproduces this camera's :meth:`project` exactly: no distortion,
    or OpenCV's radial one (five coefficients without decentring terms: its fold radius
    is the same in every direction). Other lenses (OpenCV's full model, the fisheye,
    double sphere and extended unified models) go through the numpy reference."""
    if not getattr(camera, "is_distorted", False):
        return True
    return type(camera.lens) is RadialTangential and bool(camera.lens.is_radial)


@dataclass
class WorldParams:
    """Per-item parameters of a batch of worlds (what :func:`observe_batch` needs).

    Attributes:
        base_points: (N, 6, 3) base joint centres, base frame [m].
        platform_points: (N, 6, 3) platform joint centres, platform frame [m].
        leg_radius: (N,) [m].
        platform_radius: (N,) radius of the platform disc [m].
        camera_rotation: (N, 3, 3) rotation of ``camera_from_base``.
        camera_translation: (N, 3) translation of ``camera_from_base`` [m].
        camera: (N, 12) :func:`camera_vector` of each item's camera.
        unified: Whether the cameras are unified (else perspective).
        width, height: Image size [px] (the same for every item).
        compiled: Whether the C core reproduces every item's camera (:func:`supported`);
            else :func:`observe_batch` runs the numpy reference item by item.
    """

    base_points: np.ndarray
    platform_points: np.ndarray
    leg_radius: np.ndarray
    platform_radius: np.ndarray
    camera_rotation: np.ndarray
    camera_translation: np.ndarray
    camera: np.ndarray
    unified: bool
    width: int
    height: int
    compiled: bool = True
    geometries: list[Any] | None = None
    cameras: list[Any] | None = None
    #: (N, :data:`INPUTS` size) the rows of :meth:`pack` without the poses (built on
    #: first use).
    constant_rows: np.ndarray | None = field(default=None, repr=False)

    @classmethod
    def from_worlds(cls, geometries: list[HexapodGeometry], cameras: list[Any]) -> WorldParams:
        """One item per (geometry, camera) pair; the platform disc radius is the largest
        distance of a platform joint from the platform origin (as in ``observe_legs``)."""
        kinds = {c.kind for c in cameras}
        sizes = {(int(c.width), int(c.height)) for c in cameras}
        if len(kinds) != 1 or len(sizes) != 1:
            raise ValueError(f"one camera kind and size per batch, got {kinds} and {sizes}")
        (width, height), = sizes
        # the arrays of each distinct robot and camera, then one row per item (a study
        # without calibration error has one world for all its trials)
        g_ids: dict[int, int] = {}
        g_idx = np.array([g_ids.setdefault(id(g), len(g_ids)) for g in geometries], dtype=int)
        c_ids: dict[int, int] = {}
        c_idx = np.array([c_ids.setdefault(id(c), len(c_ids)) for c in cameras], dtype=int)
        geos = list({id(g): g for g in geometries}.values())
        cams = list({id(c): c for c in cameras}.values())
        return cls(
            base_points=np.array([g.base_points for g in geos], float)[g_idx],
            platform_points=np.array([g.platform_points for g in geos], float)[g_idx],
            leg_radius=np.array([g.leg_radius for g in geos], float)[g_idx],
            platform_radius=np.array([float(np.max(np.linalg.norm(g.platform_points, axis=1)))
                                      for g in geos])[g_idx],
            camera_rotation=np.array([c.camera_from_base.rotation for c in cams], float)[c_idx],
            camera_translation=np.array([c.camera_from_base.translation for c in cams],
                                        float)[c_idx],
            camera=np.array([camera_vector(c) for c in cams])[c_idx],
            unified=kinds.pop() == "unified", width=width, height=height,
            compiled=all(supported(c) for c in cams), geometries=list(geometries),
            cameras=list(cameras))

    def pack(self, rotations: np.ndarray, translations: np.ndarray,
             items: np.ndarray | None = None) -> np.ndarray:
        """The (n, :data:`INPUTS` size) parameter rows of the C core for poses of items
        ``items`` (None: every item, in order)."""
        if self.constant_rows is None:  # the columns that do not depend on the pose
            c = np.zeros((len(self.leg_radius), INPUTS.size))
            for block in ("base_points", "platform_points", "leg_radius", "platform_radius",
                          "camera_rotation", "camera_translation", "camera"):
                INPUTS.view(c, block)[...] = getattr(self, block)
            self.constant_rows = c
        rows = (self.constant_rows.copy() if items is None
                else self.constant_rows[np.asarray(items)])
        rows[:, _R] = np.asarray(rotations, float).reshape(len(rows), 9)
        rows[:, _T] = translations
        return rows


@dataclass
class BatchObservation:
    """What :func:`observe_batch` returns, (n, ...) arrays in each item's camera frame.

    Attributes:
        normals: (n, 6, 2, 3) edge normals (NaN where the edges do not exist).
        exists: (n, 6) the projection centre is outside the leg cylinder.
        visible_fraction: (n, 6, 2) fraction of the visible samples of each edge.
        edge_visible: (n, 6, 2) the edge is observed.
        base_points: (n, 6, 3) ``A_i`` [m].
        directions: (n, 6, 3) ``u_i``.
        lengths: (n, 6) ``q_i`` [m].
        visible_interval: (n, 6, 2, 2) first and last visible sample (NaN: none).
        platform_centre: (n, 3) [m]; platform_normal: (n, 3).
    """

    normals: np.ndarray
    exists: np.ndarray
    visible_fraction: np.ndarray
    edge_visible: np.ndarray
    base_points: np.ndarray
    directions: np.ndarray
    lengths: np.ndarray
    visible_interval: np.ndarray
    platform_centre: np.ndarray
    platform_normal: np.ndarray


def compiled() -> bool:
    """Whether the C core is available (compiles the vision kernels on first call)."""
    return kernels.available()


def observe_batch(params: WorldParams, rotations: np.ndarray, translations: np.ndarray,
                  items: np.ndarray | None = None, n_samples: int = 16,
                  min_fraction: float = 0.5, occlusion: bool = True) -> BatchObservation:
    """Observe the legs of items ``items`` at their platform poses.

    Args:
        params: The worlds.
        rotations: (n, 3, 3) platform orientations in the base frames.
        translations: (n, 3) platform positions [m].
        items: (n,) indices of the items (all, in order, when None).
        n_samples: Samples per edge for the visibility test.
        min_fraction: Fraction of visible samples for an edge to be observed.
        occlusion: Test the occlusions by the legs and the platform disc.

    Returns:
        The :class:`BatchObservation`.
    """
    rows = params.pack(rotations, translations, items)
    n = rows.shape[0]
    lib = kernels.library()
    if lib is None or not params.compiled:
        idx = np.arange(len(params.leg_radius)) if items is None else np.asarray(items)
        return _observe_numpy(params, rows, idx, n_samples, min_fraction, occlusion)
    out = np.empty((n, OUTPUTS.size))
    if lib.hexapod_observe_batch(rows.ctypes.data, out.ctypes.data, n, float(params.width),
                                 float(params.height), int(params.unified), int(n_samples),
                                 float(min_fraction), int(occlusion)):
        raise MemoryError(f"observe_batch: no memory for the table of {n_samples} samples")
    return _unpack(out)


def segments_certainly_imaged(camera: Any, segments: np.ndarray) -> np.ndarray:
    """The compiled core's shortcut: segments it proves wholly inside the image.

    An edge whose samples all lie on a segment proved inside skips the projection of
    every sample (exact: without distortion, the image of a segment in front of a
    perspective camera is the segment of the images of its ends; with the unified
    model, its largest angle to the axis is at an end, see the C source).

    Args:
        camera: A camera (:class:`~vision.cameras.Camera` or
            :class:`~vision.cameras.UnifiedCamera`).
        segments: (n, 2, 3) segment ends in the camera frame [m].

    Returns:
        (n,) True where every point of the segment projects inside the image; False
        says nothing.

    Raises:
        RuntimeError: The C core is not available.
    """
    lib = kernels.library()
    if lib is None:
        raise RuntimeError("the vision kernels are not compiled (no C compiler?)")
    seg = np.ascontiguousarray(segments, dtype=float).reshape(-1, 6)
    out = np.empty(seg.shape[0])
    cam = np.ascontiguousarray(camera_vector(camera))
    lib.hexapod_segments_imaged(seg.ctypes.data, seg.shape[0], cam.ctypes.data,
                                int(camera.kind == "unified"), float(camera.width),
                                float(camera.height), out.ctypes.data)
    return out == 1.0


#: Each output block's slice and shape (:data:`OUTPUTS`; the views of every period's
#: batch are taken without the layout's checks, the array being the core's own).
_OUT_BLOCKS = tuple((name, OUTPUTS[name], OUTPUTS.shapes[name]) for name in OUTPUTS)


def _unpack(out: np.ndarray) -> BatchObservation:
    n = out.shape[0]
    fields = {name: out[:, s].reshape(n, *shape) for name, s, shape in _OUT_BLOCKS}
    for mask in ("exists", "edge_visible"):
        fields[mask] = fields[mask] > 0.5
    return BatchObservation(**fields)


def _observe_numpy(params: WorldParams, rows: np.ndarray, items: np.ndarray, n_samples: int,
                   min_fraction: float, occlusion: bool) -> BatchObservation:
    """The numpy reference, item by item (no compiler, or a camera the core cannot do)."""
    from vision.legs import observe_legs_numpy

    if params.geometries is None or params.cameras is None:
        raise ValueError("WorldParams without its geometries and cameras (use from_worlds)")
    out = []
    for row, k in zip(rows, items, strict=True):
        v = INPUTS.views(row)
        lo = observe_legs_numpy(params.cameras[k], params.geometries[k], v["R"], v["t"],
                                min_fraction, n_samples, float(v["platform_radius"]), occlusion)
        out.append(np.concatenate([np.ravel(getattr(lo, block)) for block in OUTPUTS]))
    return _unpack(np.array(out, dtype=float).reshape(len(rows), OUTPUTS.size))
