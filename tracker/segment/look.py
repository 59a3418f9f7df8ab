"""Whether the belt's own look moves with it: the belt model ``segment.model: "auto"`` turns to.

The reference model (reference.py) learns the empty belt only where a frame differs from the one
before by at most ``segment.motion_threshold``: a belt whose texture, streaks or seams change by more
than that as it moves cannot be learnt, and its look becomes foreground. Such a belt changes the
whole view from frame to frame, parts only where their edges pass. So the region of interest is cut
into tiles, and the share of tiles in which the frame changed (its difference from the one before,
averaged over 3 x 3 pixels so that sensor noise does not count, the whole region's mean step taken
out so that a lamp's flicker does not either) is watched. Its median over 9 frames (measured, see
docs/HISTORY.md): 0.81 on the diamond-textured real belt, 0.47 among the CCTV clip's rollers, 0.34 on
the tests' knurled belt (tests/textured_support.py), 0.21 (0.32 at most) on the fine grey belt of the
mixed-items video, whose streaks the reference model turns into parts; on rendered plain belts with
one to five parts in view at most 0.17, with sensor noise of 4 grey levels too. A part with a printed
top covering 40 % of the view changes as many tiles as a moving belt does (0.33). One frame can
change everywhere (a part's shadow, a hand): the median over several new frames decides, and a
repeated frame (a frame-rate conversion) is not new.
"""

from __future__ import annotations

from collections import deque

import cv2
import numpy as np

from tracker.config import SegmentConfig
from tracker.segment.motion import DUPLICATE_LEVEL

# A tile is watched when at least this share of it lies in the region of interest.
_TILE_IN_ROI = 0.5
# The region is watched through at most this many pixels on its longer side, every so many pixels
# picked (not averaged: averaging would smooth away the very texture watched): the cost stays bounded.
_WATCH_PX = 640


class MovingLook:
    """Frame in, whether the belt's own look has been seen to move with it (for good once it has)."""

    def __init__(self, config: SegmentConfig, roi: np.ndarray) -> None:
        """``roi``: the region of interest (uint8 mask, > 0 inside)."""
        self._cfg = config
        x, y, w, h = cv2.boundingRect(roi)
        self._box = (slice(y, y + h), slice(x, x + w))
        scale = min(1.0, _WATCH_PX / max(w, h))
        self._size = (max(1, round(w * scale)), max(1, round(h * scale))) if scale < 1 else None
        self._roi = self._picked(roi[self._box])
        n = config.auto_tiles
        # Tiles as square as the region allows, auto_tiles along its longer side.
        self._grid = (n, max(1, round(n * h / w))) if w >= h else (max(1, round(n * w / h)), n)
        self._in_roi = self._share(self._roi) >= _TILE_IN_ROI * 255
        self._roi_px = max(1, cv2.countNonZero(self._roi))
        self._whole = self._roi_px == self._roi.size
        self._prev: np.ndarray | None = None
        self._shares: deque[float] = deque(maxlen=config.auto_frames)
        self.moving = False
        # The share of tiles this frame changed (0 for the first and a repeated frame).
        self.last_share = 0.0
        # The median share of tiles changing over the last auto_frames new frames (0 before as many).
        self.changing = 0.0

    @property
    def watched_tiles(self) -> int:
        """How many tiles are watched (0: the region is too thin for any to lie half in it)."""
        return int(np.count_nonzero(self._in_roi))

    @property
    def unsure(self) -> bool:
        """Whether the belt's look may be moving though not yet seen to: fewer than auto_frames new frames
        watched, or this frame changed as many tiles as a moving look does (a belt that starts to move)."""
        return not self.moving and (len(self._shares) < self._shares.maxlen
                                    or self.last_share >= self._cfg.auto_moving_share)

    def __call__(self, frame: np.ndarray) -> bool:
        if self.moving:
            return True
        patch = self._picked(frame[self._box])
        prev, self._prev = self._prev, patch if self._size else patch.copy()
        self.last_share = 0.0
        if prev is None:
            return False
        signed = cv2.subtract(patch, prev, dtype=cv2.CV_16S)
        # The whole region's step (a lamp's flicker, an exposure change) is no texture: taken out.
        step = cv2.mean(signed, mask=None if self._whole else self._roi)[0]
        diff = cv2.convertScaleAbs(signed, alpha=1.0, beta=-step)
        if not self._whole:
            diff = cv2.bitwise_and(diff, self._roi)
        changed = self._share(cv2.compare(cv2.blur(diff, (3, 3)), self._cfg.motion_threshold, cv2.CMP_GT))
        tiles = changed[self._in_roi] > self._cfg.auto_tile_changed * 255
        if not tiles.any() and cv2.sumElems(diff)[0] / self._roi_px < DUPLICATE_LEVEL:
            return False  # a repeated frame (a slow part on a noiseless view changes a tile or two: new)
        self.last_share = float(tiles.mean()) if tiles.size else 0.0
        self._shares.append(self.last_share)
        if len(self._shares) == self._shares.maxlen:
            self.changing = float(np.median(self._shares))
            self.moving = self.changing >= self._cfg.auto_moving_share
        return self.moving

    def _picked(self, image: np.ndarray) -> np.ndarray:
        """``image`` (of the region's box) at the watched size, its pixels picked."""
        if self._size is None:
            return image
        return cv2.resize(image, self._size, interpolation=cv2.INTER_NEAREST)

    def _share(self, mask: np.ndarray) -> np.ndarray:
        """Each tile's share of ``mask``'s set pixels (0-255 for 0-1, one per tile; 8 bits are plenty)."""
        return cv2.resize(mask, self._grid, interpolation=cv2.INTER_AREA)
