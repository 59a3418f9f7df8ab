"""Real-belt conditions on rendered scenes with exact truth: a knurled belt whose texture moves with
the parts, the same after lossy video compression, and a belt region of interest with clutter
outside it. Parts differ from the belt's mean level by 45 grey levels; the knurl swings +-25 around
it. Measured with the textured belt model: centroid mean 0.10 mm on the moving knurl, 0.15 mm after
MPEG-4 compression (the goal is 0.1 mm for both); angle ~0.05 / 0.11 deg; one track per part."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import rendered

from tracker.config import MeasureConfig, SegmentConfig, TrackerConfig
from tracker.evaluate import evaluate
from tracker.measure import HALF_WINDOW_PX, Measurer, _Crossings
from tracker.pipeline import Pipeline
from tracker.synthetic import CameraSpec, PartSpec, SceneSpec, mpeg4_round_trip
from tracker.undistort import BeltMapper

SPEED = 240.0  # mm/s, the belt's and so the parts'


def _scene(contrast: float = 45.0, texture: float = 25.0, **kw) -> SceneSpec:
    # 1.25 mm per pixel at the centre: a 6 mm knurl is ~5 px, like the real black belt's diamonds.
    cam = CameraSpec(width=320, height=240, focal_px=560.0, tilt_deg=10.0)
    parts = (PartSpec(80, 50, 0, -260, -20, 25, SPEED, 0, intensity=60 + contrast),
             PartSpec(70, 45, 0, -420, 50, -40, SPEED, 0, intensity=60 - contrast))
    settings = dict(n_frames=70, fps=30.0, supersample=4, blur_samples=3, belt_texture=texture,
                    belt_texture_period_mm=6.0, belt_velocity_mm_s=(SPEED, 0.0)) | kw
    return SceneSpec(cam, parts, **settings)


# The belt model under test, its flat parts measured as flat (--part-height 0): with auto, the default,
# their first votes lead at 5 mm on this belt (tests/test_height_auto.py measures that).
TEXTURED = TrackerConfig(segment=SegmentConfig(model="textured"), measure=MeasureConfig(estimate_height=False))


def _run(scene: SceneSpec, frames: list[np.ndarray], config: TrackerConfig = TEXTURED):
    renderer, rendered_frames = rendered(scene)
    pipeline = Pipeline(renderer.calibration, config)
    poses = [pipeline.process(i, image, scene.t_ns(i)).to_dict() for i, image in enumerate(frames)]
    return poses, [truth for _, truth in rendered_frames], pipeline


def _check(poses, truths, centroid_mean_mm=0.12):
    acc = evaluate(poses, truths, skip_first=3)
    s = acc.summary()
    assert acc.visible_frames > 50 and acc.missed_frames <= 3, s
    assert acc.false_objects == 0, s
    assert s["centroid_mean_mm"] <= centroid_mean_mm, s
    assert s["angle_mean_deg"] <= 0.5, s
    ids = {o["id"] for p in poses for o in p["objects"]}
    assert len(ids) == 2, f"one track per part, got ids {sorted(ids)}"


def test_a_knurled_belt_moving_with_the_parts():
    scene = _scene()
    _, frames = rendered(scene)
    poses, truths, _ = _run(scene, [f for f, _ in frames])
    _check(poses, truths)
    # The belt's measured speed is the parts' speed (once the belt has moved for a frame).
    speeds = [np.hypot(p["belt"]["vx_mm_s"], p["belt"]["vy_mm_s"]) for p in poses[2:]]
    assert np.median(speeds) == pytest.approx(SPEED, rel=0.05)


def test_the_plain_belt_model_sees_the_moving_knurl_as_phantoms():
    scene = _scene()
    _, frames = rendered(scene)
    # The default, "auto", turns to the textured model on this belt (tests/test_belt_look.py).
    config = TrackerConfig(segment=SegmentConfig(model="reference"))
    poses, truths, _ = _run(scene, [f for f, _ in frames], config)
    acc = evaluate(poses, truths)
    # The moving knurl joins parts and belt into shapes that are no boxes: phantoms, or parts lost in them.
    assert acc.false_objects > 0 or acc.missed_frames > acc.visible_frames / 4, acc.summary()


def test_the_same_belt_after_video_compression():
    scene = _scene()
    _, frames = rendered(scene)
    poses, truths, _ = _run(scene, mpeg4_round_trip([f for f, _ in frames], scene.fps))
    _check(poses, truths, centroid_mean_mm=0.2)


def test_nothing_outside_the_region_of_interest_is_a_part():
    # A bright bar moves across the floor beside the belt (rows 12-31): outside the belt's region.
    scene = _scene()
    _, frames = rendered(scene)
    cluttered = []
    for i, (f, _) in enumerate(frames):
        f = f.copy()
        x = 10 + 4 * i
        f[12:32, x : x + 40] = 230
        cluttered.append(f)
    roi = [[0, 45], [319, 45], [319, 239], [0, 239]]
    config = dataclasses.replace(TEXTURED, segment=dataclasses.replace(TEXTURED.segment, roi_px=roi))
    poses, truths, _ = _run(scene, cluttered, config)
    _check(poses, truths)
    poses_all, _, _ = _run(scene, cluttered)
    assert evaluate(poses_all, truths).false_objects > 0, "without the region the bar is a part"


def test_boxes_on_the_knurled_belt_with_their_height_given():
    """A box's edges are read against the face next to each, one pixel, and the knurl's bright diamonds
    come within min_contrast of the dark part's face in a few windows: those windows are left out, the
    rest read (before, any one of them sent the whole blob to its pixel staircase: 0.57 mm, 0.22 deg;
    now 0.13 mm, 0.06 deg)."""
    scene = _scene()
    scene = dataclasses.replace(scene, parts=tuple(dataclasses.replace(p, height_mm=10.0) for p in scene.parts))
    _, frames = rendered(scene)
    config = TrackerConfig(segment=TEXTURED.segment, measure=MeasureConfig(part_height_mm=10.0))
    poses, truths, _ = _run(scene, [f for f, _ in frames], config)
    s = evaluate(poses, truths, skip_first=3).summary()
    assert s["false_objects"] == 0 and s["missed_frames"] <= 3, s
    assert s["centroid_mean_mm"] <= 0.2 and s["angle_mean_deg"] <= 0.1, s


def _crossings(unreadable_left: int, unreadable_right: int, n: int = 20) -> _Crossings:
    """n left and n right edge windows of a part 150 grey levels over a belt of 60; the first
    ``unreadable_*`` of each side have a face pixel at the belt's level (a knurl diamond under it)."""
    k = HALF_WINDOW_PX
    image = np.full((2 * n, 2 * k), 150.0)
    rising = np.arange(2 * n) < n
    image[:unreadable_left, k + 1] = 65.0  # a left edge's face pixel
    image[n : n + unreadable_right, k - 2] = 65.0  # a right edge's
    return _Crossings(np.arange(2 * n) % n, np.zeros(2 * n, dtype=int), rising, image, np.full((2 * n, 2 * k), 60.0))


