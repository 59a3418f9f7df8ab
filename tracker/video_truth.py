"""Scoring the tracker on real footage against hand labels (``truth/<video>.truth.json``).

The labels give, per part, the frames it is wholly in view and its image box at one frame, and
the number of parts wholly in view at sample frames. From those:

* the track of a part is the track measured inside the part's box (with a margin) at the
  labelled frame; the part is *found as one track* when that one track is measured from near
  the part's first full frame to near its last (no re-birth, no id switch);
* a *phantom* is a track measured at least ``PHANTOM_MEASUREMENTS`` times that is no part's track;
* the *count* at a sample frame is the number of objects measured there (a part clipped by the
  border is predicted, not measured), compared with the labelled number wholly in view.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from tracker.calibration import Calibration
from tracker.config import TrackerConfig
from tracker.pipeline import Pipeline

PHANTOM_MEASUREMENTS = 10
# Pixels around a labelled box within which a track's centroid still belongs to it.
BOX_MARGIN_PX = 10
# Frames of slack at a part's first and last full frame (the labels are +-2-3 frames; a track
# needs a few frames to start).
SPAN_SLACK_FRAMES = 12


@dataclass
class FrameTracks:
    frame: int
    # (track id, measured, centroid in image pixels or None when predicted)
    objects: list[tuple[int, bool, tuple[float, float] | None]]


@dataclass
class VideoScore:
    video: str
    parts: int
    found_once: list[int] = field(default_factory=list)  # labelled ids found as one track
    phantoms: list[int] = field(default_factory=list)  # track ids
    count_right: int = 0
    count_samples: int = 0
    loop_ms_p50: float = 0.0
    loop_ms_p99: float = 0.0
    frame_interval_ms: float = 0.0
    frames: int = 0
    tracks: int = 0
    notes: list[str] = field(default_factory=list)

    def line(self) -> str:
        return (f"{self.video}: {len(self.found_once)}/{self.parts} parts as one track, {len(self.phantoms)} phantoms "
                f"({self.tracks} tracks), counts right at {self.count_right}/{self.count_samples} samples, "
                f"loop p50 {self.loop_ms_p50:.2f} ms p99 {self.loop_ms_p99:.2f} ms "
                f"(frame interval {self.frame_interval_ms:.1f} ms)")


def read_frames(path: str | Path, last_frame: int | None = None) -> tuple[list[np.ndarray], float]:
    """Every frame of a video as 8-bit grey (up to ``last_frame``), and the container's fps."""
    cap = cv2.VideoCapture(str(path))
    fps = cap.get(cv2.CAP_PROP_FPS) or 30.0
    frames = []
    while last_frame is None or len(frames) <= last_frame:
        ok, image = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image)
    cap.release()
    return frames, fps


def track_video(frames: list[np.ndarray], fps: float, calibration: Calibration,
                config: TrackerConfig | None = None) -> tuple[list[FrameTracks], np.ndarray]:
    """Runs the pipeline over ``frames``: what it tracked per frame, and its time per frame (ns)."""
    pipeline = Pipeline(calibration, config)
    out, loop_ns = [], np.zeros(len(frames), dtype=np.int64)
    for index, image in enumerate(frames):
        t0 = time.perf_counter_ns()
        result = pipeline.process(index, image, round(index * 1e9 / fps))
        loop_ns[index] = time.perf_counter_ns() - t0
        out.append(FrameTracks(index, [(o.id, o.measured, o.raw.centroid_px if o.raw is not None else None)
                                       for o in result.objects]))
    return out, loop_ns


def score(truth: dict, tracked: list[FrameTracks], loop_ns: np.ndarray, fps: float,
          last_frame: int | None = None) -> VideoScore:
    last = len(tracked) - 1 if last_frame is None else min(last_frame, len(tracked) - 1)
    tracked = tracked[: last + 1]
    result = VideoScore(truth["video"], len(truth["parts"]), frames=len(tracked),
                        frame_interval_ms=1000.0 / fps)
    measured_at: dict[int, list[int]] = {}
    for ft in tracked:
        for track_id, measured, _ in ft.objects:
            if measured:
                measured_at.setdefault(track_id, []).append(ft.frame)
    result.tracks = len(measured_at)
    part_tracks: set[int] = set()
    for part in truth["parts"]:
        track_id = _track_in_box(tracked, part)
        if track_id is None:
            result.notes.append(f"part {part['id']}: no track in its box at frame {part['bbox_frame']}")
            continue
        part_tracks.add(track_id)
        frames = measured_at.get(track_id, [])
        start_ok = frames and frames[0] <= part["first_full_frame"] + SPAN_SLACK_FRAMES
        end = min(part["last_full_frame"], last)
        end_ok = frames and frames[-1] >= end - SPAN_SLACK_FRAMES
        if start_ok and end_ok:
            result.found_once.append(part["id"])
        else:
            result.notes.append(f"part {part['id']}: track {track_id} measured {frames[0] if frames else '-'}-"
                                f"{frames[-1] if frames else '-'}, labelled {part['first_full_frame']}-{end}")
    result.phantoms = sorted(t for t, f in measured_at.items()
                             if len(f) >= PHANTOM_MEASUREMENTS and t not in part_tracks)
    for sample in truth["count_samples"]:
        if sample["frame"] > last:
            continue
        result.count_samples += 1
        counted = sum(measured for _, measured, _ in tracked[sample["frame"]].objects)
        if counted == sample["n_fully_visible"]:
            result.count_right += 1
        else:
            result.notes.append(f"frame {sample['frame']}: counted {counted}, labelled {sample['n_fully_visible']}")
    n = len(loop_ns[: last + 1])
    if n:
        result.loop_ms_p50 = float(np.percentile(loop_ns[:n], 50) / 1e6)
        result.loop_ms_p99 = float(np.percentile(loop_ns[:n], 99) / 1e6)
    return result


def _track_in_box(tracked: list[FrameTracks], part: dict) -> int | None:
    x, y, w, h = part["bbox_xywh"]
    m = BOX_MARGIN_PX
    frame = part["bbox_frame"]
    if frame >= len(tracked):
        return None
    inside = [track_id for track_id, measured, c in tracked[frame].objects
              if measured and c is not None and x - m <= c[0] <= x + w + m and y - m <= c[1] <= y + h + m]
    return inside[0] if len(inside) == 1 else None


def load_truth(path: str | Path) -> dict:
    return json.loads(Path(path).read_text(encoding="utf-8"))
