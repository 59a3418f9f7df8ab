"""The shadow a part casts on the belt under a lamp (the renderer's, tracker/synthetic.py).

A lamp far away (a direction: azimuth on the belt, elevation above it) casts a box's shadow as the
convex hull of its eight corners, each pushed along the light onto the belt: a corner at height z
lands z / tan(elevation) away from the lamp. The penumbra of a lamp that is not a point is modelled as
a linear ramp ``softness_mm`` wide just inside the hull's edge: none outside it, so that where the hull's
edge is the part's own base (a flat part's whole outline) no shadow shows past it.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from tracker.geometry import rectangle_corners


def shadow_polygon(length_mm: float, width_mm: float, bottom_mm: float, top_mm: float,
                   pose: tuple[float, float, float], azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """The shadow on the belt (Z = 0) of a box ``length_mm`` x ``width_mm`` at ``pose`` (x, y, angle),
    from ``bottom_mm`` to ``top_mm`` above the belt: its convex outline (K, 2), mm, counter-clockwise."""
    corners = rectangle_corners(*pose, length_mm, width_mm)
    away = -np.array([math.cos(math.radians(azimuth_deg)), math.sin(math.radians(azimuth_deg))])
    reach = away / math.tan(math.radians(elevation_deg))
    cast = np.vstack([corners + bottom_mm * reach, corners + top_mm * reach]).astype(np.float32)
    hull = cv2.convexHull(cast, clockwise=False)[:, 0, :].astype(np.float64)
    if _signed_area(hull) < 0:  # OpenCV's orientation follows its y-down image convention
        hull = hull[::-1]
    return hull


def polygon_cover(xy_mm: np.ndarray, polygon: np.ndarray, softness_mm: float) -> np.ndarray:
    """How much of each point (``xy_mm``: (..., 2)) lies in the shadow of convex ``polygon`` (K, 2;
    counter-clockwise), 0 to 1: 1 deeper than ``softness_mm`` inside its edge, 0 on and outside it."""
    edges = np.roll(polygon, -1, axis=0) - polygon
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)  # outward for a counter-clockwise outline
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets = np.einsum("kd,kd->k", normals, polygon)
    # Distance outside the polygon (negative inside); the largest over its edges is exact inside and
    # near an edge, which is all a penumbra a few millimetres wide needs.
    outside = (xy_mm @ normals.T - offsets).max(axis=-1)
    if softness_mm <= 0:
        return (outside <= 0).astype(np.float32)
    return np.clip(-outside / softness_mm, 0.0, 1.0).astype(np.float32)


def _signed_area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
