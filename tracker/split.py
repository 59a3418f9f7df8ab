"""Touching parts: a blob whose outline has deep notches is cut into convex pieces.

Parts are boxes, and a box's silhouette is convex from any viewpoint, so a blob with a
deep notch in its outline is several parts touching (or one lying on another). It is cut
along the shortest chord between two notches (where the parts meet) or, with a single
notch, along the extension of one of the notch's sides (two parts flush along one side);
the pieces are cut again until each is convex. Convex means no notch deeper than
``min_notch_px``: a single part's pixel staircase and blur leave notches of about 1 px.
A blob that cannot be cut into a few convex pieces is returned whole, marked unclean: its
parts cannot be told apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

# Contour points either side of a notch that give the directions of its two sides.
_SIDE_STEP_PX = 6
# A cut must run inside the blob for this fraction of its length.
_CUT_INSIDE = 0.9


@dataclass(frozen=True)
class SplitRule:
    """When a blob is several parts (pixels; derived from the measurement settings)."""

    # A notch this deep (px) in the outline is where two parts meet; shallower ones are noise.
    min_notch_px: float
    # Pieces smaller than this (px) are slivers of the cut, not parts.
    min_area_px: float
    max_pieces: int = 6
    # At most this many cuts are tried per blob: the search for pieces branches at every cut, and a blob
    # with dozens of notches (a textured belt's knurl joined to a part under the plain belt model) cost
    # 10 s of one frame. A few touching boxes need a handful; beyond, the blob is returned whole.
    max_cuts: int = 64
    # A piece fills at least this fraction of its minimum-area rectangle: a box seen from any side
    # does (its silhouette is a rectangle or a hexagon), and so does the corner of a box lying across
    # another one (a triangle at worst); a thin curved piece of a ring or of a bag may not.
    min_fill: float = 0.5


@dataclass(frozen=True)
class Split:
    pieces: tuple[np.ndarray, ...]  # contours (Nx1x2 int32) in image pixels
    clean: bool  # every piece convex: one part each


def split_blob(contour: np.ndarray, rule: SplitRule) -> Split:
    """The parts of one blob: itself when convex enough, else its convex pieces (see module doc)."""
    if not _notches(contour, rule):
        return Split((contour,), True)  # convex up to the pixels' staircase and the segmentation's noise
    x, y, w, h = cv2.boundingRect(contour)
    mask = np.zeros((h + 2, w + 2), dtype=np.uint8)
    cv2.drawContours(mask, [contour], -1, 255, cv2.FILLED, offset=(1 - x, 1 - y))
    pieces = _cut_until_convex(mask, rule, depth=0, budget=[rule.max_cuts])
    if pieces is None or not 2 <= len(pieces) <= rule.max_pieces:
        return Split((contour,), False)
    return Split(tuple(p + (x - 1, y - 1) for p in pieces), True)


def _cut_until_convex(mask: np.ndarray, rule: SplitRule, depth: int, budget: list[int]) -> list[np.ndarray] | None:
    """``mask``'s convex pieces, or None; ``budget``: the cuts the whole search may still try (shared)."""
    contours = _pieces(mask, rule)
    if len(contours) != 1:
        return None
    contour = contours[0]
    if not _notches(contour, rule):
        return [contour] if _boxlike(contour, rule) else None
    if depth >= rule.max_pieces - 1:
        return None
    for cut in _cuts(contour, mask, rule):
        if budget[0] <= 0:
            return None
        budget[0] -= 1
        halves = mask.copy()
        cv2.line(halves, cut[0], cut[1], 0, thickness=2)
        parts = _components(halves, rule)
        if len(parts) < 2:
            continue
        out = []
        for part in parts:
            sub = _cut_until_convex(part, rule, depth + 1, budget)
            if sub is None:
                break
            out.extend(sub)
        else:
            return out
    return None


