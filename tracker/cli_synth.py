"""``tracker synth``: render a synthetic scene with exact ground truth to disk."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import sys
from pathlib import Path
from typing import TextIO

import cv2

from tracker import calibration as calib_io
from tracker.errors import BadInput
from tracker.scenes import PRESETS, preset, resized
from tracker.synthetic import Renderer, SceneSpec


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "synth", help="render a synthetic scene (frames, calibration, ground truth)",
        description="With --out DIR: writes DIR/frames/%05d.png, DIR/calibration.yaml, DIR/truth.jsonl "
        "(pose-stream shape) and DIR/scene.json. With --record OUT.mcap: tracks the scene and records it "
        "(the same command gives the same bytes; `make demo` remakes recordings/demo.mcap).",
    )
    p.add_argument("preset", choices=sorted(PRESETS), help="scene to render")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--out", help="output folder")
    out.add_argument("--record", metavar="OUT.mcap",
                     help="instead of files, track the scene and record it (how recordings/demo.mcap is made)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing --record file, or the scene in an existing --out folder")
    p.add_argument("--zstd-level", type=int, metavar="N",
                   help="with --record, compress harder than a live recording does (default: the recorder's, 1; "
                        "`make demo` uses 19: a third smaller, twice the time)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--frames", type=int, help="number of frames (default: the preset's)")
    p.add_argument("--size", help="WIDTHxHEIGHT (same field of view)")
    p.add_argument("--noise", type=float, help="sensor noise sigma, grey levels")
    p.add_argument("--flicker", type=float, help="relative lighting flicker, e.g. 0.03")
    p.add_argument("--seed", type=int, help="noise seed")
    p.set_defaults(func=run)


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise BadInput(f"--size: expected WIDTHxHEIGHT, got {text!r}") from None
    if w < 64 or h < 64:
        raise BadInput(f"--size: expected at least 64x64, got {w}x{h}")
    return w, h


def scene_from_args(args: argparse.Namespace) -> SceneSpec:
    if args.frames is not None and args.frames < 1:
        raise BadInput(f"--frames: expected at least 1, got {args.frames}")
    scene = preset(args.preset)
    changes = {k: v for k, v in (("n_frames", args.frames), ("noise_sigma", args.noise),
                                 ("flicker", args.flicker), ("seed", args.seed)) if v is not None}
    scene = dataclasses.replace(scene, **changes)
    if args.size:
        scene = resized(scene, *parse_size(args.size))
    return scene


def write_scene(scene: SceneSpec, out: Path, progress_out: TextIO | None = None) -> Path:
    """Render every frame; returns the printf pattern of the frames."""
    frames = out / "frames"
    try:
        frames.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BadInput(f"{out}: cannot create the output folder: {exc.strerror}") from None
    renderer = Renderer(scene)
    calib_io.save(renderer.calibration, out / "calibration.yaml")
    (out / "scene.json").write_text(json.dumps(dataclasses.asdict(scene), indent=1))
    progress = _progress(progress_out, scene.n_frames)
    with open(out / "truth.jsonl", "w", encoding="utf-8") as truth_file:
        for index in range(scene.n_frames):
            image, truth = renderer.render(index)
            if not cv2.imwrite(str(frames / f"{index:05d}.png"), image, [cv2.IMWRITE_PNG_COMPRESSION, 1]):
                raise BadInput(f"{frames}: cannot write frame {index}")
            truth_file.write(json.dumps(truth) + "\n")
            if progress:
                progress.update(index + 1)
    if progress:
        progress.end(scene.n_frames)
    return frames / "%05d.png"


def _progress(out: TextIO | None, total: int):
    if out is None:
        return None
    from tracker.recording.replay import Progress  # noqa: PLC0415 - the bar lives with the recording tools

    return Progress(out, total, "synth")


def run(args: argparse.Namespace) -> int:
    scene = scene_from_args(args)
    progress_out = None if args.quiet else sys.stderr
    if args.record:
        if os.path.exists(args.record) and not args.force:
            raise BadInput(f"--record {args.record}: the file exists (give --force to replace it)")
        from tracker.demo_recording import record_scene  # noqa: PLC0415 - optional edge
        from tracker.recording.writer import RecorderConfig  # noqa: PLC0415

        if args.zstd_level is not None and not -7 <= args.zstd_level <= 22:
            raise BadInput(f"--zstd-level: expected -7 to 22, got {args.zstd_level}")
        recorder = RecorderConfig() if args.zstd_level is None else RecorderConfig(zstd_level=args.zstd_level)
        summary = record_scene(scene, args.record, name=f"synthetic {args.preset}", recorder=recorder,
                               progress_out=progress_out)
        print(f"tracker: {summary.line()} -> {args.record}")
        return 0
    if not args.out:
        raise BadInput("synth: give --out DIR (frames on disk) or --record OUT.mcap")
    if args.zstd_level is not None:
        raise BadInput("synth: --zstd-level goes with --record")
    out = Path(args.out)
    _check_out_folder(out, args.force)
    pattern = write_scene(scene, out, progress_out)
    print(f"tracker: {scene.n_frames} frames at {scene.fps:g} fps -> {pattern}")
    print(f"tracker: run it with: tracker run --source {pattern} --calibration {Path(args.out) / 'calibration.yaml'} "
          f"--fps {scene.fps:g} --no-plc --poses poses.jsonl")
    return 0


def _check_out_folder(out: Path, force: bool) -> None:
    """``out`` is new or empty, or (``force``) a scene of ours to replace: its old frames are removed
    first. Written over, a 40-frame scene given 3 new frames kept 37 old ones beside the new truth,
    and a run over them was tracked against the wrong scene without a word."""
    if out.exists() and not out.is_dir():
        raise BadInput(f"--out {out}: it is a file; expected a folder")
    if not out.is_dir() or not any(out.iterdir()):
        return
    if not force:
        raise BadInput(f"--out {out}: the folder exists and is not empty (give --force to replace the scene in it)")
    ours = {"frames", "calibration.yaml", "truth.jsonl", "scene.json"}
    others = sorted(p.name for p in out.iterdir() if p.name not in ours)
    frames = out / "frames"
    if frames.is_dir():
        others += sorted(f"frames/{p.name}" for p in frames.iterdir() if not _FRAME.fullmatch(p.name))
    if others:
        raise BadInput(f"--out {out}: holds files that are not a scene's ({', '.join(others[:3])}); "
                       "choose another folder")
    for old in frames.glob("*.png") if frames.is_dir() else ():
        old.unlink()


_FRAME = re.compile(r"\d{5,}\.png")
