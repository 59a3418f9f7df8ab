"""Segmentation: frame in, foreground mask out, with ``reference`` the expected empty belt.

Two belt models behind one interface (``segment.model`` in the configuration):
``reference`` (reference.py) for belts whose look stays put, exact to sub-pixel edges;
``textured`` (textured.py) for real belts whose texture moves with the parts; ``auto``
(the default) is the first until look.py sees the belt's own look move, then the second
(the pipeline switches). Around them: the region of interest (roi.py), the belt's motion
(motion.py) and the clutter guard (guard.py).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from tracker.config import SegmentConfig
from tracker.segment.reference import Segmenter
from tracker.segment.textured import TexturedSegmenter
from tracker.segment.views import UpsampledView

__all__ = ["BeltModel", "Segmenter", "TexturedSegmenter", "make_segmenter"]


class BeltModel(Protocol):
    # Expected empty-belt image (float32, frame size) for sub-pixel edges; None before the first frame.
    reference: np.ndarray | None
    # Where the last frame's light parts cast shadows (> 0 in them, indexable like the frame), for a
    # model whose reference cannot tell a shadow from the belt's texture; None: not told.
    shadows: UpsampledView | None

    def __call__(self, frame: np.ndarray) -> np.ndarray: ...


def make_segmenter(config: SegmentConfig, roi: np.ndarray, mm_per_px: float = 1.0) -> BeltModel:
    """Belt model ``config.model`` ("reference" or "textured"; "auto" is the pipeline's to resolve); ``roi``
    is the region of interest (uint8 mask), ``mm_per_px`` the belt's scale at the image centre."""
    if config.model == "textured":
        return TexturedSegmenter(config, roi, mm_per_px)
    return Segmenter(config, roi)
