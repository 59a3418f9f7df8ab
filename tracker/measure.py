"""Measurement: blobs of the foreground mask -> rectangles on the belt, in millimetres.

Edges are located from grey levels: within a blob's neighbourhood each pixel's
value, compared with the belt reference and the part's own level, is the
fraction of the pixel the part covers. Along a row (or column) crossing a
straight edge, the covered fractions add up to exactly where the edge crosses
that row, so each crossing gives one sub-pixel edge point. The points are
undistorted, mapped onto the belt and fitted with a rectangle there, where a
rectangle is still a rectangle.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from tracker.box import BoxCamera, EdgeWindows, compile_model
from tracker.boxfit import (
    CONVERGED_STEPS,
    PRECISE_STEPS,
    BoxFit,
    ShadePrior,
    SizePrior,
    ViewShades,
    comparable_costs_px2,
    comparable_ms_px2,
    fit_box,
    widened,
)
from tracker.calibration import apply_homography
from tracker.config import MeasureConfig
from tracker.geometry import Rect, min_area_rect, rectangle_corners, refine_rect
from tracker.height import HeightTrial, vote_due
from tracker.segment.views import SmoothedView, UpsampledView
from tracker.shadebounds import BRIGHT, ShadeBounds, shade_bounds
from tracker.shades import FaceShades
from tracker.split import SplitRule, deepest_notch_px, split_blob
from tracker.undistort import BeltMapper

# Pixels on each side of a crossing that the coverage sum spans (covers blur up to ~4 px).
HALF_WINDOW_PX = 3
# A row crossing is used where |d/dx| >= this * |d/dy| (edge within ~63 deg of vertical).
_STEEP_RATIO = 0.5
# A view's own shape (Measurer._own_shape): its height and size free, nothing lent, every window within
# the model's errors kept, and what it kept (to compare two such fits over the same windows).
_OWN = {"free_height": True, "keep_model_errors": True, "keep_residuals": True}
# A side face's shade as bright as the top's (a shade is a side's contrast as a fraction of the top's),
# where Measurer._lit_as_top starts a face lit that brightly, held no surer than this (1 sigma): anything
# from the belt's to the top's.
_TOP_SHADE = 1.0
_LIT_SHADE_SIGMA = 1.0
# A gap between a blob and its hull this far (px) inside the hull is a notch (see Measurer._filled).
_NOTCH_DEPTH_PX = 2.0
_ERODE = cv2.getStructuringElement(cv2.MORPH_RECT, (5, 5))
_ZONE = cv2.getStructuringElement(cv2.MORPH_RECT, (7, 7))
# Fewer belt (or part) pixels than this around a blob tell no level.
_MIN_BELT_PX = 16
# Where the reference is unsure (a part lay there at the start), the belt's level is read from the belt
# pixels around within about this many px (a Gaussian's sigma: some fifty pixels, a fifth of a grey
# level of sensor noise), where any lie within ~3 sigmas (the weight they leave there, of one at most).
_UNSURE_SIGMA_PX = 3.0
_UNSURE_MIN_WEIGHT = 0.01
# Fewer sub-pixel edge points than this: the blob is measured from its pixel staircase.
_MIN_EDGE_POINTS = 12
# A view's own fits (from its pose and from the plane's rectangle, Measurer._own_shape) whose mean squares
# lie within this fraction of each other explain it alike (see told_alike).
_ALIKE_MS = 0.1
# A flat outline whose sides read faces this unlike (the dimmest side's contrast over the brightest's),
# each side over at least this many windows, is a box's (see _uneven_faces).
_UNEVEN_RATIO = 0.8
_UNEVEN_MIN_WINDOWS = 5
# Where an outline is drawn from working pixels, a window's boundary pixel whose contrast with the belt is
# less than this fraction of the contrast of the pixel beyond its face pixel lies past the part's edge
# (see _Crossings.inner_contrast).
_PAST_EDGE = 0.25
# A coarse belt reference's plane correction drops belt pixels this many robust sigmas off (_plane_corrected).
_PLANE_TRIM_SIGMAS = 3.0
# ... and is left out where it would move the level by more than this fraction of the part's contrast.
_PLANE_MAX_OF_CONTRAST = 0.25
# Belt pixels (at most, evenly spaced) the plane is fitted to, and the fewest it is fitted to at all.
_PLANE_FIT_PX = 1000
_PLANE_MIN_PX = 12


@dataclass(frozen=True)
class Measurement:
    """One blob measured in one frame."""

    rect: Rect
    # Touches the image border: part of it may be outside, so its geometry is not trusted.
    clipped: bool
    bbox_px: tuple[int, int, int, int]
    # Image pixel of the centroid (for drawing), distorted coordinates.
    centroid_px: tuple[float, float]
    edge_points: int
    # False: touching or lying on another part, or parts that could not be told apart (see split.py).
    pickable: bool = True
    # Cut from a blob of touching parts.
    piece: bool = False
    # A box's fit: how well this view alone decides the size (covariance of length and width, mm^2,
    # see BoxFit); None where the size is as sure as any.
    size_cov_mm2: np.ndarray | None = field(default=None, compare=False)
    # A box fitted with its track's size lent: the (length, width) this view alone tells (see
    # BoxFit.own_size_mm; None: the rectangle's).
    own_size_mm: tuple[float, float] | None = None
    # --part-height auto (tracker/height.py). While its track votes on its height: the view fitted at
    # each height. While it refines it, and in its vote's views: what this view alone tells of (length,
    # width, height) (see boxfit.view_information), and the height of the box it was fitted from (its
    # pose's).
    trials: tuple[HeightTrial, ...] = ()
    shape_info: np.ndarray | None = field(default=None, compare=False)
    shape_vec: np.ndarray | None = field(default=None, compare=False)
    shape_at_mm: float | None = None
    # --part-height auto: the same blob measured as flat (the pose of a part its track finds flat), and for
    # a part found flat how much a box's silhouette there would outgrow its footprint per mm of its height
    # (length, width: BoxCamera.silhouette_growth; whether its track is flat after all, see height.py).
    flat_rect: Rect | None = None
    flat_growth: tuple[float, float] | None = None
    # Where the camera saw it (world frame, mm: the plain outline's centre; None: the rectangle's). The
    # views a height is estimated from are told apart by it; unlike the poses it stays in the world
    # frame when a moving belt's parts are tracked in the belt's own (see moved).
    view_mm: tuple[float, float] | None = None
    # What this view alone tells of its box's side shades (tracker/shades.py): a refined part's pose
    # fit, or the box at the height leading its vote.
    view_shades: ViewShades | None = None

    @property
    def seen_at_mm(self) -> tuple[float, float]:
        return self.view_mm if self.view_mm is not None else (self.rect.x_mm, self.rect.y_mm)

    def moved(self, dx_mm: float, dy_mm: float) -> Measurement:
        """The same view with its poses (the rectangle, the flat one, the trials') moved by (dx, dy): into
        a moving belt's own frame and back."""
        def move(r: Rect) -> Rect:
            return replace(r, x_mm=r.x_mm + dx_mm, y_mm=r.y_mm + dy_mm)

        return replace(self, rect=move(self.rect), flat_rect=None if self.flat_rect is None else move(self.flat_rect),
                       trials=tuple(replace(t, rect=move(t.rect)) for t in self.trials))


class Measurer:
    def __init__(self, mapper: BeltMapper, config: MeasureConfig, smoothing_px: float = 0.0,
                 coarse_reference: bool = False) -> None:
        """``smoothing_px``: the belt model's smoothing (a Gaussian's sigma, px; 0: none), through which the
        edges of parts whose contrast the belt's texture disturbs are read (measure.smooth_texture_ratio).
        ``coarse_reference``: the belt reference is coarse and still learning (the textured model's, at low
        resolution), so near a part it is corrected by a plane fitted to the belt pixels around it; and
        the blob's outline is drawn from the model's working pixels (see _Crossings.inner_contrast)."""
        self.mapper = mapper
        self.config = config
        self._smoothing_px = smoothing_px
        self._coarse_reference = coarse_reference
        self._width, self._height = mapper.calibration.size
        # Conservative pixel-area pre-filter, so tiny specks are never mapped at all.
        self._min_area_px = 0.5 * config.min_area_mm2 / mapper.max_mm_per_px() ** 2
        self._mm_per_px = mapper.calibration.mm_per_px_at_centre()
        self._box_camera = BoxCamera(mapper.calibration)
        # Normalised coordinates -> mm on the plane of a box's top, for each height the vote tries.
        self._plane_homographies: dict[float, np.ndarray] = {}
        # Each height the vote tries stands for those halfway to its neighbours (see _trials).
        self._height_spans_mm = _height_spans(config.height_starts_mm)
        # Parts are boxes with side faces (a height given or estimated), not flat rectangles.
        self._boxes = config.part_height_mm > 0 or config.estimate_height
        self._focal_px = float(mapper.calibration.camera_matrix[0, 0])
        if self._boxes:
            compile_model()
        self._split_rule = SplitRule(config.touch_min_notch_px, self._min_area_px)
        self._known: Sequence[KnownPart] = ()
        self._votes_left = 0
        self._shadows: UpsampledView | None = None

    def __call__(self, frame: np.ndarray, reference: np.ndarray, mask: np.ndarray,
                 known: Sequence[KnownPart] = (), shadows: UpsampledView | None = None,
                 unsure: np.ndarray | None = None) -> list[Measurement]:
        """Measure every blob of ``mask``; ``reference`` is the empty belt (float32 or uint8); ``known``:
        the parts tracked so far, where they are expected now and their sizes (boxes use them);
        ``shadows``: where the segmentation found light parts' shadows (indexable like the frame, > 0 in
        them; None: not told), on a coarse reference the only belt read as shadowed; ``unsure``: where the
        reference is not yet the belt's own (> 0 there; None: nowhere; see _read_where_unsure)."""
        self._known = known
        self._shadows = shadows
        self._unsure = unsure
        self._votes_left = self.config.height_votes_per_frame
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        contours = [c for c in contours if cv2.contourArea(c) >= self._min_area_px]
        boxes = [cv2.boundingRect(c) for c in contours]
        parts = None  # every blob that may be a part, drawn only when two come near each other
        found = []
        for n, contour in enumerate(contours):
            contour = self._filled(frame, reference, contour, boxes[n])
            split = split_blob(contour, self._split_rule)
            window = self._window(boxes[n])
            near = len(split.pieces) > 1 or any(k != n and _overlap(window, b) for k, b in enumerate(boxes))
            if near and parts is None:
                parts = np.zeros(mask.shape, dtype=np.uint8)
                cv2.drawContours(parts, contours, -1, 255, thickness=cv2.FILLED)
            for piece in split.pieces:
                m = self._measure(frame, reference, piece, parts if near else None, piece=len(split.pieces) > 1)
                if m is not None:
                    # A blob that is not one box and cannot be cut into boxes: never a pick target.
                    found.append(m if split.clean else replace(m, pickable=False))
        # Deterministic order for the tracker: left to right, top to bottom in the image.
        found.sort(key=lambda m: (m.bbox_px[0], m.bbox_px[1]))
        return found

    def _filled(self, frame: np.ndarray, reference, contour: np.ndarray, bbox) -> np.ndarray:
        """The blob with its notches that hold the part's own pixels, not belt: a box's silhouette is convex,
        and a face near the segmentation's threshold loses pixels to noise, which notches the outline as
        where two parts meet. A notch is a gap between the blob and its convex hull _NOTCH_DEPTH_PX deep or
        more; it joins the blob where most of its pixels are unlike the belt, by measure.min_contrast or
        more on the blob's side of the belt's level (where two parts meet it holds belt, only its pixels
        next to their edges blurred unlike it). The slivers between a straight edge's pixel staircase and
        its hull stay out: the pixels their edge crosses are unlike the belt too, and joined they would move
        the edge's windows out (its face read off a pixel the edge still crosses)."""
        if deepest_notch_px(contour) < _NOTCH_DEPTH_PX:
            return contour  # convex up to its pixels' staircase: nearly every blob, at the cost of its hull
        x, y, w, h = bbox
        blob = np.zeros((h + 2, w + 2), np.uint8)  # a pixel's margin: the hull's outside, for its depth
        cv2.drawContours(blob, [contour], -1, 255, thickness=cv2.FILLED, offset=(1 - x, 1 - y))
        hull = np.zeros_like(blob)
        cv2.fillConvexPoly(hull, cv2.convexHull(contour).reshape(-1, 2) - (x - 1, y - 1), 255)
        gaps = cv2.bitwise_and(hull, cv2.bitwise_not(blob))
        deep = cv2.bitwise_and(gaps, cv2.compare(cv2.distanceTransform(hull, cv2.DIST_L2, 3), _NOTCH_DEPTH_PX,
                                                 cv2.CMP_GE))
        if not cv2.countNonZero(deep):
            return contour
        n, labels = cv2.connectedComponents(gaps, connectivity=8)
        notches = np.unique(labels[deep > 0])
        img = np.zeros(blob.shape, np.float32)
        img[1:-1, 1:-1] = frame[y:y + h, x:x + w]
        img[1:-1, 1:-1] -= np.asarray(reference[y:y + h, x:x + w], dtype=np.float32)
        side = 1.0 if cv2.mean(img, mask=blob)[0] >= 0 else -1.0
        unlike = side * img >= self.config.min_contrast
        counts = np.bincount(labels.ravel(), minlength=n)
        like = np.bincount(labels.ravel(), weights=unlike.ravel(), minlength=n)
        fill = np.zeros(n, dtype=bool)
        fill[notches] = like[notches] >= 0.5 * counts[notches]
        fill[0] = False  # the blob and what lies outside its hull
        joined = cv2.bitwise_or(blob, fill[labels].astype(np.uint8) * 255)
        found, _ = cv2.findContours(joined, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE, offset=(x - 1, y - 1))
        return max(found, key=cv2.contourArea)

    def _measure(self, frame, reference, contour, parts, piece: bool = False) -> Measurement | None:
        """One part; ``parts``: the mask of every blob (None: no other blob is near); ``piece``: the contour
        was cut from a larger blob."""
        cfg = self.config
        x, y, w, h = cv2.boundingRect(contour)
        others = None if parts is None else self._others(contour, (x, y, w, h), parts)
        b = cfg.border_margin_px
        clipped = x < b or y < b or x + w > self._width - b or y + h > self._height - b
        # The hull in pixels maps to the hull on the belt closely enough for the area test
        # (and costs a tenth of mapping the whole outline).
        hull_mm = self.mapper.to_mm(cv2.convexHull(contour).reshape(-1, 2))
        if cv2.contourArea(hull_mm.astype(np.float32)) < cfg.min_area_mm2:
            return None
        box = known = None
        trials: tuple[HeightTrial, ...] = ()
        flat_rect = flat_growth = None
        crossed = None
        if cfg.subpixel and not clipped:
            crossed = self._crossings(frame, reference, contour, (x, y, w, h), others)
        # Binary staircase unless its edges read: boundary pixel centres sit half a pixel inside the edge.
        staircase = contour.reshape(-1, 2).astype(np.float64), min_area_rect(hull_mm)
        if not self._boxes:
            points_px, rect = self._flat_reading(crossed, staircase)
            view = rect
        else:
            points_px, rect = staircase
            view = rect
            edges = None if crossed is None else self._box_edges(crossed)
            flat = None
            if cfg.estimate_height and crossed is not None:
                # The pose of a part its track finds flat (a box's edges are read against the face next
                # to each, which on a flat part is a blurred mix).
                flat = self._flat_reading(crossed, staircase)
                flat_rect = flat[1]
            if edges is not None:
                points_px = edges.points_px
                # Undistorted once: the rectangle on the belt and a box's fit both start from them.
                points_norm = self.mapper.to_norm(points_px)
                points_mm = self.mapper.norm_to_mm(points_norm)
                rect = view = self._rect_of(points_mm)
            elif flat_rect is not None:
                rect = view = flat_rect  # no box reads from these edges: measured as flat parts are
            known = self._known_part(rect)
            if known is not None and known.flat:
                # Found flat (--part-height auto): measured as flat mode measures it (with no windows to
                # read, as the staircase it is already).
                if flat is not None:
                    points_px, rect = flat
                    view = rect
                    flat_growth = self._box_camera.silhouette_growth(_sized(rect, known.size))
            elif edges is not None:
                # A box: its side faces are part of the silhouette; fit the box to its edges instead.
                box, trials = self._fit_box(points_norm, self._windows(edges), rect, known)
                if trials and flat_rect is not None and edges.blur_px == 0 and cfg.vote_on_shades:
                    uneven = _uneven_faces(edges, points_mm, flat_rect, self._coarse_reference)
                    trials = tuple(replace(t, faces_uneven=uneven) if t.height_mm == 0 else t for t in trials)
                if box is not None:
                    rect = box.rect
                elif flat_rect is not None:
                    rect = flat_rect  # no box (yet) for this estimated part: measured as flat parts are
        centroid_px = tuple(float(c) for c in points_px.mean(axis=0))
        # Another part within reach of its edges touches it, or nearly: not a pick (contract 4b).
        return Measurement(rect, clipped, (x, y, w, h), centroid_px, len(points_px),
                           pickable=others is None, piece=piece, view_mm=(view.x_mm, view.y_mm),
                           size_cov_mm2=None if box is None else box.size_cov_mm2, flat_rect=flat_rect,
                           flat_growth=flat_growth, trials=trials,
                           own_size_mm=None if box is None else box.own_size_mm,
                           shape_info=None if box is None else box.shape_info,
                           shape_vec=None if box is None else box.shape_vec,
                           shape_at_mm=None if box is None or box.shape_info is None else box.height_mm,
                           view_shades=None if box is None else box.view_shades)

    def _flat_reading(self, crossed: _Crossed | None,
                      staircase: tuple[np.ndarray, Rect]) -> tuple[np.ndarray, Rect]:
        """The blob measured as a flat part always is: its edge points (Nx2 px) and rectangle, read against
        the part's own level; without windows to read, or too little contrast in them, ``staircase``
        (its boundary pixels and its outline's rectangle)."""
        flat = None if crossed is None else self._flat_points(crossed)
        return staircase if flat is None else (flat, self._rect_of(self.mapper.to_mm(flat)))

    def _flat_points(self, crossed: _Crossed) -> np.ndarray | None:
        """Sub-pixel edge points (Nx2 px) read against the part's own level (a flat part's, uniform);
        None where some window has too little contrast to trust, or too few read."""
        level = crossed.part_level
        if any(c.low_contrast(level, self.config.min_contrast) for c in (crossed.rows, crossed.cols)):
            return None
        points = _edge_points_of(crossed.rows, crossed.cols, (level, level))
        return points + crossed.origin if len(points) >= _MIN_EDGE_POINTS else None

    def _rect_of(self, pts_mm: np.ndarray) -> Rect:
        """The rectangle of edge points on a plane (mm): the least-area one, its sides refined."""
        return refine_rect(pts_mm, min_area_rect(pts_mm), band=self.config.side_band_px * self._mm_per_px)

    def _known_part(self, rect: Rect) -> KnownPart | None:
        """The known part whose expected centre lies within this blob's rectangle's width."""
        near = [(math.dist((k.x_mm, k.y_mm), (rect.x_mm, rect.y_mm)), k) for k in self._known]
        near = [(d, k) for d, k in near if d < rect.width_mm / 2]
        return min(near, key=lambda n: n[0])[1] if near else None

    def _size_of(self, known: KnownPart | None) -> SizePrior | None:
        """A known part's size to lend a fit: none for a near-square part, whose sides may be taken the
        other way round."""
        if known is None or known.size is None or known.size.length_mm - known.size.width_mm <= self.config.square_mm:
            return None
        return known.size

    def _window(self, bbox) -> tuple[int, int, int, int]:
        """The pixels examined for a blob's edges: its bounding box and a margin (x0, y0, x1, y1)."""
        x, y, w, h = bbox
        m = self.config.roi_margin_px
        return max(0, x - m), max(0, y - m), min(self._width, x + w + m), min(self._height, y + h + m)

    def _others(self, contour, bbox, parts) -> np.ndarray | None:
        """Pixels of the blob's window that belong to (or neighbour) other parts; None when none is within
        reach of its edges' windows."""
        x0, y0, x1, y1 = self._window(bbox)
        own = np.zeros((y1 - y0, x1 - x0), dtype=np.uint8)
        cv2.drawContours(own, [contour], -1, 255, thickness=cv2.FILLED, offset=(-x0, -y0))
        other = cv2.bitwise_and(parts[y0:y1, x0:x1], cv2.bitwise_not(own))
        if not cv2.countNonZero(other):
            return None
        # Their blurred rims too, which the mask leaves out.
        blocked = cv2.dilate(other, _ERODE)
        # Only what the edge windows reach counts (a bounding box's corners lie far from a turned part).
        if not cv2.countNonZero(cv2.bitwise_and(blocked, cv2.dilate(own, _ZONE))):
            return None
        return blocked > 0

    def _fit_box(self, points: np.ndarray, windows: EdgeWindows, rect: Rect,
                 known: KnownPart | None) -> tuple[BoxFit | None, tuple[HeightTrial, ...]]:
        """The box fitted to a blob's edges (``points``: normalised; None: no box explains them), and with
        heights estimated while its track votes (tracker/height.py), the trials at every height it votes on."""
        cfg = self.config
        starts: dict[float, Rect] = {}
        # Side shades are told (learnt, voted on) in a sharp image only: a blur spreads a sliver's shade
        # into its neighbours, and views misread it.
        sharp = windows.blur_px == 0
        tell_shades = cfg.learn_shades and sharp
        # The track's shades of the side faces this view shows (those on the camera's side of where the
        # part is expected).
        shades, facing = None, None
        if known is not None and known.shades is not None:
            facing = self._box_camera.facing_deg(np.array([known.x_mm, known.y_mm, rect.angle_deg]))
            shades = known.shades.facing(facing)

        def fit(height_mm: float, start: Rect | None = None, **kwargs) -> BoxFit | None:
            # From ``start``, or the outline measured on the plane of its top (where the measurement maps it
            # already with the height given): near the box for a tall part too.
            if start is None and height_mm not in starts:
                starts[height_mm] = (rect if not cfg.estimate_height or height_mm == 0
                                     else self._rect_on_plane(points, height_mm))
            start = starts[height_mm] if start is None else start
            return fit_box(self._box_camera, points, windows, start, height_mm, cfg.box_max_rms_px,
                           self._focal_px, sum_sigma_px=cfg.sum_sigma_px,
                           converged_steps=PRECISE_STEPS if cfg.estimate_height else CONVERGED_STEPS,
                           model_sigma_px=cfg.model_sigma_px, **kwargs)

        if not cfg.estimate_height:
            # Its height given: its size and side shades lent; what the view tells of the shades goes
            # back to the track (from a sharp image only, as below).
            told = dict(size_prior=self._size_of(known), tell_shades=tell_shades and cfg.part_height_mm > 0,
                        keep_residuals=True)
            pose = fit(cfg.part_height_mm, shade_prior=shades, **told)
            untold = (True, True) if shades is None else tuple(not t for t in known.shades.told_facing(facing))
            if told["tell_shades"] and self._lit_untold(pose, shades, untold, windows.shade_bounds):
                # Its track is to learn shades and no view has told those of a face this one shows: these
                # views seed them (see _lit_as_top).
                pose = self._lit_as_top(pose, fit, shades, untold, **told)
            return pose, ()
        if known is not None and known.height_mm is not None:
            # Its height voted on, being refined. Its pose: a box of that height, its size and side shades
            # lent (with the height free too, a thin part's fit wanders along the valley where height
            # trades with size); what the view tells of the shades goes back to the track, from a sharp
            # image only (a blur spreads a sliver's shade into its neighbours, and views misread it:
            # 0.2-0.5 against a rendered 0.5-0.7, with the camera's or the textured model's blur).
            pose = fit(known.height_mm, size_prior=self._size_of(known), shade_prior=shades,
                       tell_shades=tell_shades)
            return self._own_shape(pose, fit, known.refine, known.height_mm, sharp), ()
        # Voted on, or new: at each height of height_starts_mm when the view votes, its pose at the
        # height leading the vote (a new part's: the height that fits it best).
        lead = None if known is None else known.leading_mm
        if (known is not None and not known.votes_at(rect.x_mm, rect.y_mm)) or self._votes_left <= 0:
            # Between votes, or this frame's votes spent (a vote is several fits): at the leading height,
            # and what the view tells of the shape, kept until the vote decides (tracker/height.py).
            if lead in (None, 0.0):
                return None, ()
            pose = fit(lead, shade_prior=shades, tell_shades=tell_shades)
            return self._own_shape(pose, fit, known.refine, lead, sharp), ()
        self._votes_left -= 1
        boxes, trials = self._trials(fit, rect, windows)
        if lead == 0.0 or not boxes:
            # Flat leads the vote: the pose is the plain measurement's (as with no box at all: a
            # cylinder lying down, a bag).
            return None, trials
        box = next((b for b in boxes if b.height_mm == lead), None)
        if box is None and lead is not None and lead not in cfg.height_starts_mm:
            # The leading height lies between those tried: its own box (whose shades the track may learn).
            box = fit(lead, tell_shades=tell_shades)
        # A vote's view tells its own shape too, as a view between votes does (kept until the vote
        # decides): the first views, near the edge of the view, tell a height best (bench/heights_random.py
        # scene 10, 20 mm at 10 deg: those between the votes told it to 0.35 mm, converging only after 39 %
        # of the crossing; with the vote's views too, under 0.3 mm when the vote decides, after 12 %).
        if box is None:
            # No box of the leading height: the best one's pose, whose shades are another height's. A new
            # part (no height leads yet) tells its shape as that box, if it has sides.
            best = replace(min(boxes, key=lambda f: f.rms_px), view_shades=None)
            told = lead is None and best.height_mm > 0
            return (self._own_shape(best, fit, True, best.height_mm, sharp) if told else best), trials
        # Its shades go to the track with learn_shades, which learns them from the view that decides its
        # vote on (if the vote chooses this box's height, to track.view_height_sigma_mm).
        box = box if cfg.learn_shades else replace(box, view_shades=None)
        return self._own_shape(box, fit, known.refine, lead, sharp), trials

    @staticmethod
    def _lit_untold(pose: BoxFit | None, shades: ShadePrior | None, untold: tuple[bool, bool],
                    bounds: ShadeBounds) -> bool:
        """Whether ``pose`` is to be fitted again with faces lit as brightly as the top (see _lit_as_top):
        its track has learnt no shade yet, or, on a part brighter than the belt, no view has told that of
        a face this one shows. On a part darker than the belt a side as dark as the top is its usual
        shade (1.07-1.13 rendered), where the fits start anyway; fitted both ways in every view there,
        the tests' dark 5 mm box straight down, its sides never told, took the other fit by 0.02-0.03
        px^2 in view after view and grew 0.8 mm long (p95 0.04 -> 0.35 mm)."""
        if pose is None:
            return False
        return shades is None or (bounds == BRIGHT and any(
            face and width > 0 for face, width in zip(untold, pose.side_widths_px, strict=True)))

    def _lit_as_top(self, pose: BoxFit | None, fit, shades: ShadePrior | None, untold: tuple[bool, bool],
                    **kwargs) -> BoxFit | None:
        """``pose`` (a box fitted with its track's ``shades``, where no view has told those of the faces
        ``untold``, end and long), or the same box fitted again with those faces started as bright as the
        top, whichever explains the view better, its size as far from the size lent as the fit weighs
        it (``kwargs``: the pose's fit's own).

        Under a lamp to one side a face can be lit as brightly as the top. A box whose top reaches over
        that face, the face beyond it as dark as the belt, explains the view nearly as well, and a fit
        started at middling shades can end there. The views that first show a face seed the shade the
        track lends the rest, which then stay in that valley: a track learnt a sliver's end face as dark
        as the belt, and the length it lent grew with how much of the face each view showed
        (bench/heights_random.py --side-light --tilt 25, scene 6, its height given: 2.8 mm too long at
        worst, 1.01 mm centroid mean; 0.022 mm with its first views fitted both ways). That face may come
        into view only later, lit by the lamp that casts the part's shadow (--shadow scene 20, a 5 mm box
        at 20 deg: its length grew 1.6 mm as the face turned towards the camera). Started as bright as
        the top, a sliver whose shade no view tells can stay there, narrowing the part (--shadow scene
        25's long faces, its width 0.27 mm short when the fits were compared by their sums alone): what
        the track's other views tell of its size decides between them too."""
        if pose is None or pose.height_mm <= 0:
            return pose
        start = np.array(shades.shades if shades is not None else (_TOP_SHADE, _TOP_SHADE))
        sigma = np.array(shades.sigma if shades is not None else (_LIT_SHADE_SIGMA, _LIT_SHADE_SIGMA))
        lit = ShadePrior(tuple(np.where(untold, _TOP_SHADE, start)), tuple(np.where(untold, _LIT_SHADE_SIGMA, sigma)))
        other = fit(pose.height_mm, shade_prior=lit, **kwargs)
        if other is None:
            return pose
        cost = comparable_costs_px2([pose, other], self.config.sum_sigma_px, kwargs.get("size_prior"))
        return other if cost[1] < cost[0] else pose

    def _own_shape(self, pose: BoxFit | None, fit, refine: bool, height_mm: float, sharp: bool) -> BoxFit | None:
        """``pose`` (a box of ``height_mm``) with what its view tells of the part's shape on its own (when
        the track wants it, ``refine``): fitted again with the height and size free, nothing lent,
        from the pose (in a sharp image) and from the plane's rectangle at that height, the better kept
        (where both explain it alike, no surer than they lie apart: see told_alike). Lent the track's
        size, a view reads the height it is lent (the size a height needs holds the height where they
        trade: a 15 mm box's views lent 13.6 mm read 13.5, lent 16.5 read 16.0); lent the side shades
        learnt at a wrong height, likewise."""
        if pose is None or not refine:
            return pose
        # Its sums have minima a millimetre or more apart (a thin side face's shade trades with its width),
        # and where the fit ends depends on where it starts: from the plane's rectangle, the 8 mm box of
        # bench/view_heights.py at 20 deg read 5.0-5.4 mm in views where a box of 8 mm explains the sums
        # better (0.050 against 0.078 px RMS); from the pose, other views end in the worse minimum. Both
        # are fitted, and the one that explains the view better is kept. Not in a blurred image (the
        # textured belt model smooths): there the fits from the pose held the track near a wrong height
        # (the tests' 20 mm box on a knurled belt converged on 15.8-16.5 mm; 19.5-19.7 from the plane's
        # rectangle alone).
        near = [fit(pose.height_mm, start=pose.rect, near=True, **_OWN)] if sharp else []
        views = [f for f in (*near, fit(height_mm, **_OWN)) if f is not None]
        if not views:
            return pose
        ms = comparable_ms_px2(views, self.config.sum_sigma_px)
        best = int(np.argmin(ms))
        info, vec = views[best].shape_info, views[best].shape_vec
        if len(views) == 2 and max(ms) <= ms[best] * (1.0 + _ALIKE_MS) and info is not None:
            # Both explain the view about as well: two minima, and the view tells its shape no surer than
            # they lie apart (random scene 10 at 25 deg: a view whose fits ended at 21.6 and 18.4 mm,
            # their mean squares 6 % apart, claimed 18.4 +- 0.05 mm and held the estimate 0.64 mm off).
            info, vec = told_alike(views[best], views[1 - best])
        return replace(pose, shape_info=info, shape_vec=vec)

    def _trials(self, fit, rect: Rect, windows: EdgeWindows) -> tuple[list[BoxFit], tuple[HeightTrial, ...]]:
        """A box of each height of measure.height_starts_mm, its size free: those that fit, and the trials."""
        cfg = self.config
        sharp = windows.blur_px == 0
        # Their shades: for the vote's check, and for the track to learn from the view that decides it.
        tell = sharp and (cfg.vote_on_shades or cfg.learn_shades)
        # Each height's fit judged over the windows some height's kept (see comparable_ms_px2), in a sharp
        # image: in a blurred one (the textured belt model smooths) a flat part's fit drops more of the
        # windows its knurl disturbs than a box's, whose side shades take some of it up (the tests' flat
        # parts on a knurled belt led at 2.5-10 mm for most of their crossing: 0.64 mm off, 0.37 with
        # each fit's own RMS).
        # Each stands for the heights halfway to its neighbours: whether its box needs a side no part has
        # is judged over them (see boxfit._view_shades).
        fits = [(h, fit(h, tell_shades=tell and h > 0, keep_residuals=sharp, keep_model_errors=True,
                        height_span_mm=self._height_spans_mm[h]))
                for h in cfg.height_starts_mm]
        boxes = [f for _, f in fits if f is not None]
        if not boxes:
            return [], ()
        ms = iter(comparable_ms_px2(boxes, cfg.sum_sigma_px) if sharp else [f.rms_px**2 for f in boxes])
        # A height no box of explains (worse than box_max_rms_px) votes as if it had just that.
        trials = tuple(HeightTrial(h, rect, cfg.box_max_rms_px, len(windows), fitted=False) if f is None else
                       HeightTrial(h, f.rect, math.sqrt(next(ms)), f.windows, _size_variances(f),
                                   shades=f.view_shades if cfg.vote_on_shades else None)
                       for h, f in fits)
        return boxes, trials

    def _rect_on_plane(self, points_norm: np.ndarray, height_mm: float) -> Rect:
        """The rectangle of edge points (normalised) mapped onto the plane ``height_mm`` above the belt."""
        homography = self._plane_homographies.get(height_mm)
        if homography is None:
            calibration = self.mapper.calibration
            homography = calibration.homography_at_height(height_mm) @ calibration.camera_matrix
            if height_mm in self.config.height_starts_mm:  # a refined height is new every frame: not kept
                self._plane_homographies[height_mm] = homography
        pts = apply_homography(homography, points_norm)
        return self._rect_of(pts)

    def _crossings(self, frame, reference, contour, bbox, blocked=None) -> _Crossed | None:
        """The windows across the blob's boundary and the part's level; ``blocked``: window pixels of
        other parts, which no edge's window may reach (there the next part is no belt). None: too little
        belt or part in the window to read levels from."""
        x0, y0, x1, y1 = self._window(bbox)
        img8 = frame[y0:y1, x0:x1]
        ref = reference[y0:y1, x0:x1].astype(np.float32)
        piece = np.zeros(img8.shape, dtype=np.uint8)
        cv2.drawContours(piece, [contour], -1, 255, thickness=cv2.FILLED, offset=(-x0, -y0))
        # The belt is read around this part and the others next to it.
        whole = piece if blocked is None else cv2.bitwise_or(piece, blocked.astype(np.uint8) * 255)
        zone = cv2.dilate(whole, _ZONE)
        belt = cv2.bitwise_not(zone)
        inner = cv2.erode(piece, _ERODE)
        if cv2.countNonZero(belt) < _MIN_BELT_PX or cv2.countNonZero(inner) < _MIN_BELT_PX:
            return None
        ref8 = cv2.convertScaleAbs(ref)
        ref_here = max(_median_u8(ref8, belt), 1.0)

        def levels(image: np.ndarray) -> tuple[float, np.ndarray, float]:
            # The belt's level around the blob, its model scaled by this frame's lighting gain against
            # it there (outside a bright part's shadow), and the part's own.
            belt_here, part_here = _median_u8(image, belt), _median_u8(image, inner)
            lit = self._lit(image, ref8, belt) if part_here > belt_here and not self._coarse_reference else None
            if lit is None:
                level = belt_here / ref_here * ref
            else:
                belt_here = _median_u8(image, lit)
                level = belt_here / max(_median_u8(ref8, lit), 1.0) * ref
            if self._coarse_reference:
                level = _plane_corrected(level, image, belt, _PLANE_MAX_OF_CONTRAST * abs(part_here - belt_here))
            return belt_here, level, part_here

        belt_here, belt_level, part_level = levels(img8)
        if self._unsure is not None:
            belt_level = _read_where_unsure(img8, belt_level, belt, self._unsure[y0:y1, x0:x1])
        blur_px = self.config.edge_blur_px
        if self._smoothing_px and self._texture_strong(img8, belt_level, belt, part_level - belt_here):
            img8 = SmoothedView(frame, self._smoothing_px)[y0:y1, x0:x1]
            blur_px = math.hypot(blur_px, self._smoothing_px)
            belt_here, belt_level, part_level = levels(img8)
        inside = piece > 0
        k = HALF_WINDOW_PX
        rows = _boundary_crossings(img8, belt_level, inside, k, blocked)
        cols = _boundary_crossings(img8.T, belt_level.T, inside.T, k, None if blocked is None else blocked.T)
        if part_level > belt_here and (not self._coarse_reference or self._shadowed(x0, y0, x1, y1)):
            # On a textured belt only beside a shadow the segmentation found: its model is a coarse mean
            # of a pattern passing under each pixel, and a pixel darker than it is the knurl as often as
            # a shadow (bench/heights_random.py --textured, every part's windows read as in shadows: 12
            # scenes' heights closer, 10 further, 13 -> 12 of 30).
            rows, cols = (_in_shadow(c, self.config.shadow_min_levels) for c in (rows, cols))
        return _Crossed(rows, cols, (x0, y0), part_level, belt_here, blur_px)

    def _shadowed(self, x0: int, y0: int, x1: int, y1: int) -> bool:
        """Whether the segmentation found a shadow in the window (x0, y0)-(x1, y1)."""
        return self._shadows is not None and float(np.max(self._shadows[y0:y1, x0:x1], initial=0.0)) > 127.0

    def _lit(self, image: np.ndarray, ref8: np.ndarray, belt: np.ndarray) -> np.ndarray | None:
        """Of the ``belt`` pixels around a bright part, those not in its shadow (darker than the model by
        more than measure.shadow_min_levels): the shadow is the part's, not the frame's lighting, which
        the belt around the part tells. None: all of them (none in a shadow, or too few left outside)."""
        _, dark = cv2.threshold(cv2.subtract(ref8, image), self.config.shadow_min_levels, 255, cv2.THRESH_BINARY)
        lit = cv2.bitwise_and(belt, cv2.bitwise_not(dark))
        left = cv2.countNonZero(lit)
        return lit if _MIN_BELT_PX <= left < cv2.countNonZero(belt) else None

    def _texture_strong(self, img8: np.ndarray, belt_level: np.ndarray, belt: np.ndarray, contrast: float) -> bool:
        """Whether the belt's texture around a part (its pixels' median deviation from the belt model) is
        strong against the part's ``contrast`` (measure.smooth_texture_ratio): its edges are then read
        through the belt model's smoothing."""
        deviation = _median_u8(cv2.absdiff(img8, cv2.convertScaleAbs(belt_level)), belt)
        return deviation > self.config.smooth_texture_ratio * abs(contrast)

    def _box_edges(self, crossed: _Crossed) -> _Edges | None:
        """A box's sub-pixel edge points, each read against the face next to its edge (its side faces are
        shaded unlike its top: a start for the box fit); None where too few read."""
        k = HALF_WINDOW_PX
        rows, cols = (self._readable(c, k) for c in (crossed.rows, crossed.cols))
        if rows is None or cols is None:
            return None
        levels = (rows.face_levels(k), cols.face_levels(k))
        points = _edge_points_of(rows, cols, levels)
        if len(points) < _MIN_EDGE_POINTS:
            return None
        return _Edges(points + crossed.origin, rows, cols, crossed.origin, levels,
                      shade_bounds(crossed.part_level, crossed.belt_level), crossed.blur_px)

    def _readable(self, crossings: _Crossings, half_window: int) -> _Crossings | None:
        """A box's windows whose face (one pixel, see _Crossings.face_levels) differs enough from the belt
        under them to read the edge from: on a textured belt the belt under a few windows comes near
        it, and those are left out; None when more than measure.max_unreadable_fraction of those on
        one side of the blob (its left or right edges along rows, say) are (a side of the outline may
        then be missing, and with it the part's size)."""
        readable = crossings.readable(crossings.face_levels(half_window), self.config.min_contrast)
        for side in (crossings.rising, ~crossings.rising):
            if side.any() and 1.0 - readable[side].mean() > self.config.max_unreadable_fraction:
                return None
        return crossings.subset(readable)

    def _windows(self, edges: _Edges) -> EdgeWindows:
        """The edge windows for the box fit, each read against the face next to its edge."""
        inner_r, out_r = edges.rows.ends_px()
        inner_c, out_c = edges.cols.ends_px()
        inner = np.concatenate([inner_r, inner_c[:, ::-1]]) + edges.origin
        outward = np.concatenate([out_r, out_c[:, ::-1]])
        covered = np.concatenate([edges.rows.covered(edges.levels[0]), edges.cols.covered(edges.levels[1])])
        # The fit's cost grows with the windows: a large part's are thinned evenly along its outline.
        every = max(1, math.ceil(len(inner) / self.config.box_max_windows))
        inner, outward, covered = inner[::every], outward[::every], covered[::every]
        k = HALF_WINDOW_PX
        n = len(inner)
        ends = self.mapper.to_norm(np.concatenate([inner, inner + 2 * k * outward]))
        # The level pixel (see _Crossings.face_levels) is the window's (k+2)-th from its inner end.
        return EdgeWindows(ends[:n], (ends[n:] - ends[:n]) / (2 * k), covered, 2.0 * k, (k - 2.0, k - 1.0),
                           edges.blur_px, edges.shade_bounds)


@dataclass(frozen=True)
class KnownPart:
    """A part tracked so far: where its centre is expected in this frame (world frame, mm) and its size."""

    x_mm: float
    y_mm: float
    # None: a young track's, whose size has not settled (it lends none; it is known for its vote).
    size: SizePrior | None
    # --part-height auto (tracker/height.py). Its height once voted on, being refined (mm; None: given,
    # or still voted on), and whether this view is to tell its own too (a second fit).
    height_mm: float | None = None
    refine: bool = True
    # Found flat: measured as flat, no box fitted.
    flat: bool = False
    # Still voted on: where the camera saw its last vote's view (world frame, mm; None: none yet), how
    # far from there a view votes again, and the height leading the vote (the pose's; None before any).
    last_vote_mm: tuple[float, float] | None = None
    vote_step_mm: float = 0.0
    leading_mm: float | None = None
    # Its height given, refined, or leading its vote: the side shades its views have told at that height
    # (tracker/shades.py; None: none yet).
    shades: FaceShades | None = None

    def votes_at(self, x_mm: float, y_mm: float) -> bool:
        """Whether a view of it seen at (x, y) (world frame) votes (as HeightEstimate.wants_vote judges it)."""
        return vote_due(self.last_vote_mm, x_mm, y_mm, self.vote_step_mm)


@dataclass(frozen=True)
class _Crossed:
    """The windows across a blob's boundary, before they are read."""

    rows: _Crossings
    cols: _Crossings  # transposed: their "rows" are columns
    origin: tuple[int, int]  # the examined window's first pixel (x0, y0)
    part_level: float  # the part's own level (its inner pixels' median)
    belt_level: float  # the belt's around it
    blur_px: float  # the image's blur the windows were read through (the camera's, and any smoothing)


@dataclass(frozen=True)
class _Edges:
    """A box's sub-pixel edge points and the windows they were read from."""

    points_px: np.ndarray  # (N, 2) whole-frame pixels
    rows: _Crossings
    cols: _Crossings
    origin: tuple[int, int]
    levels: tuple[np.ndarray, np.ndarray]  # the face each window was read against (per window)
    shade_bounds: ShadeBounds  # the shades its side faces may have (a dark part's are others)
    blur_px: float  # as _Crossed's


def _edge_points_of(rows: _Crossings, cols: _Crossings, levels: tuple) -> np.ndarray:
    """The edge points (Nx2: x, y in the examined window) of the row and column crossings, each read
    against its level (per window, or one)."""
    return np.concatenate([rows.points(levels[0]), cols.points(levels[1])[:, ::-1]])


def _height_spans(heights_mm: tuple[float, ...]) -> dict[float, tuple[float, float]]:
    """How far below and above each height tried the heights it stands for reach: halfway to its
    neighbours (none beyond the lowest and the highest)."""
    ordered = sorted(heights_mm)
    return {h: (0.5 * (h - ordered[max(k - 1, 0)]), 0.5 * (ordered[min(k + 1, len(ordered) - 1)] - h))
            for k, h in enumerate(ordered)}


def told_alike(best: BoxFit, other: BoxFit) -> tuple[np.ndarray, np.ndarray]:
    """What a view tells of its shape (``best``'s information and vector on (length, width, height)) when
    another fit of it, ``other``, ends in another minimum that explains it about as well: no surer than
    they lie apart, along the line between them (half their distance as one sigma; the estimate stays
    ``best``'s). A side face's shade trades with its width, and a sliver's sums have minima millimetres
    apart: each fit's own curvature claims its minimum alone."""
    apart = np.array([best.rect.length_mm - other.rect.length_mm, best.rect.width_mm - other.rect.width_mm,
                      best.height_mm - other.height_mm])
    return widened(best.shape_info, best.shape_vec, np.outer(apart, apart) / 4.0)


def _uneven_faces(edges: _Edges, points_mm: np.ndarray, rect: Rect, coarse_outline: bool = False) -> bool:
    """Whether the sides of a blob's flat outline ``rect`` read faces unlike each other: the face next to
    its edges (see _Crossings.inner_contrast, ``coarse_outline`` as there) differs from the belt under it
    by less than _UNEVEN_RATIO of the most along one side than along another (each side's median), as
    where a box's side face makes one side of its silhouette. A flat part's top is one face.
    ``points_mm``: the edge points (``edges.points_px``) on the belt."""
    k = HALF_WINDOW_PX
    contrast = np.concatenate([edges.rows.inner_contrast(k, coarse_outline),
                               edges.cols.inner_contrast(k, coarse_outline)])
    corners = rectangle_corners(rect.x_mm, rect.y_mm, rect.angle_deg, rect.length_mm, rect.width_mm)
    # Each point's distance to each side's line (the sides' lines: corner i to i+1).
    a, b = corners, np.roll(corners, -1, axis=0)
    along = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    rel = points_mm[:, None, :] - a[None]
    dist = np.abs(rel[..., 0] * along[None, :, 1] - rel[..., 1] * along[None, :, 0])
    side = np.argmin(dist, axis=1)
    medians = [float(np.median(contrast[side == s])) for s in range(4)
               if np.count_nonzero(side == s) >= _UNEVEN_MIN_WINDOWS]
    return len(medians) >= 2 and min(medians) < _UNEVEN_RATIO * max(medians)


def _sized(rect: Rect, size: SizePrior | None) -> Rect:
    """``rect`` (its place and turn) of a track's ``size``, its longer side along the rectangle's longer;
    ``rect`` itself where the track lends none."""
    if size is None:
        return rect
    long, short = size.length_mm, size.width_mm
    return replace(rect, length_mm=long, width_mm=short) if rect.length_mm >= rect.width_mm else (
        replace(rect, length_mm=short, width_mm=long))


def _size_variances(fit: BoxFit) -> tuple[float, float]:
    """How well a box fit's view alone decides its length and width (variances, mm^2; inf: not at all)."""
    if fit.size_cov_mm2 is None:
        return math.inf, math.inf
    return float(fit.size_cov_mm2[0, 0]), float(fit.size_cov_mm2[1, 1])


def _overlap(window: tuple[int, int, int, int], box: tuple[int, int, int, int]) -> bool:
    """Whether a window (x0, y0, x1, y1) and a bounding box (x, y, w, h) share a pixel."""
    x0, y0, x1, y1 = window
    x, y, w, h = box
    return x < x1 and x + w > x0 and y < y1 and y + h > y0


def _median_u8(image: np.ndarray, mask: np.ndarray) -> float:
    """Median of 8-bit pixels under ``mask``, interpolated within its grey level (a histogram
    is ~20x cheaper than sorting, and the interpolation keeps sub-grey-level resolution)."""
    hist = cv2.calcHist([image], [0], mask, [256], [0, 256]).ravel()
    cumulative = np.cumsum(hist)
    half = cumulative[-1] / 2
    level = int(np.searchsorted(cumulative, half))
    below = cumulative[level - 1] if level else 0.0
    return level - 0.5 + (half - below) / hist[level]


@dataclass(frozen=True)
class _Crossings:
    """The windows across a blob's boundary along rows (or columns): pixel values and the belt under them."""

    rows: np.ndarray  # (N,) the row of each window
    first_col: np.ndarray  # (N,) its first column; it spans 2k pixels
    rising: np.ndarray  # (N,) bool: the part lies on the window's high side (a left edge)
    image: np.ndarray  # (N, 2k) grey levels
    belt: np.ndarray  # (N, 2k) the belt's level under them

    def low_contrast(self, level: np.ndarray | float, min_contrast: float) -> bool:
        """Whether the part's level (per window, or one) differs from the belt under some window by less
        than ``min_contrast``: too little to read its edge from."""
        return not bool(np.all(self.readable(level, min_contrast)))

    def readable(self, level: np.ndarray | float, min_contrast: float) -> np.ndarray:
        """(N,) bool: where the part's level (per window, or one) differs from the belt under every pixel
        of the window by ``min_contrast`` or more."""
        return np.min(np.abs(np.reshape(level, (-1, 1)) - self.belt), axis=1, initial=np.inf) >= min_contrast

    def subset(self, keep: np.ndarray) -> _Crossings:
        """The windows where ``keep`` (N,) holds."""
        return _Crossings(self.rows[keep], self.first_col[keep], self.rising[keep], self.image[keep], self.belt[keep])

    def points(self, level: np.ndarray | float) -> np.ndarray:
        """Where the edge crosses each row (Nx2: col, row), the part's level given per window or once."""
        cover = self.covered(level)
        along = np.where(self.rising, self.image.shape[1] - cover, cover)
        return np.column_stack([self.first_col - 0.5 + along, self.rows.astype(np.float64)])

    def covered(self, level: np.ndarray | float) -> np.ndarray:
        """Pixels of each window the part covers, in units of ``level``'s contrast (Pixel = (1 - c) *
        belt + c * part); along a row the covered fractions add up to where the edge crosses it."""
        return ((self.image - self.belt) / (np.reshape(level, (-1, 1)) - self.belt)).sum(axis=1)

    def inner_contrast(self, half_window: int, coarse_outline: bool) -> np.ndarray:
        """Each window's face's contrast with the belt (absolute), at its face pixel; with a
        ``coarse_outline`` (drawn from working pixels two or three wide, as the textured belt model's
        is), where the window's boundary pixel's contrast is less than _PAST_EDGE of the pixel beyond
        its face pixel, at that pixel. Such an outline reaches a pixel past the edge along some sides,
        and there the face pixel is a blend with the belt (bench/heights_random.py --textured scene 0,
        a flat part: along one side its face pixels read 102-113 grey levels off the belt against
        143-147 along the others, which took it for a box's side face, and a 5 mm box led its vote
        for 8 frames, 1.2 mm off). An outline traced at full resolution stops at the edge's pixel: a
        faint boundary pixel there is the edge of a side face's sliver, read where it is. (The pixel
        beyond the face pixel is the window's innermost at half_window = 3.)"""
        contrast = np.abs(self.image - self.belt)
        face = self._at_face(contrast, half_window)
        if not coarse_outline:
            return face
        boundary, beyond = (self._at_face(contrast, half_window, d) for d in (-1, 1))
        return np.where(boundary < _PAST_EDGE * beyond, beyond, face)

    def face_levels(self, half_window: int) -> np.ndarray:
        """Each window's face next to the edge: the first pixel wholly inside, one past the boundary pixel."""
        return self._at_face(self.image, half_window)

    def _at_face(self, values: np.ndarray, half_window: int, further_in: int = 0) -> np.ndarray:
        """Of ``values`` (N, 2k), each window's at its face pixel (see face_levels), or ``further_in``
        pixels further into the part (-1: its boundary pixel)."""
        return np.where(self.rising, values[:, half_window + 1 + further_in], values[:, half_window - 2 - further_in])

    def ends_px(self) -> tuple[np.ndarray, np.ndarray]:
        """Each window's inner end (Nx2: col, row, pixel coordinates of this orientation) and its
        outward direction (a unit step along the row)."""
        span = self.image.shape[1]
        col = np.where(self.rising, self.first_col + span - 0.5, self.first_col - 0.5)
        outward = np.where(self.rising, -1.0, 1.0)
        return (np.column_stack([col, self.rows.astype(np.float64)]),
                np.column_stack([outward, np.zeros(len(col))]))


def _read_where_unsure(image: np.ndarray, level: np.ndarray, belt: np.ndarray, unsure: np.ndarray) -> np.ndarray:
    """The belt's ``level`` (float32) where the reference is ``unsure`` (> 0: where a part lay at the start
    the reference still stands in for the belt, inpainted from around it) corrected by how the ``belt``
    pixels (> 0) around read against it, averaged locally (a Gaussian of _UNSURE_SIGMA_PX, normalised by
    the pixels it averages). The stand-in is off by up to 9 grey levels under a lamp's falloff, which a
    window's sum reads as a tenth of a pixel and more: bench/heights_random.py --dark scene 28's first
    views read its 60 mm box 1.5 mm high, and the tests' dark 60 mm box at 10 deg was 0.12 mm off in
    its first frame with its height given. (In the tests' small view, the belt's level beside its 10 mm
    box's edges where the reference was unsure: 1.7 grey levels high on average, 0.0 now.)"""
    unsure, belt = unsure > 0, belt > 0
    if not (unsure & belt).any():
        return level
    # The belt pixels beyond the unsure ones count too (their reference holds; the stand-in was carried in
    # from them, so it is off by less near them).
    weight = belt.astype(np.float32)
    off = cv2.GaussianBlur((image.astype(np.float32) - level) * weight, (0, 0), _UNSURE_SIGMA_PX)
    spread = cv2.GaussianBlur(weight, (0, 0), _UNSURE_SIGMA_PX)
    read = spread > _UNSURE_MIN_WEIGHT
    off[read] /= spread[read]
    return np.where(unsure & read, level + off, level).astype(np.float32)


def _boundary_crossings(img8: np.ndarray, belt: np.ndarray, inside: np.ndarray, half_window: int,
                        blocked: np.ndarray | None = None) -> _Crossings:
    """The windows where each row crosses the blob's outer boundary.

    The window of each crossing starts at the blob's first (last) pixel of the row and
    reaches ``half_window`` pixels to either side. Only rows where the boundary is within
    ~63 deg of vertical are used (the window then holds the whole transition); the
    transposed call takes the other edges. ``blocked``: pixels no window may reach (another
    part touching this one).
    """
    k = half_window
    n_rows, n_cols = inside.shape
    has = inside.any(axis=1)
    left = np.argmax(inside, axis=1)
    right = n_cols - 1 - np.argmax(inside[:, ::-1], axis=1)
    r = np.nonzero(has)[0]
    # Slope of the boundary from the rows either side (columns per row).
    ok = (r > 0) & (r < n_rows - 1)
    r = r[ok]
    ok = has[r - 1] & has[r + 1]
    r = r[ok]
    out = []
    offsets = np.arange(-k, k)
    for edge, rising in ((left, True), (right, False)):
        slope = 0.5 * (edge[r + 1].astype(np.int64) - edge[r - 1])
        rr = r[np.abs(slope) <= 1.0 / _STEEP_RATIO]
        start = edge[rr] - k if rising else edge[rr] - k + 1
        cols = start[:, None] + offsets + k  # the window: 2k pixels around the boundary
        fits = (cols[:, 0] >= 0) & (cols[:, -1] < n_cols)
        rr, cols = rr[fits], cols[fits]
        if blocked is not None:
            free = ~blocked[rr[:, None], cols].any(axis=1)
            rr, cols = rr[free], cols[free]
        out.append((rr, cols[:, 0], np.full(len(rr), rising), img8[rr[:, None], cols].astype(np.float64),
                    belt[rr[:, None], cols].astype(np.float64)))
    parts = [np.concatenate(a) for a in zip(*out, strict=True)]
    parts[-2] = parts[-2].reshape(-1, 2 * k)
    parts[-1] = parts[-1].reshape(-1, 2 * k)
    return _Crossings(*parts)


def _in_shadow(crossings: _Crossings, min_levels: float) -> _Crossings:
    """``crossings`` of a bright part, each window with a pixel on its belt half darker than the belt's
    model by more than ``min_levels`` (the darkest of them: the part's shadow) read against the belt that
    much darker from that pixel in to the part (a lamp's shadow takes a fraction of the belt's light),
    and beyond it against what its pixels show where they are darker still (the shadow's penumbra, the
    lit belt past a narrow shadow's end: no part lies there). Read against the belt as lit, a window
    3 px outside the edge in a shadow 30 levels deep, on a part 100 levels brighter, covered 0.9 px less
    than it holds (bench/heights_random.py --shadow: the boxes 0.3-0.7 mm off). A thin part's shadow
    is narrower than the window's belt half: found from its two outermost pixels only, the shadows of
    the 5-10 mm boxes there went unread (with the height given 34 of their 48 boxes within the issue's
    bounds, every scene's 35 of 60; from the darkest pixel of the half, 41 and 49)."""
    span = crossings.image.shape[1]
    n = np.arange(len(crossings.rows))
    # The belt half of each window (the outermost pixel first), and its darkest pixel against the model.
    outer = np.where(crossings.rising[:, None], np.arange(span // 2), span - 1 - np.arange(span // 2))
    ratio = crossings.image[n[:, None], outer] / np.maximum(crossings.belt[n[:, None], outer], 1.0)
    darkest = outer[n, np.argmin(ratio, axis=1)]
    depth = crossings.belt[n, darkest] - crossings.image[n, darkest]
    dark = depth > min_levels
    if not dark.any():
        return crossings
    columns = np.arange(span)
    inward = np.where(crossings.rising[:, None], columns >= darkest[:, None], columns <= darkest[:, None])
    scaled = crossings.belt * ratio.min(axis=1)[:, None]
    belt = np.where(inward, scaled, np.minimum(crossings.belt, crossings.image))
    return replace(crossings, belt=np.where(dark[:, None], belt, crossings.belt))


def _plane_corrected(level: np.ndarray, image: np.ndarray, belt: np.ndarray, most: float) -> np.ndarray:
    """The belt ``level`` plus a plane fitted to how the ``belt`` pixels of ``image`` differ from it;
    ``level`` as it is where the plane would move it by more than ``most`` somewhere in the window.

    A coarse reference that is still learning sits a few grey levels off the belt near a part, and
    unevenly (it starts from line medians); a part's edge is read from the level next to it, so an
    offset there moves the edge by a fraction of a pixel. Pixels beyond 3 robust sigmas (the knurl's
    peaks, a piece of the part the mask missed, another part's shadow) are left out: first around the
    residuals' median, then around each fitted plane."""
    # A plane needs no more than about a thousand pixels: a large part's window is read on a grid.
    step = max(1, int(math.sqrt(belt.size / _PLANE_FIT_PX)))
    ys, xs = np.nonzero(belt[::step, ::step])
    if len(xs) < _PLANE_MIN_PX:
        return level
    ys, xs = ys * step, xs * step
    residual = image[ys, xs].astype(np.float64) - level[ys, xs]
    design = np.column_stack([np.ones(len(xs)), xs, ys]).astype(np.float64)
    # Centred on their median at first, as a fitted plane's residuals are on zero.
    off = residual - np.median(residual)
    keep = np.ones(len(xs), dtype=bool)
    for _ in range(2):
        # A robust sigma (1.4826 x the median absolute deviation), and a grey level more: on a plain belt
        # read to the grey level the deviation can be 0, and nothing off the median would be kept.
        keep = np.abs(off) <= _PLANE_TRIM_SIGMAS * (1.4826 * np.median(np.abs(off[keep])) + 1.0)
        if keep.sum() < _PLANE_MIN_PX:
            return level
        kept = design[keep]
        try:
            coef = np.linalg.solve(kept.T @ kept, kept.T @ residual[keep])
        except np.linalg.LinAlgError:  # the belt pixels kept lie on one line: no plane through them
            return level
        off = residual - design @ coef
    h, w = level.shape
    # A plane is largest at a corner. One that far off is the belt's own pattern (a real belt's), not a
    # reference lagging behind it, and near the part's level it would wreck the edges' coverage.
    if max(abs(coef[0] + coef[1] * x + coef[2] * y) for x in (0, w - 1) for y in (0, h - 1)) > most:
        return level
    across = (coef[0] + coef[1] * np.arange(w, dtype=np.float32))[None, :]
    down = (coef[2] * np.arange(h, dtype=np.float32))[:, None]
    return level + across + down
