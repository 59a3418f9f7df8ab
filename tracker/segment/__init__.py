"""Segmentation: which pixels of a frame are parts, on a belt whose texture moves with them.

``Segmenter`` (tracker/segment/reference.py) differences each frame against a learnt reference of
the empty belt, after a blur that averages the belt's fine texture out; ``BeltMotion``
(motion.py) measures how the belt moved since the previous frame; ``RegionOfInterest`` (roi.py)
is the belt area outside which nothing is a part.
"""

from tracker.segment.motion import BeltMotion, MotionEstimate
from tracker.segment.reference import Segmenter
from tracker.segment.roi import RegionOfInterest

__all__ = ["BeltMotion", "MotionEstimate", "RegionOfInterest", "Segmenter"]
