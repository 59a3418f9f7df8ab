"""``tracker replay REC.mcap [--poses OUT.jsonl] [--check]``."""

from __future__ import annotations

import argparse
import logging
import sys

from tracker.errors import BadInput, RecordingError
from tracker.outputs import refuse_clashes
from tracker.recording.replay import replay

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay", help="re-run the pipeline on a recording (--check: compare with the live poses)",
        description="Re-runs the pipeline with the recording's own calibration and configuration on its "
        "frames, as fast as it can. --check exits 1 at the first pose that differs from the live run.")
    p.add_argument("recording", metavar="REC.mcap", help="a recording made with 'tracker run --record'")
    p.add_argument("--poses", metavar="OUT.jsonl", help="write the replayed pose stream (JSON Lines)")
    p.add_argument("--check", action="store_true", help="compare every pose with the one logged live")
    p.add_argument("--tolerance", type=float, default=0.0, metavar="X",
                   help="with --check, accept numbers that differ by up to X (mm, deg, mm/s): for a replay on "
                        "another CPU type, whose floating-point rounding may differ in the last digit "
                        "(default 0: byte-identical)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not args.tolerance >= 0:
        raise BadInput(f"--tolerance: expected a number >= 0, got {args.tolerance}")
    if args.tolerance and not args.check:
        raise BadInput("--tolerance goes with --check (it is how far a pose may differ from the live run's)")
    refuse_clashes({"--poses": args.poses}, {"REC.mcap": args.recording})
    report = replay(args.recording, args.poses, args.check, args.tolerance, None if args.quiet else sys.stderr)
    end = report.end
    if end.damaged:
        raise RecordingError(f"{end.describe(args.recording)}; replayed the {report.frames} frames before it")
    if not end.complete:
        print(f"tracker: {end.describe(args.recording)}; replayed the {report.frames} frames up to there",
              file=sys.stderr)
    same = f"within {args.tolerance:g} of" if args.tolerance else "identical to"
    checked = f"; all {report.checked} poses {same} the live run" if args.check else ""
    overruns = report.end_metadata.get("overruns")
    live = f" (live run: {overruns} overruns)" if overruns not in (None, "", "0") else ""
    print(f"tracker: replayed {report.frames} frames in {report.seconds:.2f} s ({report.fps:.0f} fps){checked}{live}")
    return 0
