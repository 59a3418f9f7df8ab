"""What the plain belt model's faint faces cost (segment.faint_threshold): its segmentation per frame with
them and without, in one run, as a ratio.

    .venv/bin/python bench/faint_faces.py [--size 1280x720] [--parts 1] [--frames 60] [--repeats 5]

Each frame holds --parts bright parts (160x120 px), each with a side face 8 px wide 18 grey levels above
the belt (joined with them, left out without), moving 8 px a frame over a belt with noise (sigma 1.5).
Prints each variant's best mean time per frame (ms) over the repeats and their ratio.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402

from tracker.config import SegmentConfig  # noqa: E402
from tracker.segment.reference import Segmenter  # noqa: E402

BELT, TOP, SIDE = 80, 180, 98  # grey levels


def frames(width: int, height: int, parts: int, count: int) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    out = []
    for i in range(count):
        image = np.full((height, width), float(BELT))
        for p in range(parts):
            x = 40 + 8 * i + 220 * p
            y = 40 + (p % 3) * 200
            image[y:y + 120, x:x + 160] = TOP
            image[y:y + 120, x + 160:x + 168] = SIDE
        out.append(np.clip(image + rng.normal(0, 1.5, image.shape), 0, 255).astype(np.uint8))
    return out


def per_frame_ms(config: SegmentConfig, sequence: list[np.ndarray], repeats: int) -> float:
    """The best over ``repeats`` passes of the mean segmentation time per frame (the first frame, the
    reference, not counted)."""
    best = float("inf")
    for _ in range(repeats):
        segmenter = Segmenter(config)
        segmenter(sequence[0])
        start = time.perf_counter()
        for frame in sequence[1:]:
            segmenter(frame)
        best = min(best, (time.perf_counter() - start) / (len(sequence) - 1) * 1e3)
    return best


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--parts", type=int, default=1)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))
    sequence = frames(width, height, args.parts, args.frames)
    with_ms = per_frame_ms(SegmentConfig(), sequence, args.repeats)
    without_ms = per_frame_ms(SegmentConfig(faint_threshold=0), sequence, args.repeats)
    print(f"segmentation at {args.size}, {args.parts} part(s): faint faces joined {with_ms:.2f} ms/frame, "
          f"without {without_ms:.2f} ms/frame, ratio {with_ms / without_ms:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
