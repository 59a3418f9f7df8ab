"""Region of interest: the belt area, set once; outside it nothing is a part (rails, floor, shoes)."""

from __future__ import annotations

import cv2
import numpy as np

from tracker.calibration import Calibration, apply_homography
from tracker.config import SegmentConfig


def roi_polygon_px(config: SegmentConfig, calibration: Calibration) -> np.ndarray | None:
    """The region of interest as an image polygon (Nx2 float64 pixels), or None for the whole image.

    A belt polygon (mm) is mapped into the image through the inverse belt homography and the lens
    distortion, densified first so that its straight belt edges stay true under distortion.
    """
    if config.roi_px:
        return np.array(config.roi_px, dtype=np.float64)
    if not config.roi_mm:
        return None
    corners = np.array(config.roi_mm, dtype=np.float64)
    dense = []
    for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
        for t in np.linspace(0.0, 1.0, 32, endpoint=False):
            dense.append(a + t * (b - a))
    undistorted = apply_homography(np.linalg.inv(calibration.belt_homography), np.array(dense))
    k, d = calibration.camera_matrix, calibration.dist_coeffs
    rays = cv2.undistortPoints(undistorted.reshape(-1, 1, 2), k, np.zeros(5), P=None).reshape(-1, 2)
    pts3 = np.column_stack([rays, np.ones(len(rays))])
    pixels, _ = cv2.projectPoints(pts3, np.zeros(3), np.zeros(3), k, d)
    return pixels.reshape(-1, 2)


def roi_mask(polygon_px: np.ndarray | None, size: tuple[int, int]) -> np.ndarray:
    """255 inside the polygon (the whole frame when None), 0 outside; uint8 of ``size`` = (w, h)."""
    w, h = size
    if polygon_px is None:
        return np.full((h, w), 255, np.uint8)
    mask = np.zeros((h, w), np.uint8)
    cv2.fillPoly(mask, [np.round(polygon_px).astype(np.int32)], 255)
    return mask
