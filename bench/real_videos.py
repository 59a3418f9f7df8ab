"""Real conveyor videos: the pipeline's loop time per frame against each camera's frame interval.

    .venv/bin/python bench/real_videos.py        # also run by `make bench`

For each video in ../shared/data/conveyor_videos (skipped when absent): frames decoded first,
then the pipeline (textured belt model, the belt area, an approximate straight-down calibration)
timed per frame; p50 and p99 are printed beside the frame interval, with the hand-label score
where labels exist. Numbers, not assertions.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tracker.score_video import VIDEOS, load_truth, run_video, score  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "conveyor_videos"


def main() -> int:
    if not DATA.is_dir():
        print(f"real videos: skipped ({DATA} is absent)")
        return 0
    print(f"{'real video':<38} {'frames':>6} {'p50 ms':>7} {'p99 ms':>7} {'interval ms':>11}  within  score")
    for video in VIDEOS:
        run = run_video(video, DATA)
        interval = 1000.0 / run.fps
        p50, p99 = run.loop_ms(50), run.loop_ms(99)
        line = (f"{video.file:<38} {len(run.results):>6} {p50:>7.2f} {p99:>7.2f} {interval:>11.1f}  "
                f"{'yes' if p99 <= interval else 'NO':>6}  ")
        if video.labelled:
            line += score(run.results, load_truth(DATA, video), video.last_frame).line()
        else:
            line += f"{len({o.id for r in run.results for o in r.objects})} tracks (no labels)"
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
