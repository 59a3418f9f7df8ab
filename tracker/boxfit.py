"""Fitting a box's footprint to the coverage sums across its silhouette's edges (tracker/box.py).

Levenberg-Marquardt on the footprint (x, y, angle, length, width), optionally the height. Each
window's residual is its measured coverage sum minus the box's prediction (each face's pixels in
it times its shade, over the shade of the pixel the sum was read against), in pixels. The two side
shades (a side face's contrast as a fraction of the top's: one for the faces at the part's ends,
one for those along it) are solved for every box pose tried (variable projection: they are nearly
linear, and left free beside the pose they open long curved valleys that stop the fit short). The
box is first brought near with its plain outline against the edge points. A fit that does not
explain the data (a part no box at all) is rejected, and the caller keeps the plain rectangle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from tracker.box import SIDE_X, SIDE_Y, BoxCamera, EdgeWindows, distances_to_outline, lengths_in_faces
from tracker.geometry import Rect, wrap_angle_deg
from tracker.shadebounds import BRIGHT, ShadeBounds

# Parameters: x, y (mm), angle (deg), length, width, height (mm).
_H = 5
# The footprint's: all the outline's fit moves (see fit_box).
_FOOTPRINT = [0, 1, 2, 3, 4]
# Finite-difference steps: mm, the angle in degrees.
_STEP = np.array([0.01, 0.01, 0.005, 0.01, 0.01, 0.01])
# Iterations of each stage: the outline's from the start rectangle, the sums' from the outline's result.
_OUTLINE_ITERATIONS, _SUM_ITERATIONS = 20, 8
# Converged once no parameter moves by more than this fraction of its difference step: a smaller step
# is below what the differences resolve (on the tests' box scenes the poses agree within 0.003 mm with
# a twentieth, which takes a third more time). Heights estimated compare fits more finely (see
# PRECISE_STEPS).
CONVERGED_STEPS = 1.0
# The tolerance of every fit while heights are estimated: a height vote compares the sizes its fits
# find across views, and a fit with the height free travels long, nearly flat valleys in small steps
# (with 1.0 the tests' 10 mm box is estimated 0.6 mm off instead of 0.3).
PRECISE_STEPS = 0.05
# How weakly the side shades' prior holds them (px of residual per unit of shade): a side face too
# narrow to show its shade leaves the shade undecided. Where the shades start, where a fit keeps them
# and which a view tells: the windows' ShadeBounds (tracker/shadebounds.py). A view tells none that
# reads like the top: such a side looks like more of the top, and lent, it lets a box of another
# height pass for the part (when the vote's boxes learnt shades too, a flat part's 5-10 mm boxes
# learnt 1.0-1.2 and led its vote).
_SHADE_PRIOR = 0.02
_DEFAULT_HOLD = np.full(2, _SHADE_PRIOR**2)
# How many of its sigmas a view's shade has to lie outside the shades a side may have for the view to
# tell a side no part has (ViewShades.outside): a vote's height is counted against on it, so one
# view's noise should rarely do it (2 sigma: about 2 % of views at a side's limit; the tests' boxes' own
# heights were flagged in none of their vote's views).
_OUTSIDE_SIGMAS = 2.0
# ... and the face at least this wide (px): a narrower one has no pixel of its own, its shade and its
# width are read as one product, and the linear step that tells its shade misjudges how unsure it is
# (the tests' 10 mm box near the view's middle, its faces 0.1-0.3 px: told brighter than its top).
_OUTSIDE_MIN_WIDTH_PX = 1.0
# The step a shade's derivative is taken over (a fraction of the top's contrast).
_SHADE_STEP = 0.01
# Reweighting rounds of the shades' solution (their sums are ratios, linear once the level is fixed).
_SHADE_ROUNDS = 3
# The least level (a fraction of the top's) a window's level pixel is taken to have.
_MIN_LEVEL = 0.05
# Windows whose residual exceeds this many median residuals are outliers (a corner, a speck).
_OUTLIER_FACTOR = 4.0
# In comparable_ms_px2 a window counts at most this many sum sigmas: a speck
# costs every box alike, a window one box explains and another misses by a pixel costs that one.
# Within as many, no fit drops a window as an outlier (see inliers).
_TRIM_SIGMAS = 4.0


@dataclass(frozen=True)
class BoxFit:
    rect: Rect
    height_mm: float
    # RMS residual (px): lower is the better of two fits.
    rms_px: float = 0.0
    # How well this view alone decides the footprint's size: the covariance of (length, width) (mm^2).
    # A thin side face's shade trades with the edge next to it: there one side of the footprint is
    # poorly placed and the size uncertain, and a size known from other views (size_prior) places it.
    size_cov_mm2: np.ndarray | None = None
    # With the height free: this view's own information on (length, width, height) (3x3, 1/mm^2) and
    # information vector (3), any prior taken back out (see view_information): views add up.
    shape_info: np.ndarray | None = None
    shape_vec: np.ndarray | None = None
    # How many windows the sums were fitted to.
    windows: int = 0
    # With a size lent (size_prior): the (length, width) this view alone tells, the prior's pull taken
    # back out (mm); a track adding the fitted size would count what it lent twice.
    own_size_mm: tuple[float, float] | None = None
    # A box with side faces: what this view alone tells of their shades (see ViewShades).
    view_shades: ViewShades | None = None
    # With keep_residuals: each window's residual (px) and whether the fit kept it (not an outlier): what
    # compares fits of other boxes to the same windows (see comparable_ms_px2; rms_px leaves out the
    # windows each fit drops, and a wrong height drops those it cannot explain: a corner's jog, a side
    # face).
    residuals_px: np.ndarray | None = field(default=None, compare=False)
    kept: np.ndarray | None = field(default=None, compare=False)
    # With tell_shades: how wide the end face and the long face the camera sees are in the image (px; 0:
    # not seen, or not told).
    side_widths_px: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class SizePrior:
    """A part's size as known from other views (a track's): length >= width, 1-sigma each (mm)."""

    length_mm: float
    width_mm: float
    length_sigma_mm: float
    width_sigma_mm: float

    def __post_init__(self) -> None:
        if not (self.length_mm >= self.width_mm > 0 and self.length_sigma_mm > 0 and self.width_sigma_mm > 0):
            raise ValueError(f"size prior: expected length >= width > 0 and sigmas > 0, got {self}")


@dataclass(frozen=True)
class ShadePrior:
    """A part's side shades (end faces, long faces; each a side's contrast as a fraction of the top's)
    as known from other views (a track's), 1-sigma each (inf: not known, held as a fit alone holds it)."""

    shades: tuple[float, float]
    sigma: tuple[float, float]

    def __post_init__(self) -> None:
        if not (np.all(np.isfinite(self.shades)) and min(self.sigma) > 0):
            raise ValueError(f"shade prior: expected finite shades and sigmas > 0 (inf: not known), got {self}")


@dataclass(frozen=True)
class ViewShades:
    """The side shades (end faces, long faces) one view of a box tells on its own, any prior taken back
    out, and their variances (inf: the view shows no such face, or cannot tell its shade). A thin
    part's side face is a sliver whose shade trades with its edge: one view decides it poorly, and the
    same part's views decide it together (tracker/shades.py)."""

    shades: tuple[float, float]
    variances: tuple[float, float]
    # Whether the view tells, beyond _OUTSIDE_SIGMAS of its uncertainty, a shade no side has (beyond
    # ShadeBounds.possible: on a part brighter than the belt as bright as the top, or as dark as the
    # belt): a box of this height explains the view only as some other shape would (a taller box's
    # sides as bright as its top pass for a flat part's larger top; its sides as dark as the belt, for
    # a flat part's top). A face whose shade the view does not tell (its step leaps, unsure by 0.2-0.9)
    # tells none: flagged, the part's own height was counted against (15, 20 and 60 mm boxes near the
    # view's edge).
    outside: tuple[bool, bool] = (False, False)
    # What the view tells of (length, width, end shade, long shade) together, its pose marginalised out:
    # information (4x4; 1/mm^2, 1/mm per unit shade, per unit shade^2) and information vector (4); None
    # where not told. A sliver's shade trades with the size next to it, and the same part's views, which
    # see its faces at other widths, decide the two together (tracker/shades.py).
    info: np.ndarray | None = field(default=None, compare=False)
    vec: np.ndarray | None = field(default=None, compare=False)
    # Which end face and which long face the view saw: the directions of their outward normals (belt
    # frame, deg; BoxCamera.facing_deg; None: not said). A lamp to one side lights a face and the one
    # opposite it unalike, and a part crossing the view shows one, then the other (tracker/shades.py).
    facing_deg: tuple[float, float] | None = None
    # The shades a side may have (ShadeBounds.possible of the part's levels in this view).
    possible: tuple[float, float] = BRIGHT.possible


def predicted_sums(camera: BoxCamera, windows: EdgeWindows, params: np.ndarray, shades: np.ndarray | None = None,
                   shade_start: np.ndarray | None = None, shade_hold: np.ndarray = _DEFAULT_HOLD) -> np.ndarray:
    """The coverage sums each box (P rows of ``params``) predicts for ``windows`` (P, N; px) with the
    side ``shades`` (end faces, long faces), or with the shades that explain the sums best (None; from
    ``shade_start``, the windows' ShadeBounds.start by default, held there by ``shade_hold``, each (2,):
    see _best_shades)."""
    polygons, kinds = camera.faces(params)
    bounds = windows.shade_bounds
    start = np.full(2, bounds.start) if shade_start is None else shade_start
    return _shaded(lengths_in_faces(windows, polygons), kinds, windows.covered_px, shades, start, shade_hold,
                   bounds)[0]


def _best_shades(total: np.ndarray, level: np.ndarray, covered: np.ndarray,
                 bounds: ShadeBounds = BRIGHT) -> np.ndarray:
    """The side shades that best explain the sums (P, 2), given each kind's pixels in each window
    (P, N, 3) and in its level pixel: covered * (level . s) = total . s is linear in the shades s,
    and reweighted by the level it implies it is the residual itself (_SHADE_ROUNDS rounds from
    ``bounds.start``, held by _SHADE_PRIOR, kept within ``bounds``)."""
    return _shaded((total, level), np.arange(3), covered, None, np.full(2, bounds.start), _DEFAULT_HOLD, bounds)[1]


def _shaded(lengths: tuple[np.ndarray, np.ndarray], kinds: np.ndarray, covered: np.ndarray, shades: np.ndarray | None,
            start: np.ndarray, hold: np.ndarray, bounds: ShadeBounds) -> tuple[np.ndarray, np.ndarray]:
    """The sums (P, N) the faces' pixels in each window and its level pixel (``lengths``: each P, N, F;
    face f of kind ``kinds[f]``) predict with the side ``shades``, or with the best (None: from
    ``start``, held there by ``hold``, px^2 per unit shade^2, kept within ``bounds``); and the shades
    (P, 2). Compiled (tracker/facecover.py): in numpy's small whole-array steps the shades' solution
    cost as much as the faces' clipping."""
    from tracker.facecover import shaded_sums  # noqa: PLC0415 (compiled: see box.lengths_in_faces)

    total, level = lengths
    sums = np.empty(total.shape[:2])
    solved = np.empty((len(total), 2))
    given = np.zeros(2) if shades is None else np.asarray(shades, dtype=np.float64)
    shaded_sums(total, level, np.ascontiguousarray(kinds, dtype=np.int64),
                np.ascontiguousarray(covered, dtype=np.float64), given, shades is None,
                np.asarray(start, dtype=np.float64), np.asarray(hold, dtype=np.float64), bounds.low, bounds.high,
                _SHADE_ROUNDS, _MIN_LEVEL, sums, solved)
    return sums, solved


def fit_box(camera: BoxCamera, points_norm: np.ndarray, windows: EdgeWindows, start: Rect,
            height_mm: float, max_rms_px: float, px_per_norm: float, free_height: bool = False,
            size_prior: SizePrior | None = None, sum_sigma_px: float = 0.1, converged_steps: float = CONVERGED_STEPS,
            shade_prior: ShadePrior | None = None, tell_shades: bool = False,
            keep_residuals: bool = False, keep_model_errors: bool = False, near: bool = False,
            model_sigma_px: float = 0.0, height_span_mm: tuple[float, float] = (0.0, 0.0)) -> BoxFit | None:
    """The footprint (and with ``free_height`` the height, from ``height_mm`` on) whose box best
    explains ``windows``, or None when the fit's RMS residual exceeds ``max_rms_px``. ``points_norm``:
    the edge points (Nx2, normalised) that bring the box near first; ``px_per_norm``: the focal
    length. ``size_prior``: the size known from other views, weighed against the sums as if each had
    noise ``sum_sigma_px``; ``converged_steps``: how near the minimum the edge sums' fit stops
    (in difference steps: see PRECISE_STEPS); ``shade_prior``: the side shades known from other views,
    weighed likewise (without: held weakly to middling shades). The height reported is the fitted
    box's; with ``free_height`` the view's own information on its shape (the priors taken back out)
    comes with it, and with ``tell_shades`` what the view tells of its side faces' shades (ViewShades:
    a Jacobian more); with ``keep_residuals`` every window's residual and whether the fit kept it (for
    comparable_ms_px2: the sums once more where it dropped some); with ``keep_model_errors`` no window
    within _TRIM_SIGMAS sum sigmas is dropped as an outlier (see inliers), for a fit that nothing holds
    near the part's shape (a box of a height tried, a view's own shape); with ``near`` the ``start``
    (and ``height_mm``) is already this view's fit (a pose): only the sums' stages run, their shades
    solved from the start (see measure.Measurer._own_shape); ``model_sigma_px``: the box model's own error
    on the sums, which bounds how surely the view tells its height (see view_information);
    ``height_span_mm``: how far below and above ``height_mm`` the box may be (a vote's height tried
    stands for those halfway to its neighbours), over which ViewShades.outside is judged."""
    free = [*_FOOTPRINT, *([_H] if free_height else [])]
    floor_px = _TRIM_SIGMAS * sum_sigma_px if keep_model_errors else 0.0
    params = box_params(start, height_mm)
    bounds = windows.shade_bounds
    shade_start, shade_hold = np.full(2, bounds.start), _DEFAULT_HOLD
    if shade_prior is not None:
        known = np.isfinite(shade_prior.sigma)
        shade_start = np.where(known, shade_prior.shades, bounds.start)
        shade_hold = np.where(known, (sum_sigma_px / np.array(shade_prior.sigma)) ** 2, _DEFAULT_HOLD)

    # Each takes boxes (P rows of parameters) and gives their residuals (P, N) over the rows ``which``.
    def outline(p: np.ndarray, which: np.ndarray | slice = slice(None)) -> np.ndarray:
        return np.stack([px_per_norm * distances_to_outline(points_norm[which], o) for o in camera.outlines(p)])

    def sums(p: np.ndarray, which: np.ndarray | slice = slice(None), shades: np.ndarray | None = None) -> np.ndarray:
        w = windows if isinstance(which, slice) else windows.subset(which)
        return w.covered_px - predicted_sums(camera, w, p, shades, shade_start, shade_hold)

    # The outline brings the box near at the height it starts at: an outline hardly tells a height from a
    # size (a taller box on a smaller footprint has nearly the same outline), and with the height free
    # it wandered along that valley to another minimum of the sums (an 8 mm box near the view's edge,
    # started at 8 mm, ended at 15.2).
    if not near:
        params, r, jac, _ = _robust(outline, params, _FOOTPRINT, _OUTLINE_ITERATIONS, floor_px=floor_px,
                                    converged=converged_steps)
    middle = shade_start
    if shade_prior is not None:
        # A side face wider than a window's inner half fills that half: its sums read its shade apart
        # from its edge, and the fit starts it middling. A narrower one trades them, and its fit ends
        # in that valley near where it starts: at the shade the track's views tell (started there,
        # a 60 mm box's wide faces took the views' slightly biased shades: 0.44 -> 0.79 mm off).
        middle = np.where(_side_widths_px(*camera.faces(params), px_per_norm) >= windows.span_px / 2, bounds.start,
                          shade_start)

    def middling(p: np.ndarray, which: np.ndarray | slice = slice(None)) -> np.ndarray:
        return sums(p, which, middle)

    index, value, sigma = [], [], []
    if size_prior is not None:
        # Start the sums' fit at the known size too: in a flat valley it need not travel far.
        index = [3, 4] if params[3] >= params[4] else [4, 3]
        value = [size_prior.length_mm, size_prior.width_mm]
        sigma = [size_prior.length_sigma_mm, size_prior.width_sigma_mm]
        params[index] = value
    prior = (index, np.array(value), sum_sigma_px / np.array(sigma)) if index else None
    # The outline's edge points lie inside a thin side face's outer edge by (1 - its shade) times its
    # width: from there a fit of the shades finds them near the top's shade, and the edge where
    # the outline put it. Middling shades (or those other views tell) first bring the box to the
    # middle of that valley.
    params, r, jac, keep = _robust(sums if near else middling, params, free, _SUM_ITERATIONS, prior, converged_steps,
                                   floor_px)
    if near or size_prior is not None or shade_prior is not None or windows.blur_px > 0:
        params, r, jac = _least_squares(lambda p: sums(p, keep), params, free, _SUM_ITERATIONS, prior, converged_steps)
    else:
        # Nothing lent, in a sharp image: then with the shades the sums tell, every window judged again.
        # Judged under middling shades, a side of another shade lost windows it needs, and the fit over
        # the rest stayed where a shade trades with its edge (bench/heights_random.py scene 113's first
        # view, a 10 mm box at the view's edge: its long sides' shade 0.69 for 0.54, its width 2.1 mm off
        # at RMS 0.099 px; the true box explains the view with 0.061, and this ends there). A fit lent a
        # size or shades would drop the windows that disagree with what it is lent, and with them what
        # the view tells on its own; in a blurred image a sliver's shade is read poorly (measured: the
        # tests' 10 mm box blurred by 1 px, 0.11 -> 0.126 mm centroid mean).
        params, r, jac, keep = _robust(sums, params, free, _SUM_ITERATIONS, prior, converged_steps, floor_px)
    rms = float(np.sqrt(np.mean(r**2))) if len(r) else math.inf
    # The sums' own normal matrix, inverted once: the size's covariance and, with a size lent, its own estimate.
    normal_inv = np.linalg.pinv(jac.T @ jac) if len(r) > len(free) else None
    size_cov = None if normal_inv is None else _size_covariance(normal_inv, free, rms)
    if not np.isfinite(params).all() or rms > max_rms_px or min(params[3], params[4]) <= 0:
        return None
    info = (None, None)
    if free_height and len(jac) > len(free):
        info = view_information(jac, r, params, rms, model_sigma_px)
    own = None if size_prior is None or normal_inv is None else _own_size(normal_inv, jac, r, params, free)
    # Every window's residual at the fit's box (``r`` holds those it kept), for the shades and the caller.
    wanted = tell_shades or keep_residuals
    every = r if isinstance(keep, slice) else (sums(params[None])[0] if wanted else None)
    shades, side_widths = None, (0.0, 0.0)
    if tell_shades and params[_H] > 0 and len(r) > len(free) + 2:
        polygons, kinds = camera.faces(params)
        # The sums along one side may share an error of sum_sigma_px (the belt's level under them, the
        # blur): a face w px wide tells its shade no better than sum_sigma_px / w.
        widths = _side_widths_px(polygons, kinds, px_per_norm)
        side_widths = (float(widths[0]), float(widths[1]))
        floor = (sum_sigma_px / np.maximum(widths, 1e-9)) ** 2

        def told_over(which: np.ndarray | slice) -> ViewShades:
            kept = windows if isinstance(which, slice) else windows.subset(which)
            # The shades these sums are best predicted with at the fit's box (``at`` their residuals).
            solved = _shaded(lengths_in_faces(kept, polygons), kinds, kept.covered_px, None, shade_start,
                             shade_hold, bounds)[1][0]
            at = sums(params[None], which, solved)[0]
            return _view_shades(lambda p, s: sums(p, which, s), params, solved, at, free, floor,
                                widths >= _OUTSIDE_MIN_WIDTH_PX, bounds, height_span_mm)

        # The shades are told over every window within _TRIM_SIGMAS sum sigmas, not only those the fit
        # kept: a fit lent shades drops the windows of a sliver they do not explain, and the rest tell
        # back what it was lent (bench/heights_random.py's scene 79: its end faces, 0.70, told 0.56-0.69
        # as it was lent 0.4-0.9; over these windows 0.65-0.68). Whether a box of this height needs a
        # side no part has is judged over the windows it kept, as the vote's heights are compared.
        near_box = inliers(every, _TRIM_SIGMAS * sum_sigma_px)
        shades = told_over(near_box)
        fit_kept = np.ones(len(windows), dtype=bool) if isinstance(keep, slice) else keep
        if shade_prior is None and not np.array_equal(near_box, fit_kept):
            shades = replace(shades, outside=told_over(keep).outside)
        shades = replace(shades, facing_deg=camera.facing_deg(params))
    inlying = None
    if keep_residuals:
        inlying = np.ones(len(every), dtype=bool) if isinstance(keep, slice) else keep
    else:
        every = None
    x, y, angle, length, width = params[:5]
    if width > length:
        length, width, angle = width, length, angle + 90.0
        side_widths = side_widths[::-1]
        size_cov = None if size_cov is None else size_cov[::-1, ::-1]
        own = None if own is None else own[::-1]
        if info[0] is not None:
            order = [1, 0, 2]
            info = (info[0][np.ix_(order, order)], info[1][order])
        if shades is not None:
            # Its faces' kinds follow its parameters' axes: the end faces are now those of its width.
            shades = _swapped(shades)
    rect = Rect(float(x), float(y), wrap_angle_deg(float(angle)), float(length), float(width))
    return BoxFit(rect, float(params[_H]), rms, size_cov, *info, len(windows),
                  None if own is None else (float(own[0]), float(own[1])), shades, every, inlying, side_widths)


def comparable_ms_px2(fits: list[BoxFit], sum_sigma_px: float) -> list[float]:
    """Each fit's mean square residual (px^2) over the windows of a view (the same for every fit) that
    some fit kept, each counted at most _TRIM_SIGMAS sum sigmas: a window a fit drops and another
    explains counts against the one, while one that every fit drops is no box's (a speck, a textured
    belt's knurl under it) and counts for none."""
    squares = _comparable_squares(fits, sum_sigma_px)
    return [float(np.mean(sq)) if sq.size else math.inf for sq in squares]


def comparable_costs_px2(fits: list[BoxFit], sum_sigma_px: float, size_prior: SizePrior | None) -> list[float]:
    """Each fit's sum of squares (px^2) over the windows comparable_ms_px2 counts, and how far its size
    lies from ``size_prior`` (None: not lent), weighed as fit_box weighs it: what two fits of one view lent
    one size are compared by."""
    costs = []
    for fit, squares in zip(fits, _comparable_squares(fits, sum_sigma_px), strict=True):
        cost = float(np.sum(squares)) if squares.size else math.inf
        if size_prior is not None:
            off = ((fit.rect.length_mm - size_prior.length_mm) / size_prior.length_sigma_mm,
                   (fit.rect.width_mm - size_prior.width_mm) / size_prior.width_sigma_mm)
            cost += sum_sigma_px**2 * (off[0] ** 2 + off[1] ** 2)
        costs.append(cost)
    return costs


def _comparable_squares(fits: list[BoxFit], sum_sigma_px: float) -> list[np.ndarray]:
    """Each fit's squared residuals (px^2) over the windows some fit kept, capped (see comparable_ms_px2)."""
    some = np.any([f.kept for f in fits], axis=0)
    cap = (_TRIM_SIGMAS * sum_sigma_px) ** 2
    return [np.minimum(f.residuals_px[some] ** 2, cap) for f in fits]


def _side_widths_px(polygons: np.ndarray, kinds: np.ndarray, px_per_norm: float) -> np.ndarray:
    """How wide a box's end face and long face the camera sees are in the image (2,; px, 0: not seen),
    from its faces (BoxCamera.faces of one box): each face's area over its footprint edge's length (a
    side face's polygon runs footprint, footprint, top, top)."""
    x, y = polygons[0, ..., 0], polygons[0, ..., 1]
    area = 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1))
    edge = np.hypot(x[:, 1] - x[:, 0], y[:, 1] - y[:, 0])
    widths = np.zeros(3)
    widths[kinds] = px_per_norm * area / np.maximum(edge, 1e-12)
    return widths[[SIDE_X, SIDE_Y]]


