"""The vision pipeline: frame -> segment -> measure -> track, one frame at a time.

Deterministic by construction: its output depends only on the frames, their
capture times and the configuration, never on wall-clock time or threads, so a
recording replays to byte-identical poses.
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from tracker.calibration import Calibration
from tracker.config import TrackerConfig
from tracker.measure import Measurer
from tracker.poses import FrameResult
from tracker.segment import Segmenter
from tracker.track import Tracker
from tracker.undistort import BeltMapper

STAGES = ("segment", "undistort", "measure", "track")


class Pipeline:
    def __init__(self, calibration: Calibration, config: TrackerConfig | None = None) -> None:
        calibration.require_belt()
        self.calibration = calibration
        self.config = config or TrackerConfig()
        self.segmenter = Segmenter(self.config.segment)
        self.mapper = mapper = BeltMapper(calibration, self.config.measure.part_height_mm)
        self.measurer = Measurer(mapper, self.config.measure)
        outline = mapper.view_outline_mm().astype(np.float32)
        self.tracker = Tracker(self.config.track, lambda x, y: cv2.pointPolygonTest(outline, (x, y), False) >= 0)
        # Time spent per stage on the last frame (ns); for the status line and the benchmark only.
        self.stage_ns = dict.fromkeys(STAGES, 0)

    def process(self, index: int, frame: np.ndarray, t_ns: int) -> FrameResult:
        clock = time.perf_counter_ns
        t0 = clock()
        mask = self.segmenter(frame)
        t1 = clock()
        undistort_before = self.mapper.spent_ns
        measurements = self.measurer(frame, self.segmenter.reference, mask)
        t2 = clock()
        objects = self.tracker.step(measurements, t_ns)
        t3 = clock()
        undistort = self.mapper.spent_ns - undistort_before
        self.stage_ns.update(segment=t1 - t0, undistort=undistort, measure=t2 - t1 - undistort, track=t3 - t2)
        return FrameResult(index, t_ns, objects, tuple(measurements))
