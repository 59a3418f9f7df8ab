"""The rectangle fit's side refinement (tracker/geometry.py) on edge points with exact geometry."""

from __future__ import annotations

import numpy as np

from tracker.geometry import Rect, refine_rect


def _sides(length: float, width: float, step: float = 0.5) -> list[np.ndarray]:
    """Points along each side of a length x width rectangle centred at the origin, along x."""
    along, across = np.arange(-length / 2, length / 2, step), np.arange(-width / 2, width / 2, step)
    return [np.c_[along, np.full_like(along, -width / 2)], np.c_[along, np.full_like(along, width / 2)],
            np.c_[np.full_like(across, -length / 2), across], np.c_[np.full_like(across, length / 2), across]]


def test_straight_sides_are_refined_to_where_they_lie():
    points = np.vstack(_sides(120.0, 50.0))
    rect = refine_rect(points, Rect(0.6, -0.4, 0.3, 121.0, 49.2), band=2.0)
    assert abs(rect.x_mm) < 1e-6 and abs(rect.y_mm) < 1e-6 and abs(rect.angle_deg) < 1e-6
    assert abs(rect.length_mm - 120.0) < 1e-6 and abs(rect.width_mm - 50.0) < 1e-6


def test_a_side_whose_few_points_cannot_say_where_it_lies_leaves_the_rectangle_as_it_is():
    """A rounded end (a phone's, a bottle's) leaves a short side a small cluster of edge points spread
    along the part rather than across it: a line through them runs across the side, and the corners it
    would make lie far outside the part (a 55 x 127 mm blob of the real mixed-items video was posed
    158 x 140 mm). The refinement keeps the rectangle it was given instead."""
    bottom, top, left, _ = _sides(120.0, 50.0)
    rounded = np.array([[59.0, 0.0], [59.6, 0.15], [60.2, -0.1], [60.8, 0.05]])
    given = Rect(0.0, 0.0, 0.0, 120.0, 50.0)
    rect = refine_rect(np.vstack([bottom, top, left, rounded]), given, band=2.0)
    assert abs(rect.length_mm - 120.0) < 1.0 and abs(rect.width_mm - 50.0) < 1.0
    assert abs(rect.x_mm) < 0.5 and abs(rect.y_mm) < 0.5
