"""The region of interest: the belt area, set once; outside it nothing is a part.

Given in the configuration as an image polygon (pixels) or a belt polygon (millimetres, mapped
into the image through the calibration); by default the whole image. A blob touching the
region's edge is clipped like one touching the image border: part of it may be outside.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.calibration import Calibration
from tracker.config import SegmentConfig
from tracker.errors import BadInput


class RegionOfInterest:
    def __init__(self, config: SegmentConfig, calibration: Calibration) -> None:
        w, h = calibration.size
        if config.roi_px and config.roi_mm:
            raise BadInput("segment: give roi_px (image polygon) or roi_mm (belt polygon), not both")
        if config.roi_mm:
            polygon = _belt_to_image(_polygon("segment.roi_mm", config.roi_mm), calibration)
        elif config.roi_px:
            polygon = _polygon("segment.roi_px", config.roi_px)
        else:
            polygon = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=np.float64)
        self.polygon_px = polygon
        mask = np.zeros((h, w), dtype=np.uint8)
        cv2.fillPoly(mask, [np.round(polygon).astype(np.int32)], 255)
        if cv2.countNonZero(mask) < 64:
            raise BadInput(f"segment: the region of interest covers {cv2.countNonZero(mask)} pixels of the "
                           f"{w}x{h} image; expected a belt area inside the image")
        self.mask = mask
        self.full = cv2.countNonZero(mask) == w * h
        self.area_px = cv2.countNonZero(mask)
        # Its edge, where a blob is cut by the region (the image border is checked separately).
        self.edge = cv2.subtract(mask, cv2.erode(mask, np.ones((3, 3), np.uint8), borderValue=255))
        x, y, bw, bh = cv2.boundingRect(mask)
        self.box = (x, y, bw, bh)

    def touches_edge(self, points_px: np.ndarray) -> bool:
        """Whether any of the (integer) contour points lie on the region's edge."""
        if self.full:
            return False
        pts = points_px.reshape(-1, 2)
        return bool(self.edge[pts[:, 1], pts[:, 0]].any())


def _polygon(name: str, points) -> np.ndarray:
    arr = np.asarray(points, dtype=np.float64) if all(
        isinstance(p, list | tuple) and len(p) == 2 for p in points) else None
    if arr is None or len(arr) < 3 or not np.isfinite(arr).all():
        raise BadInput(f"{name}: expected a polygon of at least 3 [x, y] points, got {points!r}")
    return arr


def _belt_to_image(polygon_mm: np.ndarray, calibration: Calibration) -> np.ndarray:
    """Belt millimetres -> distorted image pixels, edges sampled so a curved image of a straight
    belt edge (lens distortion) is followed."""
    dense = []
    for a, b in zip(polygon_mm, np.roll(polygon_mm, -1, axis=0), strict=True):
        for s in np.linspace(0.0, 1.0, 16, endpoint=False):
            dense.append(a + s * (b - a))
    world = np.column_stack([np.asarray(dense), np.zeros(len(dense))])
    pts, _ = cv2.projectPoints(world, calibration.belt_rvec, calibration.belt_tvec,
                               calibration.camera_matrix, calibration.dist_coeffs)
    return pts.reshape(-1, 2)
