"""Each part's outline at full resolution, from the textured belt model's small working image.

- A part's core is where the contrast is at least half the strongest near it (its blurred rim and
  the faint belt texture drop out), closed over gaps narrower than the narrowest part (print, a
  fold, a screen): one blob per part, whatever its light and dark patches.
- A part is lighter or darker than the belt; the shadow a lamp makes it cast is only darker, and
  lies beside it, fainter than the part. A dark region of the foreground touching a light part, less
  than half as far off the belt's level, mostly outside the part's hull, not enclosing it and no more
  than twice its size, is its shadow and is left out before the blobs are formed (outlined by contrast
  alone, a shadow reaching farther than "near" joined its part). A dark screen within a light phone's
  frame, a light label on a dark part, a dark part with a light edge and a foil bag's dark folds
  stay. A faint dark part touching a light one is taken for its shadow while they touch, as by the
  reference model (segment.reference._without_shadows).
- The foreground on the part's side of the belt (that of its outermost pixels) connected to its
  core joins it, less its outermost working pixel: a box's side faces, lit less than its top, differ
  from the belt by less than half the top's contrast, and are its silhouette all the same. Not on a
  part of light and dark patches (a phone's frame and screen), whose faint rim is no face.
- The outline is the convex hull of that, grown at full resolution to where the (interpolated)
  contrast falls to half the part's own.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracker.config import SegmentConfig
from tracker.segment.views import UpsampledView

# Blobs smaller than this (working pixels) are specks, not parts: never outlined.
_MIN_BLOB_WORK_PX = 6
# A blob's own contrast: this percentile of its |level - belt| (its body, not its blurred rim).
_BLOB_LEVEL_PERCENTILE = 90
# A part's faint faces reach at most this far (working pixels) past its core: light on the belt
# farther off does not join it.
_FAINT_REACH_WORK_PX = 12
# A dark region is a light part's shadow when less than this fraction of it lies within the part's
# hull (a shadow lies beside its part) and its holes hold less than this fraction of the part (a
# label on a dark part lies in it).
_INSIDE_FRACTION = 0.5
# ... and differs from the belt by less than this fraction of the part's contrast (a shadow takes a part
# of the belt's light; a part's dark folds or side, and a dark part, are darker: a real foil bag's folds
# along its edge were taken for its shadow and cut off)
_SHADOW_MAX_CONTRAST = 0.5
# ... and at most this many times the part's size: a lamp 45 deg above the belt makes a box as tall as
# it is wide cast a shadow about its own size.
_SHADOW_MAX_AREA = 2.0
# A dark core this near (working pixels) a light region touches it: the blurred pixels between a part
# and its shadow are neither.
_TOUCH_WORK_PX = 2
_TOUCH = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * _TOUCH_WORK_PX + 1,) * 2)
# A part more than this fraction of whose core lies on the other side of the belt's level than its edge
# has light and dark patches: no faces are read on it.
_MIXED_FRACTION = 0.1
_SQUARE = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))


@dataclass(frozen=True)
class OutlineGeometry:
    """How the working image maps onto the frame, and the sizes (as kernels) outlining uses."""

    size: tuple[int, int]  # the frame's (width, height)
    scale: float  # working pixels per frame pixel
    near: np.ndarray  # "near" a pixel, for the strongest contrast around it (working pixels)
    thin: np.ndarray  # the narrowest part (working pixels): narrower gaps lie inside one
    band: np.ndarray  # one working pixel at full resolution: how far a hull grows


def outline_parts(diff: np.ndarray, contrast: np.ndarray, fg: np.ndarray, geo: OutlineGeometry,
                  config: SegmentConfig) -> tuple[np.ndarray, np.ndarray | None]:
    """The full-resolution mask of the parts in ``fg`` (working resolution), and the light parts'
    shadows left out of it (working resolution; None: none); ``diff``: the working image less the
    belt's level (float32), ``contrast`` its absolute value. Only the largest segment.max_blobs blobs
    are outlined."""
    w, h = geo.size
    mask = np.zeros((h, w), np.uint8)
    if not cv2.countNonZero(fg):
        return mask, None
    strong = cv2.bitwise_and(fg, cv2.compare(contrast, 0.5 * cv2.dilate(contrast, geo.near), cv2.CMP_GE))
    lighter = cv2.compare(diff, 0, cv2.CMP_GT)
    shadows = _shadows(contrast, strong, lighter, fg, config)
    if shadows is not None:
        strong = cv2.bitwise_and(strong, cv2.bitwise_not(shadows))
        fg = cv2.bitwise_and(fg, cv2.bitwise_not(shadows))
    strong = cv2.morphologyEx(strong, cv2.MORPH_CLOSE, geo.thin)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(strong, connectivity=8)
    levels, _ = _levels(contrast, labels, n)
    full_diff = UpsampledView(diff, geo.size, geo.scale)
    for i in np.argsort(-stats[1:, cv2.CC_STAT_AREA], kind="stable")[: config.max_blobs] + 1:
        if stats[i, cv2.CC_STAT_AREA] >= _MIN_BLOB_WORK_PX and levels[i] >= config.min_part_contrast:
            _draw(mask, labels, stats[i], i, levels[i], diff, fg, full_diff, geo)
    return mask, shadows


def _levels(contrast: np.ndarray, labels: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each blob's own contrast (``contrast``: |level - belt|; blob 0, the rest, 0): of its body, not
    its blurred rim: its pixels' _BLOB_LEVEL_PERCENTILE percentile, interpolated as numpy's is; and its
    pixel count. One sort for all of them (a percentile per blob cost 0.1 ms each)."""
    inside = labels > 0
    blob, value = labels[inside], contrast[inside]
    # Sorted by blob, then value (contrast < 256: one key sorts both).
    order = np.argsort(blob * 256.0 + np.minimum(value, 255.0), kind="stable")
    blob, value = blob[order], value[order]
    counts = np.bincount(blob, minlength=n)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    out = np.zeros(n)
    present = np.nonzero(counts)[0]
    rank = (counts[present] - 1) * _BLOB_LEVEL_PERCENTILE / 100.0
    low = np.floor(rank).astype(np.int64)
    high = np.minimum(low + 1, counts[present] - 1)
    a, b = value[starts[present] + low], value[starts[present] + high]
    out[present] = a + (rank - low) * (b - a)
    return out, counts


