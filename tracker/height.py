"""A part's height, estimated from its views as it crosses the camera's (--part-height auto).

One view rarely decides a height: near the edge of the view a flat part looks like a taller box with
a smaller footprint, and a thin box seen from above shows hardly any side. What decides it is how the
silhouette changes as the part moves: a wrong height fits each view only with another size, and the
size it needs changes across the view, while the right height fits every view with the part's one
size. The estimate has two stages.

1. **Vote.** Views the camera saw ``vote_step_mm`` apart (``track.height_vote_step_mm``, less on a small
   view; in the world frame, also on a moving belt whose parts are tracked in its own) along
   the part's path are fitted as a box at
   every height of ``measure.height_starts_mm``, its size free (``HeightTrial``). Each height scores,
   over the views, how much its sizes scatter (what decides it; no view adds more than
   ``track.height_vote_view_cap``) and how much worse its boxes explain the edges than the view's best
   height (weighted ``track.height_vote_cost_weight``: a box fit stopped short costs as much as a wrong
   height; a box's two side shades, which fit some of the noise, are charged as Akaike's criterion
   charges parameters). The best height wins once it leads by ``track.height_vote_margin`` every height
   tried that does not bracket the vote's lead (see _rivals; from ``track.height_vote_min_views`` views
   on), or after ``track.height_vote_views`` views; a flat lead has to lead only the boxes whose sides
   its views read together as a side's (not as dark as the belt nor as bright as the top: see
   _needs_other_sides). A winner of 0
   makes the part flat: from then on it is measured as flat, exactly as a flat part always was,
   unless its sizes grow across the view as a box's silhouette does (``track.flat_check_*``, see
   _check_flat): then flat is refuted and the vote goes on without it. A
   part's height is rarely one of those tried: between the best height's neighbours (halfway to
   each) every view's sizes are interpolated, and the height where they agree best leads the vote
   (to ``track.height_vote_resolution_mm``), and starts the refinement if its height wins. Meanwhile
   a view's pose is its box at the leading height.
2. **Refine.** Otherwise each later view is measured as a box of the estimated height, its size lent
   (its pose), and fitted once more from there with its height and size free, nothing lent (lent the
   track's size, a view reads back the height it is lent): what that view tells of (length, width,
   height) on its own (``boxfit.view_information``, as unsure as the box model's own error leaves it:
   ``measure.model_sigma_px``) adds to the estimate. A view
   that tells the height alone (its size marginalised out) less surely than
   ``track.view_height_told_sigma_mm`` adds nothing to it: it shows hardly any side face, and tells the
   height only from the part's apparent size, which the same small bias of the edges moves by
   millimetres in every such view (whether it disagrees still counts). The estimate is made of the
   vote's start and the views that tell the height, less those that disagree beyond
   ``track.view_gate_chi2`` with what the start and the rest tell (a hand over the part, a fit gone
   astray; see _robust_sum): one the estimate let in while young is left out once the views after it
   disagree with it. The vote's views and those between them are fitted so too, from the leading
   height (a new part's first view: from the best fitting); those fitted from the height that wins
   refine the estimate when the vote decides, as if they came then (see _replay_between_votes). A
   view that disagrees with the estimate counts as disagreeing; views that keep disagreeing for
   ``track.view_gate_frames`` views start the vote again (meanwhile the height told is the one voted
   on again). The height has converged once its uncertainty is below
   ``track.height_converged_sigma_mm`` over ``track.height_converged_views`` views that agree with it
   (those that add nothing to it too: a part passing under the camera shows no side for many views),
   and stays so until it exceeds ``track.height_unconverged_sigma_mm`` (or the vote is held again);
   from then on every ``track.height_refine_every``-th view still tells its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from tracker.boxfit import ViewShades, marginalised, widened
from tracker.config import TrackConfig
from tracker.geometry import Rect, wrap_angle_deg
from tracker.shades import read_together

# A view's disagreement with the estimate is a chi-square of this many degrees of freedom (length,
# width, height), whose expectation this is.
_SHAPE_DOF = 3.0
# The newest views this many are judged again as each comes (see _robust_sum); an older one joins the
# vote's start for good if the rest agreed with it, else it is dropped. A part parked under the camera
# (a stopped belt) tells a view every few frames for as long as it stays: judging them all again would
# cost more with every view. A part crossing the view tells far fewer (9-19 in random scenes 51, 72, 96).
_JUDGED_VIEWS = 64
# The parameters a box's fit has that flat's has not: its two side shades (end faces, long faces); and
# what Akaike's criterion charges each, in units of the fit's mean square per window.
_SHADE_PARAMETERS = 2
_AKAIKE_PER_PARAMETER = 2.0
# Heights closer than this (mm) are one height, apart by a rounding error only.
_ROUNDING_MM = 1e-9

if TYPE_CHECKING:
    from tracker.measure import Measurement


def vote_due(last_vote_mm: tuple[float, float] | None, x_mm: float, y_mm: float, step_mm: float) -> bool:
    """Whether a view seen at (x, y) votes: the first, or ``step_mm`` or more from the last vote's view
    (world frame, mm)."""
    return last_vote_mm is None or math.dist(last_vote_mm, (x_mm, y_mm)) >= step_mm


@dataclass(frozen=True)
class HeightTrial:
    """One view fitted as a box of one height, its size free."""

    height_mm: float
    rect: Rect
    # The fit's RMS residual (px), over the windows some height's fit kept in a sharp image (see
    # boxfit.comparable_ms_px2): comparable between the heights a view is fitted at.
    rms_px: float
    windows: int
    # How well the view alone decides the length and width at this height (variances, mm^2).
    size_var_mm2: tuple[float, float] = (math.inf, math.inf)
    # False: no box of this height explains the view (rect is the plain measurement's).
    fitted: bool = True
    # What the view tells of this box's side shades (None: not told, a blurred image or no sides).
    shades: ViewShades | None = None
    # Flat (height 0): the sides of its outline read faces unlike each other (a box's side face along
    # one; see measure._uneven_faces).
    faces_uneven: bool = False

    def __post_init__(self) -> None:
        if not (self.height_mm >= 0 and self.rms_px >= 0 and self.windows > 0 and min(self.size_var_mm2) >= 0):
            raise ValueError(f"height trial: expected height >= 0, rms >= 0 and windows > 0, got {self}")

    @property
    def another_shape(self) -> bool:
        """Whether this height explains the view only as another shape would: a box only with a side face
        of a shade no side has (ViewShades.outside), flat only with an outline whose sides read unlike
        faces (a box's side face along one)."""
        return (self.shades is not None and any(self.shades.outside)) or self.faces_uneven


class HeightEstimate:
    """What a track's views tell of its part's height (and, once voted, its size)."""

    def __init__(self, cfg: TrackConfig, vote_step_mm: float) -> None:
        """``vote_step_mm``: how far apart along the part's path views vote (track.height_vote_step_mm, less
        on a small view: see Pipeline)."""
        if not vote_step_mm > 0:
            raise ValueError(f"height vote: expected a step > 0 mm between the views that vote, got {vote_step_mm}")
        self._cfg = cfg
        self.vote_step_mm = vote_step_mm
        # No view is surer than the model is right: each counts with at least this uncertainty (mm^2).
        self._view_floor_mm2 = np.diag([cfg.view_size_sigma_mm**2] * 2 + [cfg.view_height_sigma_mm**2])
        # The height told until a view leads the vote: 0 for a new part; one voted on again keeps the
        # estimate its views disagreed with (not 0: a jump of the whole height for a frame).
        self._held_mm = 0.0
        # Flat was voted and the part's sizes then grew as a box's (see _check_flat): no longer a candidate.
        self.flat_refuted = False
        self._reset()

    def _reset(self) -> None:
        self.flat = False
        self.heights_mm: tuple[float, ...] = ()  # the vote's (those of its first view's trials)
        # The vote, per view: each height's excess cost (windows' units), sizes and their variances (K, 2).
        self._excess: list[np.ndarray] = []
        self._sizes: list[np.ndarray] = []
        self._size_vars: list[np.ndarray] = []
        self._fitted: list[np.ndarray] = []  # (K,) whether each height's box explained the view
        self._another: list[np.ndarray] = []  # (K,) whether it did only as another shape would
        self._shades: list[tuple[ViewShades | None, ...]] = []  # (K,) what it tells of each box's side shades
        self._last_vote_mm: np.ndarray | None = None  # where the part was at the last vote
        self._between_votes: list[tuple[float, np.ndarray, np.ndarray]] = []  # what views between votes told (see add)
        self._lead: tuple[float, np.ndarray] | None = None  # the leading height and its size (see _between)
        self._lead_tried = 0  # the index of the height tried it lies near (the best scoring)
        # The refinement: the information on (length, width, height) and its vector, the vote's (its
        # start) and that of every view that tells the height (see _robust_sum).
        self._info: np.ndarray | None = None
        self._vec = np.zeros(3)
        self._start: tuple[np.ndarray, np.ndarray] | None = None
        self._views: list[tuple[np.ndarray, np.ndarray]] = []
        self._kept = np.zeros(0, dtype=bool)  # which of them the estimate is made of
        self._settled_chi2s: list[float] = []  # the disagreements of those no longer judged again
        self._refine_views = 0  # refining views that agreed with the estimate (added to it or not)
        self._chi2s: list[float] = []  # each view's disagreement with the rest (see _robust_sum)
        self._disagreeing = 0
        self._since_refine = 0  # views since the last that told its own shape
        self._converged = False  # see converged
        # Found flat: its views' flat sizes against how a box's would grow there, as the normal equations
        # of their fit (see _check_flat; sums, so a part parked under the camera costs no more each view),
        # and the last view (length, width, their growths).
        self._flat_fit = _GrowthFit()
        self._flat_last: np.ndarray | None = None
        self._flat_seen_mm: tuple[float, float] | None = None  # where the last view it counted was seen

    @property
    def voting(self) -> bool:
        return not self.flat and self._info is None

    @property
    def last_vote_mm(self) -> tuple[float, float] | None:
        """Where the camera saw the last view that voted (world frame, mm; None: none yet)."""
        return None if self._last_vote_mm is None else (float(self._last_vote_mm[0]), float(self._last_vote_mm[1]))

    def wants_vote(self, x_mm: float, y_mm: float) -> bool:
        """Whether a view of the part seen at (x, y) (world frame) would vote: the first, or far enough
        from the last."""
        return self.voting and vote_due(self.last_vote_mm, x_mm, y_mm, self.vote_step_mm)

    @property
    def wants_refine(self) -> bool:
        """Whether the next view is to tell its own shape: each until the height converges, then every
        track.height_refine_every-th (a second fit each)."""
        return not self.converged or self._since_refine + 1 >= self._cfg.height_refine_every

    def add(self, m: Measurement, x_mm: float, y_mm: float) -> None:
        """Add view ``m`` of the part, seen by the camera at (x, y) (world frame, mm)."""
        if m.trials and self.wants_vote(x_mm, y_mm):
            if m.shape_info is not None and m.shape_at_mm:
                # What the vote's view tells of its shape, fitted from the height then leading (a new
                # part's: the best fitting), refines the estimate once the vote decides, as the views
                # between votes do.
                self._between_votes.append((m.shape_at_mm, m.shape_info, m.shape_vec))
            self._vote(m.trials, x_mm, y_mm)
        elif self.voting and m.shape_info is not None and self.leading_mm:
            # A view between votes tells its shape (fitted at the leading height): it refines the
            # estimate once the vote decides.
            self._between_votes.append((self.leading_mm, m.shape_info, m.shape_vec))
        elif self._info is not None:
            self._since_refine += 1
            if m.shape_info is not None:
                self._since_refine = 0
                self._refine(m.shape_info, m.shape_vec)
        elif (self.flat and m.flat_growth is not None and m.pickable and not (m.piece or m.clipped)
              and vote_due(self._flat_seen_mm, x_mm, y_mm, self._cfg.flat_check_step_mm)):
            self._flat_seen_mm = (x_mm, y_mm)
            self._check_flat(m.flat_rect, m.flat_growth)
        self._settle()

    def _check_flat(self, rect: Rect, growth: tuple[float, float]) -> None:
        """A part found flat: whether its views' flat sizes grow with how much a box's would there
        (``growth``, per mm of its height), as a box's silhouette does. Fitted over its views as two
        sizes and one height; where that height is at least track.flat_check_height_mm and
        track.flat_check_z standard errors from 0 (over track.flat_check_views views or more), flat
        is refuted and the vote goes on without it."""
        view = np.array([rect.length_mm, rect.width_mm, *growth])
        last = self._flat_last
        # The rectangle's sides in the order of the last view's (a near-square part's swap).
        if last is not None and (abs(view[0] - last[1]) + abs(view[1] - last[0])
                                 < abs(view[0] - last[0]) + abs(view[1] - last[1])):
            view = view[[1, 0, 3, 2]]
        self._flat_last = view
        self._flat_fit.add(view)
        cfg = self._cfg
        if self._flat_fit.views < cfg.flat_check_views:
            return
        height, sigma = self._flat_fit.height(cfg.flat_check_size_sigma_mm, cfg.flat_check_growth_spread)
        if height >= cfg.flat_check_height_mm and height >= cfg.flat_check_z * sigma:
            # The vote goes on from the views that found it flat, flat out of it (it cannot be found flat
            # again, so its check is done): they were seen where the sides told most, nearer the view's
            # edge than the part is now.
            self.flat, self.flat_refuted = False, True
            self._tally()

    @property
    def leading_mm(self) -> float | None:
        """The height the vote puts first so far (None before any view; 0 for a flat part): near the best
        scoring height tried, where the views' sizes agree best (see _between)."""
        if self.flat:
            return 0.0
        if self._lead is None or not self.voting:
            return None
        return self._lead[0]

    @property
    def lead_sigma_mm(self) -> float:
        """How surely the vote's lead tells the height (1 sigma, mm): a fraction
        (track.start_height_span_fraction) of the span of the neighbours of the height tried it lies
        near (the best scoring: halfway between two, it is that one's), at least
        track.start_shape_sigma_mm; inf before any view."""
        if self._lead is None:
            return math.inf
        heights, k = np.array(self.heights_mm), self._lead_tried
        span = float(heights[min(k + 1, len(heights) - 1)] - heights[max(k - 1, 0)])
        return max(span * self._cfg.start_height_span_fraction, self._cfg.start_shape_sigma_mm)

    def shape(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The refined (length, width, height) mm and their covariance (mm^2), widened by how much more
        the views disagree than they claim (see _spread); None while voting or flat."""
        shape = self._shape()
        return None if shape is None else (shape[0], shape[1] * self._spread())

    def _shape(self) -> tuple[np.ndarray, np.ndarray] | None:
        """shape() as the views claim it (their information added up)."""
        if self._info is None:
            return None
        cov = np.linalg.inv(self._info)
        return cov @ self._vec, cov

    def _spread(self) -> float:
        """How many times the views' disagreement with the estimate exceeds what their information
        claims: their mean chi-square (each counted at most as the gate, track.view_gate_chi2: a view left
        out disagrees at least that much) over its expectation, 3 (length, width, height); at least 1,
        and 1 until track.height_converged_views views have told theirs. A blurred image or a box the
        model misreads gives views that each claim a height to a fraction of a mm and scatter by
        several: their estimate is then as unsure as their scatter says, and converges only as that
        allows."""
        if len(self._chi2s) < self._cfg.height_converged_views:
            return 1.0
        return max(1.0, float(np.mean(np.minimum(self._chi2s, self._cfg.view_gate_chi2))) / _SHAPE_DOF)

    @property
    def height_mm(self) -> float:
        """The height as estimated so far (0 before any view, and for a flat part; voted on again, the
        estimate voted on until a view leads)."""
        shape = self.shape()
        if shape is not None:
            return max(float(shape[0][2]), 0.0)
        lead = self.leading_mm
        return self._held_mm if lead is None else lead

    @property
    def converged(self) -> bool:
        """Whether the height is settled: flat, or refined to track.height_converged_sigma_mm over
        track.height_converged_views views; once settled, until its uncertainty exceeds
        track.height_unconverged_sigma_mm (or the views vote again)."""
        return self.flat or self._converged

    def _settle(self) -> None:
        """Whether the height has converged after this view (see converged): a second, wider limit
        once it has, so that views widening it a little do not flip it."""
        shape = self.shape()
        if shape is None or self._refine_views < self._cfg.height_converged_views:
            self._converged = False
            return
        limit_mm = self._cfg.height_unconverged_sigma_mm if self._converged else self._cfg.height_converged_sigma_mm
        self._converged = math.sqrt(shape[1][2, 2]) < limit_mm

    def rect(self, m: Measurement) -> Rect:
        """The pose to take from view ``m``: its flat measurement when flat leads (or is decided); on a
        view that voted, its box at the height leading the vote or, the vote decided by this view, at the
        height estimated (see _rect_at; its own was measured at the height that led before it); else its
        own."""
        lead = self.leading_mm
        if lead == 0.0:
            return m.flat_rect or m.rect
        if m.trials and (lead is not None or not self.voting):
            return _rect_at(m.trials, self.height_mm if lead is None else lead) or m.rect
        return m.rect

    def _vote(self, trials: tuple[HeightTrial, ...], x_mm: float, y_mm: float) -> None:
        by_height = {t.height_mm: t for t in trials}
        if not self.heights_mm:
            self.heights_mm = tuple(sorted(by_height))
        if not set(self.heights_mm) <= set(by_height):
            return  # a view fitted at other heights (settings changed): it cannot vote with the rest
        self._last_vote_mm = np.array([x_mm, y_mm])
        trials = tuple(by_height[h] for h in self.heights_mm)
        self._fitted.append(np.array([t.fitted for t in trials]))
        self._another.append(np.array([t.another_shape for t in trials]))
        self._shades.append(tuple(t.shades for t in trials))
        windows = min(t.windows for t in trials)
        mse = np.array([_charged_ms_px2(t, windows) for t in trials])
        # How much worse each height explains this view than its best, in windows: a view whose edges
        # no height explains (a hand over the part) counts no more than one that one height explains.
        self._excess.append(np.minimum(windows * (mse / max(float(mse.min()), 1e-12) - 1.0), windows))
        self._sizes.append(np.array([(t.rect.length_mm, t.rect.width_mm) for t in trials]))
        # Their variances: the view's own, and no less than the floor.
        self._size_vars.append(np.array([t.size_var_mm2 for t in trials]) + self._cfg.height_vote_size_sigma_mm**2)
        self._tally()

    def _tally(self) -> None:
        """The vote's lead over its views so far, and whether it wins (see the module's doc)."""
        scores = self._scores()
        self._lead_tried = int(np.argmin(scores))
        self._lead = self._between(self._lead_tried)
        votes = len(self._excess)
        lead_by = self._rivals(scores, self._lead[0]).min(initial=np.inf) - scores.min()
        if votes >= self._cfg.height_vote_views or (
                votes >= self._cfg.height_vote_min_views and lead_by >= self._cfg.height_vote_margin):
            self._decide()

    def _rivals(self, scores: np.ndarray, height_mm: float) -> np.ndarray:
        """Of the heights tried's ``scores``, those the vote's lead ``height_mm`` has to lead by
        track.height_vote_margin to win: all but the two that bracket it (its neighbours, where it is one
        of them), and flat's unless flat leads (a part found flat is measured flat unless refuted, while the
        refinement moves a box's height within its bracket: a part between two heights tried, 8 mm, fits
        both alike and their scores kept within the margin of each other for 6 views). A flat lead's
        rivals are the boxes whose sides its views read together as a side's (see _needs_other_sides)."""
        heights = np.array(self.heights_mm)
        below, above = heights[heights < height_mm], heights[heights > height_mm]
        low = below.max() if below.size else -np.inf
        high = above.min() if above.size else np.inf
        apart = (heights < low) | (heights > high) | ((heights == 0) != (height_mm == 0))
        if height_mm == 0:
            apart &= ~self._other_shapes(scores)
        return scores[apart & (heights != height_mm)]

    def _other_shapes(self, scores: np.ndarray) -> np.ndarray:
        """Which heights' boxes the vote's views need sides no part has for (see _needs_other_sides), read
        only for the boxes within track.height_vote_margin of the best score: those beyond it are led by
        it anyway."""
        near = scores - scores.min() < self._cfg.height_vote_margin
        return np.array([h > 0 and bool(near[k]) and self._needs_other_sides(k) for k, h in enumerate(self.heights_mm)])

    def _needs_other_sides(self, k: int) -> bool:
        """Whether the vote's views of the ``k``-th height's box, read together with the size they share
        (each face on its own), need a side shade no side has (track.height_vote_flat_shade_sigmas beyond
        ShadeBounds.possible). A flat part's thin boxes explain each view as well as flat, a long face
        as dark as the belt, the one opposite or an end as bright as the top, which one view does not
        tell from a thin side: bench/heights_random.py scene 106, flat at 10 deg, led its 5 mm box by
        14-20 over 4-8 views (the margin 25), and flat won only after its 8 views, 53 % of its crossing;
        that box's ends and long faces read together 0.07 +- 0.03 and 0.04 +- 0.02 over its first three
        views. A real part's thin sides lie within (the random scenes' 5 mm boxes read 0.28-0.82 so)."""
        views = [view[k] for view in self._shades if view[k] is not None]
        if not views:
            return False
        shades, sigma = read_together(views, self._cfg.shade_view_min_sigma)
        margin = self._cfg.height_vote_flat_shade_sigmas * sigma
        # The widest the views allow (a part whose level crosses the belt's has a dark part's bounds in some).
        low, high = min(v.possible[0] for v in views), max(v.possible[1] for v in views)
        return bool(np.any((shades + margin < low) | (shades - margin >= high)))

    def _scores(self) -> np.ndarray:
        """Each height's score (lower is better), in units of a chi-square; flat's none once refuted."""
        sizes, weights, _ = self._sizes_weighed()
        scores = self._scored(sizes, weights, np.array(self._excess), self._against())
        if self.flat_refuted:
            scores[np.array(self.heights_mm) == 0] = np.inf
        return scores

    def _told(self) -> np.ndarray:
        """Whether each view's box of each height explains it and tells its size (views, K): a size its view
        does not tell (an infinite variance) would weigh nothing, and agree with any."""
        return np.array(self._fitted) & np.all(np.isfinite(np.array(self._size_vars)), axis=2)

    def _against(self) -> np.ndarray:
        """Whether each view counts against each height as much as a view can (views, K): no box of that
        height explains the view and tells its size, or one does only with a side face as bright as its
        top (or as dark as the belt), or flat only with an outline whose sides read unlike faces, however
        well it fits the edges: that is the shape of another part (a taller box's bright sides pass for a
        flat part's top; a box seen along its axis near the edge of the view, for a larger flat part)."""
        return ~self._told() | np.array(self._another)

    def _scored(self, sizes: np.ndarray, weights: np.ndarray, excess: np.ndarray, against: np.ndarray) -> np.ndarray:
        """The score of each height (or height between them) from its views' sizes and their weights
        (views, K, 2), excess costs (views, K) and how much each view counts against it (views, K; 1:
        as much as a view can, see _against)."""
        mean = _weighted_mean(sizes, weights)
        cap = self._cfg.height_vote_view_cap
        scatter = np.minimum((sizes - mean) ** 2 * weights, cap)
        scatter = scatter + (cap - scatter) * against[..., None]
        return self._cfg.height_vote_cost_weight * np.sum(excess, axis=0) + np.sum(scatter, axis=(0, 2))

    def _between(self, k: int) -> tuple[float, np.ndarray]:
        """The height near the ``k``-th tried (from halfway to its lower neighbour to halfway to its
        upper, at steps of track.height_vote_resolution_mm) whose sizes the views agree on best, and
        that size (length, width). Each view's sizes and their variances are interpolated linearly
        between the heights whose boxes explain it and tell its size, its excess cost and whether it
        counts against a height between all, and scored as the vote scores the heights tried. Flat
        stays 0: a flat part is measured as flat, not as a box a fraction of a mm tall."""
        heights = np.array(self.heights_mm)
        if heights[k] == 0:
            return 0.0, self._sizes_weighed()[2][k]
        lo = 0.5 * (heights[max(k - 1, 0)] + heights[k])
        hi = 0.5 * (heights[min(k + 1, len(heights) - 1)] + heights[k])
        # The height tried itself among them, whatever the step, and no step a rounding error from it
        # (np.arange(7.5, 15, 0.1)[25] is 9.999999999999991: where the scores tie, the first would lead).
        steps = np.arange(lo, hi, self._cfg.height_vote_resolution_mm)
        apart = np.abs(steps - heights[k]) > _ROUNDING_MM
        at = np.union1d(steps[apart], [heights[k], hi])
        sizes, variances = np.array(self._sizes), np.array(self._size_vars)
        told = self._told()
        if not told.any():
            return float(heights[k]), self._sizes_weighed()[2][k]
        sizes_at, weights_at = np.zeros((len(sizes), len(at), 2)), np.zeros((len(sizes), len(at), 2))
        for v, f in enumerate(told):
            if f.any():  # else it weighs nothing
                for side in range(2):
                    sizes_at[v, :, side] = np.interp(at, heights[f], sizes[v, f, side])
                    weights_at[v, :, side] = 1.0 / np.interp(at, heights[f], variances[v, f, side])
        excess_at = np.array([np.interp(at, heights, e) for e in self._excess])
        against_at = np.array([np.interp(at, heights, a) for a in self._against().astype(float)])
        j = int(np.argmin(self._scored(sizes_at, weights_at, excess_at, against_at)))
        return float(at[j]), _weighted_mean(sizes_at[:, j], weights_at[:, j])

    def _sizes_weighed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The vote's sizes (views, K, 2), their weights (1 / variance) and each height's weighted mean (K, 2)."""
        sizes, weights = np.array(self._sizes), 1.0 / np.array(self._size_vars)
        return sizes, weights, _weighted_mean(sizes, weights)

    def _decide(self) -> None:
        heights, k = np.array(self.heights_mm), self._lead_tried  # the best scoring, as the vote just scored
        if heights[k] == 0:
            self.flat = True
            return
        if not np.any(self._told()[:, k]):
            return  # no box of the winning height explained any view: no size to start from; vote on
        # The refinement starts from the vote: the leading height and the size it needs, held
        # start_shape_sigma_mm; the height held a fraction (track.start_height_span_fraction) of the
        # span of the winner's neighbours.
        height, size = self._lead
        start = self._cfg.start_shape_sigma_mm
        sigma = np.array([start, start, self.lead_sigma_mm])
        self._info = np.diag(1.0 / sigma**2)
        self._vec = self._info @ np.array([*size, height])
        self._start = self._info, self._vec
        self._replay_between_votes(height)

    def _replay_between_votes(self, height_mm: float) -> None:
        """The views between the votes, fitted from the leading height ``height_mm`` (within
        track.view_height_sigma_mm), refine the estimate as if they came now: a part crossing the view
        quickly would otherwise converge only after as many views more. Where they move it farther than
        that from the height they were fitted from, they do not count towards its convergence: the views
        fitted from the estimate itself decide that."""
        for lead_mm, info, vec in self._between_votes:
            if self._info is None:
                break  # they disagreed so that it is voted again
            if abs(lead_mm - height_mm) <= self._cfg.view_height_sigma_mm:
                self._refine(info, vec)
        self._between_votes = []
        if self._info is not None and abs(self.height_mm - height_mm) > self._cfg.view_height_sigma_mm:
            self._refine_views = 0

    def _refine(self, info: np.ndarray, vec: np.ndarray) -> None:
        if not (np.isfinite(info).all() and np.isfinite(vec).all()):
            return
        # A view that tells its height from its apparent size alone (track.view_height_told_sigma_mm) adds
        # nothing to the estimate; it still tells whether the estimate is wrong (its size along its valley).
        weak = not height_information(info) >= self._cfg.view_height_told_sigma_mm**-2
        # The view's uncertainty widened by the floor.
        info, vec = widened(info, vec, self._view_floor_mm2)
        # The view against the estimate (see _disagreement), as its views claim it, not widened by their
        # spread: widened, it would let in the very views that scatter, and a wrong estimate would never
        # be voted on again.
        chi2 = float(_disagreement(info[None], vec[None], self._info[None], self._vec[None])[0])
        if not weak:
            # It joins the views the estimate is made of whether it agrees with it or not: what they
            # tell together decides (see _robust_sum).
            self._views.append((info, vec))
            if len(self._views) > _JUDGED_VIEWS:
                self._settle_oldest()
            self._robust_sum()
        if chi2 > self._cfg.view_gate_chi2:
            self._disagreeing += 1
            if self._disagreeing >= self._cfg.view_gate_frames:
                held = self.height_mm
                self._reset()  # the estimate itself is wrong: vote again
                self._held_mm = held
            return
        self._disagreeing = 0
        self._refine_views += 1

    def _settle_oldest(self) -> None:
        """The oldest view judged again no longer is (see _JUDGED_VIEWS): into the start if the estimate is
        made of it, else dropped; its disagreement stays for _spread."""
        info, vec = self._views.pop(0)
        if self._kept[0]:
            self._start = self._start[0] + info, self._start[1] + vec
        self._settled_chi2s.append(self._chi2s[len(self._settled_chi2s)])

    def _robust_sum(self) -> None:
        """The estimate's information and vector: the vote's start and the views that tell the height,
        less those that disagree (track.view_gate_chi2) with what the start and the rest tell, the worst
        first; and each view's disagreement (one left out: the gate) for _spread. Added up as they came,
        one view that a young estimate let in could lock it: one whose edges read a 10 mm box 1.4 mm
        narrow, sure to 0.1 mm, moved the estimate so far that every later view disagreed with it until
        the vote was held again (bench/heights_random.py scene 51: converged after 82 % of its
        crossing, now 33 %). Judged against all, it is left out; views that agree with each other
        and tell more than the vote's start also move the estimate off it (two views, each sure of
        its height to 0.5 mm, against a start held to a few mm)."""
        infos = np.array([i for i, _ in self._views])
        vecs = np.array([v for _, v in self._views])
        keep = np.ones(len(infos), dtype=bool)
        start_info, start_vec = self._start
        while keep.any():
            total_info = start_info + infos[keep].sum(axis=0)
            total_vec = start_vec + vecs[keep].sum(axis=0)
            # Each kept view against the others (its own information taken back out).
            others_info = total_info - infos
            others_vec = total_vec - vecs
            others_info[~keep] = total_info
            others_vec[~keep] = total_vec
            chi2 = _disagreement(infos, vecs, others_info, others_vec)
            chi2[~keep] = -np.inf
            worst = int(np.argmax(chi2))
            if chi2[worst] <= self._cfg.view_gate_chi2:
                break
            keep[worst] = False
        self._kept = keep
        self._chi2s = self._settled_chi2s + list(np.where(keep, chi2, self._cfg.view_gate_chi2))
        self._info, self._vec = start_info + infos[keep].sum(axis=0), start_vec + vecs[keep].sum(axis=0)


class _GrowthFit:
    """Flat sizes fitted as a box's silhouette grows with its height: each view's length and width as
    length0 + h * growth and width0 + h * growth (least squares), kept as running sums of the views'
    differences from the first (so that a part parked under the camera costs no more each view, and
    sums of squares of sizes 100 mm long do not drown their hundredths)."""

    def __init__(self) -> None:
        self.views = 0
        self._first: np.ndarray | None = None
        self._sums = np.zeros(4)  # of (length, width, growth along the length, along the width)
        self._products = np.zeros((4, 4))

    def add(self, view: np.ndarray) -> None:
        """One view: (length, width, how much a box's would grow per mm along each)."""
        if self._first is None:
            self._first = view
        d = view - self._first
        self._sums += d
        self._products += np.outer(d, d)
        self.views += 1

    def height(self, size_sigma_mm: float, min_spread: float) -> tuple[float, float]:
        """The height (mm) the views tell and its standard error, their scatter about the fit the noise
        of a size, at least ``size_sigma_mm`` (inf: their growths scatter by less than ``min_spread``
        (RMS), so they tell none)."""
        n = self.views
        if n < 2:
            return 0.0, math.inf
        # Each side's (co)variances about its own mean: the two sizes have their own intercepts.
        centred = self._products - np.outer(self._sums, self._sums) / n
        sxx = centred[2, 2] + centred[3, 3]
        sxy = centred[2, 0] + centred[3, 1]
        syy = centred[0, 0] + centred[1, 1]
        if sxx < 2 * n * min_spread**2:
            return 0.0, math.inf
        height = sxy / sxx
        noise = max((syy - height * sxy) / max(2 * n - 3, 1), size_sigma_mm**2)
        return float(height), math.sqrt(noise / sxx)


def _weighted_mean(sizes: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The views' sizes (views, ...) averaged over the views by their weights (0 where none weighs)."""
    return np.sum(sizes * weights, axis=0) / np.maximum(np.sum(weights, axis=0), 1e-12)


def _disagreement(infos: np.ndarray, vecs: np.ndarray, others_info: np.ndarray,
                  others_vec: np.ndarray) -> np.ndarray:
    """Each view's (information ``infos`` (V, 3, 3) on (length, width, height), vector ``vecs``)
    chi-square against an estimate (information and vector each, (V, 3, 3) and (V, 3)), from
    information alone (a view's own estimate need not exist: one view may leave a valley open): its own
    estimate's distance in (its covariance + the estimate's)."""
    cov = np.linalg.inv(others_info)
    mean = np.einsum("vij,vj->vi", cov, others_vec)
    residual = vecs - np.einsum("vij,vj->vi", infos, mean)
    spread = infos + infos @ cov @ infos
    return np.einsum("vi,vij,vj->v", residual, np.linalg.pinv(spread), residual)


def height_information(info: np.ndarray) -> float:
    """What a view's information on (length, width, height) tells of the height alone, its size
    marginalised out (a Schur complement; 1/mm^2, 0 or less: nothing)."""
    return float(marginalised(info, np.zeros(3), [2], [0, 1])[0][0, 0])


def _charged_ms_px2(trial: HeightTrial, windows: int) -> float:
    """A trial's mean square (px^2) as the vote compares it: a box's fit has parameters flat's has not (its
    side shades), which fit some of any view's noise, and each is charged as Akaike's criterion charges
    one (a flat part at 10 deg, its 5 mm box's sides as dark as the belt: RMS 0.034 px each; uncharged,
    the box led its first view by 0.6 and posed the part 2 mm off until the next vote)."""
    extra = _SHADE_PARAMETERS if trial.height_mm > 0 else 0
    return trial.rms_px**2 * (1.0 + _AKAIKE_PER_PARAMETER * extra / windows)


def _rect_at(trials: tuple[HeightTrial, ...], height_mm: float) -> Rect | None:
    """A view's pose as a box of ``height_mm``: its trial of that height, or interpolated between those of
    the nearest heights below and above whose boxes explain it (a box's pose moves smoothly with its
    height); None where there are no such."""
    fitted = sorted((t for t in trials if t.fitted), key=lambda t: t.height_mm)
    same = [t for t in fitted if t.height_mm == height_mm]
    if same:
        return same[0].rect
    below = [t for t in fitted if t.height_mm < height_mm]
    above = [t for t in fitted if t.height_mm > height_mm]
    if not below or not above:
        return None
    a, b = below[-1], above[0]
    turn = wrap_angle_deg(b.rect.angle_deg - a.rect.angle_deg)
    if abs(turn) > 45.0:
        return None  # a near-square part whose longer side is another in each: no pose between
    f = (height_mm - a.height_mm) / (b.height_mm - a.height_mm)

    def between(name: str) -> float:
        return getattr(a.rect, name) + f * (getattr(b.rect, name) - getattr(a.rect, name))

    return Rect(between("x_mm"), between("y_mm"), wrap_angle_deg(a.rect.angle_deg + f * turn),
                between("length_mm"), between("width_mm"))