def _cuts(contour: np.ndarray, mask: np.ndarray, rule: SplitRule) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """Candidate cuts, most likely first: chords between notches (shortest first), then notch sides."""
    pts = contour.reshape(-1, 2)
    notches = _notches(contour, rule)
    chords = []
    for i, a in enumerate(notches):
        for b in notches[i + 1:]:
            p, q = pts[a], pts[b]
            if _inside_fraction(mask, p, q) >= _CUT_INSIDE:
                chords.append((float(np.hypot(*(p - q))), (tuple(map(int, p)), tuple(map(int, q)))))
    out = [c for _, c in sorted(chords)]
    n = len(pts)
    reach = float(np.hypot(*mask.shape))
    for f in notches:
        p = pts[f].astype(np.float64)
        for side in (pts[(f - _SIDE_STEP_PX) % n], pts[(f + _SIDE_STEP_PX) % n]):
            d = p - side
            norm = float(np.hypot(*d))
            if norm == 0:
                continue
            end = _march(mask, p, d / norm, reach)
            if end is not None:
                out.append((tuple(map(int, p)), end))
    return out


def _boxlike(contour: np.ndarray, rule: SplitRule) -> bool:
    """Fills its minimum-area rectangle as a box's silhouette does (an arc of a ring does not)."""
    (_, _), (w, h), _ = cv2.minAreaRect(contour)
    return cv2.contourArea(contour) >= rule.min_fill * w * h


def _notches(contour: np.ndarray, rule: SplitRule) -> list[int]:
    """Indices of the contour points deepest in each notch deeper than the rule's minimum."""
    defects = _defects(contour)
    if defects is None:  # a self-touching outline: no notches to cut along
        return []
    return [int(f) for f, d in zip(*defects, strict=True) if d >= rule.min_notch_px]


def deepest_notch_px(contour: np.ndarray) -> float:
    """How far (px) the contour's deepest point lies inside its convex hull (inf: a self-touching outline)."""
    defects = _defects(contour)
    return np.inf if defects is None else float(defects[1].max(initial=0.0))


def _defects(contour: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Each notch's deepest contour point (index) and its depth (px); None for a self-touching outline
    (OpenCV finds no defects along it)."""
    hull = cv2.convexHull(contour, returnPoints=False)
    try:
        defects = cv2.convexityDefects(contour, np.sort(hull, axis=0))
    except cv2.error:
        return None
    if defects is None or not defects.size:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    defects = defects.reshape(-1, 4)
    return defects[:, 2], defects[:, 3] / 256.0


def _march(mask: np.ndarray, start: np.ndarray, direction: np.ndarray, reach: float) -> tuple[int, int] | None:
    """Where a ray from ``start`` into the blob leaves it again (None if it never enters)."""
    h, w = mask.shape
    inside_seen = False
    for s in np.arange(1.0, reach, 0.5):
        x, y = np.rint(start + s * direction).astype(int)
        if not (0 <= x < w and 0 <= y < h):
            break
        if mask[y, x]:
            inside_seen = True
        elif inside_seen:
            return int(x), int(y)
    return None


def _inside_fraction(mask: np.ndarray, p: np.ndarray, q: np.ndarray) -> float:
    n = max(2, int(np.hypot(*(p - q))) + 1)
    xs = np.rint(np.linspace(p[0], q[0], n)).astype(int)
    ys = np.rint(np.linspace(p[1], q[1], n)).astype(int)
    return float(np.mean(mask[ys, xs] > 0))


def _pieces(mask: np.ndarray, rule: SplitRule) -> list[np.ndarray]:
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return [c for c in contours if cv2.contourArea(c) >= rule.min_area_px]


def _components(mask: np.ndarray, rule: SplitRule) -> list[np.ndarray]:
    """Each piece of a cut mask as its own mask (same shape)."""
    out = []
    for c in _pieces(mask, rule):
        part = np.zeros_like(mask)
        cv2.drawContours(part, [c], -1, 255, cv2.FILLED)
        out.append(cv2.bitwise_and(part, mask))
    return out
