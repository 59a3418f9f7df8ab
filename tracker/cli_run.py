"""``tracker run``: the real-time loop on a camera, a video, an image sequence or a recording."""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import signal
import sys
import threading
from pathlib import Path

from tracker import calibration as calib_io
from tracker.cli_types import CAMERA_INDEX_MAX, FPS, FRAME_COUNT, endpoint, part_height
from tracker.config import TrackerConfig
from tracker.errors import BadInput, SourceError
from tracker.health import Health
from tracker.outputs import PublishOnFirstFrame, StagedFile, check_target, refuse_clashes
from tracker.pipeline import Pipeline
from tracker.pose_sink import PoseSink
from tracker.runner import Runner, Sink, StatusLine
from tracker.scenes import SyntheticSource, preset
from tracker.sources import CameraSource, FrameSource, ImageSequenceSource, Paced, Prefetch, VideoFileSource

log = logging.getLogger(__name__)

DEMO_RECORDING = Path(__file__).resolve().parent.parent / "recordings" / "demo.mcap"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="track parts (no arguments: the bundled demo)",
                       description="Track parts on the belt. With no --source, runs the bundled demo.")
    p.add_argument("--source", help="camera index, video file, printf image pattern or .mcap recording")
    p.add_argument("--calibration", help="calibration file (.yaml/.yml/.xml); a .mcap source carries its own")
    plc = p.add_mutually_exclusive_group()
    plc.add_argument("--plc", metavar="HOST:PORT", type=endpoint, help="write poses to this Modbus TCP server")
    plc.add_argument("--no-plc", action="store_true", help="do not talk to a PLC")
    p.add_argument("--plc-unit", type=int, default=1, help="Modbus unit id (default 1)")
    p.add_argument("--plc-base", type=int, default=0, help="register base address (default 0)")
    p.add_argument("--plc-word-order", choices=("ABCD", "CDAB"), default="ABCD",
                   help="word order of 32-bit values (default ABCD: high word first)")
    p.add_argument("--plc-mode", choices=("client", "server"), default="client",
                   help="client: write into the PLC (default); server: serve the map for the arm to poll")
    p.add_argument("--record", metavar="OUT.mcap", help="record every frame and result to MCAP")
    p.add_argument("--poses", metavar="OUT.jsonl", help="write the pose stream (JSON Lines)")
    p.add_argument("--fps", type=FPS,
                   help="the frame rate a file source was captured at, for its timestamps (default: from the "
                        "container; it does not limit speed: see --realtime)")
    p.add_argument("--realtime", action="store_true",
                   help="play a file or recording at its recorded rate, like a camera (the demo does)")
    p.add_argument("--part-height", type=part_height, default=None, metavar="MM|auto",
                   help="every part is a box this many mm tall (its footprint's pose is fitted to the box's "
                        "outline; 0: flat); auto (the default): each part's height is estimated as it crosses "
                        "the view. Without the option: the settings (measure.part_height_mm, "
                        "measure.estimate_height)")
    p.add_argument("--web", metavar="HOST:PORT",
                   help="serve the live view (a read-only web page) there, e.g. 127.0.0.1:8080; "
                        "give 0.0.0.0:PORT only on a closed cell network")
    p.add_argument("--config", metavar="FILE.json", help="pipeline settings (see tracker/config.py)")
    p.add_argument("--max-frames", type=FRAME_COUNT, help="stop after this many frames (>= 1)")
    p.add_argument("--quiet", action="store_true", help="no live status line")
    p.set_defaults(func=run)


