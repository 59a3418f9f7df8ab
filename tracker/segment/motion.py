"""Belt motion from the images: the shift between consecutive frames, and repeated frames.

Parts ride the belt, so everything in the region of interest that moves, moves with the belt:
phase correlation of two consecutive (reduced, windowed) frames peaks at the belt's shift. Static
things (rails, floor) are outside the region of interest. A frame that repeats the previous one
(frame-rate conversion, a stopped belt with nothing moving) carries no new information.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracker.config import SegmentConfig


@dataclass(frozen=True)
class MotionEstimate:
    # Belt shift since the last frame that was not a repeat, full-resolution image pixels.
    dx_px: float = 0.0
    dy_px: float = 0.0
    # Phase-correlation peak strength (0-1): how much of the image agrees with the shift.
    confidence: float = 0.0
    # No pixel changed by more than the motion threshold: a repeat of the previous frame.
    repeated: bool = False


class BeltMotion:
    """Feeds on each frame (and the ROI's bounding box); ``estimate`` is the latest motion."""

    def __init__(self, config: SegmentConfig, box: tuple[int, int, int, int]) -> None:
        self.config = config
        x, y, w, h = box
        self._box = box
        self._scale = max(1, config.motion_reduce)
        # Blur as for the textured-belt case always: it only feeds the reduction here.
        self._blur = (config.texture_blur_px or config.texture_blur_auto_px,) * 2
        self._size = (max(8, w // self._scale), max(8, h // self._scale))
        self._window = cv2.createHanningWindow(self._size, cv2.CV_32F)
        self._prev: np.ndarray | None = None
        self.estimate = MotionEstimate()

    def __call__(self, frame: np.ndarray) -> MotionEstimate:
        x, y, w, h = self._box
        crop = frame[y : y + h, x : x + w]
        if self._blur[0] > 1:
            crop = cv2.blur(crop, self._blur)  # a fine periodic texture would alias when reduced
        small = cv2.resize(crop, self._size, interpolation=cv2.INTER_AREA)
        prev = self._prev
        if prev is None:
            self._prev = small
            self.estimate = MotionEstimate()
            return self.estimate
        changed = cv2.countNonZero(cv2.compare(cv2.absdiff(small, prev), self.config.motion_threshold, cv2.CMP_GT))
        if changed == 0:
            # Compared with the last frame that was not a repeat, so that a slow creep adds up.
            self.estimate = MotionEstimate(repeated=True)
            return self.estimate
        self._prev = small
        (dx, dy), response = cv2.phaseCorrelate(prev.astype(np.float32), small.astype(np.float32), self._window)
        sx, sy = w / self._size[0], h / self._size[1]
        self.estimate = MotionEstimate(dx * sx, dy * sy, float(response))
        return self.estimate
