"""Defaults and thresholds of the calibration commands, in one typed place."""

from __future__ import annotations

from dataclasses import dataclass

import cv2


@dataclass(frozen=True)
class CalibrateSettings:
    # Fewest usable views ``calibrate intrinsics`` accepts (Zhang needs >= 3; a reliable K and D needs many more).
    min_views: int = 8
    # A view is an outlier when its RMS exceeds both factor x the median and median + excess.
    outlier_factor: float = 3.0
    outlier_min_excess_px: float = 0.3
    # A calibration whose RMS exceeds this is refused (nothing written).
    max_rms_px: float = 1.0
    # Coverage grid (cells per side) and the border band (fraction of width/height) that must be reached.
    coverage_cells: int = 4
    border_band: float = 0.10
    # Views should be tilted against the image plane; without tilt the focal length is poorly determined.
    min_max_tilt_deg: float = 20.0
    # The board used for the belt should cover at least this fraction of the image (else extrapolation).
    min_belt_board_area: float = 0.10
    # --pattern too small for the board: warned when the pattern goes on past the corners found in at
    # least this share of the views (a single view can be fooled by clutter beside the board).
    larger_board_share: float = 0.25
    # --points: RANSAC inlier threshold (px) and the residual (mm, RMS over inliers) that is refused.
    ransac_px: float = 3.0
    max_points_residual_mm: float = 2.0
    # cornerSubPix: half window clamp (px) and stopping rule. A wide window averages the corner over
    # more of its edges: on real wide-angle views 11 px halves (23x23) reach RMS 0.234 px where 5 px
    # (OpenCV's own test recipe) gives 0.767; the window also stays inside one square (board.py).
    subpix_half_window_max: int = 11
    subpix_half_window_min: int = 2
    # A ChArUco view is used when it shows at least this many corners, not all on one line (fewer
    # constrain the camera little and let one bad marker decode weigh much).
    charuco_min_corners: int = 8
    subpix_criteria: tuple = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 40, 0.01)


DEFAULTS = CalibrateSettings()
