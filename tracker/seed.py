"""The plain "seed" method, kept as the baseline the README and the benchmark compare with.

Whole-frame ``cv2.undistort`` (same K: the border is cropped), consecutive-frame
difference (the union of the part at t and t-1), the largest contour's
``cv2.minAreaRect`` in pixels mapped through the homography, no filter.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.calibration import Calibration, apply_homography
from tracker.geometry import rect_from_sides
from tracker.poses import FrameResult, TrackedObject

THRESHOLD = 30
MIN_AREA_PX = 200


class SeedMethod:
    def __init__(self, calibration: Calibration) -> None:
        self.k, self.d = calibration.camera_matrix, calibration.dist_coeffs
        self.h = calibration.homography_at_height(0.0)
        self._prev: np.ndarray | None = None

    def process(self, index: int, frame: np.ndarray, t_ns: int) -> FrameResult:
        image = cv2.undistort(frame, self.k, self.d)
        prev, self._prev = self._prev, image
        if prev is None:
            return FrameResult(index, t_ns, ())
        _, mask = cv2.threshold(cv2.absdiff(image, prev), THRESHOLD, 255, cv2.THRESH_BINARY)
        mask = cv2.dilate(mask, None, iterations=2)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if not contours:
            return FrameResult(index, t_ns, ())
        largest = max(contours, key=cv2.contourArea)
        if cv2.contourArea(largest) < MIN_AREA_PX:
            return FrameResult(index, t_ns, ())
        box_mm = apply_homography(self.h, cv2.boxPoints(cv2.minAreaRect(largest)))
        sides = np.roll(box_mm, -1, axis=0) - box_mm
        lengths = np.hypot(sides[:, 0], sides[:, 1])
        rect = rect_from_sides(box_mm.mean(axis=0), sides[0], lengths[0], lengths[1])
        obj = TrackedObject(1, rect.x_mm, rect.y_mm, rect.angle_deg, rect.length_mm, rect.width_mm,
                            rect.corners(), 0.0, 0.0, True)
        return FrameResult(index, t_ns, (obj,))
