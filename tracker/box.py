"""What a box (a right prism) standing on the belt shows the camera, face by face.

A part is modelled as its footprint rectangle (x, y, angle, length, width) on the belt and a
height h: its top face is the same rectangle h mm above the belt. Seen through a pinhole, the
box shows its top face and the one or two side faces that face the camera; together they make
its silhouette. Coordinates here are undistorted, normalised image coordinates (x/z, y/z in the
camera frame), where straight edges stay straight.

Edges are measured as coverage sums across short windows of pixels (tracker/measure.py), each
read against the level of one pixel just inside the edge. Each face adds its own level (a side
face's is a fixed fraction of the top's: its shade) times its length in the window, so a window
that holds a side face narrower than itself and then the top (a thin part's sliver, a bias of
up to half a pixel when ignored) sums to more or less than the distance to its edge. The model
below predicts each sum for a box pose, faces and shades included. As a sum stops changing once
its edge has left the window, the fit first brings the box near with the plain outline (the
hull of the 8 corners, against the edge points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from tracker.calibration import Calibration
from tracker.geometry import Rect, rectangle_corners
from tracker.shadebounds import BRIGHT, ShadeBounds

# Face kinds: the top, the sides facing the part's own x (its ends) and those facing its y.
TOP, SIDE_X, SIDE_Y = 0, 1, 2


@dataclass(frozen=True)
class EdgeWindows:
    """Coverage sums across a silhouette's edge, one per image row or column that crosses it.

    Each window is a straight run of ``span_px`` pixels from ``inner_norm`` (its end inside the
    part) outwards, ``step_norm`` per pixel (normalised coordinates, the lens's distortion taken
    as linear over a few pixels); ``covered_px`` is how many pixels of it the part covers, in
    units of the contrast of the pixel that spans ``level_px`` (from, to: px from the inner end).
    ``blur_px``: the image's blur (a Gaussian's sigma, px) that spreads each face's level into the
    pixels next to it: the level pixel of a window across a thin side face is a blurred mix.
    ``shade_bounds``: the shades the part's side faces may have (a part darker than the belt has
    others than a brighter one: tracker/shadebounds.py).
    """

    inner_norm: np.ndarray  # (N, 2)
    step_norm: np.ndarray  # (N, 2)
    covered_px: np.ndarray  # (N,)
    span_px: float
    level_px: tuple[float, float]
    blur_px: float = 0.0
    shade_bounds: ShadeBounds = BRIGHT

    def __post_init__(self) -> None:
        n = len(self.covered_px)
        if self.inner_norm.shape != (n, 2) or self.step_norm.shape != (n, 2):
            raise ValueError(f"edge windows: expected (N, 2) ends and steps for N={n} sums, got "
                             f"{self.inner_norm.shape} and {self.step_norm.shape}")

    def __len__(self) -> int:
        return len(self.covered_px)

    def subset(self, which: np.ndarray) -> EdgeWindows:
        return replace(self, inner_norm=self.inner_norm[which], step_norm=self.step_norm[which],
                       covered_px=self.covered_px[which])


class BoxCamera:
    """Projects belt-frame points (mm; Z into the belt, so a top face h high is at Z = -h)."""

    def __init__(self, calibration: Calibration) -> None:
        self.rotation = np.ascontiguousarray(calibration.rotation(), dtype=np.float64)
        self.translation = np.ascontiguousarray(calibration.belt_tvec, dtype=np.float64).reshape(3)
        # The camera's centre (belt frame, mm; Z into the belt, so it is < 0), and its foot on the belt: a
        # side face is seen from the side of its plane the foot is on.
        self.centre_mm = -self.rotation.T @ self.translation
        self.nadir_mm = self.centre_mm[:2]

    def project(self, world: np.ndarray) -> np.ndarray:
        cam = world @ self.rotation.T + self.translation
        return cam[:, :2] / cam[:, 2:3]

    def corners(self, params: np.ndarray, height_mm: float) -> np.ndarray:
        """The 8 corners' normalised images: footprint first (counter-clockwise), then the top face."""
        return self._corner_images(np.array([[*params[:5], height_mm]]))[0]

    def _corner_images(self, params: np.ndarray) -> np.ndarray:
        """The 8 corners' images of each box (P rows of x, y, angle, length, width, height): (P, 8, 2)."""
        from tracker.facecover import corner_images  # noqa: PLC0415 (compiled: see lengths_in_faces)

        out = np.empty((len(params), 8, 2))
        corner_images(np.ascontiguousarray(params, dtype=np.float64), self.rotation, self.translation, out)
        return out

    def outlines(self, params: np.ndarray) -> list[np.ndarray]:
        """The silhouette polygon of each box (P rows of x, y, angle, length, width, height)."""
        pts = self._corner_images(params)
        # The hull's vertices chosen in float32 (all OpenCV takes), their coordinates kept in float64.
        return [p[:4] if h == 0 else p[cv2.convexHull(p.astype(np.float32), returnPoints=False).reshape(-1)]
                for p, h in zip(pts, params[:, 5], strict=True)]

    def faces(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The faces the camera sees of each box (P rows of x, y, angle, length, width, height): their
        polygons (P, F, 4, 2) in normalised coordinates and kinds (F,). Which faces are seen is decided
        on the first box (the others are its small variations: a Jacobian's)."""
        from tracker.facecover import box_faces  # noqa: PLC0415 (compiled: see lengths_in_faces)

        params = np.ascontiguousarray(np.atleast_2d(params), dtype=np.float64)
        return box_faces(params, self.rotation, self.translation, self.nadir_mm)

    def facing_deg(self, params: np.ndarray) -> tuple[float, float]:
        """Which of a box's side faces (x, y, angle, length, width, ...) face the camera: the directions
        (belt frame, deg) of the outward normals of the end face and of the long face on the side of the
        camera's foot, those it sees where it sees any. Under a lamp to one side a face and the one
        opposite it differ in shade."""
        x, y, angle = params[:3]
        a = math.radians(angle)
        towards = self.nadir_mm - np.array([x, y])
        along = towards @ np.array([math.cos(a), math.sin(a)])
        across = towards @ np.array([-math.sin(a), math.cos(a)])
        return (float(angle) + (0.0 if along >= 0 else 180.0), float(angle) + (90.0 if across >= 0 else -90.0))

    def silhouette_growth(self, rect: Rect) -> tuple[float, float]:
        """How much the silhouette of a box whose footprint is ``rect`` (belt frame, mm), cast on the
        belt from the camera's centre, outgrows the footprint along its length and its width per mm of
        the box's height (to first order): what a box's sides add to it measured as flat, where the
        camera sees them fully (sides read dimmer than its top add less)."""
        foot = rectangle_corners(rect.x_mm, rect.y_mm, rect.angle_deg, rect.length_mm, rect.width_mm)
        centre = self.centre_mm
        # The top's corners 1 mm up (Z = -1), along the rays from the centre down to the belt.
        cast = centre[:2] + (foot - centre[:2]) * (centre[2] / (centre[2] + 1.0))
        outline = np.vstack([foot, cast])
        a = np.radians(rect.angle_deg)
        along, across = outline @ np.array([np.cos(a), np.sin(a)]), outline @ np.array([-np.sin(a), np.cos(a)])
        return (float(np.ptp(along)) - rect.length_mm, float(np.ptp(across)) - rect.width_mm)


def distances_to_outline(points: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """Signed distance of each point to the nearest edge of a convex polygon (outside positive),
    so that a least-squares fit sees on which side of the outline each point lies: shape (N,)."""
    from tracker.facecover import outline_distances  # noqa: PLC0415 (compiled: see lengths_in_faces)

    out = np.empty(len(points))
    outline_distances(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(outline, dtype=np.float64),
                      out)
    return out


def lengths_in_faces(windows: EdgeWindows, polygons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of each window inside each face, for each box's polygons (P, F, 4, 2): over the whole
    window, and the share of its level pixel (``level_px``), each (P, N, F). A window's line is
    clipped to each convex polygon (Cyrus-Beck); its level pixel, a square, is clipped to it
    (Sutherland-Hodgman) for the share of its area: a sum is read against that pixel's value, so an
    error in its share is an error of the whole sum. In a blurred image (``blur_px``) both are what
    the blur makes of them along the window's line (the level pixel's share read on two lines across
    it: Gauss's points)."""
    # Compiled on first use (numba): flat parts never load it, and a run with boxes compiles it at start.
    from tracker.facecover import clip  # noqa: PLC0415

    n_box, n_face = polygons.shape[:2]
    total = np.zeros((n_box, len(windows), n_face))
    level = np.zeros_like(total)
    clip(np.ascontiguousarray(polygons, dtype=np.float64), np.ascontiguousarray(windows.inner_norm),
         np.ascontiguousarray(windows.step_norm), float(windows.span_px), *map(float, windows.level_px),
         float(windows.blur_px), total, level)
    return total, level


def compile_model() -> None:
    """Compile the face model now (about 1.5 s the first time, a cached load after): a run with boxes
    calls this before its first frame, so the loop never waits on the compiler."""
    windows = EdgeWindows(np.zeros((1, 2)), np.array([[1.0, 0.0]]), np.zeros(1), 6.0, (1.0, 2.0))
    square = np.array([[[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]]])
    lengths_in_faces(windows, square)
    lengths_in_faces(replace(windows, blur_px=1.0), square)  # the blurred path is compiled apart
    distances_to_outline(np.zeros((1, 2)), square[0, 0])
    from tracker.facecover import box_faces, corner_images  # noqa: PLC0415

    box = np.array([[0.0, 0.0, 0.0, 2.0, 1.0, 1.0]])
    box_faces(box, np.eye(3), np.array([0.0, 0.0, 10.0]), np.zeros(2))
    corner_images(box, np.eye(3), np.array([0.0, 0.0, 10.0]), np.empty((1, 8, 2)))  # the outline's, called apart
