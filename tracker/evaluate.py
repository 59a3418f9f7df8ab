"""Accuracy of a pose stream against ground truth (synthetic scenes' truth.jsonl)."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from tracker.geometry import wrap_angle_deg

if TYPE_CHECKING:
    from tracker.pipeline import Pipeline
    from tracker.synthetic import SceneSpec

# A reported object within this distance of a true part is that part.
MATCH_MM = 20.0
# Parts at least this far (px) from the image border are fully visible: they must be measured.
VISIBLE_MARGIN_PX = 4
# Below this difference of sides, a part is square: its angle is defined modulo 90 deg.
SQUARE_MM = 1.0


@dataclass
class Accuracy:
    centroid_mm: list[float] = field(default_factory=list)
    along_mm: list[float] = field(default_factory=list)  # signed, along the true velocity
    angle_deg: list[float] = field(default_factory=list)
    length_mm: list[float] = field(default_factory=list)
    width_mm: list[float] = field(default_factory=list)
    visible_frames: int = 0
    missed_frames: int = 0
    false_objects: int = 0

    def summary(self) -> dict:
        def stats(values, q=95):
            a = np.abs(np.asarray(values, dtype=np.float64))
            return (float(a.mean()), float(np.percentile(a, q))) if a.size else (math.nan, math.nan)

        c_mean, c_p95 = stats(self.centroid_mm)
        a_mean, a_p95 = stats(self.angle_deg)
        return {
            "visible_frames": self.visible_frames, "missed_frames": self.missed_frames,
            "false_objects": self.false_objects,
            "centroid_mean_mm": c_mean, "centroid_p95_mm": c_p95,
            "along_bias_mm": float(np.mean(self.along_mm)) if self.along_mm else math.nan,
            "angle_mean_deg": a_mean, "angle_p95_deg": a_p95,
            "length_max_mm": float(np.max(np.abs(self.length_mm))) if self.length_mm else math.nan,
            "width_max_mm": float(np.max(np.abs(self.width_mm))) if self.width_mm else math.nan,
        }


def evaluate(poses: list[dict], truths: list[dict], skip_first: int = 0) -> Accuracy:
    """Compare pose-stream frames with truth frames (matched by ``frame``).

    ``skip_first`` measured frames of each part are left out of the error
    statistics (not of the detection count): the filter's velocity is unknown
    at a track's birth.
    """
    by_frame = {p["frame"]: p for p in poses}
    acc = Accuracy()
    seen: dict[int, int] = {}
    for truth in truths:
        reported = by_frame.get(truth["frame"], {"objects": []})["objects"]
        for obj in reported:
            near = [t for t in truth["objects"] if t["visible_px"] > 0
                    and math.dist((t["x_mm"], t["y_mm"]), (obj["x_mm"], obj["y_mm"])) < MATCH_MM + t["length_mm"]]
            if not near:
                acc.false_objects += 1
        for t in truth["objects"]:
            if t["border_px"] < VISIBLE_MARGIN_PX:
                continue
            acc.visible_frames += 1
            cands = [o for o in reported if o["measured"]
                     and math.dist((t["x_mm"], t["y_mm"]), (o["x_mm"], o["y_mm"])) < MATCH_MM]
            if not cands:
                acc.missed_frames += 1
                continue
            o = min(cands, key=lambda o: math.dist((t["x_mm"], t["y_mm"]), (o["x_mm"], o["y_mm"])))
            seen[t["id"]] = seen.get(t["id"], 0) + 1
            if seen[t["id"]] <= skip_first:
                continue
            dx, dy = o["x_mm"] - t["x_mm"], o["y_mm"] - t["y_mm"]
            acc.centroid_mm.append(math.hypot(dx, dy))
            speed = math.hypot(t["vx_mm_s"], t["vy_mm_s"])
            if speed > 0:
                acc.along_mm.append((dx * t["vx_mm_s"] + dy * t["vy_mm_s"]) / speed)
            d_angle = wrap_angle_deg(o["angle_deg"] - t["angle_deg"])
            if t["length_mm"] - t["width_mm"] < SQUARE_MM:
                d_angle = min(abs(d_angle), 90 - abs(d_angle))
            acc.angle_deg.append(d_angle)
            acc.length_mm.append(o["length_mm"] - t["length_mm"])
            acc.width_mm.append(o["width_mm"] - t["width_mm"])
    return acc


def centroid_error_mm(obj: dict, truth: dict) -> float:
    """How far a reported object's centre is from a true part's (mm)."""
    return math.hypot(obj["x_mm"] - truth["x_mm"], obj["y_mm"] - truth["y_mm"])


def part_views(poses: list[dict], truths: list[dict], part: int) -> list[tuple[dict, dict]]:
    """(object, truth) of the ``part``-th true part in each frame it is wholly in view (more than
    VISIBLE_MARGIN_PX from the image's border) with a measured object within half its width of it: the
    nearest such object. ``poses`` and ``truths`` are frame by frame."""
    views = []
    for pose, truth in zip(poses, truths, strict=True):
        t = truth["objects"][part]
        seen = [o for o in pose["objects"] if o["measured"]]
        if t is not None and t["border_px"] > VISIBLE_MARGIN_PX and seen:
            o = min(seen, key=lambda o: centroid_error_mm(o, t))
            if centroid_error_mm(o, t) < t["width_mm"] / 2:
                views.append((o, t))
    return views


def own_track(views: list[tuple[dict, dict]]) -> list[tuple[dict, dict]]:
    """Those of a part's ``views`` (see part_views) whose object is of the track that is so most often:
    the part's own, not the ghost a part in view at the start leaves behind."""
    if not views:
        return []
    own = Counter(o["id"] for o, _ in views).most_common(1)[0][0]
    return [(o, t) for o, t in views if o["id"] == own]


def own_height_readings(pipeline: Pipeline, scene: SceneSpec, frames: Iterable[tuple[np.ndarray, dict]],
                        height_mm: float) -> list[tuple[float, float]]:
    """What each view of a one-part scene tells of the part's height on its own (--part-height auto: see
    measure.Measurer._own_shape), each view given the true ``height_mm`` as its track's: (error, claimed
    1 sigma), mm, of the views that tell the height as the track counts them (the part wholly measured,
    surer than track.view_height_told_sigma_mm). ``frames``: (image, truth) of ``scene`` in order, which
    ``pipeline`` processes too (its segmentation and belt reference as a run's)."""
    # The measurement's modules only here: `tracker evaluate` reads pose files and needs none.
    from tracker.height import height_information  # noqa: PLC0415
    from tracker.measure import KnownPart  # noqa: PLC0415

    told = pipeline.config.track.view_height_told_sigma_mm**-2
    readings = []
    for i, (image, truth) in enumerate(frames):
        part = truth["objects"][0]
        if part is not None and part["visible_px"] > 0:
            mask = pipeline.segmenter(image)
            known = KnownPart(part["x_mm"], part["y_mm"], None, height_mm=height_mm)
            found = pipeline.measurer(image, pipeline.segmenter.reference, mask, [known])
            m = min(found, key=lambda f: math.hypot(f.rect.x_mm - part["x_mm"], f.rect.y_mm - part["y_mm"]),
                    default=None)
            if m is not None and not m.clipped and m.shape_info is not None:
                # The height alone, the size marginalised out (as the track judges a view).
                information = height_information(m.shape_info)
                if information >= told:
                    readings.append((float(np.linalg.solve(m.shape_info, m.shape_vec)[2]) - height_mm,
                                     float(information**-0.5)))
        pipeline.process(i, image, scene.t_ns(i))
    return readings
