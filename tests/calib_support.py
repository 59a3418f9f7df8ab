"""Rendered chessboard views through a known camera, cached for the session (test helper)."""

from __future__ import annotations

import functools
from pathlib import Path

import cv2
import numpy as np

from tracker.calibrate.board import Pattern
from tracker.calibrate.synthetic_board import BoardRenderer, look_at_pose
from tracker.synthetic import STRONG_DISTORTION, CameraSpec

# The true camera: 640x480, focal 560 px, strong barrel distortion, 700 mm above the belt, tilted 15 deg.
CAMERA = CameraSpec(dist_coeffs=STRONG_DISTORTION, height_mm=700.0, tilt_deg=15.0, yaw_deg=20.0)
VIEW_PATTERN = Pattern(9, 6, 20.0)
BELT_PATTERN = Pattern(9, 6, 40.0)
N_VIEWS = 15
# The belt board's pose in the belt's world frame: turned 10 deg about Z, centred where the optical axis meets the belt.
BELT_BOARD_YAW_DEG = 10.0


@functools.cache
def true_calibration():
    return CAMERA.calibration()


@functools.cache
def renderer(pattern: Pattern) -> BoardRenderer:
    c = true_calibration()
    return BoardRenderer(c.camera_matrix, c.dist_coeffs, c.size, pattern)


@functools.cache
def intrinsic_views() -> tuple[np.ndarray, ...]:
    """Views 430-490 mm away, tilted 20-45 deg in all directions, centres spread over the image."""
    rng = np.random.default_rng(1)
    c = true_calibration()
    w, h = c.size
    f = c.camera_matrix[0, 0]
    images = []
    for i in range(N_VIEWS):
        z = 430 + 60 * rng.random()
        ang = 2 * np.pi * i / N_VIEWS
        rad = 0.0 if i == 0 else (0.18 if i % 2 else 0.30)
        x, y = z * rad * np.cos(ang) * (w / f), z * rad * np.sin(ang) * (h / f)
        tilt = 20 + 25 * ((i * 7) % N_VIEWS) / (N_VIEWS - 1)
        rvec, tvec = look_at_pose(np.array([x, y, z]), tilt, rng.uniform(0, 360), rng.uniform(-30, 30), VIEW_PATTERN)
        images.append(renderer(VIEW_PATTERN).render(rvec, tvec, seed=i))
    return tuple(images)


def belt_board_pose() -> tuple[np.ndarray, np.ndarray]:
    """(rvec, tvec) of the belt board in the camera frame (board frame -> camera frame, mm)."""
    c = true_calibration()
    yaw = np.radians(BELT_BOARD_YAW_DEG)
    r_wb = cv2.Rodrigues(np.array([0.0, 0.0, yaw]))[0]
    centre = np.array([(BELT_PATTERN.cols - 1) / 2, (BELT_PATTERN.rows - 1) / 2, 0.0]) * BELT_PATTERN.square_mm
    t_wb = -r_wb @ centre
    r_cw = cv2.Rodrigues(c.belt_rvec)[0]
    r_cb = r_cw @ r_wb
    t_cb = r_cw @ t_wb + c.belt_tvec.reshape(3)
    return cv2.Rodrigues(r_cb)[0], t_cb.reshape(3, 1)


@functools.cache
def belt_view() -> np.ndarray:
    rvec, tvec = belt_board_pose()
    return renderer(BELT_PATTERN).render(rvec, tvec, seed=99)


def write_views(folder: Path, images, prefix: str = "view") -> list[str]:
    paths = []
    for i, image in enumerate(images):
        p = folder / f"{prefix}{i:02d}.png"
        cv2.imwrite(str(p), image)
        paths.append(str(p))
    return paths
