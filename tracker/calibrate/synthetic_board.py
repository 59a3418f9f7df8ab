"""Renders a flat chessboard seen by a camera with exact OpenCV distortion (for tests with a known camera).

Like :mod:`tracker.synthetic`: the ray of every pixel centre comes from inverting the distortion
model to 1e-12 px; each ray meets the board's plane analytically; pixels an edge crosses are
supersampled (S x S rays interpolated between the exact pixel-centre rays). The board's object frame
is that of :mod:`tracker.calibrate.board`: inner corner (i, j) at (i, j, 0) x square, and the square
between the first four corners is black.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracker.calibrate.board import Pattern
from tracker.raycast import edge_pixels, interpolate, pixel_rays, subpixel_pattern


@dataclass(frozen=True)
class BoardLook:
    """Grey levels of the print and its surroundings, and the image noise."""

    black: float = 30.0
    white: float = 215.0
    background: float = 110.0
    # White margin around the outer squares, in squares (the detectors need a quiet zone).
    margin_squares: float = 1.0
    noise_sigma: float = 1.0
    supersample: int = 6


class BoardRenderer:
    """Renders views of one board through one camera (K, D, image size)."""

    def __init__(self, camera_matrix: np.ndarray, dist_coeffs: np.ndarray, size: tuple[int, int],
                 pattern: Pattern, look: BoardLook = BoardLook()) -> None:
        self.k = np.asarray(camera_matrix, dtype=np.float64)
        self.d = np.asarray(dist_coeffs, dtype=np.float64).reshape(1, -1)
        self.width, self.height = size
        self.pattern = pattern
        self.look = look
        norm = pixel_rays(self.k, self.d, self.width, self.height)
        # Camera-frame ray (x, y, 1) of each pixel centre.
        self._rays = np.concatenate([norm, np.ones((self.height, self.width, 1))], axis=2)

    def render(self, rvec: np.ndarray, tvec: np.ndarray, seed: int = 0, z_mm: float = 0.0) -> np.ndarray:
        """8-bit grey view of the board at pose (rvec, tvec) (board frame -> camera frame, mm).

        ``z_mm`` moves the printed plane along the board's Z (e.g. -3 for a print 3 mm above Z = 0).
        """
        rot, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
        t = np.asarray(tvec, dtype=np.float64).reshape(3) + z_mm * rot[:, 2]
        grey = self._shade(self._rays, rot, t)
        # Supersample pixels whose neighbourhood is not uniform (edges of squares and of the board).
        er, ec = edge_pixels(grey)
        ou, ov = subpixel_pattern(self.look.supersample)
        su = ec[:, None] + ou
        sv = er[:, None] + ov
        grey[er, ec] = self._shade(interpolate(self._rays, su, sv), rot, t).mean(axis=1)
        rng = np.random.default_rng(seed)
        if self.look.noise_sigma:
            grey = grey + rng.normal(0.0, self.look.noise_sigma, grey.shape)
        return np.clip(np.rint(grey), 0, 255).astype(np.uint8)

    def _shade(self, rays: np.ndarray, rot: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Grey level where each camera ray meets the board plane (background where it misses)."""
        normal = rot[:, 2]
        denom = rays @ normal
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = (normal @ t) / denom
        hit = np.isfinite(scale) & (scale > 0)
        points = rays * np.where(hit, scale, 0.0)[..., None]
        board = (points - t) @ rot  # camera -> board frame: R^T (X - t)
        return self._paint(board[..., 0], board[..., 1], hit).astype(np.float64)

    def _paint(self, x_mm: np.ndarray, y_mm: np.ndarray, hit: np.ndarray) -> np.ndarray:
        """The print's grey level at board point (x, y) mm; ``hit``: the ray meets the board's plane."""
        look, pat = self.look, self.pattern
        bx, by = x_mm / pat.square_mm, y_mm / pat.square_mm
        # Squares span -1..cols in x and -1..rows in y (square units); the print adds a white margin.
        m = look.margin_squares
        on_print = hit & (bx >= -1 - m) & (bx <= pat.cols + m) & (by >= -1 - m) & (by <= pat.rows + m)
        on_squares = (bx >= -1) & (bx < pat.cols) & (by >= -1) & (by < pat.rows)
        black = on_squares & ((np.floor(bx) + np.floor(by)) % 2 == 0)
        return np.where(on_print, np.where(black, look.black, look.white), look.background)


def look_at_pose(target_cam_mm: np.ndarray, tilt_deg: float, tilt_dir_deg: float, spin_deg: float,
                 pattern: Pattern) -> tuple[np.ndarray, np.ndarray]:
    """Board pose whose centre is at ``target_cam_mm`` (camera frame), its normal tilted by ``tilt_deg``
    from the optical axis towards azimuth ``tilt_dir_deg``, turned by ``spin_deg`` in its own plane.
    The board faces the camera (its Z points away from it)."""
    spin, tilt, azim = np.radians([spin_deg, tilt_deg, tilt_dir_deg])
    rz = cv2.Rodrigues(np.array([0.0, 0.0, spin]))[0]
    axis = np.array([np.cos(azim + np.pi / 2), np.sin(azim + np.pi / 2), 0.0])
    rt = cv2.Rodrigues(axis * tilt)[0]
    rot = rt @ rz
    centre_board = np.array([(pattern.cols - 1) / 2, (pattern.rows - 1) / 2, 0.0]) * pattern.square_mm
    tvec = np.asarray(target_cam_mm, dtype=np.float64) - rot @ centre_board
    rvec, _ = cv2.Rodrigues(rot)
    return rvec.reshape(3, 1), tvec.reshape(3, 1)
