"""Differencing against a learnt reference of the empty belt, robust to a belt texture that moves.

Differencing against a reference of the empty belt measures the part where it is *now*;
differencing consecutive frames would give the union of its outlines at t and t-1 (half a frame
of lag). Both differences are taken after a box blur: a real belt's fine texture moves with the
belt, so frame and reference disagree pixel by pixel everywhere on it, but their local means
agree; parts, much larger than the texture's period, keep their level. Consecutive differences
only tell the reference where things move, so that it learns where nothing does; on a moving
textured belt the learnt reference converges to the texture's mean, which is what sub-pixel
measurement needs as the belt's level.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.config import SegmentConfig

# Side of the guard band around moving/foreground pixels: blur fringes fainter than the
# threshold must not leak into the reference. Two dilations reach 2 * (7 // 2) rows.
_GUARD_PX = 7
_GUARD_REACH = 2 * (_GUARD_PX // 2)
# Pixels around a parked blob compared with it to tell a ghost from a parked part.
_GHOST_RING_PX = _GUARD_PX


class Segmenter:
    """Frame in, foreground mask out; ``reference`` is the learnt empty belt used for that frame.

    The reference learns one horizontal stripe per frame (``background_every`` stripes cover
    the frame), so learning costs the same on every frame instead of a spike every few frames.
    ``roi`` (uint8 mask) bounds the foreground; ``belt_moving`` (set by the pipeline from the
    measured belt motion) allows absorbing still blobs into the reference: while the belt
    stands, a still blob is a part that stopped with it.
    """

    def __init__(self, config: SegmentConfig, roi: np.ndarray | None = None) -> None:
        self.config = config
        self._kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (config.open_kernel_px,) * 2)
        self._close = cv2.getStructuringElement(cv2.MORPH_RECT, (config.close_kernel_px,) * 2)
        self._guard = cv2.getStructuringElement(cv2.MORPH_RECT, (_GUARD_PX, _GUARD_PX))
        self._blur = (config.texture_blur_px or 1,) * 2
        self._roi = roi
        self._inner: np.ndarray | None = None  # the image less a band along its border
        self._count = 0
        self._prev: np.ndarray | None = None  # previous frame, blurred
        # The learnt reference (float32): measurement reads it, since rounding it to 8 bits
        # would bias sub-pixel edges by up to ~0.01 px.
        self.reference: np.ndarray | None = None
        # Per pixel: learning steps its blob has been foreground without moving (uint8).
        self._still_steps: np.ndarray | None = None
        self.background: np.ndarray | None = None  # uint8 copy of the reference
        self._background_blurred: np.ndarray | None = None
        self.belt_moving = True
        # Fraction of the region of interest that was foreground in the last frame.
        self.foreground_fraction = 0.0

    def _smooth(self, image: np.ndarray) -> np.ndarray:
        return image if self._blur[0] == 1 else cv2.blur(image, self._blur)

    @property
    def blur_px(self) -> int:
        return self._blur[0]

    def _choose_blur(self, frame: np.ndarray) -> None:
        """Auto texture blur: on only when the belt has fine texture (a plain belt's edges stay sharp)."""
        cfg = self.config
        if cfg.texture_blur_px:
            return
        k = (cfg.texture_blur_auto_px,) * 2
        high = cv2.absdiff(frame, cv2.blur(frame, k))
        spread = cv2.mean(high, mask=self._roi)[0] * 1.2533  # mean |x| of a normal -> its sigma
        self._blur = k if spread > cfg.texture_spread else (1, 1)

    def reset(self, frame: np.ndarray) -> None:
        """Learn the reference anew from ``frame`` (start, or a scene that changed as a whole)."""
        if self.reference is None:
            self._choose_blur(frame)
        self.reference = frame.astype(np.float32)
        self._still_steps = np.zeros(frame.shape, dtype=np.uint8)
        self.background = frame.copy()
        self._background_blurred = self._smooth(frame)
        self._prev = self._background_blurred
        self._count = 1

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        cfg = self.config
        if self.reference is None:
            self.reset(frame)
            return np.zeros(frame.shape, dtype=np.uint8)
        smooth = self._smooth(frame)
        diff = cv2.absdiff(smooth, self._background_blurred)
        _, fg = cv2.threshold(diff, cfg.diff_threshold, 255, cv2.THRESH_BINARY)

        if self._roi is not None:
            fg = cv2.bitwise_and(fg, self._roi)
        area = cv2.countNonZero(self._roi) if self._roi is not None else fg.size
        self.foreground_fraction = cv2.countNonZero(fg) / area
        opened = cv2.morphologyEx(fg, cv2.MORPH_OPEN, self._kernel)
        # Closing near the image border would stretch a blob onto it (clipped, not measured).
        mask = cv2.bitwise_or(opened, cv2.bitwise_and(cv2.morphologyEx(opened, cv2.MORPH_CLOSE, self._close),
                                                      self._interior(frame.shape)))
        if self._roi is not None:
            mask = cv2.bitwise_and(mask, self._roi)
        self._learn_stripe(frame, smooth, fg, self._count % cfg.background_every)
        if self._count % cfg.background_every == 0:
            self._absorb_parked(frame, smooth, fg)
        self._prev = smooth
        self._count += 1
        return mask

    def _interior(self, shape: tuple[int, int]) -> np.ndarray:
        if self._inner is None or self._inner.shape != shape:
            m = self.config.close_kernel_px // 2 + 1
            self._inner = np.zeros(shape, dtype=np.uint8)
            self._inner[m:-m, m:-m] = 255
        return self._inner

    def _moving(self, smooth: np.ndarray, prev: np.ndarray) -> np.ndarray:
        _, moving = cv2.threshold(cv2.absdiff(smooth, prev), self.config.motion_threshold, 255, cv2.THRESH_BINARY)
        return moving

    def _learn_stripe(self, frame: np.ndarray, smooth: np.ndarray, fg: np.ndarray, stripe: int) -> None:
        """Blend this frame into the reference in stripe ``stripe`` of the frame, where nothing moves."""
        rows = frame.shape[0]
        n = self.config.background_every
        r0, r1 = rows * stripe // n, rows * (stripe + 1) // n
        # Compute the guard band on the stripe plus the rows the dilations reach into.
        g0, g1 = max(0, r0 - _GUARD_REACH), min(rows, r1 + _GUARD_REACH)
        moving = self._moving(smooth[g0:g1], self._prev[g0:g1])
        busy = cv2.dilate(cv2.bitwise_or(fg[g0:g1], cv2.dilate(moving, self._guard)), self._guard)
        still = cv2.bitwise_not(busy[r0 - g0 : r1 - g0])
        cv2.accumulateWeighted(frame[r0:r1], self.reference[r0:r1], self.config.background_rate, mask=still)
        self.background[r0:r1] = cv2.convertScaleAbs(self.reference[r0:r1])
        self._reblur(r0, r1)

    def _reblur(self, r0: int, r1: int) -> None:
        """Refresh the blurred reference on rows r0..r1 (the blur reaches half its size beyond them)."""
        if self._blur[0] == 1:
            self._background_blurred = self.background
            return
        half = self._blur[0] // 2
        rows = self.background.shape[0]
        b0, b1 = max(0, r0 - half), min(rows, r1 + half)
        blurred = cv2.blur(self.background[b0:b1], self._blur, borderType=cv2.BORDER_REFLECT_101)
        # Rows near a cut edge were blurred with reflected rows: keep only those computed from real ones.
        k0 = r0 - b0 if r0 > 0 else 0
        k1 = (b1 - b0) - (b1 - r1 if r1 < rows else 0)
        self._background_blurred[b0 + k0 : b0 + k1] = blurred[k0:k1]

    def _absorb_parked(self, frame: np.ndarray, smooth: np.ndarray, fg: np.ndarray) -> None:
        """A foreground blob with no motion anywhere in it, while the belt moves, is not on the
        belt (a parked object, glare) or is a ghost (what the reference held when a part left):
        count how long; past the limit it is belt. A ghost is recognised at once."""
        cfg = self.config
        parked, ghosts = self._parked(frame, fg, cv2.dilate(self._moving(smooth, self._prev), self._guard))
        if not self.belt_moving:
            # Parts that stop with the belt stay parts; ghosts still go.
            parked = cv2.bitwise_and(parked, ghosts)
        # (OpenCV ops with a mask and no dst zero what the mask leaves out.)
        still = cv2.add(self._still_steps, 1, mask=parked)
        limit = -(-cfg.absorb_after_frames // cfg.background_every)  # learning steps, rounded up
        absorb = cv2.bitwise_or(cv2.compare(still, limit, cv2.CMP_GE), ghosts)
        if cv2.countNonZero(absorb):
            cv2.copyTo(frame.astype(np.float32), absorb, self.reference)
            self.background = cv2.convertScaleAbs(self.reference)
            self._background_blurred = self._smooth(self.background)
            still = cv2.bitwise_and(still, still, mask=cv2.bitwise_not(absorb))
        self._still_steps = still

    def _parked(self, frame: np.ndarray, fg: np.ndarray, moving: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Masks of the foreground blobs that have no moving pixel, and of those among them that
        are ghosts: the reference inside differs from the belt around it, while the frame inside
        looks like that belt (a part that was in view when the reference was taken, now gone)."""
        parked = np.zeros_like(fg)
        ghosts = np.zeros_like(fg)
        contours, _ = cv2.findContours(fg, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        h, w = fg.shape
        m = _GHOST_RING_PX
        for contour in contours:
            x, y, bw, bh = cv2.boundingRect(contour)
            if cv2.countNonZero(moving[y : y + bh, x : x + bw]):
                continue
            cv2.drawContours(parked, [contour], -1, 255, thickness=cv2.FILLED)
            x0, y0, x1, y1 = max(0, x - m), max(0, y - m), min(w, x + bw + m), min(h, y + bh + m)
            blob = np.zeros((y1 - y0, x1 - x0), np.uint8)
            cv2.drawContours(blob, [contour], -1, 255, thickness=cv2.FILLED, offset=(-x0, -y0))
            ring = cv2.bitwise_xor(cv2.dilate(blob, self._guard), blob)
            ref, img = self.background[y0:y1, x0:x1], frame[y0:y1, x0:x1]
            if not cv2.countNonZero(ring):
                continue
            belt = cv2.mean(ref, mask=ring)[0]
            if (abs(cv2.mean(ref, mask=blob)[0] - belt) > self.config.diff_threshold
                    and abs(cv2.mean(img, mask=blob)[0] - belt) < self.config.diff_threshold / 2):
                ghosts[y0:y1, x0:x1] |= blob
        return parked, ghosts
