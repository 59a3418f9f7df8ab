"""Belt motion: how far off the belt's shift per frame reads, and what reading it costs, for the
textured model's estimator (tracker/segment/motion.py) and OpenCV's cv2.phaseCorrelate (the peak's
centroid, what it used before 2026-12-02) in the same run.

    .venv/bin/python bench/belt_motion.py [--json]

A random texture slid diagonally (dy = 0.35 dx) by a given step per frame, region 640x480 (averaged
down to 256 px, as the model does), 30 frames per step. Prints, per step, each estimator's mean error
and worst error (px, both axes), and the time per frame of each with their ratio.
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

from tracker.segment.motion import BeltMotion  # noqa: E402

STEPS_PX = (0.5, 1.0, 1.5, 2.5, 3.7, 6.0, 11.3)
FRAMES = 30
REGION = (640, 480)


class CentroidMotion:
    """The estimator before: cv2.phaseCorrelate on the same averaged-down patch."""

    def __init__(self, size: tuple[int, int], scale: float) -> None:
        self._size, self._scale = size, scale
        self._window = cv2.createHanningWindow(size, cv2.CV_32F)
        self._prev: np.ndarray | None = None

    def __call__(self, frame: np.ndarray) -> tuple[float, float]:
        patch = cv2.resize(frame, self._size, interpolation=cv2.INTER_AREA).astype(np.float32)
        prev, self._prev = self._prev, patch
        if prev is None:
            return 0.0, 0.0
        (dx, dy), _ = cv2.phaseCorrelate(prev, patch, self._window)
        return dx / self._scale, dy / self._scale


def texture() -> np.ndarray:
    """A random belt texture (grey levels 40-90, a 1.5 px blur), wider than the region by the travel."""
    rng = np.random.default_rng(4)
    width, height = REGION
    return cv2.GaussianBlur(rng.uniform(40, 90, (height + 120, width + 600)).astype(np.float32), (0, 0), 1.5)


def frames(belt: np.ndarray, step_px: float) -> list[np.ndarray]:
    width, height = REGION
    out = []
    for i in range(FRAMES):
        moved = cv2.warpAffine(belt, np.float32([[1, 0, step_px * i], [0, 1, 0.35 * step_px * i]]),
                               (belt.shape[1], belt.shape[0]), flags=cv2.INTER_CUBIC)
        out.append(np.ascontiguousarray(moved[60:60 + height, 300:300 + width]).astype(np.uint8))
    return out


def measure() -> dict:
    width, height = REGION
    scale = 256 / max(width, height)
    rows, spent, belt = [], {"phase": 0.0, "centroid": 0.0}, texture()
    for step in STEPS_PX:
        images, truth = frames(belt, step), np.array([step, 0.35 * step])
        row = {"step_px": step}
        for name, estimator in (("phase", BeltMotion(np.full((height, width), 255, np.uint8))),
                                ("centroid", CentroidMotion((round(width * scale), round(height * scale)), scale))):
            start = time.perf_counter()
            read = np.array([estimator(image) for image in images][1:])
            spent[name] += time.perf_counter() - start
            error = read - truth
            row[name] = {"mean_error_px": [round(float(e), 4) for e in error.mean(axis=0)],
                         "worst_error_px": round(float(np.abs(error).max()), 4)}
        rows.append(row)
    per_frame = {name: 1e3 * s / (len(STEPS_PX) * FRAMES) for name, s in spent.items()}
    return {"steps": rows, "ms_per_frame": per_frame, "cost_ratio": per_frame["phase"] / per_frame["centroid"]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    result = measure()
    if args.json:
        print(json.dumps(result, indent=1))
        return 0
    print(f"OpenCV {cv2.__version__}; region {REGION[0]}x{REGION[1]}, {FRAMES} frames per step, dy = 0.35 dx")
    print("| step (px/frame) | motion.py: mean error dx, dy / worst (px) "
          "| cv2.phaseCorrelate: mean error dx, dy / worst (px) |")
    print("|---|---|---|")
    for row in rows_of(result):
        print(row)
    ms = result["ms_per_frame"]
    print(f"time per frame (resize included): motion.py {ms['phase']:.2f} ms, cv2.phaseCorrelate "
          f"{ms['centroid']:.2f} ms, ratio {result['cost_ratio']:.2f}")
    return 0


def rows_of(result: dict) -> list[str]:
    def cell(r: dict) -> str:
        dx, dy = r["mean_error_px"]
        return f"{dx:+.3f}, {dy:+.3f} / {r['worst_error_px']:.3f}"

    return [f"| {r['step_px']:g} | {cell(r['phase'])} | {cell(r['centroid'])} |" for r in result["steps"]]


if __name__ == "__main__":
    raise SystemExit(main())
