"""Fitting a box's footprint to silhouette edge points (the outline model in tracker/box.py).

Gauss-Newton on the footprint (x, y, angle, length, width) with the height known: each edge
point's residual is its distance to the projected outline; the Jacobian is taken numerically
(five outline projections per step, each of 8 points), a few steps from the rectangle fitted on
the top face's plane. A fit that does not explain the points (a part that is not a prism: a
cylinder lying down, a bag) is rejected, and the caller keeps the plain rectangle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tracker.box import BoxCamera, distances_to_outline
from tracker.geometry import Rect, wrap_angle_deg

# Finite-difference steps: mm for positions, sides and height, degrees for the angle.
_STEP = np.array([0.01, 0.01, 0.005, 0.01, 0.01, 0.01])
_ITERATIONS = 20
# Points farther than this many median residuals from the outline are outliers (noise, corners).
_OUTLIER_FACTOR = 4.0


@dataclass(frozen=True)
class BoxFit:
    rect: Rect
    height_mm: float
    # 1-sigma uncertainty of the height from this view (inf when the height was given).
    height_sigma_mm: float = math.inf
    # Sum of squared residuals (normalised units): lower is the better of two fits.
    cost: float = 0.0


def fit_box(camera: BoxCamera, points_norm: np.ndarray, start: Rect, height_mm: float,
            max_rms_norm: float, free_height: bool = False) -> BoxFit | None:
    """The footprint (and with ``free_height`` the height, from ``height_mm`` on) whose box outline
    best fits ``points_norm`` (Nx2, normalised), or None when the fit's RMS residual exceeds
    ``max_rms_norm`` (the points are not a box's outline)."""
    n = 6 if free_height else 5
    params = np.array([start.x_mm, start.y_mm, start.angle_deg, start.length_mm, start.width_mm, height_mm],
                      dtype=np.float64)
    pts = np.asarray(points_norm, dtype=np.float64)

    def residuals(p: np.ndarray, which: np.ndarray | slice = slice(None)) -> np.ndarray:
        return distances_to_outline(pts[which], camera.outline(p[:5], p[5]))

    damping = 1e-3
    r = residuals(params)
    cost = float(np.sum(r**2))
    jac = np.zeros((0, n))
    for iteration in range(_ITERATIONS):
        # Outliers are judged only once the outline is near the points.
        keep = np.ones(len(r), bool)
        if iteration >= 3:
            keep = np.abs(r) <= _OUTLIER_FACTOR * max(np.median(np.abs(r)), 1e-12)
        jac = np.empty((int(keep.sum()), n))
        for i in range(n):
            step = np.zeros(6)
            step[i] = _STEP[i]
            jac[:, i] = (residuals(params + step, keep) - r[keep]) / _STEP[i]
        # Levenberg-Marquardt: the nearest edge of a point may change between steps.
        normal = jac.T @ jac
        delta = np.zeros(6)
        delta[:n] = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-12), -jac.T @ r[keep])
        trial = params + delta
        trial[5] = max(trial[5], 0.0)  # a part's top is above the belt
        r_trial = residuals(trial)
        trial_cost = float(np.sum(r_trial**2))
        if trial_cost < cost:
            params, r, cost, damping = trial, r_trial, trial_cost, damping * 0.3
            if np.all(np.abs(delta) < _STEP * 0.01):
                break
        else:
            damping *= 10.0
    rms = float(np.sqrt(np.mean(r**2)))
    if not np.isfinite(params).all() or rms > max_rms_norm or min(params[3], params[4]) <= 0:
        return None
    sigma_h = math.inf
    if free_height and len(jac) > n:
        # The height's variance from the normal matrix, scaled by the residuals' own spread.
        with np.errstate(all="ignore"):
            cov = np.linalg.pinv(jac.T @ jac) * rms**2
        sigma_h = float(np.sqrt(max(cov[5, 5], 0.0))) if np.isfinite(cov[5, 5]) else math.inf
    x, y, angle, length, width, h = params
    if width > length:
        length, width, angle = width, length, angle + 90.0
    rect = Rect(float(x), float(y), wrap_angle_deg(float(angle)), float(length), float(width))
    return BoxFit(rect, float(h), sigma_h, cost)
