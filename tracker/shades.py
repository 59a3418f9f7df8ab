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

from tracker.boxfit import ShadePrior, ViewShades
from tracker.config import TrackConfig


class ShadeEstimate:
    """The side shades (end faces, long faces) a track's views tell of its part at its estimated height."""

    def __init__(self, cfg: TrackConfig) -> None:
        self._cfg = cfg
        self._weight = np.zeros(2)  # the views' information on each shade (1 / variance), summed
        self._weighted = np.zeros(2)  # and their shades weighted by it

    def add(self, view: ViewShades) -> None:
        cfg = self._cfg
        sigma = np.sqrt(np.array(view.variances))
        shades = np.array(view.shades)
        told = np.isfinite(shades) & (sigma <= cfg.shade_view_max_sigma)
        # Newer views weigh more: the information kept fades over shade_memory_views views.
        self._weight *= 1.0 - 1.0 / cfg.shade_memory_views
        self._weighted *= 1.0 - 1.0 / cfg.shade_memory_views
        weight = np.where(told, 1.0 / np.maximum(sigma, cfg.shade_view_min_sigma) ** 2, 0.0)
        self._weight += weight
        self._weighted += weight * np.where(told, shades, 0.0)

    def prior(self) -> ShadePrior | None:
        """The shades to lend a fit (a shade no view has told yet: middling, held as weakly as a fit
        holds it alone); None before any view has told one."""
        if not np.any(self._weight > 0):
            return None
        told = self._weight > 0
        shades = np.divide(self._weighted, self._weight, out=np.full(2, 0.5), where=told)
        sigma = np.maximum(np.divide(1.0, np.sqrt(self._weight), out=np.full(2, math.inf), where=told),
                           self._cfg.known_shade_sigma)
        return ShadePrior((float(shades[0]), float(shades[1])), (float(sigma[0]), float(sigma[1])))
