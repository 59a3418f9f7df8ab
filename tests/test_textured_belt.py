"""Exact truth on textured moving belts: texture moving with the belt, stops, repeated frames,
lighting drift, sensor noise and an MPEG-4 round trip (tests/textured_support.py)."""

from __future__ import annotations

import pytest
from textured_support import textured_run

from tracker.config import MeasureConfig, SegmentConfig, TrackerConfig
from tracker.evaluate import evaluate
from tracker.pipeline import Pipeline
from tracker.synthetic import CameraSpec

SKIP_FIRST = 2
# The belt model under test, its flat parts measured as flat (--part-height 0): with auto, the default,
# their first votes lead at 5-10 mm there (tests/test_height_auto.py measures that).
FLAT_TEXTURED = TrackerConfig(segment=SegmentConfig(model="textured"), measure=MeasureConfig(estimate_height=False))


def _run(contrast: float):
    frames, truths, t_ns = textured_run(contrast)
    pipeline = Pipeline(CameraSpec().calibration(), FLAT_TEXTURED)
    poses = [pipeline.process(i, f, t).to_dict() for i, (f, t) in enumerate(zip(frames, t_ns, strict=True))]
    return poses, truths


@pytest.mark.parametrize("contrast", [30.0, -30.0, 140.0], ids=["lighter_by_30", "darker_by_30", "white"])
def test_part_on_a_textured_moving_belt_with_stops_drift_and_compression(contrast):
    poses, truths = _run(contrast)
    acc = evaluate(poses, truths, skip_first=SKIP_FIRST)
    s = acc.summary()
    assert acc.visible_frames > 150
    assert acc.false_objects == 0, s
    assert s["centroid_mean_mm"] <= 0.1, s
    # One part, one track, through the 40-frame stop and the repeated frames.
    assert len({o["id"] for p in poses for o in p["objects"]}) == 1
    # Measured in most frames: the darker part is not where the shaded corners and the drift's dark
    # phase take its contrast under the 30 levels (to ~23) and under segment.min_part_contrast (~19 %).
    assert acc.missed_frames <= 0.25 * acc.visible_frames, s


def test_the_reference_model_fails_on_the_same_belt():
    """Without the textured model the moving texture is foreground: phantoms (the test above can fail)."""
    frames, truths, t_ns = textured_run(30.0)
    pipeline = Pipeline(CameraSpec().calibration())
    poses = [pipeline.process(i, f, t).to_dict() for i, (f, t) in enumerate(zip(frames, t_ns, strict=True))]
    acc = evaluate(poses, truths, skip_first=SKIP_FIRST)
    assert acc.false_objects > 0 or acc.summary()["centroid_mean_mm"] > 0.1
