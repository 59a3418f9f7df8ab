"""Chessboard pattern, detection and a well-defined corner order.

Corner order (= the board's object frame, contract section 1): row-major, ``cols`` corners per
row; X along a row, Y along a column, Z = X x Y pointing away from the camera. Of the two orders
that satisfy this (the board and the board turned by 180 deg), the one whose first square (between
corners 0, 1, cols and cols + 1) is black is chosen. That square's colour only tells the two apart
when ``cols + rows`` is odd: a board with an even sum (both counts even or both odd) looks the same
after a 180 deg turn, so its origin is ambiguous (:func:`Pattern.symmetric`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from tracker.calibrate.settings import DEFAULTS, CalibrateSettings
from tracker.errors import BadInput

DETECTORS = ("auto", "classic", "sb")


@dataclass(frozen=True)
class Pattern:
    """A chessboard: ``cols`` x ``rows`` inner corners, squares of ``square_mm``."""

    cols: int
    rows: int
    square_mm: float

    def __post_init__(self) -> None:
        if self.cols < 3 or self.rows < 3:
            raise BadInput(f"--pattern: expected at least 3x3 inner corners, got {self.cols}x{self.rows}")
        if not (math.isfinite(self.square_mm) and self.square_mm > 0):
            raise BadInput(f"--square: expected a positive size in mm, got {self.square_mm}")

    @property
    def size(self) -> tuple[int, int]:
        return self.cols, self.rows

    @property
    def count(self) -> int:
        return self.cols * self.rows

    @property
    def symmetric(self) -> bool:
        """The board looks the same after a 180 deg turn: colour of square (i, j) is (i + j) mod 2 and
        (cols - i, rows - j) has the same colour exactly when cols + rows is even."""
        return (self.cols + self.rows) % 2 == 0

    def object_points(self, z_mm: float = 0.0) -> np.ndarray:
        """Nx3 corner positions in the board frame, in the corner order above."""
        grid = np.mgrid[0 : self.cols, 0 : self.rows].T.reshape(-1, 2) * self.square_mm
        return np.column_stack([grid, np.full(len(grid), z_mm)]).astype(np.float64)

    def __str__(self) -> str:
        return f"{self.cols}x{self.rows}"


def parse_pattern(text: str, square_mm: float) -> Pattern:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise BadInput(f"--pattern: expected COLSxROWS inner corners (e.g. 9x6), got {text!r}") from None
    return Pattern(cols, rows, square_mm)


@dataclass(frozen=True)
class Detection:
    corners: np.ndarray  # Nx2 float64 pixel coordinates, in the corner order of the module docstring
    method: str  # "classic" or "sb"


def detect(
    image: np.ndarray, pattern: Pattern, detector: str = "auto", settings: CalibrateSettings = DEFAULTS
) -> Detection | None:
    """Find the board; None when it is not (completely) visible.

    ``auto`` tries the classic detector first and refines with cornerSubPix (a window of 0.4 x the
    corner spacing, up to 11 px each side: see settings.py; on OpenCV's sample images its corners are
    more self-consistent than the sector-based detector's: RMS 0.181 vs 0.244 px), then falls back to
    ``findChessboardCornersSB``, which finds boards the classic one misses (blur, glare, strong perspective).
    """
    if detector not in DETECTORS:
        raise BadInput(f"--detector: expected one of {', '.join(DETECTORS)}, got {detector!r}")
    found = None
    if detector in ("auto", "classic"):
        ok, corners = cv2.findChessboardCorners(image, pattern.size)
        if ok:
            corners = corners.reshape(-1, 1, 2).astype(np.float32)
            half = _subpix_half_window(corners.reshape(-1, 2), pattern, settings)
            corners = cv2.cornerSubPix(image, corners, (half, half), (-1, -1), settings.subpix_criteria)
            found = Detection(corners.reshape(-1, 2).astype(np.float64), "classic")
    if found is None and detector in ("auto", "sb"):
        ok, corners = cv2.findChessboardCornersSB(
            image, pattern.size, flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
        )
        if ok:
            found = Detection(corners.reshape(-1, 2).astype(np.float64), "sb")
    if found is None:
        return None
    return Detection(canonical_order(image, found.corners, pattern), found.method)


def find(image: np.ndarray, board, detector: str = "auto", settings: CalibrateSettings = DEFAULTS):
    """The board's corners in ``image`` (a Detection; with ``ids`` for a ChArUco board), or None."""
    from tracker.calibrate.charuco import CharucoSpec, detect_charuco  # noqa: PLC0415 - only for ChArUco

    if isinstance(board, CharucoSpec):
        return detect_charuco(image, board, settings)
    return detect(image, board, detector, settings)


def _subpix_half_window(corners: np.ndarray, pattern: Pattern, settings: CalibrateSettings) -> int:
    """Largest half window that stays inside one square (a window spanning two corners biases both)."""
    grid = corners.reshape(pattern.rows, pattern.cols, 2)
    spacing = min(
        np.linalg.norm(np.diff(grid, axis=1), axis=2).min(), np.linalg.norm(np.diff(grid, axis=0), axis=2).min()
    )
    return int(np.clip(spacing * 0.4, settings.subpix_half_window_min, settings.subpix_half_window_max))


def canonical_order(image: np.ndarray, corners: np.ndarray, pattern: Pattern) -> np.ndarray:
    """Reorder detected corners into the order of the module docstring."""
    grid = corners.reshape(pattern.rows, pattern.cols, 2)
    # Right-handed as seen by the camera (image u right, v down, z forward): X x Y along +z means the
    # cross product of the row and column directions is positive in image coordinates.
    if _handedness(grid) < 0:
        grid = grid[:, ::-1]
    turned = grid[::-1, ::-1]
    if pattern.symmetric:
        # Colour cannot tell; take the order whose origin is nearer the image's top-left (as OpenCV does
        # for even boards), so at least the same view always gives the same frame.
        first = grid if grid[0, 0].sum() <= turned[0, 0].sum() else turned
    else:
        first = grid if _first_square_darkness(image, grid) >= _first_square_darkness(image, turned) else turned
    return np.ascontiguousarray(first.reshape(-1, 2))


def _handedness(grid: np.ndarray) -> float:
    x_dir = grid[0, -1] - grid[0, 0]
    y_dir = grid[-1, 0] - grid[0, 0]
    return float(x_dir[0] * y_dir[1] - x_dir[1] * y_dir[0])


def _first_square_darkness(image: np.ndarray, grid: np.ndarray) -> float:
    """How much darker the first square is than its two neighbours inside the grid (grey levels)."""
    rows, cols = grid.shape[:2]
    src = np.array([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]], dtype=np.float32)
    dst = np.array([grid[0, 0], grid[0, -1], grid[-1, -1], grid[-1, 0]], dtype=np.float32)
    to_image = cv2.getPerspectiveTransform(src, dst)
    # Sample the central part of each square (board units), away from the corners' blur.
    offs = np.array([[dx, dy] for dx in (-0.2, 0.0, 0.2) for dy in (-0.2, 0.0, 0.2)])

    def mean_at(cx: float, cy: float) -> float:
        pts = cv2.perspectiveTransform((offs + [cx, cy]).reshape(-1, 1, 2), to_image).reshape(-1, 2)
        h, w = image.shape[:2]
        u = np.clip(np.rint(pts[:, 0]).astype(int), 0, w - 1)
        v = np.clip(np.rint(pts[:, 1]).astype(int), 0, h - 1)
        return float(image[v, u].astype(np.float64).mean())

    first = mean_at(0.5, 0.5)
    return (mean_at(1.5, 0.5) + mean_at(0.5, 1.5)) / 2 - first


