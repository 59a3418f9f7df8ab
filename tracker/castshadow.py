"""The shadow a part casts on the belt under a lamp (the renderer's, tracker/synthetic.py).

A lamp far away (a direction: azimuth on the belt, elevation above it) casts a box's shadow as the
convex hull of its eight corners, each pushed along the light onto the belt: a corner at height z
lands z / tan(elevation) away from the lamp. A lamp is not a point: seen from the belt it spans
``size_deg``, and its shadow is the mean of the hard shadows of points spread over that disk. The
penumbra then widens with the height of what casts it, as a real one does: none where the part
stands on the belt, a few millimetres at the far end of a tall part's shadow.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from tracker.geometry import rectangle_corners

# Points across the lamp's disk (in units of its radius): its centre and a ring of six, each standing
# for about as much of its area. More cost a render more than they change a pixel's shade.
_DISK = np.array([(0.0, 0.0)] + [(0.7 * math.cos(a), 0.7 * math.sin(a)) for a in np.arange(6) * math.pi / 3])
# Each point's hard shadow is anti-aliased over this much of its inside edge (mm, well under a pixel).
_EDGE_MM = 0.2


def lamp_reaches(azimuth_deg: float, elevation_deg: float, size_deg: float) -> np.ndarray:
    """How far (mm on the belt, per mm of height) the light of each point across a lamp at
    (``azimuth_deg``, ``elevation_deg``), ``size_deg`` across as seen from the belt, pushes a point
    away from it: (K, 2)."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    towards = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    # Two directions across the lamp's disk, at right angles to the light and to each other.
    across = np.array([-math.sin(az), math.cos(az), 0.0])
    up = np.cross(towards, across)
    spread = math.tan(math.radians(size_deg) / 2)
    rays = towards + spread * (_DISK[:, :1] * across + _DISK[:, 1:] * up)
    return -rays[:, :2] / rays[:, 2:]


def shadow_polygon(length_mm: float, width_mm: float, bottom_mm: float, top_mm: float,
                   pose: tuple[float, float, float], reach: np.ndarray) -> np.ndarray:
    """The hard shadow on the belt (Z = 0) of a box ``length_mm`` x ``width_mm`` at ``pose`` (x, y,
    angle), from ``bottom_mm`` to ``top_mm`` above the belt, in light that pushes a point ``reach``
    (mm per mm of height, see lamp_reaches): its convex outline (K, 2), mm, counter-clockwise."""
    corners = rectangle_corners(*pose, length_mm, width_mm)
    cast = np.vstack([corners + bottom_mm * reach, corners + top_mm * reach]).astype(np.float32)
    hull = cv2.convexHull(cast, clockwise=False)[:, 0, :].astype(np.float64)
    if _signed_area(hull) < 0:  # OpenCV's orientation follows its y-down image convention
        hull = hull[::-1]
    return hull


def polygon_cover(xy_mm: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Whether each point (``xy_mm``: (..., 2)) lies in the shadow of convex ``polygon`` (K, 2;
    counter-clockwise), 0 to 1: 1 deeper than _EDGE_MM inside its edge, 0 on and outside it (where its
    edge is the part's own base, no shadow shows past it)."""
    edges = np.roll(polygon, -1, axis=0) - polygon
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)  # outward for a counter-clockwise outline
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets = np.einsum("kd,kd->k", normals, polygon)
    # Distance outside the polygon (negative inside); the largest over its edges is exact inside and
    # near an edge, which is all the anti-aliasing needs.
    outside = (xy_mm @ normals.T - offsets).max(axis=-1)
    return np.clip(-outside / _EDGE_MM, 0.0, 1.0).astype(np.float32)


def _signed_area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