def load_config(path: str | None) -> TrackerConfig:
    if path is None:
        return TrackerConfig()
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except OSError as exc:
        raise BadInput(f"{path}: cannot read the configuration: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise BadInput(f"{path}: not a UTF-8 text file (expected JSON settings)") from None
    except json.JSONDecodeError as exc:
        raise BadInput(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    except RecursionError:
        raise BadInput(f"{path}: JSON nested too deeply (expected sections of settings)") from None
    try:
        return TrackerConfig.from_dict(data)
    except BadInput as exc:
        raise BadInput(f"{path}: {exc}") from None
    except TypeError as exc:
        raise BadInput(f"{path}: {exc}") from None


def open_source(spec: str, fps: float | None = None) -> FrameSource:
    """Camera index, video file, printf image pattern or ``.mcap`` recording. The choice is made here,
    where the run is built, so that tracker.sources never imports the recording package."""
    if fps is not None and not fps > 0:
        raise SourceError(f"--fps: expected a positive number, got {fps}")
    if spec.isdigit():
        if int(spec) > CAMERA_INDEX_MAX:
            raise SourceError(f"--source {spec}: expected a camera index from 0 to {CAMERA_INDEX_MAX}, "
                              "a video file, an image pattern or a .mcap recording")
        return CameraSource(int(spec), fps)
    if spec.lower().endswith(".mcap"):
        from tracker.recording.source import McapSource  # noqa: PLC0415 - only for recordings

        return McapSource(spec, fps)
    if "%" in spec:
        return ImageSequenceSource(spec, fps)
    return VideoFileSource(spec, fps)


def open_inputs(args: argparse.Namespace):
    """The source and its calibration (and the configuration the source may carry)."""
    demo = args.source is None
    if demo:
        if DEMO_RECORDING.is_file():
            args.source = str(DEMO_RECORDING)
        else:
            source = SyntheticSource(preset("demo"), name="synthetic demo")
            return source, source.calibration, None
    # The calibration first: a bad one is reported before any camera is opened.
    calibration = calib_io.load(args.calibration) if args.calibration else None
    if calibration is None and not args.source.lower().endswith(".mcap"):
        raise BadInput(f"--calibration is required for source {args.source}")
    source = open_source(args.source, args.fps)
    if not source.live:
        source = Prefetch(source)
        if args.realtime or demo:
            source = Paced(source)
    recorded_config = getattr(source, "config", None)
    if calibration is None:
        calibration = source.calibration
    return source, calibration, recorded_config


def _plc_sink(args: argparse.Namespace, health: Health, demo: bool) -> Sink | None:
    """The PLC writer (contract section 4), or None with --no-plc."""
    from plc.sink import open_plc_sink  # noqa: PLC0415 - pymodbus is loaded only when a PLC is used

    return open_plc_sink(args, health, demo)


def _record_sink(path: str, health: Health, source, calibration, config, fps: float | None) -> Sink:
    """The MCAP recorder writing ``path``."""
    from tracker.recording.writer import Recorder, RunInfo  # noqa: PLC0415 - optional edge

    scene = getattr(source, "scene", None)  # a synthetic scene knows its frame rate
    fps = fps or getattr(source, "fps", None) or getattr(scene, "fps", None)
    info = RunInfo(calibration, config, source.name, fps)
    return Recorder.open(path, info, health, overruns=lambda: source.overruns)


def _open_sinks(args: argparse.Namespace, health: Health, source, calibration, config, demo: bool,
                staged: list[StagedFile]) -> list[Sink]:
    """Pose stream, PLC, recorder. Output files are staged (see tracker/outputs.py and the
    recorder): they replace an existing file only once there is something to keep."""
    refuse_clashes({"--poses": args.poses, "--record": args.record},
                   {"--source": None if args.source.isdigit() else args.source,
                    "--calibration": args.calibration, "--config": args.config})
    sinks: list[Sink] = []
    try:
        if args.poses:
            staged.append(poses := StagedFile("--poses", args.poses, "the pose stream"))
            sinks.append(PublishOnFirstFrame(PoseSink(poses.path, health, shown_as=args.poses), poses))
        plc = _plc_sink(args, health, demo)
        if plc is not None:
            sinks.append(plc)
        if args.record:
            # The recorder stages its own file (moved into place with its first chunk).
            check_target("--record", args.record, "the recording")
            sinks.append(_record_sink(args.record, health, source, calibration, config, args.fps))
    except BaseException:
        for sink in sinks:
            sink.close()
        raise
    return sinks


def run(args: argparse.Namespace) -> int:
    demo = args.source is None
    # Settings first: a bad file is reported before any camera or file is opened.
    given_config = load_config(args.config) if args.config else None
    source, calibration, recorded_config = open_inputs(args)
    config = given_config or recorded_config or TrackerConfig()
    if args.part_height is not None:
        # The option replaces the settings' height, given or estimated, whichever they held.
        auto = args.part_height == "auto"
        height = {"part_height_mm": 0.0 if auto else args.part_height, "estimate_height": auto}
        config = dataclasses.replace(config, measure=dataclasses.replace(config.measure, **height))
    health = Health()
    stop = threading.Event()
    staged: list[StagedFile] = []
    try:
        pipeline = Pipeline(calibration, config)
        sinks = _open_sinks(args, health, source, calibration, config, demo, staged)
    except BaseException:
        for file in staged:
            file.discard()
        source.close()
        raise
    web = None
    if args.web:
        try:
            web = _web(args.web, calibration, health, sinks, pipeline)
        except BaseException:
            for sink in sinks:
                sink.close()
            source.close()
            raise
        sinks.append(web.view)
    status = None if args.quiet else StatusLine(sys.stderr)
    runner = Runner(source, pipeline, sinks, health, status, stop, args.max_frames)
    previous = _install_signal_handlers(stop)
    try:
        summary = runner.run()
    finally:
        _restore_signal_handlers(previous)
        if web is not None:
            web.close()
    if not summary.frames and summary.stopped_by == "end of source":
        # An empty video, a recording cut before its first chunk: "0 frames" and exit 0 hid it.
        raise SourceError(f"--source {source.name}: it ended before its first frame; nothing was tracked "
                          f"(outputs left as they were)")
    print(f"tracker: {summary.line()}")
    return 0


def _web(spec: str, calibration, health: Health, sinks: list, pipeline: Pipeline):
    """The live view's server on HOST:PORT (tracker/web), started; its sink is ``.view``."""
    from plc.options import parse_endpoint  # noqa: PLC0415 - the same HOST:PORT rules as --plc
    from tracker.web import LiveView, WebServer  # noqa: PLC0415 - only with --web

    host, port = parse_endpoint(spec, "--web")
    view = LiveView(calibration, health, list(sinks), pipeline.roi_px)
    server = WebServer(view, host, port).start()
    server.view = view
    return server


def _install_signal_handlers(stop: threading.Event) -> dict:
    """SIGINT/SIGTERM end the loop after the current frame, so every sink closes properly."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, lambda *_: stop.set())
    return previous


def _restore_signal_handlers(previous: dict) -> None:
    for sig, handler in previous.items():
        signal.signal(sig, handler)
