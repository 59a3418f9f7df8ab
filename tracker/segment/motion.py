"""Belt motion from the images: the shift of the belt between consecutive frames.

Phase correlation of two frames finds their dominant translation to a fraction of a
pixel: inside the belt's region of interest that is the belt (its texture, streaks and
the parts riding on it all move together). Duplicate frames and stops read as zero.
"""

from __future__ import annotations

import cv2
import numpy as np

# The correlated patch is at most this many pixels on its long side (averaged down first):
# the cost stays bounded on any camera, and a belt's travel per frame stays measurable.
_PATCH_PX = 256
# A shift whose correlation peak is weaker than this is no measurement (a featureless or
# changing view): the belt is taken to keep its last shift.
_MIN_RESPONSE = 0.05
# Frames differing by less than this (mean |diff|, grey levels) repeat each other (a frame-rate
# conversion): the belt did not stop, the frame is just not new; its last shift is kept.
_DUPLICATE_LEVEL = 0.3


class BeltMotion:
    """Shift of the belt (image pixels, dx, dy) between each frame and the one before it."""

    def __init__(self, roi_mask: np.ndarray) -> None:
        ys, xs = np.nonzero(roi_mask)
        x0, x1, y0, y1 = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
        self._box = (slice(int(y0), int(y1)), slice(int(x0), int(x1)))
        self._scale = min(1.0, _PATCH_PX / max(x1 - x0, y1 - y0))
        self._size = (max(8, round((x1 - x0) * self._scale)), max(8, round((y1 - y0) * self._scale)))
        self._window = cv2.createHanningWindow(self._size, cv2.CV_32F)
        self._prev: np.ndarray | None = None
        self.shift_px = (0.0, 0.0)
        # The last frame repeated the one before it.
        self.duplicate = False

    def __call__(self, frame: np.ndarray) -> tuple[float, float]:
        patch = frame[self._box]
        if self._scale < 1.0:
            patch = cv2.resize(patch, self._size, interpolation=cv2.INTER_AREA)
        patch = patch.astype(np.float32)
        prev, self._prev = self._prev, patch
        self.duplicate = prev is not None and cv2.norm(patch, prev, cv2.NORM_L1) / patch.size < _DUPLICATE_LEVEL
        if prev is None or self.duplicate:
            return self.shift_px
        (dx, dy), response = cv2.phaseCorrelate(prev, patch, self._window)
        if response >= _MIN_RESPONSE:
            self.shift_px = (dx / self._scale, dy / self._scale)
        return self.shift_px
