"""Region of interest, clutter guard, belt motion in the output, scene fault: on small exact scenes."""

from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest
from conftest import run_pipeline

from tracker.config import SegmentConfig, TrackerConfig
from tracker.errors import BadInput
from tracker.health import FAULT_SCENE, Health
from tracker.pipeline import Pipeline
from tracker.poses import FrameResult
from tracker.runner import Runner, describe_belt
from tracker.scenes import nadir
from tracker.segment.guard import ClutterGuard
from tracker.segment.motion import BeltMotion
from tracker.segment.roi import roi_polygon_px
from tracker.sources import Frame, FrameSource
from tracker.synthetic import CameraSpec
from tracker.undistort import BeltMapper


@pytest.mark.parametrize(("segment", "message"), [
    ({"model": "belt-map"}, "segment.model: expected one of ['auto', 'reference', 'textured']"),
    ({"roi_px": [[0, 0], [10, 0]]}, "segment.roi_px: expected a polygon of >= 3"),
    ({"roi_mm": [[0, 0], [10, "a"], [3, 4]]}, "segment.roi_mm: expected a polygon of >= 3"),
    ({"roi_px": [[0, 0], [9, 0], [9, 9]], "roi_mm": [[0, 0], [9, 0], [9, 9]]}, "expected roi_px or roi_mm, not both"),
    ({"scene_fault_fraction": 1.5}, "segment.scene_fault_fraction: expected 0 < f <= 1"),
    ({"roi_px": 3}, "segment.roi_px: expected a list"),
    ({"faint_threshold": -1}, "segment.faint_threshold: expected >= 0"),
    ({"faint_threshold": 12.5}, "segment.faint_threshold: expected an integer"),
])
def test_bad_segment_settings_are_one_clear_line(segment, message):
    with pytest.raises(BadInput, match=message.replace("[", r"\[").replace("]", r"\]")):
        TrackerConfig.from_dict({"segment": segment})


def test_settings_with_a_region_round_trip_through_json():
    config = TrackerConfig.from_dict({"segment": {"model": "textured", "roi_px": [[0, 10], [639, 10], [639, 470]]}})
    assert TrackerConfig.from_dict(config.to_dict()) == config
    assert config.to_dict()["segment"]["roi_px"] == [[0.0, 10.0], [639.0, 10.0], [639.0, 470.0]]


def test_outside_the_region_of_interest_nothing_is_a_part():
    # The part crosses the middle of the view (rows ~220-300); the region is the top quarter.
    top = ((0, 0), (639, 0), (639, 120), (0, 120))
    poses, _ = run_pipeline(nadir(300.0), TrackerConfig(segment=SegmentConfig(roi_px=top)))
    assert all(not p["objects"] for p in poses)
    whole, _ = run_pipeline(nadir(300.0))
    assert sum(bool(p["objects"]) for p in whole) > 100


def test_region_in_belt_mm_maps_to_the_same_image_polygon():
    calib = CameraSpec(dist_coeffs=(-0.2, 0.05, 0.0, 0.0, 0.0)).calibration()
    corners_px = np.array([[50.0, 60.0], [600.0, 40.0], [590.0, 420.0], [70.0, 400.0]])
    corners_mm = BeltMapper(calib).to_mm(corners_px)
    polygon = roi_polygon_px(SegmentConfig(roi_mm=tuple(map(tuple, corners_mm))), calib)
    # The belt polygon is densified (32 points per side) before it is mapped: its corners come first.
    np.testing.assert_allclose(polygon[::32], corners_px, atol=1e-3)
    # A straight belt edge is curved in a distorting lens's image: the midpoints are not on the chords.
    assert np.abs(polygon[16] - (corners_px[0] + corners_px[1]) / 2).max() > 0.5
    config = TrackerConfig(segment=SegmentConfig(roi_mm=tuple(map(tuple, corners_mm))))
    np.testing.assert_allclose(Pipeline(calib, config).roi_px, polygon)


def _blobs(n: int, size: tuple[int, int] = (480, 640)) -> np.ndarray:
    mask = np.zeros(size, np.uint8)
    for i in range(n):
        r, c = divmod(i, 8)
        side = 6 + i % 5  # different areas, so "the largest" is well defined
        cv2.rectangle(mask, (40 + 70 * c, 40 + 70 * r), (40 + 70 * c + side, 40 + 70 * r + side), 255, -1)
    return mask


def test_clutter_guard_measures_only_the_largest_blobs():
    roi = np.full((480, 640), 255, np.uint8)
    guarded = ClutterGuard(roi, 0.5, 5, 0)(_blobs(40))
    contours, _ = cv2.findContours(guarded.mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    assert len(contours) == 5 and not guarded.scene_fault
    assert all(cv2.contourArea(c) == 100 for c in contours)  # the 11x11 squares (area of the outline)


def test_clutter_guard_faults_when_foreground_covers_most_of_the_region():
    roi = np.zeros((480, 640), np.uint8)
    roi[100:400] = 255
    mask = np.zeros_like(roi)
    mask[100:280] = 255  # 60 % of the region
    guarded = ClutterGuard(roi, 0.5, 24, 0)(mask)
    assert guarded.scene_fault and not guarded.mask.any()
    mask[100:240] = 0  # 13 %
    assert not ClutterGuard(roi, 0.5, 24, 0)(mask).scene_fault


def test_blob_at_the_region_edge_is_clipped():
    roi = np.zeros((480, 640), np.uint8)
    roi[100:400] = 255
    mask = np.zeros_like(roi)
    mask[100:130, 50:90] = 255  # reaches the region's top edge
    mask[200:240, 300:340] = 255  # well inside
    guarded = ClutterGuard(roi, 0.5, 24, 3)(mask)
    assert guarded.at_edge == {(50, 100, 40, 30)}


def test_pose_stream_and_status_line_carry_the_belt_velocity_only_where_measured():
    assert "belt" not in FrameResult(3, 0, ()).to_dict() and describe_belt(FrameResult(3, 0, ())) == ""
    assert describe_belt(FrameResult(3, 0, (), belt_mm_s=(-84.4, 0.2))) == "belt -84,+0 mm/s"
    line = FrameResult(3, 0, (), belt_mm_s=(-84.123456, 0.5)).to_dict()
    assert line["belt"] == {"vx_mm_s": -84.1235, "vy_mm_s": 0.5}


def _texture(seed: int, shape: tuple[int, int]) -> np.ndarray:
    """A random belt texture (grey levels 40-90, a 1.5 px blur: fine grain, no two places alike)."""
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.uniform(40, 90, shape).astype(np.float32), (0, 0), 1.5)


