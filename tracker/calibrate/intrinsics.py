"""Camera intrinsics from chessboard views, with the figures that say how far to trust them."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from tracker.calibrate.board import Pattern, board_continues, find
from tracker.calibrate.settings import DEFAULTS, CalibrateSettings
from tracker.errors import BadInput


@dataclass
class View:
    path: str
    corners: np.ndarray | None  # Nx2 px, None when the board was not found
    method: str | None
    rms_px: float | None = None  # per-view reprojection RMS in the calibration that used it
    tilt_deg: float | None = None  # angle between the board's normal and the optical axis
    rejected: str | None = None  # why it was left out of the final calibration
    ids: np.ndarray | None = None  # which of the board's corners ``corners`` are (ChArUco); None: all


@dataclass
class Solve:
    rms_px: float
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    view_indices: list[int]
    per_view_rms_px: list[float]
    tilts_deg: list[float]

    def to_dict(self) -> dict:
        return {
            "rms_px": self.rms_px,
            "n_views": len(self.view_indices),
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.reshape(-1).tolist(),
        }


@dataclass
class IntrinsicsResult:
    pattern: Pattern
    image_size: tuple[int, int]
    views: list[View]
    all_views: Solve
    without_outliers: Solve | None
    coverage_counts: np.ndarray  # cells x cells corner counts (rows = image v)
    borders_missed: list[str]
    warnings: list[str] = field(default_factory=list)

    @property
    def final(self) -> Solve:
        return self.without_outliers or self.all_views


def solve(pattern: Pattern, views: list[View], indices: list[int], size: tuple[int, int], flags: int) -> Solve:
    every = pattern.object_points().astype(np.float32)
    objs = [every if views[i].ids is None else every[views[i].ids] for i in indices]
    imgs = [views[i].corners.astype(np.float32).reshape(-1, 1, 2) for i in indices]
    rms, k, d, rvecs, tvecs = cv2.calibrateCamera(objs, imgs, size, None, None, flags=flags)
    per_view, tilts = [], []
    for obj, img, rvec, tvec in zip(objs, imgs, rvecs, tvecs, strict=True):
        proj, _ = cv2.projectPoints(obj, rvec, tvec, k, d)
        per_view.append(float(np.sqrt(np.mean(np.sum((proj - img).reshape(-1, 2) ** 2, axis=1)))))
        rot, _ = cv2.Rodrigues(rvec)
        tilts.append(math.degrees(math.acos(min(1.0, abs(rot[2, 2])))))
    return Solve(float(rms), k, d.reshape(1, -1), list(indices), per_view, tilts)


def outliers(s: Solve, settings: CalibrateSettings) -> dict[int, str]:
    """View index -> reason, for views whose error is far above the median."""
    median = float(np.median(s.per_view_rms_px))
    limit = max(settings.outlier_factor * median, median + settings.outlier_min_excess_px)
    return {
        i: f"per-view RMS {e:.3f} px > {limit:.3f} px (median {median:.3f} px)"
        for i, e in zip(s.view_indices, s.per_view_rms_px, strict=True)
        if e > limit
    }


def calibrate_intrinsics(
    paths: list[str],
    images: list[np.ndarray],
    pattern: Pattern,
    min_views: int,
    fix_k3: bool = False,
    detector: str = "auto",
    settings: CalibrateSettings = DEFAULTS,
) -> IntrinsicsResult:
    h, w = images[0].shape[:2]
    size = (w, h)
    views = []
    larger = 0  # views where the board goes on past the pattern
    for path, image in zip(paths, images, strict=True):
        found = find(image, pattern, detector, settings)
        views.append(View(path, found.corners if found else None, found.method if found else None,
                          ids=getattr(found, "ids", None)))
        if found is not None and isinstance(pattern, Pattern) and board_continues(image, found.corners, pattern):
            larger += 1
    usable = [i for i, v in enumerate(views) if v.corners is not None]
    if not usable:
        raise BadInput(
            f"--pattern {pattern}: no board found in any of the {len(paths)} images "
            "(COLSxROWS counts inner corners, e.g. 9x6 for a board of 10x7 squares)"
        )
    if len(usable) < min_views:
        raise BadInput(
            f"only {len(usable)} of {len(paths)} images show the whole {pattern} board, "
            f"expected at least {min_views} (--min-views)"
        )
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    all_views = solve(pattern, views, usable, size, flags)
    _annotate(views, all_views)
    bad = outliers(all_views, settings)
    without = None
    warnings = []
    if bad:
        kept = [i for i in usable if i not in bad]
        if len(kept) >= min_views:
            without = solve(pattern, views, kept, size, flags)
            for i, reason in bad.items():
                views[i].rejected = reason
        else:
            warnings.append(
                f"{len(bad)} outlier view(s) kept: without them fewer than {min_views} views (--min-views) remain"
            )
    # A probe can land on clutter beside a board: only a share of views counts as evidence.
    if larger >= settings.larger_board_share * len(usable):
        warnings.append(
            f"in {larger} view(s) the checker pattern goes on past the {pattern} corners found: the board may "
            "have more inner corners than --pattern says (COLSxROWS counts inner corners)"
        )
    final = without or all_views
    counts, missed = coverage(views, final.view_indices, size, settings)
    if missed:
        warnings.append(
            f"corners never reached the {', '.join(missed)} border(s) of the image: distortion there is "
            "extrapolated; add views with the board near those borders"
        )
    empty = int(np.count_nonzero(counts == 0))
    if empty:
        warnings.append(f"{empty} of {counts.size} image cells have no corner (see the coverage grid)")
    if max(final.tilts_deg) < settings.min_max_tilt_deg:
        warnings.append(
            f"views are barely tilted (max {max(final.tilts_deg):.1f} deg < {settings.min_max_tilt_deg:.0f} deg): "
            "the focal length is poorly determined; add views tilted 20-45 deg"
        )
    return IntrinsicsResult(pattern, size, views, all_views, without, counts, missed, warnings)


def _annotate(views: list[View], s: Solve) -> None:
    for i, e, t in zip(s.view_indices, s.per_view_rms_px, s.tilts_deg, strict=True):
        views[i].rms_px, views[i].tilt_deg = e, t


def coverage(
    views: list[View], indices: list[int], size: tuple[int, int], settings: CalibrateSettings
) -> tuple[np.ndarray, list[str]]:
    """Corner counts on a cells x cells grid over the image, and the borders no corner came near."""
    w, h = size
    n = settings.coverage_cells
    pts = np.concatenate([views[i].corners for i in indices])
    cu = np.clip((pts[:, 0] / w * n).astype(int), 0, n - 1)
    cv = np.clip((pts[:, 1] / h * n).astype(int), 0, n - 1)
    counts = np.zeros((n, n), dtype=int)
    np.add.at(counts, (cv, cu), 1)
    band_u, band_v = settings.border_band * w, settings.border_band * h
    missed = [
        name
        for name, reached in (
            ("left", pts[:, 0].min() <= band_u),
            ("right", pts[:, 0].max() >= w - band_u),
            ("top", pts[:, 1].min() <= band_v),
            ("bottom", pts[:, 1].max() >= h - band_v),
        )
        if not reached
    ]
    return counts, missed
