"""Edge normals measured from noisy pixels (the "pixel" noise model), batched.

Points are sampled along the visible part of each edge (limb) of each leg,
projected by the TRUE camera, perturbed by Gaussian pixel noise (and optional
outliers), lifted with the ESTIMATED camera and fitted by the minimal SVD fit of
:func:`vision.estimate.fit_normal` (docs/math.md section 5). This is what a real
detector followed by the estimator gives, without rendering images.
"""

from __future__ import annotations

import numpy as np

from vision.cameras import Camera
from vision.estimate import fit_normal
from vision.legs import LegObservation, limb_points
from vision.noise import add_outliers


def normals_from_noisy_pixels(
    true_camera: Camera,
    estimated_camera: Camera,
    obs: LegObservation,
    sigma_px: float,
    n_points: int,
    rng: np.random.Generator,
    outlier_fraction: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Fit every visible edge normal from ``n_points`` noisy pixels.

    Args:
        true_camera: Makes the pixels.
        estimated_camera: Lifts them (intrinsics error reaches the normals here).
        obs: The observation of the legs (:func:`vision.legs.observe_legs` with the
            true camera), batched (..., 6, 2).
        sigma_px: Standard deviation of the pixel noise [px].
        n_points: Points per edge (>= 2).
        rng: Generator.
        outlier_fraction: Fraction of points replaced by gross errors.

    Returns:
        ``normals`` (..., 6, 2, 3) (NaN where not visible, oriented like the true
        normals) and the visibility mask (..., 6, 2) (an edge with fewer than two
        valid points is dropped).
    """
    if n_points < 2:
        raise ValueError(f"n_points must be >= 2, got {n_points}")
    vis = np.asarray(obs.edge_visible, dtype=bool)
    interval = np.nan_to_num(obs.visible_interval, nan=0.5)  # (..., 6, 2, 2)
    grid = np.linspace(0.0, 1.0, n_points)
    s = interval[..., :1] + (interval[..., 1:] - interval[..., :1]) * grid  # (..., 6, 2, N)
    normals = np.nan_to_num(obs.normals)
    P = limb_points(obs.base_points, obs.directions, obs.radius, obs.lengths, normals, s)
    px, ok = true_camera.project(P)
    px = px + rng.normal(scale=sigma_px, size=px.shape)
    if outlier_fraction > 0:
        px, _ = add_outliers(px, outlier_fraction, rng, width=true_camera.width,
                             height=true_camera.height)
    weights = (ok & vis[..., None]).astype(float)
    fit = fit_normal(estimated_camera, np.where(ok[..., None], px, 0.0), weights=weights,
                     reference=normals)
    valid = vis & (fit.n_points >= 2) & np.all(np.isfinite(fit.normal), axis=-1)
    return np.where(valid[..., None], fit.normal, np.nan), valid
