"""segment.model "auto" (the default): the plain belt model until the belt's own look is seen to move with
it, then the textured one (tracker/segment/look.py)."""

from __future__ import annotations

import logging
import re

import cv2
import numpy as np
import pytest
from conftest import run_pipeline
from textured_support import textured_run

from tracker.config import MeasureConfig, SegmentConfig, TrackConfig, TrackerConfig
from tracker.errors import BadInput
from tracker.evaluate import evaluate
from tracker.pipeline import Pipeline
from tracker.segment.look import MovingLook
from tracker.synthetic import CameraSpec, PartSpec, SceneSpec

FRAMES = SegmentConfig().auto_frames
SHAPE = (240, 320)


def _diamonds(shift_px: int, shape: tuple[int, int] = SHAPE) -> np.ndarray:
    """A diamond-knurled belt (levels 30-110, a 20 px period) carried ``shift_px`` along +x."""
    v, u = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float32)
    u -= shift_px
    knurl = np.sin(2 * np.pi * (u + v) / 20.0) * np.sin(2 * np.pi * (u - v) / 20.0)
    return np.clip(70 + 40 * knurl, 0, 255).astype(np.uint8)


def _plain_with_part(i: int, noise_rng: np.random.Generator | None = None) -> np.ndarray:
    """A plain belt (level 60) under a bright 80 x 50 px part carried 10 px per frame along +x."""
    image = np.full(SHAPE, 60.0, np.float32)
    x = -80 + 10 * i
    cv2.rectangle(image, (x, 90), (x + 80, 140), 200.0, -1)
    if noise_rng is not None:
        image += noise_rng.normal(0, 4, SHAPE)
    return np.clip(image, 0, 255).astype(np.uint8)


def _watched(frames, roi: np.ndarray | None = None) -> list[bool]:
    look = MovingLook(SegmentConfig(), np.full(SHAPE, 255, np.uint8) if roi is None else roi)
    return [look(f) for f in frames]


def test_a_knurled_belt_moving_is_told_after_as_many_new_frames_as_the_median_takes():
    seen = _watched([_diamonds(3 * i) for i in range(30)])
    # The first frame has none before it: the FRAMES-th new frame after it decides, and for good.
    assert seen.index(True) == FRAMES and all(seen[FRAMES:])


