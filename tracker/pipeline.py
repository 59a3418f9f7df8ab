"""The vision pipeline: frame -> segment -> measure -> track, one frame at a time.

Deterministic by construction: its output depends only on the frames, their
capture times and the configuration, never on wall-clock time or threads, so a
recording replays to byte-identical poses.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time

import cv2
import numpy as np

from tracker.calibration import Calibration
from tracker.config import TrackerConfig
from tracker.errors import BadInput
from tracker.measure import Measurer
from tracker.poses import FrameResult
from tracker.segment import make_segmenter
from tracker.segment.guard import ClutterGuard
from tracker.segment.look import MovingLook
from tracker.segment.motion import BeltMotion
from tracker.segment.roi import roi_mask, roi_polygon_px
from tracker.track import Tracker
from tracker.undistort import BeltMapper

log = logging.getLogger(__name__)

STAGES = ("segment", "undistort", "measure", "track")
# On a textured belt, the edges of parts whose contrast its texture disturbs are measured through this
# slight blur (px; measure.smooth_texture_ratio): it averages the belt's texture over neighbouring rows
# too, and as it is symmetric the edges stay where they are.
_TEXTURE_BLUR_PX = 1.0


class Pipeline:
    def __init__(self, calibration: Calibration, config: TrackerConfig | None = None) -> None:
        calibration.require_belt()
        self.calibration = calibration
        self.config = config or TrackerConfig()
        if self.config.measure.estimate_height and calibration.approximate:
            # An approximate calibration assumes the camera's distance: how a silhouette changes across
            # the view then tells a height only as a fraction of that guess, never in mm.
            log.warning("calibration %s is approximate (%s): without the camera's pose measured on a board no "
                        "height can be estimated, so parts are measured flat (--part-height MM gives their height)",
                        calibration.source, calibration.approximate)
            measure = dataclasses.replace(self.config.measure, estimate_height=False)
            self.config = dataclasses.replace(self.config, measure=measure)
        # A given height is reported as such; an estimated one comes from each track.
        self._height_mm = 0.0 if self.config.measure.estimate_height else self.config.measure.part_height_mm
        if self.config.measure.part_height_mm >= calibration.camera_height_mm():
            raise BadInput(f"part height: expected less than the camera's height above the belt "
                           f"({calibration.camera_height_mm():.0f} mm), got {self.config.measure.part_height_mm:g} mm")
        seg = self.config.segment
        # The region of interest as an image polygon (pixels; None: the whole frame), for previews.
        self.roi_px = roi_polygon_px(seg, calibration)
        self._roi = roi_mask(self.roi_px, calibration.size)
        self.roi_mask = None if self.roi_px is None else self._roi
        self._roi_centre_px = np.array(cv2.boundingRect(self._roi), dtype=np.float64)
        self._roi_centre_px = self._roi_centre_px[:2] + self._roi_centre_px[2:] / 2
        self.mapper = mapper = BeltMapper(calibration, self.config.measure.part_height_mm)
        # With "auto", the plain model until the belt's own look is seen to move (then _use_model).
        self._look = MovingLook(seg, self._roi) if seg.model == "auto" else None
        self._offered_ids: set[int] = set()
        # Under auto: the last frame (the belt's motion into the frame the model turns at is measured from it).
        self._last_frame: tuple[np.ndarray, int] | None = None
        if self._look is not None and not self._look.watched_tiles:
            log.warning("belt model: the region of interest is too thin to watch the belt's look (no tile of %d "
                        "along its longer side lies half in it): the plain belt model throughout; set "
                        "segment.model to \"textured\" for a belt whose texture moves", seg.auto_tiles)
            self._look = None
        self._use_model("reference" if seg.model == "auto" else seg.model)
        outline = mapper.view_outline_mm().astype(np.float32)
        # With --part-height auto, a part's views vote on its height track.height_vote_step_mm apart, closer
        # on a small view (a fraction of the square root of the belt area it sees): a part crossing it
        # decides as early in its crossing as one crossing a larger view.
        track = self.config.track
        view_size_mm = math.sqrt(cv2.contourArea(outline))
        vote_step_mm = (min(track.height_vote_step_mm, track.height_vote_step_fraction * view_size_mm)
                        if self.config.measure.estimate_height else None)
        self.tracker = Tracker(self._track_config, lambda x, y: cv2.pointPolygonTest(
            outline, (x + self._belt_offset_mm[0], y + self._belt_offset_mm[1]), False) >= 0, vote_step_mm)
        # Time spent per stage on the last frame (ns); for the status line and the benchmark only.
        self.stage_ns = dict.fromkeys(STAGES, 0)

    def _use_model(self, model: str) -> None:
        """Segment and measure with belt model ``model`` ("reference" or "textured") from the next frame on."""
        self.model = model
        seg, measure = self.config.segment, self.config.measure
        roi = self._roi
        self.segmenter = make_segmenter(dataclasses.replace(seg, model=model), roi,
                                        self.calibration.mm_per_px_at_centre())
        if model == "reference" and 0 < seg.faint_threshold < measure.min_contrast:
            # The faint faces the plain belt model joins to a part are read too (on a textured belt the
            # knurl comes near a face, and min_contrast keeps those windows out).
            measure = dataclasses.replace(measure, min_contrast=float(seg.faint_threshold))
        textured = model == "textured"
        track = self.config.track
        # The tracks' settings under this model (new tracks take them: see track.view_height_sigma_coarse_mm).
        self._track_config = (dataclasses.replace(track, view_height_sigma_mm=max(track.view_height_sigma_mm,
                                                                                  track.view_height_sigma_coarse_mm))
                              if textured else track)
        self.measurer = Measurer(self.mapper, measure, _TEXTURE_BLUR_PX if textured else 0.0,
                                 coarse_reference=textured)
        # The belt's own motion is measured where the belt model needs it (textured belts).
        self.motion = BeltMotion(roi) if textured else None
        self._last_t_ns: int | None = None
        self._belt_mm_s = (0.0, 0.0)
        # Blobs this close to the region's edge are clipped (the measurement itself checks the image's).
        edge_px = measure.border_margin_px + getattr(self.segmenter, "edge_px", 0)
        self.guard = ClutterGuard(roi, seg.scene_fault_fraction, seg.max_blobs,
                                  edge_px if self.roi_px is not None or textured else 0)
        # Where the belt has carried a point since the start (mm, world frame). With the belt's motion
        # measured, parts are tracked on the belt, where a part riding it stands still through the
        # belt's stops, slow phases and duplicate frames; without it the offset stays zero.
        self._belt_offset_mm = np.zeros(2)

    def _watch_look(self, index: int, frame: np.ndarray) -> bool:
        """segment.model "auto": once the belt's own look moves with it, the textured model from this frame
        on; whether it turned now (the kept tracks then move into the belt's frame: see process)."""
        if self._look is None or not self._look(frame):
            return False
        log.info("belt model: the belt's own look moves with it (%.0f %% of the view's tiles change from frame to "
                 "frame): the textured belt model from frame %d on (segment.model chooses one)",
                 100 * self._look.changing, index)
        self._look = None
        self._use_model("textured")
        # The belt's motion from the last frame to this one: the kept tracks move into its frame with it. (The
        # last frame is held, not copied: from a source that reuses its buffer it reads as a repeat, no
        # motion, and the tracks move into the belt's frame as they were.)
        self.motion(self._last_frame[0])
        self._last_t_ns = self._last_frame[1]
        self._last_frame = None
        self.tracker.config = self._track_config
        # Tracks of parts offered for picking go on under their ids (a PLC that took one is not offered it
        # again under a new id, if the textured model finds it before it coasts out), in the belt's frame,
        # which is the world's at this instant. The rest were never offered and end (mostly the moving belt).
        self.tracker.tracks[:] = [t for t in self.tracker.tracks if t.id in self._offered_ids]
        self._offered_ids = set()
        return True

    def process(self, index: int, frame: np.ndarray, t_ns: int) -> FrameResult:
        clock = time.perf_counter_ns
        t0 = clock()
        turned = self._watch_look(index, frame)
        belt = self._belt_motion(frame, t_ns)
        if turned:
            for track in self.tracker.tracks:
                track.into_frame_moving_at(*belt)
        if self._look is not None:
            self._last_frame = (frame, t_ns)
        mask = self.segmenter(frame)
        if self.roi_mask is not None and self.motion is None:
            mask = cv2.bitwise_and(mask, self.roi_mask)
        guarded = self.guard(mask)
        t1 = clock()
        undistort_before = self.mapper.spent_ns
        measurements = self.measurer(frame, self.segmenter.reference, guarded.mask, self._known(t_ns),
                                     self.segmenter.shadows, self.segmenter.unsure)
        if guarded.at_edge:
            # A blob reaching the edge of the region of interest may go on outside it: clipped.
            measurements = [dataclasses.replace(m, clipped=True) if m.bbox_px in guarded.at_edge else m
                            for m in measurements]
        t2 = clock()
        objects = self._track(measurements, t_ns, belt)
        if self._look is not None:
            if self._look.unsure:
                # The belt model is not settled (auto, its first frames or a belt starting to move): what the
                # plain model makes of a moving textured belt is no part to pick.
                objects = tuple(dataclasses.replace(o, pickable=False) for o in objects)
            # The parts in view offered for picking (until the model turns: see _watch_look).
            self._offered_ids = {o.id for o in objects if o.pickable} | (self._offered_ids & {o.id for o in objects})
        if self._height_mm:
            objects = tuple(dataclasses.replace(o, height_mm=self._height_mm) for o in objects)
        t3 = clock()
        undistort = self.mapper.spent_ns - undistort_before
        self.stage_ns.update(segment=t1 - t0, undistort=undistort, measure=t2 - t1 - undistort, track=t3 - t2)
        return FrameResult(index, t_ns, objects, tuple(measurements), belt_mm_s=belt,
                           scene_fault=guarded.scene_fault)

    def _known(self, t_ns: int) -> list:
        """The tracked parts where they are expected now, in the world frame (boxes lean on their sizes;
        tracks on a moving belt live in its frame, offset from the world's by where it has carried them)."""
        if self.config.measure.part_height_mm <= 0 and not self.config.measure.estimate_height:
            return []
        return self.tracker.known(t_ns, tuple(map(float, self._belt_offset_mm)))

    def _track(self, measurements: list, t_ns: int, belt: tuple[float, float] | None) -> tuple:
        if belt is None:
            return self.tracker.step(measurements, t_ns)
        ox, oy = self._belt_offset_mm
        on_belt = [m.moved(-ox, -oy) for m in measurements]
        raw = {id(b): m for b, m in zip(on_belt, measurements, strict=True)}
        return tuple(
            dataclasses.replace(o, x_mm=o.x_mm + ox, y_mm=o.y_mm + oy, corners_mm=o.corners_mm + (ox, oy),
                                vx_mm_s=o.vx_mm_s + belt[0], vy_mm_s=o.vy_mm_s + belt[1],
                                raw=None if o.raw is None else raw[id(o.raw)])
            for o in self.tracker.step(on_belt, t_ns))

    def _belt_motion(self, frame: np.ndarray, t_ns: int) -> tuple[float, float] | None:
        """The belt's velocity (mm/s, world frame) from its shift since the last frame; None when not measured."""
        if self.motion is None:
            return None
        dx, dy = self.motion(frame)
        self.segmenter.shift_px = (dx, dy)
        self.segmenter.duplicate = self.motion.duplicate
        if self.motion.duplicate:
            return self._belt_mm_s  # not a new view of the belt: its last velocity holds
        last, self._last_t_ns = self._last_t_ns, t_ns
        if last is not None and t_ns > last:
            a, b = self.mapper.to_mm(np.array([self._roi_centre_px, self._roi_centre_px + (dx, dy)]))
            dt_s = (t_ns - last) / 1e9
            self._belt_mm_s = (float(b[0] - a[0]) / dt_s, float(b[1] - a[1]) / dt_s)
            self._belt_offset_mm = self._belt_offset_mm + (b - a)
        return self._belt_mm_s
