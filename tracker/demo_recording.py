"""Recording a synthetic scene through the real pipeline (how ``recordings/demo.mcap`` is made)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TextIO

from tracker.atomic import atomic_path
from tracker.config import TrackerConfig
from tracker.errors import BadInput
from tracker.health import Health
from tracker.pipeline import Pipeline
from tracker.recording.replay import Progress
from tracker.recording.writer import Recorder, RecorderConfig, RunInfo
from tracker.runner import Runner, RunSummary
from tracker.scenes import SyntheticSource
from tracker.sources import Frame, FrameSource
from tracker.synthetic import SceneSpec


class _Counted(FrameSource):
    """A source that reports each frame it delivers to a progress bar."""

    def __init__(self, source: FrameSource, progress: Progress) -> None:
        self.source, self.name, self.progress = source, source.name, progress

    def __iter__(self) -> Iterator[Frame]:
        done = 0
        for frame in self.source:
            yield frame
            done += 1
            self.progress.update(done)
        self.progress.end(done)


def record_scene(scene: SceneSpec, path: str, name: str = "synthetic demo",
                 config: TrackerConfig | None = None, recorder: RecorderConfig | None = None,
                 progress_out: TextIO | None = None) -> RunSummary:
    """Render, track and record ``scene`` with the recorder's normal settings, into a temporary
    file renamed over ``path`` at the end (a failure leaves what was there). No wall-clock time
    goes into the file: the same scene and settings give the same bytes."""
    source: FrameSource = SyntheticSource(scene, name=name)
    calibration = source.calibration
    if progress_out is not None:
        source = _Counted(source, Progress(progress_out, scene.n_frames, "synth"))
    config = config or TrackerConfig()
    health = Health()
    info = RunInfo(calibration, config, name, scene.fps, wall_clock=False)
    try:
        with atomic_path(path) as tmp:
            sink = Recorder.open(str(tmp), info, health, recorder)
            return Runner(source, Pipeline(calibration, config), [sink], health).run()
    except OSError as exc:
        raise BadInput(f"--record {path}: cannot write the recording: {exc.strerror}") from None
