"""The textured model's outlines (segment/outline.py), on working images built by hand whose regions are
known exactly (a light part's shadow is left out, a dark part's light label keeps it whole, a box's
faint side face is in its outline) and on a rendered tall box under a lamp."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
from conftest import BOX_SUPERSAMPLE, rendered

from tracker.config import SegmentConfig
from tracker.segment.outline import OutlineGeometry, outline_parts
from tracker.segment.textured import TexturedSegmenter
from tracker.synthetic import CameraSpec, PartSpec, Renderer, SceneSpec

SCALE = 0.5  # working pixels per frame pixel
WORK = (100, 80)  # the working image's (width, height)
CONFIG = SegmentConfig(model="textured")


def _outline(regions: list[tuple[slice, slice, float]]) -> np.ndarray:
    """The full-resolution mask of a working image that differs from the belt by each region's level
    (rows, columns, grey levels), blurred as the model's smoothing blurs it."""
    diff = np.zeros(WORK[::-1], np.float32)
    for rows, cols, level in regions:
        diff[rows, cols] = level
    diff = cv2.GaussianBlur(diff, (3, 3), 0.8)
    fg = cv2.compare(np.abs(diff), CONFIG.textured_threshold, cv2.CMP_GT)
    geo = OutlineGeometry((round(WORK[0] / SCALE), round(WORK[1] / SCALE)), SCALE,
                          cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (13, 13)),
                          cv2.getStructuringElement(cv2.MORPH_RECT, (5, 5)),
                          cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    return outline_parts(diff, np.abs(diff), fg, geo, CONFIG)[0] > 0


def _full(rows: slice, cols: slice) -> np.ndarray:
    """A working image's region at full resolution, as a mask."""
    out = np.zeros((round(WORK[1] / SCALE), round(WORK[0] / SCALE)), bool)
    out[round(rows.start / SCALE):round(rows.stop / SCALE), round(cols.start / SCALE):round(cols.stop / SCALE)] = True
    return out


def _covered(mask: np.ndarray, region: np.ndarray) -> float:
    return np.count_nonzero(mask & region) / np.count_nonzero(region)


def test_a_light_parts_shadow_beside_it_is_left_out():
    """A part 120 levels lighter than the belt, its shadow 40 levels darker along one side: far enough
    from the part, the shadow is the strongest contrast around it, and outlined by contrast alone it
    joined the part's hull."""
    part, shadow = (slice(20, 40), slice(20, 60)), (slice(40, 55), slice(24, 64))
    mask = _outline([(*part, 120.0), (*shadow, -40.0)])
    assert _covered(mask, _full(*part)) > 0.97
    # Its edge's blurred pixels aside: nothing of the shadow a working pixel past the part.
    assert _covered(mask, _full(slice(42, 55), shadow[1])) == 0.0


def test_a_dark_part_with_a_light_label_is_outlined_whole():
    """A light label lies inside the dark part it is printed on: the part is not the label's shadow."""
    part, label = (slice(20, 60), slice(20, 70)), (slice(30, 45), slice(35, 55))
    mask = _outline([(*part, -50.0), (*label, 120.0)])
    assert _covered(mask, _full(*part)) > 0.97
    assert np.count_nonzero(mask & ~_full(slice(19, 61), slice(19, 71))) == 0


def test_a_faint_side_face_of_a_light_box_is_in_its_outline():
    """A box's side face, lit less than its top, differs from the belt by 45 levels where its top does by
    120: less than half the top's contrast, it is the box's silhouette all the same."""
    top, face = (slice(20, 50), slice(20, 60)), (slice(50, 56), slice(20, 60))
    mask = _outline([(*top, 120.0), (*face, 45.0)])
    assert _covered(mask, _full(*top)) > 0.97
    # All but its outermost working pixel, blurred with the belt (its edge is found at half the box's
    # contrast, not the face's): 80 %.
    assert _covered(mask, _full(*face)) > 0.75
    # ... and no further than the face's own edge.
    assert _covered(mask, _full(slice(57, 80), slice(0, 100))) == 0.0


def test_a_dark_part_beside_light_on_the_belt_is_no_shadow():
    """Light on the belt (22 levels: foreground, but fainter than any part) beside a dark part casts no
    shadow: the part is outlined."""
    part, light = (slice(20, 50), slice(20, 60)), (slice(50, 65), slice(20, 60))
    mask = _outline([(*part, -60.0), (*light, 22.0)])
    assert _covered(mask, _full(*part)) > 0.97
    assert _covered(mask, _full(slice(52, 65), light[1])) == 0.0


def _lamp_scene(n_frames: int) -> SceneSpec:
    """A 40 mm box riding a knurled belt that moves with it, under a lamp 45 deg up to one side that
    lights its sides unalike and casts its shadow (60 % deep), the camera tilted 10 deg."""
    cam = CameraSpec(width=480, height=360, focal_px=420.0, tilt_deg=10.0, yaw_deg=15)
    part = PartSpec(80, 50, 40.0, -420, -30, 20, 300, 40, omega_deg_s=20.0, intensity=190.0)
    return SceneSpec(cam, (part,), fps=30, n_frames=n_frames, supersample=BOX_SUPERSAMPLE, blur_samples=3,
                     belt_level=80.0, side_light=(200.0, 0.25), cast_shadow=(200.0, 45.0, 0.6),
                     belt_texture=10.0, belt_texture_period_mm=6.0, belt_velocity_mm_s=(300.0, 40.0),
                     noise_sigma=2.0)


def test_a_tall_box_on_a_moving_knurl_is_outlined_with_its_faint_faces_and_without_its_shadow():
    """Rendered, against where the box and its shadow truly are, near the edge of the view (its faces
    large): its side faces, lit less than its top, are in its outline and its shadow is not. Outlined by
    contrast alone, the outline held 83 % of the shadow and 90.5 % of the box (its edge's blurred pixels
    aside); now none of the shadow and 98 % of the box."""
    index = 16
    scene = _lamp_scene(index + 1)
    renderer, frames = rendered(scene)
    calibration = renderer.calibration
    segmenter = TexturedSegmenter(CONFIG, np.full((scene.camera.height, scene.camera.width), 255, np.uint8),
                                  calibration.mm_per_px_at_centre())
    # The belt's travel per frame, as the pipeline measures it (near enough over the view for learning).
    step_px = np.array(scene.belt_velocity_mm_s) / scene.fps / calibration.mm_per_px_at_centre()
    for image, _ in frames:
        segmenter.shift_px = tuple(step_px)
        mask = segmenter(image) > 0
    # Where the box and its shadow are: each rendered alone, without noise or texture.
    plain = replace(scene, cast_shadow=(0.0, 90.0, 0.0), noise_sigma=0.0, belt_texture=0.0)
    alone = Renderer(plain).render(index)[0]
    part = cv2.absdiff(alone, Renderer(replace(plain, parts=())).render(index)[0]) > 5
    shaded = Renderer(replace(scene, noise_sigma=0.0, belt_texture=0.0)).render(index)[0]
    # Its edge's blurred pixels aside (the outline's edge lies where they are half part, half belt).
    square = np.ones((3, 3), np.uint8)
    inside = cv2.erode(part.astype(np.uint8), square) > 0
    shadow = (cv2.subtract(alone, shaded) > 5) & (cv2.dilate(part.astype(np.uint8), square) == 0)
    assert np.count_nonzero(shadow) > 0.3 * np.count_nonzero(part)  # the scene has one worth leaving out
    assert _covered(mask, inside) > 0.97
    assert _covered(mask, shadow) < 0.02