def _view_shades(residuals, params: np.ndarray, shades: np.ndarray, r: np.ndarray, free: list[int],
                 floor: np.ndarray, wide: np.ndarray, bounds: ShadeBounds,
                 height_span_mm: tuple[float, float] = (0.0, 0.0)) -> ViewShades:
    """What one view tells of its side shades on its own: a Gauss-Newton step on the sums alone from the
    fit's result (``params``, and the ``shades`` solved there, which a prior may have held), the box's
    ``free`` parameters marginalised out (the pose and size differ from view to view; a sliver's shade
    trades with its edge). ``residuals(boxes, shades)``: the sums' residuals (P, N) with those shades,
    ``r`` theirs at the fit's result; ``floor``: the least variance of each (end faces, long faces);
    ``wide``: whether each is wide enough to tell a shade no side has (ViewShades.outside). A kind of
    face the view does not show, or whose step leaves the shades ``bounds.told``, gets an infinite
    variance. A shade is outside only if it would be at every height within ``height_span_mm`` (below,
    above) of the box's."""
    box_jac = (residuals(params + _difference_steps(free, len(params)), shades) - r) / _STEP[free][:, None]
    shade_jac = np.stack([(residuals(params[None], shades + d)[0] - r) / _SHADE_STEP for d in np.eye(2) * _SHADE_STEP])
    jac = np.vstack([box_jac, shade_jac]).T
    normal, grad = jac.T @ jac, jac.T @ r
    n = len(free)
    info, reduced = marginalised(normal, grad, [n, n + 1], list(range(n)))
    # A face not shown moves no sum: its shade is untold (and out of the other's solution).
    shown = np.diag(normal)[n:] > 1e-12
    variance = max(float(np.mean(r**2)), 1e-12)
    own, variances = shades.astype(np.float64), np.full(2, math.inf)
    if shown.any():
        sub = np.ix_(shown, shown)
        cov = np.linalg.pinv(info[sub])
        own[shown] = shades[shown] - cov @ reduced[shown]
        variances[shown] = np.diag(cov) * variance
    joint = _size_and_shades(normal, grad, params, shades, free, variance)
    variances = np.maximum(variances, floor)
    margin = _OUTSIDE_SIGMAS * np.sqrt(variances)
    # A step that leaps farther than the shades a side may have span is no reading of the shade (the
    # linear model of a face the view hardly tells: the tests' 15 mm box at 10 deg, its end face solved
    # at 0.1 and stepped to 3.0 +- 0.9, flagged its own height and the vote chose 20 mm).
    near = np.abs(own - shades) <= bounds.high - bounds.low
    (possible_from, possible_to), (told_from, told_to) = bounds.possible, bounds.told
    outside = wide & near & ((own + margin < possible_from) | (own - margin >= possible_to))
    if outside.any() and any(height_span_mm) and _H not in free:
        # Outside only if the shades a box within ``height_span_mm`` of this height would tell (linearly)
        # are too: a height tried a few mm off the part's reads a wide face's shade far off (a 46.7 mm
        # box fitted at 50 mm: its faces 0.08 for 0.47, as dark as the belt), and it is the height, not
        # the shape, that is wrong. (Worked out only where needed: 3-4 % of auto's time if always.)
        h_jac = (residuals(params + _difference_steps([_H], len(params)), shades)[0] - r) / _STEP[_H]
        per_mm = -(np.linalg.pinv(normal) @ (jac.T @ h_jac))[n:]
        ends = np.stack([own, own - per_mm * height_span_mm[0], own + per_mm * height_span_mm[1]])
        lowest, highest = ends.min(axis=0), ends.max(axis=0)
        outside &= (highest + margin < possible_from) | (lowest - margin >= possible_to)
    variances[~(variances > 0) | (own < told_from) | (own >= told_to)] = math.inf
    return ViewShades((float(own[0]), float(own[1])), (float(variances[0]), float(variances[1])),
                      (bool(outside[0]), bool(outside[1])), *joint, possible=bounds.possible)


