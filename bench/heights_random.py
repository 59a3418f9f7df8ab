"""Parts with height on random scenes: how often the issue's bounds hold where nothing was tuned.

    .venv/bin/python bench/heights_random.py [--scenes N] [--first K] [--any-height] [--tilt DEG] [--dark]
                                             [--textured] [--side-light] [--shadow] [--height MM]
                                             [--near] [--two-parts] [--json]

Each scene is drawn from its own seed: a camera (480x360 to 640x480, focal length 0.8-1.1 times the
width, 600-900 mm above the belt, tilted 0, 10 or 20 deg in turn, or with --tilt every one that much,
turned -40 to 40 deg), one box
(60-100 x 35-65 mm, its height 0, 5, 10, 20 or 60 mm in turn, or with --any-height drawn from 3-60
mm, or with --height that, 150-220 grey on a 50-80 grey belt, or with --dark 20-60 grey on a 130-180
belt: its sides, lit less than its top, then differ from the belt by more than its top does; with --textured on a belt
with a knurl of 5-15 grey levels moving with the part, 2 levels of sensor noise, through an MPEG-4
encode and decode, measured with the textured belt model; with --side-light under a lamp to one side,
its azimuth from a seed of its own, that lights each side face 0.75-1.25 times its kind's shade: a face
and the one opposite differ; with --shadow that lamp also casts the part's shadow on the belt, from
45-80 deg above it, 2-8 deg across, taking 30-60 % of the belt's light there; with --near every
camera 0.7 times as high, at least 500 mm: a smaller view; with --two-parts a second box of another
height beside the first across the belt, both riding straight along it, scored with auto only)
crossing the whole view at 250-400 mm/s while turning, in view at the start or entering it. The
bounds (issue 10): with the height given, centroid mean <= 0.1 mm, p95 <= 0.3 mm and angle mean <= 0.05
deg; with auto, converged within the first third of the crossing, and from then on the height within 0.5
mm and the centroid within 0.2 mm mean, within 1 mm mean before. Prints one line per scene and what each missed,
then how many scenes met every bound.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import Counter
from dataclasses import replace
from functools import partial
from multiprocessing import Pool
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402

from tracker.config import MeasureConfig, SegmentConfig, TrackerConfig  # noqa: E402
from tracker.evaluate import centroid_error_mm, evaluate, own_track, part_views  # noqa: E402
from tracker.pipeline import Pipeline  # noqa: E402
from tracker.synthetic import CameraSpec, PartSpec, Renderer, SceneSpec, mpeg4_round_trip  # noqa: E402

HEIGHTS_MM = (0.0, 5.0, 10.0, 20.0, 60.0)
TILTS_DEG = (0.0, 10.0, 20.0)
# --side-light: how much the lamp lights a side face facing it more (and the one opposite less).
SIDE_LIGHT_STRENGTH = 0.25
# --shadow: how high that lamp stands above the belt (deg) and how much light the shadow takes.
SHADOW_ELEVATION_DEG = (45.0, 80.0)
SHADOW_DEPTH = (0.3, 0.6)
# ... and how large it looks from the belt (deg across: a spot to a panel): its shadows' penumbra.
LAMP_SIZE_DEG = (2.0, 8.0)
# --near: every camera this much nearer the belt (no nearer than the calibration allows): a smaller
# view, as a pick cell's camera often has.
NEAR_SCALE = 0.7
NEAREST_MM = 500.0


def scene(k: int, any_height: bool = False, tilt_deg: float | None = None, dark: bool = False,
          textured: bool = False, side_light: bool = False, shadow: bool = False, near: bool = False,
          two_parts: bool = False) -> SceneSpec:
    """The k-th random scene (its tilt cycles fastest, then its height; with ``any_height`` its height is
    drawn from 3-60 mm, evenly on a log scale, from a seed of its own; ``tilt_deg``: every camera's tilt,
    the rest of the scene as it is; ``dark``: the part dark on a bright belt, their levels from a seed of
    their own, the rest as it is; ``textured``: a knurl moving with the part, its depth from a seed of
    its own, and more sensor noise; ``side_light``: a lamp to one side, its azimuth from a seed of its
    own; ``shadow``: that lamp, also casting the part's shadow on the belt, its elevation and the
    shadow's depth from a seed of their own; ``near``: the camera NEAR_SCALE as high; ``two_parts``: a
    second box of another height beside the first, across the belt, both riding straight along it,
    the second's size, turn, level and lag behind the first from a seed of its own)."""
    rng = np.random.default_rng(1000 + k)
    width, height = [(480, 360), (560, 420), (640, 480)][rng.integers(3)]
    focal = float(rng.uniform(0.8, 1.1) * width)
    above = float(rng.uniform(600, 900))
    if near:
        above = max(NEAREST_MM, NEAR_SCALE * above)
    cam = CameraSpec(width=width, height=height, focal_px=focal,
                     tilt_deg=TILTS_DEG[k % 3] if tilt_deg is None else tilt_deg,
                     yaw_deg=float(rng.uniform(-40, 40)), height_mm=above,
                     principal_offset_px=(float(rng.uniform(-5, 5)), float(rng.uniform(-5, 5))))
    half_view = 0.5 * width * above / focal
    length = float(rng.uniform(60, 100))
    width_mm = float(rng.uniform(35, min(65, length - 8)))
    speed, vy = float(rng.uniform(250, 400)), float(rng.uniform(-40, 40))
    height_mm = (float(np.round(np.exp(np.random.default_rng(5000 + k).uniform(np.log(3.0), np.log(60.0))), 1))
                 if any_height else HEIGHTS_MM[(k // 3) % len(HEIGHTS_MM)])
    part = PartSpec(length, width_mm, height_mm,
                    float(-(half_view + rng.uniform(0.0, 0.5) * length)),
                    float(rng.uniform(-0.25, 0.25) * height * above / focal), float(rng.uniform(-90, 90)), speed, vy,
                    omega_deg_s=float(rng.uniform(-25, 25)), intensity=float(rng.uniform(150, 220)))
    belt_level = float(rng.uniform(50, 80))
    if dark:
        levels = np.random.default_rng(7000 + k)
        part = replace(part, intensity=float(levels.uniform(20, 60)))
        belt_level = float(levels.uniform(130, 180))
    fps = 30.0
    parts, extra_frames = (part,), 0
    if two_parts:
        # Side by side across the belt, each about halfway from the view's middle to its edge, riding along.
        other = np.random.default_rng(20000 + k)
        half_across = 0.5 * height * above / focal
        first = replace(part, y0_mm=-0.45 * half_across, vy_mm_s=0.0)
        second = replace(part, length_mm=float(other.uniform(60, 100)), width_mm=float(other.uniform(35, 55)),
                         height_mm=HEIGHTS_MM[(k // 3 + 2) % len(HEIGHTS_MM)], y0_mm=0.5 * half_across,
                         x0_mm=part.x0_mm - float(other.uniform(20, 120)), vy_mm_s=0.0,
                         angle0_deg=float(other.uniform(-90, 90)),
                         intensity=float(other.uniform(20, 60) if dark else other.uniform(150, 220)))
        # Until the second, behind the first and perhaps longer, has crossed the view too.
        behind_mm = part.x0_mm - second.x0_mm + max(0.0, second.length_mm - length)
        parts, extra_frames = (first, second), math.ceil(behind_mm / speed * fps)
    belt = {}
    if textured:
        belt = dict(belt_texture=float(np.random.default_rng(8000 + k).uniform(5, 15)), belt_texture_period_mm=6.0,
                    belt_velocity_mm_s=(speed, 0.0 if two_parts else vy), noise_sigma=2.0)
    if side_light or shadow:
        belt["side_light"] = (float(np.random.default_rng(9000 + k).uniform(0, 360)), SIDE_LIGHT_STRENGTH)
    if shadow:
        lamp = np.random.default_rng(10000 + k)
        belt["cast_shadow"] = (belt["side_light"][0], float(lamp.uniform(*SHADOW_ELEVATION_DEG)),
                               float(lamp.uniform(*SHADOW_DEPTH)))
        belt["lamp_size_deg"] = float(lamp.uniform(*LAMP_SIZE_DEG))
    return SceneSpec(cam, parts, fps=fps, n_frames=int((2 * half_view + length) / speed * fps) + 4 + extra_frames,
                     supersample=8, blur_samples=3, belt_level=belt_level, seed=k, **belt)


def poses_of(spec: SceneSpec, images: list, measure: MeasureConfig, segment: SegmentConfig | None = None) -> list[dict]:
    """The pose stream (as dicts) of ``images`` of ``spec`` measured with ``measure`` (and ``segment``)."""
    pipeline = Pipeline(Renderer(spec).calibration, TrackerConfig(segment=segment or SegmentConfig(), measure=measure))
    return [pipeline.process(i, image, spec.t_ns(i)).to_dict() for i, image in enumerate(images)]


def measure_scene(k: int, any_height: bool = False, tilt_deg: float | None = None, dark: bool = False,
                  textured: bool = False, height_mm: float | None = None, side_light: bool = False,
                  shadow: bool = False, near: bool = False, two_parts: bool = False) -> list[dict]:
    """Scene ``k``'s row (with ``two_parts`` one per part, their heights estimated only: one height given
    is not both parts')."""
    spec = scene(k, any_height, tilt_deg, dark, textured, side_light, shadow, near, two_parts)
    if two_parts:
        return _measure_parts(k, spec, textured)
    if height_mm is not None:
        spec = replace(spec, parts=(replace(spec.parts[0], height_mm=height_mm),))
    images, truths, segment = _rendered(spec, textured)
    part = spec.parts[0]
    row = {"scene": k, "height_mm": part.height_mm, "tilt_deg": spec.camera.tilt_deg,
           "side_contrast": round(part.intensity * 0.65 - spec.belt_level, 1)}
    if part.height_mm > 0:
        given = evaluate(poses_of(spec, images, MeasureConfig(part_height_mm=part.height_mm), segment), truths,
                         skip_first=2)
        summary = given.summary()
        row |= {"given_mean_mm": summary["centroid_mean_mm"], "given_p95_mm": summary["centroid_p95_mm"],
                "given_angle_deg": summary["angle_mean_deg"]}
    frames_own = own_track(part_views(poses_of(spec, images, MeasureConfig(estimate_height=True), segment), truths, 0))
    return [row | auto_row(frames_own, part.height_mm)]


def _rendered(spec: SceneSpec, textured: bool) -> tuple[list, list[dict], SegmentConfig | None]:
    """``spec``'s frames as measured (on a textured belt through MPEG-4), their truths, and the belt model
    to measure them with (None: the default)."""
    renderer = Renderer(spec)
    frames = [renderer.render(i) for i in range(spec.n_frames)]
    images, truths = [image for image, _ in frames], [truth for _, truth in frames]
    if textured:
        return mpeg4_round_trip(images, spec.fps), truths, SegmentConfig(model="textured")
    return images, truths, None


def _measure_parts(k: int, spec: SceneSpec, textured: bool) -> list[dict]:
    """Each part's row of a scene of several, with auto."""
    images, truths, segment = _rendered(spec, textured)
    poses = poses_of(spec, images, MeasureConfig(estimate_height=True), segment)
    rows = []
    for j, part in enumerate(spec.parts):
        frames_own = own_track(part_views(poses, truths, j))
        row = {"scene": k, "part": j, "height_mm": part.height_mm, "tilt_deg": spec.camera.tilt_deg}
        rows.append(row | (auto_row(frames_own, part.height_mm) if frames_own else {"converged": None}))
    return rows


def auto_row(frames_own: list[tuple[dict, dict]], height_mm: float) -> dict:
    """How a part's own track (its (pose, truth) pairs) met the bounds with auto: when its height
    converged (a fraction of its frames; None: never), and its errors after and before."""
    converged = [i for i, (o, _) in enumerate(frames_own) if o["height_converged"]]
    if not converged:
        return {"converged": None}
    first = converged[0]
    after = frames_own[first:]
    return {
        "converged": first / len(frames_own),
        "height_max_mm": max(abs(o["height_mm"] - height_mm) for o, _ in after),
        "centroid_after_mm": float(np.mean([centroid_error_mm(o, t) for o, t in after])),
        "centroid_before_mm": (float(np.mean([centroid_error_mm(o, t) for o, t in frames_own[:first]]))
                               if first else 0.0),
        "unconverged_after": sum(not o["height_converged"] for o, _ in after)}


def missed(row: dict) -> list[str]:
    """The bounds a scene's row misses."""
    out = []
    if (row.get("given_mean_mm", 0.0) > 0.1 or row.get("given_p95_mm", 0.0) > 0.3
            or row.get("given_angle_deg", 0.0) > 0.05):
        out.append("given")
    if row["converged"] is None:
        return [*out, "never converged"]
    checks = (("late", row["converged"] > 1 / 3), ("height", row["height_max_mm"] > 0.5),
              ("centroid after", row["centroid_after_mm"] > 0.2), ("centroid before", row["centroid_before_mm"] > 1.0),
              ("unconverged again", row["unconverged_after"] > 0))
    return out + [name for name, miss in checks if miss]


def row_line(row: dict, misses: list[str]) -> str:
    """A row as printed: its figures to 3 decimals, then the bounds it missed."""
    shown = {key: round(value, 3) if isinstance(value, float) else value for key, value in row.items()}
    return f"{json.dumps(shown)} -> {', '.join(misses) or 'every bound met'}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=30)
    parser.add_argument("--first", type=int, default=0, help="the first scene's number")
    parser.add_argument("--any-height", action="store_true",
                        help="each scene's height drawn from 3-60 mm (evenly on a log scale), not 0/5/10/20/60")
    parser.add_argument("--tilt", type=float, help="every camera tilted this much (deg; the issue allows up to 25)")
    parser.add_argument("--dark", action="store_true", help="each part 20-60 grey on a 130-180 grey belt")
    parser.add_argument("--height", type=float, help="every part this tall (mm; thin boxes: what auto tells from flat)")
    parser.add_argument("--textured", action="store_true",
                        help="on a knurled belt moving with the part, through MPEG-4, with the textured belt model")
    parser.add_argument("--side-light", action="store_true",
                        help="under a lamp to one side: a side face and the one opposite differ in shade")
    parser.add_argument("--shadow", action="store_true",
                        help="that lamp (--side-light implied) 45-80 deg above the belt and 2-8 deg across, "
                             "casting the part's shadow, 30-60 %% deep")
    parser.add_argument("--near", action="store_true",
                        help=f"every camera {NEAR_SCALE} times as high (at least {NEAREST_MM:g} mm): a smaller view")
    parser.add_argument("--two-parts", action="store_true",
                        help="a second box of another height beside the first (auto only: one height given "
                             "is not both parts')")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    if args.two_parts and args.height is not None:
        parser.error("--height: one height for both of --two-parts' parts would not be theirs")
    with Pool(2) as pool:
        rows = pool.map(partial(measure_scene, any_height=args.any_height, tilt_deg=args.tilt, dark=args.dark,
                                 textured=args.textured, height_mm=args.height, side_light=args.side_light,
                                 shadow=args.shadow, near=args.near, two_parts=args.two_parts),
                        range(args.first, args.first + args.scenes))
    rows = [row for scene_rows in rows for row in scene_rows]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    tally: Counter = Counter()
    for row in rows:
        misses = missed(row)
        tally.update(misses)
        print(row_line(row, misses))
    what = "parts" if args.two_parts else "scenes"
    print(f"{sum(not missed(r) for r in rows)} of {len(rows)} {what} met every bound; missed: {dict(tally)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
