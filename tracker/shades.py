"""A part's side shades, as its views tell them together (boxes: tracker/box.py, tracker/boxfit.py).

A box's side face is fitted with its own shade (its contrast as a fraction of the top's). Where the
face is a sliver of a pixel or two (a thin part, or any part near the middle of the view) its shade
trades with its edge: one view leaves it open, and the fit settles wherever it started, a tenth of
a pixel or more off. That bias is what kept thin parts' estimated heights off (the tests' 5 mm box
straight down refined to 6.2 mm; with the rendered shades lent to every fit, an experiment, every
one of the tests' boxes but that one came within 0.6 mm once converged, and it within 0.8). A part's faces
keep their shades as it crosses the view (the lighting is fixed), so the views that show a face
wide enough tell its shade, and the track lends it to the rest, as it lends its size
(``track.known_shade_sigma``). Views count as surely as they tell the shade, from
``track.shade_view_min_sigma`` down; one that tells it worse than ``track.shade_view_max_sigma`` is
left out; and the oldest views weigh less than the newest (``track.shade_memory_views``): a face
turning towards or away from a lamp changes its shade. With ``measure.learn_shades`` (on by
default; the README says what it gains and costs), a track learns them from sharp images only: with
the height given from every view, with --part-height auto from its boxes at the height it is
estimated (or, while voted on, leads the vote) to have, forgotten when that moves by more than
``track.view_height_sigma_mm`` (see Track._learn_shades).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tracker.boxfit import ShadePrior, ViewShades, marginalised
from tracker.config import TrackConfig

# The least information (a fraction of the most, per unit of a combination of parameters) read_together
# takes a combination to have: one no view tells (a view's sliver tells its shade and the size beside
# it only as one sum) gets a vast variance rather than the pseudo-inverse's small one, or a negative one.
_UNTOLD = 1e-12


@dataclass(frozen=True)
class FaceShades:
    """The side shades a track lends its fits: each side face's (its contrast as a fraction of the top's),
    1 sigma each (inf: not known), the two end faces', then the two long faces'. A fit shows one face of
    each pair (the one on the camera's side, BoxCamera.facing_deg): the first of a pair is the one whose
    outward normal points within 90 deg of ``reference_deg`` (that kind's first view's; None: no view
    said which, the first)."""

    shades: tuple[float, float, float, float]
    sigma: tuple[float, float, float, float]
    reference_deg: tuple[float, float] | None = None
    # Whether a view has told each face's shade itself (not only through the face opposite, nor not at all).
    told: tuple[bool, bool, bool, bool] = (True, True, True, True)

    def facing(self, facing_deg: tuple[float, float] | None) -> ShadePrior:
        """The shades of the end face and the long face whose outward normals point ``facing_deg`` (deg;
        None: the first of each pair)."""
        end, long = _slots(facing_deg, self.reference_deg)
        return ShadePrior((self.shades[end], self.shades[2 + long]), (self.sigma[end], self.sigma[2 + long]))

    def told_facing(self, facing_deg: tuple[float, float] | None) -> tuple[bool, bool]:
        """Whether a view has told the shade of the end face and of the long face facing ``facing_deg``
        itself (see facing)."""
        end, long = _slots(facing_deg, self.reference_deg)
        return self.told[end], self.told[2 + long]


class ShadeEstimate:
    """The side shades (each end face's, each long face's) a track's views tell of its part at its
    estimated height.

    Decided together with the size (length, width), in information form: a sliver's shade trades with
    the size next to it, one view's reading of either leans towards what its fit was lent, and told
    apart the track's shades stayed near where they started (the tests' 5 mm box at 10 deg, its height
    given: its end faces learnt 0.59 for 0.71-0.72). Its views see the faces at other widths, and
    together they decide both (0.66; with each view's shades told over every window near its box too,
    see boxfit.fit_box. bench/heights_random.py's scene 79, a 5 mm box: 0.63 -> 0.70 for 0.70, its
    pose with the height given 0.110 -> 0.094 mm off, 0.026 with the rendered shades of both faces
    lent: its long faces are slivers no view tells). A part crossing the view shows one end face, then
    the other: under a lamp to one side they differ (SceneSpec.side_light; learnt as one, the shade of
    the first held the fits of the second: the tests' 20 mm box straight down, its height given, 0.096
    mm off on average, 95th percentile 0.55, against 0.020 and 0.054 with a shade for each). Each face
    has its own, tied to the one opposite to within ``track.opposite_shade_sigma``: a face not seen yet
    starts from the other's (under an even light they are alike)."""

    def __init__(self, cfg: TrackConfig) -> None:
        self._cfg = cfg
        # The views' information on (length, width, end shades a and b, long shades a and b) and its
        # vector, summed; which way each kind's first face faces (see FaceShades).
        self._info = np.zeros((6, 6))
        self._vec = np.zeros(6)
        self._reference_deg: tuple[float, float] | None = None

    def add(self, view: ViewShades) -> None:
        info, vec = _told(view, self._cfg)
        if self._reference_deg is None:
            self._reference_deg = view.facing_deg
        at = _placed(view.facing_deg, self._reference_deg)
        # Newer views weigh more: the information kept fades over shade_memory_views views.
        keep = 1.0 - 1.0 / self._cfg.shade_memory_views
        self._info *= keep
        self._vec *= keep
        self._info[np.ix_(at, at)] += info
        self._vec[at] += vec

    def lent(self) -> FaceShades | None:
        """The shades to lend a fit (a shade no view has told yet, nor the face opposite: middling, held as
        weakly as a fit holds it alone); None before any view has told one."""
        told = np.diag(self._info)[2:] > 0
        if not told.any():
            return None
        # A face opposite one told is known through it.
        known = told | told.reshape(2, 2)[:, ::-1].reshape(4)
        info = self._info.copy()
        tie = 1.0 / self._cfg.opposite_shade_sigma**2
        for a in (2, 4):
            info[np.ix_([a, a + 1], [a, a + 1])] += tie * np.array([[1.0, -1.0], [-1.0, 1.0]])
        # The size and the shades known, solved together; a shade unknown is out of the solution.
        use = [0, 1, *(2 + np.nonzero(known)[0])]
        cov = np.linalg.pinv(info[np.ix_(use, use)])
        solved = cov @ self._vec[use]
        shades, sigma = np.full(4, 0.5), np.full(4, math.inf)
        shades[known] = solved[2:]
        sigma[known] = np.maximum(np.sqrt(np.maximum(np.diag(cov)[2:], 0.0)), self._cfg.known_shade_sigma)
        return FaceShades(tuple(map(float, shades)), tuple(map(float, sigma)), self._reference_deg,
                          tuple(map(bool, told)))


