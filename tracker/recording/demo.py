"""Recording a synthetic scene through the real pipeline (how ``recordings/demo.mcap`` is made)."""

from __future__ import annotations

from tracker.config import TrackerConfig
from tracker.health import Health
from tracker.pipeline import Pipeline
from tracker.recording.writer import Recorder, RecorderConfig, RunInfo
from tracker.runner import Runner, RunSummary
from tracker.scenes import SyntheticSource
from tracker.synthetic import SceneSpec

# Offline there is time to compress hard: level 19 makes the bundled demo ~3x smaller than level 1.
ARCHIVE = RecorderConfig(zstd_level=19, zstd_threads=0)


def record_scene(scene: SceneSpec, path: str, name: str = "synthetic demo",
                 config: TrackerConfig | None = None, recorder: RecorderConfig = ARCHIVE) -> RunSummary:
    source = SyntheticSource(scene, name=name)
    config = config or TrackerConfig()
    health = Health()
    sink = Recorder.open(path, RunInfo(source.calibration, config, name, scene.fps), health, recorder)
    return Runner(source, Pipeline(source.calibration, config), [sink], health).run()
