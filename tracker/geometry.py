"""Rectangles on the belt plane: the angle convention and the fit to edge points.

Angles are computed here from the fitted rectangle, never taken from
``cv2.minAreaRect``, whose angle range changed between OpenCV releases.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np


def wrap_angle_deg(angle: float) -> float:
    """An axis direction (180 deg symmetric) in (-90, 90]."""
    a = math.fmod(angle, 180.0)
    if a <= -90.0:
        a += 180.0
    elif a > 90.0:
        a -= 180.0
    return a


def rectangle_corners(x: float, y: float, angle_deg: float, length: float, width: float) -> np.ndarray:
    """The 4 corners (4x2) in counter-clockwise order: positive signed area in (X, Y)."""
    a = math.radians(angle_deg)
    ux, uy = math.cos(a) * length / 2, math.sin(a) * length / 2
    vx, vy = -math.sin(a) * width / 2, math.cos(a) * width / 2
    return np.array(
        [[x - ux - vx, y - uy - vy], [x + ux - vx, y + uy - vy], [x + ux + vx, y + uy + vy], [x - ux + vx, y - uy + vy]]
    )


def signed_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return float(0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


@dataclass(frozen=True)
class Rect:
    """A rectangle on the belt: centroid, long-side angle in (-90, 90], sides (length >= width)."""

    x_mm: float
    y_mm: float
    angle_deg: float
    length_mm: float
    width_mm: float

    def corners(self) -> np.ndarray:
        return rectangle_corners(self.x_mm, self.y_mm, self.angle_deg, self.length_mm, self.width_mm)

    @property
    def area_mm2(self) -> float:
        return self.length_mm * self.width_mm


def rect_from_sides(centre: np.ndarray, side_a: np.ndarray, len_a: float, len_b: float) -> Rect:
    """Rectangle from its centre, the direction of one side and both side lengths."""
    angle = math.degrees(math.atan2(side_a[1], side_a[0]))
    if len_b > len_a:
        len_a, len_b, angle = len_b, len_a, angle + 90.0
    return Rect(float(centre[0]), float(centre[1]), wrap_angle_deg(angle), float(len_a), float(len_b))


def min_area_rect(points: np.ndarray) -> Rect:
    """Minimum-area rectangle of Nx2 points, with our own angle convention."""
    box = cv2.boxPoints(cv2.minAreaRect(np.asarray(points, dtype=np.float32))).astype(np.float64)
    side_a, side_b = box[1] - box[0], box[2] - box[1]
    return rect_from_sides(box.mean(axis=0), side_a, float(np.hypot(*side_a)), float(np.hypot(*side_b)))


def refine_rect(points: np.ndarray, rect: Rect, band: float, end_fraction: float = 0.15) -> Rect:
    """Refit each side of ``rect`` to the points near it; intersect the four lines.

    ``band`` is how far (same units as points) a point may lie from a side to
    belong to it; points near the corners (``end_fraction`` of the side at each
    end) are left out, since anti-aliasing and blur round the corners.
    """
    a = math.radians(rect.angle_deg)
    u = np.array([math.cos(a), math.sin(a)])
    v = np.array([-u[1], u[0]])
    rel = points - np.array([rect.x_mm, rect.y_mm])
    pu, pv = rel @ u, rel @ v
    hl, hw = rect.length_mm / 2, rect.width_mm / 2
    lines = []
    # Sides in order: -v (bottom), +u (right), +v (top), -u (left).
    sides = ((pv, pu, -hw, hl), (pu, pv, hl, hw), (pv, pu, hw, hl), (pu, pv, -hl, hw))
    for normal_coord, along, half_off, half_along in sides:
        sel = (np.abs(normal_coord - half_off) < band) & (np.abs(along) < half_along * (1 - 2 * end_fraction))
        if sel.sum() < 3:
            return rect
        lines.append(_fit_line(points[sel]))
    corners = np.array([_intersect(lines[i - 1], lines[i]) for i in range(4)])
    if not np.all(np.isfinite(corners)):
        return rect
    centre = _polygon_centroid(corners)
    sides = np.roll(corners, -1, axis=0) - corners
    lengths = np.hypot(sides[:, 0], sides[:, 1])
    # Average the two opposite sides' directions (their sign is opposite) for the angle.
    direction = sides[0] - sides[2]
    return rect_from_sides(centre, direction, (lengths[0] + lengths[2]) / 2, (lengths[1] + lengths[3]) / 2)


def _fit_line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Total least squares line: (point on it, unit direction), from the 2x2 covariance."""
    mean = points.mean(axis=0)
    d = points - mean
    sxx, syy, sxy = float(d[:, 0] @ d[:, 0]), float(d[:, 1] @ d[:, 1]), float(d[:, 0] @ d[:, 1])
    theta = 0.5 * math.atan2(2 * sxy, sxx - syy)
    return mean, np.array([math.cos(theta), math.sin(theta)])


def _intersect(l1: tuple[np.ndarray, np.ndarray], l2: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    (p1, d1), (p2, d2) = l1, l2
    det = d2[0] * d1[1] - d1[0] * d2[1]
    if abs(det) < 1e-9:
        return np.array([np.nan, np.nan])
    rx, ry = p2[0] - p1[0], p2[1] - p1[1]
    s = (d2[0] * ry - d2[1] * rx) / det
    return p1 + s * d1


def _polygon_centroid(poly: np.ndarray) -> np.ndarray:
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2
    if abs(area) < 1e-12:
        return poly.mean(axis=0)
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6 * area)
