"""Accuracy of belt-tracker against the plain seed method on the same synthetic scenes.

    .venv/bin/python bench/compare_seed.py [--json]

Prints a Markdown table (the README's "Accuracy" section comes from it): for each
scene, the errors of our pipeline, of the same pipeline with binary-mask edges,
and of the seed method (whole-frame undistort, consecutive-frame difference,
pixel minAreaRect, no filter), all against exact ground truth.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from tracker.config import MeasureConfig, TrackerConfig  # noqa: E402
from tracker.evaluate import evaluate  # noqa: E402
from tracker.pipeline import Pipeline  # noqa: E402
from tracker.scenes import nadir, tilted  # noqa: E402
from tracker.seed import SeedMethod  # noqa: E402
from tracker.synthetic import Renderer  # noqa: E402
from tracker.undistort import BeltMapper, FrameUndistorter  # noqa: E402

SCENES = {
    "nadir, 300 mm/s, 60 fps": lambda: nadir(300.0),
    "nadir, 600 mm/s, 60 fps": lambda: nadir(600.0),
    "20 deg tilt + strong distortion, 300 mm/s": lambda: tilted(300.0),
}
METHODS = {
    "belt-tracker": lambda calib: Pipeline(calib),
    "belt-tracker, binary edges": lambda calib: Pipeline(calib, TrackerConfig(measure=MeasureConfig(subpixel=False))),
    "seed method": SeedMethod,
}
COLUMNS = ("centroid_mean_mm", "centroid_p95_mm", "along_bias_mm", "angle_mean_deg", "length_max_mm",
           "width_max_mm", "missed_frames", "false_objects")


def compare() -> list[dict]:
    rows = []
    for scene_name, make in SCENES.items():
        scene = make()
        renderer = Renderer(scene)
        frames = [renderer.render(i) for i in range(scene.n_frames)]
        truths = [t for _, t in frames]
        for method_name, build in METHODS.items():
            method = build(renderer.calibration)
            poses = [method.process(i, img, scene.t_ns(i)).to_dict() for i, (img, _) in enumerate(frames)]
            summary = evaluate(poses, truths, skip_first=2).summary()
            rows.append({"scene": scene_name, "method": method_name, **{k: summary[k] for k in COLUMNS}})
    return rows


def undistortion_choice(repeats: int = 200) -> dict:
    """Whole-frame remap vs exact undistortion of one part's edge points, 1280x720."""
    scene = tilted()
    from tracker.scenes import resized  # noqa: PLC0415

    scene = resized(scene, 1280, 720)
    calib = Renderer(scene).calibration
    frame = np.zeros((720, 1280), np.uint8)
    remap = FrameUndistorter(calib)
    mapper = BeltMapper(calib)
    points = np.random.default_rng(0).uniform([0, 0], [1280, 720], (450, 2))  # ~ one part's edge points
    t0 = time.perf_counter()
    for _ in range(repeats):
        remap(frame)
    t1 = time.perf_counter()
    for _ in range(repeats):
        mapper.to_mm(points)
    t2 = time.perf_counter()
    for _ in range(repeats):
        cv2.undistort(frame, calib.camera_matrix, calib.dist_coeffs)
    t3 = time.perf_counter()
    return {"remap_frame_ms": (t1 - t0) / repeats * 1e3, "undistort_frame_ms": (t3 - t2) / repeats * 1e3,
            "points_450_ms": (t2 - t1) / repeats * 1e3}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    rows = compare()
    choice = undistortion_choice()
    if args.json:
        print(json.dumps({"accuracy": rows, "undistortion": choice}, indent=1))
        return 0
    print("| scene | method | centroid mean / p95 (mm) | along-track bias (mm) | angle mean (deg) "
          "| length / width max error (mm) | missed / false |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['method']} | {r['centroid_mean_mm']:.3f} / {r['centroid_p95_mm']:.3f} "
              f"| {r['along_bias_mm']:+.3f} | {r['angle_mean_deg']:.3f} "
              f"| {r['length_max_mm']:.2f} / {r['width_max_mm']:.2f} | {r['missed_frames']} / {r['false_objects']} |")
    print()
    print(f"Undistortion at 1280x720: whole frame remap {choice['remap_frame_ms']:.2f} ms, cv2.undistort "
          f"{choice['undistort_frame_ms']:.2f} ms; 450 edge points exactly {choice['points_450_ms']:.3f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
