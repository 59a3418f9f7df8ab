"""An approximate calibration for trying a video before a chessboard is at hand.

A camera looking straight down, principal point at the image centre, no lens distortion, the
belt square to the optical axis at a nominal distance; the scale (mm per pixel on the belt) is
all that is measured. Positions and sizes are right to the accuracy of the scale near the image
centre; tilt and distortion are not modelled. The file says so (``approximate`` nodes), and
``tracker calibrate show`` prints it.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from tracker.calibration import Calibration, homography_from_pose
from tracker.errors import BadInput

# Only sets the focal length (mm per pixel = height / focal); any value gives the same mapping.
NOMINAL_HEIGHT_MM = 1000.0


def nadir_calibration(width: int, height: int, mm_per_px: float, note: str = "") -> Calibration:
    """World frame: origin below the image centre, X along image columns, Y along rows (so Z points
    into the belt, as the contract's board frame does)."""
    if not (isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0):
        raise BadInput(f"--size: expected a positive WIDTHxHEIGHT in pixels, got {width}x{height}")
    if not (math.isfinite(mm_per_px) and 0.001 <= mm_per_px <= 1000):
        raise BadInput(f"scale: expected 0.001 to 1000 mm per pixel, got {mm_per_px}")
    focal = NOMINAL_HEIGHT_MM / mm_per_px
    k = np.array([[focal, 0.0, (width - 1) / 2], [0.0, focal, (height - 1) / 2], [0.0, 0.0, 1.0]])
    rvec, _ = cv2.Rodrigues(np.eye(3))
    tvec = np.array([[0.0], [0.0], [NOMINAL_HEIGHT_MM]])
    note = note or (f"straight-down camera assumed, {mm_per_px:g} mm/px from a scale; no tilt, no lens "
                    "distortion: calibrate with a board before production")
    return Calibration(width, height, k, np.zeros((1, 5)), None, rvec, tvec, homography_from_pose(k, rvec, tvec),
                       source="<approximate>", approximate=note)
