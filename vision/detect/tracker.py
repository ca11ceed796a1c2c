"""The perspective leg-edge tracker (moving edges with a global alignment)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vision.cameras import Camera, PerspectiveCamera
from vision.detect.common import (
    EdgeDetection,
    LegPrediction,
    _check_image,
    _orient,
    _robust_fit,
    fit_normals,
)
from vision.detect.curves import curved_samples, lift_near, lift_near_parts, pixels_per_radian
from vision.detect.profiles import (
    _NO_GRADIENT,
    _gradient_profiles,
    _pixel_lines,
    _theil_sen_inliers,
)
from vision.exceptions import DetectionError


class PerspectiveTracker:
    """Tracker of the two edges of each leg in a perspective image.

    Through a distorted lens (``camera.is_distorted``) the predicted edges are curves
    (:mod:`vision.detect.curves`): samples on the projected limbs, searched along the
    curves' normals, lifted through the distortion; an ideal lens keeps the straight
    segments.

    Args:
        camera: The (estimated) perspective camera (lifts the edge pixels).
        n_samples: Sample points per edge.
        search_px: Half-length of the 1D search along the normal [px].
        refine_px: Half-length of the second, narrow pass around the first fit [px]
            (0: no second pass).
        min_contrast: Minimal gradient of a valid edge point [grey levels per px].
        end_margin: Fraction of the segment left out at each end (joints, caps).
        occlusion_margin_px: Samples closer than this to another leg's predicted band
            are not used [px].
        min_points: Minimal number of inliers for an edge.
        outlier_px: Inlier distance to the robust line [px].
        max_rms_px: An edge whose inliers' RMS distance exceeds this is missing [px].
    """

    def __init__(
        self,
        camera: Camera,
        n_samples: int = 24,
        search_px: float = 12.0,
        refine_px: float = 0.0,
        min_contrast: float = 12.0,
        end_margin: float = 0.06,
        occlusion_margin_px: float = 3.0,
        min_points: int = 6,
        outlier_px: float = 1.0,
        max_rms_px: float = 0.8,
    ) -> None:
        if not isinstance(camera, PerspectiveCamera) and camera.xi != 0:
            raise DetectionError("camera", "the tracker needs a perspective camera")
        if n_samples < 4:
            raise DetectionError("n_samples", f"must be >= 4, got {n_samples}")
        if search_px < 1:
            raise DetectionError("search_px", f"must be >= 1, got {search_px}")
        self.camera = camera
        self.n_samples = int(n_samples)
        self.search_px = float(search_px)
        self.refine_px = float(refine_px)
        self.min_contrast = float(min_contrast)
        self.end_margin = float(end_margin)
        self.occlusion_margin_px = float(occlusion_margin_px)
        self.min_points = int(min_points)
        self.outlier_px = float(outlier_px)
        self.max_rms_px = float(max_rms_px)
        self._Kinv = np.linalg.inv(camera.K)
        self._f = 0.5 * (camera.fx + camera.fy)
        self._kernel: Any = None  # vision.kernels.TrackKernel, built on first use

    # ----------------------------------------------------------------- geometry
    def predicted_segments(self, prediction: LegPrediction) -> np.ndarray:
        """(6, 2, 2, 2) pixel end points of the predicted edges: the projections of the
        limb end points ``A + r n + s q u`` (s = 0, 1), moved onto the predicted line
        (through a distorted lens, where the edge is a curve: the end points moved onto
        the plane of ``n`` in 3D, then projected, so that they lie on the curve)."""
        A, u, q, r, n = (prediction.base_points, prediction.directions, prediction.lengths,
                         prediction.radius, prediction.normals)
        s = np.array([0.0, 1.0])
        P = (A[:, None, None, :] + r * n[:, :, None, :]
             + (s[None, None, :, None] * q[:, None, None, None]) * u[:, None, None, :])
        if self.camera.is_distorted:
            P = P - np.sum(P * n[:, :, None, :], -1, keepdims=True) * n[:, :, None, :]
            return np.asarray(self.camera.project(P)[0])
        pix, _ = self.camera.project(P)
        lines = _pixel_lines(self.camera, n)  # (6, 2, 3), (a, b) unit
        d = np.sum(lines[:, :, None, :2] * pix, -1) + lines[:, :, None, 2]
        return pix - d[..., None] * lines[:, :, None, :2]

    def detect(
        self, image: np.ndarray, prediction: LegPrediction,
        search_px: float | None = None, refine_px: float | None = None,
        use_compiled: bool = True,
    ) -> EdgeDetection:
        """Find the twelve edges near their prediction.

        Args:
            image: (height, width) uint8 grey image (BGR is converted).
            prediction: Predicted legs in the estimated camera frame.
            search_px: Overrides the search half-length of this call [px].
            refine_px: Overrides the second-pass half-length of this call [px].
            use_compiled: Use the compiled robust fit (:mod:`vision.kernels`) when it
                is available; False runs the numpy reference (same results).

        Returns:
            An :class:`EdgeDetection` (``expected_points = n_samples``).
        """
        image = _check_image(image, self.camera)
        search = self.search_px if search_px is None else float(search_px)
        refine = self.refine_px if refine_px is None else float(refine_px)
        if self.camera.is_distorted:
            det = self._curved_pass(image, prediction, search, use_compiled)
            if refine > 0:
                ok = det.edge_visible
                det = self._curved_pass(image, prediction.with_normals(det.normals),
                                        np.where(ok, refine, search), use_compiled)
            return det
        seg = self.predicted_segments(prediction)
        lines = _pixel_lines(self.camera, prediction.normals)
        det = self._pass(image, seg, lines, prediction, search, use_compiled)
        if refine > 0:
            ok = det.edge_visible
            l2 = np.where(ok[..., None], _pixel_lines(self.camera, det.normals), lines)
            d = np.sum(l2[:, :, None, :2] * seg, -1) + l2[:, :, None, 2]
            seg2 = seg - d[..., None] * l2[:, :, None, :2]
            pred2 = prediction.with_normals(det.normals)
            det = self._pass(image, seg2, l2, pred2, np.where(ok, refine, search),
                             use_compiled)
        return det

    def _pass(
        self, image: np.ndarray, seg: np.ndarray, lines: np.ndarray,
        prediction: LegPrediction, search: float | np.ndarray, use_compiled: bool = True,
    ) -> EdgeDetection:
        """One search pass: profiles along the normals of the predicted edges, the
        strongest gradient of the right polarity on each, occlusion gate, Theil-Sen
        line, robust plane fit. The compiled core (:class:`vision.kernels.TrackKernel`)
        computes the same as :meth:`_profile_offsets`, :meth:`_contested`,
        :func:`_theil_sen_inliers` and :func:`_robust_fit` below."""
        from vision import kernels

        M = self.n_samples
        t, P, out = self._samples(seg, lines)
        search_arr = np.broadcast_to(np.asarray(search, float), (6, 2))
        R = math.ceil(float(np.max(search_arr)))
        if use_compiled and kernels.available():
            if self._kernel is None:
                self._kernel = kernels.TrackKernel(self.camera.width, self.camera.height, M)
            normals, vis, cnt, rms, pts = self._kernel.track(
                image, P, out, search_arr, R, t, seg, lines, prediction.normals,
                self.occlusion_margin_px, self.min_contrast, self.outlier_px, self._Kinv,
                self._f, (self.camera.cx, self.camera.cy), self.min_points, self.max_rms_px,
                iterations=2)
            return EdgeDetection(normals, vis, cnt, rms, pts, M)
        offset, valid = self._profile_offsets(image, P, out, search_arr, R)
        valid &= ~self._contested(P, seg, lines)
        valid &= _theil_sen_inliers(offset, valid, t, 2.0 * self.outlier_px)
        pts = P + offset[..., None] * out[:, :, None, :]
        pts = np.where(valid[..., None], pts, np.nan)
        rays = self._lift(np.where(valid[..., None], pts, 0.0))
        normals, vis, cnt, rms, inl = _robust_fit(
            rays, valid, self._px_per_rad(pts), prediction.normals, self.outlier_px,
            self.min_points, self.max_rms_px, use_compiled=False)
        return EdgeDetection(normals, vis, cnt, rms, np.where(inl[..., None], pts, np.nan), M)

    def _positions(self) -> np.ndarray:
        """(M,) positions of the samples along the edges (fractions, ends left out)."""
        M = self.n_samples
        m = self.end_margin
        return np.asarray(m + (1 - 2 * m) * (np.arange(M) + 0.5) / M)

    def _curved_pass(
        self, image: np.ndarray, prediction: LegPrediction, search: float | np.ndarray,
        use_compiled: bool = True,
    ) -> EdgeDetection:
        """:meth:`_pass` through a distorted lens: samples on the predicted curves,
        profiles along the curves' normals, occlusion gate in the ideal image
        (:func:`vision.detect.curves.curved_samples`), Theil-Sen on the offsets, the
        edge points lifted through the distortion (:func:`vision.detect.curves.lift_near`)
        with their own pixels per radian, robust plane fit. The compiled path
        (:meth:`vision.kernels.TrackKernel.points`, :func:`vision.kernels.fit_planes`)
        computes the same as the numpy one; the lift is shared."""
        from vision import kernels

        M = self.n_samples
        t = self._positions()
        cs = curved_samples(self.camera, prediction, t, self.occlusion_margin_px)
        search_arr = np.broadcast_to(np.asarray(search, float), (6, 2))
        R = math.ceil(float(np.max(search_arr)))
        compiled = use_compiled and kernels.available()
        if compiled:
            if self._kernel is None:
                self._kernel = kernels.TrackKernel(self.camera.width, self.camera.height, M)
            offset, valid = self._kernel.points(
                image, cs.P, cs.out, search_arr, R, t, cs.gate, cs.seg, cs.lines, cs.margin,
                self.min_contrast, self.outlier_px)
        else:
            offset, valid = self._profile_offsets(image, cs.P, cs.out, search_arr, R)
            valid &= ~self._contested(cs.gate, cs.seg, cs.lines, cs.margin)
            valid &= _theil_sen_inliers(offset, valid, t, 2.0 * self.outlier_px)
        pts = np.where(valid[..., None], cs.P + offset[..., None] * cs.out, np.nan)
        rays, m, jac = lift_near_parts(self.camera, pts, cs.m, cs.md, cs.jac)
        rays = np.where(valid[..., None], rays, 0.0)
        ppr = pixels_per_radian(self.camera, m, prediction.normals, jac)
        normals, vis, cnt, rms, inl = _robust_fit(
            rays, valid, ppr, prediction.normals, self.outlier_px, self.min_points,
            self.max_rms_px, use_compiled=compiled)
        return EdgeDetection(normals, vis, cnt, rms, np.where(inl[..., None], pts, np.nan), M)

    def _samples(self, seg: np.ndarray, lines: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions ``t`` (M,) along the segments, sample points ``P`` (6, 2, M, 2) [px]
        and the outward unit normals ``out`` (6, 2, 2) (away from the leg's other edge)."""
        t = self._positions()
        p0, p1 = seg[:, :, 0, :], seg[:, :, 1, :]
        P = p0[:, :, None, :] + t[None, None, :, None] * (p1 - p0)[:, :, None, :]  # (6,2,M,2)
        nrm = lines[..., :2]  # unit (a, b): the line normal in pixels
        other = lines[:, ::-1]
        side = np.sum(other[:, :, None, :2] * P, -1) + other[:, :, None, 2]  # (6,2,M)
        sgn = np.sign(np.sum(side, -1) * np.sum(nrm * other[..., :2], -1))  # (6, 2)
        out = nrm * np.where(sgn == 0, 1.0, sgn)[..., None]
        return t, P, out

    def track(
        self, image: np.ndarray, prediction: LegPrediction,
        previous: np.ndarray | None = None, align_px: float = 40.0, refine_px: float = 4.0,
    ) -> EdgeDetection:
        """Detect the edges of one frame of a sequence (the policy of every caller).

        Edges found in the previous frame (finite rows of ``previous``) are searched
        around their last position (``search_px``); if any edge was not found, the
        model prediction is first aligned with the image (:meth:`align`, translations
        up to ``align_px``) and gives the others. A second pass of ``refine_px``
        around the first fit ends every frame, so that the final samples depend on
        the detected lines, not on the history of predictions (the goal image and the
        images near it are measured alike).

        Args:
            image: (height, width) uint8 grey image (BGR is converted).
            prediction: The model's prediction (e.g. at the pose of the measured leg
                lengths) in the estimated camera frame.
            previous: (6, 2, 3) normals of the previous frame, NaN where not found
                (None: first frame).
            align_px: Largest translation of the alignment [px] (0: no alignment).
            refine_px: Half-length of the final pass [px] (0: none).

        Returns:
            An :class:`EdgeDetection`.
        """
        tracked = np.zeros((6, 2), bool)
        if previous is not None:
            prev = np.asarray(previous, float)
            if prev.shape != (6, 2, 3):
                raise DetectionError("previous", f"expected shape (6, 2, 3), got {prev.shape}")
            tracked = np.all(np.isfinite(prev), axis=-1)
        base = prediction
        if not tracked.all() and align_px > 0:
            _, base = self.align(image, prediction, align_px)
        if tracked.any():
            base = base.with_normals(np.where(tracked[..., None], prev, np.nan))
        return self.detect(image, base, self.search_px, refine_px)

    def align(
        self, image: np.ndarray, prediction: LegPrediction, max_shift_px: float = 40.0,
        use_compiled: bool = True,
    ) -> tuple[np.ndarray, LegPrediction]:
        """The image translation that best aligns the predicted edges with the image.

        A calibration error (camera pose, intrinsics) moves the whole image of the
        robot by about the same amount, often more than the tracker's search window:
        a per-edge search then picks whatever strong edge of the right polarity is
        nearest, possibly another leg's limb. Instead, every edge's gradient response
        towards the bright outside (positive part, summed over its samples outside
        the other legs' predicted bands) is read as a function of the offset along
        its normal, and the one translation ``(dx, dy)`` maximising the total
        response of the twelve edges (integer pixels within ``max_shift_px``) is
        kept: an edge of another leg in one window cannot outvote the others.

        Args:
            image: (height, width) uint8 grey image.
            prediction: Predicted legs in the estimated camera frame.
            max_shift_px: Largest translation tried in each axis [px].
            use_compiled: Use the compiled core (:func:`vision.kernels.align_shift`)
                when it is available; False runs the numpy reference (same shift).

        Returns:
            ``shift`` (2,) [px] and the prediction with its edges moved by it.
        """
        from vision import kernels

        image = _check_image(image, self.camera)
        if not max_shift_px >= 1:
            raise DetectionError("max_shift_px", f"must be >= 1, got {max_shift_px}")
        if self.camera.is_distorted:
            return self._curved_align(image, prediction, float(max_shift_px), use_compiled)
        seg = self.predicted_segments(prediction)
        lines = _pixel_lines(self.camera, prediction.normals)
        _, P, out = self._samples(seg, lines)
        R = math.ceil(float(max_shift_px)) + 1
        if use_compiled and kernels.available():
            shift = kernels.align_shift(image, P, out, seg, lines, self.occlusion_margin_px,
                                        R, float(max_shift_px))
        else:
            shift = self._align_numpy(image, P, out, seg, lines, R, float(max_shift_px))
        moved = lines.copy()
        moved[..., 2] -= moved[..., 0] * shift[0] + moved[..., 1] * shift[1]
        with np.errstate(invalid="ignore", divide="ignore"):  # any camera with xi = 0
            n = moved @ self.camera.K
            n /= np.linalg.norm(n, axis=-1, keepdims=True)
        return shift, prediction.with_normals(n)

    def _curved_align(self, image: np.ndarray, prediction: LegPrediction, max_shift_px: float,
                      use_compiled: bool) -> tuple[np.ndarray, LegPrediction]:
        """:meth:`align` through a distorted lens. The samples lie on the predicted
        curves and the occlusion gate works in the ideal image (as in
        :meth:`_curved_pass`); each edge's profiles are read along one direction, the
        mean of its curve's normals (a translation ``s`` then moves the edge by
        ``s . out`` along them, up to ``|s|`` times the turn of the curve's normal
        from the mean, a few degrees), and the translation maximising the summed
        response is kept as for an ideal lens. The moved prediction: the plane of each
        edge fitted to its samples moved by the translation and lifted through the
        distortion."""
        from vision import kernels

        cs = curved_samples(self.camera, prediction, self._positions(),
                            self.occlusion_margin_px)
        out = cs.edge_out
        R = math.ceil(max_shift_px) + 1
        if use_compiled and kernels.available():
            shift = kernels.align_shift(image, cs.P, out, cs.seg, cs.lines, cs.margin, R,
                                        max_shift_px, gate=cs.gate)
        else:
            shift = self._align_numpy(image, cs.P, out, cs.seg, cs.lines, R, max_shift_px,
                                      gate=cs.gate, margin=cs.margin)
        rays, _ = lift_near(self.camera, cs.P + shift, cs.m)
        ok = np.all(np.isfinite(rays), axis=-1)
        n, _ = fit_normals(np.where(ok[..., None], rays, 0.0), ok.astype(float))
        n = np.where((ok.sum(-1) >= 2)[..., None], _orient(n, prediction.normals), np.nan)
        return shift, prediction.with_normals(n)

    def _align_numpy(self, image: np.ndarray, P: np.ndarray, out: np.ndarray, seg: np.ndarray,
                     lines: np.ndarray, R: int, max_shift_px: float,
                     gate: np.ndarray | None = None, margin: np.ndarray | None = None,
                     ) -> np.ndarray:
        """The numpy reference of the alignment's shift (see :meth:`align`; ``gate`` and
        ``margin``: the occlusion gate's coordinates and margins, default ``P`` and
        ``occlusion_margin_px``)."""
        _, grad = _gradient_profiles(image, P, out, R)
        grad = np.maximum(grad, 0.0)
        use = np.all(np.isfinite(P), -1) & ~self._contested(
            P if gate is None else gate, seg, lines, margin)
        G = np.sum(np.where(use[..., None], grad, 0.0), axis=2)  # (6, 2, 2R - 1)
        G = np.where(np.all(np.isfinite(out), -1)[..., None], G, 0.0)
        d = np.arange(-(R - 1), R, dtype=float)
        d = d[np.abs(d) <= max_shift_px]
        DX, DY = np.meshgrid(d, d, indexing="ij")
        o = DX.ravel()[:, None, None] * out[..., 0] + DY.ravel()[:, None, None] * out[..., 1]
        o = np.nan_to_num(o, nan=0.0) + (R - 1)  # index into G (S, 6, 2)
        k0 = np.clip(np.floor(o).astype(np.intp), 0, G.shape[-1] - 2)
        w = np.clip(o - k0, 0.0, 1.0)
        ii, jj = np.meshgrid(np.arange(6), np.arange(2), indexing="ij")
        score = np.sum((1 - w) * G[ii, jj, k0] + w * G[ii, jj, k0 + 1], axis=(1, 2))
        best = int(np.argmax(score))
        return np.array([DX.ravel()[best], DY.ravel()[best]])

    def _profile_offsets(
        self, image: np.ndarray, P: np.ndarray, out: np.ndarray, search: np.ndarray, R: int,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Edge offset along ``out`` of every sample [px] and whether it is valid.

        The profile through sample ``P`` is read at the integer offsets ``-R .. R``
        along ``out`` (exact bilinear interpolation, 0 outside the image); its central
        difference at the offsets ``o`` with ``|o| <= search`` whose point lies in the
        image is the gradient towards the outside (bright). The strongest one (the
        first on ties) is refined by a parabola through it and its neighbours (no
        refinement when a neighbour is not a candidate); it is valid if at least
        ``min_contrast`` and not at ``o = +-(R - 1)``.
        """
        Q, grad = _gradient_profiles(image, P, out, R)
        finite = np.all(np.isfinite(Q), axis=(-2, -1))
        g_off = np.arange(-(R - 1), R, dtype=float)
        candidate = np.abs(g_off)[None, None, None, :] <= search[..., None, None]
        Qg = Q[..., 1:-1, :]
        in_img = ((Qg[..., 0] >= 0) & (Qg[..., 0] <= self.camera.width - 1)
                  & (Qg[..., 1] >= 0) & (Qg[..., 1] <= self.camera.height - 1))
        g = np.where(candidate & in_img, grad, _NO_GRADIENT)
        L = g.shape[-1]
        k = np.argmax(g, axis=-1)
        km = np.clip(k, 1, max(L - 2, 1))
        gk = np.take_along_axis(g, k[..., None], -1)[..., 0]
        if L >= 3:
            gm, g0, gp = (np.take_along_axis(g, (km + d)[..., None], -1)[..., 0]
                          for d in (-1, 0, 1))
        else:
            gm = g0 = gp = np.zeros(k.shape)
        den = gm - 2 * g0 + gp
        with np.errstate(invalid="ignore", divide="ignore"):
            frac = np.where((den < 0) & (den > -1e5), 0.5 * (gm - gp) / den, 0.0)
        frac = np.clip(frac, -0.5, 0.5)
        offset = g_off[km] + frac if L >= 1 else np.zeros(k.shape)
        valid = finite & (gk >= self.min_contrast) & (k == km) & (L >= 3)
        return offset, valid

    def _lift(self, pix: np.ndarray) -> np.ndarray:
        h = np.concatenate([pix, np.ones((*pix.shape[:-1], 1))], -1) @ self._Kinv.T
        return h / np.linalg.norm(h, axis=-1, keepdims=True)

    def _px_per_rad(self, pts: np.ndarray) -> np.ndarray:
        # Distance to a line in pixels ~ angle * f / cos^2 of the ray angle (at most):
        # |n.X| is the sine of the angle between the ray and the plane; one pixel
        # across the line at radius rho from the centre is about f / (f^2 + rho^2)
        # ^(1/2) * cos... use the local scale f * (1 + (rho/f)^2) ^ 0.5.
        d = np.nan_to_num(pts - np.array([self.camera.cx, self.camera.cy]))
        rho2 = np.sum(d * d, -1) / self._f**2
        return self._f * np.sqrt(1.0 + rho2)

    def _contested(self, P: np.ndarray, seg: np.ndarray, lines: np.ndarray,
                   margin: np.ndarray | None = None) -> np.ndarray:
        """(6, 2, M): samples inside (or within the margin of) another leg's band
        (``margin`` (6, 2, M) per sample [px], default ``occlusion_margin_px``)."""
        mg: Any = self.occlusion_margin_px if margin is None else margin[..., None]
        # Signed distances of every sample to both edge lines of every leg k.
        d = (np.einsum("ijmx,kex->ijmke", P, lines[..., :2]) + lines[None, None, None, :, :, 2])
        # Inside leg k: on opposite sides of its two lines (the band between them).
        d1, d2 = d[..., 0], d[..., 1]
        s1 = np.sign(np.sum(lines[:, 0, :2] * lines[:, 1, :2], -1))  # (6,) same/opposite normals
        between = (d1 * d2 * s1 <= 0) | (np.abs(d1) < mg) | (np.abs(d2) < mg)
        # Within the leg's extent along its axis (with the margin).
        c0 = 0.5 * (seg[:, 0, 0] + seg[:, 1, 0])  # (6, 2) base end centre
        c1 = 0.5 * (seg[:, 0, 1] + seg[:, 1, 1])
        ax = c1 - c0
        L = np.linalg.norm(ax, axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            axu = ax / L[:, None]
        tt = np.einsum("ijmkx,kx->ijmk", P[:, :, :, None, :] - c0, axu)
        along = (tt >= -mg) & (tt <= L + mg)
        hit = between & along & np.isfinite(tt)
        hit &= ~np.eye(6, dtype=bool)[:, None, None, :]
        return np.any(hit, axis=-1)

