"""Score the pipeline on a real video against its hand labels (``truth/<stem>.truth.json``).

Used by the real-video tests and ``bench/real_videos.py``. The labels give, per part, the frames
it is wholly in view and its bounding box at one frame; and the number of parts wholly in view
at sample frames. A track *matches* a part when one of its measurements within a few frames of
the part's labelled frame lies inside the labelled box. Scored:

- found: parts matched by exactly one track (one track per part, not a chain of them);
- phantoms: tracks with at least ``PHANTOM_MEASUREMENTS`` measurements that match no part;
- counts: sample frames where the measured, unclipped objects number the labelled parts.
"""

from __future__ import annotations

import json
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from tracker.calibrate.approximate import nadir_calibration
from tracker.config import MeasureConfig, SegmentConfig, TrackConfig, TrackerConfig
from tracker.pipeline import Pipeline
from tracker.poses import FrameResult

PHANTOM_MEASUREMENTS = 10
# Tracked on the belt (its motion measured), a part riding it hardly accelerates: a tenth of the
# default, which must allow for a belt starting and stopping.
_ON_BELT_ACCEL_MM_S2 = 200.0
# Frames either side of a part's labelled frame in which a track may show it (labels are +-3 frames).
_MATCH_FRAMES = 4
# The labelled box is grown by this fraction of its size (a centroid on the box's edge still matches).
_MATCH_GROW = 0.1


@dataclass(frozen=True)
class RealVideo:
    """A real video and how it is set up: the belt area and an approximate straight-down scale."""

    file: str
    # Approximate scale from a part of known size (nadir camera; no calibration exists).
    mm_per_px: float
    roi_px: tuple = ()
    # Score only up to this frame (None: all).
    last_frame: int | None = None
    labelled: bool = True
    # The narrowest part's width (mm): marks across the belt that are thinner are no parts.
    min_part_mm: float = 0.0
    # Blobs smaller than this are no parts (the installation's smallest part, halved).
    min_area_mm2: float = 300.0

    @property
    def stem(self) -> str:
        return Path(self.file).stem

    def config(self) -> TrackerConfig:
        """Textured belt model, the belt area, and measurement noise of about a pixel (real edges on
        a textured belt, compression) instead of the rendered scenes' hundredth of a pixel."""
        px = self.mm_per_px
        return TrackerConfig(
            segment=SegmentConfig(model="textured", roi_px=self.roi_px, min_part_mm=self.min_part_mm),
            measure=MeasureConfig(min_area_mm2=self.min_area_mm2),
            track=TrackConfig(position_sigma_mm=px, size_sigma_mm=px, angle_sigma_deg=1.0,
                              accel_sigma_mm_s2=_ON_BELT_ACCEL_MM_S2))


# The belt areas are each camera's one-time setting: between the side rails; the picture
# between the letterbox bars; the CCTV clip's near conveyor. Scales: a white housing about
# 100 mm long (250 px), a smartphone about 140 mm (54 px), a carton about 400 mm (90 px).
# Part sizes, set once per installation like the area: the smallest parts are the cones
# (~62 x 62 mm: half is 1900 mm2) and the pocket calculator (~52 x 88 mm: 2300 mm2, and 40 mm
# as the narrowest width, under its 52).
VIDEOS = (
    RealVideo("topdown_white_parts_black_belt.mp4", 0.4, ((0, 40), (959, 40), (959, 470), (0, 470)),
              min_area_mm2=1900.0),
    RealVideo("topdown_mixed_items_grey_belt.avi", 2.6, ((0, 61), (219, 61), (219, 418), (0, 418)), last_frame=470,
              min_part_mm=40.0, min_area_mm2=2300.0),
    RealVideo("cctv_boxes_roller_conveyor.mp4", 4.4,
              ((0, 330), (200, 290), (500, 275), (719, 285), (719, 470), (500, 470), (200, 480), (0, 500)),
              labelled=False),
)


def decode(path: Path) -> tuple[list[np.ndarray], float]:
    """Every frame of a video in grey, and its frame rate."""
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise FileNotFoundError(f"{path}: cannot open the video")
    fps = cap.get(cv2.CAP_PROP_FPS) or 25.0
    frames = []
    while True:
        ok, image = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))
    cap.release()
    return frames, fps


@dataclass
class Run:
    results: list[FrameResult]
    loop_ns: np.ndarray
    fps: float

    def loop_ms(self, q: float) -> float:
        return float(np.percentile(self.loop_ns, q) / 1e6)


