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


# Fields only a truth file's objects have (the renderer's visibility), never a pose stream's.
_TRUTH_ONLY = "visible_px"


def _read(path: str, what: str, truth: bool) -> list[dict]:
    try:
        frames = read_poses(path)
    except OSError as exc:
        raise BadInput(f"{path}: cannot read: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise BadInput(f"{path}: not a text file; expected {what}") from None
    except json.JSONDecodeError as exc:
        raise BadInput(f"{path}: line {exc.lineno}: not JSON ({exc.msg}); expected {what}") from None
    for n, frame in enumerate(frames, 1):
        objects = frame.get("objects") if isinstance(frame, dict) else None
        if not isinstance(objects, list) or not isinstance(frame.get("frame"), int):
            raise BadInput(f"{path}: line {n}: expected {what} (a 'frame' number and an 'objects' list)")
        for obj in objects:
            if not isinstance(obj, dict) or not {"x_mm", "y_mm", "angle_deg"} <= obj.keys():
                raise BadInput(f"{path}: line {n}: an object without x_mm, y_mm, angle_deg; expected {what}")
            if (_TRUTH_ONLY in obj) != truth:
                other = "a truth file" if not truth else "a pose stream"
                raise BadInput(f"{path}: line {n}: this is {other}, expected {what} (arguments swapped?)")
    return frames


def run(args: argparse.Namespace) -> int:
    poses = _read(args.poses, "a pose stream (tracker run --poses)", truth=False)
    truths = _read(args.truth, "a truth file (truth.jsonl from tracker synth)", truth=True)
    if not {p["frame"] for p in poses} & {t["frame"] for t in truths}:
        raise BadInput(f"{args.poses} and {args.truth} have no frame number in common")
    acc = evaluate(poses, truths, skip_first=args.skip_first)
    if acc.visible_frames and acc.missed_frames == acc.visible_frames and acc.false_objects:
        raise BadInput(f"{args.poses}: no reported object is near any true part of {args.truth}: "
                       "is it the truth of the scene these poses were tracked on?")
    summary = acc.summary()
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
