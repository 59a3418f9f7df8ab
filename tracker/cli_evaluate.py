"""``tracker evaluate``: accuracy of a pose stream against a synthetic scene's ground truth."""

from __future__ import annotations

import argparse
import json

from tracker.errors import BadInput
from tracker.evaluate import evaluate
from tracker.poses import read_poses


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="compare a pose stream with ground truth (from tracker synth)",
                       description="Prints centroid, angle and size errors of POSES against TRUTH.")
    p.add_argument("poses", help="pose stream (.jsonl) from tracker run --poses")
    p.add_argument("truth", help="truth.jsonl from tracker synth")
    p.add_argument("--skip-first", type=int, default=2,
                   help="measured frames of each part left out of the errors (default 2: velocity unknown)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def _read(path: str) -> list[dict]:
    try:
        return read_poses(path)
    except OSError as exc:
        raise BadInput(f"{path}: cannot read: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise BadInput(f"{path}: line {exc.lineno}: not JSON ({exc.msg})") from None


def run(args: argparse.Namespace) -> int:
    summary = evaluate(_read(args.poses), _read(args.truth), skip_first=args.skip_first).summary()
    if args.json:
        print(json.dumps(summary))
        return 0
    print(f"fully visible part-frames: {summary['visible_frames']}, missed: {summary['missed_frames']}, "
          f"false objects: {summary['false_objects']}")
    print(f"centroid error: mean {summary['centroid_mean_mm']:.3f} mm, p95 {summary['centroid_p95_mm']:.3f} mm; "
          f"along-track bias {summary['along_bias_mm']:+.3f} mm")
    print(f"angle error: mean {summary['angle_mean_deg']:.3f} deg, p95 {summary['angle_p95_deg']:.3f} deg; "
          f"length/width max error {summary['length_max_mm']:.3f} / {summary['width_max_mm']:.3f} mm")
    return 0
