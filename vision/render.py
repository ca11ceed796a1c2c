"""Synthetic grayscale images of the legs of a Gough-Stewart platform (OpenCV).

Each leg is a solid cylinder of radius ``geometry.leg_radius`` around the segment
``A_i .. B_i`` (``docs/math.md`` section 4). The image is drawn with the painter's
algorithm: the objects (six legs and, optionally, the platform disc) are sorted by
the distance of their centre to the projection centre and filled from the farthest
to the nearest (the order of the true depths wherever two legs overlap in the image,
checked per pixel by ray casting on random poses), the platform disc first or last
depending on the side of its plane the camera is on (:meth:`Renderer.draw_order`).
Each polygon is blended into the image by its exact coverage of every pixel (the
area of the pixel's unit square inside it, i.e. the box filter of
an ideal sensor pixel; :class:`vision.polygon_fill.PolygonFiller`, compiled C), so a
rendered edge has its 50 % level on the true edge whatever its direction and
sub-pixel position. Without a C compiler the renderer falls back to OpenCV's
anti-aliased polygons (``cv2.fillPoly`` with ``LINE_AA`` and 4 fractional bits,
shrunk by ``aa_compensation_px``), whose edges are off by up to about 0.1 px
depending on direction and sub-pixel position.

A leg is drawn as nested bands between pairs of generators of the cylinder (the
outermost pair being the two limbs, i.e. the edges of ``docs/math.md`` section 4) plus
its two end discs. The bands carry a Lambertian shading for a light at the camera:
the intensity at the generator of angle ``phi`` from the generator facing the camera
is ``edge + (centre - edge) cos(phi)``, so the limbs (``phi = phi0``) are the
darkest part of the leg. Each band is sampled along the leg at ``edge_samples``
points, projected with the camera model: 2 points suffice for a perspective camera
(straight lines), a unified camera images straight lines as conics, so its bands are
sampled densely. Through a distorted lens (``camera.is_distorted``) the image of each
generator is a curve: it is drawn as an adaptive polyline whose vertices are true
projections of points of the generator, refined until every chord is within
``curve_tolerance_px`` of the curve (:mod:`vision.render_curves`), so the exact
coverage keeps the drawn limbs within hundredths of a pixel of the true curved limbs;
an ideal lens is drawn exactly as before (same polygons, same pixels).

Backgrounds: ``"plain"`` (uniform, bright, as in seed 003) or ``"cluttered"``
(a seeded low-frequency texture plus random rectangles, discs and lines). The
cluttered background stays brighter than the legs (levels >= ``clutter_min``) so
that legs remain dark objects: the detectors of :mod:`vision.detect` rely on this
polarity.

After drawing, an optional Gaussian blur (optics, ``blur_px`` is the standard
deviation [px]) and an additive Gaussian pixel noise (sensor, ``noise_std`` [grey
levels]) are applied. The noise is drawn once into a bank from the renderer's
generator and each frame uses a random window of it (saturating ``cv2.add`` /
``cv2.subtract``), which keeps a 1024x780 frame at about a millisecond.
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from typing import Any

import cv2
import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import legs_in_frame
from vision.cameras import Camera, PerspectiveCamera
from vision.exceptions import RenderError
from vision.render_curves import projected_polylines
from vision.render_style import BACKGROUNDS, RenderStyle, make_background

logger = logging.getLogger(__name__)

#: Fractional bits of the fixed-point vertices given to OpenCV (1/16 px).
_SHIFT = 4
_SCALE = float(1 << _SHIFT)


class Renderer:
    """Renders the legs of a robot seen by a camera.

    Args:
        camera: The camera (its ``camera_from_base`` places it in the base frame).
        geometry: The robot (leg radius ``geometry.leg_radius``).
        style: How to draw (default :class:`RenderStyle`).
        rng: Generator (or seed) of the pixel noise.
        use_compiled: Fill by exact coverage (compiled C) when available; False
            uses OpenCV's anti-aliased polygons (the fallback).

    Example:
        >>> r = Renderer(front_camera(), deltalab(), RenderStyle(blur_px=0.8))
        >>> image = r.render(*home_pose(deltalab()))
    """

    def __init__(
        self,
        camera: Camera,
        geometry: HexapodGeometry,
        style: RenderStyle | None = None,
        rng: np.random.Generator | int | None = None,
        use_compiled: bool = True,
    ) -> None:
        self.camera = camera
        self.geometry = geometry
        self.style = RenderStyle() if style is None else style
        self.rng = np.random.default_rng(rng)
        self.background = make_background(camera.width, camera.height, self.style)
        n_edge = self.style.edge_samples
        if n_edge is None:
            n_edge = 2 if isinstance(camera, PerspectiveCamera) else 24
        self._s = np.linspace(0.0, 1.0, n_edge)
        nb = self.style.shading_bands
        # Band k spans |phi| in [phi0 * f[k+1], phi0 * f[k]]; f[0] = 1 is the limb.
        self._band_fractions = 1.0 - np.arange(nb) / nb
        mid = 1.0 - (np.arange(nb) + 0.5) / nb
        e, c = self.style.leg_edge_level, self.style.leg_centre_level
        # Level of band k: shading at the middle of its angular range (phi0 ~ 90 deg
        # for thin legs, so cos(phi) ~ cos(90 deg * mid)); band 0 holds the limbs.
        lv = e + (c - e) * np.cos(0.5 * np.pi * mid)
        lv[0] = e
        self._levels = [round(x) for x in lv]
        psi = np.linspace(0.0, 2.0 * np.pi, self.style.cap_samples, endpoint=False)
        self._cap_cs = np.stack([np.cos(psi), np.sin(psi)], axis=-1)
        rho = self.style.platform_radius
        if rho is None:
            rho = float(np.max(np.linalg.norm(geometry.platform_points, axis=1)))
        self._platform_radius = float(rho)
        psi = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
        self._disc_cs = np.stack([np.cos(psi), np.sin(psi)], axis=-1)
        self._left_sizes: list[int] = []  # vertices of limb 1 in the last curved polygons
        self._noise_pos: np.ndarray | None = None
        self._noise_neg: np.ndarray | None = None
        from vision import kernels
        from vision.polygon_fill import PolygonFiller

        self._filler = (PolygonFiller(camera.width, camera.height)
                        if use_compiled and kernels.available() else None)

    @property
    def exact(self) -> bool:
        """Whether polygons are filled by their exact pixel coverage (compiled C);
        False: OpenCV's anti-aliased polygons (fallback)."""
        return self._filler is not None

    def with_style(self, **changes: Any) -> Renderer:
        """A renderer with some style fields changed (same camera, geometry, generator)."""
        return Renderer(self.camera, self.geometry, replace(self.style, **changes), self.rng,
                        use_compiled=self.exact)

    # ------------------------------------------------------------------ drawing
    def _shrink(self, pix: np.ndarray) -> np.ndarray:
        """Offset polygons (..., V, 2) inwards by ``aa_compensation_px`` (mitred)."""
        d = self.style.aa_compensation_px
        if d == 0:
            return pix
        e = np.roll(pix, -1, axis=-2) - pix  # edge k: vertex k -> k+1
        area = np.sum(pix[..., 0] * np.roll(pix[..., 1], -1, -1)
                      - np.roll(pix[..., 0], -1, -1) * pix[..., 1], axis=-1)
        sgn = np.where(area >= 0, 1.0, -1.0)[..., None, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            # Outward unit normal of each edge (for a counter-clockwise polygon in a
            # y-down image, area > 0 means clockwise on screen: the sign handles both).
            nrm = sgn * np.stack([e[..., 1], -e[..., 0]], -1)
            nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
        nrm = np.nan_to_num(nrm)
        prev = np.roll(nrm, 1, axis=-2)
        den = np.maximum(1.0 + np.sum(prev * nrm, -1, keepdims=True), 0.3)
        return pix - d * (prev + nrm) / den

    def _to_fixed(self, pix: np.ndarray) -> np.ndarray:
        # Keep coordinates in a range OpenCV's fixed-point arithmetic accepts.
        lim = 8.0 * max(self.camera.width, self.camera.height)
        pix = np.clip(np.nan_to_num(pix, nan=0.0), -lim, lim)
        return np.round(pix * _SCALE).astype(np.int32)

    def _leg_polygons(
        self, A: np.ndarray, u: np.ndarray, q: np.ndarray, exact: bool | None = None,
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray]:
        """Pixel polygons of the six legs, all projected at once.

        Returns:
            ``bands`` (6, nb, 2 Ns, 2) (a distorted camera: nested lists ``[i][k]`` of
            polygons (V, 2), see :meth:`_curved_leg_polygons`), ``caps`` (6, 2, C, 2)
            [px] (for the fallback: shrunk by ``aa_compensation_px``, int32 fixed
            point), ``ok_bands`` (6, nb) and ``ok_caps`` (6, 2) (every vertex imaged).
            Band 0 is the silhouette: its first half runs along limb 1 (edge normal
            ``n1``, from the base end), its second half back along limb 2.
            ``exact``: the polygons of the exact renderer (default: of this renderer).
        """
        exact = self._filler is not None if exact is None else exact
        r = self.geometry.leg_radius
        h = np.cross(A, u)
        hn = np.linalg.norm(h, axis=-1)
        exists = hn > r
        hn_safe = np.where(exists, hn, 1.0)
        h_hat = h / hn_safe[:, None]
        w = np.cross(u, h_hat)
        phi0 = np.arccos(np.clip(r / hn_safe, -1.0, 1.0))  # limb angle from -w
        phi = phi0[:, None] * self._band_fractions[None, :]  # (6, nb)
        c, s_ = np.cos(phi)[..., None], np.sin(phi)[..., None]
        m_left = -c * w[:, None, :] + s_ * h_hat[:, None, :]
        m_right = -c * w[:, None, :] - s_ * h_hat[:, None, :]
        ends = np.stack([A, A + q[:, None] * u], axis=1)  # (6, 2, 3)
        ring = (self._cap_cs[None, :, :1] * h_hat[:, None, :]
                + self._cap_cs[None, :, 1:] * w[:, None, :])  # (6, C, 3)
        caps = ends[:, :, None, :] + r * ring[:, None, :, :]
        if self.camera.is_distorted:
            return self._curved_leg_polygons(A, u, q, m_left, m_right, caps, exists, exact)
        axis = A[:, None, :] + (self._s[None, :, None] * q[:, None, None]) * u[:, None, :]
        left = axis[:, None] + r * m_left[:, :, None, :]
        right = axis[:, None] + r * m_right[:, :, None, :]
        bands = np.concatenate([left, right[:, :, ::-1]], axis=2)
        nb, nv = bands.shape[1], bands.shape[2]
        pts = np.concatenate([bands.reshape(6, -1, 3), caps.reshape(6, -1, 3)], axis=1)
        pix, _ = self.camera.project(pts)
        fin = np.isfinite(pix).all(axis=-1)
        nbv = nb * nv
        ok_bands = fin[:, :nbv].reshape(6, nb, nv).all(-1) & exists[:, None]
        ok_caps = fin[:, nbv:].reshape(6, 2, -1).all(-1) & exists[:, None]
        pb, pc = pix[:, :nbv].reshape(6, nb, nv, 2), pix[:, nbv:].reshape(6, 2, -1, 2)
        if not exact:  # fallback: shrunk fixed-point polygons, all at once
            pb, pc = self._to_fixed(self._shrink(pb)), self._to_fixed(self._shrink(pc))
        return pb, pc, ok_bands, ok_caps

    def _curved_leg_polygons(
        self, A: np.ndarray, u: np.ndarray, q: np.ndarray, m_left: np.ndarray,
        m_right: np.ndarray, caps: np.ndarray, exists: np.ndarray, exact: bool,
    ) -> tuple[list[list[np.ndarray]], np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_leg_polygons` through a distorted lens: each generator of a band (a
        3D segment) is drawn as an adaptive polyline within ``curve_tolerance_px`` of
        its curved image (:func:`vision.render_curves.projected_polylines`), starting
        from ``edge_samples`` points (at least 5); ``bands[i][k]`` is a polygon of its
        own length. The end discs are projected at their ``cap_samples`` points."""
        r = self.geometry.leg_radius
        nb = m_left.shape[1]
        gen = np.stack([m_left, m_right], axis=2)  # (6, nb, 2, 3)
        starts = A[:, None, None, :] + r * gen
        stops = starts + (q[:, None] * u)[:, None, None, :]
        s0 = self._s if self._s.size >= 5 else np.linspace(0.0, 1.0, 5)
        lines = projected_polylines(self.camera, starts.reshape(-1, 3), stops.reshape(-1, 3),
                                    s0, self.style.curve_tolerance_px)
        bands: list[list[np.ndarray]] = []
        ok_bands = np.zeros((6, nb), bool)
        self._left_sizes = [lines[i * nb * 2].shape[0] for i in range(6)]  # limb 1 of band 0
        for i in range(6):
            row = []
            for k in range(nb):
                left, right = lines[(i * nb + k) * 2], lines[(i * nb + k) * 2 + 1]
                poly = np.concatenate([left, right[::-1]], axis=0)
                ok_bands[i, k] = bool(exists[i] and np.all(np.isfinite(poly)))
                row.append(poly)
            bands.append(row)
        pc, _ = self.camera.project(caps)
        ok_caps = np.isfinite(pc).all(-1).all(-1) & exists[:, None]
        if not exact:  # fallback: each polygon shrunk, in fixed point
            bands = [[self._to_fixed(self._shrink(b)) for b in row] for row in bands]
            pc = self._to_fixed(self._shrink(pc))
        return bands, pc, ok_bands, ok_caps

    def limb_polylines(self, rotation: np.ndarray, translation: np.ndarray
                       ) -> list[list[np.ndarray | None]]:
        """The limbs as the exact renderer draws them, before any occlusion.

        Args:
            rotation: (3, 3) platform orientation in the base frame.
            translation: (3,) platform position in the base frame [m].

        Returns:
            ``limbs[i][j]`` (V, 2) [px]: the side of leg ``i``'s silhouette polygon along
            edge ``j`` (the limb on the plane of normal ``n_j`` of
            :func:`vision.legs.leg_edges`), from the base end to the platform end; None
            where the silhouette is not drawn (camera inside the leg, a point not imaged).
        """
        T = self.camera.camera_from_base
        legs = legs_in_frame(self.geometry, np.asarray(rotation, float),
                             np.asarray(translation, float), T)
        bands, _, ok, _ = self._leg_polygons(legs.base_points, legs.directions, legs.lengths,
                                             exact=True)
        out: list[list[np.ndarray | None]] = []
        for i in range(6):
            poly = np.asarray(bands[i][0])
            n_left = self._left_sizes[i] if self.camera.is_distorted else poly.shape[0] // 2
            out.append([poly[:n_left] if ok[i, 0] else None,
                        poly[n_left:][::-1] if ok[i, 0] else None])
        return out

    def _leg_shapes(self, i: int, bands: Any, caps: np.ndarray,
                    ok_bands: np.ndarray, ok_caps: np.ndarray
                    ) -> list[tuple[list[np.ndarray], int]]:
        """The shapes of leg i: its end discs and outer band (the silhouette) at the
        edge level, then the inner bands, lighter towards the generator facing the
        camera."""
        outer = [caps[i, k] for k in range(2) if ok_caps[i, k]]
        if ok_bands[i, 0]:
            outer.append(bands[i][0])
        shapes = [(outer, self._levels[0])] if outer else []
        shapes += [([bands[i][k]], self._levels[k]) for k in range(1, ok_bands.shape[1])
                   if ok_bands[i, k]]
        return shapes

    def _platform_shape(self, centre: np.ndarray, R_cam: np.ndarray
                        ) -> list[tuple[list[np.ndarray], int]]:
        rho = self._platform_radius
        pts = centre + rho * (self._disc_cs[:, :1] * R_cam[:, 0] + self._disc_cs[:, 1:]
                              * R_cam[:, 1])
        pix, _ = self.camera.project(pts)
        if not np.all(np.isfinite(pix)):
            return []
        if self._filler is None:
            pix = self._to_fixed(self._shrink(pix))
        return [([pix], self.style.platform_level)]

    def _draw(self, img: np.ndarray, shapes: list[tuple[list[np.ndarray], int]]) -> None:
        """Draw shapes in order: exact coverage in one compiled call, or the fallback
        (each polygon shrunk by ``aa_compensation_px``, OpenCV ``LINE_AA``)."""
        if self._filler is not None:
            self._filler.draw(img, [(polys, float(level)) for polys, level in shapes])
            return
        for polys, level in shapes:  # already shrunk and in fixed point
            cv2.fillPoly(img, polys, (float(level),), cv2.LINE_AA, _SHIFT)

    def _noise_bank(self, size: int) -> tuple[np.ndarray, np.ndarray]:
        if self._noise_pos is None or self._noise_pos.size < 2 * size:
            noise = np.rint(self.rng.normal(0.0, self.style.noise_std, size=2 * size))
            noise = np.clip(noise, -255, 255)
            self._noise_pos = np.clip(noise, 0, 255).astype(np.uint8)
            self._noise_neg = np.clip(-noise, 0, 255).astype(np.uint8)
        neg = self._noise_neg
        if neg is None:  # set together with _noise_pos
            raise RenderError("noise_std", "noise bank not initialised")
        return self._noise_pos, neg

    def draw_order(self, rotation: np.ndarray, translation: np.ndarray) -> list[int]:
        """The objects in the order they are drawn (farthest first): leg indices 0-5,
        and -1 for the platform disc (when the style draws it).

        Args:
            rotation: (3, 3) platform orientation in the base frame.
            translation: (3,) platform position in the base frame [m].
        """
        T = self.camera.camera_from_base
        legs = legs_in_frame(self.geometry, np.asarray(rotation, float),
                             np.asarray(translation, float), T)
        return self._order(legs.base_points, legs.directions, legs.lengths,
                           T.apply(np.asarray(translation, float)),
                           T.rotation @ np.asarray(rotation, float))

    def _order(self, A: np.ndarray, u: np.ndarray, q: np.ndarray, centre: np.ndarray,
               R_cam: np.ndarray) -> list[int]:
        depth = np.linalg.norm(A + 0.5 * q[:, None] * u, axis=1)
        items: list[tuple[float, int]] = [(float(depth[i]), i) for i in range(6)]
        if self.style.platform:
            # Every leg lies on the base side of the platform plane (it touches it at
            # its joint on the rim): the disc hides every leg from a camera on the
            # other side, and none from a camera on the base side.
            normal = R_cam[:, 2]
            camera_side = float(-centre @ normal)
            base_side = float(np.mean(A, axis=0) @ normal - centre @ normal)
            items.append((-np.inf if camera_side * base_side < 0 else np.inf, -1))
        return [i for _, i in sorted(items, reverse=True)]

    def render(self, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
        """Render one frame.

        Args:
            rotation: (3, 3) platform orientation in the base frame.
            translation: (3,) platform position in the base frame [m].

        Returns:
            (height, width) uint8 image.
        """
        return self.finish(self.draw(rotation, translation))

    def draw(self, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
        """The scene at one pose on the background, before the optics' blur and the
        pixel noise (:meth:`finish`): (height, width) uint8 image."""
        R = np.asarray(rotation, float)
        t = np.asarray(translation, float)
        if R.shape != (3, 3) or t.shape != (3,):
            raise RenderError("pose", f"expected rotation (3, 3) and translation (3,), got "
                                      f"{R.shape} and {t.shape}")
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            raise RenderError("pose", "contains NaN or inf")
        T = self.camera.camera_from_base
        legs = legs_in_frame(self.geometry, R, t, T)
        A, u, q = legs.base_points, legs.directions, legs.lengths
        img = self.background.copy()
        centre = T.apply(t)
        polys = self._leg_polygons(A, u, q)
        shapes: list[tuple[list[np.ndarray], int]] = []
        for i in self._order(A, u, q, centre, T.rotation @ R):
            if i < 0:
                shapes += self._platform_shape(centre, T.rotation @ R)
            else:
                shapes += self._leg_shapes(i, *polys)
        self._draw(img, shapes)
        return img

    def finish(self, img: np.ndarray) -> np.ndarray:
        """The optics' Gaussian blur and the pixel noise on a drawn image (in place);
        returns it."""
        if self.style.blur_px > 0:
            k = 2 * math.ceil(3.0 * self.style.blur_px) + 1
            cv2.GaussianBlur(img, (k, k), self.style.blur_px, dst=img)
        if self.style.noise_std > 0:
            n = img.size
            pos, neg = self._noise_bank(n)
            off = int(self.rng.integers(0, pos.size - n + 1))
            shape = img.shape
            cv2.add(img, pos[off:off + n].reshape(shape), dst=img)
            cv2.subtract(img, neg[off:off + n].reshape(shape), dst=img)
        return img


def render_legs(
    camera: Camera,
    geometry: HexapodGeometry,
    rotation: np.ndarray,
    translation: np.ndarray,
    style: RenderStyle | None = None,
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """One-shot rendering (builds a :class:`Renderer`; reuse one for many frames)."""
    return Renderer(camera, geometry, style, rng).render(rotation, translation)


__all__ = ["BACKGROUNDS", "RenderError", "RenderStyle", "Renderer", "make_background",
           "render_legs"]
