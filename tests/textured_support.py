"""Textured moving belts with exact truth, built in the tests from the renderer's exact frames.

The renderer draws parts on a belt that looks the same wherever it is. Here a belt texture
(diamonds, noise, streaks across the belt) that moves with the belt is laid over every pixel the
part does not cover (the coverage is exact: a noise-free frame is belt + coverage x (part - belt)),
the belt stops (the same instant held for many frames, its capture times running on) and repeats
frames, the light drifts, sensor noise is added, and the frames go through an MPEG-4 encode and
decode. Truth is the rendered instant's, so it is exact through all of it.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
from conftest import rendered

from tracker.config import MeasureConfig, SegmentConfig, TrackerConfig
from tracker.pipeline import Pipeline
from tracker.synthetic import CameraSpec, PartSpec, SceneSpec, mpeg4_round_trip

FPS = 30.0
# The belt model under test, its flat parts measured as flat (--part-height 0): with auto, the default,
# their first votes lead at 5-10 mm there (tests/test_height_auto.py measures that).
FLAT_TEXTURED = TrackerConfig(segment=SegmentConfig(model="textured"), measure=MeasureConfig(estimate_height=False))
BELT_LEVEL = 60.0
# 150 mm/s at 30 fps on a straight-down camera at 1.25 mm/px: 4 px of belt per frame along +x
# (less than half the knurl's period, as a camera must be set up to see a belt's motion).
SPEED_MM_S = 150.0
PX_PER_FRAME = 4


def scene(contrast: float) -> SceneSpec:
    part = PartSpec(80, 50, 0, -420, 12, 25, SPEED_MM_S, 0, intensity=BELT_LEVEL + contrast)
    return SceneSpec(CameraSpec(), (part,), FPS, 220, noise_sigma=0.0, belt_level=BELT_LEVEL)


def schedule(n_rendered: int) -> list[int]:
    """Rendered instant shown in each output frame: running, a stop of 40 frames, running again,
    with a repeated frame every 13 (a frame-rate conversion)."""
    out = []
    for r in range(n_rendered):
        out.append(r)
        if r == 90:
            out += [r] * 40
        if r % 13 == 0:
            out.append(r)
    return out


def _texture(height: int, width: int, seed: int = 3) -> np.ndarray:
    v, u = np.mgrid[0:height, 0:width].astype(np.float32)
    # A knurled pattern (diamonds of a 10 px period), grain, and marks across the belt.
    diamonds = 12.0 * np.sin(2 * np.pi * (u + v) / 10.0) * np.sin(2 * np.pi * (u - v) / 10.0)
    rng = np.random.default_rng(seed)
    fibres = cv2.GaussianBlur(rng.normal(0, 8, (height, width)).astype(np.float32), (0, 0), 1.2)
    streaks = np.zeros((height, width), np.float32)
    for x in rng.integers(0, width, width // 90):
        streaks[:, x : x + 2] = 30.0  # marks across the belt, moving with it
    return diamonds + fibres + streaks


@functools.cache
def textured_run(contrast: float, compress: bool = True) -> tuple[list[np.ndarray], list[dict], list[int]]:
    """(frames, truths, capture times in ns) of the textured scene."""
    sc = scene(contrast)
    # The belt is shaded (darker towards the corners), the part is not: its contrast is exactly
    # ``contrast`` at the image centre (|part - belt| >= 30 must hold where it is measured).
    renderer, frames = rendered(sc)
    belt = renderer._background
    part_level = BELT_LEVEL + contrast
    order = schedule(sc.n_frames)
    h, w = belt.shape
    travel = PX_PER_FRAME * sc.n_frames
    texture = _texture(h, w + travel)
    rng = np.random.default_rng(7)
    out, truths = [], []
    for i, r in enumerate(order):
        image = frames[r][0].astype(np.float32)
        cover = np.clip((image - belt) / (part_level - belt), 0.0, 1.0)
        start = travel - PX_PER_FRAME * r  # the window slides back: the belt's content moves +x
        textured = image + (1.0 - cover) * texture[:, start : start + w]
        gain = 1.0 + 0.12 * np.sin(2 * np.pi * i / len(order))  # lighting drift
        noisy = textured * gain + rng.normal(0, 1.5, textured.shape)
        out.append(np.clip(np.rint(noisy), 0, 255).astype(np.uint8))
        truth = dict(frames[r][1], frame=i)
        truths.append(truth)
    if compress:
        out = mpeg4_round_trip(out, FPS)
    return out, truths, [round(i * 1e9 / FPS) for i in range(len(out))]


@functools.cache
def flat_textured_results(contrast: float) -> tuple:
    """Each frame's pipeline result over ``textured_run(contrast)`` with FLAT_TEXTURED (shared by the
    tests that need that run: it costs seconds)."""
    frames, _, t_ns = textured_run(contrast)
    pipeline = Pipeline(CameraSpec().calibration(), FLAT_TEXTURED)
    return tuple(pipeline.process(i, f, t) for i, (f, t) in enumerate(zip(frames, t_ns, strict=True)))