def run_video(video: RealVideo, data_dir: Path, config: TrackerConfig | None = None,
              change: Callable[[np.ndarray], np.ndarray] | None = None) -> Run:
    """The video through the pipeline; ``change``: what is done to each frame first (another cell's
    camera: blur, exposure)."""
    frames, fps = decode(data_dir / video.file)
    if change is not None:
        frames = [change(frame) for frame in frames]
    h, w = frames[0].shape
    pipeline = Pipeline(nadir_calibration(w, h, video.mm_per_px), config or video.config())
    results, loop_ns = [], []
    step_ns = round(1e9 / fps)
    for i, frame in enumerate(frames):
        t0 = time.perf_counter_ns()
        results.append(pipeline.process(i, frame, i * step_ns))
        loop_ns.append(time.perf_counter_ns() - t0)
    return Run(results, np.array(loop_ns, dtype=np.int64), fps)


@dataclass
class Score:
    parts: int
    found_one_track: int
    phantoms: int
    count_right: int
    count_samples: int
    tracks_per_part: dict[int, list[int]] = field(default_factory=dict)
    phantom_ids: list[int] = field(default_factory=list)
    count_misses: list[tuple[int, int, int]] = field(default_factory=list)  # (frame, measured, labelled)

    @property
    def count_accuracy(self) -> float:
        return self.count_right / self.count_samples if self.count_samples else 1.0

    def line(self) -> str:
        return (f"{self.found_one_track}/{self.parts} parts found as one track, {self.phantoms} phantoms, "
                f"counts right at {self.count_right}/{self.count_samples} sample frames")


def _counted(result: FrameResult) -> int:
    return sum(1 for o in result.objects if o.measured and o.raw is not None and not o.raw.clipped)


def score(results: list[FrameResult], truth: dict, last_frame: int | None = None) -> Score:
    """Parts are matched on the whole run (a part first wholly seen before ``last_frame`` may have its
    labelled frame after it); phantoms and counts are judged up to ``last_frame`` only."""
    end = len(results) - 1 if last_frame is None else min(last_frame, len(results) - 1)
    # Per track: its measurements (frame, image centroid).
    seen: dict[int, list[tuple[int, tuple[float, float]]]] = defaultdict(list)
    for r in results:
        for o in r.objects:
            if o.measured and o.raw is not None:
                seen[o.id].append((r.frame, o.raw.centroid_px))
    matches: dict[int, set[int]] = defaultdict(set)  # part id -> track ids
    matched_tracks: set[int] = set()
    later = []
    for part in truth["parts"]:
        if part["bbox_frame"] > end:
            later.append(part)
            continue
        x, y, w, h = part["bbox_xywh"]
        gx, gy = _MATCH_GROW * w, _MATCH_GROW * h
        f0 = part["bbox_frame"]
        for tid, points in seen.items():
            for frame, (cx, cy) in points:
                if abs(frame - f0) <= _MATCH_FRAMES and x - gx <= cx <= x + w + gx and y - gy <= cy <= y + h + gy:
                    matches[part["id"]].add(tid)
                    matched_tracks.add(tid)
                    break
    # A part labelled only after the scored range, but wholly in view within it: the tracks (matching
    # no other part) measured within it on the part's line of travel, upstream of its labelled box.
    for part in later:
        for tid, points in seen.items():
            if tid in matched_tracks:
                continue
            if any(part["first_full_frame"] <= frame <= end and _upstream(part, cx, cy) for frame, (cx, cy) in points):
                matches[part["id"]].add(tid)
        matched_tracks |= matches[part["id"]]
    parts = [p for p in truth["parts"] if p["first_full_frame"] <= end]
    found = sum(1 for p in parts if len(matches[p["id"]]) == 1)
    phantom_ids = sorted(t for t, pts in seen.items() if t not in matched_tracks
                         and sum(frame <= end for frame, _ in pts) >= PHANTOM_MEASUREMENTS)
    samples = [s for s in truth["count_samples"] if s["frame"] <= end]
    misses = [(s["frame"], _counted(results[s["frame"]]), s["n_fully_visible"]) for s in samples
              if _counted(results[s["frame"]]) != s["n_fully_visible"]]
    return Score(len(parts), found, len(phantom_ids), len(samples) - len(misses), len(samples),
                 {p["id"]: sorted(matches[p["id"]]) for p in parts}, phantom_ids, misses)


def _upstream(part: dict, cx: float, cy: float) -> bool:
    """Whether an image point lies on the part's line of travel, before its labelled box."""
    x, y, w, h = part["bbox_xywh"]
    gx, gy = _MATCH_GROW * w, _MATCH_GROW * h
    direction = part["direction"]
    if direction == "bottom_to_top":
        return x - gx <= cx <= x + w + gx and cy >= y + h / 2
    if direction == "top_to_bottom":
        return x - gx <= cx <= x + w + gx and cy <= y + h / 2
    if direction == "right_to_left":
        return y - gy <= cy <= y + h + gy and cx >= x + w / 2
    if direction == "left_to_right":
        return y - gy <= cy <= y + h + gy and cx <= x + w / 2
    raise ValueError(f"truth: unknown direction {direction!r}")


def load_truth(data_dir: Path, video: RealVideo) -> dict:
    with open(data_dir / "truth" / f"{video.stem}.truth.json", encoding="utf-8") as f:
        return json.load(f)
