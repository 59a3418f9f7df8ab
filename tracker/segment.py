"""Segmentation: what differs from the empty belt, with the belt's reference kept up to date.

Differencing against a reference of the empty belt measures the part where it
is *now*; differencing consecutive frames would give the union of its outlines
at t and t-1 (half a frame of lag). Consecutive differences are used only to
tell where things move, so that the reference learns where nothing does.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.config import SegmentConfig


class Segmenter:
    """Frame in, foreground mask out; ``background`` is the 8-bit reference used for that frame."""

    def __init__(self, config: SegmentConfig) -> None:
        self.config = config
        self._kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (config.open_kernel_px,) * 2)
        # Guard band around moving/foreground pixels: blur fringes fainter than the
        # threshold must not leak into the reference.
        self._guard = cv2.getStructuringElement(cv2.MORPH_RECT, (7, 7))
        self._count = 0
        self._prev: np.ndarray | None = None
        # The learnt reference (float32): measurement reads it, since rounding it to 8 bits
        # would bias sub-pixel edges by up to ~0.01 px.
        self.reference: np.ndarray | None = None
        self._still_frames: np.ndarray | None = None  # uint16, per pixel
        self.background: np.ndarray | None = None  # uint8 view of the reference

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        cfg = self.config
        if self.reference is None:
            self.reference = frame.astype(np.float32)
            self._still_frames = np.zeros(frame.shape, dtype=np.uint16)
            self.background = frame.copy()
            self._prev = frame
            self._count = 1
            return np.zeros(frame.shape, dtype=np.uint8)
        _, fg = cv2.threshold(cv2.absdiff(frame, self.background), cfg.diff_threshold, 255, cv2.THRESH_BINARY)
        mask = cv2.morphologyEx(fg, cv2.MORPH_OPEN, self._kernel)
        if self._count % cfg.background_every == 0:
            self._learn(frame, fg)
        self._prev = frame
        self._count += 1
        return mask

    def _learn(self, frame: np.ndarray, fg: np.ndarray) -> None:
        cfg = self.config
        _, moving = cv2.threshold(cv2.absdiff(frame, self._prev), cfg.motion_threshold, 255, cv2.THRESH_BINARY)
        moving = cv2.dilate(moving, self._guard)
        busy = cv2.dilate(cv2.bitwise_or(fg, moving), self._guard)
        cv2.accumulateWeighted(frame, self.reference, cfg.background_rate, mask=cv2.bitwise_not(busy))
        # A foreground blob with no motion anywhere in it is a parked part or a ghost (what
        # the reference held when a part left): count how long; past the limit it is belt.
        parked = self._parked(fg, moving)
        # (OpenCV ops with a mask and no dst zero what the mask leaves out.)
        still = cv2.add(self._still_frames, cfg.background_every, mask=parked)
        absorb = cv2.compare(still, cfg.absorb_after_frames, cv2.CMP_GE)
        if cv2.countNonZero(absorb):
            cv2.copyTo(frame.astype(np.float32), absorb, self.reference)
            still = cv2.bitwise_and(still, still, mask=cv2.bitwise_not(absorb))
        self._still_frames = still
        self.background = cv2.convertScaleAbs(self.reference)

    @staticmethod
    def _parked(fg: np.ndarray, moving: np.ndarray) -> np.ndarray:
        """Mask of the foreground blobs that have no moving pixel."""
        parked = np.zeros_like(fg)
        contours, _ = cv2.findContours(fg, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        for contour in contours:
            x, y, w, h = cv2.boundingRect(contour)
            if not cv2.countNonZero(moving[y : y + h, x : x + w]):
                cv2.drawContours(parked, [contour], -1, 255, thickness=cv2.FILLED)
        return parked
