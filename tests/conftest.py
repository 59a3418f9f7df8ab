"""Shared fixtures: synthetic scenes are rendered once per session and reused."""

from __future__ import annotations

import functools
import logging
from pathlib import Path

import pytest

from tracker.pipeline import Pipeline
from tracker.synthetic import Renderer, SceneSpec

ROOT = Path(__file__).resolve().parent.parent
SHARED_DATA = ROOT.parent / "shared" / "data"
# Sub-pixel samples per side of an edge pixel in the rendered scenes of parts with height. At 4 a side
# face's rendered area was off by up to 0.07 px of its width over 8 px of its edge, always the same way
# along an edge at some angles (the pattern repeats in every pixel), which a thin box's height and
# first sizes read as tenths of a mm; at 8 it is within 0.01 px (tests/test_synthetic.py).
BOX_SUPERSAMPLE = 8


@pytest.fixture(autouse=True)
def _logging_left_to_pytest():
    """The CLI (called in-process) points the root logger at the sys.stderr of its test, which pytest
    closes: a later test's log line would fail on it ("--- Logging error ---", I/O operation on closed
    file). Its handler goes with its test (pytest's own are subclasses, and stay)."""
    yield
    root = logging.getLogger()
    for handler in root.handlers[:]:
        if type(handler) is logging.StreamHandler:
            root.removeHandler(handler)


@functools.cache
def rendered(scene: SceneSpec) -> tuple[Renderer, tuple]:
    """(renderer, ((image, truth), ...)) for every frame of ``scene``; cached for the session."""
    renderer = Renderer(scene)
    return renderer, tuple(renderer.render(i) for i in range(scene.n_frames))


def run_pipeline(scene: SceneSpec, config=None, images: list | None = None) -> tuple[list[dict], list[dict]]:
    """(pose-stream dicts, truth dicts) of the pipeline over a rendered scene; ``images``: its frames
    altered (clutter painted on them), one per frame, instead of the rendered ones."""
    renderer, frames = rendered(scene)
    pipeline = Pipeline(renderer.calibration, config)
    images = [image for image, _ in frames] if images is None else images
    poses = [pipeline.process(i, image, scene.t_ns(i)).to_dict() for i, image in enumerate(images)]
    return poses, [truth for _, truth in frames]


@pytest.fixture(scope="session")
def scene_dir(tmp_path_factory) -> Path:
    """A short synthetic scene on disk (frames/%05d.png, calibration.yaml, truth.jsonl), 30 fps."""
    from tracker.cli_synth import write_scene
    from tracker.scenes import nadir

    out = tmp_path_factory.mktemp("scene")
    write_scene(nadir(600.0, fps=30.0), out)
    return out


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"../shared/data is absent ({SHARED_DATA}): real-data tests need it")
    return SHARED_DATA
