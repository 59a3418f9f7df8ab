"""Belt mapping accuracy of the calibration commands against OpenCV used directly, on rendered
calibration sets of cameras the tests do not use (true camera and belt known).

For each set: intrinsics from ~18 chessboard views and the belt pose from one board on the belt,
(a) by the product (calibrate_intrinsics + belt_from_board), (b) by OpenCV directly
(findChessboardCorners, cornerSubPix 11x11, calibrateCamera, solvePnP). The error is how far a grid
of image points lands on the belt from where the true camera puts them (mean and p95, mm).

    .venv/bin/python bench/calib_belt.py
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import cv2
import numpy as np

from tracker.calibrate.belt import belt_from_board
from tracker.calibrate.board import Pattern
from tracker.calibrate.intrinsics import calibrate_intrinsics
from tracker.calibrate.synthetic_board import BoardLook, BoardRenderer, look_at_pose
from tracker.calibration import Calibration
from tracker.synthetic import CameraSpec
from tracker.undistort import BeltMapper


@dataclass(frozen=True)
class CalibSet:
    name: str
    camera: CameraSpec
    views: Pattern
    belt: Pattern
    n_views: int = 18
    max_tilt_deg: float = 45.0
    noise: float = 1.5


SETS = (
    CalibSet("720p mild lens, 12 deg tilt",
             CameraSpec(1280, 720, 1000.0, (-12.0, 8.0), (-0.12, 0.05, 0.0005, -0.0003, 0.0), 800.0, 12.0, 25.0),
             Pattern(9, 6, 25.0), Pattern(9, 6, 50.0)),
    CalibSet("VGA strong lens, 22 deg tilt",
             CameraSpec(640, 480, 480.0, (5.0, -3.0), (-0.35, 0.15, 0.001, -0.0008, -0.03), 650.0, 22.0, -10.0),
             Pattern(8, 5, 25.0), Pattern(8, 5, 45.0)),
    CalibSet("1080p wide lens, straight down",
             CameraSpec(1920, 1080, 1150.0, (20.0, 15.0), (-0.28, 0.09, 0.0, 0.0, -0.015), 900.0, 0.0, 0.0),
             Pattern(11, 8, 20.0), Pattern(11, 8, 40.0), n_views=20, max_tilt_deg=50.0),
)


def render_set(s: CalibSet):
    c = s.camera.calibration()
    look = BoardLook(noise_sigma=s.noise, supersample=4)
    views_r = BoardRenderer(c.camera_matrix, c.dist_coeffs, c.size, s.views, look)
    rng = np.random.default_rng(11)
    w, h = c.size
    f = c.camera_matrix[0, 0]
    size_mm = max(s.views.cols, s.views.rows) * s.views.square_mm
    images = []
    for i in range(s.n_views):
        z = f * size_mm / (0.5 * w) * (0.9 + 0.4 * rng.random())  # the board spans about half the width
        ang = 2 * np.pi * i / s.n_views
        rad = 0.0 if i == 0 else (0.2 if i % 2 else 0.34)
        x, y = z * rad * np.cos(ang) * (w / f), z * rad * np.sin(ang) * (h / f)
        tilt = 15 + (s.max_tilt_deg - 15) * ((i * 7) % s.n_views) / (s.n_views - 1)
        rvec, tvec = look_at_pose(np.array([x, y, z]), tilt, rng.uniform(0, 360), rng.uniform(-30, 30), s.views)
        images.append(views_r.render(rvec, tvec, seed=i))
    # The belt board: centred where the optical axis meets the belt, turned 15 deg.
    r_wb = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(15.0)]))[0]
    centre = np.array([(s.belt.cols - 1) / 2, (s.belt.rows - 1) / 2, 0.0]) * s.belt.square_mm
    t_wb = -r_wb @ centre
    r_cw = cv2.Rodrigues(c.belt_rvec)[0]
    rvec = cv2.Rodrigues(r_cw @ r_wb)[0]
    tvec = (r_cw @ t_wb + c.belt_tvec.reshape(3)).reshape(3, 1)
    belt_r = BoardRenderer(c.camera_matrix, c.dist_coeffs, c.size, s.belt, look)
    return c, images, belt_r.render(rvec, tvec, seed=99), c.with_belt(rvec, tvec)


def product(s: CalibSet, c: Calibration, images, belt_image) -> Calibration:
    r = calibrate_intrinsics([f"v{i}" for i in range(len(images))], images, s.views, 8)
    f = r.final
    intr = Calibration(c.image_width, c.image_height, f.camera_matrix, f.dist_coeffs, f.rms_px)
    return belt_from_board(intr, belt_image, "belt", s.belt).calibration


def opencv_direct(s: CalibSet, c: Calibration, images, belt_image) -> Calibration:
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)

    def corners(image, pattern):
        ok, pts = cv2.findChessboardCorners(image, pattern.size)
        return cv2.cornerSubPix(image, pts, (11, 11), (-1, -1), crit) if ok else None

    found = [p for p in (corners(im, s.views) for im in images) if p is not None]
    obj = s.views.object_points().astype(np.float32)
    _, k, d, _, _ = cv2.calibrateCamera([obj] * len(found), found, c.size, None, None)
    pts = corners(belt_image, s.belt)
    _, rvec, tvec = cv2.solvePnP(s.belt.object_points(), pts.reshape(-1, 2).astype(np.float64), k, d)
    return Calibration(c.image_width, c.image_height, k, d.reshape(1, -1)).with_belt(rvec, tvec)


def mapping_error_mm(est: Calibration, truth: Calibration) -> np.ndarray:
    w, h = truth.size
    u, v = np.meshgrid(np.linspace(0.05 * w, 0.95 * w, 17), np.linspace(0.05 * h, 0.95 * h, 11))
    px = np.column_stack([u.ravel(), v.ravel()])
    # The board's frame on the belt may differ from the belt world frame: compare in the board frame.
    return np.linalg.norm(BeltMapper(est).to_mm(px) - BeltMapper(truth).to_mm(px), axis=1)


def main(argv: list[str] | None = None) -> int:
    print(f"{'set':<34} {'method':<14} {'mean mm':>8} {'p95 mm':>8}")
    for s in SETS:
        c, images, belt_image, truth = render_set(s)
        for name, method in (("product", product), ("opencv direct", opencv_direct)):
            err = mapping_error_mm(method(s, c, images, belt_image), truth)
            print(f"{s.name:<34} {name:<14} {err.mean():>8.3f} {np.percentile(err, 95):>8.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
