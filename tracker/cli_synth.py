"""``tracker synth``: render a synthetic scene with exact ground truth to disk."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import cv2

from tracker import calibration as calib_io
from tracker.errors import BadInput
from tracker.scenes import PRESETS, preset, resized
from tracker.synthetic import Renderer, SceneSpec


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "synth", help="render a synthetic scene (frames, calibration, ground truth)",
        description="Writes DIR/frames/%%05d.png, DIR/calibration.yaml, DIR/truth.jsonl (pose-stream shape) "
        "and DIR/scene.json.",
    )
    p.add_argument("preset", choices=sorted(PRESETS), help="scene to render")
    p.add_argument("--out", help="output folder")
    p.add_argument("--record", metavar="OUT.mcap",
                   help="instead of files, track the scene and record it (how recordings/demo.mcap is made)")
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
    scene = preset(args.preset)
    changes = {k: v for k, v in (("n_frames", args.frames), ("noise_sigma", args.noise),
                                 ("flicker", args.flicker), ("seed", args.seed)) if v is not None}
    scene = dataclasses.replace(scene, **changes)
    if args.size:
        scene = resized(scene, *parse_size(args.size))
    return scene


def write_scene(scene: SceneSpec, out: Path) -> Path:
    """Render every frame; returns the printf pattern of the frames."""
    frames = out / "frames"
    try:
        frames.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BadInput(f"{out}: cannot create the output folder: {exc.strerror}") from None
    renderer = Renderer(scene)
    calib_io.save(renderer.calibration, out / "calibration.yaml")
    (out / "scene.json").write_text(json.dumps(dataclasses.asdict(scene), indent=1))
    with open(out / "truth.jsonl", "w", encoding="utf-8") as truth_file:
        for index in range(scene.n_frames):
            image, truth = renderer.render(index)
            if not cv2.imwrite(str(frames / f"{index:05d}.png"), image, [cv2.IMWRITE_PNG_COMPRESSION, 1]):
                raise BadInput(f"{frames}: cannot write frame {index}")
            truth_file.write(json.dumps(truth) + "\n")
    return frames / "%05d.png"


def run(args: argparse.Namespace) -> int:
    scene = scene_from_args(args)
    if args.record:
        from tracker.recording.demo import record_scene  # noqa: PLC0415 - optional edge

        summary = record_scene(scene, args.record, name=f"synthetic {args.preset}")
        print(f"tracker: {summary.line()} -> {args.record}")
        return 0
    if not args.out:
        raise BadInput("synth: give --out DIR (frames on disk) or --record OUT.mcap")
    pattern = write_scene(scene, Path(args.out))
    print(f"tracker: {scene.n_frames} frames at {scene.fps:g} fps -> {pattern}")
    print(f"tracker: run it with: tracker run --source {pattern} --calibration {Path(args.out) / 'calibration.yaml'} "
          f"--fps {scene.fps:g} --no-plc --poses poses.jsonl")
    return 0
