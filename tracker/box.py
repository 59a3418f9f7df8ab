"""The outline a box (a right prism) standing on the belt casts into the camera.

A part is modelled as its footprint rectangle (x, y, angle, length, width) on the belt and a
height h: its top face is the same rectangle h mm above the belt. Seen through a pinhole, the
silhouette of that convex solid is the convex hull of its 8 corners' images: top-face edges
where they bound it, bottom and vertical edges elsewhere. Coordinates here are undistorted,
normalised image coordinates (x/z, y/z in the camera frame), where straight edges stay straight.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.calibration import Calibration
from tracker.geometry import rectangle_corners


class BoxCamera:
    """Projects belt-frame points (mm; Z into the belt, so a top face h high is at Z = -h)."""

    def __init__(self, calibration: Calibration) -> None:
        self.rotation = calibration.rotation()
        self.translation = np.asarray(calibration.belt_tvec, dtype=np.float64).reshape(3)

    def project(self, world: np.ndarray) -> np.ndarray:
        cam = world @ self.rotation.T + self.translation
        return cam[:, :2] / cam[:, 2:3]

    def corners(self, params: np.ndarray, height_mm: float) -> np.ndarray:
        """The 8 corners' normalised images: footprint first, then the top face."""
        x, y, angle, length, width = params
        foot = rectangle_corners(x, y, angle, length, width)
        world = np.zeros((8, 3))
        world[:4, :2] = foot
        world[4:, :2] = foot
        world[4:, 2] = -height_mm
        return self.project(world)

    def outline(self, params: np.ndarray, height_mm: float) -> np.ndarray:
        """The silhouette polygon (Kx2, normalised coordinates)."""
        pts = self.corners(params, height_mm)
        if height_mm == 0:
            return pts[:4]
        # The hull's vertices chosen in float32 (all OpenCV takes), their coordinates kept in float64.
        index = cv2.convexHull(pts.astype(np.float32).reshape(-1, 1, 2), returnPoints=False)
        return pts[index.reshape(-1)]


def distances_to_outline(points: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """Signed distance of each point to the nearest edge of a convex polygon (outside positive),
    so that a least-squares fit sees on which side of the outline each point lies: shape (N,)."""
    a = outline
    b = np.roll(outline, -1, axis=0)
    ab = b - a  # (K, 2)
    ap = points[:, None, :] - a[None, :, :]  # (N, K, 2)
    t = np.clip((ap * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-30), 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    dist = np.sqrt(((points[:, None, :] - nearest) ** 2).sum(-1))
    k = dist.argmin(axis=1)
    rows = np.arange(len(points))
    cross = ab[k, 0] * ap[rows, k, 1] - ab[k, 1] * ap[rows, k, 0]
    # The polygon's orientation decides which side of an edge is outside.
    area2 = float(np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]))
    sign = np.where(cross * area2 > 0, -1.0, 1.0)
    return sign * dist[rows, k]
