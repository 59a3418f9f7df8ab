"""Guided capture: which frames of a live camera (or of a video of a board being waved) make good
calibration views, and when there are enough.

A frame is kept when the whole board is found, it is sharp (no motion blur: the width of its
black-to-white transitions, measured across both edge directions) and it differs enough from every
view kept so far in where the board is, how large it looks and how it is tilted. Enough means the
corners have covered most of the image (the report's coverage grid), views are tilted in several
directions, and there are ``target_views`` of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from tracker.calibrate.board import Pattern
from tracker.errors import BadInput


@dataclass(frozen=True)
class CaptureSettings:
    # Mean black-to-white transition width (px, 10-90 %) above which a view is blurred. OpenCV's own
    # advice is below ~3 px; a still board through a focused lens gives 1.5-2.5.
    max_edge_width_px: float = 3.0
    # A view is new when its board centre moved by this fraction of the image diagonal, its size changed
    # by this fraction, or its tilt (as a vector: direction and amount) by this many degrees.
    min_shift: float = 0.08
    min_scale_change: float = 0.15
    min_tilt_change_deg: float = 10.0
    # Enough: this many views, this many of the coverage grid's cells reached, and views tilted by at
    # least tilt_deg in this many of the four directions (left, right, up, down).
    target_views: int = 15
    coverage_cells: int = 4
    min_cells: int = 12
    tilt_deg: float = 15.0
    min_tilt_directions: int = 3
    max_views: int = 40

    def __post_init__(self) -> None:
        if not 3 <= self.target_views <= self.max_views:
            raise BadInput(f"capture: expected 3 <= target views <= max views, got {self.target_views} "
                           f"and {self.max_views}")
        if not 0 < self.min_cells <= self.coverage_cells**2:
            raise BadInput(f"capture: expected 1 to {self.coverage_cells ** 2} coverage cells, got {self.min_cells}")


@dataclass(frozen=True)
class ViewPose:
    """Where the board is in a view: centre (fraction of the image), size (fraction of the diagonal),
    tilt as a vector in degrees (x: turned about the image's vertical axis, y: about its horizontal)."""

    centre: tuple[float, float]
    scale: float
    tilt_deg: tuple[float, float]

    @property
    def tilt_amount_deg(self) -> float:
        return math.hypot(*self.tilt_deg)


@dataclass
class Progress:
    frames: int = 0
    kept: int = 0
    cells: int = 0
    tilt_directions: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    last: str = ""


class ViewSelector:
    """Offered one frame and its board corners at a time; keeps the good, new ones."""

    def __init__(self, pattern: Pattern, size: tuple[int, int], settings: CaptureSettings = CaptureSettings()) -> None:
        self.pattern = pattern
        self.size = size
        self.settings = settings
        self.poses: list[ViewPose] = []
        self.progress = Progress()
        self._cells = np.zeros((settings.coverage_cells, settings.coverage_cells), dtype=bool)
        self._directions: set[str] = set()
        w, h = size
        # A rough pinhole camera, good enough to tell tilts apart (the calibration comes later).
        self._k = np.array([[w, 0, (w - 1) / 2], [0, w, (h - 1) / 2], [0, 0, 1]], dtype=np.float64)

    def offer(self, image: np.ndarray, corners: np.ndarray | None) -> bool:
        """Whether to keep this view; the reason for a refusal is in ``progress.last``."""
        p = self.progress
        p.frames += 1
        reason = self._refusal(image, corners)
        if reason:
            p.rejected[reason] = p.rejected.get(reason, 0) + 1
            p.last = reason
            return False
        pose = self.pose(corners)
        self.poses.append(pose)
        self._add_coverage(corners)
        p.kept, p.last = len(self.poses), "kept"
        return True

    @property
    def cells(self) -> np.ndarray:
        """The coverage grid's cells (rows = image v) that corners of kept views have reached."""
        return self._cells

    def enough(self) -> bool:
        s, p = self.settings, self.progress
        return p.kept >= s.max_views or (p.kept >= s.target_views and p.cells >= s.min_cells
                                         and p.tilt_directions >= s.min_tilt_directions)

    def _refusal(self, image: np.ndarray, corners: np.ndarray | None) -> str:
        if corners is None:
            return "no whole board"
        if edge_width_px(image, self.pattern, corners) > self.settings.max_edge_width_px:
            return "blurred"
        pose = self.pose(corners)
        if any(not self._differs(pose, kept) for kept in self.poses):
            return "like a kept view"
        return ""

    def _differs(self, a: ViewPose, b: ViewPose) -> bool:
        s = self.settings
        w, h = self.size
        shift = math.hypot((a.centre[0] - b.centre[0]) * w, (a.centre[1] - b.centre[1]) * h) / math.hypot(w, h)
        scale = abs(a.scale - b.scale) / max(a.scale, b.scale)
        tilt = math.dist(a.tilt_deg, b.tilt_deg)
        return shift >= s.min_shift or scale >= s.min_scale_change or tilt >= s.min_tilt_change_deg

    def pose(self, corners: np.ndarray) -> ViewPose:
        w, h = self.size
        centre = corners.mean(axis=0)
        hull = cv2.convexHull(corners.astype(np.float32))
        scale = math.sqrt(cv2.contourArea(hull)) / math.hypot(w, h)
        ok, rvec, _ = cv2.solvePnP(self.pattern.object_points(), corners.astype(np.float64), self._k, None)
        normal = cv2.Rodrigues(rvec)[0][:, 2] if ok else np.array([0.0, 0.0, 1.0])
        if normal[2] < 0:
            normal = -normal  # the board's normal towards the camera's viewing direction, either side
        tilt = (math.degrees(math.atan2(normal[0], normal[2])), math.degrees(math.atan2(normal[1], normal[2])))
        return ViewPose((float(centre[0] / w), float(centre[1] / h)), scale, tilt)

    def _add_coverage(self, corners: np.ndarray) -> None:
        w, h = self.size
        n = self.settings.coverage_cells
        cu = np.clip((corners[:, 0] / w * n).astype(int), 0, n - 1)
        cv = np.clip((corners[:, 1] / h * n).astype(int), 0, n - 1)
        self._cells[cv, cu] = True
        tx, ty = self.poses[-1].tilt_deg
        limit = self.settings.tilt_deg
        for name, value in (("left", -tx), ("right", tx), ("up", -ty), ("down", ty)):
            if value >= limit:
                self._directions.add(name)
        self.progress.cells = int(self._cells.sum())
        self.progress.tilt_directions = len(self._directions)


def edge_width_px(image: np.ndarray, pattern: Pattern, corners: np.ndarray) -> float:
    """Mean width of the board's black-to-white transitions across both edge directions (motion blur
    widens those across the motion only, so the wider of the two counts)."""
    pts = corners.reshape(-1, 1, 2).astype(np.float32)
    widths = []
    for vertical in (False, True):
        result = cv2.estimateChessboardSharpness(image, pattern.size, pts, vertical=vertical)
        widths.append(float(result[0][0]))
    return max(widths)
