"""The belt pose: a board lying flat on the belt (or measured point pairs) seen by a calibrated camera."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracker.calibrate.board import Pattern, find
from tracker.calibrate.settings import DEFAULTS, CalibrateSettings
from tracker.calibration import Calibration
from tracker.errors import BadInput
from tracker.undistort import BeltMapper


@dataclass
class BeltResult:
    calibration: Calibration  # with the belt pose
    image_points: np.ndarray  # Nx2 px used
    world_mm: np.ndarray  # Nx2 mm on the belt
    inliers: np.ndarray  # N bools
    reprojection_rms_px: float
    residual_mm: np.ndarray  # N distances: pixel mapped to the belt vs the known position
    warnings: list[str]

    @property
    def residual_rms_mm(self) -> float:
        r = self.residual_mm[self.inliers]
        return float(np.sqrt(np.mean(r**2)))


def _finish(calib: Calibration, rvec: np.ndarray, tvec: np.ndarray, img: np.ndarray, world: np.ndarray,
            inliers: np.ndarray, warnings: list[str]) -> BeltResult:
    with_belt = calib.with_belt(rvec, tvec)
    obj = np.column_stack([world, np.zeros(len(world))])
    proj, _ = cv2.projectPoints(obj, rvec, tvec, calib.camera_matrix, calib.dist_coeffs)
    err = np.linalg.norm(proj.reshape(-1, 2) - img, axis=1)[inliers]
    mapped = BeltMapper(with_belt).to_mm(img)
    residual = np.linalg.norm(mapped - world, axis=1)
    return BeltResult(with_belt, img, world, inliers, float(np.sqrt(np.mean(err**2))), residual, warnings)


def _check_size(calib: Calibration, image: np.ndarray, where: str) -> None:
    h, w = image.shape[:2]
    if (w, h) != calib.size:
        raise BadInput(f"{where}: image is {w}x{h}, calibration {calib.source} is for {calib.image_width}x"
                       f"{calib.image_height}")


def belt_from_board(calib: Calibration, image: np.ndarray, where: str, pattern: Pattern,
                    detector: str = "auto", settings: CalibrateSettings = DEFAULTS) -> BeltResult:
    _check_size(calib, image, where)
    found = find(image, pattern, detector, settings)
    if found is None:
        if not isinstance(pattern, Pattern):
            raise BadInput(f"{where}: no {pattern} board found (at least {settings.charuco_min_corners} "
                           "corners, not all in one line)")
        raise BadInput(f"{where}: no {pattern} board found (COLSxROWS counts inner corners; the whole board "
                       "must be visible)")
    obj = pattern.object_points()
    if getattr(found, "ids", None) is not None:
        obj = obj[found.ids]
    img = found.corners
    k, d = calib.camera_matrix, calib.dist_coeffs
    ok, rvec, tvec = cv2.solvePnP(obj, img, k, d, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise BadInput(f"{where}: cannot solve the board's pose")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, k, d, rvec, tvec)
    warnings = []
    if pattern.symmetric:
        warnings.append(
            f"the {pattern} board looks the same turned by 180 deg (cols + rows even): the origin may be at "
            "either end; use a board with odd x even inner corners (e.g. 9x6)"
        )
    hull = cv2.convexHull(img.astype(np.float32))
    area = cv2.contourArea(hull) / (calib.image_width * calib.image_height)
    if area < settings.min_belt_board_area:
        warnings.append(
            f"the board covers {100 * area:.0f} % of the image (< {100 * settings.min_belt_board_area:.0f} %): "
            "the belt pose is extrapolated far from it; use a larger board"
        )
    return _finish(calib, rvec, tvec, img, obj[:, :2], np.ones(len(img), dtype=bool), warnings)


def read_pairs(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(Nx2 px, Nx2 mm) from a CSV of u, v, X, Y lines; a header line and '#' comments are allowed."""
    path = Path(path)
    if not path.is_file():
        raise BadInput(f"{path}: points file not found")
    px, mm = [], []
    with open(path, newline="") as f:
        for lineno, row in enumerate(csv.reader(f), start=1):
            cells = [c.strip() for c in row]
            if not cells or not any(cells) or cells[0].startswith("#"):
                continue
            try:
                values = [float(c) for c in cells]
            except ValueError:
                if not px and lineno == 1:
                    continue  # a header line
                raise BadInput(f"{path}:{lineno}: expected 4 numbers u, v, X, Y, got {','.join(row)!r}") from None
            if len(values) != 4 or not np.all(np.isfinite(values)):
                raise BadInput(f"{path}:{lineno}: expected 4 finite numbers u, v, X, Y, got {','.join(row)!r}")
            px.append(values[:2])
            mm.append(values[2:])
    if len(px) < 4:
        raise BadInput(f"{path}: expected at least 4 point pairs u, v, X, Y, got {len(px)}")
    return np.array(px, dtype=np.float64), np.array(mm, dtype=np.float64)


