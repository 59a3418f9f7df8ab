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
from tracker.measure import HALF_WINDOW_PX, Measurer
from tracker.poses import BeltState, FrameResult
from tracker.segment import BeltMotion, RegionOfInterest, Segmenter
from tracker.track import Tracker
from tracker.undistort import BeltMapper

STAGES = ("segment", "undistort", "measure", "track")


class Pipeline:
    def __init__(self, calibration: Calibration, config: TrackerConfig | None = None) -> None:
        calibration.require_belt()
        self.calibration = calibration
        self.config = config or TrackerConfig()
        seg = self.config.segment
        self.roi = RegionOfInterest(seg, calibration)
        self.segmenter = Segmenter(seg, None if self.roi.full else self.roi.mask)
        self.motion = BeltMotion(seg, self.roi.box)
        self.mapper = mapper = BeltMapper(calibration, self.config.measure.part_height_mm)
        self.measurer = Measurer(mapper, self.config.measure, self.roi)
        outline = mapper.view_outline_mm().astype(np.float32)
        self.tracker = Tracker(self.config.track, lambda x, y: cv2.pointPolygonTest(outline, (x, y), False) >= 0)
        x, y, w, h = self.roi.box
        self._belt_centre_px = np.array([[x + w / 2, y + h / 2]])
        self._last: FrameResult | None = None
        self._last_moved_ns: int | None = None  # capture time of the last frame that was not a repeat
        self._scene_faults = 0
        # Time spent per stage on the last frame (ns); for the status line and the benchmark only.
        self.stage_ns = dict.fromkeys(STAGES, 0)

    @property
    def roi_px(self) -> np.ndarray:
        """The region of interest as an image polygon (for previews and the live view)."""
        return self.roi.polygon_px

    def process(self, index: int, frame: np.ndarray, t_ns: int) -> FrameResult:
        clock = time.perf_counter_ns
        t0 = clock()
        motion = self.motion(frame)
        if motion.repeated and self._last is not None:
            # A repeat of the previous image holds no news: the parts are where they were.
            self.tracker.hold(t_ns)
            self.stage_ns.update(segment=clock() - t0, undistort=0, measure=0, track=0)
            self._last = FrameResult(index, t_ns, self._last.objects, (), self._belt(motion, t_ns), repeated=True)
            return self._last
        self.segmenter.belt_moving = np.hypot(motion.dx_px, motion.dy_px) >= self.config.segment.belt_still_px
        mask = self.segmenter(frame)
        self.measurer.blur_px = self.segmenter.blur_px
        self.measurer.half_window_px = HALF_WINDOW_PX + self.segmenter.blur_px // 2 + self.segmenter.blur_px // 2
        t1 = clock()
        scene_fault = self.segmenter.foreground_fraction > self.config.segment.scene_fault_fraction
        undistort_before = self.mapper.spent_ns
        if scene_fault:
            # Not understood (lights, a bumped camera): measure nothing, hold the tracks; if it
            # lasts, the scene is the new normal: learn the belt anew.
            self._scene_faults += 1
            if self._scene_faults >= self.config.segment.relearn_after_frames:
                self.segmenter.reset(frame)
                self._scene_faults = 0
            self.tracker.hold(t_ns)
            objects = tuple(o for o in (self._last.objects if self._last else ()))
            self.stage_ns.update(segment=t1 - t0, undistort=0, measure=0, track=0)
            self._last = FrameResult(index, t_ns, objects, (), self._belt(motion, t_ns), scene_fault=True)
            return self._last
        self._scene_faults = 0
        measurements = self.measurer(frame, self.segmenter.reference, mask)
        t2 = clock()
        objects = self.tracker.step(measurements, t_ns)
        t3 = clock()
        undistort = self.mapper.spent_ns - undistort_before
        self.stage_ns.update(segment=t1 - t0, undistort=undistort, measure=t2 - t1 - undistort, track=t3 - t2)
        self._last = FrameResult(index, t_ns, objects, tuple(measurements), self._belt(motion, t_ns))
        return self._last

    def _belt(self, motion, t_ns: int) -> BeltState:
        """The belt's velocity on the belt plane (mm/s) from its image shift at the region's centre."""
        if motion.repeated:
            return BeltState(0.0, 0.0, True)
        since, self._last_moved_ns = self._last_moved_ns, t_ns
        if since is None or t_ns <= since:
            return BeltState()
        a = self.mapper.to_mm(self._belt_centre_px)
        b = self.mapper.to_mm(self._belt_centre_px + [motion.dx_px, motion.dy_px])
        vx, vy = (b - a)[0] / ((t_ns - since) / 1e9)
        return BeltState(float(vx), float(vy), False)