def _shadows(contrast: np.ndarray, strong: np.ndarray, lighter: np.ndarray, fg: np.ndarray,
             config: SegmentConfig) -> np.ndarray | None:
    """The foreground's dark regions that are light parts' shadows (None: none is)."""
    light_fg = cv2.bitwise_and(fg, lighter)
    dark_fg = cv2.bitwise_and(fg, cv2.bitwise_not(lighter))
    touching = cv2.bitwise_and(dark_fg, cv2.dilate(light_fg, _TOUCH))
    if not cv2.countNonZero(touching):
        return None  # no dark region touches a light one
    # Each light region's part's contrast, from its core (0: none, as light on the belt next to a dark
    # part, which casts no shadow).
    n_light, light, light_stats, _ = cv2.connectedComponentsWithStats(light_fg, connectivity=8)
    cores = np.where(cv2.bitwise_and(strong, lighter) > 0, light, 0)
    levels, core_px = _levels(contrast, cores, n_light)
    levels = np.where(core_px >= _MIN_BLOB_WORK_PX, levels, 0.0)
    levels[(levels < config.min_part_contrast) | (np.arange(n_light) == 0)] = 0.0
    if not levels.any():
        return None
    n, dark, stats, _ = cv2.connectedComponentsWithStats(dark_fg, connectivity=8)
    dark_levels, _ = _levels(contrast, dark, n)
    shadows = np.zeros_like(fg)
    rows, cols = fg.shape
    m = _TOUCH_WORK_PX
    for r in np.unique(dark[touching > 0]):
        x, y, bw, bh, area = stats[r]
        box = (slice(max(y - m, 0), min(y + bh + m, rows)), slice(max(x - m, 0), min(x + bw + m, cols)))
        region = (dark[box] == r).astype(np.uint8) * 255
        touched = np.unique(light[box][cv2.dilate(region, _TOUCH) > 0])
        touched = touched[touched > 0]
        if not levels[touched].any() or dark_levels[r] >= _SHADOW_MAX_CONTRAST * levels[touched].max():
            continue  # as dark as the part is light: a dark part, or the part's own dark side
        # The light regions it touches, whole (they may reach past its box): a part and its pieces.
        part_px = int(light_stats[touched, cv2.CC_STAT_AREA].sum())
        if area > _SHADOW_MAX_AREA * part_px:
            continue  # larger than a shadow the part casts: a dark part with a light edge or patch
        x0, y0 = light_stats[touched, :2].min(axis=0)
        x1, y1 = (light_stats[touched, :2] + light_stats[touched, 2:4]).max(axis=0)
        part = np.isin(light[y0:y1, x0:x1], touched).astype(np.uint8)
        hull = np.zeros_like(fg)
        cv2.fillConvexPoly(hull, cv2.convexHull(cv2.findNonZero(part)) + (x0, y0), 255)
        if cv2.countNonZero(cv2.bitwise_and(hull[box], region)) >= _INSIDE_FRACTION * area:
            continue  # within the part: its print, a screen, a fold
        if np.count_nonzero(np.isin(light[box], touched) & (_filled(region) > 0)) >= _INSIDE_FRACTION * part_px:
            continue  # around the part: a label on a dark part
        shadows[box][region > 0] = 255
    return shadows


