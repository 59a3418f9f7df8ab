"""Clutter guard: bounded work per frame, and a fault instead of thousands of phantoms.

Counting pixels and labelling blobs is cheap; measuring a blob (edges, undistortion,
mapping, fitting) is not. So before any measurement: a foreground covering most of
the region of interest is a changed scene, not parts; blobs too small to be a part are
dropped; of the rest only the largest few are kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class Guarded:
    """The mask to measure, whether the scene is not understood, and the bounding boxes
    (x, y, w, h) of the kept blobs that touch the edge of the region of interest."""

    mask: np.ndarray
    scene_fault: bool
    at_edge: frozenset[tuple[int, int, int, int]]


class ClutterGuard:
    def __init__(self, roi: np.ndarray, fault_fraction: float, max_blobs: int, min_area_px: float,
                 edge_px: int) -> None:
        self._roi_area = max(1, cv2.countNonZero(roi))
        self._fault_fraction = fault_fraction
        self._max_blobs = max_blobs
        self._min_area_px = min_area_px
        # The band just inside the region's edge (the image's border included): a blob reaching it
        # may go on outside, so it is clipped. None (edge_px 0): the measurement's own border check only.
        self._edge = None
        if edge_px > 0:
            kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * edge_px + 1,) * 2)
            inner = cv2.erode(roi, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
            self._edge = cv2.bitwise_and(roi, cv2.bitwise_not(inner))

    def __call__(self, mask: np.ndarray) -> Guarded:
        if cv2.countNonZero(mask) > self._fault_fraction * self._roi_area:
            return Guarded(np.zeros_like(mask), True, frozenset())
        n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        areas = stats[1:, cv2.CC_STAT_AREA]
        keep = np.nonzero(areas >= self._min_area_px)[0] + 1
        if len(keep) > self._max_blobs:
            keep = keep[np.argsort(-areas[keep - 1], kind="stable")[: self._max_blobs]]
        if len(keep) < n - 1:
            lut = np.zeros(n, np.uint8)
            lut[keep] = 255
            mask = lut[labels]
        at_edge: frozenset = frozenset()
        if self._edge is not None and len(keep):
            touching = np.zeros(n, bool)
            touching[labels[self._edge > 0]] = True
            at_edge = frozenset(tuple(int(v) for v in stats[i, :4]) for i in keep if touching[i])
        return Guarded(mask, False, at_edge)