def _slots(facing_deg: tuple[float, float] | None, reference_deg: tuple[float, float] | None) -> tuple[int, int]:
    """Which of each pair (end faces, long faces) faces ``facing_deg``: 0 the one facing within 90 deg of
    ``reference_deg``, 1 the one opposite (0 where either is not said)."""
    if facing_deg is None or reference_deg is None:
        return 0, 0
    end, long = (int(math.cos(math.radians(f - r)) < 0.0) for f, r in zip(facing_deg, reference_deg, strict=True))
    return end, long


def _placed(facing_deg: tuple[float, float] | None, reference_deg: tuple[float, float] | None) -> list[int]:
    """Where a view's (length, width, end shade, long shade) go among (length, width, end shades a and b,
    long shades a and b): its faces by which way they face (see _slots)."""
    end, long = _slots(facing_deg, reference_deg)
    return [0, 1, 2 + end, 4 + long]


def _told(view: ViewShades, cfg: TrackConfig) -> tuple[np.ndarray, np.ndarray]:
    """What ``view`` adds (information 4x4 and vector over length, width and the two shades): only the
    shades it tells to track.shade_view_max_sigma, no surer than track.shade_view_min_sigma (nor than
    the model is right: ViewShades.variances); a view that tells them only apart adds them alone."""
    sigma = np.sqrt(np.array(view.variances))
    shades = np.array(view.shades)
    told = np.isfinite(shades) & (sigma <= cfg.shade_view_max_sigma)
    least = np.maximum(sigma, cfg.shade_view_min_sigma) ** 2
    use = 2 + np.nonzero(told)[0]
    if view.info is None or not told.any():
        info = np.zeros((4, 4))
        info[use, use] = 1.0 / least[told]
        at = np.concatenate([np.zeros(2), np.where(told, shades, 0.0)])
        return info, info @ at
    # A shade it does not tell is marginalised out (not held where the fit had it: what the view tells
    # of the size next to that face would lean towards it).
    sub, info, vec = _kept(view, told)
    # No surer than the least variance of each shade it tells: its information scaled down to that.
    alone = np.diag(np.linalg.pinv(info))[2:]
    return _embedded(sub, info, vec, min(1.0, float(np.min(alone / least[told]))))


