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

import numpy as np

from tracker.boxfit import ShadePrior, ViewShades, marginalised
from tracker.config import TrackConfig


class ShadeEstimate:
    """The side shades (end faces, long faces) a track's views tell of its part at its estimated height.

    Decided together with the size (length, width), in information form: a sliver's shade trades with
    the size next to it, one view's reading of either leans towards what its fit was lent, and told
    apart the track's shades stayed near where they started (the tests' 5 mm box at 10 deg, its height
    given: its end faces learnt 0.59 for 0.71-0.72). Its views see the faces at other widths, and
    together they decide both (0.66; with each view's shades told over every window near its box too,
    see boxfit.fit_box. bench/heights_random.py's scene 79, a 5 mm box: 0.63 -> 0.70 for 0.70, its
    pose with the height given 0.110 -> 0.094 mm off, 0.026 with the rendered shades of both faces
    lent: its long faces are slivers no view tells)."""

    def __init__(self, cfg: TrackConfig) -> None:
        self._cfg = cfg
        # The views' information on (length, width, end shade, long shade) and its vector, summed.
        self._info = np.zeros((4, 4))
        self._vec = np.zeros(4)

    def add(self, view: ViewShades) -> None:
        info, vec = _told(view, self._cfg)
        # Newer views weigh more: the information kept fades over shade_memory_views views.
        keep = 1.0 - 1.0 / self._cfg.shade_memory_views
        self._info = keep * self._info + info
        self._vec = keep * self._vec + vec

    def prior(self) -> ShadePrior | None:
        """The shades to lend a fit (a shade no view has told yet: middling, held as weakly as a fit
        holds it alone); None before any view has told one."""
        told = np.diag(self._info)[2:] > 0
        if not told.any():
            return None
        # The size and the shades told, solved together; a shade untold is out of the solution.
        use = [0, 1, *(2 + np.nonzero(told)[0])]
        cov = np.linalg.pinv(self._info[np.ix_(use, use)])
        solved = cov @ self._vec[use]
        shades, sigma = np.full(2, 0.5), np.full(2, math.inf)
        shades[told] = solved[2:]
        sigma[told] = np.maximum(np.sqrt(np.maximum(np.diag(cov)[2:], 0.0)), self._cfg.known_shade_sigma)
        return ShadePrior((float(shades[0]), float(shades[1])), (float(sigma[0]), float(sigma[1])))


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
    sub = [0, 1, *use]
    info, vec = marginalised(view.info, view.vec, sub, [i for i in range(4) if i not in sub])
    # No surer than the least variance of each shade it tells: its information scaled down to that.
    alone = np.diag(np.linalg.pinv(info))[2:]
    scale = min(1.0, float(np.min(alone / least[told])))
    full, full_vec = np.zeros((4, 4)), np.zeros(4)
    full[np.ix_(sub, sub)], full_vec[sub] = info * scale, vec * scale
    return full, full_vec
