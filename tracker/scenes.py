"""Named synthetic scenes (for the demo, the tests and the benchmark) and a source that renders them."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import replace

from tracker.sources import Frame, FrameSource
from tracker.synthetic import STRONG_DISTORTION, CameraSpec, PartSpec, Renderer, SceneSpec


def _crossing(speed_mm_s: float, fps: float, span_mm: float) -> int:
    """Frames a part needs to cross ``span_mm`` of belt."""
    return int(span_mm / speed_mm_s * fps) + 1


def nadir(speed_mm_s: float = 300.0, fps: float = 60.0, **kw) -> SceneSpec:
    """Camera straight down, no distortion; an 80x50 mm flat part crosses the view along +X."""
    part = PartSpec(80, 50, 0, -480, 12, 25, speed_mm_s, 0)
    return SceneSpec(CameraSpec(), (part,), fps, _crossing(speed_mm_s, fps, 960), **kw)


def tilted(speed_mm_s: float = 300.0, fps: float = 60.0, **kw) -> SceneSpec:
    """20 deg tilt, 30 deg yaw, strong barrel distortion; the part crosses diagonally."""
    cam = CameraSpec(dist_coeffs=STRONG_DISTORTION, tilt_deg=20, yaw_deg=30)
    part = PartSpec(80, 50, 0, -560, -150, -35, speed_mm_s * 0.94, speed_mm_s * 0.34)
    return SceneSpec(cam, (part,), fps, _crossing(speed_mm_s, fps, 1150), **kw)


def empty(n_frames: int = 120, **kw) -> SceneSpec:
    """Nothing moves: any object reported is false."""
    return SceneSpec(CameraSpec(), (), n_frames=n_frames, **kw)


def demo(**kw) -> SceneSpec:
    """Several parts at different angles, one turning, through a tilted, distorting lens."""
    cam = CameraSpec(width=480, height=360, focal_px=420.0, dist_coeffs=STRONG_DISTORTION, tilt_deg=10, yaw_deg=5)
    v = 300.0
    parts = (
        PartSpec(80, 50, 0, -560, -40, 20, v, 0),
        PartSpec(60, 60, 0, -560 - 1.2 * v, 60, 5, v, 0, intensity=170),
        PartSpec(120, 40, 0, -560 - 2.4 * v, 0, -60, v, 0, omega_deg_s=40.0, intensity=220),
        PartSpec(70, 45, 0, -560 - 3.6 * v, -70, 90, v, 0, intensity=190),
    )
    # Low sensor noise: noise is incompressible, and the bundled recording must stay under 5 MB.
    settings = {"fps": 30.0, "n_frames": 240, "noise_sigma": 0.1, "exposure_s": 0.004} | kw
    return SceneSpec(cam, parts, **settings)


PRESETS: dict[str, Callable[..., SceneSpec]] = {
    "nadir": nadir,
    "tilted": tilted,
    "empty": empty,
    "demo": demo,
}


def preset(name: str, **kw) -> SceneSpec:
    return PRESETS[name](**kw)


def resized(scene: SceneSpec, width: int, height: int) -> SceneSpec:
    """The same scene seen by a camera of another resolution (same field of view)."""
    cam = scene.camera
    scale = width / cam.width
    return replace(scene, camera=replace(cam, width=width, height=height, focal_px=cam.focal_px * scale))


class SyntheticSource(FrameSource):
    """Renders a scene frame by frame, as if it were a video file (not paced)."""

    def __init__(self, scene: SceneSpec, name: str = "synthetic") -> None:
        self.name = name
        self.scene = scene
        self.renderer = Renderer(scene)
        self.calibration = self.renderer.calibration
        self.truth: list[dict] = []

    def __iter__(self) -> Iterator[Frame]:
        for index in range(self.scene.n_frames):
            image, truth = self.renderer.render(index)
            self.truth.append(truth)
            yield Frame(index, self.scene.t_ns(index), image, time.monotonic_ns())
