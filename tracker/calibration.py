"""The calibration file of contract section 1: load, validate, save atomically.

The file is OpenCV FileStorage (YAML or XML by extension) so that any OpenCV
program can read it. Everything the loader rejects is reported as one line
naming the file and the node.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from tracker.atomic import atomic_path
from tracker.errors import CalibrationError, FrameSizeError

DIST_LENGTHS = (4, 5, 8, 12, 14)
SUFFIXES = (".yaml", ".yml", ".xml")
# A stored homography may be rounded; this is how far (mm, at the image's
# corners and centre) it may disagree with the one derived from the belt pose.
HOMOGRAPHY_TOLERANCE_MM = 0.05
HOMOGRAPHY_TOLERANCE_REL = 1e-5


def homography_from_pose(
    camera_matrix: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, height_mm: float = 0.0
) -> np.ndarray:
    """Undistorted pixel -> world (X, Y) mm on the plane ``height_mm`` above the belt.

    World Z points into the belt (contract section 1), so that plane is ``Z = -height_mm``:
    ``K [r1 r2 (t - h r3)]`` maps (X, Y, 1) on it to pixels; its inverse is the homography.
    """
    rot, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    t = np.asarray(tvec, dtype=np.float64).reshape(3) - height_mm * rot[:, 2]
    forward = camera_matrix @ np.column_stack([rot[:, 0], rot[:, 1], t])
    inverse = np.linalg.inv(forward)
    return inverse / inverse[2, 2]


def apply_homography(h: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map Nx2 points through a 3x3 homography."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    mapped = pts @ h[:, :2].T + h[:, 2]
    return mapped[:, :2] / mapped[:, 2:3]


@dataclass(frozen=True)
class Calibration:
    """Camera intrinsics plus (optionally) the belt pose. Validated on construction."""

    image_width: int
    image_height: int
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    rms_reprojection_error_px: float | None = None
    belt_rvec: np.ndarray | None = None
    belt_tvec: np.ndarray | None = None
    belt_homography: np.ndarray | None = None
    source: str = field(default="<memory>", compare=False)
    # Non-empty for a calibration made without a board (from a scale alone): what it assumes.
    approximate: str = ""

    def __post_init__(self) -> None:
        where = self.source
        if self.image_width <= 0 or self.image_height <= 0:
            raise CalibrationError(
                f"{where}: image_width/image_height: expected positive integers, "
                f"got {self.image_width}x{self.image_height}"
            )
        _check_matrix(where, "camera_matrix", self.camera_matrix, (3, 3))
        k = self.camera_matrix
        if k[0, 0] <= 0 or k[1, 1] <= 0 or k[2, 2] != 1 or k[1, 0] or k[2, 0] or k[2, 1]:
            raise CalibrationError(
                f"{where}: camera_matrix: expected [[fx,s,cx],[0,fy,cy],[0,0,1]] with fx, fy > 0, "
                f"got {k.tolist()}"
            )
        d = np.asarray(self.dist_coeffs, dtype=np.float64).reshape(1, -1)
        object.__setattr__(self, "dist_coeffs", d)
        if d.shape[1] not in DIST_LENGTHS:
            raise CalibrationError(
                f"{where}: dist_coeffs: expected 1xN with N in {DIST_LENGTHS}, got {d.shape[1]} values"
            )
        _check_finite(where, "dist_coeffs", d)
        if self.rms_reprojection_error_px is not None and not (
            math.isfinite(self.rms_reprojection_error_px) and self.rms_reprojection_error_px >= 0
        ):
            raise CalibrationError(
                f"{where}: rms_reprojection_error_px: expected a finite number >= 0, "
                f"got {self.rms_reprojection_error_px}"
            )
        belt = (self.belt_rvec, self.belt_tvec, self.belt_homography)
        if all(b is None for b in belt):
            return
        for name, value, shape in zip(
            ("belt_rvec", "belt_tvec", "belt_homography"), belt, ((3, 1), (3, 1), (3, 3)), strict=True
        ):
            if value is None:
                raise CalibrationError(f"{where}: {name}: missing (the belt pose needs all three nodes)")
            _check_matrix(where, name, value, shape)
        self._check_homography()
        self._check_camera_side()

    def _check_camera_side(self) -> None:
        """The belt must lie in front of the camera, and the camera on the belt's side that World Z
        points away from (Z points into the belt: a part's top is at Z = -h)."""
        rot, _ = cv2.Rodrigues(np.asarray(self.belt_rvec, dtype=np.float64).reshape(3, 1))
        t = np.asarray(self.belt_tvec, dtype=np.float64).reshape(3)
        centre_world = -rot.T @ t
        k = self.camera_matrix
        seen = apply_homography(homography_from_pose(k, self.belt_rvec, self.belt_tvec), [[k[0, 2], k[1, 2]]])[0]
        depth = float((rot @ np.array([seen[0], seen[1], 0.0]) + t)[2])
        if not depth > 0:
            raise CalibrationError(f"{self.source}: belt_rvec/belt_tvec: the belt lies behind the camera "
                                   f"(depth {depth:.1f} mm at the image centre); expected it in front")
        if not centre_world[2] < 0:
            raise CalibrationError(f"{self.source}: belt_rvec/belt_tvec: the camera is on the far side of the "
                                   f"belt (world Z {centre_world[2]:.1f} mm; Z points into the belt, so the camera "
                                   "must be at Z < 0): the board's frame is mirrored")

    def _check_homography(self) -> None:
        expected = homography_from_pose(self.camera_matrix, self.belt_rvec, self.belt_tvec)
        h = self.belt_homography
        if abs(h[2, 2]) < 1e-12:
            raise CalibrationError(f"{self.source}: belt_homography: H[2,2] is 0, expected 1")
        h = h / h[2, 2]
        w, hh = self.image_width, self.image_height
        probe = np.array([[0, 0], [w, 0], [w, hh], [0, hh], [w / 2, hh / 2]], dtype=np.float64)
        got, want = apply_homography(h, probe), apply_homography(expected, probe)
        err = np.linalg.norm(got - want, axis=1)
        allowed = HOMOGRAPHY_TOLERANCE_MM + HOMOGRAPHY_TOLERANCE_REL * np.linalg.norm(want, axis=1)
        if not np.all(np.isfinite(err)) or np.any(err > allowed):
            raise CalibrationError(
                f"{self.source}: belt_homography: disagrees with belt_rvec/belt_tvec by up to "
                f"{np.nanmax(err):.3f} mm over the image (expected <= {HOMOGRAPHY_TOLERANCE_MM} mm)"
            )

    # --- derived quantities -------------------------------------------------------------
    @property
    def size(self) -> tuple[int, int]:
        return self.image_width, self.image_height

    @property
    def has_belt(self) -> bool:
        return self.belt_homography is not None

    def require_belt(self) -> None:
        if not self.has_belt:
            raise CalibrationError(
                f"{self.source}: belt_rvec: missing (run 'tracker calibrate belt' first)"
            )

    def homography_at_height(self, height_mm: float) -> np.ndarray:
        """Undistorted pixel -> world mm on the plane ``height_mm`` above the belt."""
        self.require_belt()
        if height_mm == 0:
            return self.belt_homography / self.belt_homography[2, 2]
        return homography_from_pose(self.camera_matrix, self.belt_rvec, self.belt_tvec, height_mm)

    def rotation(self) -> np.ndarray:
        self.require_belt()
        rot, _ = cv2.Rodrigues(self.belt_rvec)
        return rot

    def camera_height_mm(self) -> float:
        """Distance of the camera centre from the belt plane."""
        centre = -self.rotation().T @ self.belt_tvec.reshape(3)
        return float(abs(centre[2]))

    def tilt_deg(self) -> float:
        """Angle between the optical axis and the belt's normal."""
        axis_world = self.rotation().T @ np.array([0.0, 0.0, 1.0])
        return float(math.degrees(math.acos(min(1.0, abs(axis_world[2])))))

    def mm_per_px_at_centre(self) -> float:
        h = self.homography_at_height(0.0)
        c = np.array([self.camera_matrix[0, 2], self.camera_matrix[1, 2]])
        pts = apply_homography(h, np.array([c, c + [1, 0], c + [0, 1]]))
        return float((np.linalg.norm(pts[1] - pts[0]) + np.linalg.norm(pts[2] - pts[0])) / 2)

    def check_frame_size(self, width: int, height: int, where: str) -> None:
        if (width, height) != (self.image_width, self.image_height):
            raise FrameSizeError(
                f"{where}: frame is {width}x{height}, calibration {self.source} is for "
                f"{self.image_width}x{self.image_height}"
            )

    def with_belt(self, rvec: np.ndarray, tvec: np.ndarray) -> Calibration:
        rvec = np.asarray(rvec, dtype=np.float64).reshape(3, 1)
        tvec = np.asarray(tvec, dtype=np.float64).reshape(3, 1)
        return Calibration(
            self.image_width, self.image_height, self.camera_matrix, self.dist_coeffs,
            self.rms_reprojection_error_px, rvec, tvec,
            homography_from_pose(self.camera_matrix, rvec, tvec), self.source,
        )


def _check_matrix(where: str, name: str, value: object, shape: tuple[int, int]) -> None:
    arr = np.asarray(value) if value is not None else None
    if arr is None or arr.shape != shape:
        got = "nothing" if arr is None else "x".join(map(str, arr.shape))
        raise CalibrationError(f"{where}: {name}: expected a {shape[0]}x{shape[1]} matrix, got {got}")
    _check_finite(where, name, arr)


def _check_finite(where: str, name: str, arr: np.ndarray) -> None:
    if not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{where}: {name}: contains non-finite values (NaN or Inf)")


# --- file I/O ---------------------------------------------------------------------------


def _check_suffix(path: Path) -> None:
    if path.suffix.lower() not in SUFFIXES:
        raise CalibrationError(
            f"{path}: unsupported extension {path.suffix!r}, expected one of {', '.join(SUFFIXES)}"
        )


def load(path: str | os.PathLike, require_belt: bool = True) -> Calibration:
    """Read and validate a calibration file; raise CalibrationError naming file and node."""
    path = Path(path)
    _check_suffix(path)
    if path.is_dir():
        raise CalibrationError(f"{path}: is a folder; expected a calibration file")
    if not path.is_file():
        raise CalibrationError(f"{path}: calibration file not found")
    if not os.access(path, os.R_OK):
        raise CalibrationError(f"{path}: cannot read the calibration file: permission denied")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:
        # OpenCV's parser reports a syntax error as cv2.error (wrapped in SystemError by some builds).
        cause = exc.__cause__ or exc
        first = str(cause).strip().splitlines()[-1] if str(cause).strip() else "parse error"
        raise CalibrationError(f"{path}: not a readable OpenCV FileStorage file ({first})") from None
    if not fs.isOpened():
        raise CalibrationError(f"{path}: not a readable OpenCV FileStorage file")
    try:
        where = str(path)

        def node(name: str, optional: bool = False):
            n = fs.getNode(name)
            if n.empty() or n.isNone():
                if optional:
                    return None
                raise CalibrationError(f"{where}: {name}: missing")
            return n

        def integer(name: str) -> int:
            n = node(name)
            if not n.isInt():
                raise CalibrationError(f"{where}: {name}: expected an integer")
            return int(n.real())

        def matrix(name: str, optional: bool = False) -> np.ndarray | None:
            n = node(name, optional)
            if n is None:
                return None
            m = n.mat() if n.isMap() else None
            if m is None:
                raise CalibrationError(f"{where}: {name}: expected a matrix")
            return np.asarray(m, dtype=np.float64)

        width, height = integer("image_width"), integer("image_height")
        k = matrix("camera_matrix")
        d = matrix("dist_coeffs")
        if d.ndim != 2 or 1 not in d.shape:
            raise CalibrationError(
                f"{where}: dist_coeffs: expected a 1xN matrix, got {'x'.join(map(str, d.shape))}"
            )
        rms_node = node("rms_reprojection_error_px", optional=True)
        rms = None
        if rms_node is not None:
            if not rms_node.isReal() and not rms_node.isInt():
                raise CalibrationError(f"{where}: rms_reprojection_error_px: expected a number")
            rms = float(rms_node.real())
        rvec, tvec, hom = (matrix(n, optional=True) for n in ("belt_rvec", "belt_tvec", "belt_homography"))
        note = ""
        if node("approximate", optional=True) is not None:
            note_node = node("approximate_note", optional=True)
            note = (note_node.string() if note_node is not None and note_node.isString() else "") or "approximate"
    finally:
        fs.release()
    calib = Calibration(width, height, k, d, rms, rvec, tvec, hom, source=where, approximate=note)
    if require_belt:
        calib.require_belt()
    return calib


def save(calib: Calibration, path: str | os.PathLike) -> None:
    """Write atomically: a temp file in the same folder, fsync, then rename over ``path``."""
    path = Path(path)
    _check_suffix(path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise CalibrationError(f"{path}: folder {directory} does not exist")
    try:
        with atomic_path(path) as tmp:
            fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
            if not fs.isOpened():
                raise CalibrationError(f"{path}: cannot write calibration")
            fs.write("image_width", int(calib.image_width))
            fs.write("image_height", int(calib.image_height))
            fs.write("camera_matrix", calib.camera_matrix)
            fs.write("dist_coeffs", calib.dist_coeffs.reshape(1, -1))
            if calib.rms_reprojection_error_px is not None:
                fs.write("rms_reprojection_error_px", float(calib.rms_reprojection_error_px))
            if calib.approximate:
                # Extra nodes: any OpenCV reader ignores them; ours says the file is approximate.
                fs.write("approximate", 1)
                fs.write("approximate_note", calib.approximate)
            if calib.has_belt:
                fs.write("belt_rvec", calib.belt_rvec.reshape(3, 1))
                fs.write("belt_tvec", calib.belt_tvec.reshape(3, 1))
                fs.write("belt_homography", calib.belt_homography)
            fs.release()
    except OSError as exc:
        raise CalibrationError(f"{path}: cannot write calibration: {exc.strerror}") from None
