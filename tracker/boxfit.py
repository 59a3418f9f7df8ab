"""Fitting a box's footprint to silhouette edge points (the outline model in tracker/box.py).

Gauss-Newton on the footprint (x, y, angle, length, width) with the height known: each edge
point's residual is its distance to the projected outline; the Jacobian is taken numerically
(five outline projections per step, each of 8 points), a few steps from the rectangle fitted on
the top face's plane. A fit that does not explain the points (a part that is not a prism: a
cylinder lying down, a bag) is rejected, and the caller keeps the plain rectangle.
"""

from __future__ import annotations

import numpy as np

from tracker.box import BoxCamera, distances_to_outline
from tracker.geometry import Rect, wrap_angle_deg

# Finite-difference steps: mm for positions and sides, degrees for the angle.
_STEP = np.array([0.01, 0.01, 0.005, 0.01, 0.01])
_ITERATIONS = 20
# Points farther than this many median residuals from the outline are outliers (noise, corners).
_OUTLIER_FACTOR = 4.0


def fit_box(camera: BoxCamera, points_norm: np.ndarray, start: Rect, height_mm: float,
            max_rms_norm: float) -> Rect | None:
    """The footprint whose box outline best fits ``points_norm`` (Nx2, normalised), or None
    when the fit's RMS residual exceeds ``max_rms_norm`` (the points are not a box's outline)."""
    params = np.array([start.x_mm, start.y_mm, start.angle_deg, start.length_mm, start.width_mm], dtype=np.float64)
    pts = np.asarray(points_norm, dtype=np.float64)
    damping = 1e-3
    r = distances_to_outline(pts, camera.outline(params, height_mm))
    cost = float(np.sum(r**2))
    for iteration in range(_ITERATIONS):
        # Outliers are judged only once the outline is near the points.
        keep = np.ones(len(r), bool)
        if iteration >= 3:
            keep = np.abs(r) <= _OUTLIER_FACTOR * max(np.median(np.abs(r)), 1e-12)
        jac = np.empty((int(keep.sum()), 5))
        for i in range(5):
            step = np.zeros(5)
            step[i] = _STEP[i]
            jac[:, i] = (distances_to_outline(pts[keep], camera.outline(params + step, height_mm)) - r[keep]) / _STEP[i]
        # Levenberg-Marquardt: the nearest edge of a point may change between steps.
        normal = jac.T @ jac
        delta = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-12), -jac.T @ r[keep])
        trial = params + delta
        r_trial = distances_to_outline(pts, camera.outline(trial, height_mm))
        trial_cost = float(np.sum(r_trial**2))
        if trial_cost < cost:
            params, r, cost, damping = trial, r_trial, trial_cost, damping * 0.3
            if np.all(np.abs(delta) < _STEP * 0.01):
                break
        else:
            damping *= 10.0
    r = distances_to_outline(pts, camera.outline(params, height_mm))
    if not np.isfinite(params).all() or np.sqrt(np.mean(r**2)) > max_rms_norm or min(params[3], params[4]) <= 0:
        return None
    x, y, angle, length, width = params
    if width > length:
        length, width, angle = width, length, angle + 90.0
    return Rect(float(x), float(y), wrap_angle_deg(float(angle)), float(length), float(width))
