"""``tracker calibrate capture``: watch a camera (or a video) for the board, keep good views, calibrate.

The edge of the capture: it reads the source, prints the status line, saves the views and hands
them to the same code as ``calibrate intrinsics``. Which view to keep is :mod:`capture`'s business.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import cv2
import numpy as np

from tracker.calibrate.board import Pattern, detect, parse_pattern
from tracker.calibrate.capture import CaptureSettings, Progress, ViewSelector
from tracker.calibrate.cli import calibrate_and_write, check_intrinsics_args
from tracker.errors import BadInput
from tracker.outputs import check_writable


def run_capture(args: argparse.Namespace) -> int:
    pattern = parse_pattern(args.pattern, args.square)
    out, report_path = check_intrinsics_args(args)
    settings = _settings(args)
    views_dir = _views_dir(Path(args.views) if args.views else out.with_suffix(".views"))
    from tracker.cli_run import open_source  # noqa: PLC0415 - the source choice lives with the run

    source = open_source(args.source)
    view, server = _web(args.web, settings) if args.web else (None, None)
    live = sys.stderr.isatty() and not args.quiet
    selector: ViewSelector | None = None
    paths: list[str] = []
    images: list[np.ndarray] = []
    stopped_by = "end of source"
    try:
        for frame in source:
            image = frame.image
            if selector is None:
                selector = ViewSelector(pattern, (image.shape[1], image.shape[0]), settings)
            elif image.shape[:2] != (selector.size[1], selector.size[0]):
                raise BadInput(f"{args.source}: frame {frame.index} is {image.shape[1]}x{image.shape[0]}, "
                               f"expected {selector.size[0]}x{selector.size[1]} like the first")
            corners = _board(image, pattern, args.detector)
            kept = selector.offer(image, corners)
            if view is not None:
                view.submit(frame.index, image, corners, selector.progress, selector.cells)
            if kept:
                views_dir.mkdir(exist_ok=True)  # only now: a capture that keeps no view leaves no folder
                path = views_dir / f"view_{len(paths):03d}.png"
                if not cv2.imwrite(str(path), image):
                    raise BadInput(f"{path}: cannot write the view")
                paths.append(str(path))
                images.append(image)
            _status(selector.progress, settings, live, kept_now=selector.progress.last == "kept")
            if selector.enough():
                stopped_by = "enough views"
                break
    except KeyboardInterrupt:
        stopped_by = "Ctrl-C"
    finally:
        source.close()
        if server is not None:
            server.close()
    if live:
        print(file=sys.stderr)
    p = selector.progress if selector else Progress()
    refused = ", ".join(f"{n} {why}" for why, n in sorted(p.rejected.items())) or "none"
    print(f"capture: {stopped_by}: {p.frames} frames, {p.kept} views kept in {views_dir} "
          f"(coverage {p.cells}/{settings.coverage_cells ** 2} cells, tilted {p.tilt_directions}/4 "
          f"directions); frames not kept: {refused}")
    if len(paths) < args.min_views:
        raise BadInput(f"{args.source}: only {len(paths)} good views of the {pattern} board, expected at least "
                       f"{args.min_views} (--min-views): move the board slowly through the whole image, "
                       f"tilted in several directions")
    print(f"capture: the same result again: tracker calibrate intrinsics {views_dir}/view_*.png "
          f"--pattern {args.pattern} --square {args.square:g} --out {out}")
    return calibrate_and_write(paths, images, pattern, out, report_path, args)


def _web(spec: str, settings: CaptureSettings):
    from plc.options import parse_endpoint  # noqa: PLC0415 - the same HOST:PORT rules as tracker run --web
    from tracker.calibrate.capture_view import CaptureView  # noqa: PLC0415 - only with --web
    from tracker.web import WebServer  # noqa: PLC0415 - only with --web

    host, port = parse_endpoint(spec, "--web")
    view = CaptureView(settings)
    server = WebServer(view, host, port).start()
    print(f"capture: live view on {server.url}", file=sys.stderr)
    return view, server


def _settings(args: argparse.Namespace) -> CaptureSettings:
    if args.target_views < args.min_views:
        raise BadInput(f"--target-views: expected at least --min-views ({args.min_views}), got {args.target_views}")
    return dataclasses.replace(CaptureSettings(), target_views=args.target_views, max_views=args.max_views)


def _views_dir(path: Path) -> Path:
    """A new or empty folder (made once the first view is kept): views of another session are never
    mixed in or overwritten."""
    if path.exists() and (not path.is_dir() or any(path.iterdir())):
        raise BadInput(f"{path}: the views folder exists and is not empty: choose another with --views")
    check_writable(path, "the views")
    return path


def _board(image: np.ndarray, pattern: Pattern, detector: str) -> np.ndarray | None:
    # A quick look first: a live camera mostly shows no whole board, and the full search is slow.
    ok, _ = cv2.findChessboardCorners(image, pattern.size, flags=cv2.CALIB_CB_FAST_CHECK)
    if not ok:
        return None
    found = detect(image, pattern, detector)
    return None if found is None else found.corners


def _status(p: Progress, s: CaptureSettings, live: bool, kept_now: bool) -> None:
    line = (f"capture: frame {p.frames}, {p.kept}/{s.target_views} views, coverage {p.cells}/"
            f"{s.coverage_cells ** 2} cells (want {s.min_cells}), tilted {p.tilt_directions}/4 directions "
            f"(want {s.min_tilt_directions}); last: {p.last}")
    if live:
        print("\r" + line.ljust(120), end="", file=sys.stderr, flush=True)
    elif kept_now:
        print(line, file=sys.stderr)
