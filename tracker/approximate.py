"""An approximate calibration for a camera looking straight down, from a scale alone.

For trying a video before a chessboard is at hand: principal point at the image centre, no
distortion, the belt plane square to the optical axis at a nominal distance. Positions and
sizes are right to the accuracy of the scale; anything tilted or distorted is not modelled.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.calibration import Calibration, homography_from_pose
from tracker.errors import BadInput

# The nominal camera height: it only sets the focal length (mm per px = height / focal).
NOMINAL_HEIGHT_MM = 1000.0


def nadir_calibration(width: int, height: int, mm_per_px: float, source: str = "<approximate>") -> Calibration:
    """A straight-down camera seeing ``mm_per_px`` millimetres of belt per pixel.

    World frame: origin below the image centre, X along image columns, Y along rows (so Z points
    into the belt, as the contract's board frame does)."""
    if not (width > 0 and height > 0):
        raise BadInput(f"image size: expected positive width and height, got {width}x{height}")
    if not 0.001 <= mm_per_px <= 1000:
        raise BadInput(f"scale: expected 0.001 to 1000 mm per pixel, got {mm_per_px}")
    focal = NOMINAL_HEIGHT_MM / mm_per_px
    k = np.array([[focal, 0.0, (width - 1) / 2], [0.0, focal, (height - 1) / 2], [0.0, 0.0, 1.0]])
    rvec = np.zeros((3, 1))
    tvec = np.array([[0.0], [0.0], [NOMINAL_HEIGHT_MM]])
    rvec, _ = cv2.Rodrigues(np.eye(3))
    return Calibration(width, height, k, np.zeros((1, 5)), None, rvec, tvec,
                       homography_from_pose(k, rvec, tvec), source=source)
