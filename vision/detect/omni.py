"""The omnidirectional leg-edge detector: seed 003's circle scan (section III-A)."""

from __future__ import annotations

from typing import Any

import numpy as np

from hexapod.geometry import HexapodGeometry
from vision.cameras import Camera
from vision.detect.common import (
    EdgeDetection,
    LegPrediction,
    _check_image,
    _robust_fit,
)
from vision.exceptions import DetectionError

#: Points per segment of the model-based association reference
#: (:meth:`OmniDetector._model_crossings`).
CROSSING_SAMPLES = 65


class OmniDetector:
    """Automatic leg-edge detector for a unified camera looking along the legs.

    The circles are scanned in pixel space, whatever the lens. Through a distorted
    lens the circles' elevations, the rays of the edge points and the pixels per
    radian (along the circles, across the edges) come from the camera model with the
    distortion; without the image's rotational symmetry (decentring terms, or an
    anisotropic ``K``) the association reference is projected with the camera model
    too (see :mod:`vision.detect`).

    Args:
        camera: The (estimated) unified camera: its principal point centres the
            circles and its model lifts the edge pixels.
        d_min: Smallest circle diameter [px] (seed 003: 184).
        d_max: Largest circle diameter [px] (seed 003: 370).
        n_circles: Number of circles (seed 003: 17).
        n_angles: Samples per circle.
        min_points: Minimal number of inlier points for an edge.
        outlier_px: Points farther than this from the fitted edge are rejected [px].
        max_rms_px: An edge whose inliers' RMS distance exceeds this is missing [px].
        width_tolerance: A band is kept if its angular width is within a factor
            ``width_tolerance`` of the predicted one.
        min_contrast: Minimal grey-level range along a circle for it to be used.
    """

    def __init__(
        self,
        camera: Camera,
        d_min: float = 184.0,
        d_max: float = 370.0,
        n_circles: int = 17,
        n_angles: int = 1024,
        min_points: int = 5,
        outlier_px: float = 1.5,
        max_rms_px: float = 0.5,
        width_tolerance: float = 1.8,
        min_contrast: float = 40.0,
    ) -> None:
        if not 0 < d_min < d_max:
            raise DetectionError("d_min/d_max", f"expected 0 < d_min < d_max, got {d_min}, "
                                                f"{d_max}")
        if n_circles < 2 or n_angles < 16:
            raise DetectionError("n_circles/n_angles", f"too few: {n_circles}, {n_angles}")
        self.camera = camera
        self.d_min, self.d_max = float(d_min), float(d_max)
        self.n_circles, self.n_angles = int(n_circles), int(n_angles)
        self.min_points = int(min_points)
        self.outlier_px = float(outlier_px)
        self.max_rms_px = float(max_rms_px)
        self.width_tolerance = float(width_tolerance)
        self.min_contrast = float(min_contrast)
        cx, cy = camera.cx, camera.cy
        W, H = camera.width, camera.height
        self.radii = np.linspace(0.5 * d_min, 0.5 * d_max, n_circles)
        self.angles = np.arange(n_angles) * (2.0 * np.pi / n_angles)
        mx = cx + self.radii[:, None] * np.cos(self.angles)[None, :]
        my = cy + self.radii[:, None] * np.sin(self.angles)[None, :]
        inside = (mx >= 0) & (mx <= W - 2) & (my >= 0) & (my <= H - 2)
        if not np.all(inside):
            raise DetectionError(
                "d_max", f"circles of diameter up to {d_max} px around ({cx:.1f}, {cy:.1f}) "
                         f"leave the {W}x{H} image")
        # Nearest-pixel flat indices (coarse signal) and bilinear data (refinement).
        self._idx = (np.rint(my).astype(np.intp) * W + np.rint(mx).astype(np.intp))
        x0, y0 = np.floor(mx), np.floor(my)
        self._base = (y0.astype(np.intp) * W + x0.astype(np.intp))
        self._fx, self._fy = mx - x0, my - y0
        self._W = W
        # Unit rays of the samples: exact rays at the sample points, and the elevation
        # (z) and pixels-per-radian of each circle.
        pix = np.stack([mx, my], -1)
        self._rays = camera.lift(pix)
        self._z = np.nanmean(self._rays[..., 2], axis=1)
        r_in = camera.lift(np.stack([cx + self.radii - 0.5, np.full_like(self.radii, cy)], -1))
        r_out = camera.lift(np.stack([cx + self.radii + 0.5, np.full_like(self.radii, cy)], -1))
        d_ang = np.arccos(np.clip(np.sum(r_in * r_out, -1), -1.0, 1.0))
        self._px_per_rad = 1.0 / d_ang  # (n_circles,)
        # Exact lift of a point at (circle k, fractional sample position) is the
        # rotation of the circle's ray only for fx = fy, no skew and a lens without
        # decentring terms (a radial distortion keeps the image rotationally symmetric).
        self._isotropic = bool(camera.K[0, 1] == 0 and camera.fx == camera.fy
                               and camera.lens.is_radial)
        # Through a distorted lens: the residuals are scaled by the pixels per radian
        # along the circle (across a leg's edge, which crosses the circles nearly
        # radially; a distorted image is not conformal), per sample, and without the
        # rotational symmetry the association reference and the rays of the edge points
        # come from the camera model (_model_crossings, _table_rays).
        self._model = bool(camera.is_distorted and not self._isotropic)
        self._ppr_table: np.ndarray | None = None
        if camera.is_distorted:
            h = 0.5 / self.radii[:, None]  # half a pixel along the circle [rad]
            ends = [np.stack([cx + self.radii[:, None] * np.cos(self.angles + e),
                              cy + self.radii[:, None] * np.sin(self.angles + e)], -1)
                    for e in (-h, h)]
            a_lo, a_hi = camera.lift(ends[0]), camera.lift(ends[1])
            table = 1.0 / np.arccos(np.clip(np.sum(a_lo * a_hi, -1), -1.0, 1.0))
            self._ppr_table = table  # (n_circles, n_angles)
            self._px_per_rad = np.mean(table, axis=1)
        self._default: LegPrediction | None = None
        self._geometry: HexapodGeometry | None = None
        self._ref_key: LegPrediction | None = None
        self._ref: tuple[np.ndarray, ...] = ()
        self._kernel: Any = None  # vision.kernels.OmniKernel, built on first use

    def default_prediction(self, geometry: HexapodGeometry) -> LegPrediction:
        """The legs at the home pose (the automatic mode's association reference)."""
        if self._default is None or self._geometry is not geometry:
            self._default = LegPrediction.from_pose(self.camera, geometry)
            self._geometry = geometry
        return self._default

    # ----------------------------------------------------------------- reference
    def _crossings(self, P0: np.ndarray, d: np.ndarray, length: np.ndarray) -> np.ndarray:
        """Azimuth [rad] where the segments ``P0 + s d`` (s in [0, length]) cross the
        cone of each circle: (..., n_circles), NaN if they do not."""
        if self._model:
            return self._model_crossings(P0, d, length)
        Z = self._z
        P0 = P0[..., None, :]
        d = d[..., None, :]
        a = d[..., 2] ** 2 - Z**2 * np.sum(d * d, -1)
        b = 2.0 * (P0[..., 2] * d[..., 2] - Z**2 * np.sum(P0 * d, -1))
        c = P0[..., 2] ** 2 - Z**2 * np.sum(P0 * P0, -1)
        disc = b * b - 4 * a * c
        with np.errstate(invalid="ignore", divide="ignore"):
            sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
            best = np.full(a.shape, np.nan)
            for sgn in (-1.0, 1.0):
                s = (-b + sgn * sq) / (2 * a)
                z = P0[..., 2] + s * d[..., 2]
                ok = (s >= 0) & (s <= length[..., None]) & (z * Z >= 0)
                best = np.where(ok & np.isnan(best), s, best)
            P = P0 + best[..., None] * d
        if self.camera.K[0, 1] == 0:
            # The unified projection scales (X, Y) by a positive factor, then K by
            # (fx, fy): the image azimuth about the principal point is that of
            # (fx X, fy Y) (NaN where no crossing).
            return np.arctan2(self.camera.fy * P[..., 1], self.camera.fx * P[..., 0])
        pix, _ = self.camera.project(P)
        return np.arctan2(pix[..., 1] - self.camera.cy, pix[..., 0] - self.camera.cx)

    def _model_crossings(self, P0: np.ndarray, d: np.ndarray, length: np.ndarray
                         ) -> np.ndarray:
        """:meth:`_crossings` from the camera model (an image without rotational
        symmetry): each segment is projected at :data:`CROSSING_SAMPLES` points and the
        azimuth of its first crossing of each circle is interpolated linearly between
        the two projected points around it (NaN if it does not cross)."""
        s = np.linspace(0.0, 1.0, CROSSING_SAMPLES)
        X = (P0[..., None, :]
             + (s[:, None] * np.asarray(length)[..., None, None]) * d[..., None, :])
        pix, _ = self.camera.project(X)  # (..., S, 2)
        rel = pix - np.array([self.camera.cx, self.camera.cy])
        diff = np.hypot(rel[..., 0], rel[..., 1])[..., None, :] - self.radii[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            cross = diff[..., :-1] * diff[..., 1:] <= 0  # False where NaN
            k = np.argmax(cross, axis=-1)[..., None]
            d0 = np.take_along_axis(diff, k, -1)[..., 0]
            d1 = np.take_along_axis(diff, k + 1, -1)[..., 0]
            f = np.where(d0 != d1, d0 / (d0 - d1), 0.0)
            r0 = np.take_along_axis(rel[..., None, :, :], k[..., None], -2)[..., 0, :]
            r1 = np.take_along_axis(rel[..., None, :, :], k[..., None] + 1, -2)[..., 0, :]
            p = r0 + f[..., None] * (r1 - r0)
            az = np.arctan2(p[..., 1], p[..., 0])
        return np.where(np.any(cross, axis=-1), az, np.nan)

    def _table_rays(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays (..., 3) of edge points at azimuths ``a`` (6, 2, C) [rad] on the circles,
        and their pixels per radian (6, 2, C): the lifted rays of the circle's two
        neighbouring samples (``camera.lift``, distortion removed) interpolated
        linearly and normalised (the samples are about a pixel apart: the point lies
        within 0.001 px of the chord, the lift is smooth) and the nearest sample's
        entry of the table of pixels per radian."""
        N = self.n_angles
        pos = a * (N / (2.0 * np.pi))
        j0 = np.floor(pos)
        f = (pos - j0)[..., None]
        j0 = j0.astype(np.intp) % N
        j1 = (j0 + 1) % N
        c = np.arange(self.n_circles)
        X = (1.0 - f) * self._rays[c, j0] + f * self._rays[c, j1]
        X /= np.linalg.norm(X, axis=-1, keepdims=True)
        table = self._ppr_table if self._ppr_table is not None else np.broadcast_to(
            self._px_per_rad[:, None], (self.n_circles, N))
        near = np.where(f[..., 0] < 0.5, j0, j1)
        return X, table[c, near]

    def _reference(self, prediction: LegPrediction) -> tuple[np.ndarray, ...]:
        """Per (leg, circle): predicted axis azimuth, association gate, predicted band
        width [rad] and whether edge 1 comes first (smaller azimuth). Cached."""
        if self._ref_key is prediction:
            return self._ref
        A, u, q, r = (prediction.base_points, prediction.directions, prediction.lengths,
                      prediction.radius)
        starts = np.stack([A, A + r * prediction.normals[:, 0], A + r * prediction.normals[:, 1]])
        dirs = np.broadcast_to(u, starts.shape)
        ref = self._crossings(starts, dirs, np.broadcast_to(q, starts.shape[:-1]))
        axis = ref[0]  # (6, C)
        d = np.abs(_wrap(axis[:, None, :] - axis[None, :, :]))  # (6, 6, C)
        d = np.where(np.eye(6, dtype=bool)[..., None] | np.isnan(d), np.inf, d)
        gate = np.minimum(0.5 * d.min(axis=1), np.deg2rad(20.0))
        de = _wrap(ref[1] - ref[2])
        width = np.abs(de)
        e1_first = de < 0
        self._ref = (np.nan_to_num(axis, nan=1e3), np.where(np.isnan(axis), 0.0, gate),
                     np.nan_to_num(width, nan=0.0), e1_first)
        self._ref_key = prediction
        return self._ref

    # ----------------------------------------------------------------- detect
    def scan(self, image: np.ndarray) -> np.ndarray:
        """The coarse (nearest-pixel) polar samples (n_circles, n_angles) uint8."""
        image = _check_image(image, self.camera)
        return np.ravel(image)[self._idx]

    def _bilinear(self, flat: np.ndarray, c: np.ndarray, j: np.ndarray) -> np.ndarray:
        b = self._base[c, j]
        fx, fy = self._fx[c, j], self._fy[c, j]
        W = self._W
        v00, v01 = flat[b].astype(float), flat[b + 1].astype(float)
        v10, v11 = flat[b + W].astype(float), flat[b + W + 1].astype(float)
        return (1 - fy) * ((1 - fx) * v00 + fx * v01) + fy * ((1 - fx) * v10 + fx * v11)

    def track(
        self, image: np.ndarray, prediction: LegPrediction,
        previous: np.ndarray | None = None, align_px: float = 0.0, refine_px: float = 0.0,
    ) -> EdgeDetection:
        """Detect the edges of one frame of a sequence (same call as
        :meth:`PerspectiveTracker.track`): the scan is global; the normals found in
        the previous frame (finite rows of ``previous``) replace the model's in the
        association reference. ``align_px`` and ``refine_px`` are not used."""
        if previous is not None:
            prediction = prediction.with_normals(np.asarray(previous, float))
        return self.detect(image, prediction)

    def detect(
        self, image: np.ndarray, prediction: LegPrediction | None = None,
        geometry: HexapodGeometry | None = None, use_compiled: bool = True,
    ) -> EdgeDetection:
        """Detect the twelve leg edges.

        Args:
            image: (height, width) uint8 grey image (BGR is converted).
            prediction: Predicted legs (association and edge order); default: the
                home pose of ``geometry``. Derived data are cached while the same
                prediction object is passed.
            geometry: The robot, needed when ``prediction`` is None.
            use_compiled: Use the compiled scan and fit (:mod:`vision.kernels`) when
                they are available; False runs the numpy reference (same results).

        Returns:
            An :class:`EdgeDetection` (``expected_points = n_circles``).
        """
        from vision import kernels

        if prediction is None:
            if geometry is None:
                raise DetectionError("prediction", "give a prediction or the geometry")
            prediction = self.default_prediction(geometry)
        image = _check_image(image, self.camera)
        refs = self._reference(prediction)
        compiled = use_compiled and kernels.available()
        C = self.n_circles
        if compiled:
            if self._kernel is None:
                self._kernel = kernels.OmniKernel(
                    self._idx, self._base, self._fx, self._fy, self._W, self.radii,
                    self._z, self._px_per_rad, (self.camera.cx, self.camera.cy))
            if self._isotropic:
                normals, vis, cnt, rms, pts = self._kernel.detect(
                    image, refs, prediction.normals, self.min_contrast,
                    self.width_tolerance, self.outlier_px, self.min_points,
                    self.max_rms_px, iterations=1)
                return EdgeDetection(normals, vis, cnt, rms, pts, C)
            pts_a = self._kernel.scan(image, refs, self.min_contrast, self.width_tolerance)
        else:
            pts_a = self._scan(image, refs)
        valid = np.isfinite(pts_a)
        a = np.where(valid, pts_a, 0.0)
        r = self.radii
        px = self.camera.cx + r * np.cos(a)
        py = self.camera.cy + r * np.sin(a)
        ppr: np.ndarray = self._px_per_rad
        if self._isotropic:
            z = self._z
            rho = np.sqrt(np.maximum(1.0 - z * z, 0.0))
            rays = np.stack([rho * np.cos(a), rho * np.sin(a), np.broadcast_to(z, a.shape)], -1)
        elif self._model:
            rays, ppr = self._table_rays(a)
        else:
            rays = self.camera.lift(np.stack([px, py], -1))
        normals, vis, cnt, rms, inl = _robust_fit(
            rays, valid, ppr, prediction.normals, self.outlier_px,
            self.min_points, self.max_rms_px, iterations=1, use_compiled=compiled)
        pts = np.where(inl[..., None], np.stack([px, py], -1), np.nan)
        return EdgeDetection(normals, vis, cnt, rms, pts, C)

    def _scan(self, image: np.ndarray, refs: tuple[np.ndarray, ...]) -> np.ndarray:
        """The numpy circle scan: azimuths (6, 2, C) of the edge points [rad] (NaN
        where none), the reference of the compiled ``omni_scan``."""
        flat = np.ravel(image)
        sig = flat[self._idx]
        C, N = sig.shape
        lo = sig.min(axis=1)
        # The background level of a circle is its (lower) median: the legs cover a
        # small part of every circle, while its maximum may be a bright object.
        bg = np.partition(sig, (N - 1) // 2, axis=1)[:, (N - 1) // 2]
        thr_i = ((lo.astype(np.uint16) + bg + 1) // 2).astype(np.uint8)
        thr_i[(bg.astype(float) - lo) < self.min_contrast] = 0  # flat circle: no band
        dark = (sig < thr_i[:, None]).view(np.int8)
        # Transitions: +1 = first dark sample of a band, -1 = first bright after it.
        step = np.empty_like(dark)
        np.subtract(dark[:, 1:], dark[:, :-1], out=step[:, 1:])
        np.subtract(dark[:, :1], dark[:, -1:], out=step[:, :1])
        c_t, j_t = np.nonzero(step)
        is_start = step[c_t, j_t] > 0
        c_s, j_s = c_t[is_start], j_t[is_start]
        c_e, j_e = c_t[~is_start], j_t[~is_start]
        axis_ref, gate_ref, width_ref, e1_first_ref = refs
        pts_a = np.full((6, 2, C), np.nan)  # azimuth of each edge point [rad]
        if c_s.size:
            # Pair each band start with the next end on the same circle (wrapping).
            key_e = c_e * N + j_e
            idx = np.searchsorted(key_e, c_s * N + j_s)
            first = np.searchsorted(key_e, c_s * N)
            wrap = (idx >= key_e.size) | (c_e[np.minimum(idx, key_e.size - 1)] != c_s)
            je = j_e[np.where(wrap, first, idx)]
            a_c = (j_s + 0.5 * ((je - j_s) % N)) * (2 * np.pi / N)  # coarse centre
            width = ((je - j_s) % N) * (2 * np.pi / N)
            diff = np.abs(_wrap(a_c[:, None] - axis_ref[:, c_s].T))  # (nb, 6)
            leg = np.argmin(diff, axis=1)
            dbest = diff[np.arange(leg.size), leg]
            w_ref = width_ref[leg, c_s]
            tol = self.width_tolerance
            ok = (dbest < gate_ref[leg, c_s]) & (width < tol * w_ref + 2 * np.pi / N) & (
                width > w_ref / tol - 2 * np.pi / N)
            if np.any(ok):
                c_k, leg_k, d_k, js, jek = c_s[ok], leg[ok], dbest[ok], j_s[ok], je[ok]
                # One band per (circle, leg): the nearest to the prediction.
                key = c_k * 6 + leg_k
                order = np.lexsort((d_k, key))
                ks = key[order]
                keep = order[np.concatenate([[True], ks[1:] != ks[:-1]])]
                c_k, leg_k, js, jek = c_k[keep], leg_k[keep], js[keep], jek[keep]
                # Sub-sample edges: the strongest gradient of the edge's polarity
                # (falling at a band start, rising at its end) among the central
                # differences at samples j-2 .. j+1 of the bilinear signal, refined
                # by a parabola through it and its neighbours.
                cc = np.concatenate([c_k, c_k])
                jj = np.concatenate([js, jek])
                sign = np.concatenate([np.full(js.size, -1.0), np.full(jek.size, 1.0)])
                b = np.stack([self._bilinear(flat, cc, (jj + o) % N) for o in range(-3, 3)],
                             axis=-1)
                g = 0.5 * (b[:, 2:] - b[:, :-2]) * sign[:, None]  # at samples j-2 .. j+1
                rows = np.arange(jj.size)
                kk = np.clip(np.argmax(g, axis=1), 1, 2)
                gm, g0, gp = g[rows, kk - 1], g[rows, kk], g[rows, kk + 1]
                den = gm - 2 * g0 + gp
                with np.errstate(invalid="ignore", divide="ignore"):
                    frac = np.where(den < 0, 0.5 * (gm - gp) / den, 0.0)
                frac = np.clip(frac, -0.5, 0.5)
                ang = (jj - 2 + kk + frac) * (2 * np.pi / N)
                n_k = c_k.size
                a_start, a_end = ang[:n_k], ang[n_k:]
                first1 = e1_first_ref[leg_k, c_k]
                pts_a[leg_k, 0, c_k] = np.where(first1, a_start, a_end)
                pts_a[leg_k, 1, c_k] = np.where(first1, a_end, a_start)
        return pts_a


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi

