"""Fitting a box's footprint to the coverage sums across its silhouette's edges (tracker/box.py).

Levenberg-Marquardt on the footprint (x, y, angle, length, width), optionally the height, and
the two side shades (a side face's contrast as a fraction of the top's: one for the faces at the
part's ends, one for those along it). Each window's residual is its measured coverage sum minus
the box's prediction (each face's pixels in it times its shade, over the shade of the pixel the
sum was read against), in pixels. The geometric columns of the Jacobian are taken numerically, the shades' exactly (the
sums are linear in them). A fit that does not explain the sums (a part that is no prism: a bag)
is rejected, and the caller keeps the plain rectangle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tracker.box import BoxCamera, EdgeWindows, distances_to_outline, lengths_in_faces
from tracker.geometry import Rect, wrap_angle_deg

# Parameters: x, y (mm), angle (deg), length, width, height (mm), the two side shades.
_H, _SHADES = 5, (6, 7)
# Finite-difference steps: mm, the angle in degrees, the shades as fractions.
_STEP = np.array([0.01, 0.01, 0.005, 0.01, 0.01, 0.01, 0.001, 0.001])
_ITERATIONS = 6
# Converged once no parameter moves by more than this fraction of its difference step.
_CONVERGED = 0.05
# Where the fit starts the side shades, and how weakly it holds them there (a pseudo-residual in
# px per unit of shade): a side face too narrow to show its shade leaves the shade undecided.
_SHADE_START, _SHADE_PRIOR = 0.5, 0.02
# The least level (a fraction of the top's) a window's level pixel is taken to have.
_MIN_LEVEL = 0.05
# Windows whose residual exceeds this many median residuals are outliers (a corner, a speck).
_OUTLIER_FACTOR = 4.0


@dataclass(frozen=True)
class BoxFit:
    rect: Rect
    height_mm: float
    # 1-sigma uncertainty of the height from this view (inf when the height was given).
    height_sigma_mm: float = math.inf
    # Sum of squared residuals (px^2): lower is the better of two fits.
    cost: float = 0.0
    rms_px: float = 0.0


def predicted_sums(camera: BoxCamera, windows: EdgeWindows, params: np.ndarray) -> np.ndarray:
    """The coverage sum the box ``params`` predicts for each window (px)."""
    polygons, kinds = camera.faces(params[:5], params[_H])
    shade = np.array([1.0, params[_SHADES[0]], params[_SHADES[1]]])[kinds]
    total, level = lengths_in_faces(windows, polygons, ((0.0, windows.span_px), windows.level_px))
    # The level pixel outside the part (a window across a corner) is an outlier, not a division by 0.
    return (total @ shade) / np.maximum(level @ shade, _MIN_LEVEL)


def fit_box(camera: BoxCamera, points_norm: np.ndarray, windows: EdgeWindows, start: Rect, height_mm: float,
            max_rms_px: float, px_per_norm: float, free_height: bool = False) -> BoxFit | None:
    """The footprint (and with ``free_height`` the height, from ``height_mm`` on) whose box best
    explains ``windows``, or None when the fit's RMS residual exceeds ``max_rms_px``. ``points_norm``:
    the edge points (Nx2, normalised) that bring the box near first; ``px_per_norm``: the focal length."""
    free = [0, 1, 2, 3, 4, *([_H] if free_height else [])]
    params = np.array([start.x_mm, start.y_mm, start.angle_deg, start.length_mm, start.width_mm, height_mm,
                       _SHADE_START, _SHADE_START], dtype=np.float64)

    def outline(p: np.ndarray, which: np.ndarray | slice = slice(None)) -> np.ndarray:
        return px_per_norm * distances_to_outline(points_norm[which], camera.outline(p[:5], p[_H]))

    def sums(p: np.ndarray, which: np.ndarray | slice = slice(None)) -> np.ndarray:
        w = windows if isinstance(which, slice) else windows.subset(which)
        return w.covered_px - predicted_sums(camera, w, p)

    params, r, jac = _robust(outline, params, free)
    params, r, jac = _robust(sums, params, [*free, *_SHADES])
    rms = float(np.sqrt(np.mean(r**2))) if len(r) else math.inf
    if not np.isfinite(params).all() or rms > max_rms_px or min(params[3], params[4]) <= 0:
        return None
    sigma_h = math.inf
    if free_height and len(jac) > len(free):
        # The height's variance from the normal matrix, scaled by the residuals' own spread.
        with np.errstate(all="ignore"):
            cov = np.linalg.pinv(jac.T @ jac) * rms**2
        k = free.index(_H)
        sigma_h = float(np.sqrt(max(cov[k, k], 0.0))) if np.isfinite(cov[k, k]) else math.inf
    x, y, angle, length, width, h = params[: _H + 1]
    if width > length:
        length, width, angle = width, length, angle + 90.0
    rect = Rect(float(x), float(y), wrap_angle_deg(float(angle)), float(length), float(width))
    return BoxFit(rect, float(h), sigma_h, float(np.sum(r**2)), rms)


def _robust(residuals, params: np.ndarray, free: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least squares, then again without the outliers (a corner's windows, a speck). They are
    judged only once the box is near: judged earlier, a side still far off would be dropped whole
    and left free to drift. ``residuals(params, which)``: the residuals (px) of the rows ``which``."""
    params, r, jac = _least_squares(residuals, params, free)
    keep = np.abs(r) <= _OUTLIER_FACTOR * max(float(np.median(np.abs(r))), 1e-3)
    if keep.all():
        return params, r, jac
    return _least_squares(lambda p: residuals(p, keep), params, free)


def _least_squares(residuals, params: np.ndarray, free: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Levenberg-Marquardt from ``params`` over the ``free`` ones: (params, residuals, Jacobian)."""

    def cost_of(r: np.ndarray, p: np.ndarray) -> float:
        return float(np.sum(r**2) + _SHADE_PRIOR**2 * np.sum((p[list(_SHADES)] - _SHADE_START) ** 2))

    # The shades' weak prior enters as two more rows.
    prior = np.zeros((2, len(free)))
    for row, i in enumerate(_SHADES):
        if i in free:
            prior[row, free.index(i)] = _SHADE_PRIOR
    damping = 1e-3
    r = residuals(params)
    cost = cost_of(r, params)
    jac = np.zeros((len(r), len(free)))
    for _ in range(_ITERATIONS):
        for c, i in enumerate(free):
            step = np.zeros_like(params)
            step[i] = _STEP[i]
            jac[:, c] = (residuals(params + step) - r) / _STEP[i]
        a = np.vstack([jac, prior])
        b = np.concatenate([r, _SHADE_PRIOR * (params[list(_SHADES)] - _SHADE_START)])
        normal = a.T @ a
        delta = np.zeros_like(params)
        delta[free] = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-12), -a.T @ b)
        trial = params + delta
        trial[_H] = max(trial[_H], 0.0)  # a part's top is above the belt
        r_trial = residuals(trial)
        trial_cost = cost_of(r_trial, trial)
        if trial_cost < cost:
            params, r, cost, damping = trial, r_trial, trial_cost, damping * 0.3
            # The shades are free to wander in the flat directions: only the box decides.
            if np.all(np.abs(delta[: _H + 1]) < _STEP[: _H + 1] * _CONVERGED):
                break
        else:
            damping *= 10.0
    return params, r, jac