def _kept(view: ViewShades, shades: np.ndarray) -> tuple[list[int], np.ndarray, np.ndarray]:
    """``view``'s information and vector on the size and the ``shades`` (which of end, long) alone, the
    rest marginalised out, and which of (length, width, end shade, long shade) they are."""
    sub = [0, 1, *(2 + np.nonzero(shades)[0])]
    info, vec = marginalised(view.info, view.vec, sub, [i for i in range(4) if i not in sub])
    return sub, info, vec


def _embedded(sub: list[int], info: np.ndarray, vec: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Information and vector on ``sub`` of (length, width, end shade, long shade), scaled by ``scale``,
    as the 4x4 and 4 a view adds (zero elsewhere)."""
    full, full_vec = np.zeros((4, 4)), np.zeros(4)
    full[np.ix_(sub, sub)], full_vec[sub] = info * scale, vec * scale
    return full, full_vec


def read_together(views: list[ViewShades], min_sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """The side shades ``views`` of one box tell together, with the size they share: each end face's,
    then each long face's (as FaceShades orders them, the face the first view that says which it saw
    first), and their 1 sigma (inf: no view shows that face). Every shade a view shows counts, told or
    not (a sliver's reading as dark as the belt, or as bright as the top, is what this is for), each
    view no surer of a shade alone (its size unknown) than ``min_sigma``. A view whose information is
    not finite tells nothing."""
    info, vec = np.zeros((6, 6)), np.zeros(6)
    reference = next((view.facing_deg for view in views if view.facing_deg is not None), None)
    for view in views:
        if view.info is None or view.vec is None or not (np.isfinite(view.info).all() and np.isfinite(view.vec).all()):
            continue
        shown = np.diag(view.info)[2:] > 0
        if not shown.any():
            continue
        sub, kept, kept_vec = _kept(view, shown)
        alone = np.diag(_inverse(kept))[2:]
        at = _placed(view.facing_deg, reference)
        full, full_vec = _embedded(sub, kept, kept_vec, min(1.0, float(np.min(alone / min_sigma**2))))
        info[np.ix_(at, at)] += full
        vec[at] += full_vec
    shades, sigma = np.full(4, math.nan), np.full(4, math.inf)
    shown = np.diag(info)[2:] > 0
    if shown.any():
        use = [0, 1, *(2 + np.nonzero(shown)[0])]
        cov = _inverse(info[np.ix_(use, use)])
        shades[shown] = (cov @ vec[use])[2:]
        sigma[shown] = np.sqrt(np.diag(cov)[2:])
    return shades, sigma


def _inverse(info: np.ndarray) -> np.ndarray:
    """The covariance of an information matrix (symmetric, positive semi-definite up to rounding), each
    combination of parameters taken to hold at least _UNTOLD of the most any does: positive definite."""
    values, vectors = np.linalg.eigh(0.5 * (info + info.T))
    least = max(float(np.abs(values).max(initial=0.0)), 1.0) * _UNTOLD
    return (vectors / np.maximum(values, least)) @ vectors.T