def _filled(blob: np.ndarray) -> np.ndarray:
    """``blob`` with its holes filled (everything not reachable from outside it)."""
    padded = cv2.copyMakeBorder(blob, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    outside = np.zeros((padded.shape[0] + 2, padded.shape[1] + 2), np.uint8)
    cv2.floodFill(padded.copy(), outside, (0, 0), 255, flags=4 | cv2.FLOODFILL_MASK_ONLY | (255 << 8))
    return cv2.bitwise_not(outside[2:-2, 2:-2])


def _draw(mask: np.ndarray, labels: np.ndarray, stat: np.ndarray, i: int, level: float, diff: np.ndarray,
          fg: np.ndarray, full_diff: UpsampledView, geo: OutlineGeometry) -> None:
    """Draw one part (blob ``i`` of ``labels``, ``level`` its contrast) into ``mask``."""
    rows, cols = labels.shape
    x, y, bw, bh, _ = stat
    r = _FAINT_REACH_WORK_PX + 1
    x0, y0, x1, y1 = max(x - r, 0), max(y - r, 0), min(x + bw + r, cols), min(y + bh + r, rows)
    core = (labels[y0:y1, x0:x1] == i).astype(np.uint8) * 255
    # The part's side of the belt's level: that of its outermost pixels, which meet the belt.
    edge = cv2.bitwise_and(core, cv2.bitwise_not(cv2.erode(core, _SQUARE, borderType=cv2.BORDER_CONSTANT,
                                                           borderValue=0)))
    lighter = diff[y0:y1, x0:x1] > 0
    sign = 1.0 if 2 * np.count_nonzero(lighter & (edge > 0)) > np.count_nonzero(edge) else -1.0
    own = sign * diff[y0:y1, x0:x1]
    if np.count_nonzero((own < 0) & (core > 0)) > _MIXED_FRACTION * np.count_nonzero(core):
        # Light and dark patches (a phone's frame and screen, print): outlined by its contrast alone, its
        # faint edge pixels no face (joined, a white phone frame's blurred edge widened a real phone by
        # 8 mm in some frames and not others, and its track broke: topdown_mixed_items_grey_belt.avi).
        inside = core
    else:
        inside = _with_faces(core, own, fg[y0:y1, x0:x1])
    # The hull of the core and its faces; the band grown at full resolution finds the edge around it
    # where the contrast falls to half the part's (a face's own half would be nearer its edge, but a
    # face's level read near its edge is uneven, and the outline then notched: a real part's, measured
    # as two pieces, took 1.7 ms a frame more to measure).
    points = cv2.findNonZero(inside)
    scale = geo.scale
    hull = (cv2.convexHull(points).reshape(-1, 2) + (x0, y0) + 0.5) / scale - 0.5
    w, h = geo.size
    # The band one working pixel around the hull, at full resolution.
    fx0, fy0 = np.floor(hull.min(axis=0) - 1.5 / scale).astype(int)
    fx1, fy1 = np.ceil(hull.max(axis=0) + 1.5 / scale).astype(int)
    fx0, fy0, fx1, fy1 = max(0, fx0), max(0, fy0), min(w, fx1 + 1), min(h, fy1 + 1)
    blob = np.zeros((fy1 - fy0, fx1 - fx0), np.uint8)
    cv2.fillConvexPoly(blob, np.round(hull - (fx0, fy0)).astype(np.int32), 255)
    band = cv2.dilate(blob, geo.band)
    crop = (slice(fy0, fy1), slice(fx0, fx1))
    grown = cv2.bitwise_and(cv2.compare(np.abs(full_diff[crop]), 0.5 * level, cv2.CMP_GE), band)
    mask[crop] |= cv2.bitwise_or(blob, grown)


def _with_faces(core: np.ndarray, own: np.ndarray, fg: np.ndarray) -> np.ndarray:
    """A part on one side of the belt's level (``own``: how far each pixel is off the belt on that side;
    ``fg``: the foreground around it): its core with its faint faces, less their outermost pixels
    (blurred with the belt, they lie a whole working pixel too far out)."""
    # The foreground on the part's side connected to its core, as far as a face reaches.
    side_fg = cv2.bitwise_and(fg, cv2.compare(own, 0, cv2.CMP_GT))
    reach = cv2.dilate(core, cv2.getStructuringElement(cv2.MORPH_RECT, (2 * _FAINT_REACH_WORK_PX + 1,) * 2))
    part = _grown(core, cv2.bitwise_and(side_fg, reach))
    return cv2.bitwise_or(core, cv2.erode(part, _SQUARE, borderType=cv2.BORDER_CONSTANT, borderValue=0))


def _grown(core: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """``core`` and the pixels of ``allowed`` connected to it."""
    candidates = cv2.bitwise_or(core, allowed)
    filled = np.zeros((core.shape[0] + 2, core.shape[1] + 2), np.uint8)
    for contour in cv2.findContours(core, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)[0]:
        seed = (int(contour[0, 0, 0]), int(contour[0, 0, 1]))
        if not filled[seed[1] + 1, seed[0] + 1]:
            cv2.floodFill(candidates, filled, seed, 0, flags=8 | cv2.FLOODFILL_MASK_ONLY | (255 << 8))
    return filled[1:-1, 1:-1]

