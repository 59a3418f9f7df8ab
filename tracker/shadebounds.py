"""The shades a box's side faces may have, from the part's level and the belt's.

A side face's shade is its contrast with the belt as a fraction of the top's (tracker/box.py). Lit
from above, a side is darker than the top. On a part brighter than the belt its shade then lies
between 0 (as dark as the belt) and 1 (as bright as the top); on a part darker than the belt a
darker side has more contrast than the top, and its shade lies between 1 and that of black,
belt / (belt - top) (a black side differs from the belt by the belt's whole level). A dark part's
sides read 1.07-1.13 (rendered: 0.8 and 0.65 of a 40 grey top on a 150 belt), which the bounds of
a bright part took for sides as bright as the top: with its height given such a 5-10 mm box was
off by up to 0.8 mm, and `auto` found 5 mm boxes flat.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ShadeBounds:
    """Where a fit keeps the side shades (``low``-``high``: a fit that would need others is wandering in
    a flat valley); which a view tells (``told``, from, to: a side that reads like the top, or as dark
    as the belt, tells none); beyond which a view's shade is no side's (``possible``, from, to: the
    box explains the view only as another shape would, boxfit.ViewShades.outside); and where a fit
    starts a shade no view has told (``start``)."""

    low: float
    high: float
    told: tuple[float, float]
    possible: tuple[float, float]
    start: float

    def __post_init__(self) -> None:
        if not (0.0 < self.low <= self.told[0] < self.told[1] <= self.high and self.low <= self.start <= self.high
                and self.low <= self.possible[0] < self.possible[1] <= self.high):
            raise ValueError(f"shade bounds: expected 0 < low <= told from < told to <= high, possible within "
                             f"[low, high] and start too, got {self}")


# A part brighter than the belt: kept from nearly the belt's level (a window read against a side face
# as dark as the belt has no contrast to read; the measurement refuses those) to half again the top's
# contrast; told, and possible, below the top's. A floor of 0.01 (tried for a side a lamp leaves as
# dark as the belt, which it did place) let the fits of tall parts wander into sides they do not have:
# under a side lamp 50 -> 37 of 60 random scenes met every bound, some 8 mm off with the height given.
BRIGHT = ShadeBounds(0.1, 1.5, (0.1, 1.0), (0.1, 1.0), 0.5)


def shade_bounds(part_level: float, belt_level: float) -> ShadeBounds:
    """The bounds for a part whose top reads ``part_level`` on a belt of ``belt_level`` (grey levels)."""
    if part_level >= belt_level:
        return BRIGHT
    black = belt_level / (belt_level - part_level)
    # As much room beyond black as a bright part has beyond its top's shade. A side brighter than the
    # top is no more impossible than one a little darker is likely: a dark part's sides differ from its
    # top by a few grey levels (1.07 and 1.13 rendered, whose sliver faces read 0.2-0.7 in some views of
    # a 20 mm box at 10 deg): only a side as bright as the belt, or darker than black, is no side's.
    return ShadeBounds(BRIGHT.low, black + BRIGHT.high - BRIGHT.told[1], (1.0, black), (BRIGHT.low, black),
                       0.5 * (1.0 + black))
