"""Human-readable and JSON reports of the calibration commands."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tracker.atomic import atomic_path
from tracker.calibrate.belt import BeltResult
from tracker.calibrate.intrinsics import IntrinsicsResult
from tracker.calibration import Calibration
from tracker.errors import TrackerError


def intrinsics_text(r: IntrinsicsResult, max_rms_px: float) -> list[str]:
    w, h = r.image_size
    what = f"{r.pattern}" if str(r.pattern).startswith("charuco:") else f"{r.pattern} inner corners"
    lines = [f"board {what}, {r.pattern.square_mm:g} mm squares; images {w}x{h}", ""]
    lines.append(f"{'view':<32} {'corners':>8} {'rms px':>8} {'tilt deg':>9}  note")
    for v in r.views:
        name = os.path.basename(v.path)
        if v.corners is None:
            lines.append(f"{name:<32} {0:>8} {'-':>8} {'-':>9}  no board found: skipped")
            continue
        note = f"REJECTED: {v.rejected}" if v.rejected else ""
        lines.append(f"{name:<32} {len(v.corners):>8} {v.rms_px:>8.3f} {v.tilt_deg:>9.1f}  {note}".rstrip())
    a = r.all_views
    lines.append("")
    lines.append(f"all {len(a.view_indices)} views: RMS {a.rms_px:.4f} px, " + _k_text(a.camera_matrix))
    if r.without_outliers is not None:
        b = r.without_outliers
        lines.append(f"without outliers ({len(b.view_indices)} views): RMS {b.rms_px:.4f} px, "
                     + _k_text(b.camera_matrix))
    f = r.final
    lines.append("distortion (k1 k2 p1 p2 k3): " + " ".join(f"{c:.5g}" for c in f.dist_coeffs.reshape(-1)))
    lines.append("")
    lines.append(f"coverage of the image by corners ({r.coverage_counts.shape[0]}x{r.coverage_counts.shape[1]} grid, "
                 "corner counts):")
    for row in r.coverage_counts:
        lines.append("    " + " ".join(f"{c:5d}" for c in row))
    t = np.array(f.tilts_deg)
    lines.append(f"tilt of the views: min {t.min():.1f}, median {np.median(t):.1f}, max {t.max():.1f} deg")
    for warning in r.warnings:
        lines.append(f"WARNING: {warning}")
    lines.append(verdict(r, max_rms_px))
    return lines


def verdict(r: IntrinsicsResult, max_rms_px: float) -> str:
    f = r.final
    if f.rms_px > max_rms_px:
        return f"verdict: BAD: RMS {f.rms_px:.3f} px > {max_rms_px} px (--max-rms)"
    if r.warnings:
        n = len(f.view_indices)
        return f"verdict: USABLE with {len(r.warnings)} warning(s): RMS {f.rms_px:.3f} px over {n} views"
    return f"verdict: GOOD: RMS {f.rms_px:.3f} px over {len(f.view_indices)} views, image covered, views tilted"


def intrinsics_json(r: IntrinsicsResult, max_rms_px: float) -> dict:
    return {
        "pattern": str(r.pattern),
        "square_mm": r.pattern.square_mm,
        "image_size": list(r.image_size),
        "views": [
            {"file": v.path, "corners": 0 if v.corners is None else len(v.corners), "method": v.method,
             "rms_px": v.rms_px, "tilt_deg": v.tilt_deg, "rejected": v.rejected}
            for v in r.views
        ],
        "all_views": r.all_views.to_dict(),
        "without_outliers": r.without_outliers.to_dict() if r.without_outliers else None,
        "written": "without_outliers" if r.without_outliers else "all_views",
        "coverage_counts": r.coverage_counts.tolist(),
        "borders_missed": r.borders_missed,
        "warnings": r.warnings,
        "verdict": verdict(r, max_rms_px),
    }


def _k_text(k: np.ndarray) -> str:
    return f"fx {k[0, 0]:.2f} fy {k[1, 1]:.2f} cx {k[0, 2]:.2f} cy {k[1, 2]:.2f} px"


def belt_text(r: BeltResult, names: list[str] | None = None) -> list[str]:
    c = r.calibration
    lines = [
        f"camera height above the belt: {c.camera_height_mm():.1f} mm",
        f"tilt from vertical: {c.tilt_deg():.2f} deg",
        f"scale at the image centre: {c.mm_per_px_at_centre():.4f} mm/px",
        f"reprojection error: {r.reprojection_rms_px:.3f} px RMS",
        f"residual on the belt: {r.residual_rms_mm:.3f} mm RMS, max {r.residual_mm[r.inliers].max():.3f} mm",
        "world frame: origin at the first inner corner, X along the first row, Y along the first column, "
        "Z into the belt",
    ]
    if names is not None:
        lines.append(f"{'pair':<8} {'u':>9} {'v':>9} {'X mm':>10} {'Y mm':>10} {'residual mm':>12}")
        for name, (u, v), (x, y), e, ok in zip(names, r.image_points, r.world_mm, r.residual_mm, r.inliers,
                                               strict=True):
            lines.append(f"{name:<8} {u:>9.2f} {v:>9.2f} {x:>10.2f} {y:>10.2f} {e:>12.3f}"
                         + ("" if ok else "  outlier"))
    for w in r.warnings:
        lines.append(f"WARNING: {w}")
    return lines


def show_text(c: Calibration) -> list[str]:
    k = c.camera_matrix
    lines = [
        f"{c.source}: {c.image_width}x{c.image_height}",
        f"fx {k[0, 0]:.3f}  fy {k[1, 1]:.3f}  cx {k[0, 2]:.3f}  cy {k[1, 2]:.3f} px",
        "distortion: " + " ".join(f"{v:.6g}" for v in c.dist_coeffs.reshape(-1)),
        "intrinsic RMS: " + ("-" if c.rms_reprojection_error_px is None else f"{c.rms_reprojection_error_px:.4f} px"),
    ]
    if c.approximate:
        lines.insert(1, f"APPROXIMATE: {c.approximate}")
    if c.has_belt:
        lines += [
            f"camera height above the belt: {c.camera_height_mm():.1f} mm",
            f"tilt from vertical: {c.tilt_deg():.2f} deg",
            f"scale at the image centre: {c.mm_per_px_at_centre():.4f} mm/px",
        ]
    else:
        lines.append("belt pose: none (run 'tracker calibrate belt')")
    return lines


def write_atomic(path: Path, data: bytes) -> None:
    """``data`` as ``path``, whole or not at all; a failure (a full disk) is one line, exit 1."""
    try:
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)
    except OSError as exc:
        raise TrackerError(f"{path}: cannot write: {exc.strerror}") from None