def board_continues(image: np.ndarray, corners: np.ndarray, pattern: Pattern) -> list[str]:
    """Sides (in board terms) past which the checker pattern goes on: a board with more inner
    corners than ``--pattern`` says. A board's edge squares lie one square beyond its outermost
    inner corners; one more square out is its margin, uniform. Where the squares there still
    alternate as strongly as inside, the detector found part of a larger board."""
    rows, cols = pattern.rows, pattern.cols
    grid = corners.reshape(rows, cols, 2).astype(np.float64)
    board = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), axis=-1).astype(np.float64)
    h, w = image.shape[:2]

    def levels(near: tuple[slice, slice], points: list[tuple[float, float]]) -> np.ndarray | None:
        # Extrapolate from the three lines of corners nearest the side: lens distortion bends the
        # board, and a homography over the whole grid would place the probes half a square off.
        to_image, _ = cv2.findHomography(board[near].reshape(-1, 2), grid[near].reshape(-1, 2))
        if to_image is None:
            return None
        pts = cv2.perspectiveTransform(np.array(points, dtype=np.float64).reshape(-1, 1, 2), to_image).reshape(-1, 2)
        if np.any(pts < 0) or np.any(pts[:, 0] > w - 1) or np.any(pts[:, 1] > h - 1):
            return None  # outside the image: nothing to tell
        return image[np.rint(pts[:, 1]).astype(int), np.rint(pts[:, 0]).astype(int)].astype(np.float64)

    def swing(values: np.ndarray | None) -> float:
        return 0.0 if values is None or len(values) < 2 else float(np.mean(np.abs(np.diff(values))))

    everything = (slice(None), slice(None))
    inside = swing(levels(everything, [(c + 0.5, 0.5) for c in range(cols - 1)]))
    sides = {
        "first row": ((slice(0, 3), slice(None)), [(c + 0.5, -1.5) for c in range(cols - 1)]),
        "last row": ((slice(-3, None), slice(None)), [(c + 0.5, rows - 1 + 1.5) for c in range(cols - 1)]),
        "first column": ((slice(None), slice(0, 3)), [(-1.5, r + 0.5) for r in range(rows - 1)]),
        "last column": ((slice(None), slice(-3, None)), [(cols - 1 + 1.5, r + 0.5) for r in range(rows - 1)]),
    }
    return [name for name, (near, pts) in sides.items() if inside > 0 and swing(levels(near, pts)) > 0.5 * inside]
