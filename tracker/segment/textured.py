"""Segmentation for real belts whose texture, streaks and seams move with the parts.

A per-pixel image of the empty belt is wrong as soon as the belt moves: its texture
moves too. Two things stay true while it moves, and this model rests on them:

- averaged over a few pixels, a belt's fine texture (diamonds, fibres, compression
  noise) is nearly flat, while a part tens of pixels across keeps its level; so the
  frame is averaged down to a small working image first;
- at a fixed image pixel, the belt passing under it has a mean level and a spread
  (streaks and seams pass by, rails and letterbox bars stay): per-pixel statistics
  along the motion, which do not change as the belt moves. They learn in proportion
  to the belt's travel (a stopped belt or a duplicate frame teaches nothing), and only
  where nothing is foreground, so a part that stops with the belt stays a part.

Foreground is where the smoothed level leaves the belt's mean by more than a floor and
by more than a few of its standard deviations. Each part's outline is then drawn at full
resolution, on its own side of the belt's level (``outline.outline_parts``); ``reference`` is the
belt's mean seen at full resolution, for the measurement's sub-pixel edges.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.config import SegmentConfig
from tracker.segment.outline import OutlineGeometry, outline_parts
from tracker.segment.views import UpsampledView

# Belt travel (working pixels) that counts as one full learning step.
_STEP_PX = 1.0
# Learning never stops entirely: a static scene (belt not moving, rollers) still adapts slowly.
_MIN_STEP = 0.1
# A foreground blob whose frame content sits this close (mean |level - ring|, in thresholds)
# to the plain belt around it is a ghost: belt the model learnt wrongly (a part or a sheet
# in view at start, since gone). It joins the belt at once.
_GHOST_FRACTION = 0.5
# Radius (working pixels) within which the strongest contrast sets what is half of it.
_NEAR_WORK_PX = 6
# Working pixels along the region's edge that the smoothing blends with what lies outside it.
_EDGE_WORK_PX = 4
# Parts are at least this thick (working pixels, ~2 % of the long side): thinner is a streak.
_MIN_PART_WORK_PX = 5
# The belt's gain is followed only while at least this fraction of the working image shows belt.
_MIN_BELT_FRACTION = 0.1
# A blob is stationary (scenery, not a part) when the belt travelled at least this far (working
# pixels) since the last frame and the blob matches the last frame in place this much better than
# moved along with the belt; it is then learnt at this rate per frame.
_STATIONARY_TRAVEL_WORK_PX = 0.25
_STATIONARY_RATIO = 0.5
_STATIONARY_RATE = 0.2


class TexturedSegmenter:
    """Frame in, foreground mask out; ``reference`` is the expected empty belt (float32, full size)."""

    def __init__(self, config: SegmentConfig, roi: np.ndarray, mm_per_px: float = 1.0) -> None:
        self.config = config
        h, w = roi.shape
        self._size = (w, h)
        self._scale = min(1.0, config.textured_work_px / max(w, h))
        self._work = (max(8, round(w * self._scale)), max(8, round(h * self._scale)))
        self._roi = roi
        self._roi_small = cv2.resize(roi, self._work, interpolation=cv2.INTER_AREA)
        # Any working pixel touching the region belongs to it (the full mask is cut to the region later).
        _, self._roi_small = cv2.threshold(self._roi_small, 0, 255, cv2.THRESH_BINARY)
        self._kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))
        # How much of each working pixel's smoothing window lies in the region (None: all of it).
        self._weight = None
        if cv2.countNonZero(roi) < roi.size:
            weight = cv2.resize(roi, self._work, interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
            self._weight = np.maximum(cv2.GaussianBlur(weight, (3, 3), 0.8), 1e-3)
        # Foreground thinner than this (working pixels) is a streak or seam across the belt, no part.
        thin = max(_MIN_PART_WORK_PX, int(config.min_part_mm / mm_per_px * self._scale))
        self._thin = cv2.getStructuringElement(cv2.MORPH_RECT, (thin, thin))
        # A blob within this many pixels of the region's edge reaches it: it may go on outside and
        # is clipped (the smoothing blends what lies outside into the region's last working pixels).
        self.edge_px = int(np.ceil(_EDGE_WORK_PX / self._scale))
        # "Near" a pixel for its peak contrast: a shadow or glow this close to a part is judged against it.
        self._near = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * _NEAR_WORK_PX + 1,) * 2)
        # One working pixel, at full resolution: how far a hull may grow to the half-contrast edge.
        band = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * round(1 / self._scale) + 1,) * 2)
        self._geometry = OutlineGeometry(self._size, self._scale, self._near, self._thin, band)
        self.mean: np.ndarray | None = None
        self._prev: np.ndarray | None = None
        # Working pixels of the last frame that showed plain belt (far from any foreground).
        self._belt = self._roi_small
        self.var: np.ndarray | None = None
        # The belt's travel since the last frame (image pixels) and whether the frame repeats the
        # one before; set by the pipeline from the belt's measured motion before each frame.
        self.shift_px = (0.0, 0.0)
        self.duplicate = False
        # The light parts' shadows in the last frame (255 in them; None: none), seen at full resolution:
        # the edges beside them are read against the belt as dark as it is there.
        self.shadows: UpsampledView | None = None
        # Where its reference is not yet the belt's own: nowhere it knows of (a coarse model learnt from
        # the start; measure.py reads its belt through a fitted plane instead).
        self.unsure: np.ndarray | None = None

    @property
    def reference(self) -> UpsampledView | None:
        """The belt's mean level at full resolution (float32), indexable like the full image; only
        the pieces measurement reads (around each blob) are ever computed."""
        return None if self.mean is None else UpsampledView(self.mean, self._size, self._scale)

    def _smooth(self, frame: np.ndarray) -> np.ndarray:
        """The frame averaged down and blurred, over the region only: what lies outside it (letterbox
        bars, rails) is not blended into the region's edge (normalised by the region's own weight)."""
        if self._weight is not None:
            frame = cv2.bitwise_and(frame, self._roi)
        small = cv2.resize(frame, self._work, interpolation=cv2.INTER_AREA).astype(np.float32)
        small = cv2.GaussianBlur(small, (3, 3), 0.8)
        if self._weight is not None:
            small = cv2.divide(small, self._weight)
        return small

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        cfg = self.config
        small = self._smooth(frame)
        if self.mean is None:
            self._start(small)
        else:
            self._follow_exposure(small)
        diff = small - self.mean
        contrast = np.abs(diff)
        # Foreground where |diff| > max(floor, k * sigma).
        limit = np.maximum(cfg.textured_sigmas * np.sqrt(self.var), cfg.textured_threshold)
        fg = cv2.bitwise_and(cv2.compare(contrast, limit, cv2.CMP_GT), self._roi_small)
        fg = cv2.morphologyEx(fg, cv2.MORPH_CLOSE, self._kernel)
        # Everything unlike the belt (shadows and reflections included) is kept from learning,
        # unless nearly everything is unlike it: then the model is wrong (light switched on, camera
        # moved), not the belt covered, and it learns the scene anew.
        lost = cv2.countNonZero(fg) > self.config.scene_fault_fraction * cv2.countNonZero(self._roi_small)
        self._learn(small, diff, np.zeros_like(fg) if lost else fg)
        self._belt = cv2.bitwise_and(cv2.bitwise_not(cv2.dilate(fg, self._near)), self._roi_small)
        ghosts = self._absorb_ghosts(small, fg)
        # Open: thin streaks, seams and edges across the belt are no parts.
        fg = cv2.morphologyEx(cv2.bitwise_and(fg, cv2.bitwise_not(ghosts)), cv2.MORPH_OPEN, self._thin)
        mask, shadows = outline_parts(diff, contrast, fg, self._geometry, cfg)
        self.shadows = None if shadows is None else UpsampledView(shadows.astype(np.float32), self._size, self._scale)
        return cv2.bitwise_and(mask, self._roi)

    def _start(self, small: np.ndarray) -> None:
        """First frame: the belt runs along the region's long side, so each line along it is mostly
        belt, whatever lies on it (parts, a sheet): the belt's level across it is that line's median.
        Structure that stays put while the belt moves is learnt as it shows itself (``_stationary``)."""
        roi = self._roi_small > 0
        along_rows = np.count_nonzero(roi.any(axis=0)) >= np.count_nonzero(roi.any(axis=1))
        # Outside the region: the region's overall median, so that lines leaving it are still defined.
        values = np.where(roi, small, np.median(small[roi]))
        axis = 1 if along_rows else 0
        profile = np.median(values, axis=axis, keepdims=True)
        # The belt's spread along each line (a robust sigma: 1.4826 x the median absolute deviation):
        # a belt of rollers or bold stripes passes by with a large one, a plain belt with the floor.
        sigma = 1.4826 * np.median(np.abs(values - profile), axis=axis, keepdims=True)
        floor = self.config.textured_threshold / self.config.textured_sigmas
        self.mean = (profile + np.zeros_like(small)).astype(np.float32)
        self.var = (np.maximum(sigma, floor) ** 2 + np.zeros_like(small)).astype(np.float32)

    def _follow_exposure(self, small: np.ndarray) -> None:
        """A camera's automatic exposure (or the light) changes the whole belt's level at once,
        faster than the belt can be learnt: the model follows the belt's overall gain each frame."""
        if cv2.countNonZero(self._belt) < _MIN_BELT_FRACTION * self._belt.size:
            return
        model = cv2.mean(self.mean, mask=self._belt)[0]
        if model > 1.0:
            gain = cv2.mean(small, mask=self._belt)[0] / model
            self.mean *= gain
            self.var *= gain * gain

    def _learn(self, small: np.ndarray, diff: np.ndarray, fg: np.ndarray) -> None:
        if self.duplicate:
            return  # a repeated frame brings no new belt
        travel = float(np.hypot(*self.shift_px)) * self._scale / _STEP_PX
        rate = self.config.textured_rate * min(1.0, max(_MIN_STEP, travel))
        # Shadows and the light a part throws on the belt near it are no belt to learn either.
        learn = cv2.bitwise_not(cv2.dilate(fg, self._near))
        cv2.accumulateWeighted(small, self.mean, rate, mask=learn)
        cv2.accumulateWeighted(cv2.multiply(diff, diff), self.var, rate, mask=learn)

    def _absorb_ghosts(self, small: np.ndarray, fg: np.ndarray) -> np.ndarray:
        """Blobs that are ghosts join the belt at once, blobs that stay put while the belt moves
        join it quickly; returns the mask of the ghosts."""
        ghosts = np.zeros_like(fg)
        prev, self._prev = self._prev, small
        n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
        if n <= 1:
            return ghosts
        floor = self.config.textured_threshold
        h, w = fg.shape
        dx, dy = (self._scale * d for d in self.shift_px)
        moved = None
        if prev is not None and not self.duplicate and np.hypot(dx, dy) >= _STATIONARY_TRAVEL_WORK_PX:
            # The last frame moved along with the belt: what rides on the belt matches it, not ``prev``.
            moved = cv2.warpAffine(prev, np.float32([[1, 0, dx], [0, 1, dy]]), (w, h), borderMode=cv2.BORDER_REPLICATE)
        order = np.argsort(-stats[1:, cv2.CC_STAT_AREA], kind="stable")[: 2 * self.config.max_blobs] + 1
        for i in order:
            x, y, bw, bh, _ = stats[i]
            x0, y0, x1, y1 = max(0, x - 2), max(0, y - 2), min(w, x + bw + 2), min(h, y + bh + 2)
            blob = (labels[y0:y1, x0:x1] == i).astype(np.uint8) * 255
            ring = cv2.bitwise_and(cv2.bitwise_xor(cv2.dilate(blob, self._kernel, iterations=2), blob),
                                   cv2.bitwise_not(fg[y0:y1, x0:x1]))
            if cv2.countNonZero(ring) < 4:
                continue
            img = small[y0:y1, x0:x1]
            belt = cv2.mean(img, mask=ring)[0]
            spread = cv2.mean(cv2.absdiff(img, belt), mask=blob)[0]
            if spread < _GHOST_FRACTION * floor:
                cv2.copyTo(img, blob, self.mean[y0:y1, x0:x1])
                ghosts[y0:y1, x0:x1] |= blob
            elif moved is not None:
                still = cv2.mean(cv2.absdiff(img, prev[y0:y1, x0:x1]), mask=blob)[0]
                riding = cv2.mean(cv2.absdiff(img, moved[y0:y1, x0:x1]), mask=blob)[0]
                if still < _STATIONARY_RATIO * riding:
                    # Rails, glare, a floor or rollers: belt scenery, not a part.
                    cv2.accumulateWeighted(img, self.mean[y0:y1, x0:x1], _STATIONARY_RATE, mask=blob)
        return ghosts