def test_a_box_side_with_too_many_unreadable_windows_is_not_read_from_levels():
    """Windows whose face pixel the belt comes near are left out where they are scattered; where one
    side of the blob loses more than measure.max_unreadable_fraction (15 %) of its windows, that side
    may be missing altogether (an elongated part's short side holds an eighth of all windows at 45
    deg), and the blob is not read from levels: counted over both sides, 4 of 40 would pass."""
    measurer = Measurer(BeltMapper(CameraSpec().calibration()), MeasureConfig(part_height_mm=10.0))
    kept = measurer._readable(_crossings(2, 2), HALF_WINDOW_PX)
    assert kept is not None and len(kept.rows) == 36
    assert measurer._readable(_crossings(4, 0), HALF_WINDOW_PX) is None


def test_a_coarse_belt_reference_off_near_a_part_is_corrected_by_the_belt_around_it():
    """The textured model's reference is coarse and still learning: near a part it may sit a few grey
    levels off the belt, and unevenly. Edges are read against it, so a flat part 40 levels off a belt
    its reference puts 3 levels too dark on one side and 3 too bright on the other is measured 0.2 mm
    off centre; with coarse_reference the belt pixels around the part correct the level (a plane
    fitted to them), and its centre comes out as drawn."""
    part = PartSpec(80, 50, 0, 10, -5, 20, intensity=100.0)
    scene = SceneSpec(CameraSpec(width=320, height=240, focal_px=800.0), (part,), n_frames=1, noise_sigma=1.0,
                      belt_level=60.0)
    renderer, ((image, truth),) = rendered(scene)
    drawn = truth["objects"][0]
    mask = (image > 80).astype(np.uint8) * 255
    cols = np.arange(image.shape[1], dtype=np.float32)
    reference = np.broadcast_to(scene.belt_level - 8.0 + 16.0 * cols / cols[-1], image.shape).astype(np.float32)
    mapper = BeltMapper(renderer.calibration)

    def centre_error_mm(coarse: bool) -> float:
        (m,) = Measurer(mapper, MeasureConfig(estimate_height=False), coarse_reference=coarse)(image, reference, mask)
        return float(np.hypot(m.rect.x_mm - drawn["x_mm"], m.rect.y_mm - drawn["y_mm"]))

    assert centre_error_mm(False) > 0.1
    assert centre_error_mm(True) < 0.03
