"""Undistortion: exact for the few points we measure, whole frames only for viewing.

The pipeline undistorts edge *points* (a few hundred per part): exact to 1e-9 px
with enough iterations, and the border is never lost. Whole-frame remapping
(maps built once) is kept for people who want to look at a straightened image;
``alpha=1`` keeps every source pixel, where ``cv2.undistort`` with the same K
would crop the border under barrel distortion.
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from tracker.calibration import Calibration, apply_homography

# OpenCV's default (5 fixed iterations) leaves errors of ~0.1 px near the border
# of a strongly distorted lens; iterate to convergence instead.
POINT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)


class BeltMapper:
    """Distorted pixel coordinates -> world millimetres on a plane parallel to the belt."""

    def __init__(self, calibration: Calibration, height_mm: float = 0.0) -> None:
        self.calibration = calibration
        self._k = calibration.camera_matrix
        self._d = calibration.dist_coeffs
        self._h = calibration.homography_at_height(height_mm)
        # Undistorted pixel -> mm, combined with K^-1 once: normalized coords -> mm.
        self._h_norm = self._h @ self._k
        # Time spent undistorting, for the pipeline's per-stage figures.
        self.spent_ns = 0

    def to_mm(self, points_px: np.ndarray) -> np.ndarray:
        return self.norm_to_mm(self.to_norm(points_px))

    def norm_to_mm(self, norm: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates (Nx2) -> mm on the plane."""
        return apply_homography(self._h_norm, norm) if len(norm) else np.zeros((0, 2))

    def to_norm(self, points_px: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates (x/z, y/z) of distorted pixels (Nx2)."""
        t0 = time.perf_counter_ns()
        pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 1, 2)
        if pts.shape[0] == 0:
            return np.zeros((0, 2))
        norm = cv2.undistortPoints(pts, self._k, self._d, criteria=POINT_CRITERIA).reshape(-1, 2)
        self.spent_ns += time.perf_counter_ns() - t0
        return norm

    def view_outline_mm(self, step_px: int = 8) -> np.ndarray:
        """The image border mapped onto the plane: the polygon of belt the camera sees."""
        w, h = self.calibration.size
        top = [(u, 0) for u in range(0, w - 1, step_px)]
        right = [(w - 1, v) for v in range(0, h - 1, step_px)]
        bottom = [(u, h - 1) for u in range(w - 1, 0, -step_px)]
        left = [(0, v) for v in range(h - 1, 0, -step_px)]
        return self.to_mm(np.array(top + right + bottom + left, dtype=np.float64))

    def max_mm_per_px(self, step_px: int = 32) -> float:
        """Largest pixel footprint over the image (for conservative pixel-area pre-filters)."""
        w, h = self.calibration.size
        u, v = np.meshgrid(np.arange(0, w, step_px, dtype=np.float64), np.arange(0, h, step_px, dtype=np.float64))
        p = np.column_stack([u.ravel(), v.ravel()])
        a, b, c = self.to_mm(p), self.to_mm(p + [1, 0]), self.to_mm(p + [0, 1])
        # Square root of the area of one pixel on the belt.
        (ux, uy), (vx, vy) = (b - a).T, (c - a).T
        area = np.abs(ux * vy - uy * vx)
        return float(np.sqrt(area.max()))


class FrameUndistorter:
    """Whole-frame undistortion for viewing: maps built once, applied with ``cv2.remap``."""

    def __init__(self, calibration: Calibration, keep_all_pixels: bool = True) -> None:
        k, d = calibration.camera_matrix, calibration.dist_coeffs
        size = calibration.size
        alpha = 1.0 if keep_all_pixels else 0.0
        self.new_camera_matrix, _ = cv2.getOptimalNewCameraMatrix(k, d, size, alpha, size)
        self._map1, self._map2 = cv2.initUndistortRectifyMap(
            k, d, None, self.new_camera_matrix, size, cv2.CV_16SC2
        )

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        return cv2.remap(frame, self._map1, self._map2, cv2.INTER_LINEAR)
