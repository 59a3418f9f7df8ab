"""Renders a ChArUco board through a known camera, exactly like :mod:`synthetic_board` renders a
chessboard (for tests). The print is OpenCV's own board image at an integer number of texels per
square, looked up at each ray's intersection with the board: with 100 texels per 20 mm square and
14 mm markers every square and marker cell edge falls on a texel edge, so the print is exact."""

from __future__ import annotations

import numpy as np

from tracker.calibrate.board import Pattern
from tracker.calibrate.charuco import CharucoSpec
from tracker.calibrate.synthetic_board import BoardLook, BoardRenderer


class CharucoRenderer(BoardRenderer):
    def __init__(self, camera_matrix: np.ndarray, dist_coeffs: np.ndarray, size: tuple[int, int],
                 spec: CharucoSpec, look: BoardLook | None = None, texels_per_square: int = 100) -> None:
        # The chessboard renderer's pattern is only used for its square size here.
        super().__init__(camera_matrix, dist_coeffs, size, Pattern(spec.squares_x - 1, spec.squares_y - 1,
                                                                   spec.square_mm), look or BoardLook())
        self.spec = spec
        self.texels = texels_per_square
        w, h = spec.squares_x * texels_per_square, spec.squares_y * texels_per_square
        self.texture = spec.board().generateImage((w, h), marginSize=0, borderBits=1)

    def _paint(self, x_mm: np.ndarray, y_mm: np.ndarray, hit: np.ndarray) -> np.ndarray:
        look, spec = self.look, self.spec
        h, w = self.texture.shape
        col = np.floor(x_mm / spec.square_mm * self.texels)
        row = np.floor(y_mm / spec.square_mm * self.texels)
        on_board = hit & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        texel = self.texture[np.clip(row, 0, h - 1).astype(int), np.clip(col, 0, w - 1).astype(int)]
        printed = look.black + (look.white - look.black) * (texel / 255.0)
        m = look.margin_squares * spec.square_mm
        width_mm, height_mm = spec.size_mm
        on_print = hit & (x_mm >= -m) & (x_mm <= width_mm + m) & (y_mm >= -m) & (y_mm <= height_mm + m)
        return np.where(on_board, printed, np.where(on_print, look.white, look.background))
