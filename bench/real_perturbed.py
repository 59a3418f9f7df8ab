"""The labelled real videos as another cell's camera would show them: each change applied alone.

    .venv/bin/python bench/real_perturbed.py            # every change, both labelled videos
    .venv/bin/python bench/real_perturbed.py --only blur7 --default-settings

Changes that keep each pixel where it is (exposure, gamma, contrast, noise, JPEG, flicker, blur
along the belt, half the frame rate), so the hand labels hold as they are. Each run is scored by the
real-video bench's own code (tracker/score_video.py): parts found as one track, phantoms, counts.
``--default-settings``: with no settings at all (the default belt model, no region, no part sizes)
instead of each video's own. Numbers, not assertions; docs/HISTORY.md ("The labelled videos
perturbed") has the figures and what they showed.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tracker.config import TrackerConfig  # noqa: E402
from tracker.score_video import VIDEOS, load_truth, run_video, score  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "conveyor_videos"


def _lut(f: Callable[[np.ndarray], np.ndarray]) -> Callable[[np.ndarray], np.ndarray]:
    table = np.clip(np.rint(f(np.arange(256, dtype=np.float64))), 0, 255).astype(np.uint8)
    return lambda frame: cv2.LUT(frame, table)


def _noise(sigma: float) -> Callable[[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(0)
    return lambda frame: np.clip(np.rint(frame + rng.normal(0, sigma, frame.shape)), 0, 255).astype(np.uint8)


def _jpeg(quality: int) -> Callable[[np.ndarray], np.ndarray]:
    def change(frame: np.ndarray) -> np.ndarray:
        ok, data = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, quality])
        return cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
    return change


def _flicker(depth: float, period_frames: int) -> Callable[[np.ndarray], np.ndarray]:
    count = iter(range(10**9))
    return lambda frame: cv2.convertScaleAbs(frame, alpha=1 + depth * np.sin(2 * np.pi * next(count) / period_frames))


def _blur_along(px: int, vertical: bool) -> Callable[[np.ndarray], np.ndarray]:
    kernel = np.ones((px, 1) if vertical else (1, px), np.float32) / px
    return lambda frame: cv2.filter2D(frame, -1, kernel, borderType=cv2.BORDER_REPLICATE)


def _frame_flicker(levels: int) -> Callable[[np.ndarray], np.ndarray]:
    """The whole view ``levels`` brighter and darker in turn, frame by frame (mains flicker against a
    short exposure)."""
    count = iter(range(10**9))
    return lambda frame: (cv2.add if next(count) % 2 else cv2.subtract)(frame, levels)


def _half_rate() -> Callable[[np.ndarray], np.ndarray]:
    """Every other frame repeats the one before, capture times kept (a half-rate camera behind a
    frame-rate conversion)."""
    state = {"i": 0, "last": None}

    def change(frame: np.ndarray) -> np.ndarray:
        state["i"] += 1
        if state["i"] % 2 == 0 and state["last"] is not None:
            return state["last"]
        state["last"] = frame
        return frame
    return change


def changes(vertical_belt: bool) -> dict[str, Callable[[], Callable[[np.ndarray], np.ndarray]]]:
    """Each change by name, made fresh per run (some keep state across frames)."""
    return {
        "none": lambda: (lambda frame: frame),
        "darker40": lambda: _lut(lambda v: 0.6 * v),
        "brighter30": lambda: _lut(lambda v: 1.3 * v),
        "gamma0.6": lambda: _lut(lambda v: 255 * (v / 255) ** 0.6),
        "gamma1.6": lambda: _lut(lambda v: 255 * (v / 255) ** 1.6),
        "contrast0.6": lambda: _lut(lambda v: 128 + 0.6 * (v - 128)),
        "noise6": lambda: _noise(6.0),
        "jpeg10": lambda: _jpeg(10),
        "flicker10": lambda: _flicker(0.10, 30),
        "frame_flicker10": lambda: _frame_flicker(10),
        "blur7": lambda: _blur_along(7, vertical_belt),
        "half_rate": _half_rate,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", action="append", help="run only this change (repeatable)")
    parser.add_argument("--default-settings", action="store_true",
                        help="no settings at all, instead of each video's own")
    args = parser.parse_args(argv)
    unknown = set(args.only or ()) - set(changes(False))
    if unknown:
        parser.error(f"--only: expected one of {sorted(changes(False))}, got {sorted(unknown)}")
    if not DATA.is_dir():
        print(f"real videos perturbed: skipped ({DATA} is absent)")
        return 0
    for video in (v for v in VIDEOS if v.labelled):
        truth = load_truth(DATA, video)
        vertical = truth["parts"][0]["direction"] in ("bottom_to_top", "top_to_bottom")
        for name, make in changes(vertical).items():
            if args.only and name not in args.only:
                continue
            config = TrackerConfig() if args.default_settings else None
            run = run_video(video, DATA, config, change=make())
            s = score(run.results, truth, video.last_frame)
            print(f"{video.file:<38} {name:<12} {s.line()}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