def test_repeated_frames_are_not_new():
    """Each frame shown twice (a frame-rate conversion): only the new ones count."""
    seen = _watched([_diamonds(3 * (i // 2)) for i in range(40)])
    assert seen.index(True) == 2 * FRAMES


@pytest.mark.parametrize("noisy", [False, True], ids=["clean", "sensor_noise_4"])
def test_a_part_crossing_a_plain_belt_is_not_a_moving_look(noisy):
    rng = np.random.default_rng(5) if noisy else None
    assert not any(_watched([_plain_with_part(i, rng) for i in range(40)]))


def test_a_still_knurled_belt_and_a_flash_are_not_a_moving_look():
    """The belt stands still (its texture is learnt as it is); one frame 60 levels brighter (a lamp) changes
    every tile, once."""
    frames = [_diamonds(0) for _ in range(30)]
    frames[12] = cv2.add(frames[12], 60)
    assert not any(_watched(frames))


def test_texture_moving_outside_the_region_of_interest_is_not_watched():
    roi = np.zeros(SHAPE, np.uint8)
    roi[:, :100] = 255
    frames = [_diamonds(3 * i) for i in range(30)]
    for f in frames:
        f[:, :100] = 60  # plain inside the region, knurled beyond it
    assert not any(_watched(frames, roi))
    assert any(_watched(frames))


def test_a_lamp_flickering_over_a_plain_belt_is_not_a_moving_look():
    """The whole view 10 levels brighter and darker in turn (a lamp's flicker against a short exposure),
    a part crossing: the region's mean step is no texture."""
    frames = [_plain_with_part(i) for i in range(40)]
    frames = [cv2.add(f, 10) if i % 2 else cv2.subtract(f, 10) for i, f in enumerate(frames)]
    assert not any(_watched(frames))


def test_the_default_model_stays_plain_on_a_plain_belt():
    """A rendered plain belt: "auto" measures exactly as "reference" does, every frame; only until as many
    new frames as the median takes are watched is no part pickable (the belt model is not yet settled)."""
    # The part in view from the start, crossing the view's right half.
    scene = SceneSpec(CameraSpec(), (PartSpec(80, 50, 0, -60, 12, 25, 300.0, 0),), 60.0, 60)
    auto, _ = run_pipeline(scene)
    reference, _ = run_pipeline(scene, TrackerConfig(segment=SegmentConfig(model="reference")))
    assert sum(bool(p["objects"]) for p in auto) > 50
    held = [p for p in auto[:FRAMES] if p["objects"]]
    assert held and all(not o["pickable"] for p in held for o in p["objects"])
    assert any(o["pickable"] for p in reference[:FRAMES] for o in p["objects"])
    unpicked = [dict(p, objects=[dict(o, pickable=False) for o in p["objects"]]) for p in reference[:FRAMES]]
    assert auto[:FRAMES] == unpicked and auto[FRAMES:] == reference[FRAMES:]


def test_a_region_too_thin_to_watch_is_said_once(caplog):
    """A 6 px diagonal band: no tile lies half in it, so the belt's look cannot be watched: one warning,
    and the plain model throughout (no frame held back either)."""
    band = ((0, 4), (4, 0), (320, 316), (316, 320))
    config = TrackerConfig(segment=SegmentConfig(roi_px=band))
    with caplog.at_level(logging.WARNING, logger="tracker.pipeline"):
        pipeline = Pipeline(CameraSpec(width=320, height=320).calibration(), config)
    assert [r.getMessage() for r in caplog.records if "too thin" in r.getMessage()]
    assert pipeline.model == "reference"
    for i in range(3 * FRAMES):
        pipeline.process(i, _diamonds(3 * i, (320, 320)), round(i * 1e9 / 30))
    assert pipeline.model == "reference"


def test_the_default_model_turns_textured_on_a_knurled_moving_belt(caplog):
    """The tests' knurled belt (diamonds, grain, marks, moving 4 px a frame, through MPEG-4): the plain
    model invents parts there (tests/test_textured_belt.py); "auto" turns to the textured model, says so
    once, and then finds only the part, at the textured model's accuracy."""
    frames, truths, t_ns = textured_run(30.0)
    pipeline = Pipeline(CameraSpec().calibration())
    with caplog.at_level(logging.INFO, logger="tracker.pipeline"):
        results = [pipeline.process(i, f, t) for i, (f, t) in enumerate(zip(frames[:90], t_ns, strict=False))]
    assert pipeline.model == "textured"
    # Tracks made from now on take the coarse reference's settings (tests/test_height_auto.py).
    assert pipeline.tracker.config.view_height_sigma_mm == TrackConfig().view_height_sigma_coarse_mm
    (line,) = [r.getMessage() for r in caplog.records if "belt model" in r.getMessage()]
    switched = int(re.search(r"textured belt model from frame (\d+)", line).group(1))
    assert FRAMES <= switched <= 3 * FRAMES, line
    # Nothing the plain model made of the moving knurl was offered for picking.
    assert not any(o.pickable for r in results[:switched] for o in r.objects)
    # Its first frames learn the belt (a part in view is tracked from its next move on).
    start = switched + 30
    poses = [r.to_dict() for r in results[start:]]
    acc = evaluate(poses, truths[start:len(results)], skip_first=0)
    assert len({o["id"] for p in poses for o in p["objects"]}) == 1
    assert acc.visible_frames > 20 and acc.false_objects == 0
    assert acc.summary()["centroid_mean_mm"] <= 0.1, acc.summary()


@pytest.mark.parametrize(("setting", "value"), [("auto_moving_share", 1.5), ("auto_tile_changed", 0.0),
                                                ("auto_frames", 0), ("auto_tiles", -2)])
def test_bad_auto_settings_are_one_clear_line(setting, value):
    with pytest.raises(BadInput, match=f"{setting}: expected"):
        TrackerConfig.from_dict({"segment": {setting: value}})


@pytest.mark.parametrize("step", [3, 6])
def test_a_part_offered_while_the_belt_stood_keeps_its_id_when_the_model_turns(step):
    """A part put on a standing knurled belt is tracked by the plain model and offered for picking; the belt
    then moves: the model turns textured, and the part goes on under the same id (a PLC that took it is
    not offered it again under another), while what the plain model made of the moving knurl ends. Its
    track moves into the belt's frame with the belt's motion into the frame it turns at (carried over as
    it was, in the world's, its velocity there read the belt's own speed: 189 and 225 mm/s)."""
    h, w, stand = 480, 640, 30
    moving = 45  # frames: the part stays in view
    travel = step * moving
    v, u = np.mgrid[0:h, 0:w + travel].astype(np.float32)
    bare = 70 + 40 * np.sin(2 * np.pi * (u + v) / 20.0) * np.sin(2 * np.pi * (u - v) / 20.0)
    with_part = cv2.rectangle(bare.copy(), (travel + 250, 200), (travel + 330, 250), 200.0, -1)
    rng = np.random.default_rng(0)
    pipeline = Pipeline(CameraSpec().calibration(), TrackerConfig(measure=MeasureConfig(estimate_height=False)))
    results = []
    for i in range(stand + moving):
        shift = step * max(0, i - stand)
        belt = (bare if i < 5 else with_part)[:, travel - shift: travel - shift + w]
        frame = np.clip(np.rint(belt + rng.normal(0, 2, (h, w))), 0, 255).astype(np.uint8)
        before = pipeline.model
        results.append(pipeline.process(i, frame, round(i * 1e9 / 30)))
        if before != pipeline.model:
            # Moved into the belt's frame, in which the part riding it stands, as it turned.
            (kept,) = pipeline.tracker.tracks
            turned_vx_mm_s = float(kept.kf.x[2, 0])
    assert pipeline.model == "textured"
    belt_mm_s = step * 30 * CameraSpec().calibration().mm_per_px_at_centre()
    assert abs(turned_vx_mm_s) < 0.2 * belt_mm_s, turned_vx_mm_s
    offered = {o.id for r in results[:stand] for o in r.objects if o.pickable}
    assert len(offered) == 1
    later = results[-20:]
    assert all(len(r.objects) == 1 and r.objects[0].measured for r in later)
    assert {o.id for r in later for o in r.objects} == offered
    vx = [r.objects[0].vx_mm_s for r in later]
    # The belt's speed read frame by frame from the knurl jitters by 10-15 % (the part's own filter
    # does not smooth what is added back): within 25 % each, 5 % on average.
    np.testing.assert_allclose(vx, belt_mm_s, rtol=0.25)
    assert np.mean(vx) == pytest.approx(belt_mm_s, rel=0.05)


def test_a_noiseless_view_of_a_slow_small_part_is_new_every_frame():
    """A 40 x 30 px part moving 2 px a frame over a noiseless plain belt changes a tile or two: new frames,
    so the belt model settles and the part is pickable (by the region's mean change alone they read as
    repeats, and it never was)."""
    look = MovingLook(SegmentConfig(), np.full(SHAPE, 255, np.uint8))
    for i in range(2 * FRAMES):
        image = np.full(SHAPE, 60, np.uint8)
        cv2.rectangle(image, (20 + 2 * i, 100), (60 + 2 * i, 130), 200, -1)
        look(image)
    assert not look.unsure and not look.moving


def test_one_busy_frame_then_repeats_does_not_hold_parts_back():
    """A hand crossing the view in one frame, then the view repeated (a frozen scene, a frame-rate
    conversion): the frame after is sure again."""
    look = MovingLook(SegmentConfig(), np.full(SHAPE, 255, np.uint8))
    still = _diamonds(0)
    rng = np.random.default_rng(2)
    for _ in range(FRAMES + 1):
        look(np.clip(still + rng.normal(0, 2, SHAPE), 0, 255).astype(np.uint8))
    assert not look.unsure
    look(_diamonds(7))  # every tile changes
    assert look.unsure
    look(_diamonds(7))  # repeated
    assert not look.unsure and not look.moving