def test_textured_model_measures_the_belt_moving_with_its_texture():
    """A random texture slid 3 px per frame along +x: the belt's velocity is read from the images."""
    calib = CameraSpec().calibration()  # 1.25 mm/px at the centre
    texture = _texture(1, (480, 1000))
    pipeline = Pipeline(calib, TrackerConfig(segment=SegmentConfig(model="textured")))
    results = [pipeline.process(i, texture[:, 300 - 3 * i: 940 - 3 * i].astype(np.uint8), round(i * 1e9 / 60))
               for i in range(40)]
    vx = np.array([r.belt_mm_s[0] for r in results[2:]])
    mm_per_px = calib.mm_per_px_at_centre()
    # Within 2 % (the scale of the calibration's centre is not quite the scale across the view).
    np.testing.assert_allclose(vx, 3 * 60 * mm_per_px, rtol=0.02)
    assert all(not r.objects for r in results), "a moving textured belt is no part"


@pytest.mark.parametrize("step_px", [0.5, 1.0, 2.5, 3.7, 11.3])
def test_belt_motion_reads_fractions_of_a_pixel_without_bias(step_px):
    """A texture slid by a fraction of a pixel per frame, diagonally: the patch is averaged down to 256 px
    (0.4 of this view), and the shift is still read to a tenth of a pixel (the peak's centroid,
    cv2.phaseCorrelate's, read a 1 px step as 0.6 and 2.5 as 2.3)."""
    texture = _texture(4, (600, 1400))
    motion = BeltMotion(np.full((480, 640), 255, np.uint8))
    step = np.array([step_px, 0.35 * step_px])
    read = []
    for i in range(8):
        moved = cv2.warpAffine(texture, np.float32([[1, 0, step[0] * i], [0, 1, step[1] * i]]), (1400, 600),
                               flags=cv2.INTER_CUBIC)
        read.append(motion(moved[60:540, 300:940].astype(np.uint8)))
    read = np.array(read[1:])
    np.testing.assert_allclose(read, np.broadcast_to(step, read.shape), atol=0.15)
    np.testing.assert_allclose(read.mean(axis=0), step, atol=0.05)


class _Frames(FrameSource):
    name = "frames"

    def __init__(self, images):
        self._images = images

    def __iter__(self):
        for i, image in enumerate(self._images):
            yield Frame(i, round(i * 1e9 / 30), image)


def test_scene_fault_when_the_camera_sees_something_else(caplog):
    calib = CameraSpec().calibration()
    rng = np.random.default_rng(2)
    belt = np.clip(60 + rng.normal(0, 2, (480, 640)), 0, 255).astype(np.uint8)
    # The camera bumped towards a bold pattern (or wrong settings): unlike the belt nearly everywhere,
    # and not by one gain the model could follow.
    yy, xx = np.mgrid[0:480, 0:640]
    lit = np.where((yy // 40 + xx // 40) % 2 == 0, 250, 5).astype(np.uint8)
    health = Health()
    pipeline = Pipeline(calib, TrackerConfig(segment=SegmentConfig(model="textured")))

    class FaultWord:
        """What a PLC would read after each frame."""

        seen: list[int] = []

        def submit(self, frame, result):
            self.seen.append((result.scene_fault, health.fault))

        def status(self):
            return ""

        def close(self):
            pass

    word = FaultWord()
    with caplog.at_level(logging.WARNING):
        summary = Runner(_Frames([belt] * 5 + [lit] * 5), pipeline, [word], health=health).run()
    # Every frame not understood reaches the fault word; one understood again clears it.
    assert all(fault == (FAULT_SCENE if bad else 0) for bad, fault in word.seen), word.seen
    assert summary.scene_faults >= 1 and "frames with the scene not understood" in summary.line()
    assert sum("scene not understood" in r.message for r in caplog.records) == 1
    assert not summary.track_ids


def test_recording_overlay_draws_the_region_of_interest():
    from tracker.recording import schemas

    calib = CameraSpec().calibration()
    polygon = roi_polygon_px(SegmentConfig(roi_px=((10, 20), (600, 20), (600, 400))), calib)
    drawn = schemas.Overlay(calib, 0.0, polygon).annotations(FrameResult(0, 0, ()))["points"]
    assert [(p["x"], p["y"]) for p in drawn[0]["points"]] == [(10, 20), (600, 20), (600, 400)]
    assert drawn[0]["outline_color"] == schemas.COLOR_ROI
    assert schemas.Overlay(calib).annotations(FrameResult(0, 0, ()))["points"] == []