def belt_from_points(calib: Calibration, px: np.ndarray, mm: np.ndarray, where: str,
                     settings: CalibrateSettings = DEFAULTS) -> BeltResult:
    obj = np.column_stack([mm, np.zeros(len(mm))])
    k, d = calib.camera_matrix, calib.dist_coeffs
    inliers = np.ones(len(px), dtype=bool)
    if len(px) >= 5:
        ok, rvec, tvec, idx = cv2.solvePnPRansac(obj, px, k, d, reprojectionError=settings.ransac_px)
        if ok and idx is not None and len(idx) >= 4:
            inliers = np.zeros(len(px), dtype=bool)
            inliers[idx.reshape(-1)] = True
    else:
        ok, rvec, tvec = cv2.solvePnP(obj, px, k, d, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise BadInput(f"{where}: cannot solve the belt pose from the point pairs (are they collinear?)")
    rvec, tvec = cv2.solvePnPRefineLM(obj[inliers], px[inliers], k, d, rvec, tvec)
    result = _finish(calib, rvec, tvec, px, mm, inliers, [])
    if result.residual_rms_mm > settings.max_points_residual_mm:
        raise BadInput(
            f"{where}: point pairs disagree with one plane pose by {result.residual_rms_mm:.2f} mm RMS "
            f"(expected <= {settings.max_points_residual_mm} mm): check the pairs; nothing written"
        )
    if not inliers.all():
        result.warnings.append(f"{int((~inliers).sum())} pair(s) left out as outliers (> {settings.ransac_px} px)")
    return result


def draw_preview(image: np.ndarray, result: BeltResult, axis_mm: float) -> np.ndarray:
    """Colour image with the points used, the world origin and the X (red) / Y (green) axes."""
    calib = result.calibration
    out = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    for (u, v), good in zip(result.image_points, result.inliers, strict=True):
        cv2.circle(out, (round(u), round(v)), 3, (0, 200, 255) if good else (0, 0, 255), 1, cv2.LINE_AA)
    pts = np.array([[0, 0, 0], [axis_mm, 0, 0], [0, axis_mm, 0]], dtype=np.float64)
    proj, _ = cv2.projectPoints(pts, calib.belt_rvec, calib.belt_tvec, calib.camera_matrix, calib.dist_coeffs)
    o, x, y = (tuple(int(round(c)) for c in p) for p in proj.reshape(-1, 2))
    cv2.arrowedLine(out, o, x, (0, 0, 255), 2, cv2.LINE_AA, tipLength=0.1)
    cv2.arrowedLine(out, o, y, (0, 255, 0), 2, cv2.LINE_AA, tipLength=0.1)
    cv2.circle(out, o, 5, (255, 0, 0), -1, cv2.LINE_AA)
    cv2.putText(out, "X", x, cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 0, 255), 2, cv2.LINE_AA)
    cv2.putText(out, "Y", y, cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 255, 0), 2, cv2.LINE_AA)
    cv2.putText(out, "origin", (o[0] + 6, o[1] - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 0, 0), 1, cv2.LINE_AA)
    return out
