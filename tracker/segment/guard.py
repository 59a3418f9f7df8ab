"""Clutter guard: bounded work per frame, and a fault instead of thousands of phantoms.

Counting pixels and tracing outlines is cheap; measuring a blob (edges, undistortion,
mapping, fitting) is not. So before any measurement: a foreground covering most of
the region of interest is a changed scene, not parts; of the blobs only the largest
few are kept; and blobs reaching the region's edge are marked (they may go on outside).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class Guarded:
    """The mask to measure, whether the scene is not understood, and the bounding boxes
    (x, y, w, h) of the kept blobs that reach the edge of the region of interest."""

    mask: np.ndarray
    scene_fault: bool
    at_edge: frozenset[tuple[int, int, int, int]]


class ClutterGuard:
    def __init__(self, roi: np.ndarray, fault_fraction: float, max_blobs: int, edge_px: int) -> None:
        self._fault_px = fault_fraction * max(1, cv2.countNonZero(roi))
        self._max_blobs = max_blobs
        # The band just inside the region's edge (the image's border included). None (edge_px 0):
        # the measurement's own check of the image border is all.
        self._edge = None
        if edge_px > 0:
            kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * edge_px + 1,) * 2)
            inner = cv2.erode(roi, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
            self._edge = cv2.bitwise_and(roi, cv2.bitwise_not(inner))

    def __call__(self, mask: np.ndarray) -> Guarded:
        if cv2.countNonZero(mask) > self._fault_px:
            return Guarded(np.zeros_like(mask), True, frozenset())
        if self._edge is None:
            # Nothing to mark at an edge: count the blobs a measurement would find costly (large
            # enough to survive a quarter-size view) on that view, at a tenth of the full cost.
            h, w = mask.shape
            quarter = cv2.resize(mask, (max(1, w // 4), max(1, h // 4)), interpolation=cv2.INTER_NEAREST)
            few, _ = cv2.findContours(quarter, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
            if len(few) <= self._max_blobs:
                return Guarded(mask, False, frozenset())
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if len(contours) > self._max_blobs:
            areas = np.array([cv2.contourArea(c) for c in contours])
            contours = [contours[i] for i in np.argsort(-areas, kind="stable")[: self._max_blobs]]
            mask = np.zeros_like(mask)
            cv2.drawContours(mask, contours, -1, 255, thickness=cv2.FILLED)
        at_edge: set[tuple[int, int, int, int]] = set()
        if self._edge is not None:
            for contour in contours:
                # A blob reaching into the band has outline pixels in it.
                pts = contour.reshape(-1, 2)
                if self._edge[pts[:, 1], pts[:, 0]].any():
                    at_edge.add(tuple(int(v) for v in cv2.boundingRect(contour)))
        return Guarded(mask, False, frozenset(at_edge))
