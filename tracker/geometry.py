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


def rectangle_corners(x, y, angle_deg, length, width) -> np.ndarray:
    """The 4 corners (4x2) in counter-clockwise order: positive signed area in (X, Y). Given arrays
    (P,) of each, the corners of every rectangle at once: (P, 4, 2)."""
    a = np.radians(angle_deg)
    ux, uy = np.cos(a) * length / 2, np.sin(a) * length / 2
    vx, vy = -np.sin(a) * width / 2, np.cos(a) * width / 2
    corners = np.stack([x - ux - vx, y - uy - vy, x + ux - vx, y + uy - vy,
                        x + ux + vx, y + uy + vy, x - ux + vx, y - uy + vy], axis=-1)
    return corners.reshape((*np.shape(corners)[:-1], 4, 2)).astype(np.float64)


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


def rect_from_sides(centre, side_a, len_a: float, len_b: float) -> Rect:
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
    end) are left out, since anti-aliasing and blur round the corners. ``rect``
    as it is where a side's points cannot say where it lies: fewer than 3, or a
    line through them turned further than a line within the band along the
    whole side can be (a few points on a rounded end).
    """
    a = math.radians(rect.angle_deg)
    ca, sa = math.cos(a), math.sin(a)
    # Work in the rectangle's own frame (u along the long side, v across): centred, well conditioned.
    dx, dy = points[:, 0] - rect.x_mm, points[:, 1] - rect.y_mm
    pu, pv = dx * ca + dy * sa, -dx * sa + dy * ca
    hl, hw = rect.length_mm / 2, rect.width_mm / 2
    inner_l, inner_w = hl * (1 - 2 * end_fraction), hw * (1 - 2 * end_fraction)
    # Sides in order: -v (bottom), +u (right), +v (top), -u (left); label each point with its side.
    side = np.full(len(points), 4)
    side[(np.abs(pv + hw) < band) & (np.abs(pu) < inner_l)] = 0
    side[(np.abs(pu - hl) < band) & (np.abs(pv) < inner_w)] = 1
    side[(np.abs(pv - hw) < band) & (np.abs(pu) < inner_l)] = 2
    side[(np.abs(pu + hl) < band) & (np.abs(pv) < inner_w)] = 3
    sums = [np.bincount(side, weights=w, minlength=5) for w in (None, pu, pv, pu * pu, pv * pv, pu * pv)]
    lines = []
    for i in range(4):
        n, su, sv, suu, svv, suv = (float(x[i]) for x in sums)
        if n < 3:
            return rect
        mu, mv = su / n, sv / n
        # Total least squares: the direction of the 2x2 scatter matrix's largest eigenvector.
        theta = 0.5 * math.atan2(2 * (suv - n * mu * mv), (suu - n * mu * mu) - (svv - n * mv * mv))
        du, dv = math.cos(theta), math.sin(theta)
        inner = inner_l if i % 2 == 0 else inner_w
        if abs(dv if i % 2 == 0 else du) > math.sin(math.atan2(band, inner)):
            return rect
        # Back to the plane's frame.
        x0, y0 = rect.x_mm + mu * ca - mv * sa, rect.y_mm + mu * sa + mv * ca
        lines.append((x0, y0, du * ca - dv * sa, du * sa + dv * ca))
    corners = [_intersect(lines[i - 1], lines[i]) for i in range(4)]
    if any(c is None for c in corners):
        return rect
    cx, cy = _polygon_centroid(corners)
    sides = [(corners[(i + 1) % 4][0] - corners[i][0], corners[(i + 1) % 4][1] - corners[i][1]) for i in range(4)]
    lengths = [math.hypot(*side) for side in sides]
    # Average the two opposite sides' directions (their sign is opposite) for the angle.
    direction = (sides[0][0] - sides[2][0], sides[0][1] - sides[2][1])
    return rect_from_sides((cx, cy), direction, (lengths[0] + lengths[2]) / 2, (lengths[1] + lengths[3]) / 2)


def _intersect(l1: tuple[float, ...], l2: tuple[float, ...]) -> tuple[float, float] | None:
    x1, y1, dx1, dy1 = l1
    x2, y2, dx2, dy2 = l2
    det = dx2 * dy1 - dx1 * dy2
    if abs(det) < 1e-9:
        return None
    s = (dx2 * (y2 - y1) - dy2 * (x2 - x1)) / det
    return x1 + s * dx1, y1 + s * dy1


def _polygon_centroid(poly: list[tuple[float, float]]) -> tuple[float, float]:
    area = cx = cy = 0.0
    for (x0, y0), (x1, y1) in zip(poly, poly[1:] + poly[:1], strict=True):
        cross = x0 * y1 - x1 * y0
        area += cross
        cx += (x0 + x1) * cross
        cy += (y0 + y1) * cross
    if abs(area) < 1e-12:
        n = len(poly)
        return sum(p[0] for p in poly) / n, sum(p[1] for p in poly) / n
    return cx / (3 * area), cy / (3 * area)
