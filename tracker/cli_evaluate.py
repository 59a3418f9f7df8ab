"""``tracker evaluate``: accuracy of a pose stream against a synthetic scene's ground truth."""

from __future__ import annotations

import argparse
import json
import math

from tracker.errors import BadInput
from tracker.evaluate import evaluate
from tracker.poses import PoseLineError, read_poses


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
    except PoseLineError as exc:
        raise BadInput(f"{path}: {exc}; expected {what}") from None
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
    # No measured part-frame (all missed, or all within --skip-first): no error to state. JSON has no
    # NaN (json.dumps wrote one, which JSON readers refuse): null, and "none" in the text.
    summary = {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in acc.summary().items()}
    if args.json:
        print(json.dumps(summary))
        return 0

    def mm(key: str, sign: str = "") -> str:
        return "none" if summary[key] is None else f"{summary[key]:{sign}.3f}"

    print(f"fully visible part-frames: {summary['visible_frames']}, missed: {summary['missed_frames']}, "
          f"false objects: {summary['false_objects']}")
    print(f"centroid error: mean {mm('centroid_mean_mm')} mm, p95 {mm('centroid_p95_mm')} mm; "
          f"along-track bias {mm('along_bias_mm', '+')} mm")
    print(f"angle error: mean {mm('angle_mean_deg')} deg, p95 {mm('angle_p95_deg')} deg; "
          f"length/width max error {mm('length_max_mm')} / {mm('width_max_mm')} mm")
    return 0