def _swapped(view: ViewShades) -> ViewShades:
    """``view`` with its length and width, and its end and long faces, swapped (a box whose width
    outgrew its length: its rectangle's length is the other side)."""
    order = [1, 0, 3, 2]
    return ViewShades(view.shades[::-1], view.variances[::-1], view.outside[::-1],
                      None if view.info is None else view.info[np.ix_(order, order)],
                      None if view.vec is None else view.vec[order],
                      None if view.facing_deg is None else view.facing_deg[::-1], possible=view.possible)


def marginalised(normal: np.ndarray, grad: np.ndarray, keep: list[int],
                 rest: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """A normal matrix and gradient (or an information matrix and vector) over the parameters ``keep``
    (indices), those of ``rest`` marginalised out: a Schur complement."""
    if not rest:
        return normal[np.ix_(keep, keep)], grad[keep]
    with np.errstate(all="ignore"):
        coupling = np.linalg.lstsq(normal[np.ix_(rest, rest)], normal[np.ix_(rest, keep)], rcond=None)[0]
    return normal[np.ix_(keep, keep)] - normal[np.ix_(keep, rest)] @ coupling, grad[keep] - coupling.T @ grad[rest]


def _size_and_shades(normal: np.ndarray, grad: np.ndarray, params: np.ndarray, shades: np.ndarray, free: list[int],
                     variance: float) -> tuple[np.ndarray, np.ndarray]:
    """What the sums alone tell of (length, width, end shade, long shade) together (see ViewShades.info):
    ``normal`` and ``grad`` are the sums' normal matrix and gradient over the ``free`` box parameters
    and then the two shades, at the fit's result (``params``, ``shades``); the rest of ``free`` (the
    pose, a free height) is marginalised out (a Schur complement), and the sums' noise is ``variance``."""
    n = len(free)
    keep = [free.index(3), free.index(4), n, n + 1]
    info, reduced = marginalised(normal, grad, keep, [i for i in range(n + 2) if i not in keep])
    at = np.array([params[3], params[4], shades[0], shades[1]])
    return info / variance, (info @ at - reduced) / variance


def _own_size(normal_inv: np.ndarray, jac: np.ndarray, r: np.ndarray, params: np.ndarray,
              free: list[int]) -> np.ndarray:
    """(length, width) as the windows alone tell them: a Gauss-Newton step on the sums alone (their
    normal matrix's pseudo-inverse ``normal_inv``) from the fit's result, which the prior held short of
    their own minimum."""
    step = -normal_inv @ (jac.T @ r)
    return params[[3, 4]] + step[[free.index(3), free.index(4)]]


def view_information(jac: np.ndarray, r: np.ndarray, params: np.ndarray, rms: float,
                     model_sigma_px: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """One view's own information on the box's shape (length, width, height: what every view of the
    part shares) from a fit with all six free: (information 3x3, information vector 3; 1/mm^2, 1/mm).

    The pose (x, y, angle) differs from view to view, so it is marginalised out (a Schur complement).
    Any prior the fit had is taken back out: the vector is that of the sums' own Gauss-Newton
    estimate from the fit's result. One view of a thin box from above decides its height and size
    only together (a valley along which the box grows as it shrinks); views from elsewhere run their
    valleys other ways, and their information added up decides both.

    The sums' noise averages out over the windows; the model's own error (``model_sigma_px``) need
    not: the height is held no surer than an error that size on every window moves it, each window's
    the way that moves it most (the height's column of the Jacobian, the other parameters' part taken
    out, ``lone``: the height moves by sum(|lone|) / sum(lone^2) mm per pixel of such an error). Where
    the height rests on a few windows across slivers that move it by tens of mm per pixel, that
    bounds the view; where many windows of wide side faces tell it, hardly."""
    shape = [3, 4, _H]
    info, reduced_grad = marginalised(jac.T @ jac, jac.T @ r, shape, [0, 1, 2])
    variance = max(rms, 1e-6) ** 2
    info, vec = info / variance, (info @ params[shape] - reduced_grad) / variance
    if model_sigma_px > 0:
        rest = jac[:, :_H]
        lone = jac[:, _H] - rest @ np.linalg.lstsq(rest, jac[:, _H], rcond=None)[0]
        lever_mm_px = float(np.sum(np.abs(lone))) / max(float(np.sum(lone**2)), 1e-12)
        info, vec = widened(info, vec, np.diag([0.0, 0.0, (model_sigma_px * lever_mm_px) ** 2]))
    return info, vec


def widened(info: np.ndarray, vec: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An information matrix and vector whose estimate is the less sure by the covariance ``cov``
    added to it: (I + info . cov)^-1 applied to both, in information form, so that a singular
    information (a view's valley) stays as it is where ``cov`` does not reach."""
    damp = np.linalg.inv(np.eye(len(info)) + info @ cov)
    info = damp @ info
    return 0.5 * (info + info.T), damp @ vec


def _size_covariance(normal_inv: np.ndarray, free: list[int], rms: float) -> np.ndarray:
    """The covariance of (length, width) from the windows alone (``normal_inv``: the pseudo-inverse of
    their normal matrix; the prior left out, the shades projected out), scaled by the residuals' spread."""
    size = [free.index(i) for i in (3, 4)]
    return (normal_inv * rms**2)[np.ix_(size, size)]


def inliers(residuals: np.ndarray, floor_px: float = 0.0) -> np.ndarray:
    """The residuals that are no outliers (a corner's windows, a speck): within a few median residuals,
    or within ``floor_px``. In a sharp image the median is a few hundredths of a pixel, and the box
    model's own errors (a tenth of a pixel where a side face meets the top, or a corner) lie beyond
    four of them: dropped, they left a wrong height to explain the windows kept (a noiseless render of an
    8 mm box near the view's edge, fitted with its height free: 6.3 mm, RMS 0.025 px over the windows
    kept and 0.072 over all; with them kept, 8.1 mm)."""
    return np.abs(residuals) <= max(_OUTLIER_FACTOR * float(np.median(np.abs(residuals))), floor_px, 1e-3)


def box_params(rect: Rect, height_mm: float) -> np.ndarray:
    """A box's parameters as the fit orders them: x, y, angle, length, width, height."""
    return np.array([rect.x_mm, rect.y_mm, rect.angle_deg, rect.length_mm, rect.width_mm, height_mm])


def _robust(residuals, params: np.ndarray, free: list[int], iterations: int, prior: tuple | None = None,
            converged: float = CONVERGED_STEPS,
            floor_px: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | slice]:
    """Least squares, then again without the outliers (a corner's windows, a speck). They are
    judged only once the box is near: judged earlier, a side still far off would be dropped whole
    and left free to drift. ``residuals(params, which)``: the residuals (px) of the rows ``which``;
    ``prior``: see _least_squares; ``floor_px``: see inliers. Returns the last's params, residuals and
    Jacobian, and the rows kept."""
    params, r, jac = _least_squares(residuals, params, free, iterations, prior, converged)
    keep = inliers(r, floor_px)
    if keep.all():
        return params, r, jac, slice(None)
    return (*_least_squares(lambda p: residuals(p, keep), params, free, iterations, prior, converged), keep)


def _difference_steps(free: list[int], n_params: int) -> np.ndarray:
    """One box per ``free`` parameter, each that parameter's difference step (_STEP) and no other:
    added to a box's parameters, the boxes a forward-difference Jacobian is taken at."""
    steps = np.zeros((len(free), n_params))
    steps[np.arange(len(free)), free] = _STEP[free]
    return steps


def _least_squares(residuals, params: np.ndarray, free: list[int], iterations: int, prior: tuple | None = None,
                   converged: float = CONVERGED_STEPS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Levenberg-Marquardt from ``params`` over the ``free`` ones: (params, residuals, Jacobian of the
    residuals). ``residuals`` takes boxes (P rows) at once: the Jacobian's differences are one call.
    ``prior``: (indices, values, weights), rows weight * (param - value) beside them; ``converged``:
    done once no step moves a parameter by more than this many of its difference steps."""
    index, value, weight = prior if prior is not None else ([], np.zeros(0), np.zeros(0))
    prior_jac = np.zeros((len(index), len(free)))
    for row, i in enumerate(index):
        prior_jac[row, free.index(i)] = weight[row]
    steps = _difference_steps(free, len(params))

    def cost_of(r: np.ndarray, p: np.ndarray) -> float:
        return float(np.sum(r**2) + np.sum((weight * (p[index] - value)) ** 2))

    damping = 1e-3
    r = residuals(params[None])[0]
    cost = cost_of(r, params)
    jac = np.zeros((len(r), len(free)))
    for _ in range(iterations):
        jac = ((residuals(params + steps) - r) / _STEP[free][:, None]).T
        a = np.vstack([jac, prior_jac])
        b = np.concatenate([r, weight * (params[index] - value)])
        normal = a.T @ a
        delta = np.zeros_like(params)
        delta[free] = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-12), -a.T @ b)
        trial = params + delta
        trial[_H] = max(trial[_H], 0.0)  # a part's top is above the belt
        r_trial = residuals(trial[None])[0]
        trial_cost = cost_of(r_trial, trial)
        if trial_cost < cost:
            params, r, cost, damping = trial, r_trial, trial_cost, damping * 0.3
            if np.all(np.abs(delta) < _STEP * converged):
                break
        else:
            damping *= 10.0
    return params, r, jac
