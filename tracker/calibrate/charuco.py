"""ChArUco boards (OpenCV's aruco module): a chessboard whose white squares carry ArUco markers, so
every corner found has an id. Partial views count (a hand over the board, the board half out of the
image) and the origin is never ambiguous.

Spec: ``charuco:COLSxROWS:SQUARE_MM:MARKER_MM:DICT``: COLSxROWS counts *squares* (11x8 has 10x7 inner
corners), DICT is an OpenCV predefined dictionary (e.g. DICT_5X5_100). The board's object frame is
OpenCV's: origin at the board's outer top-left corner (the black square's outer corner), X along the
first row of squares, Y down its first column, Z into the board; inner corner id k sits at
((k % (COLS-1)) + 1, (k // (COLS-1)) + 1) x SQUARE_MM.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracker.calibrate.settings import DEFAULTS, CalibrateSettings
from tracker.errors import BadInput

PREFIX = "charuco:"


def dictionaries() -> list[str]:
    return sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and not n.startswith("DICT_APRILTAG_"))


@dataclass(frozen=True)
class CharucoSpec:
    squares_x: int
    squares_y: int
    square_mm: float
    marker_mm: float
    dictionary: str

    def __post_init__(self) -> None:
        if self.squares_x < 3 or self.squares_y < 3:
            raise BadInput(f"--board {self}: expected at least 3x3 squares, got {self.squares_x}x{self.squares_y}")
        if not 0 < self.marker_mm < self.square_mm:
            raise BadInput(f"--board {self}: expected 0 < marker < square, got marker {self.marker_mm:g} mm, "
                           f"square {self.square_mm:g} mm")
        if self.dictionary not in dictionaries():
            raise BadInput(f"--board {self}: unknown dictionary {self.dictionary!r}, expected one of "
                           f"{', '.join(dictionaries())}")
        count = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary)).bytesList.shape[0]
        if count < self.squares_x * self.squares_y // 2:
            raise BadInput(f"--board {self}: {self.dictionary} has {count} markers, the board needs "
                           f"{self.squares_x * self.squares_y // 2}")

    def __str__(self) -> str:
        return f"{PREFIX}{self.squares_x}x{self.squares_y}:{self.square_mm:g}:{self.marker_mm:g}:{self.dictionary}"

    @property
    def symmetric(self) -> bool:
        return False  # the markers fix the origin

    @property
    def size_mm(self) -> tuple[float, float]:
        return self.squares_x * self.square_mm, self.squares_y * self.square_mm

    def board(self) -> cv2.aruco.CharucoBoard:
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_mm, self.marker_mm, d)

    def object_points(self, z_mm: float = 0.0) -> np.ndarray:
        """All inner corners (N x 3, mm) in id order."""
        pts = np.asarray(self.board().getChessboardCorners(), dtype=np.float64).reshape(-1, 3)
        pts[:, 2] = z_mm
        return pts


def parse_board(text: str) -> CharucoSpec:
    parts = text.split(":")
    try:
        if len(parts) != 5 or parts[0] != PREFIX[:-1]:
            raise ValueError
        cols, rows = (int(v) for v in parts[1].lower().split("x"))
        spec = CharucoSpec(cols, rows, float(parts[2]), float(parts[3]), parts[4])
    except ValueError:
        raise BadInput(f"--board: expected {PREFIX}COLSxROWS:SQUARE_MM:MARKER_MM:DICT (squares, e.g. "
                       f"charuco:11x8:20:14:DICT_5X5_100), got {text!r}") from None
    return spec


@dataclass(frozen=True)
class CharucoDetection:
    corners: np.ndarray  # Nx2 float64 px
    ids: np.ndarray  # N int: which inner corner each is
    method: str = "charuco"


def detect_charuco(image: np.ndarray, spec: CharucoSpec,
                   settings: CalibrateSettings = DEFAULTS) -> CharucoDetection | None:
    """The corners found (with their ids); None when too few, or all on one line, to use."""
    board = spec.board()
    corners, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(image)
    if ids is None or len(ids) < settings.charuco_min_corners:
        return None
    if board.checkCharucoCornersCollinear(ids):
        return None
    # The detector interpolates corners from the markers and refines them in a small window; a wider one
    # averages each corner over more of its edges (settings.py), but must stay clear of the markers
    # inside the white squares, which are no part of the corner.
    spacing = _min_spacing_px(corners.reshape(-1, 2), ids.reshape(-1), spec)
    clear = (spec.square_mm - spec.marker_mm) / 2 / spec.square_mm
    half = int(np.clip(0.8 * clear * spacing, settings.subpix_half_window_min, settings.subpix_half_window_max))
    refined = cv2.cornerSubPix(image, corners.reshape(-1, 1, 2).astype(np.float32), (half, half), (-1, -1),
                               settings.subpix_criteria)
    return CharucoDetection(refined.reshape(-1, 2).astype(np.float64), ids.reshape(-1).astype(int))


def _min_spacing_px(corners: np.ndarray, ids: np.ndarray, spec: CharucoSpec) -> float:
    """Smallest image distance between neighbouring corners found (the window must stay in a square)."""
    cols = spec.squares_x - 1
    where = {int(i): c for i, c in zip(ids, corners, strict=True)}
    gaps = [float(np.linalg.norm(c - where[j])) for i, c in where.items()
            for j in (i + 1, i + cols) if j in where and (j != i + 1 or (i + 1) % cols)]
    return min(gaps) if gaps else 10.0
